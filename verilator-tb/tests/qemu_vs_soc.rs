//! The same program on QEMU (`qemu_virt` build, `UBC_FW_ELF`) and on the SoC (`softcore` build,
//! `VTB_FIRMWARE`) sends the same bytes on the LBC link for the same scripted session.
//!
//! Session: a freshly powered, already booted emulated LBC (car 3, factory EEPROM, no boot
//! delay) on the LBC UART and a radio-mac ground station (testbed key) on the radio UART. The
//! program brings the LBC up on its own while the ground station stays silent (what the car
//! sends on the radio meanwhile is dropped). 500 ms of the program's time after its `lbc up`
//! log line the ground station sends the console request `lbc` MOVE_XY 320 480 and waits for
//! its answer (the LBC's echo), lets the car drive for 200 ms, sends `lbc` STOP and waits for
//! its echo; the session ends 300 ms after that answer. The MOVE_XY request is the first
//! frame the car hears from the ground station (the ground station queues its first heartbeat
//! behind it), so the LED change the program makes on first hearing a ground station
//! (WRIT_LED) follows the MOVE_XY on both boards. While it streams with a ground station heard
//! the program sends nothing periodic on the LBC link, so the log has no timing-dependent
//! tail and is compared whole.
//!
//! The log is every byte the UBC sends on the LBC link from reset to the end of the session,
//! compared as a sequence: timing (when bytes leave, how far apart) is excluded, because QEMU
//! runs in wall-clock time and the SoC in simulated time. For the same reason a
//! retransmission (the same command again after the 50 ms reply timeout, when the QEMU side
//! was descheduled) does not count: if the bytes differ, the decoded commands are compared
//! with consecutive repeats collapsed. Both logs must hold the MOVE_XY frame, then the STOP.
//! On QEMU the LBC emulator and the ground station run in wall-clock time in this thread; on
//! the SoC in lockstep with its clock.
//!
//! Runs when both images are given (`cargo xtask test` sets both) and QEMU tests are not
//! skipped (`UBC_SKIP_QEMU=1`).
mod ground;

use ground::{Ground, GroundPeer};
use lbc_emu::{Lbc, LbcConfig};
use lbc_link::{Command, Deframer, Position, Reply as LbcReply};
use qemu_harness::{Error, Level, LineDecoder, LogFormat, Qemu, UartAttach};
use radio_mac::RequestHandle;
use std::cell::RefCell;
use std::rc::Rc;
use std::time::{Duration, Instant};
use ubc_app::program::console::{LbcOutcome, Reply, Request};
use verilator_tb::cosim::LbcCosim;
use verilator_tb::soc::{Event, Soc, Uart, CLOCK_HZ};

const CAR: u8 = 3;
/// From the `lbc up` line to the MOVE_XY request.
const AFTER_UP_US: u64 = 500_000;
/// From the MOVE_XY answer to the STOP request.
const DRIVE_US: u64 = 200_000;
/// From the STOP answer to the end of the session.
const TAIL_US: u64 = 300_000;
/// Bound on QEMU's start and bring-up (wall clock).
const MAX_BRINGUP: Duration = Duration::from_secs(20);
/// Bound on the whole session on QEMU (wall clock).
const MAX_QEMU_SESSION: Duration = Duration::from_secs(35);
/// Bound on the whole session on the SoC (simulated time).
const MAX_SOC_SESSION_US: u64 = 6_000_000;

fn target() -> Position {
    Position::new(320, 480).expect("in range")
}

fn lbc() -> Lbc {
    let mut cfg = LbcConfig::default();
    cfg.boot_time_us = 0;
    Lbc::with_memory_eeprom(cfg, CAR)
}

#[derive(Debug, Clone, Copy)]
enum Step {
    /// Waiting for the `lbc up` line.
    BringUp,
    Settle {
        until: u64,
    },
    Move(RequestHandle),
    Drive {
        until: u64,
    },
    Stop(RequestHandle),
    Tail {
        until: u64,
    },
    Done,
}

/// The scripted session on a board's clock (microseconds).
struct Session {
    step: Step,
}

impl Session {
    fn new() -> Self {
        Self {
            step: Step::BringUp,
        }
    }

    /// Advances the script at `now`; `up` once the program logged `lbc up`. True when done.
    fn advance(&mut self, now: u64, up: bool, ground: &mut Ground) -> bool {
        self.step = match self.step {
            Step::BringUp if up => Step::Settle {
                until: now + AFTER_UP_US,
            },
            Step::Settle { until } if now >= until => {
                Step::Move(ground.request(now, &Request::Lbc(Command::MoveXy(target()))))
            }
            Step::Move(h) => match ground.answer(h) {
                Some(r) => {
                    expect_echo(&r, Command::MoveXy(target()));
                    Step::Drive {
                        until: now + DRIVE_US,
                    }
                }
                None => Step::Move(h),
            },
            Step::Drive { until } if now >= until => {
                Step::Stop(ground.request(now, &Request::Lbc(Command::Stop)))
            }
            Step::Stop(h) => match ground.answer(h) {
                Some(r) => {
                    expect_echo(&r, Command::Stop);
                    Step::Tail {
                        until: now + TAIL_US,
                    }
                }
                None => Step::Stop(h),
            },
            Step::Tail { until } if now >= until => Step::Done,
            s => s,
        };
        matches!(self.step, Step::Done)
    }
}

fn expect_echo(reply: &Reply, cmd: Command) {
    assert!(
        matches!(reply, Reply::Lbc(LbcOutcome::Answer(LbcReply::Echo(c))) if *c == cmd),
        "{cmd:?} answered {reply:?}"
    );
}

fn soc_log(elf_path: &std::path::Path) -> Vec<u8> {
    let elf = std::fs::read(elf_path).expect("VTB_FIRMWARE is readable");
    let format = LogFormat::from_elf_bytes(&elf, elf_path).expect("defmt table");
    let mut soc = Soc::new();
    soc.load_elf(&elf).expect("a softcore image");
    let ground = Rc::new(RefCell::new(Ground::new(CAR, true)));
    let mut cosim = LbcCosim::new(soc, lbc()).with_radio(Box::new(GroundPeer(Rc::clone(&ground))));
    let mut decoder = LineDecoder::new(&format);
    let mut lines = Vec::new();
    let mut sent = Vec::new();
    let mut up = false;
    let mut session = Session::new();
    let step = u64::from(CLOCK_HZ) / 1000;
    while !session.advance(cosim.now_us(), up, &mut ground.borrow_mut()) {
        assert!(
            cosim.now_us() < MAX_SOC_SESSION_US,
            "the session did not end on the SoC (at {:?}): {lines:#?}",
            session.step
        );
        for e in cosim.run(step) {
            match e.value {
                Event::Tx {
                    uart: Uart::Lbc,
                    byte,
                } => sent.push(byte),
                Event::Console(b) => decoder.push(&[b], Instant::now(), &mut lines),
                Event::Exit(x) => panic!("firmware exited: {x:?}\n{lines:#?}"),
                Event::Tx { .. } => {}
            }
        }
        up = up || lines.iter().any(|l| l.is(Level::Info, "lbc up"));
    }
    sent
}

fn qemu_log(elf_path: &std::path::Path) -> Vec<u8> {
    let mut qemu = Qemu::builder(elf_path)
        .lbc(UartAttach::Harness)
        .radio(UartAttach::Harness)
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start QEMU: {e}"));
    let mut uart = qemu.take_lbc().expect("harness LBC uart");
    let mut radio = qemu.take_radio().expect("harness radio uart");
    let mut lbc = lbc();
    let mut ground = Ground::new(CAR, true);
    let mut session = Session::new();
    let start = Instant::now();
    let mut sent = Vec::new();
    let mut up = false;
    let mut buf = [0u8; 1024];
    let mut out = Vec::new();
    loop {
        let now = start.elapsed().as_micros() as u64;
        if session.advance(now, up, &mut ground) {
            break;
        }
        let limit = if up { MAX_QEMU_SESSION } else { MAX_BRINGUP };
        assert!(
            start.elapsed() < limit,
            "the session did not end on QEMU (at {:?}): {:#?}",
            session.step,
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

        let heard = radio.drain().unwrap_or_else(|e| panic!("radio uart: {e}"));
        ground.receive(now, &heard);
        out.clear();
        ground.advance(now, &mut out);
        radio.write_all(&out).expect("radio uart write");

        up = up
            || qemu
                .log()
                .lines()
                .iter()
                .any(|l| l.is(Level::Info, "lbc up"));
    }
    let _ = qemu.kill();
    sent
}

/// Every complete frame in `bytes`, decoded as a command (or why it is not one).
fn decoded(bytes: &[u8]) -> Vec<Result<Command, String>> {
    let mut d = Deframer::new();
    let mut out = Vec::new();
    for &b in bytes {
        match d.push(b) {
            None => {}
            Some(Ok(m)) => out.push(Command::parse(&m).map_err(|e| format!("unparsed {e:?}"))),
            Some(Err(e)) => out.push(Err(format!("bad frame {e:?}"))),
        }
    }
    out
}

fn frames(bytes: &[u8]) -> Vec<String> {
    decoded(bytes)
        .into_iter()
        .map(|f| match f {
            Ok(c) => format!("{c:?}"),
            Err(e) => e,
        })
        .collect()
}

/// The log holds the MOVE_XY frame byte for byte and, after it, a STOP.
fn assert_session_commands(board: &str, log: &[u8]) {
    let mut frame = [0u8; 16];
    let n = Command::MoveXy(target()).emit(&mut frame).expect("fits");
    assert!(
        log.windows(n).any(|w| w == &frame[..n]),
        "{board}: no MOVE_XY frame {:02x?} in the LBC log {:#?}",
        &frame[..n],
        frames(log)
    );
    let cmds = decoded(log);
    let moved = cmds
        .iter()
        .position(|c| *c == Ok(Command::MoveXy(target())))
        .unwrap_or_else(|| panic!("{board}: no MOVE_XY decoded: {:#?}", frames(log)));
    assert!(
        cmds[moved..].contains(&Ok(Command::Stop)),
        "{board}: no STOP after the MOVE_XY: {:#?}",
        frames(log)
    );
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
    assert_session_commands("SoC", &on_soc);
    assert_session_commands("QEMU", &on_qemu);
    if on_qemu != on_soc {
        // A retransmission (the same command again after a 50 ms reply timeout) is timing:
        // QEMU shares the machine with other work. Anything else is a real difference.
        // The LED that shows "ground station heard" goes out when the station's session
        // opens, which is timing too: LED commands are compared as a set, the rest in order.
        let (mut q, mut s) = (frames(&on_qemu), frames(&on_soc));
        q.dedup();
        s.dedup();
        let leds = |v: &[String]| {
            let mut l: Vec<String> = v
                .iter()
                .filter(|c| c.starts_with("WritLed"))
                .cloned()
                .collect();
            l.sort();
            l
        };
        assert_eq!(leds(&q), leds(&s), "LED commands differ");
        q.retain(|c| !c.starts_with("WritLed"));
        s.retain(|c| !c.starts_with("WritLed"));
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
