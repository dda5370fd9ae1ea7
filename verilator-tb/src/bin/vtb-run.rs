//! Runs a firmware ELF on the Verilated SoC: prints the defmt console (decoded with the ELF's
//! table) and the UART output, then the exit, cycle count, CPI and simulation speed.
#![forbid(unsafe_code)]

use clap::Parser;
use lbc_emu::{Lbc, LbcConfig};
use qemu_harness::{LineDecoder, LogFormat};
use soc_model::Retire;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;
use verilator_tb::cosim::LbcCosim;
use verilator_tb::lockstep::Lockstep;
use verilator_tb::pipeline;
use verilator_tb::soc::{CoreVariant, Event, Exit, Soc, Uart, CLOCK_HZ};

#[derive(Debug, Parser)]
#[command(about = "Run a firmware image on the Verilated softcore SoC")]
struct Args {
    /// Firmware ELF (linked at 0x8000_0000).
    elf: PathBuf,
    /// Stop after this many clock cycles.
    #[arg(long, default_value_t = 50_000_000)]
    max_cycles: u64,
    /// Bytes to send to the LBC UART at start (hex, e.g. `80a1ff`).
    #[arg(long, conflicts_with = "lbc_emu")]
    lbc_hex: Option<String>,
    /// Attach an emulated lower board with this car ID to the LBC UART.
    #[arg(long)]
    lbc_emu: Option<u8>,
    /// Check every retired instruction against the golden model instead (no UART peers).
    #[arg(long, conflicts_with_all = ["lbc_emu", "lbc_hex"])]
    lockstep: bool,
    /// Also estimate the cycles of pipelined core designs from the run's instruction stream
    /// (`verilator_tb::pipeline`; needs `--lbc-emu`).
    #[arg(long, requires = "lbc_emu")]
    pipeline: bool,
    /// The SoC's core: `dsp` (the reference core), `mulseq` (its multiplication in the
    /// divider's loop), `pipe` (the pipelined core) or `pipe-mulseq` (the HX8K's).
    #[arg(long, default_value = "dsp", value_parser = parse_core)]
    core: CoreVariant,
}

fn parse_core(s: &str) -> Result<CoreVariant, String> {
    match s {
        "dsp" => Ok(CoreVariant::Dsp),
        "mulseq" => Ok(CoreVariant::MulSeq),
        "pipe" => Ok(CoreVariant::Pipe),
        "pipe-mulseq" => Ok(CoreVariant::PipeMulSeq),
        _ => Err(format!(
            "unknown core `{s}` (dsp, mulseq, pipe, pipe-mulseq)"
        )),
    }
}

/// Runs the image in lockstep with the golden model.
fn lockstep(elf: &[u8], max_cycles: u64, core: CoreVariant) -> ExitCode {
    let mut ls = Lockstep::with_core(core);
    if let Err(e) = ls.load_elf(elf) {
        eprintln!("{e}");
        return ExitCode::from(2);
    }
    let start = Instant::now();
    let result = ls.run(u64::MAX, max_cycles, &[]);
    let wall = start.elapsed().as_secs_f64();
    match result {
        Ok(run) => {
            println!(
                "lockstep: {} instructions checked in {} cycles, 0 mismatches, exit {:?}; \
                 {:.2} M cycles/s, {:.2} M instructions/s ({wall:.2} s wall)",
                run.retired,
                run.cycles,
                run.exit,
                run.cycles as f64 / wall / 1e6,
                run.retired as f64 / wall / 1e6,
            );
            println!(
                "figures: mode=lockstep cycles={} instructions={} wall_s={wall:.3} mismatches=0",
                run.cycles, run.retired
            );
            ExitCode::SUCCESS
        }
        Err(m) => {
            println!("lockstep mismatch: {m:x?}");
            println!("figures: mode=lockstep mismatches=1");
            ExitCode::from(4)
        }
    }
}

/// The instruction mix of the run and the estimated cycles of pipelined designs.
fn print_pipeline(records: &[Retire], awake: u64) {
    let m = pipeline::mix(records);
    let pct = |n: u64| 100.0 * n as f64 / m.instructions.max(1) as f64;
    println!(
        "mix of {} instructions: branches {:.2} % ({:.2} % taken; backward {:.2} %, {:.2} % taken), \
         JAL {:.2} %, JALR {:.2} % (returns {:.2} %), loads {:.2} % (used at once {:.2} %), \
         products {:.2} % (used at once {:.2} %), CSR {:.2} %, MRET/WFI/ECALL/EBREAK {:.3} %, \
         trap entries {:.3} %",
        m.instructions,
        pct(m.branches),
        pct(m.taken),
        pct(m.backward),
        pct(m.backward_taken),
        pct(m.jal),
        pct(m.jalr),
        pct(m.returns),
        pct(m.loads),
        pct(m.load_use),
        pct(m.muls),
        pct(m.mul_use),
        pct(m.csr),
        pct(m.system),
        pct(m.traps),
    );
    println!(
        "two after: loaded words {:.2} %, products {:.2} %; shift and CSR results used at once \
         {:.2} %",
        pct(m.load_use2),
        pct(m.mul_use2),
        pct(m.late_use),
    );
    println!("| design | control | data | serial | awake cycles | CPI |");
    println!("|---|---:|---:|---:|---:|---:|");
    println!(
        "| this core | | | | {awake} | {:.3} |",
        awake as f64 / m.instructions.max(1) as f64
    );
    let designs = pipeline::Design::candidates()
        .into_iter()
        .chain(pipeline::Design::six_stage())
        .chain(pipeline::Design::front_end_steps());
    for d in designs {
        let e = pipeline::estimate(&d, records, awake);
        println!(
            "| {} | {} | {} | {} | {} | {:.3} |",
            d.name, e.control, e.data, e.serial, e.cycles, e.cpi
        );
    }
}

fn parse_hex(s: &str) -> Option<Vec<u8>> {
    if !s.len().is_multiple_of(2) {
        return None;
    }
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(s.get(i..i + 2)?, 16).ok())
        .collect()
}

fn main() -> ExitCode {
    let args = Args::parse();
    let bytes = match std::fs::read(&args.elf) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("cannot read {}: {e}", args.elf.display());
            return ExitCode::from(2);
        }
    };
    let format = match LogFormat::from_elf_bytes(&bytes, &args.elf) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("{e}");
            return ExitCode::from(2);
        }
    };
    if args.lockstep {
        return lockstep(&bytes, args.max_cycles, args.core);
    }
    let mut soc = Soc::with_core(args.core);
    if let Err(e) = soc.load_elf(&bytes) {
        eprintln!("{}: {e}", args.elf.display());
        return ExitCode::from(2);
    }
    if let Some(hex) = &args.lbc_hex {
        let Some(data) = parse_hex(hex) else {
            eprintln!("--lbc-hex: not an even-length hex string");
            return ExitCode::from(2);
        };
        soc.send(Uart::Lbc, &data);
    }
    let mut decoder = LineDecoder::new(&format);
    let mut lines = Vec::new();
    let start = Instant::now();
    let (soc, events, records) = match args.lbc_emu {
        Some(car) => {
            let lbc = Lbc::with_memory_eeprom(LbcConfig::default(), car);
            let mut cosim = LbcCosim::new(soc, lbc);
            if args.pipeline {
                cosim = cosim.with_records();
            }
            let events = cosim.run(args.max_cycles);
            let records: Vec<Retire> = cosim.records().iter().map(|(_, r)| *r).collect();
            (cosim.soc, events, records)
        }
        None => {
            soc.release();
            let events = soc.run(args.max_cycles);
            (soc, events, Vec::new())
        }
    };
    let wall = start.elapsed().as_secs_f64();
    let mut exit = None;
    for e in &events {
        match e.value {
            Event::Console(b) => decoder.push(&[b], Instant::now(), &mut lines),
            Event::Tx { uart, byte } => println!("[{:>12}] {uart:?} tx {byte:#04x}", e.cycle),
            Event::Exit(x) => exit = Some(x),
        }
        for l in lines.drain(..) {
            println!("[{:>12}] {l}", e.cycle);
        }
    }
    let cycles = soc.cycle();
    let retired = soc.retired();
    let awake = cycles.saturating_sub(soc.sleep_cycles());
    println!(
        "exit {exit:?} after {cycles} cycles ({:.3} s at {CLOCK_HZ} Hz), {retired} instructions; \
         awake {awake} cycles, CPI while awake {:.3}; {:.2} M cycles/s ({:.2} s wall)",
        cycles as f64 / f64::from(CLOCK_HZ),
        awake as f64 / retired.max(1) as f64,
        cycles as f64 / wall / 1e6,
        wall
    );
    println!(
        "figures: mode={} cycles={cycles} instructions={retired} awake={awake} wall_s={wall:.3}",
        if args.lbc_emu.is_some() {
            "cosim"
        } else {
            "free"
        }
    );
    if args.pipeline {
        print_pipeline(&records, awake);
    }
    match exit {
        Some(Exit::Pass) => ExitCode::SUCCESS,
        Some(Exit::Fail(code)) => ExitCode::from(u8::try_from(code).unwrap_or(255)),
        _ => ExitCode::from(3),
    }
}
