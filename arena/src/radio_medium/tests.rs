//! Unit tests of the radio medium.

use super::*;

fn quiet() -> MediumParams {
    MediumParams::default()
}

#[test]
fn single_packet_timing() {
    let p = quiet();
    let mut m = RadioMedium::new(p.clone(), 1);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    let msg = [1u8, 2, 3, 4, 5];
    assert_eq!(m.write(a, 0, &msg), 5);
    let done = p.pipeline_latency_ns(msg.len());
    assert_eq!(
        m.next_packet_time(),
        Some(5 * p.uart_byte_ns + p.gap_timeout_ns)
    );
    m.step(done - 1);
    assert_eq!(m.next_packet_time(), Some(done));
    let first = m.read(b, done - 1);
    assert_eq!(first, msg[..4].to_vec());
    assert_eq!(m.read(b, done), msg[4..].to_vec());
    assert!(m.read(a, done).is_empty(), "no echo to the sender");
    assert_eq!(m.stats().packets_sent, 1);
    assert_eq!(m.stats().deliveries, 1);
    assert_eq!(m.next_packet_time(), None);
}

#[test]
fn long_runs_reuse_transmission_slots() {
    let p = quiet();
    let mut m = RadioMedium::new(p.clone(), 1);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    let period = 10 * p.pipeline_latency_ns(8);
    for k in 0..2_000u64 {
        let t = k * period;
        m.write(a, t, &[k as u8; 8]);
        m.step(t + period - 1);
        assert_eq!(m.read(b, t + period - 1).len(), 8);
    }
    assert_eq!(m.stats().packets_sent, 2_000);
    assert!(
        m.air.len() < 16,
        "transmission table grew to {}",
        m.air.len()
    );
}

#[test]
fn mtu_splits_packets() {
    let mut m = RadioMedium::new(quiet(), 1);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    let msg: Vec<u8> = (0..150u8).collect();
    m.write(a, 0, &msg);
    let got = m.read(b, 100_000_000);
    assert_eq!(got, msg);
    assert_eq!(m.stats().packets_sent, 3);
}

#[test]
fn gap_splits_packets() {
    let p = quiet();
    let mut m = RadioMedium::new(p.clone(), 1);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    m.write(a, 0, &[1, 2]);
    m.write(a, 2 * p.uart_byte_ns + p.gap_timeout_ns / 2, &[3]);
    m.write(a, 10_000_000, &[4]);
    assert_eq!(m.read(b, 100_000_000), vec![1, 2, 3, 4]);
    assert_eq!(m.stats().packets_sent, 2);
}

#[test]
fn simultaneous_senders_collide() {
    let mut m = RadioMedium::new(quiet(), 1);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    let c = m.add_node((0.0, 1.0));
    m.write(a, 0, &[1; 10]);
    m.write(b, 0, &[2; 10]);
    m.step(50_000_000);
    // Both start within the sense delay: c hears a collision; a and b were transmitting.
    assert!(m.read(c, 50_000_000).is_empty());
    assert_eq!(m.stats().collisions, 2);
    assert_eq!(m.stats().half_duplex, 2);
}

#[test]
fn carrier_sense_defers() {
    let p = quiet();
    let mut m = RadioMedium::new(p.clone(), 1);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    let c = m.add_node((0.0, 1.0));
    m.write(a, 0, &[1; 10]);
    // b's packet becomes ready while a is on air (well after the sense delay).
    m.write(b, 1_000_000, &[2; 10]);
    m.step(100_000_000);
    let got = m.read(c, 100_000_000);
    assert_eq!(got.len(), 20);
    assert_eq!(m.stats().collisions, 0);
    assert!(m.stats().csma_defers >= 1);
}

#[test]
fn range_and_loss() {
    let mut p = quiet();
    p.range_m = 10.0;
    p.fade_start_m = 10.0;
    let mut m = RadioMedium::new(p, 1);
    let a = m.add_node((0.0, 0.0));
    let far = m.add_node((20.0, 0.0));
    m.write(a, 0, &[1; 4]);
    assert!(m.read(far, 100_000_000).is_empty());
    assert_eq!(m.stats().deliveries, 0);

    let mut p = quiet();
    p.loss_probability = 0.2;
    let mut m = RadioMedium::new(p, 7);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    for i in 0..1000u64 {
        m.write(a, i * 10_000_000, &[1; 4]);
    }
    m.step(20_000_000_000);
    let lost = m.stats().random_losses;
    assert!((150..250).contains(&lost), "{lost}");
    assert_eq!(m.read(b, 20_000_000_000).len() as u64, 4 * (1000 - lost));
}

#[test]
fn buffers_overflow() {
    let mut p = quiet();
    p.tx_buffer = 32;
    let mut m = RadioMedium::new(p, 1);
    let a = m.add_node((0.0, 0.0));
    assert_eq!(m.write(a, 0, &[1; 40]), 32);
    assert_eq!(m.stats().tx_overflow_bytes, 8);

    let mut p = quiet();
    p.rx_buffer = 20;
    let mut m = RadioMedium::new(p, 1);
    let a = m.add_node((0.0, 0.0));
    let b = m.add_node((1.0, 0.0));
    m.write(a, 0, &[1; 30]);
    assert!(m.read(b, 100_000_000).is_empty());
    assert_eq!(m.stats().rx_overflows, 1);
}

proptest::proptest! {
    /// On a lossless channel with one sender, every byte written arrives once, in order,
    /// whatever the write times and sizes.
    #[test]
    fn lossless_pipe_preserves_the_stream(
        writes in proptest::collection::vec((0u64..3_000_000, 1usize..100), 1..30)
    ) {
        let p = MediumParams { tx_buffer: 4096, rx_buffer: 4096, ..quiet() };
        let mut m = RadioMedium::new(p, 1);
        let a = m.add_node((0.0, 0.0));
        let b = m.add_node((1.0, 0.0));
        let mut t = 0;
        let mut sent = Vec::new();
        let mut got = Vec::new();
        for (i, (gap, len)) in writes.into_iter().enumerate() {
            t += gap;
            let bytes: Vec<u8> = (0..len).map(|k| (i * 31 + k) as u8).collect();
            proptest::prop_assert_eq!(m.write(a, t, &bytes), len);
            sent.extend(bytes);
            got.extend(m.read(b, t));
        }
        got.extend(m.read(b, t + 1_000_000_000));
        proptest::prop_assert_eq!(got, sent);
        proptest::prop_assert_eq!(m.stats().collisions, 0);
    }
}

#[test]
fn deterministic_per_seed() {
    let run = |seed| {
        let mut p = quiet();
        p.loss_probability = 0.3;
        let mut m = RadioMedium::new(p, seed);
        let a = m.add_node((0.0, 0.0));
        let b = m.add_node((1.0, 0.0));
        for i in 0..50u64 {
            m.write(a, i * 5_000_000, &[i as u8; 3]);
        }
        m.read(b, 1_000_000_000)
    };
    assert_eq!(run(3), run(3));
    assert_ne!(run(3), run(4));
}
