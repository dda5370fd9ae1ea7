//! Tests of the interrupt-driven serial port against the UART model.

use super::*;
use crate::uart::model::UartModel;
use proptest::prelude::*;
use std::collections::VecDeque;

type Bus = &'static UartModel;

fn open() -> (&'static UartModel, &'static PortState<Bus>, Port<Bus>) {
    let model: &'static UartModel = Box::leak(Box::default());
    let state: &'static PortState<Bus> = Box::leak(Box::new(PortState::new()));
    let port = state
        .open(Ns16550::new(model), &Config::default())
        .expect("first open");
    (model, state, port)
}

/// Delivers bytes the way hardware does: at most a FIFO's worth before the interrupt runs.
fn deliver(model: &UartModel, state: &PortState<Bus>, bytes: &[u8]) {
    for chunk in bytes.chunks(FIFO_DEPTH) {
        model.receive(chunk);
        if model.irq_line() {
            state.on_interrupt();
        }
    }
}

/// Delivers bytes like QEMU's character backend: only into free FIFO space, so a held
/// receiver makes the sender wait. Returns when nothing more can move.
fn pump(model: &UartModel, state: &PortState<Bus>, line: &mut VecDeque<u8>) {
    loop {
        let room = FIFO_DEPTH - model.s.lock().unwrap().rx.len();
        let n = room.min(line.len());
        let chunk: Vec<u8> = line.drain(..n).collect();
        model.receive(&chunk);
        let irq = model.irq_line();
        if irq {
            state.on_interrupt();
        }
        if n == 0 && !irq {
            return;
        }
    }
}

fn drain(port: &mut Port<Bus>) -> Vec<u8> {
    let mut out = Vec::new();
    while let Some(b) = port.read_byte() {
        out.push(b);
    }
    out
}

#[test]
fn open_twice_fails() {
    let (model, state, _port) = open();
    assert_eq!(
        state.open(Ns16550::new(model), &Config::default()).err(),
        Some(OpenError::AlreadyOpen)
    );
}

#[test]
fn open_enables_rx_and_line_status_interrupts() {
    let (model, _state, _port) = open();
    assert_eq!(model.s.lock().unwrap().ier, 0b0101);
}

#[test]
fn rx_bytes_arrive_in_order() {
    let (model, state, mut port) = open();
    deliver(model, state, b"hello, lower board");
    assert_eq!(port.rx_len(), 18);
    assert_eq!(drain(&mut port), b"hello, lower board");
    assert_eq!(state.stats().rx_bytes, 18);
}

#[test]
fn full_ring_holds_the_receiver_and_loses_nothing() {
    let (model, state, mut port) = open();
    let data: Vec<u8> = (0..RX_RING_SIZE + 40).map(|i| (i % 251) as u8).collect();
    let cap = RX_RING_SIZE;
    deliver(model, state, &data[..cap]);
    assert_eq!(port.rx_len(), cap);
    // The next bytes cannot go into the ring: the handler masks RX instead of dropping.
    model.receive(&data[cap..cap + FIFO_DEPTH]);
    state.on_interrupt();
    assert!(!Ier(model.s.lock().unwrap().ier).rx_available());
    assert!(
        !model.irq_line(),
        "a held receiver must not keep the line asserted"
    );
    assert_eq!(state.stats().rx_ring_full, 1);
    assert_eq!(model.s.lock().unwrap().rx.len(), FIFO_DEPTH);
    // Draining resumes the receiver; the FIFO content follows in order.
    let mut out = drain(&mut port);
    assert!(Ier(model.s.lock().unwrap().ier).rx_available());
    state.on_interrupt();
    deliver(model, state, &data[cap + FIFO_DEPTH..]);
    out.extend(drain(&mut port));
    assert_eq!(out, data);
    assert_eq!(state.stats().overruns, 0);
}

#[test]
fn overrun_is_counted_and_reported_once() {
    let (model, state, mut port) = open();
    model.receive(&[0u8; FIFO_DEPTH + 1]);
    state.on_interrupt();
    assert_eq!(state.stats().overruns, 1);
    assert_eq!(
        embedded_hal_nb::serial::Read::read(&mut port),
        Err(nb::Error::Other(SerialError::Overrun))
    );
    assert_eq!(embedded_hal_nb::serial::Read::read(&mut port), Ok(0));
    let mut buf = [0u8; 32];
    assert_eq!(embedded_io::Read::read(&mut port, &mut buf), Ok(15));
}

#[test]
fn tx_is_interrupt_driven_and_stops_when_empty() {
    let (model, state, mut port) = open();
    assert_eq!(port.write_available(b"echo"), 4);
    assert!(model.irq_line(), "queued bytes unmask THR empty");
    assert_eq!(model.sent(), b"");
    state.on_interrupt();
    assert_eq!(model.sent(), b"echo");
    assert!(!Ier(model.s.lock().unwrap().ier).thr_empty());
    assert!(!model.irq_line());
    assert!(port.tx_idle());
    assert_eq!(state.stats().tx_bytes, 4);
}

#[test]
fn tx_fills_at_most_one_fifo_per_interrupt() {
    let (model, state, mut port) = open();
    model.s.lock().unwrap().tx_stalled = true;
    let data: Vec<u8> = (0..40u8).collect();
    assert_eq!(port.write_available(&data), 40);
    state.on_interrupt();
    assert_eq!(model.sent().len(), FIFO_DEPTH);
    assert!(!port.tx_idle());
    model.s.lock().unwrap().tx_stalled = false;
    model.drain_line();
    state.on_interrupt();
    state.on_interrupt();
    assert_eq!(model.sent(), data);
}

#[test]
fn full_tx_ring_would_block() {
    let (model, _state, mut port) = open();
    model.s.lock().unwrap().tx_stalled = true;
    let data = vec![0x55u8; TX_RING_SIZE + 10];
    assert_eq!(port.write_available(&data), TX_RING_SIZE);
    assert_eq!(
        embedded_hal_nb::serial::Write::write(&mut port, 1),
        Err(nb::Error::WouldBlock)
    );
}

#[test]
fn flush_polled_sends_everything_without_interrupts() {
    let (model, _state, mut port) = open();
    port.write_available(b"last words");
    port.flush_polled();
    assert_eq!(model.sent(), b"last words");
    assert!(port.tx_idle());
}

static NOW: AtomicU32 = AtomicU32::new(0);

fn stamped(delimiter: u8) -> (&'static UartModel, &'static PortState<Bus>, Port<Bus>) {
    let (model, state, mut port) = open();
    port.stamp_frames(FrameStamping {
        delimiter,
        now: || NOW.load(Ordering::Relaxed),
        char_ticks: 10,
    });
    (model, state, port)
}

fn at(now: u32, model: &UartModel, state: &PortState<Bus>, bytes: &[u8], timeout: bool) {
    NOW.store(now, Ordering::Relaxed);
    model.s.lock().unwrap().rx_timeout = timeout;
    model.receive(bytes);
    state.on_interrupt();
}

#[test]
fn frame_ends_are_stamped_back_from_the_interrupt() {
    let (model, state, mut port) = stamped(0);
    assert!(!port.frame_end_pending());
    // Trigger level: the last byte arrived now, those before it one character apart.
    at(1000, model, state, b"ab\0cd\0e", false);
    assert!(port.frame_end_pending());
    assert_eq!(port.oldest_frame_end(), Some(960));
    let mut buf = [0u8; 16];
    assert_eq!(port.read_frame(&mut buf), (3, Some(960)));
    assert_eq!(&buf[..3], b"ab\0");
    assert!(port.frame_end_pending());
    assert_eq!(port.oldest_frame_end(), Some(990));
    assert_eq!(port.read_frame(&mut buf), (3, Some(990)));
    assert!(!port.frame_end_pending(), "only a partial frame is left");
    assert_eq!(port.oldest_frame_end(), None);
    // Receive timeout: the last byte arrived four characters before the interrupt.
    at(2000, model, state, b"fg\0", true);
    assert_eq!(port.read_frame(&mut buf), (4, Some(1960)));
    assert_eq!(&buf[..4], b"efg\0");
    assert_eq!(port.read_frame(&mut buf), (0, None));
}

#[test]
fn frame_reads_stop_at_the_buffer_and_without_stamping() {
    let (model, state, mut port) = open();
    model.receive(b"xy\0z");
    state.on_interrupt();
    assert!(!port.frame_end_pending());
    let mut buf = [0u8; 2];
    // Without stamping there is no delimiter: plain reads.
    assert_eq!(port.read_frame(&mut buf), (2, None));
    let (_, state2, mut port2) = {
        let (m, s, p) = stamped(0);
        at(50, m, s, b"12345\0", false);
        (m, s, p)
    };
    let _ = state2;
    assert_eq!(
        port2.read_frame(&mut buf),
        (2, None),
        "buffer full before the end"
    );
    let mut rest = [0u8; 8];
    assert_eq!(port2.read_frame(&mut rest), (4, Some(50)));
}

#[test]
fn stamps_stay_with_their_delimiters_when_reads_bypass_them() {
    let (model, state, mut port) = stamped(0xFF);
    at(100, model, state, &[1, 0xFF, 2, 0xFF], false);
    // Read the first frame without looking at stamps.
    let mut b = [0u8; 2];
    assert_eq!(port.read_available(&mut b), 2);
    let mut buf = [0u8; 8];
    assert_eq!(port.read_frame(&mut buf), (2, Some(100)));
}

#[test]
fn frame_ends_beyond_the_slots_are_read_unstamped() {
    let (model, state, mut port) = stamped(0);
    let n = FRAME_END_SLOTS + 5;
    for k in 0..n {
        at(1000 * (k as u32 + 1), model, state, &[7, 0], false);
    }
    let mut buf = [0u8; 4];
    for k in 0..n {
        let want = (k < FRAME_END_SLOTS).then_some(1000 * (k as u32 + 1));
        assert_eq!(port.read_frame(&mut buf), (2, want), "frame {k}");
    }
    // Slots free again: stamping resumes.
    at(99_000, model, state, &[7, 0], false);
    assert_eq!(port.read_frame(&mut buf), (2, Some(99_000)));
    assert!(!port.frame_end_pending());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Whatever the mix of arrivals and reads, bytes come out once each, in order.
    #[test]
    fn rx_preserves_every_byte(
        steps in prop::collection::vec((prop::collection::vec(any::<u8>(), 0..300), 0usize..600), 1..40)
    ) {
        let (model, state, mut port) = open();
        let mut line = VecDeque::new();
        let mut sent = Vec::new();
        let mut got = Vec::new();
        for (bytes, reads) in steps {
            line.extend(bytes.iter().copied());
            sent.extend_from_slice(&bytes);
            pump(model, state, &mut line);
            for _ in 0..reads {
                match port.read_byte() {
                    Some(b) => got.push(b),
                    None => break,
                }
            }
        }
        for _ in 0..1000 {
            pump(model, state, &mut line);
            got.extend(drain(&mut port));
            if line.is_empty() && model.s.lock().unwrap().rx.is_empty() {
                break;
            }
        }
        prop_assert_eq!(state.stats().overruns, 0);
        prop_assert_eq!(got, sent);
    }
}
