//! Program builder shared by the integration tests.
#![allow(dead_code)]

pub mod stream;

use verilator_tb::isa::{self, reg::*};
use verilator_tb::lockstep::{Lockstep, Mismatch, Run, Stimulus};
use verilator_tb::soc::{map, CoreVariant, Event, Exit, RxSend, Stamped, Uart, RAM_BASE};

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

/// Runs `prog` in lockstep with the stimuli, demands a clean exit, and checks the
/// cycle-accurate model (`soc_model`) against the run (see [`check_model`]). The other core
/// variants run it too, in lockstep (their cycles differ from the model's).
pub fn run_with(prog: &Prog, stimuli: &[(u64, Stimulus)]) -> (Run, Lockstep) {
    for core in CoreVariant::ALL
        .into_iter()
        .filter(|c| *c != CoreVariant::Dsp)
    {
        let mut ls = Lockstep::with_core(core);
        ls.load(RAM_BASE, &prog.words).expect("program fits");
        match ls.run(100_000, 4_000_000, stimuli) {
            Ok(r) => assert_eq!(
                r.exit,
                Some(Exit::Pass),
                "program did not pass on {core:?}: {r:?}"
            ),
            Err(m) => panic!("lockstep mismatch on {core:?}: {}", describe(&m)),
        }
    }
    let mut ls = Lockstep::new();
    ls.keep_records();
    ls.load(RAM_BASE, &prog.words).expect("program fits");
    let run = match ls.run(100_000, 1_000_000, stimuli) {
        Ok(r) => r,
        Err(m) => panic!("lockstep mismatch: {}", describe(&m)),
    };
    assert_eq!(run.exit, Some(Exit::Pass), "program did not pass: {run:?}");
    let rx = ls.soc_mut().rx_log().to_vec();
    check_model(&prog.words, stimuli, &rx, &run);
    (run, ls)
}

/// Runs the program on the cycle-accurate model with the same stimuli and receiver input
/// (replayed at the cycles the RTL got them) and demands the RTL run's every retirement
/// record with the same cycle stamp, the same events in the same cycles, and the same
/// cycle count.
pub fn check_model(words: &[u32], stimuli: &[(u64, Stimulus)], rx: &[RxSend], run: &Run) {
    let mut m = soc_model::Soc::new();
    m.load_words(RAM_BASE, words).expect("program fits");
    // inputs in cycle order: stimuli apply before their cycle, sends at their call's cycle
    let mut inputs: Vec<(u64, Option<Stimulus>, Option<RxSend>)> = stimuli
        .iter()
        .map(|(at, s)| (*at, Some(*s), None))
        .chain(rx.iter().map(|r| (r.called_at, None, Some(*r))))
        .collect();
    inputs.sort_by_key(|i| i.0);
    let (mut out, mut trace) = (Vec::new(), Vec::new());
    for (at, stim, send) in inputs {
        m.run_until_traced(at, &mut out, &mut trace);
        if let Some(Stimulus::ExternalIrq(level)) = stim {
            m.set_external_irq(level);
        }
        if let Some(r) = send {
            m.send_at(model_port(r.uart), r.at, &[r.byte]);
        }
    }
    let halt = m.run_until_traced(run.cycles, &mut out, &mut trace);
    compare_records(&run.records, &trace);
    let mut events = model_events(&out);
    if let Some(soc_model::Halt::Exit { value }) = halt {
        events.push((m.cycle(), Event::Exit(Exit::decode(value))));
    }
    let rtl: Vec<(u64, Event)> = run.events.iter().map(|e| (e.cycle, e.value)).collect();
    assert_eq!(rtl, events, "events: RTL vs model");
    assert_eq!(m.cycle(), run.cycles, "cycles: RTL vs model");
}

pub fn model_port(u: Uart) -> soc_model::Port {
    match u {
        Uart::Lbc => soc_model::Port::Lbc,
        Uart::Radio => soc_model::Port::Radio,
    }
}

/// The model's outputs as the RTL harness's events.
pub fn model_events(out: &[soc_model::Stamped]) -> Vec<(u64, Event)> {
    out.iter()
        .map(|s| {
            let e = match s.output {
                soc_model::Output::Tx { port, byte } => Event::Tx {
                    uart: match port {
                        soc_model::Port::Lbc => Uart::Lbc,
                        soc_model::Port::Radio => Uart::Radio,
                    },
                    byte,
                },
                soc_model::Output::Console(b) => Event::Console(b),
            };
            (s.cycle, e)
        })
        .collect()
}

/// The RTL's events without the exit, as pairs.
pub fn rtl_events(events: &[Stamped<Event>]) -> Vec<(u64, Event)> {
    events
        .iter()
        .filter(|e| !matches!(e.value, Event::Exit(_)))
        .map(|e| (e.cycle, e.value))
        .collect()
}

/// Demands the same records with the same stamps; reports the first difference with the
/// records around it.
pub fn compare_records(rtl: &[(u64, soc_model::Retire)], model: &[soc_model::Retired]) {
    let n = rtl.len().min(model.len());
    for k in 0..n {
        let (c, r) = rtl[k];
        let m = model[k];
        if c != m.cycle || r != m.retire {
            let from = k.saturating_sub(3);
            let mut ctx = String::new();
            for j in from..=k {
                ctx += &format!(
                    "\n  #{j}: rtl   @{} {:x?}\n       model @{} {:x?}",
                    rtl[j].0, rtl[j].1, model[j].cycle, model[j].retire
                );
            }
            panic!("record {k} differs (RTL vs model):{ctx}");
        }
    }
    assert_eq!(
        rtl.len(),
        model.len(),
        "record counts: RTL vs model (last RTL {:x?}, last model {:x?})",
        rtl.last(),
        model.last()
    );
}

pub fn describe(m: &Mismatch) -> String {
    match m {
        Mismatch::Record { rtl, model } => format!("\n rtl   {rtl:x?}\n model {model:x?}"),
        other => format!("{other:x?}"),
    }
}
