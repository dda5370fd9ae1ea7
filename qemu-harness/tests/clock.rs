//! Acceptance: the firmware's one-second tick agrees with the host wall clock within 2 %.

use std::time::Duration;

use qemu_harness::{Level, LogLine};

mod common;

/// Tick lines measured: the first and the last are this many seconds apart.
const SPAN_TICKS: u64 = 8;
const TOLERANCE: f64 = 0.02;

fn is_tick(line: &LogLine) -> bool {
    line.level == Some(Level::Info) && line.message.starts_with("tick ")
}

fn tick_fields(line: &LogLine) -> (u64, u64) {
    let n = line.word_after("tick").and_then(|v| v.parse().ok());
    let mtime = line.field("mtime").and_then(|v| v.parse().ok());
    match (n, mtime) {
        (Some(n), Some(mtime)) => (n, mtime),
        _ => panic!("malformed tick line: {line}"),
    }
}

#[test]
fn tick_matches_host_clock_within_2_percent() {
    let Some((qemu, banner)) = common::boot(
        "tick_matches_host_clock_within_2_percent",
        common::Firmware::EchoTest,
    ) else {
        return;
    };
    let hz: u64 = banner
        .field("timebase")
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("timebase in {banner}"));
    let log = qemu.log();
    let wait = Duration::from_secs(3);

    // Skip the first tick: its host arrival overlaps start-up.
    let (i, first_seen) = log.wait_for_from(0, is_tick, wait).expect("first tick");
    let (mut i, first) = log
        .wait_for_from(i + 1, is_tick, wait)
        .expect("second tick");
    let (n0, mtime0) = tick_fields(&first);
    let mut last = first.clone();
    let mut expected_n = n0;
    while tick_fields(&last).0 < n0 + SPAN_TICKS {
        let (j, line) = log.wait_for_from(i + 1, is_tick, wait).expect("next tick");
        expected_n += 1;
        assert_eq!(
            tick_fields(&line).0,
            expected_n,
            "tick numbers must be consecutive"
        );
        i = j;
        last = line;
    }
    let (n1, mtime1) = tick_fields(&last);
    assert_eq!(tick_fields(&first_seen).0 + 1, n0);

    let ticks = (n1 - n0) as f64;
    let host = (last.host_time - first.host_time).as_secs_f64();
    let error = (host - ticks) / ticks;
    eprintln!(
        "clock: {ticks} ticks took {host:.4} s on the host ({:+.3} %)",
        error * 100.0
    );
    assert!(
        error.abs() < TOLERANCE,
        "{ticks} firmware seconds took {host:.4} s of host time ({:+.2} %)",
        error * 100.0
    );

    // The tick's own mtime stamps agree with its count.
    let firmware = (mtime1 - mtime0) as f64 / hz as f64;
    assert!(
        ((firmware - ticks) / ticks).abs() < TOLERANCE,
        "mtime advanced {firmware:.4} s over {ticks} ticks"
    );
}
