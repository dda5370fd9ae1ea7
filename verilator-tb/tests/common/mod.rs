//! Program builder shared by the integration tests.
#![allow(dead_code)]

use verilator_tb::isa::{self, reg::*};
use verilator_tb::lockstep::{Lockstep, Mismatch, Run, Stimulus};
use verilator_tb::soc::{map, Exit, RAM_BASE};

/// A program assembled at RAM_BASE.
#[derive(Debug, Default, Clone)]
pub struct Prog {
    pub words: Vec<u32>,
}

impl Prog {
    pub fn new() -> Self {
        Self::default()
    }
    /// Address of the next instruction.
    pub fn here(&self) -> u32 {
        RAM_BASE + 4 * self.words.len() as u32
    }
    pub fn i(&mut self, w: u32) -> &mut Self {
        self.words.push(w);
        self
    }
    pub fn li(&mut self, rd: u8, v: u32) -> &mut Self {
        self.words.extend(isa::li(rd, v));
        self
    }
    /// Writes the pass value to the exit register and spins.
    pub fn exit_pass(&mut self) -> &mut Self {
        self.li(T0, map::SIM_CTRL)
            .li(T1, 0x5555)
            .i(isa::sw(T1, T0, 0))
            .i(isa::jal(0, 0))
    }
    /// Reserves `n` words and returns the index of the first, for patching.
    pub fn hole(&mut self, n: usize) -> usize {
        let at = self.words.len();
        self.words.extend(std::iter::repeat_n(isa::NOP, n));
        at
    }
    pub fn addr_of(&self, index: usize) -> u32 {
        RAM_BASE + 4 * index as u32
    }
}

/// Runs `prog` in lockstep and demands a clean exit.
pub fn run_pass(prog: &Prog) -> (Run, Lockstep) {
    run_with(prog, &[])
}

pub fn run_with(prog: &Prog, stimuli: &[(u64, Stimulus)]) -> (Run, Lockstep) {
    let mut ls = Lockstep::new();
    ls.load(RAM_BASE, &prog.words).expect("program fits");
    let run = match ls.run(100_000, 1_000_000, stimuli) {
        Ok(r) => r,
        Err(m) => panic!("lockstep mismatch: {}", describe(&m)),
    };
    assert_eq!(run.exit, Some(Exit::Pass), "program did not pass: {run:?}");
    (run, ls)
}

pub fn describe(m: &Mismatch) -> String {
    match m {
        Mismatch::Record { rtl, model } => format!("\n rtl   {rtl:x?}\n model {model:x?}"),
        other => format!("{other:x?}"),
    }
}
