//! Seeded fault injection seen through lbc-link's client.

mod common;

use common::Bench;
use lbc_emu::{FaultConfig, LbcConfig};
use lbc_link::client::Failure;
use lbc_link::{Command, Reply, StreamFormat};

fn with_faults(spec: &str, seed: u64) -> LbcConfig {
    let mut cfg = LbcConfig::default();
    cfg.faults = spec.parse::<FaultConfig>().unwrap();
    cfg.seed = seed;
    cfg
}

#[test]
fn drops_and_corruption_are_survived_by_retries() {
    let mut b = Bench::new(with_faults("drop=0.02,corrupt=0.02", 11));
    let mut ok = 0;
    for _ in 0..200 {
        match b.request(Command::ReadId) {
            Ok(Reply::ReadId(id)) => {
                assert_eq!(id.get(), 7);
                ok += 1;
            }
            Ok(other) => panic!("{other:?}"),
            Err(_) => {}
        }
    }
    let f = b.lbc.fault_stats();
    assert!(f.dropped > 0 && f.corrupted > 0, "{f:?}");
    assert!(b.client.stats().retries > 0);
    assert!(ok >= 190, "{ok} of 200 succeeded");
    // Corrupted commands that still frame get CSER or UNKCMD.
    let s = b.lbc.stats();
    assert!(s.cser + s.unkcmd > 0, "{s:?}");
}

#[test]
fn same_seed_same_faults() {
    let run = |seed| {
        let mut b = Bench::new(with_faults("drop=0.05,corrupt=0.05", seed));
        (0..50)
            .map(|_| b.request(Command::ReadId).is_ok())
            .collect::<Vec<_>>()
    };
    assert_eq!(run(3), run(3));
    assert_ne!(run(3), run(4));
}

#[test]
fn suppression_and_delay() {
    let mut b = Bench::new(with_faults("suppress=1", 1));
    assert_eq!(b.request(Command::ReadId), Err(Failure::TimedOut));

    let mut b = Bench::new(with_faults("delay-ms=5", 1));
    b.run_for(10_000);
    let sent = b.now;
    let out = b.raw_exchange(&[0xE8, 0x68, 0xFF], 20_000);
    let first = out.first().expect("a reply").0;
    // Parsed at the next 1 ms tick, held 5 ms, then one byte time on the line.
    assert!(
        first >= sent + 5_000 + 86,
        "first byte at +{} us",
        first - sent
    );
    assert!(first <= sent + 7_200, "first byte at +{} us", first - sent);
}

#[test]
fn spontaneous_resets_restart_the_lbc() {
    let mut b = Bench::new(with_faults("reset-every-s=0.5", 5));
    b.echo(Command::UpdSf(StreamFormat::new(1).unwrap()));
    let mut answered = 0;
    for _ in 0..50 {
        if b.request(Command::ReadId).is_ok() {
            answered += 1;
        }
        b.run_for(100_000);
    }
    let resets = b.lbc.stats().resets;
    assert!((4..=25).contains(&resets), "{resets} resets in ~5 s");
    assert!(answered >= 40, "{answered}");
    // After a reset the format is back to the default.
    assert_eq!(b.lbc.stream_format().bits(), 0x1F);
}
