//! The vision unit (`verilator-tb/rtl/vision_unit.v`): a camera's pixel stream classified and
//! run-length encoded into two run buffers, published at the end of each frame with an
//! interrupt (PLIC source 12).
//!
//! The RTL works pixel by pixel; the model takes a whole frame from the harness
//! ([`crate::Soc::camera_frame`]), works out when each of its events enters (pixel `(x, y)` in
//! cycle `start + y * (width + h_blank) + x`, the end of row `y` right after its last pixel,
//! the end of the frame right after the last row's end), and computes the frame's runs at once
//! with `vision::runs::RunEncoder`, the unit's reference, when it publishes. What the processor
//! can see depends only on three cycles per frame, which the model takes from the RTL's
//! pipeline:
//!
//! - `first` (the first pixel): the frame is processed only if the unit is active then;
//! - `eof` (the frame's end): an enabled unit that is not active becomes active from `eof + 1`;
//! - `eof + 2`: if the unit stayed active through the frame, the frame is published at the edge
//!   ending that cycle (registers, the swapped buffer and the interrupt line show it from
//!   `eof + 3`).
//!
//! A write to the control register in cycle `w` takes effect from `w + 1`; clearing ENABLE
//! deactivates the unit at once and drops the frame in progress. The class table takes writes
//! only while ENABLE is clear, so the table a frame is encoded with is the one it streamed
//! through. The buffer being written reads as zero, so only published contents are ever seen.

use std::collections::VecDeque;

use vision::run_window::{ctrl, next_sequence, status, BUFFER_OFFSET, LUT_OFFSET, MAGIC, WRITING};
use vision::runs::RunEncoder;

/// Words of each run buffer (the RTL's `VIS_CAP_AW = 12`).
pub const CAPACITY: usize = 4096;

/// Timing of a frame on the camera's pixel stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CameraTiming {
    /// Cycles from the last pixel of a row to the first of the next (at least 1; the row's
    /// end is the first of them).
    pub h_blank: u32,
}

/// A VGA sensor's row: 640 pixels and 144 blank, 784 pixel clocks.
pub const VGA_H_BLANK: u32 = 144;

impl Default for CameraTiming {
    fn default() -> Self {
        CameraTiming {
            h_blank: VGA_H_BLANK,
        }
    }
}

impl CameraTiming {
    /// Cycles from the first pixel of a `width` x `height` frame to its end event.
    pub fn eof_offset(&self, width: u16, height: u16) -> u64 {
        let line = u64::from(width) + u64::from(self.h_blank);
        (u64::from(height) - 1) * line + u64::from(width) + 1
    }
}

/// A frame on its way through the unit.
#[derive(Debug, Clone)]
struct Streamed {
    first: u64,
    eof: u64,
    width: u16,
    codes: Vec<u8>,
    /// 0: `first` not reached; 1: `first` passed; 2: `eof` passed.
    stage: u8,
    /// Active at `first` and not deactivated since.
    ok: bool,
}

/// The unit's state.
#[derive(Debug, Clone)]
pub(crate) struct VisionUnit {
    en: bool,
    irq_en: bool,
    active: bool,
    frame_flag: bool,
    /// The cycle whose edge last published a frame.
    published_at: Option<u64>,
    front: usize,
    seq: u32,
    count: u32,
    dropped: u32,
    size: u32,
    /// 4-bit class of each RGB332 code.
    lut: [u8; 256],
    buffers: [Vec<u32>; 2],
    frames: VecDeque<Streamed>,
    /// The first cycle a new frame's stream may start in.
    free_at: u64,
    /// Frames kept for reuse of their pixel storage.
    spare: Vec<Vec<u8>>,
}

impl VisionUnit {
    pub fn new() -> Self {
        VisionUnit {
            en: false,
            irq_en: false,
            active: false,
            frame_flag: false,
            published_at: None,
            front: 1,
            seq: 0,
            count: 0,
            dropped: 0,
            size: 0,
            lut: [0; 256],
            buffers: [vec![0; CAPACITY], vec![0; CAPACITY]],
            frames: VecDeque::new(),
            free_at: 0,
            spare: Vec::new(),
        }
    }

    /// Queues a frame whose stream starts at the first free cycle at or after `at`; returns
    /// the cycles of its first pixel and of its end event.
    pub fn queue(
        &mut self,
        at: u64,
        codes: &[u8],
        width: u16,
        height: u16,
        timing: CameraTiming,
    ) -> (u64, u64) {
        let first = at.max(self.free_at);
        let eof = first + timing.eof_offset(width, height);
        self.free_at = eof + 1;
        let mut buf = self.spare.pop().unwrap_or_default();
        buf.clear();
        buf.extend_from_slice(codes);
        self.frames.push_back(Streamed {
            first,
            eof,
            width,
            codes: buf,
            stage: 0,
            ok: false,
        });
        (first, eof)
    }

    /// Processes every frame event in a cycle before `c` (the state during cycle `c`).
    pub fn advance_to(&mut self, c: u64) {
        loop {
            let active = self.active;
            let Some(f) = self.frames.front_mut() else {
                return;
            };
            if f.stage == 0 && f.first < c {
                f.stage = 1;
                f.ok = active;
            }
            if f.stage == 1 && f.eof < c {
                f.stage = 2;
                if self.en && !self.active {
                    self.active = true;
                }
            }
            if f.stage < 2 {
                return;
            }
            // The next frame's first pixel may come before this one publishes (publishing
            // does not change whether the unit is active).
            let active = self.active;
            if let Some(n) = self.frames.get_mut(1) {
                if n.stage == 0 && n.first < c {
                    n.stage = 1;
                    n.ok = active;
                }
            }
            if self.frames.front().is_some_and(|f| f.eof + 2 < c) {
                if let Some(f) = self.frames.pop_front() {
                    if f.ok && self.active {
                        self.publish(&f);
                    }
                    self.spare.push(f.codes);
                }
            } else {
                return;
            }
        }
    }

    fn publish(&mut self, f: &Streamed) {
        let back = self.front ^ 1;
        let mut enc = RunEncoder::new(&mut self.buffers[back]);
        let lut = &self.lut;
        let width = usize::from(f.width.max(1));
        for row in f.codes.chunks(width) {
            for &c in row {
                enc.pixel(lut[usize::from(c)]);
            }
            enc.end_row();
        }
        let s = enc.finish();
        self.front = back;
        self.seq = next_sequence(self.seq);
        self.count = s.words as u32;
        self.dropped = u32::from(s.dropped);
        self.size = u32::from(s.width) | u32::from(s.height) << 16;
        self.frame_flag = true;
        self.published_at = Some(f.eof + 2);
    }

    /// The interrupt output (after [`VisionUnit::advance_to`] for the cycle).
    pub fn irq(&self) -> bool {
        self.frame_flag && self.irq_en
    }

    /// Whether the interrupt could rise without the core touching the unit.
    pub fn irq_possible(&self) -> bool {
        self.irq_en && (self.frame_flag || self.en)
    }

    /// The first cycle after `t` in which the interrupt output may change without the core.
    pub fn next_change(&self) -> u64 {
        self.frames.front().map_or(u64::MAX, |f| f.eof + 3)
    }

    /// Read of the word at `offset` in cycle `c`.
    pub fn read(&mut self, c: u64, offset: u32) -> u32 {
        self.advance_to(c);
        let buf = |i: usize, v: u32| if self.front == i { v } else { 0 };
        let seq_of = |i: usize| if self.front == i { self.seq } else { WRITING };
        let off = offset as usize;
        if (BUFFER_OFFSET[0]..BUFFER_OFFSET[1] + BUFFER_OFFSET[0]).contains(&off) {
            let i = usize::from(off >= BUFFER_OFFSET[1]);
            let w = (off >> 2) & (CAPACITY - 1);
            return buf(i, self.buffers[i][w]);
        }
        match offset {
            0x00 => u32::from_le_bytes(MAGIC),
            0x04 => 64 << 16 | 1,
            0x08 => CAPACITY as u32,
            0x0c => BUFFER_OFFSET[0] as u32,
            0x10 => BUFFER_OFFSET[1] as u32,
            0x14 => self.seq,
            0x18 => self.front as u32,
            0x1c => seq_of(0),
            0x20 => seq_of(1),
            0x24 => buf(0, self.count),
            0x28 => buf(1, self.count),
            0x2c => buf(0, self.dropped),
            0x30 => buf(1, self.dropped),
            0x34 => buf(0, self.size),
            0x38 => buf(1, self.size),
            0x40 => {
                (u32::from(self.en) * ctrl::ENABLE) | (u32::from(self.irq_en) * ctrl::IRQ_ENABLE)
            }
            0x44 => {
                (u32::from(self.frame_flag) * status::FRAME)
                    | (u32::from(self.active) * status::ACTIVE)
            }
            _ => 0,
        }
    }

    /// Write in cycle `c` (takes effect from `c + 1`).
    pub fn write(&mut self, c: u64, offset: u32, wstrb: u8, wdata: u32) {
        // every event of cycle `c` sees the state before this write
        self.advance_to(c + 1);
        let off = offset as usize;
        if offset == 0x40 && wstrb & 1 != 0 {
            let en_next = wdata & ctrl::ENABLE != 0;
            if !en_next {
                self.active = false;
                for f in self.frames.iter_mut().filter(|f| f.stage >= 1) {
                    f.ok = false;
                }
            }
            self.en = en_next;
            self.irq_en = wdata & ctrl::IRQ_ENABLE != 0;
        } else if offset == 0x44 && wstrb & 1 != 0 && wdata & status::FRAME != 0 {
            // a frame published at the same edge wins
            if self.published_at != Some(c) {
                self.frame_flag = false;
            }
        } else if (LUT_OFFSET..LUT_OFFSET + 256).contains(&off) && !self.en {
            for lane in 0..4 {
                if wstrb & (1 << lane) != 0 {
                    self.lut[off + lane - LUT_OFFSET] = ((wdata >> (8 * lane)) & 15) as u8;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
