//! The vision unit: the SoC's pixel pipeline, which classifies the camera's pixels and writes
//! their runs into a buffer the firmware reads (`docs/hal.md`, "Vision unit"). The same
//! register block appears on QEMU as RAM the host writes (`docs/camera.md`), so this driver is
//! the reader on every board: [`VisionUnit::probe`] finds it by its ID, [`VisionUnit::load_classes`]
//! and [`VisionUnit::start`] set it up, and [`VisionUnit::with_latest`] hands out the newest
//! published run buffer in place, keeping the result only if the unit did not start writing
//! that buffer meanwhile (the frame grabber's ticket rule).
//!
//! Registers are reached through [`RegisterBus`] (control, status, class table) and the header
//! and buffers through [`WindowMemory`] (volatile header copies, the buffer in place); on the
//! boards both are the same addresses, in host tests a model.

use bitfield::bitfield;
use core::sync::atomic::{fence, Ordering};
use vision::colour::ColourClasses;
use vision::run_window::{Header, HeaderError, RunTicket, HEADER_LEN, LUT_OFFSET, MAGIC, VERSION};

use crate::framegrabber::WindowMemory;
use crate::mmio::RegisterBus;

/// Register offsets (bytes from the unit's base), as `vision::run_window::field`.
pub mod reg {
    /// Identification, `"ALRN"` (`0x4E52_4C41`).
    pub const ID: usize = 0x00;
    /// [`super::Version`].
    pub const VERSION: usize = 0x04;
    /// Words per run buffer.
    pub const CAPACITY: usize = 0x08;
    /// Offset of run buffer 0 (`0x4000`).
    pub const BUFFER0_OFFSET: usize = 0x0C;
    /// Offset of run buffer 1 (`0x8000`).
    pub const BUFFER1_OFFSET: usize = 0x10;
    /// Frames published (0: none yet).
    pub const SEQUENCE: usize = 0x14;
    /// The buffer holding frame `SEQUENCE`.
    pub const READY: usize = 0x18;
    /// Frame each buffer holds (`0xFFFF_FFFF` while written): buffer 0, then buffer 1.
    pub const BUFFER_SEQ0: usize = 0x1C;
    pub const BUFFER_SEQ1: usize = 0x20;
    /// Words in each buffer.
    pub const COUNT0: usize = 0x24;
    pub const COUNT1: usize = 0x28;
    /// Runs each buffer's frame could not hold.
    pub const DROPPED0: usize = 0x2C;
    pub const DROPPED1: usize = 0x30;
    /// [`super::Size`] of each buffer's frame.
    pub const SIZE0: usize = 0x34;
    pub const SIZE1: usize = 0x38;
    /// [`super::Ctrl`].
    pub const CTRL: usize = 0x40;
    /// [`super::Status`].
    pub const STATUS: usize = 0x44;
    /// Class table: the class (low 4 bits) of RGB332 code `c` is byte `c` (write only on the
    /// SoC, and only while [`super::Ctrl::enable`] is clear).
    pub const LUT: usize = 0x100;
}

bitfield! {
    /// Control register.
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Ctrl(u32);
    impl Debug;
    /// Process frames, from the end of the next frame on; clearing it stops at once.
    pub enable, set_enable: 0;
    /// Raise the interrupt (PLIC source 12 on the SoC) while [`Status::frame`] is set.
    pub irq_enable, set_irq_enable: 1;
}

bitfield! {
    /// Status register.
    #[derive(Clone, Copy, PartialEq, Eq, Default)]
    pub struct Status(u32);
    impl Debug;
    /// A frame was published since it was last cleared; write 1 to clear.
    pub frame, set_frame: 0;
    /// The unit is processing frames.
    pub active, _: 1;
}

bitfield! {
    /// Version register.
    #[derive(Clone, Copy, PartialEq, Eq)]
    pub struct Version(u32);
    impl Debug;
    /// Layout version (1).
    pub u16, version, _: 15, 0;
    /// Bytes of the published header (64).
    pub u16, header_len, _: 31, 16;
}

bitfield! {
    /// Frame size register of a buffer.
    #[derive(Clone, Copy, PartialEq, Eq)]
    pub struct Size(u32);
    impl Debug;
    /// Pixels in the frame's last row.
    pub u16, width, _: 15, 0;
    /// Rows.
    pub u16, height, _: 31, 16;
}

/// Why no run buffer could be used.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum UnitError {
    /// The header is invalid, was read mid-publish (`Inconsistent`), or the buffer was
    /// overwritten while in use (`Torn`).
    Header(HeaderError),
    /// The buffer's words are not in the window.
    OutsideWindow,
}

impl From<HeaderError> for UnitError {
    fn from(e: HeaderError) -> Self {
        UnitError::Header(e)
    }
}

/// A published run buffer, in place.
#[derive(Debug, Clone, Copy)]
pub struct Runs<'a> {
    /// Which buffer, which frame, its size and losses.
    pub ticket: RunTicket,
    /// The run words (`vision::runs`).
    pub words: &'a [u32],
}

/// Counters of the reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct UnitStats {
    /// Buffers used and verified whole.
    pub frames: u32,
    /// Buffers discarded because the unit started on them during the read.
    pub torn: u32,
    /// Header copies taken mid-publish.
    pub inconsistent: u32,
    /// Published frames never used.
    pub skipped: u32,
}

/// The vision unit's reader and control.
#[derive(Debug)]
pub struct VisionUnit<B, M> {
    regs: B,
    memory: M,
    last_sequence: u32,
    stats: UnitStats,
}

impl<B: RegisterBus, M: WindowMemory> VisionUnit<B, M> {
    /// The unit at `regs`/`memory` (the same addresses), if its ID and layout version are
    /// there; `None` on a board without one (or a QEMU run whose host computes no runs).
    pub fn probe(regs: B, memory: M) -> Option<Self> {
        if regs.read32(reg::ID) != u32::from_le_bytes(MAGIC) {
            return None;
        }
        let v = Version(regs.read32(reg::VERSION));
        if v.version() != VERSION || usize::from(v.header_len()) != HEADER_LEN {
            return None;
        }
        Header::parse(&memory.read_header()).ok()?;
        Some(VisionUnit {
            regs,
            memory,
            last_sequence: 0,
            stats: UnitStats::default(),
        })
    }

    /// Reader counters.
    pub fn stats(&self) -> UnitStats {
        self.stats
    }

    /// Sequence of the last frame used whole (0 before the first).
    pub fn last_sequence(&self) -> u32 {
        self.last_sequence
    }

    /// The control register.
    pub fn ctrl(&self) -> Ctrl {
        Ctrl(self.regs.read32(reg::CTRL))
    }

    /// The status register.
    pub fn status(&self) -> Status {
        Status(self.regs.read32(reg::STATUS))
    }

    /// Stops the unit (it drops the frame in progress) and loads its class table: the class
    /// of every RGB332 code, four codes a word.
    pub fn load_classes(&mut self, classes: &ColourClasses) {
        self.regs.write32(reg::CTRL, 0);
        for (k, q) in classes.table().chunks_exact(4).enumerate() {
            let w = u32::from_le_bytes([q[0] & 15, q[1] & 15, q[2] & 15, q[3] & 15]);
            self.regs.write32(LUT_OFFSET + 4 * k, w);
        }
    }

    /// Starts processing frames (from the end of the next one), with the end-of-frame
    /// interrupt if `irq`.
    pub fn start(&mut self, irq: bool) {
        let mut c = Ctrl(0);
        c.set_enable(true);
        c.set_irq_enable(irq);
        self.regs.write32(reg::CTRL, c.0);
    }

    /// Stops processing frames.
    pub fn stop(&mut self) {
        self.regs.write32(reg::CTRL, 0);
    }

    /// Clears the end-of-frame flag (and so the interrupt).
    pub fn acknowledge(&self) {
        let mut s = Status(0);
        s.set_frame(true);
        self.regs.write32(reg::STATUS, s.0);
    }

    /// Whether a frame newer than the last one used is published (one register read).
    pub fn has_new_runs(&self) -> bool {
        let s = self.regs.read32(reg::SEQUENCE);
        s != 0 && s != self.last_sequence
    }

    /// Runs `use_runs` on the newest published run buffer, in place, if it is newer than the
    /// last one used; `Ok(None)` when there is none. The result is returned only if the buffer
    /// was still whole afterwards.
    pub fn with_latest<R>(
        &mut self,
        use_runs: impl FnOnce(&Runs<'_>) -> R,
    ) -> Result<Option<(RunTicket, R)>, UnitError> {
        let header = Header::parse(&self.memory.read_header())?;
        let ticket = match header.ticket() {
            Ok(t) => t,
            Err(HeaderError::NoFrame) => return Ok(None),
            Err(e) => {
                if matches!(e, HeaderError::Inconsistent { .. }) {
                    self.stats.inconsistent += 1;
                }
                return Err(e.into());
            }
        };
        if ticket.sequence == self.last_sequence {
            return Ok(None);
        }
        let bytes = self
            .memory
            .bytes(ticket.range())
            .ok_or(UnitError::OutsideWindow)?;
        let words = vision::as_words(bytes).ok_or(UnitError::OutsideWindow)?;
        let result = use_runs(&Runs { ticket, words });
        // The buffer's reads happen before the header is read again.
        fence(Ordering::SeqCst);
        let later = Header::parse(&self.memory.read_header())?;
        if let Err(e) = ticket.verify(&later) {
            self.stats.torn += 1;
            return Err(e.into());
        }
        if self.last_sequence != 0 {
            let gap = ticket.sequence.wrapping_sub(self.last_sequence);
            self.stats.skipped += gap.saturating_sub(1);
        }
        self.last_sequence = ticket.sequence;
        self.stats.frames += 1;
        Ok(Some((ticket, result)))
    }
}

#[cfg(test)]
mod tests;
