//! Speed of the model, on one host core:
//! `cargo test -p soc-model --release --test speed -- --ignored --nocapture`.
//! Each prints a `figures:` line.
//!
//! - `busy_loop`: a loop of mul/sw/lw/xor/addi/srli/jal (the RTL benchmark's), never idle.
//! - `firmware_with_lbc_emu`: the `softcore` firmware (`SOC_MODEL_FIRMWARE` or
//!   `VTB_FIRMWARE`) with `lbc-emu` (car 3) on its LBC UART, exchanged every half character
//!   time, for 60 M cycles (4.07 s of SoC time): one idle-ish car.
use lbc_emu::{Lbc, LbcConfig};
use soc_model::{isa, Output, Port, Soc, CHAR_CYCLES, CLOCK_HZ, RAM_BASE};
use std::time::Instant;

/// CPU time of this thread in nanoseconds (the machine is shared: wall time depends on the
/// other load, CPU time much less).
fn cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

#[test]
#[ignore]
fn busy_loop() {
    use isa::reg::*;
    let mut w = Vec::new();
    w.extend(isa::li(S0, RAM_BASE + 0x8_0000));
    w.extend(isa::li(A0, 1));
    let top = w.len();
    w.extend([
        isa::mul(A1, A0, A0),
        isa::sw(A1, S0, 0),
        isa::lw(A2, S0, 0),
        isa::xor(A0, A0, A2),
        isa::addi(A0, A0, 7),
        isa::srli(A3, A0, 3),
    ]);
    let here = w.len();
    w.push(isa::jal(0, 4 * (top as i32 - here as i32)));
    let mut soc = Soc::new();
    soc.load_words(RAM_BASE, &w).unwrap();
    let cycles = 500_000_000;
    let mut out = Vec::new();
    let start = Instant::now();
    let cpu0 = cpu_ns();
    soc.run_until(cycles, &mut out);
    let cpu = (cpu_ns() - cpu0) as f64 / 1e9;
    let s = start.elapsed().as_secs_f64();
    let st = soc.stats();
    println!(
        "busy loop: {} instructions in {cycles} cycles (CPI {:.3}); CPU {cpu:.2} s: {:.1} M \
         instructions/s, {:.1} M cycles/s (wall {s:.2} s: {:.1} M instructions/s)",
        st.retired,
        cycles as f64 / st.retired as f64,
        st.retired as f64 / cpu / 1e6,
        cycles as f64 / cpu / 1e6,
        st.retired as f64 / s / 1e6,
    );
    println!(
        "figures: mode=model-busy cycles={cycles} instructions={} cpu_s={cpu:.3} wall_s={s:.3}",
        st.retired
    );
}

fn cycles_to_us(c: u64) -> u64 {
    c * 1_000_000 / CLOCK_HZ
}

fn us_to_cycles(us: u64) -> u64 {
    (us * CLOCK_HZ).div_ceil(1_000_000)
}

#[test]
#[ignore]
fn firmware_with_lbc_emu() {
    let Some(path) =
        std::env::var_os("SOC_MODEL_FIRMWARE").or_else(|| std::env::var_os("VTB_FIRMWARE"))
    else {
        eprintln!("SOC_MODEL_FIRMWARE / VTB_FIRMWARE not set: skipping");
        return;
    };
    let elf = std::fs::read(path).expect("firmware readable");
    let mut soc = Soc::new();
    soc.load_elf(&elf).expect("a softcore image");
    let mut lbc = Lbc::with_memory_eeprom(LbcConfig::default(), 3);
    let cycles = 60_000_000;
    let slice = CHAR_CYCLES / 2;
    let (mut out, mut tx) = (Vec::new(), Vec::new());
    let (mut lbc_bytes, mut console) = (0u64, 0u64);
    let start = Instant::now();
    let cpu0 = cpu_ns();
    let mut sends = Vec::new();
    while soc.cycle() < cycles {
        let end = (soc.cycle() + slice).min(cycles);
        out.clear();
        let halt = soc.run_until(end, &mut out);
        assert!(halt.is_none(), "{halt:?}");
        for s in &out {
            match s.output {
                Output::Tx {
                    port: Port::Lbc,
                    byte,
                } => {
                    lbc.push_rx(cycles_to_us(s.cycle), &[byte]);
                    lbc_bytes += 1;
                }
                Output::Tx { .. } => {}
                Output::Console(_) => console += 1,
            }
        }
        let now = cycles_to_us(soc.cycle());
        lbc.step_until(now);
        tx.clear();
        while let Some(b) = lbc.pop_tx(now) {
            tx.push(b);
        }
        for &(t, b) in &tx {
            soc.send_at(Port::Lbc, us_to_cycles(t), &[b]);
            sends.push((soc.cycle(), us_to_cycles(t), b));
        }
    }
    let s = start.elapsed().as_secs_f64();
    let cpu = (cpu_ns() - cpu0) as f64 / 1e9;
    // the model alone: the same input replayed into a fresh SoC (best of 5)
    let mut model = f64::MAX;
    let mut again = Soc::new();
    for _ in 0..5 {
        again = Soc::new();
        again.load_elf(&elf).unwrap();
        let cpu0 = cpu_ns();
        for &(called, at, b) in &sends {
            again.run_until(called, &mut out);
            again.send_at(Port::Lbc, at, &[b]);
        }
        again.run_until(cycles, &mut out);
        model = model.min((cpu_ns() - cpu0) as f64 / 1e9);
    }
    assert_eq!(again.stats(), soc.stats(), "the replay is the same run");
    let st = soc.stats();
    assert!(lbc.streaming(), "the firmware brought the LBC up");
    let awake = st.cycles - st.sleep_cycles;
    println!(
        "firmware + lbc-emu: {cycles} cycles ({:.2} s of SoC time), {} instructions, {awake} awake \
         cycles (CPI awake {:.3}), {lbc_bytes} LBC bytes sent, {console} console bytes; CPU \
         {cpu:.3} s with lbc-emu ({:.0} M cycles/s, {:.0}x real time); the model alone \
         {model:.3} s ({:.0} M cycles/s, {:.1} M instructions/s); wall {s:.3} s",
        cycles as f64 / CLOCK_HZ as f64,
        st.retired,
        awake as f64 / st.retired as f64,
        cycles as f64 / cpu / 1e6,
        cycles as f64 / CLOCK_HZ as f64 / cpu,
        cycles as f64 / model / 1e6,
        st.retired as f64 / model / 1e6,
    );
    println!(
        "figures: mode=model-firmware cycles={cycles} instructions={} sleep_cycles={} cpu_s={cpu:.3} model_cpu_s={model:.3} wall_s={s:.3}",
        st.retired, st.sleep_cycles
    );
}
