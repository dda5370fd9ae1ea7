//! The `softcore` build of the firmware (path in `VTB_FIRMWARE`) on the SoC, co-simulated with
//! the emulated LBC on UART0 and a radio-mac ground station on UART1: it boots, brings the LBC
//! up, carries out a MOVE_XY the ground station sends as a console request, and keeps decoding
//! the LBC's stream frames while the car drives, and finds the marker in a frame the harness
//! writes into the frame-grabber window and streams through the SoC's vision unit (the firmware
//! takes the unit's runs where there is one). Every retired instruction is checked against
//! the golden model (lockstep) on the way. Without `VTB_FIRMWARE` the tests say so and do
//! nothing (the image is built by `cargo xtask fw --board softcore`).
mod ground;

use ground::{Ground, GroundPeer};
use lbc_emu::{Lbc, LbcConfig};
use lbc_link::{Command, Position, Reply as LbcReply};
use qemu_harness::{Level, LineDecoder, LogFormat, LogLine};
use std::cell::RefCell;
use std::rc::Rc;
use std::time::Instant;
use ubc_app::program::console::{LbcOutcome, Reply, Request, Status};
use verilator_tb::cosim::LbcCosim;
use verilator_tb::lockstep::Checker;
use verilator_tb::soc::{CoreVariant, Event, Soc, Uart, CLOCK_HZ};

const CAR: u8 = 3;
/// 10 ms of SoC clock.
const TEN_MS: u64 = CLOCK_HZ as u64 / 100;

struct Rig {
    cosim: LbcCosim,
    format: LogFormat,
    console: Vec<u8>,
    lbc_bytes: Vec<u8>,
    ground: Rc<RefCell<Ground>>,
}

impl Rig {
    fn boot() -> Option<Self> {
        Self::boot_on(CoreVariant::Dsp)
    }

    /// The firmware on the SoC with the core `core`.
    fn boot_on(core: CoreVariant) -> Option<Self> {
        let Some(path) = std::env::var_os("VTB_FIRMWARE") else {
            eprintln!("VTB_FIRMWARE not set: skipping the firmware test");
            return None;
        };
        let path = std::path::PathBuf::from(path);
        let elf = std::fs::read(&path).expect("VTB_FIRMWARE is readable");
        let format = LogFormat::from_elf_bytes(&elf, &path).expect("defmt table");
        let mut soc = Soc::with_core(core);
        soc.load_elf(&elf).expect("a softcore image");
        let ground = Rc::new(RefCell::new(Ground::new(CAR, false)));
        let peer = GroundPeer(Rc::clone(&ground));
        let mut checker = Checker::with_core(core);
        checker.load_elf(&elf).expect("a softcore image");
        let cosim = LbcCosim::new(soc, Lbc::with_memory_eeprom(LbcConfig::default(), CAR))
            .with_radio(Box::new(peer))
            .with_checker(checker);
        Some(Self {
            cosim,
            format,
            console: Vec::new(),
            lbc_bytes: Vec::new(),
            ground,
        })
    }

    fn run(&mut self, cycles: u64) {
        let events = self.cosim.run(cycles);
        if let Some(m) = self.cosim.mismatch() {
            panic!(
                "lockstep mismatch after {} instructions: {m:x?}",
                self.cosim.checked()
            );
        }
        for e in events {
            match e.value {
                Event::Console(b) => self.console.push(b),
                Event::Tx {
                    uart: Uart::Lbc,
                    byte,
                } => self.lbc_bytes.push(byte),
                Event::Exit(x) => panic!("firmware exited: {x:?}\n{:#?}", self.lines()),
                Event::Tx { .. } => {}
            }
        }
    }

    fn lines(&self) -> Vec<LogLine> {
        let mut decoder = LineDecoder::new(&self.format);
        let mut lines = Vec::new();
        decoder.push(&self.console, Instant::now(), &mut lines);
        lines
    }

    /// Runs in 10 ms steps until `done` or `max_ms` simulated milliseconds have passed.
    fn run_until(&mut self, max_ms: u64, mut done: impl FnMut(&mut Self) -> bool) -> bool {
        for _ in 0..max_ms / 10 {
            if done(self) {
                return true;
            }
            self.run(TEN_MS);
        }
        done(self)
    }

    fn lbc_up(&mut self) {
        let up = self.run_until(2_000, |r| {
            r.lines().iter().any(|l| l.is(Level::Info, "lbc up"))
        });
        let lines = self.lines();
        assert!(
            lines.iter().any(|l| l.is(Level::Info, "board=softcore")),
            "no banner: {lines:#?}"
        );
        assert!(up, "{lines:#?}");
        assert!(
            lines
                .iter()
                .any(|l| l.is(Level::Info, &format!("lbc up: car={CAR}"))),
            "{lines:#?}"
        );
    }

    /// Sends a console request from the ground station and runs until the reply.
    fn request(&mut self, req: &Request) -> Reply {
        let now = self.cosim.now_us();
        let h = self.ground.borrow_mut().request(now, req);
        let mut reply = None;
        self.run_until(3_000, |r| {
            reply = r.ground.borrow_mut().answer(h);
            reply.is_some()
        });
        reply.unwrap_or_else(|| panic!("no reply to {req:?}: {:#?}", self.lines()))
    }

    fn status(&mut self) -> Status {
        match self.request(&Request::Status) {
            Reply::Status(s) => s,
            other => panic!("status: {other:?}"),
        }
    }
}

#[test]
fn softcore_firmware_boots_and_brings_up_the_lbc() {
    let Some(mut rig) = Rig::boot() else { return };
    rig.lbc_up();
    assert!(rig.cosim.lbc.streaming());
    assert!(rig.cosim.lbc.drive_enabled());
}

#[test]
fn softcore_firmware_moves_the_car_on_a_console_request() {
    moves_the_car(CoreVariant::Dsp);
}

#[test]
fn softcore_firmware_moves_the_car_on_the_pipelined_core() {
    moves_the_car(CoreVariant::Pipe);
}

/// The HX8K's core: pipelined, products in the sequential multiplier (the idle loop's time
/// conversions multiply).
#[test]
fn softcore_firmware_moves_the_car_on_the_hx8k_core() {
    moves_the_car(CoreVariant::PipeMulSeq);
}

fn moves_the_car(core: CoreVariant) {
    let Some(mut rig) = Rig::boot_on(core) else {
        return;
    };
    rig.lbc_up();
    // a few 30 Hz stream frames
    rig.run(CLOCK_HZ as u64 / 5);
    let start = rig.status();
    assert_eq!(start.car_id, CAR);
    assert_eq!((start.x, start.y), (300, 400), "start pose from the stream");

    let target = Position::new(320, 480).expect("in range");
    let sent_before = rig.lbc_bytes.len();
    let reply = rig.request(&Request::Lbc(Command::MoveXy(target)));
    assert!(
        matches!(
            reply,
            Reply::Lbc(LbcOutcome::Answer(LbcReply::Echo(Command::MoveXy(p)))) if p == target
        ),
        "{reply:?}"
    );
    // the MOVE_XY frame is in the byte log of the LBC link
    let mut frame = [0u8; 16];
    let n = Command::MoveXy(target).emit(&mut frame).expect("fits");
    assert!(
        rig.lbc_bytes[sent_before..]
            .windows(n)
            .any(|w| w == &frame[..n]),
        "no MOVE_XY frame among {:02x?}",
        &rig.lbc_bytes[sent_before..]
    );
    // the emulated car drives towards the target and the firmware follows it on the stream
    let pose0 = rig.cosim.lbc.vehicle().pose();
    rig.run(CLOCK_HZ as u64 / 2);
    let pose1 = rig.cosim.lbc.vehicle().pose();
    assert_ne!(
        (pose0.x_mm, pose0.y_mm),
        (pose1.x_mm, pose1.y_mm),
        "the car moved"
    );
    let now = rig.status();
    assert!(now.y > start.y, "status follows the stream: {now:?}");
    assert!(now.stream_age_ms < 100, "{now:?}");
    // every instruction of the session matched the golden model
    assert!(rig.cosim.checked() > 100_000, "{}", rig.cosim.checked());
    eprintln!(
        "{} instructions checked in {} cycles, no mismatch",
        rig.cosim.checked(),
        rig.cosim.soc.cycle()
    );
}

#[test]
fn softcore_firmware_sees_a_marker_in_the_frame_window() {
    use ubc_app::program::console::CameraReport;
    use verilator_tb::soc::{CameraTiming, FRAME_WINDOW_LEN};
    use vision::colour::{Rgb, MARKER_PALETTE};
    use vision::frame::{FrameWindow, PixelFormat};
    let Some(mut rig) = Rig::boot() else { return };
    rig.lbc_up();
    // a grey 640x480 RGB332 frame with a blue (car 2's colour) 40x60 rectangle
    let mut window = FrameWindow::init(vec![0u8; FRAME_WINDOW_LEN], 640, 480, PixelFormat::Rgb332)
        .expect("window layout");
    let index = window.begin_write();
    let grey = Rgb::new(128, 128, 128).to_rgb332();
    let blue = MARKER_PALETTE[2].to_rgb332();
    for (k, px) in window.buffer_mut(index).iter_mut().enumerate() {
        let (x, y) = (k % 640, k / 640);
        *px = if (300..340).contains(&x) && (200..260).contains(&y) {
            blue
        } else {
            grey
        };
    }
    window.publish(index, rig.cosim.now_us());
    let range = window.header().buffer_range(index);
    let bytes = window.into_inner();
    rig.cosim
        .soc
        .write_frame_window(0, &bytes)
        .expect("fits the window");
    // The camera streams the same frame twice: the unit, enabled by the firmware at boot,
    // starts at the end of the first and publishes the second as its frame 1.
    for _ in 0..2 {
        rig.cosim
            .soc
            .camera_frame_at(0, &bytes[range.clone()], 640, 480, CameraTiming::default())
            .expect("a VGA frame");
    }
    let mut report = None;
    rig.run_until(2_000, |r| {
        match r.request(&Request::Camera { blob: 0 }) {
            Reply::Camera(c) if c.sequence == 1 => report = Some(c),
            Reply::Camera(_) => {}
            other => panic!("camera: {other:?}"),
        }
        report.is_some()
    });
    let report: CameraReport =
        report.unwrap_or_else(|| panic!("frame 1 never processed: {:#?}", rig.lines()));
    assert_eq!(report.blobs, 1, "{report:?}");
    let (i, blob) = report.blob.expect("blob 0 reported");
    assert_eq!(i, 0);
    assert_eq!(
        blob.class,
        vision::colour::marker_class_for_car(2),
        "{blob:?}"
    );
    assert_eq!(blob.area, 40 * 60, "{blob:?}");
    assert_eq!(
        (blob.min_x, blob.min_y, blob.max_x, blob.max_y),
        (300, 200, 339, 259),
        "{blob:?}"
    );
}

/// Firmware instructions the long lockstep run checks at least.
const LONG_FIRMWARE_INSTRUCTIONS: u64 = 20_000_000;

/// The firmware half of `cargo xtask bench --only lockstep`: boot, bring the LBC up, then
/// publish frames (a marker moving across a grey 640x480 picture) and ask for each frame's
/// camera report until at least `LONG_FIRMWARE_INSTRUCTIONS` instructions have been checked
/// against the golden model. Prints the `figures:` line the benchmark reads.
#[test]
#[ignore = "long: run by cargo xtask bench --only lockstep"]
fn firmware_in_lockstep_long() {
    use verilator_tb::soc::{CameraTiming, FRAME_WINDOW_LEN};
    use vision::colour::{Rgb, MARKER_PALETTE};
    use vision::frame::{FrameWindow, PixelFormat};
    let Some(mut rig) = Rig::boot() else {
        println!("figures: mode=lockstep-firmware instructions=0 cycles=0 mismatches=0 wall_s=0");
        return;
    };
    let start = Instant::now();
    rig.lbc_up();
    let grey = Rgb::new(128, 128, 128).to_rgb332();
    let blue = MARKER_PALETTE[2].to_rgb332();
    let mut window = FrameWindow::init(vec![0u8; FRAME_WINDOW_LEN], 640, 480, PixelFormat::Rgb332)
        .expect("window layout");
    let mut frames = 0u32;
    // The vision unit starts at the end of a frame after the firmware enables it: one frame
    // to start it, then each frame is published as the unit's next.
    let grey_frame = vec![grey; 640 * 480];
    rig.cosim
        .soc
        .camera_frame_at(0, &grey_frame, 640, 480, CameraTiming::default())
        .expect("a VGA frame");
    while rig.cosim.checked() < LONG_FIRMWARE_INSTRUCTIONS {
        let index = window.begin_write();
        let x0 = 20 + (frames as usize * 37) % 560;
        for (k, px) in window.buffer_mut(index).iter_mut().enumerate() {
            let (x, y) = (k % 640, k / 640);
            let inside = (x0..x0 + 40).contains(&x) && (200..260).contains(&y);
            *px = if inside { blue } else { grey };
        }
        window.publish(index, rig.cosim.now_us());
        let range = window.header().buffer_range(index);
        let bytes = window.into_inner();
        rig.cosim
            .soc
            .write_frame_window(0, &bytes)
            .expect("fits the window");
        rig.cosim
            .soc
            .camera_frame_at(0, &bytes[range], 640, 480, CameraTiming::default())
            .expect("a VGA frame");
        window = FrameWindow::new_checked(bytes).expect("a published window");
        let seq = frames + 1;
        let mut done = false;
        rig.run_until(5_000, |r| {
            match r.request(&Request::Camera { blob: 0 }) {
                Reply::Camera(c) => done = c.sequence == seq,
                other => panic!("camera: {other:?}"),
            }
            done
        });
        assert!(done, "frame {seq} never processed");
        frames += 1;
    }
    let wall = start.elapsed().as_secs_f64();
    let (checked, cycles) = (rig.cosim.checked(), rig.cosim.soc.cycle());
    println!(
        "firmware: {checked} instructions in {cycles} cycles ({frames} frames), no mismatch, {wall:.0} s"
    );
    println!(
        "figures: mode=lockstep-firmware instructions={checked} cycles={cycles} frames={frames} mismatches=0 wall_s={wall:.3}"
    );
}
