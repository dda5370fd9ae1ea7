//! Acceptance: 1 MiB of seeded random bytes pushed into each UART at once (the LBC and the
//! radio, each from its own writer thread, read back concurrently) all come back intact
//! and in order while the firmware keeps computing between drains of its RX rings.

use std::thread;
use std::time::{Duration, Instant};

use qemu_harness::{Error, Uart};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod common;

const TOTAL: usize = 1 << 20;
const CHUNK: usize = 4096;
/// Hard bound for the whole exchange. QEMU moves UART bytes at a few tens of KiB/s (each
/// RX FIFO refill is a hand-off between its I/O thread and the vCPU, each echoed byte one
/// socket write), so this takes about 30 s on a quiet two-core machine and over 120 s when
/// other work loads it; the bound only catches a stall.
const DEADLINE: Duration = Duration::from_secs(300);
const PANIC_REQUEST: &[u8] = b"!ubc-panic!";
/// A read shorter than this is followed by a short pause so bytes accumulate.
const BATCH: usize = 1024;
const BATCH_PAUSE: Duration = Duration::from_millis(5);

fn payload(seed: u64) -> Vec<u8> {
    let mut data = vec![0u8; TOTAL];
    ChaCha8Rng::seed_from_u64(seed).fill_bytes(&mut data);
    assert!(
        !data
            .windows(PANIC_REQUEST.len())
            .any(|w| w == PANIC_REQUEST),
        "seed {seed} happens to contain the panic request"
    );
    data
}

/// Writes `data` in chunks from one thread while another reads it back and compares.
fn echo(uart: Uart, data: &[u8], start: Instant) -> Result<Duration, String> {
    let name = uart.name();
    let mut writer = uart.try_clone().map_err(|e| e.to_string())?;
    let mut reader = uart;
    thread::scope(|s| {
        let written = s.spawn(move || -> Result<(), String> {
            for chunk in data.chunks(CHUNK) {
                writer
                    .write_all(chunk)
                    .map_err(|e| format!("{name}: write failed: {e}"))?;
            }
            Ok(())
        });
        let mut buf = vec![0u8; 64 * 1024];
        let mut offset = 0;
        let read = loop {
            if offset == data.len() {
                break Ok(start.elapsed());
            }
            let want = buf.len().min(data.len() - offset);
            let left = DEADLINE.saturating_sub(start.elapsed());
            let n = match reader.read_some_timeout(&mut buf[..want], left) {
                Ok(n) => n,
                Err(Error::UartTimeout { .. }) => {
                    break Err(format!(
                    "{name}: only {offset} of {} bytes came back (all intact) within {DEADLINE:?}",
                    data.len()
                ))
                }
                Err(e) => break Err(format!("{name}: after {offset} bytes echoed intact: {e}")),
            };
            let expected = &data[offset..offset + n];
            if let Some(i) = expected.iter().zip(&buf[..n]).position(|(a, b)| a != b) {
                let at = offset + i;
                break Err(format!(
                    "{name}: first mismatch at offset {at}: sent {:#04x}, got {:#04x}",
                    data[at], buf[i]
                ));
            }
            offset += n;
            if n < BATCH {
                // QEMU sends the echo a byte per write; letting it pile up in the socket
                // leaves the CPU to QEMU instead of waking this thread for every byte.
                thread::sleep(BATCH_PAUSE);
            }
        };
        let written = written
            .join()
            .unwrap_or_else(|_| Err(format!("{name}: writer thread panicked")));
        // A read error explains a stalled writer better than the writer's own timeout.
        let elapsed = read?;
        written?;
        Ok(elapsed)
    })
}

#[test]
fn one_mib_each_way_on_both_uarts() {
    let Some((mut qemu, _banner)) =
        common::boot("one_mib_each_way_on_both_uarts", common::Firmware::EchoTest)
    else {
        return;
    };
    let lbc = qemu.take_lbc().expect("lbc attached");
    let radio = qemu.take_radio().expect("radio attached");
    let lbc_data = payload(0x1bc_0001);
    let radio_data = payload(0x7ad_0002);

    let start = Instant::now();
    let (lbc_result, radio_result) = thread::scope(|s| {
        let l = s.spawn(|| echo(lbc, &lbc_data, start));
        let r = s.spawn(|| echo(radio, &radio_data, start));
        let join = |h: thread::ScopedJoinHandle<'_, Result<Duration, String>>| {
            h.join()
                .unwrap_or_else(|_| Err("echo thread panicked".to_owned()))
        };
        (join(l), join(r))
    });
    let mut failures = Vec::new();
    for (name, result) in [("lbc", &lbc_result), ("radio", &radio_result)] {
        match result {
            Ok(t) => eprintln!(
                "echo: {name}: {TOTAL} bytes back intact in {:.2} s ({:.0} KiB/s)",
                t.as_secs_f64(),
                TOTAL as f64 / 1024.0 / t.as_secs_f64()
            ),
            Err(e) => failures.push(e.clone()),
        }
    }
    assert!(
        failures.is_empty(),
        "{}\nQEMU status: {:?}, last log lines: {:#?}",
        failures.join("\n"),
        qemu.try_wait(),
        qemu.log()
            .lines()
            .iter()
            .rev()
            .take(5)
            .map(ToString::to_string)
            .collect::<Vec<_>>()
    );
}
