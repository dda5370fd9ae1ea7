//! The Verilated SoC in a child process (`vtb-sim`, built from `csrc/sim.cpp` by `build.rs`),
//! driven over its stdin/stdout with a compact binary protocol. Keeping the C++ model in its own
//! process keeps this crate free of `unsafe`; batching keeps the pipe out of the way: one
//! request runs up to N cycles and returns every RVFI record and output event of the batch.
//!
//! Protocol (all integers little-endian). Requests start with an opcode byte:
//!
//! | op | name | body | reply |
//! |---|---|---|---|
//! | 1 | LOAD | first word index u32, count u32, count x u32 (RAM, core held in reset, one clock per word) | none |
//! | 2 | FRAME | byte offset u32, length u32, bytes (frame-grabber window, between two clocks) | none |
//! | 3 | RX | uart u8 (0, 1), cycle u64, byte u8: present the byte on that cycle (queues stay in order) | none |
//! | 4 | IRQ | level u8: the test bench's external interrupt line | none |
//! | 5 | RELEASE | none: one more clock in reset, then run; the cycle count restarts at 0 | none |
//! | 6 | RUN | max cycles u64, flags u8 (1 = RVFI records, 2 = stop after the first event) | batch |
//! | 7 | HELLO | none | protocol version u32 |
//! | 8 | CAMERA | first cycle u64, width u16, height u16, h_blank u32, width x height RGB332 codes: a frame on the vision unit's pixel stream (pixel (x, y) in cycle first + y (width + h_blank) + x, each row's end right after its last pixel, the frame's end right after the last row's; frames queue in order and must not overlap) | none |
//!
//! A batch is: cycles run u64, instructions retired u64, sleep cycles u64 (both since start),
//! event count u32, record count u32, the events (cycle u64, kind u8 [0 UART0 TX, 1 UART1 TX,
//! 2 console, 3 exit], byte u8, exit value u32), then the records (cycle u64, order u64, insn,
//! pc_rdata, pc_wdata, rd_wdata, mem_addr, mem_rdata, mem_wdata as u32, then trap, intr,
//! rd_addr, mem_rmask, mem_wmask, ext_mip, ext_intr_mip as u8). A run always stops after the
//! cycle that wrote the exit register. End of input ends the child; dropping [`Model`] also
//! kills it, and on Linux the child asks the kernel to kill it when its parent dies.

use crate::golden::Retire;
use std::io::{BufReader, BufWriter, Read, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

/// Path of the simulator executable, set by the build script.
pub(crate) const SIM_EXE: &str = env!("VTB_SIM_EXE");
/// The same SoC with the core of the parts without DSP blocks (`MUL_SEQ = 1`).
pub(crate) const SIM_MULSEQ_EXE: &str = env!("VTB_SIM_MULSEQ_EXE");
/// The same SoC with the pipelined core (`PIPE = 1`).
pub(crate) const SIM_PIPE_EXE: &str = env!("VTB_SIM_PIPE_EXE");
/// The pipelined core with multiplication in the divider's loop (`PIPE = 1`, `MUL_SEQ = 1`).
pub(crate) const SIM_PIPE_MULSEQ_EXE: &str = env!("VTB_SIM_PIPE_MULSEQ_EXE");

/// The core a simulated SoC is built with (`rv_core`'s `MUL_SEQ` parameter).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CoreVariant {
    /// MUL* in one cycle on a 32x32 multiplier (DSP blocks): the SoC the firmware, the
    /// cycle-accurate model and the UP5K run.
    #[default]
    Dsp,
    /// MUL* in 34 cycles in the divider's loop, shifts on a barrel shifter: the HX8K's core.
    /// Its cycles differ from the cycle-accurate model's; its retirements do not.
    MulSeq,
    /// The pipelined core (`rtl/rv_pipe.v`): four stages, MUL* on the 32x32 multiplier. Its
    /// cycles differ from the cycle-accurate model's; its retirements do not.
    Pipe,
    /// The pipelined core with MUL* in the divider's loop: the HX8K's core.
    PipeMulSeq,
}

impl CoreVariant {
    /// The simulator executable of this variant.
    pub(crate) fn exe(self) -> &'static str {
        match self {
            Self::Dsp => SIM_EXE,
            Self::MulSeq => SIM_MULSEQ_EXE,
            Self::Pipe => SIM_PIPE_EXE,
            Self::PipeMulSeq => SIM_PIPE_MULSEQ_EXE,
        }
    }

    /// Every variant.
    pub const ALL: [CoreVariant; 4] = [Self::Dsp, Self::MulSeq, Self::Pipe, Self::PipeMulSeq];

    /// Whether MUL* run in the divider's loop (an interrupt waits for them).
    pub fn iterative_mul(self) -> bool {
        matches!(self, Self::MulSeq | Self::PipeMulSeq)
    }
}

const PROTOCOL_VERSION: u32 = 2;

mod op {
    pub const LOAD: u8 = 1;
    pub const FRAME: u8 = 2;
    pub const RX: u8 = 3;
    pub const IRQ: u8 = 4;
    pub const RELEASE: u8 = 5;
    pub const RUN: u8 = 6;
    pub const HELLO: u8 = 7;
    pub const CAMERA: u8 = 8;
}

const FLAG_RVFI: u8 = 1;
const FLAG_STOP_ON_EVENT: u8 = 2;

const BATCH_HEADER_LEN: usize = 32;
const EVENT_LEN: usize = 14;
const RECORD_LEN: usize = 8 + 8 + 7 * 4 + 7;

/// Why the simulator process cannot be used.
#[derive(Debug)]
pub enum SimError {
    /// The executable (its path) could not be started.
    Spawn(&'static str, std::io::Error),
    /// Talking to it failed (it died or closed its pipes).
    Pipe(std::io::Error),
    /// It speaks another protocol version (a stale build).
    Version { expected: u32, got: u32 },
    /// A batch header announced more data than a run can produce.
    BadBatch {
        cycles: u64,
        events: u32,
        records: u32,
    },
    /// An event of a kind the protocol does not have.
    BadEvent { kind: u8 },
}

impl core::fmt::Display for SimError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Spawn(exe, e) => write!(f, "cannot start the simulator {exe}: {e}"),
            Self::Pipe(e) => write!(f, "simulator process pipe: {e}"),
            Self::Version { expected, got } => {
                write!(f, "simulator speaks protocol {got}, expected {expected}")
            }
            Self::BadBatch {
                cycles,
                events,
                records,
            } => write!(
                f,
                "malformed batch: {events} events and {records} records in {cycles} cycles"
            ),
            Self::BadEvent { kind } => write!(f, "unknown event kind {kind}"),
        }
    }
}

impl std::error::Error for SimError {}

/// One of the model's output events.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RawEvent {
    Uart0Tx(u8),
    Uart1Tx(u8),
    Console(u8),
    Exit(u32),
}

/// A retirement record with the interrupt lines the RVFI extension reports.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Record {
    pub cycle: u64,
    pub retire: Retire,
    pub mip: u8,
    pub intr_mip: u8,
}

/// What one RUN produced.
#[derive(Debug, Default)]
pub(crate) struct Batch {
    pub cycles: u64,
    pub retired: u64,
    pub sleep_cycles: u64,
    pub events: Vec<(u64, RawEvent)>,
    pub records: Vec<Record>,
}

/// Owner of one simulator process.
#[derive(Debug)]
pub(crate) struct Model {
    child: Child,
    tx: BufWriter<ChildStdin>,
    rx: BufReader<ChildStdout>,
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    let mut w = [0u8; 8];
    w.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(w)
}

fn le_u32(b: &[u8], at: usize) -> u32 {
    let mut w = [0u8; 4];
    w.copy_from_slice(&b[at..at + 4]);
    u32::from_le_bytes(w)
}

impl Model {
    /// Starts a simulator: a fresh SoC in reset with zeroed memories.
    pub(crate) fn spawn(core: CoreVariant) -> Result<Self, SimError> {
        let mut child = Command::new(core.exe())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| SimError::Spawn(core.exe(), e))?;
        let (Some(stdin), Some(stdout)) = (child.stdin.take(), child.stdout.take()) else {
            let _ = child.kill();
            let _ = child.wait();
            return Err(SimError::Spawn(
                core.exe(),
                std::io::Error::other("no pipes"),
            ));
        };
        let mut model = Self {
            child,
            tx: BufWriter::with_capacity(1 << 16, stdin),
            rx: BufReader::with_capacity(1 << 16, stdout),
        };
        model.tx.write_all(&[op::HELLO]).map_err(SimError::Pipe)?;
        model.tx.flush().map_err(SimError::Pipe)?;
        let mut v = [0u8; 4];
        model.rx.read_exact(&mut v).map_err(SimError::Pipe)?;
        let got = u32::from_le_bytes(v);
        if got != PROTOCOL_VERSION {
            return Err(SimError::Version {
                expected: PROTOCOL_VERSION,
                got,
            });
        }
        Ok(model)
    }

    fn send(&mut self, bytes: &[u8]) -> Result<(), SimError> {
        self.tx.write_all(bytes).map_err(SimError::Pipe)
    }

    /// Writes words into RAM from word index `first` (wrapping in the 1 MiB RAM).
    pub(crate) fn load(&mut self, first: u32, words: &[u32]) -> Result<(), SimError> {
        const CHUNK: usize = 1 << 16;
        for (k, chunk) in words.chunks(CHUNK).enumerate() {
            let first = first.wrapping_add((k * CHUNK) as u32);
            let mut msg = Vec::with_capacity(9 + 4 * chunk.len());
            msg.push(op::LOAD);
            msg.extend_from_slice(&first.to_le_bytes());
            msg.extend_from_slice(&(chunk.len() as u32).to_le_bytes());
            for w in chunk {
                msg.extend_from_slice(&w.to_le_bytes());
            }
            self.send(&msg)?;
        }
        Ok(())
    }

    /// Writes bytes into the frame-grabber window at `offset` (bounds checked by the caller).
    pub(crate) fn write_frame(&mut self, offset: u32, bytes: &[u8]) -> Result<(), SimError> {
        for (k, chunk) in bytes.chunks(1 << 20).enumerate() {
            let at = offset.wrapping_add((k << 20) as u32);
            let mut head = [0u8; 9];
            head[0] = op::FRAME;
            head[1..5].copy_from_slice(&at.to_le_bytes());
            head[5..9].copy_from_slice(&(chunk.len() as u32).to_le_bytes());
            self.send(&head)?;
            self.send(chunk)?;
        }
        Ok(())
    }

    /// Queues a byte for a UART receiver at `cycle` (cycles must not decrease per UART).
    pub(crate) fn rx(&mut self, uart: u8, cycle: u64, byte: u8) -> Result<(), SimError> {
        let mut msg = [0u8; 11];
        msg[0] = op::RX;
        msg[1] = uart;
        msg[2..10].copy_from_slice(&cycle.to_le_bytes());
        msg[10] = byte;
        self.send(&msg)
    }

    /// Queues a frame on the camera's pixel stream from cycle `first` (checked by the caller:
    /// 1..=4096 pixels each way, `codes` whole, `h_blank` at least 1).
    pub(crate) fn camera(
        &mut self,
        first: u64,
        width: u16,
        height: u16,
        h_blank: u32,
        codes: &[u8],
    ) -> Result<(), SimError> {
        let mut head = [0u8; 17];
        head[0] = op::CAMERA;
        head[1..9].copy_from_slice(&first.to_le_bytes());
        head[9..11].copy_from_slice(&width.to_le_bytes());
        head[11..13].copy_from_slice(&height.to_le_bytes());
        head[13..17].copy_from_slice(&h_blank.to_le_bytes());
        self.send(&head)?;
        self.send(codes)
    }

    /// Drives the test bench's external interrupt line.
    pub(crate) fn irq(&mut self, level: bool) -> Result<(), SimError> {
        self.send(&[op::IRQ, u8::from(level)])
    }

    /// One more clock in reset, then the core runs; the cycle count restarts at 0.
    pub(crate) fn release(&mut self) -> Result<(), SimError> {
        self.send(&[op::RELEASE])
    }

    /// Runs up to `max_cycles` cycles (stopping after an exit, or after any event when
    /// `stop_on_event`), collecting RVFI records when `rvfi`.
    pub(crate) fn run(
        &mut self,
        max_cycles: u64,
        rvfi: bool,
        stop_on_event: bool,
    ) -> Result<Batch, SimError> {
        let mut msg = [0u8; 10];
        msg[0] = op::RUN;
        msg[1..9].copy_from_slice(&max_cycles.to_le_bytes());
        msg[9] = (if rvfi { FLAG_RVFI } else { 0 })
            | (if stop_on_event { FLAG_STOP_ON_EVENT } else { 0 });
        self.send(&msg)?;
        self.tx.flush().map_err(SimError::Pipe)?;

        let mut h = [0u8; BATCH_HEADER_LEN];
        self.rx.read_exact(&mut h).map_err(SimError::Pipe)?;
        let cycles = le_u64(&h, 0);
        let n_events = le_u32(&h, 24);
        let n_records = le_u32(&h, 28);
        // each cycle emits at most 3 events and 1 record
        if cycles > max_cycles
            || u64::from(n_events) > 3 * cycles
            || u64::from(n_records) > cycles
            || (!rvfi && n_records != 0)
        {
            return Err(SimError::BadBatch {
                cycles,
                events: n_events,
                records: n_records,
            });
        }
        let mut body = vec![0u8; n_events as usize * EVENT_LEN + n_records as usize * RECORD_LEN];
        self.rx.read_exact(&mut body).map_err(SimError::Pipe)?;
        let (ev_bytes, rec_bytes) = body.split_at(n_events as usize * EVENT_LEN);
        let events = ev_bytes
            .chunks_exact(EVENT_LEN)
            .map(|e| {
                let cycle = le_u64(e, 0);
                let ev = match e[8] {
                    0 => RawEvent::Uart0Tx(e[9]),
                    1 => RawEvent::Uart1Tx(e[9]),
                    2 => RawEvent::Console(e[9]),
                    3 => RawEvent::Exit(le_u32(e, 10)),
                    kind => return Err(SimError::BadEvent { kind }),
                };
                Ok((cycle, ev))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let records = rec_bytes
            .chunks_exact(RECORD_LEN)
            .map(|r| Record {
                cycle: le_u64(r, 0),
                retire: Retire {
                    order: le_u64(r, 8),
                    insn: le_u32(r, 16),
                    pc_rdata: le_u32(r, 20),
                    pc_wdata: le_u32(r, 24),
                    rd_wdata: le_u32(r, 28),
                    mem_addr: le_u32(r, 32),
                    mem_rdata: le_u32(r, 36),
                    mem_wdata: le_u32(r, 40),
                    trap: r[44] != 0,
                    intr: r[45] != 0,
                    rd_addr: r[46],
                    mem_rmask: r[47],
                    mem_wmask: r[48],
                },
                mip: r[49],
                intr_mip: r[50],
            })
            .collect();
        Ok(Batch {
            cycles,
            retired: le_u64(&h, 8),
            sleep_cycles: le_u64(&h, 16),
            events,
            records,
        })
    }

    /// Process id of the simulator (for tests of its lifetime).
    pub(crate) fn pid(&self) -> u32 {
        self.child.id()
    }
}

impl Drop for Model {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
