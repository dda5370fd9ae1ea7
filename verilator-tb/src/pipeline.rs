//! What a pipelined core would cost in cycles, estimated from a run of this one.
//!
//! The FPGA goals (`docs/fpga.md`, Timing) need a pipelined core: fetch, decode with the
//! register-file read, execute, memory (and write-back). Such a core loses cycles where this
//! one does not: a taken branch or a jump discards the instructions fetched behind it, an
//! instruction that needs a loaded word (or a product, when the multiplier takes two stages;
//! in deeper designs also a shift's result or a CSR read) right after it, or two after it in
//! deeper designs, waits, and a trap entry, MRET or WFI (and, in simple designs, a CSR
//! instruction) empties the pipeline. This module
//! replays the retirement records of a run on the present core (which already pays for
//! divisions, atomics, traps and counter carries) and adds those losses for a few designs, so
//! the choice between them is made on the firmware's own instruction stream.
//!
//! The estimate is `cycles awake on this core + losses`: it keeps this core's multi-cycle
//! instructions as they are and assumes each pipelined design runs everything else at one
//! instruction per cycle. A record with `intr` set starts an interrupt handler: the pipeline
//! was emptied for it (counted as a trap), so no hazard reaches across it.

use soc_model::Retire;

/// How a design fetches past control flow, and what its stages cost.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Design {
    /// Short name for tables.
    pub name: &'static str,
    /// Cycles lost when a control-flow instruction goes where the fetch did not (resolved in
    /// execute: the fetch and decode stages behind it are discarded).
    pub redirect: u32,
    /// JAL's target is taken in decode (one stage earlier: `redirect - 1` cycles).
    pub jal_in_decode: bool,
    /// Conditional branches are predicted in decode: backward ones taken (loops), forward ones
    /// not taken; a predicted-taken branch costs `redirect - 1`, a wrong guess `redirect`.
    pub backward_taken: bool,
    /// A table of this many two-bit counters (0: none), indexed by the branch's halfword
    /// address, reverses the decode-stage guess of a conditional branch that has lately gone
    /// against it (counting up when the branch does, down when it does not; reversed from 2
    /// on), as `rtl/rv_pipe.v` does with `BHT_AW`. Needs `backward_taken`.
    pub branch_table: usize,
    /// A return (`jalr x0, 0(ra)`) is predicted in decode from a return-address stack of this
    /// depth (0: none); a correct prediction costs `redirect - 1`.
    pub return_stack: usize,
    /// Cycles an instruction waits when it reads the word the instruction just before it
    /// loaded: 1 when the word arrives at the end of the memory stage, 2 when a stage later.
    pub load_use: u32,
    /// Cycles an instruction waits when it reads the word the instruction two before it
    /// loaded (1 when the word arrives a stage after memory), counted only where the one
    /// between ran through without waiting (it neither read nor rewrote that register,
    /// waited for an operand of its own, was a taken branch or a jump, nor divided).
    pub load_use2: u32,
    /// Cycles an instruction waits when it reads the product of the instruction just before
    /// it: 0 for a one-stage product, 1 for a multiplier over execute and memory, 2 when the
    /// product is written back a stage after memory.
    pub mul_use: u32,
    /// ... the product of the instruction two before it, counted as `load_use2`.
    pub mul_use2: u32,
    /// Cycles an instruction waits when it reads the result of a shift or a CSR read just
    /// before it (those results a stage after execute, as in deeper pipelines).
    pub late_use: u32,
    /// A branch target buffer of this many entries (0: none), direct-mapped by address, with
    /// a two-bit counter each: it predicts at fetch where a branch or a jump goes (a correct
    /// prediction costs nothing, a wrong one `redirect`); it replaces the decode-stage schemes
    /// for branches and jumps (not the return stack, which it leaves returns to).
    pub btb_entries: usize,
    /// Cycles an MRET, WFI, ECALL or EBREAK, and each trap entry, costs beyond its own: the
    /// pipeline is emptied behind it.
    pub serialize: u32,
    /// CSR instructions empty the pipeline too (otherwise they run in line: their effects on
    /// later instructions are on interrupts, which are taken between instructions anyway).
    pub csr_serialize: bool,
}

impl Design {
    /// Four stages (fetch, decode and register read, execute, memory and write-back),
    /// control flow resolved in execute, no prediction.
    pub const FOUR_STAGE: Design = Design {
        name: "4 stages, resolve in execute",
        redirect: 2,
        jal_in_decode: false,
        backward_taken: false,
        branch_table: 0,
        return_stack: 0,
        load_use: 1,
        load_use2: 0,
        mul_use: 0,
        mul_use2: 0,
        late_use: 0,
        btb_entries: 0,
        serialize: 2,
        csr_serialize: true,
    };

    /// Six stages (two fetch stages, decode with the register-file read, execute, memory,
    /// write-back), the plan of `docs/fpga.md` for the clock goals: control flow resolved in
    /// execute behind three stages, predicted at fetch by a branch target buffer, returns from
    /// a stack in decode; loaded words and products written back a stage after memory, shift
    /// results and CSR reads a stage after execute; CSR instructions in line; the pipeline
    /// emptied behind MRET, WFI, ECALL, EBREAK and trap entries (three cycles). The first
    /// design has a 64-entry buffer, the second 256 entries (two block RAMs), the third also
    /// has each loaded word at the end of the memory stage, as `rtl/rv_pipe.v` has it (the
    /// RAM read from the execute stage's address).
    pub fn six_stage() -> [Design; 3] {
        let six = Design {
            name: "6 stages, 64-entry branch target buffer, late results",
            redirect: 3,
            jal_in_decode: false,
            backward_taken: false,
            branch_table: 0,
            return_stack: 4,
            load_use: 2,
            load_use2: 1,
            mul_use: 2,
            mul_use2: 1,
            late_use: 1,
            btb_entries: 64,
            serialize: 3,
            csr_serialize: false,
        };
        let big = Design {
            name: "+ 256-entry branch target buffer",
            btb_entries: 256,
            ..six
        };
        let early_load = Design {
            name: "+ loaded words at the end of memory",
            load_use: 1,
            load_use2: 0,
            ..big
        };
        [six, big, early_load]
    }

    /// `rtl/rv_pipe.v` on its way to [`Design::six_stage`], a step at a time (`docs/fpga.md`,
    /// the plan): first the six-stage design's front end alone, a 256-entry branch target
    /// buffer at fetch and the redirect a cycle after execute decides (three cycles a wrong
    /// fetch), with neither the decode-stage guesses nor the branch table it replaces; then
    /// the four-entry return stack; then shift results and CSR reads a stage after execute.
    /// Loaded words stay at the end of memory and products in execute, as `rv_pipe` has them.
    pub fn front_end_steps() -> [Design; 3] {
        let front = Design {
            name: "4 stages, 256-entry branch target buffer at fetch, redirect a cycle later",
            redirect: 3,
            serialize: 3,
            btb_entries: 256,
            csr_serialize: false,
            ..Design::FOUR_STAGE
        };
        let ras = Design {
            name: "+ 4-entry return stack",
            return_stack: 4,
            ..front
        };
        let late = Design {
            name: "+ shift results and CSR reads a stage later",
            late_use: 1,
            ..ras
        };
        [front, ras, late]
    }

    /// The designs compared in `docs/fpga.md`, each adding to the one before it.
    pub fn candidates() -> [Design; 8] {
        let plain = Design::FOUR_STAGE;
        let jal = Design {
            name: "+ JAL in decode",
            jal_in_decode: true,
            ..plain
        };
        let btfn = Design {
            name: "+ backward branches taken",
            backward_taken: true,
            ..jal
        };
        let table = Design {
            name: "+ 2048-entry branch table in decode",
            branch_table: 2048,
            ..btfn
        };
        let ras = Design {
            name: "+ 4-entry return stack",
            return_stack: 4,
            ..table
        };
        let csr = Design {
            name: "+ CSRs in line",
            csr_serialize: false,
            ..ras
        };
        let btb = Design {
            name: "+ 64-entry branch target buffer",
            btb_entries: 64,
            ..csr
        };
        let mul = Design {
            name: "+ two-stage multiplier",
            mul_use: 1,
            ..btb
        };
        [plain, jal, btfn, table, ras, csr, btb, mul]
    }
}

/// What an instruction is, for the estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    Branch { backward: bool },
    Jal { link: bool },
    Jalr { ret: bool, link: bool },
    Load,
    Mul,
    Csr,
    System,
    Other,
}

/// An instruction's class and the registers it reads and writes (x0 never counts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Decoded {
    class: Class,
    /// A shift or a CSR read: its result comes a stage after execute in deeper designs.
    late: bool,
    /// A division (it holds the execute stage for many cycles).
    divides: bool,
    rd: u8,
    rs1: Option<u8>,
    rs2: Option<u8>,
}

fn decode(raw: u32) -> Decoded {
    let insn = if raw & 3 != 3 {
        // an illegal compressed encoding traps: it reads and writes nothing
        soc_model::rvc::expand(raw as u16).unwrap_or(0)
    } else {
        raw
    };
    let reg = |lo: u32| ((insn >> lo) & 31) as u8;
    let nz = |r: u8| (r != 0).then_some(r);
    let (rd, rs1, rs2) = (reg(7), reg(15), reg(20));
    let f3 = (insn >> 12) & 7;
    let (class, reads1, reads2, writes) = match insn & 0x7f {
        0x63 => {
            let backward = insn >> 31 == 1;
            (Class::Branch { backward }, true, true, false)
        }
        0x6f => (
            Class::Jal {
                link: rd == 1 || rd == 5,
            },
            false,
            false,
            true,
        ),
        0x67 => (
            Class::Jalr {
                ret: rd == 0 && rs1 == 1 && insn >> 20 == 0,
                link: rd == 1 || rd == 5,
            },
            true,
            false,
            true,
        ),
        0x03 => (Class::Load, true, false, true),
        // LR, SC and the AMOs: the loaded word is written back
        0x2f => (Class::Load, true, true, true),
        0x23 => (Class::Other, true, true, false),
        0x33 if insn >> 25 == 1 && f3 < 4 => (Class::Mul, true, true, true),
        0x33 => (Class::Other, true, true, true),
        0x13 => (Class::Other, true, false, true),
        0x37 | 0x17 => (Class::Other, false, false, true),
        0x73 if f3 != 0 => (Class::Csr, f3 & 4 == 0, false, true),
        // FENCE orders memory accesses, which an in-order core with one memory port never
        // reorders: nothing to wait for
        0x0f => (Class::Other, false, false, false),
        _ => (Class::System, false, false, false),
    };
    let opcode = insn & 0x7f;
    let shift = (opcode == 0x13 || (opcode == 0x33 && insn >> 25 != 1)) && f3 & 3 == 1;
    Decoded {
        class,
        late: shift || class == Class::Csr,
        divides: opcode == 0x33 && insn >> 25 == 1 && f3 >= 4,
        rd: if writes { rd } else { 0 },
        rs1: if reads1 { nz(rs1) } else { None },
        rs2: if reads2 { nz(rs2) } else { None },
    }
}

/// Instruction mix of a run, and where a pipelined design would lose cycles.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Mix {
    /// Records replayed.
    pub instructions: u64,
    /// Conditional branches, and of those taken.
    pub branches: u64,
    /// ... taken.
    pub taken: u64,
    /// Backward branches, and of those taken.
    pub backward: u64,
    /// ... taken.
    pub backward_taken: u64,
    /// JAL.
    pub jal: u64,
    /// JALR, and of those returns (`jalr x0, 0(ra)`).
    pub jalr: u64,
    /// ... returns.
    pub returns: u64,
    /// Loads (and LR, SC, AMOs).
    pub loads: u64,
    /// Of those, loads whose word the next instruction reads.
    pub load_use: u64,
    /// MUL, MULH, MULHSU, MULHU.
    pub muls: u64,
    /// Of those, products the next instruction reads.
    pub mul_use: u64,
    /// Loads whose word the instruction two after reads, the one between having run through
    /// (see [`Design::load_use2`]).
    pub load_use2: u64,
    /// Products likewise.
    pub mul_use2: u64,
    /// Shifts and CSR reads whose result the next instruction reads.
    pub late_use: u64,
    /// CSR instructions.
    pub csr: u64,
    /// MRET, WFI, ECALL, EBREAK and illegal instructions.
    pub system: u64,
    /// Trap and interrupt entries.
    pub traps: u64,
}

/// One design's estimate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// The design.
    pub design: Design,
    /// Cycles lost to control flow.
    pub control: u64,
    /// Cycles lost waiting for loaded words, products, shift results and CSR reads.
    pub data: u64,
    /// Cycles lost emptying the pipeline for system instructions and traps.
    pub serial: u64,
    /// Estimated awake cycles: this core's plus the losses.
    pub cycles: u64,
    /// Estimated cycles per instruction while awake.
    pub cpi: f64,
}

/// The instruction mix of `records` (in retirement order).
pub fn mix(records: &[Retire]) -> Mix {
    let mut m = Mix::default();
    let mut prev: Option<Decoded> = None;
    let mut prev2: Option<Decoded> = None;
    // the instruction before this one waited, was a taken branch or a jump, or divided: an
    // older result is there by the time this one needs it
    let mut prev_held = false;
    for r in records {
        m.instructions += 1;
        if r.intr {
            m.traps += 1;
            prev = None;
            prev2 = None;
        }
        if r.trap {
            m.traps += 1;
            prev = None;
            prev2 = None;
            continue;
        }
        let d = decode(r.insn);
        let len = if r.insn & 3 == 3 { 4 } else { 2 };
        let next_seq = r.pc_rdata.wrapping_add(len);
        let reads = |reg: u8| d.rs1 == Some(reg) || d.rs2 == Some(reg);
        let mut waits = false;
        if let Some(p) = prev.filter(|p| p.rd != 0 && reads(p.rd)) {
            let count = match p.class {
                Class::Load => Some(&mut m.load_use),
                Class::Mul => Some(&mut m.mul_use),
                _ if p.late => Some(&mut m.late_use),
                _ => None,
            };
            if let Some(n) = count {
                *n += 1;
                waits = true;
            }
        }
        if let (Some(p2), Some(p)) = (prev2, prev) {
            // the instruction between neither read the register (it waited for it then) nor
            // wrote it again, and ran through
            let between = p.rs1 == Some(p2.rd) || p.rs2 == Some(p2.rd) || p.rd == p2.rd;
            if p2.rd != 0 && reads(p2.rd) && !between && !prev_held {
                let count = match p2.class {
                    Class::Load => Some(&mut m.load_use2),
                    Class::Mul => Some(&mut m.mul_use2),
                    _ => None,
                };
                if let Some(n) = count {
                    *n += 1;
                    waits = true;
                }
            }
        }
        match d.class {
            Class::Branch { backward } => {
                let taken = r.pc_wdata != next_seq;
                m.branches += 1;
                m.taken += u64::from(taken);
                if backward {
                    m.backward += 1;
                    m.backward_taken += u64::from(taken);
                }
            }
            Class::Jal { .. } => m.jal += 1,
            Class::Jalr { ret, .. } => {
                m.jalr += 1;
                m.returns += u64::from(ret);
            }
            Class::Load => m.loads += 1,
            Class::Mul => m.muls += 1,
            Class::Csr => m.csr += 1,
            Class::System => m.system += 1,
            Class::Other => {}
        }
        prev2 = prev;
        prev = Some(d);
        let flow = matches!(
            d.class,
            Class::Branch { .. } | Class::Jal { .. } | Class::Jalr { .. }
        );
        prev_held = waits || (flow && r.pc_wdata != next_seq) || d.divides;
    }
    m
}

/// The estimate for `design` from `records` (in retirement order) of a run that was awake
/// `awake_cycles` on this core.
pub fn estimate(design: &Design, records: &[Retire], awake_cycles: u64) -> Estimate {
    let m = mix(records);
    let r = u64::from(design.redirect);
    let early = r.saturating_sub(1);
    let mut control = 0u64;
    let mut stack: Vec<u32> = Vec::new();
    let mut btb = Btb::new(design.btb_entries);
    let mut table = vec![0u8; design.branch_table];
    for rec in records.iter().filter(|rec| !rec.trap) {
        let d = decode(rec.insn);
        let len = if rec.insn & 3 == 3 { 4 } else { 2 };
        let next_seq = rec.pc_rdata.wrapping_add(len);
        let taken = rec.pc_wdata != next_seq;
        let (is_flow, link, ret) = match d.class {
            Class::Branch { .. } => (true, false, false),
            Class::Jal { link } => (true, link, false),
            Class::Jalr { ret, link } => (true, link, ret),
            _ => (false, false, false),
        };
        if !is_flow {
            continue;
        }
        let from_stack = ret && design.return_stack > 0;
        let predicted_return = from_stack && stack.pop() == Some(rec.pc_wdata);
        if link && design.return_stack > 0 {
            push_return(&mut stack, design.return_stack, next_seq);
        }
        control += if from_stack {
            if predicted_return {
                early
            } else {
                r
            }
        } else if design.btb_entries > 0 {
            if btb.predict(rec.pc_rdata, taken, rec.pc_wdata) {
                0
            } else {
                r
            }
        } else {
            match d.class {
                Class::Branch { backward } if design.backward_taken && !table.is_empty() => {
                    let n = table.len();
                    let counter = &mut table[(rec.pc_rdata as usize >> 1) % n];
                    let guess = backward ^ (*counter >= 2);
                    *counter = if taken != backward {
                        (*counter + 1).min(3)
                    } else {
                        counter.saturating_sub(1)
                    };
                    match (guess, taken) {
                        (true, true) => early,
                        (false, false) => 0,
                        _ => r,
                    }
                }
                Class::Branch { backward } => match (design.backward_taken, backward, taken) {
                    (true, true, true) => early,
                    (true, true, false) => r,
                    (_, _, true) => r,
                    (_, _, false) => 0,
                },
                Class::Jal { .. } if design.jal_in_decode => early,
                _ => r,
            }
        };
    }
    let data = m.load_use * u64::from(design.load_use)
        + m.load_use2 * u64::from(design.load_use2)
        + m.mul_use * u64::from(design.mul_use)
        + m.mul_use2 * u64::from(design.mul_use2)
        + m.late_use * u64::from(design.late_use);
    let emptied = m.system + m.traps + if design.csr_serialize { m.csr } else { 0 };
    let serial = emptied * u64::from(design.serialize);
    let cycles = awake_cycles + control + data + serial;
    Estimate {
        design: *design,
        control,
        data,
        serial,
        cycles,
        cpi: cycles as f64 / m.instructions.max(1) as f64,
    }
}

/// A direct-mapped branch target buffer with two-bit counters.
struct Btb {
    entries: Vec<Option<(u32, u32, u8)>>,
}

impl Btb {
    fn new(n: usize) -> Self {
        Btb {
            entries: vec![None; n],
        }
    }

    /// Whether the fetch at `pc` guessed right where the instruction went (`taken` to
    /// `target`, or on); then learns the outcome.
    fn predict(&mut self, pc: u32, taken: bool, target: u32) -> bool {
        let n = self.entries.len();
        let slot = &mut self.entries[(pc as usize >> 1) % n];
        let hit = slot.filter(|e| e.0 == pc);
        let right = match hit {
            Some((_, t, c)) if c >= 2 => taken && t == target,
            _ => !taken,
        };
        let counter = hit.map_or(if taken { 2 } else { 1 }, |(_, _, c)| {
            if taken {
                (c + 1).min(3)
            } else {
                c.saturating_sub(1)
            }
        });
        // a branch never taken needs no entry; a taken one (or one with history) keeps it
        if taken {
            *slot = Some((pc, target, counter));
        } else if let Some((_, t, _)) = hit {
            *slot = Some((pc, t, counter));
        }
        right
    }
}

fn push_return(stack: &mut Vec<u32>, depth: usize, addr: u32) {
    if stack.len() == depth {
        stack.remove(0);
    }
    stack.push(addr);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isa::{self, reg::*};

    fn rec(pc: u32, insn: u32, next: u32) -> Retire {
        Retire {
            order: 0,
            insn,
            trap: false,
            intr: false,
            pc_rdata: pc,
            pc_wdata: next,
            rd_addr: 0,
            rd_wdata: 0,
            mem_addr: 0,
            mem_rmask: 0,
            mem_wmask: 0,
            mem_rdata: 0,
            mem_wdata: 0,
        }
    }

    fn straight(pc: u32, insn: u32) -> Retire {
        rec(pc, insn, pc + 4)
    }

    #[test]
    fn a_loaded_word_used_at_once_waits() {
        let recs = [
            straight(0, isa::lw(A0, SP, 0)),
            straight(4, isa::addi(A1, A0, 1)),
            straight(8, isa::lw(A2, SP, 4)),
            straight(12, isa::addi(A3, A1, 1)), // does not read a2
            straight(16, isa::addi(A4, A2, 1)), // two after the load: forwarded
        ];
        let m = mix(&recs);
        assert_eq!((m.loads, m.load_use), (2, 1));
        let e = estimate(&Design::FOUR_STAGE, &recs, 5);
        assert_eq!((e.data, e.control, e.cycles), (1, 0, 6));
    }

    #[test]
    fn six_stages_wait_longer_and_further() {
        let recs = [
            straight(0, isa::lw(A0, SP, 0)),
            straight(4, isa::addi(A1, A0, 1)), // at once: 2 cycles
            straight(8, isa::lw(A2, SP, 4)),
            straight(12, isa::addi(A3, A1, 1)),
            straight(16, isa::addi(A4, A2, 1)), // two after: 1 cycle
            straight(20, isa::slli(A5, A4, 2)),
            straight(24, isa::add(T0, A5, A5)), // a shift's result at once: 1 cycle
            straight(28, isa::lw(T1, SP, 8)),
            straight(32, isa::addi(T1, ZERO, 1)), // overwrites t1 ...
            straight(36, isa::addi(A0, T1, 1)),   // ... so this reads its value: no wait
        ];
        let m = mix(&recs);
        assert_eq!((m.load_use, m.load_use2, m.late_use), (1, 1, 1));
        let [six, big, early_load] = Design::six_stage();
        assert_eq!(big.btb_entries, 256);
        let e = estimate(&six, &recs, 10);
        assert_eq!((e.data, e.control, e.cycles), (2 + 1 + 1, 0, 14));
        // with the word at the end of memory, only the one used at once waits, a cycle
        assert_eq!(estimate(&early_load, &recs, 10).data, 1 + 1);
        // the four-stage design waits only for the word used at once
        assert_eq!(estimate(&Design::FOUR_STAGE, &recs, 10).data, 1);
    }

    #[test]
    fn two_after_counts_only_behind_an_instruction_that_ran_through() {
        let recs = [
            straight(0, isa::lw(A3, SP, 0)),
            straight(4, isa::lw(A0, SP, 4)),
            straight(8, isa::addi(A1, A3, 1)), // two after the first load: waits
            straight(12, isa::addi(A2, A0, 1)), // two after the second, but behind a wait
            straight(16, isa::mul(A4, A1, A2)),
            straight(20, isa::addi(A5, A3, 1)),
            straight(24, isa::addi(S0, A4, 1)), // two after the product
            straight(28, isa::div(S1, A5, A5)),
            straight(32, isa::lw(T0, SP, 8)),
            straight(36, isa::addi(T1, ZERO, 1)),
            straight(40, isa::addi(T2, T0, 1)), // two after the load, the one between ran
        ];
        let m = mix(&recs);
        assert_eq!(
            (m.load_use, m.load_use2, m.mul_use, m.mul_use2),
            (0, 2, 0, 1)
        );
        let [six, ..] = Design::six_stage();
        assert_eq!(estimate(&six, &recs, 11).data, 2 + 1);
    }

    #[test]
    fn six_stages_lose_three_cycles_on_a_wrong_fetch() {
        // a forward branch taken once (no entry yet: 3) and a return from the stack (2)
        let recs = [
            rec(0x100, isa::beq(A0, A1, 16), 0x110),
            rec(0x110, isa::jal(RA, 0x100), 0x210),
            rec(0x210, isa::jalr(ZERO, RA, 0), 0x114),
        ];
        let [six, ..] = Design::six_stage();
        // the JAL misses the empty buffer too
        assert_eq!(estimate(&six, &recs, 3).control, 3 + 3 + 2);
    }

    #[test]
    fn the_front_end_steps_add_up() {
        // a forward branch taken twice (the first misses the empty buffer: 3), a call (its
        // first time: 3) and its return (3 without the stack, 2 with it), a shift's result
        // used at once (1 in the last step only)
        let beq = isa::beq(A0, A1, 16);
        let recs = [
            rec(0x100, beq, 0x110),
            rec(0x100, beq, 0x110),
            rec(0x110, isa::jal(RA, 0x100), 0x210),
            rec(0x210, isa::jalr(ZERO, RA, 0), 0x114),
            straight(0x114, isa::slli(A2, A0, 2)),
            straight(0x118, isa::add(A3, A2, A2)),
        ];
        let [front, ras, late] = Design::front_end_steps();
        assert_eq!(front.btb_entries, 256);
        assert_eq!(estimate(&front, &recs, 6).control, 3 + 3 + 3);
        assert_eq!(estimate(&ras, &recs, 6).control, 3 + 3 + 2);
        assert_eq!(estimate(&ras, &recs, 6).data, 0);
        assert_eq!(estimate(&late, &recs, 6).data, 1);
    }

    #[test]
    fn x0_is_never_a_dependency() {
        let recs = [
            straight(0, isa::lw(ZERO, SP, 0)),
            straight(4, isa::addi(A1, ZERO, 1)),
        ];
        assert_eq!(mix(&recs).load_use, 0);
    }

    #[test]
    fn control_flow_costs_by_design() {
        // a loop: backward branch taken twice, then falls through; a call and its return
        let bne = isa::bne(A0, A1, -8i32);
        let recs = [
            rec(0x108, bne, 0x100),
            rec(0x108, bne, 0x100),
            rec(0x108, bne, 0x10c),
            rec(0x10c, isa::jal(RA, 0x100), 0x20c),
            rec(0x20c, isa::jalr(ZERO, RA, 0), 0x110),
        ];
        let m = mix(&recs);
        assert_eq!((m.branches, m.taken, m.backward_taken), (3, 2, 2));
        assert_eq!((m.jal, m.jalr, m.returns), (1, 1, 1));
        let [plain, jal, btfn, table, ras, ..] = Design::candidates();
        // plain: 2 taken branches, the call and the return, 2 cycles each
        assert_eq!(estimate(&plain, &recs, 5).control, 8);
        // JAL in decode: the call costs 1
        assert_eq!(estimate(&jal, &recs, 5).control, 7);
        // backward taken: 1 + 1 for the taken ones, 2 for the exit
        assert_eq!(estimate(&btfn, &recs, 5).control, 2 + 2 + 1 + 2);
        // the branch table starts from the same guesses
        assert_eq!(estimate(&table, &recs, 5).control, 2 + 2 + 1 + 2);
        // and the return predicted
        assert_eq!(estimate(&ras, &recs, 5).control, 2 + 2 + 1 + 1);
    }

    #[test]
    fn a_branch_table_learns_a_forward_branch() {
        // a forward branch taken 5 times, then not: guessed not taken until its counter
        // reaches 2 (two misses), then taken (1 each), then wrong at the end
        let beq = isa::beq(A0, A1, 16);
        let mut recs: Vec<Retire> = (0..5).map(|_| rec(0x100, beq, 0x110)).collect();
        recs.push(rec(0x100, beq, 0x104));
        let [_, _, btfn, table, ..] = Design::candidates();
        assert_eq!(table.branch_table, 2048);
        assert_eq!(estimate(&btfn, &recs, 6).control, 5 * 2);
        assert_eq!(estimate(&table, &recs, 6).control, 2 + 2 + 1 + 1 + 1 + 2);
    }

    #[test]
    fn a_branch_target_buffer_learns_a_loop() {
        // the same backward branch taken 5 times, then not: the first taken one misses (no
        // entry), the next four hit, the exit misses (counter says taken)
        let bne = isa::bne(A0, A1, -8i32);
        let mut recs: Vec<Retire> = (0..5).map(|_| rec(0x108, bne, 0x100)).collect();
        recs.push(rec(0x108, bne, 0x10c));
        let btb = Design::candidates()[6];
        assert_eq!(btb.btb_entries, 64);
        assert_eq!(estimate(&btb, &recs, 6).control, 2 + 2);
    }

    #[test]
    fn csr_instructions_empty_the_pipeline_only_where_the_design_says() {
        let recs = [straight(0, isa::csrrs(A0, isa::csr::MSTATUS, ZERO))];
        assert_eq!(mix(&recs).csr, 1);
        let [plain, _, _, _, ras, in_line, ..] = Design::candidates();
        assert_eq!(estimate(&plain, &recs, 1).serial, 2);
        assert_eq!(estimate(&ras, &recs, 1).serial, 2);
        assert_eq!(estimate(&in_line, &recs, 1).serial, 0);
    }

    #[test]
    fn compressed_instructions_decode_by_their_expansion() {
        // C.LW a0, 0(a1), then C.ADD a2, a0 (reads a0): a load-use pair, 2 bytes each
        let c_lw = u32::from(isa::c::lw(A0, A1, 0));
        let c_add = u32::from(isa::c::add(A2, A0));
        let recs = [rec(0, c_lw, 2), rec(2, c_add, 4)];
        let m = mix(&recs);
        assert_eq!((m.loads, m.load_use, m.taken), (1, 1, 0));
    }

    #[test]
    fn an_interrupt_entry_breaks_the_dependency_and_empties_the_pipeline() {
        let mut second = straight(0x40, isa::addi(A1, A0, 1));
        second.intr = true;
        let recs = [straight(0, isa::lw(A0, SP, 0)), second];
        let m = mix(&recs);
        assert_eq!((m.load_use, m.traps), (0, 1));
        assert_eq!(estimate(&Design::FOUR_STAGE, &recs, 2).serial, 2);
    }
}
