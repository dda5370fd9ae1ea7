//! `template`: an upper-board program, made by `cargo xtask new-program` from
//! `ubc-app/src/bin/template.rs` (`docs/writing-a-program.md` walks through one). The stock
//! program does everything else: it brings the LBC up, keeps the car's pose from the 30 Hz
//! stream, serves the console over the radio (status, LBC commands, maneuvers) and stops the
//! car when a link is lost. What is here is the loop it runs at every stream sample once the
//! ground station starts it:
//!
//! ```sh
//! cargo xtask fw --board qemu_virt --bin template     # build (prints the ELF path)
//! almc car --radio unix:PATH program start 300 500    # start it with two arguments
//! ```
//!
//! As it comes, the loop drives to the point given by its two arguments (tracking units) with
//! the LBC's own path generator, and finishes there. Replace it with yours.

#![no_std]
#![no_main]
#![forbid(unsafe_code)]

use maneuvers::{imath, Command};
use ubc_app::program::user::{ProgramInput, Step, UserProgram};

/// Within this distance of the point the program is done, tracking units (30 mm).
const ARRIVED_UNITS: u32 = 12;

/// The program's state between samples.
struct Template {
    /// Where to drive, tracking units.
    target: (u16, u16),
}

impl UserProgram for Template {
    fn start(&mut self, _now_us: u64, args: &[i16]) {
        // Arguments as the ground station sent them; keep the default when one is missing.
        let arg = |i: usize, default: u16| {
            args.get(i)
                .and_then(|&a| u16::try_from(a).ok())
                .unwrap_or(default)
        };
        self.target = (arg(0, 300), arg(1, 400));
    }

    fn step(&mut self, input: &ProgramInput<'_>) -> Step {
        let (x, y) = self.target;
        let dx = i32::from(x) - i32::from(input.own.x);
        let dy = i32::from(y) - i32::from(input.own.y);
        if imath::hypot(dx, dy) <= ARRIVED_UNITS {
            return Step::Done;
        }
        Step::Drive(Command::MoveXy { x, y })
    }
}

#[riscv_rt::entry]
fn main() -> ! {
    ubc_app::firmware::start(Template { target: (300, 400) })
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    ubc_app::firmware::panic(info)
}
