//! `softcore`: the in-house RV32IMAC SoC of `verilator-tb`. Same register layouts as qemu virt
//! (16550 UARTs, CLINT, PLIC, SiFive-style exit register), so the drivers are shared; only the
//! addresses and clocks below differ. The LBC link is UART0, the radio UART1 (no PCI), and
//! defmt frames leave through the simulation-control console register (feature
//! `console-logger`), which the test bench decodes with the image's defmt table.

use crate::clint::Clint;
use crate::exit::TestDevice;
use crate::framegrabber::{FrameGrabber, MmioWindow};
use crate::mmio::Mmio;
use crate::plic::Plic;
use crate::serial::{FrameStamping, OpenError, Port, PortState};
use crate::uart::{Config, Ns16550};
use crate::vision_unit::VisionUnit;
use core::sync::atomic::{AtomicBool, Ordering};

/// Board name, as used by `cargo xtask fw --board`.
pub const NAME: &str = "softcore";
/// Core clock of the SoC; the UARTs run from it (divisor 8 at 115200 baud).
pub const CLOCK_HZ: u32 = 14_745_600;
/// `mtime` counts core clock cycles.
pub const TIMEBASE_HZ: u32 = CLOCK_HZ;

/// Physical addresses used on this board.
pub mod map {
    /// Simulation control: exit register (SiFive test finisher values).
    pub const SIM_CTRL: usize = 0x0010_0000;
    /// Simulation control: console byte register (low 8 bits of a write).
    pub const CONSOLE: usize = 0x0010_0004;
    /// CLINT (msip, mtimecmp, mtime).
    pub const CLINT: usize = 0x0200_0000;
    /// PLIC (sources 1..=15, one context).
    pub const PLIC: usize = 0x0C00_0000;
    /// UART0: LBC link.
    pub const UART0: usize = 0x1000_0000;
    /// UART1: radio.
    pub const UART1: usize = 0x1000_1000;
    /// Start of RAM (1 MiB; see `boards/softcore/memory.x`).
    pub const RAM: usize = 0x8000_0000;
    /// Frame-grabber window (`vision::frame::WINDOW_LEN` bytes): the SoC's frame memory,
    /// written by the test bench.
    pub const FRAME_GRABBER: usize = 0x8100_0000;
    /// The vision unit (`vision::run_window` layout, 64 KiB region).
    pub const VISION: usize = 0x8113_0000;
}

/// PLIC interrupt sources.
pub mod irq {
    /// UART0 (LBC).
    pub const UART0: u32 = 10;
    /// UART1 (radio).
    pub const UART1: u32 = 11;
    /// The vision unit's end of frame.
    pub const VISION: u32 = 12;
}

/// PLIC priority of both UARTs (any nonzero value above the threshold 0 interrupts).
const UART_PRIORITY: u8 = 1;
/// PLIC context of hart 0 in machine mode.
const PLIC_CONTEXT_M0: usize = 0;

/// Exit status used when a CPU exception ends the run.
pub const EXIT_EXCEPTION: u16 = 2;

/// A UART port of this board.
pub type Uart = Port<Mmio>;
/// The clock of this board.
pub type Clock = Clint<Mmio>;
/// The camera's frame grabber on this board.
pub type Camera = FrameGrabber<MmioWindow>;
/// The vision unit on this board.
pub type Vision = VisionUnit<Mmio, MmioWindow>;

static LBC_PORT: PortState<Mmio> = PortState::new();
static RADIO_PORT: PortState<Mmio> = PortState::new();
static TAKEN: AtomicBool = AtomicBool::new(false);

/// Why the board cannot be brought up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum BoardError {
    /// [`Board::take`] was called before.
    AlreadyTaken,
    /// The LBC UART could not be opened.
    Lbc(OpenError),
}

/// Why the radio UART is missing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum RadioError {
    /// The UART could not be opened.
    Open(OpenError),
}

/// Where the radio UART sits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RadioInfo {
    /// Register base address.
    pub base: usize,
    /// Its PLIC source number.
    pub plic_source: u32,
}

/// Everything the board hands out.
#[derive(Debug)]
#[non_exhaustive]
pub struct Board {
    /// Link to the lower board (UART0, PLIC source 10).
    pub lbc: Uart,
    /// The radio (UART1, PLIC source 11).
    pub radio: Result<Uart, RadioError>,
    /// Where the radio sits, when it opened.
    pub radio_info: Option<RadioInfo>,
    /// CLINT time and wakeups.
    pub clock: Clock,
    /// Exit device.
    pub exit: TestDevice<Mmio>,
    /// The interrupt controller (hart 0, machine mode), already routing both UARTs.
    pub plic: Plic<Mmio>,
    /// Reader of the camera's frame-grabber window at [`map::FRAME_GRABBER`].
    pub camera: Camera,
    /// The vision unit at [`map::VISION`], when the SoC has one; its end-of-frame interrupt
    /// is routed (the handler clears it, so it only wakes the program).
    pub vision: Option<Vision>,
}

/// The CLINT. Reading time is harmless from anywhere (e.g. log timestamps).
pub fn clock() -> Clock {
    const RATE: crate::clint::Rate = crate::clint::Rate::of(TIMEBASE_HZ);
    // SAFETY: the CLINT's register block on the softcore SoC.
    Clint::with_rate(unsafe { Mmio::new(map::CLINT) }, RATE)
}

/// The low word of the timer, for the serial ports' frame stamps (one register read).
fn timer_lo() -> u32 {
    // SAFETY: the CLINT's register block on this board.
    crate::mmio::RegisterBus::read32(&unsafe { Mmio::new(map::CLINT) }, crate::clint::reg::MTIME)
}

/// How a port of this board stamps the frames that `delimiter` ends on its 115200 baud line
/// (see [`Port::stamp_frames`]).
pub fn frame_stamping(delimiter: u8) -> FrameStamping {
    FrameStamping {
        delimiter,
        now: timer_lo,
        // 10 bits a character.
        char_ticks: TIMEBASE_HZ / (crate::uart::Config::default().baud / 10),
    }
}

/// The exit device, for panic and fault paths that own nothing.
pub fn exit_device() -> TestDevice<Mmio> {
    // SAFETY: the simulation-control exit register, which takes the SiFive test values.
    TestDevice::new(unsafe { Mmio::new(map::SIM_CTRL) })
}

/// A reader of the frame grabber's window (readers do not disturb each other or the writer).
pub fn camera() -> Camera {
    // SAFETY: the window is RAM (or frame memory) outside the image's region of the linker
    // script, 4 KiB aligned, written only by the camera side; no Rust object lives there.
    FrameGrabber::new(unsafe { MmioWindow::new(map::FRAME_GRABBER, vision::frame::WINDOW_LEN) })
}

/// The vision unit, if the SoC has one.
pub fn vision_unit() -> Option<Vision> {
    let len = vision::run_window::WINDOW_LEN;
    // SAFETY: the vision unit's register block and run buffers on the softcore SoC (reads of
    // a missing unit's region return zero, so the probe fails); the buffers are written only
    // by the unit.
    let (regs, memory) = unsafe { (Mmio::new(map::VISION), MmioWindow::new(map::VISION, len)) };
    VisionUnit::probe(regs, memory)
}

/// Clears the vision unit's end-of-frame flag (its interrupt).
fn vision_acknowledge() {
    // SAFETY: the vision unit's status register on the softcore SoC; writing 1 to its bit 0
    // only clears the flag.
    let regs = unsafe { Mmio::new(map::VISION) };
    crate::mmio::RegisterBus::write32(
        &regs,
        crate::vision_unit::reg::STATUS,
        vision::run_window::status::FRAME,
    );
}

fn plic() -> Plic<Mmio> {
    // SAFETY: the PLIC's register block on the softcore SoC.
    Plic::new(unsafe { Mmio::new(map::PLIC) }, PLIC_CONTEXT_M0)
}

impl Board {
    /// Brings the board up once: PLIC, both UARTs, and (with the `rt` feature on the target)
    /// external and timer interrupts.
    pub fn take() -> Result<Self, BoardError> {
        if TAKEN.swap(true, Ordering::AcqRel) {
            return Err(BoardError::AlreadyTaken);
        }
        let plic = plic();
        plic.set_threshold(0);
        let clock = clock();
        clock.clear_wakeup();

        // SAFETY: UART0's register block on the softcore SoC.
        let uart0 = Ns16550::new(unsafe { Mmio::new(map::UART0) });
        let lbc = LBC_PORT
            .open(uart0, &Config::with_clock(CLOCK_HZ))
            .map_err(BoardError::Lbc)?;
        plic.route(irq::UART0, UART_PRIORITY);

        // SAFETY: UART1's register block on the softcore SoC.
        let uart1 = Ns16550::new(unsafe { Mmio::new(map::UART1) });
        let (radio, radio_info) = match RADIO_PORT.open(uart1, &Config::with_clock(CLOCK_HZ)) {
            Ok(port) => {
                plic.route(irq::UART1, UART_PRIORITY);
                let info = RadioInfo {
                    base: map::UART1,
                    plic_source: irq::UART1,
                };
                (Ok(port), Some(info))
            }
            Err(e) => (Err(RadioError::Open(e)), None),
        };

        let vision = vision_unit();
        if vision.is_some() {
            plic.route(irq::VISION, UART_PRIORITY);
        }

        #[cfg(all(feature = "rt", target_arch = "riscv32"))]
        handlers::enable();

        Ok(Self {
            lbc,
            radio,
            radio_info,
            clock,
            exit: exit_device(),
            plic,
            camera: camera(),
            vision,
        })
    }
}

/// Serves every pending PLIC source (the machine external interrupt).
pub fn on_external_interrupt() {
    let plic = plic();
    while let Some(source) = plic.claim() {
        match source.number() {
            irq::UART0 => LBC_PORT.on_interrupt(),
            irq::UART1 => RADIO_PORT.on_interrupt(),
            irq::VISION => vision_acknowledge(),
            _ => {}
        }
        plic.complete(source);
    }
}

/// Serves the machine timer interrupt: it only ends an idle, so disarm it.
pub fn on_timer_interrupt() {
    clock().clear_wakeup();
}

#[cfg(all(feature = "console-logger", target_arch = "riscv32"))]
defmt::timestamp!("{=u64:us}", clock().micros());

/// Writes defmt frame bytes to the simulation-control console register; the board's
/// transport for the shared defmt logger (`logger.rs`).
#[cfg(all(feature = "console-logger", target_arch = "riscv32"))]
pub(crate) fn console_emit(bytes: &[u8]) {
    use crate::mmio::{Mmio, RegisterBus};
    // SAFETY: `map::CONSOLE` is the console register of the SoC's simulation-control device,
    // always mapped on this board; writing it has no effect beyond emitting the byte.
    let console = unsafe { Mmio::new(map::CONSOLE) };
    for &b in bytes {
        console.write32(0, u32::from(b));
    }
}

#[cfg(all(feature = "rt", target_arch = "riscv32"))]
mod handlers {
    use riscv::interrupt::machine::Interrupt;

    pub(super) fn enable() {
        crate::cpu::enable_interrupts();
    }

    #[riscv_rt::core_interrupt(Interrupt::MachineExternal)]
    fn machine_external() {
        super::on_external_interrupt();
    }

    #[riscv_rt::core_interrupt(Interrupt::MachineTimer)]
    fn machine_timer() {
        super::on_timer_interrupt();
    }

    /// Any CPU exception is a firmware bug: report it and end the run.
    #[export_name = "ExceptionHandler"]
    fn exception_handler(_frame: &riscv_rt::TrapFrame) -> ! {
        #[cfg(feature = "console-logger")]
        defmt::error!(
            "exception: mcause={=usize:#x} mepc={=usize:#x} mtval={=usize:#x}",
            riscv::register::mcause::read().bits(),
            riscv::register::mepc::read(),
            riscv::register::mtval::read()
        );
        super::exit_device().fail(super::EXIT_EXCEPTION)
    }

    /// An interrupt without a handler: report it and end the run.
    #[export_name = "DefaultHandler"]
    fn default_handler() -> ! {
        #[cfg(feature = "console-logger")]
        defmt::error!(
            "unexpected interrupt: mcause={=usize:#x}",
            riscv::register::mcause::read().bits()
        );
        super::exit_device().fail(super::EXIT_EXCEPTION)
    }
}
