//! The same program on QEMU (`qemu_virt` build, `UBC_FW_ELF`) and on the SoC (`softcore` build,
//! `VTB_FIRMWARE`) sends the same bytes on the LBC link for the same scripted session.
//!
//! Session: a freshly powered, already booted emulated LBC (car 3, factory EEPROM, no boot
//! delay) on the LBC UART; nothing on the radio. The program brings the LBC up on its own. The
//! log is every byte the UBC sends on the LBC link from reset until 500 ms of the program's
//! time after its `lbc up` log line, compared as a sequence: timing (when bytes leave, how far
//! apart) is excluded, because QEMU runs in wall-clock time and the SoC in simulated time. For
//! the same reason a retransmission (the same command again after the 50 ms reply timeout,
//! when the QEMU side was descheduled) does not count: if the bytes differ, the decoded
//! commands are compared with consecutive repeats collapsed.
//! On QEMU the emulator runs in wall-clock time in this thread; on the SoC in lockstep.
//! Both boards run the radio on a UART, so nothing is left out of the comparison.
//!
//! Runs when both images are given (`cargo xtask test` sets both) and QEMU tests are not
//! skipped (`UBC_SKIP_QEMU=1`).
use lbc_emu::{Lbc, LbcConfig};
use lbc_link::{Command, Deframer};
use qemu_harness::{Error, Level, LineDecoder, LogFormat, Qemu, UartAttach};
use std::time::{Duration, Instant};
use verilator_tb::cosim::LbcCosim;
use verilator_tb::soc::{Event, Soc, Uart, CLOCK_HZ};

const CAR: u8 = 3;
const AFTER_UP_US: u64 = 500_000;
const MAX_BRINGUP: Duration = Duration::from_secs(20);

fn lbc() -> Lbc {
    let mut cfg = LbcConfig::default();
    cfg.boot_time_us = 0;
    Lbc::with_memory_eeprom(cfg, CAR)
}

fn soc_log(elf_path: &std::path::Path) -> Vec<u8> {
    let elf = std::fs::read(elf_path).expect("VTB_FIRMWARE is readable");
    let format = LogFormat::from_elf_bytes(&elf, elf_path).expect("defmt table");
    let mut soc = Soc::new();
    soc.load_elf(&elf).expect("a softcore image");
    let mut cosim = LbcCosim::new(soc, lbc());
    let mut decoder = LineDecoder::new(&format);
    let mut lines = Vec::new();
    let mut sent = Vec::new();
    let mut up_at = None;
    let step = u64::from(CLOCK_HZ) / 100;
    while up_at.is_none_or(|t| cosim.now_us() < t + AFTER_UP_US) {
        assert!(
            cosim.now_us() < 3_000_000,
            "no bring-up on the SoC: {lines:#?}"
        );
        for e in cosim.run(step) {
            match e.value {
                Event::Tx {
                    uart: Uart::Lbc,
                    byte,
                } => sent.push(byte),
                Event::Console(b) => decoder.push(&[b], Instant::now(), &mut lines),
                _ => {}
            }
        }
        if up_at.is_none() && lines.iter().any(|l| l.is(Level::Info, "lbc up")) {
            up_at = Some(cosim.now_us());
        }
    }
    sent
}

fn qemu_log(elf_path: &std::path::Path) -> Vec<u8> {
    let mut qemu = Qemu::builder(elf_path)
        .lbc(UartAttach::Harness)
        .radio(UartAttach::Null)
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start QEMU: {e}"));
    let mut uart = qemu.take_lbc().expect("harness LBC uart");
    let mut lbc = lbc();
    let start = Instant::now();
    let mut sent = Vec::new();
    let mut up_at = None;
    let mut buf = [0u8; 1024];
    let mut out = Vec::new();
    while up_at.is_none_or(|t: Instant| t.elapsed() < Duration::from_micros(AFTER_UP_US)) {
        assert!(
            start.elapsed() < MAX_BRINGUP,
            "no bring-up on QEMU: {:#?}",
            qemu.log().lines()
        );
        let n = match uart.read_some_timeout(&mut buf, Duration::from_millis(1)) {
            Ok(n) => n,
            Err(Error::UartTimeout { .. }) => 0,
            Err(e) => panic!("LBC uart: {e}"),
        };
        let now = start.elapsed().as_micros() as u64;
        sent.extend_from_slice(&buf[..n]);
        lbc.push_rx(now, &buf[..n]);
        lbc.step_until(now);
        out.clear();
        lbc.drain_tx(now, &mut out);
        uart.write_all(&out).expect("LBC uart write");
        if up_at.is_none()
            && qemu
                .log()
                .lines()
                .iter()
                .any(|l| l.is(Level::Info, "lbc up"))
        {
            up_at = Some(Instant::now());
        }
    }
    let _ = qemu.kill();
    sent
}

fn frames(bytes: &[u8]) -> Vec<String> {
    let mut d = Deframer::new();
    let mut out = Vec::new();
    for &b in bytes {
        match d.push(b) {
            None => {}
            Some(Ok(m)) => out.push(match Command::parse(&m) {
                Ok(msg) => format!("{msg:?}"),
                Err(e) => format!("unparsed {e:?}"),
            }),
            Some(Err(e)) => out.push(format!("bad frame {e:?}")),
        }
    }
    out
}

#[test]
fn qemu_and_soc_send_the_same_lbc_bytes() {
    let (Some(soc_elf), Some(qemu_elf)) = (
        std::env::var_os("VTB_FIRMWARE"),
        std::env::var_os("UBC_FW_ELF"),
    ) else {
        eprintln!("VTB_FIRMWARE and UBC_FW_ELF not both set: skipping the QEMU/SoC comparison");
        return;
    };
    if qemu_harness::skip_qemu_tests("qemu_and_soc_send_the_same_lbc_bytes") {
        return;
    }
    let on_soc = soc_log(std::path::Path::new(&soc_elf));
    let on_qemu = qemu_log(std::path::Path::new(&qemu_elf));
    assert!(!on_soc.is_empty());
    if on_qemu != on_soc {
        // A retransmission (the same command again after a 50 ms reply timeout) is timing:
        // QEMU shares the machine with other work. Anything else is a real difference.
        let (mut q, mut s) = (frames(&on_qemu), frames(&on_soc));
        q.dedup();
        s.dedup();
        assert_eq!(
            q,
            s,
            "LBC byte logs differ\n QEMU: {:#?}\n SoC:  {:#?}",
            frames(&on_qemu),
            frames(&on_soc)
        );
        eprintln!(
            "the logs differ only by retransmissions: {:?}",
            frames(&on_qemu)
        );
    }
    eprintln!(
        "SoC: {} bytes, {} frames: {:?}",
        on_soc.len(),
        frames(&on_soc).len(),
        frames(&on_soc)
    );
}
