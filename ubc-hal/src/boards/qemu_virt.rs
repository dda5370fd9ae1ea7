//! `qemu-system-riscv32 -M virt -bios none`: the board for running the firmware without
//! hardware. LBC link on the built-in NS16550A (UART0), radio on a `pci-serial` card that
//! this module finds and places in PCI I/O space itself, CLINT time, PLIC interrupts, the
//! SiFive test device for exit codes, and defmt logs over semihosting.
//!
//! Expected QEMU options: `-device pci-serial,chardev=ID` for the radio and
//! `-semihosting-config enable=on,target=native[,chardev=ID]` for the log.

use crate::clint::Clint;
use crate::exit::TestDevice;
use crate::framegrabber::{FrameGrabber, MmioWindow};
use crate::mmio::Mmio;
use crate::pci::{Ecam, IoAllocator, IoDevice, IoWindow, PciError};
use crate::plic::Plic;
use crate::serial::{FrameStamping, OpenError, Port, PortState};
use crate::uart::{Config, Ns16550};
use crate::vision_unit::VisionUnit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// Board name, as used by `cargo xtask fw --board`.
pub const NAME: &str = "qemu_virt";
/// `mtime` rate of qemu virt's CLINT.
pub const TIMEBASE_HZ: u32 = 10_000_000;

/// Physical addresses used on this board.
pub mod map {
    /// SiFive test device (exit/reset).
    pub const TEST: usize = 0x0010_0000;
    /// CLINT (mtimecmp, mtime).
    pub const CLINT: usize = 0x0200_0000;
    /// CPU address of PCI I/O address 0.
    pub const PCI_IO: usize = 0x0300_0000;
    /// Size of the PCI I/O window.
    pub const PCI_IO_SIZE: u32 = 0x1_0000;
    /// PLIC.
    pub const PLIC: usize = 0x0C00_0000;
    /// UART0 (NS16550A).
    pub const UART0: usize = 0x1000_0000;
    /// PCI ECAM configuration window (the 32-bit machine's base).
    pub const PCI_ECAM: usize = 0x3000_0000;
    /// Start of RAM (the image is linked here, see `boards/qemu_virt/memory.x`).
    pub const RAM: usize = 0x8000_0000;
    /// Frame-grabber window (`vision::frame::WINDOW_LEN` bytes): RAM past the image's 16 MiB,
    /// which QEMU backs with a shared file the host writes (`-m 32M`, see qemu-harness).
    pub const FRAME_GRABBER: usize = 0x8100_0000;
    /// The vision unit's run window (`vision::run_window::WINDOW_LEN` bytes): RAM the host
    /// writes like the SoC's vision unit when it computes runs for the camera (qemu virt has no
    /// such device; the firmware finds it by its ID, `docs/camera.md`).
    pub const VISION: usize = 0x8113_0000;
}

/// PLIC interrupt sources.
pub mod irq {
    /// UART0.
    pub const UART0: u32 = 10;
    /// PCI INTA..INTD arrive on these four sources after the host bridge's rotation.
    pub const PCI_INTX_BASE: u32 = 32;
}

/// UART0's input clock (device tree `clock-frequency`).
pub const UART0_CLOCK_HZ: u32 = 3_686_400;
/// The `pci-serial` card's 16550 input clock (QEMU models a 115200 baud base).
pub const PCI_SERIAL_CLOCK_HZ: u32 = 1_843_200;
/// PCI vendor and device ID of QEMU's `pci-serial`.
pub const PCI_SERIAL_ID: (u16, u16) = (0x1b36, 0x0002);
/// First PCI I/O address handed out (low addresses stay free, as on PCs).
const PCI_IO_FIRST: u32 = 0x1000;
/// PLIC priority of both UARTs (any nonzero value above the threshold 0 interrupts).
const UART_PRIORITY: u8 = 1;
/// PLIC context of hart 0 in machine mode.
const PLIC_CONTEXT_M0: usize = 0;

/// Exit status used when a CPU exception ends the run.
pub const EXIT_EXCEPTION: u16 = 2;
/// Exit status used when a semihosting call traps (QEMU started without semihosting).
pub const EXIT_NO_SEMIHOSTING: u16 = 3;

/// A UART port of this board.
pub type Uart = Port<Mmio>;
/// The clock of this board.
pub type Clock = Clint<Mmio>;
/// The camera's frame grabber on this board.
pub type Camera = FrameGrabber<MmioWindow>;
/// The vision unit's reader on this board (the host's run window in RAM).
pub type Vision = VisionUnit<Mmio, MmioWindow>;

static LBC_PORT: PortState<Mmio> = PortState::new();
static RADIO_PORT: PortState<Mmio> = PortState::new();
/// PLIC source of the radio card (0 until it is set up).
static RADIO_SOURCE: AtomicU32 = AtomicU32::new(0);
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
    /// No usable `pci-serial` card (QEMU started without `-device pci-serial`?).
    Pci(PciError),
    /// The card's UART could not be opened.
    Open(OpenError),
}

/// Where the radio card was placed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RadioInfo {
    /// The PCI placement.
    pub device: IoDevice,
    /// Its PLIC source number.
    pub plic_source: u32,
}

/// Everything the board hands out.
#[derive(Debug)]
#[non_exhaustive]
pub struct Board {
    /// Link to the lower board (UART0, PLIC source 10).
    pub lbc: Uart,
    /// The radio (`pci-serial`), or why there is none.
    pub radio: Result<Uart, RadioError>,
    /// Where the radio card sits, when it was found.
    pub radio_info: Option<RadioInfo>,
    /// CLINT time and wakeups.
    pub clock: Clock,
    /// Exit device.
    pub exit: TestDevice<Mmio>,
    /// The interrupt controller (hart 0, machine mode), already routing both UARTs. The
    /// external interrupt handler claims and completes through its own accessor.
    pub plic: Plic<Mmio>,
    /// Reader of the camera's frame-grabber window at [`map::FRAME_GRABBER`].
    pub camera: Camera,
    /// The run window at [`map::VISION`], when the host writes one.
    pub vision: Option<Vision>,
}

/// The CLINT. Reading time is harmless from anywhere (e.g. log timestamps).
pub fn clock() -> Clock {
    const RATE: crate::clint::Rate = crate::clint::Rate::of(TIMEBASE_HZ);
    // SAFETY: the CLINT's register block on qemu virt.
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
    // SAFETY: the SiFive test device's register on qemu virt.
    TestDevice::new(unsafe { Mmio::new(map::TEST) })
}

/// A reader of the frame grabber's window (readers do not disturb each other or the writer).
pub fn camera() -> Camera {
    // SAFETY: the window is RAM (or frame memory) outside the image's region of the linker
    // script, 4 KiB aligned, written only by the camera side; no Rust object lives there.
    FrameGrabber::new(unsafe { MmioWindow::new(map::FRAME_GRABBER, vision::frame::WINDOW_LEN) })
}

fn plic() -> Plic<Mmio> {
    // SAFETY: the PLIC's register block on qemu virt.
    Plic::new(unsafe { Mmio::new(map::PLIC) }, PLIC_CONTEXT_M0)
}

fn ecam() -> Ecam<Mmio> {
    // SAFETY: the PCIe ECAM window of the 32-bit virt machine (bus 0 is all we touch).
    Ecam::new(unsafe { Mmio::new(map::PCI_ECAM) })
}

impl Board {
    /// Brings the board up once: PLIC, UART0, PCI enumeration and the radio card, and (with
    /// the `rt` feature on the target) enables external and timer interrupts.
    pub fn take() -> Result<Self, BoardError> {
        if TAKEN.swap(true, Ordering::AcqRel) {
            return Err(BoardError::AlreadyTaken);
        }
        let plic = plic();
        plic.set_threshold(0);
        let clock = clock();
        clock.clear_wakeup();

        // SAFETY: UART0's register block on qemu virt.
        let uart0 = Ns16550::new(unsafe { Mmio::new(map::UART0) });
        let lbc = LBC_PORT
            .open(uart0, &Config::with_clock(UART0_CLOCK_HZ))
            .map_err(BoardError::Lbc)?;
        plic.route(irq::UART0, UART_PRIORITY);

        let (radio, radio_info) = match open_radio() {
            Ok((port, info)) => {
                RADIO_SOURCE.store(info.plic_source, Ordering::Release);
                plic.route(info.plic_source, UART_PRIORITY);
                (Ok(port), Some(info))
            }
            Err(e) => (Err(e), None),
        };

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
            vision: vision_unit(),
        })
    }
}

/// The vision unit's run window, if the host writes one (it has no interrupt here: poll it).
pub fn vision_unit() -> Option<Vision> {
    let len = vision::run_window::WINDOW_LEN;
    // SAFETY: RAM outside the image's region of the linker script, 64 KiB aligned, written
    // only by the host (and the firmware's control words and class table through this
    // driver); no Rust object lives there.
    let (regs, memory) = unsafe { (Mmio::new(map::VISION), MmioWindow::new(map::VISION, len)) };
    VisionUnit::probe(regs, memory)
}

fn open_radio() -> Result<(Uart, RadioInfo), RadioError> {
    let mut io = IoAllocator::new(IoWindow {
        cpu_base: map::PCI_IO,
        start: PCI_IO_FIRST,
        end: map::PCI_IO_SIZE,
    });
    let device = ecam()
        .setup_io_device(PCI_SERIAL_ID.0, PCI_SERIAL_ID.1, 0, &mut io)
        .map_err(RadioError::Pci)?;
    let plic_source = irq::PCI_INTX_BASE + u32::from(device.pin.swizzle(device.bdf.device));
    // SAFETY: the card's BAR0 was just placed at this address of the PCI I/O window (device
    // space, never RAM) and its I/O decoding enabled. The 8 byte-wide 16550 registers lie
    // inside the mapped window even if the card decodes fewer: this is the window's first
    // allocation, so a BAR of 4 bytes sits at `PCI_IO_FIRST`, far from the window's end.
    let uart = Ns16550::new(unsafe { Mmio::new(device.cpu_address) });
    let port = RADIO_PORT
        .open(uart, &Config::with_clock(PCI_SERIAL_CLOCK_HZ))
        .map_err(RadioError::Open)?;
    Ok((
        port,
        RadioInfo {
            device,
            plic_source,
        },
    ))
}

/// Serves every pending PLIC source (the machine external interrupt).
pub fn on_external_interrupt() {
    let plic = plic();
    while let Some(source) = plic.claim() {
        let n = source.number();
        if n == irq::UART0 {
            LBC_PORT.on_interrupt();
        } else if n == RADIO_SOURCE.load(Ordering::Acquire) {
            RADIO_PORT.on_interrupt();
        }
        plic.complete(source);
    }
}

/// Serves the machine timer interrupt: it only ends an idle, so disarm it.
pub fn on_timer_interrupt() {
    clock().clear_wakeup();
}

#[cfg(all(feature = "logger", target_arch = "riscv32"))]
defmt::timestamp!("{=u64:us}", clock().micros());

#[cfg(all(feature = "rt", target_arch = "riscv32"))]
mod handlers {
    use riscv::interrupt::machine::{Exception, Interrupt};

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
        let mcause = riscv::register::mcause::read().bits();
        if mcause == Exception::Breakpoint as usize {
            // Most likely a semihosting call on a QEMU without semihosting: logging would
            // trap again.
            super::exit_device().fail(super::EXIT_NO_SEMIHOSTING);
        }
        #[cfg(feature = "logger")]
        defmt::error!(
            "exception: mcause={=usize:#x} mepc={=usize:#x} mtval={=usize:#x}",
            mcause,
            riscv::register::mepc::read(),
            riscv::register::mtval::read()
        );
        super::exit_device().fail(super::EXIT_EXCEPTION)
    }

    /// An interrupt without a handler: report it and end the run.
    #[export_name = "DefaultHandler"]
    fn default_handler() -> ! {
        #[cfg(feature = "logger")]
        defmt::error!(
            "unexpected interrupt: mcause={=usize:#x}",
            riscv::register::mcause::read().bits()
        );
        super::exit_device().fail(super::EXIT_EXCEPTION)
    }
}
