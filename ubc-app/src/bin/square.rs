//! `square`: an upper-board program, made by `cargo xtask new-program` from
//! `ubc-app/src/bin/template.rs` (`docs/writing-a-program.md` walks through it). The stock
//! program does everything else: it brings the LBC up, keeps the car's pose from the 30 Hz
//! stream, serves the console over the radio (status, LBC commands, maneuvers) and stops the
//! car when a link is lost. What is here is the loop it runs at every stream sample once the
//! ground station starts it:
//!
//! ```sh
//! cargo xtask fw --board qemu_virt --bin square     # build (prints the ELF path)
//! almc car --radio unix:PATH program start 160      # a square of 160 units (400 mm)
//! ```
//!
//! The car drives a square counter-clockwise, starting where it stands and along its heading:
//! to each corner in turn with the LBC's own path generator (`MOVE_XY`), and finishes back
//! at the start. The argument is the side in tracking units (default 160, 40..=400).

#![no_std]
#![no_main]
#![forbid(unsafe_code)]

use maneuvers::{imath, CarPose, Command};
use ubc_app::program::user::{ProgramInput, Step, UserProgram};

/// Within this distance of a corner the car drives on to the next, tracking units (30 mm; the
/// LBC stops within 8 units of a `MOVE_XY` point).
const REACHED_UNITS: u32 = 12;
/// Side without an argument, tracking units (400 mm).
const DEFAULT_SIDE: i32 = 160;

/// The program's state between samples.
struct Square {
    /// Side, tracking units.
    side: i32,
    /// The corners in driving order, the last one the start (known after the first sample).
    corners: Option<[(u16, u16); 4]>,
    /// The corner driven to.
    next: usize,
}

/// The corners of a counter-clockwise square of `side` units from `start` along its heading.
fn corners(start: CarPose, side: i32) -> [(u16, u16); 4] {
    let (sin, cos) = imath::sin_cos_mrad(i32::from(start.heading_mrad));
    // Forward and left, tracking units (the sines are Q14: 1 << 14 = 1.0).
    let (fx, fy) = ((side * cos) >> 14, (side * sin) >> 14);
    let (lx, ly) = (-fy, fx);
    let (x0, y0) = (i32::from(start.x), i32::from(start.y));
    // Inside what MOVE_XY takes.
    let at = |x: i32, y: i32| (x.clamp(0, 640) as u16, y.clamp(0, 960) as u16);
    [
        at(x0 + fx, y0 + fy),
        at(x0 + fx + lx, y0 + fy + ly),
        at(x0 + lx, y0 + ly),
        at(x0, y0),
    ]
}

impl UserProgram for Square {
    fn start(&mut self, _now_us: u64, args: &[i16]) {
        self.side = args
            .first()
            .map_or(DEFAULT_SIDE, |&a| i32::from(a).clamp(40, 400));
        self.corners = None;
        self.next = 0;
    }

    fn step(&mut self, input: &ProgramInput<'_>) -> Step {
        let corners = *self
            .corners
            .get_or_insert_with(|| corners(input.own, self.side));
        let Some(&(x, y)) = corners.get(self.next) else {
            return Step::Done;
        };
        let dx = i32::from(x) - i32::from(input.own.x);
        let dy = i32::from(y) - i32::from(input.own.y);
        if imath::hypot(dx, dy) > REACHED_UNITS {
            return Step::Drive(Command::MoveXy { x, y });
        }
        self.next += 1;
        match corners.get(self.next) {
            Some(&(x, y)) => Step::Drive(Command::MoveXy { x, y }),
            None => Step::Done,
        }
    }

    fn progress(&self) -> (u8, u8) {
        (self.next as u8, 4)
    }
}

#[riscv_rt::entry]
fn main() -> ! {
    ubc_app::firmware::start(Square {
        side: DEFAULT_SIDE,
        corners: None,
        next: 0,
    })
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    ubc_app::firmware::panic(info)
}
