//! The cycle-accurate model (`soc_model`) against the RTL: the same programs, the same input at
//! the same cycles, and the model must retire every instruction in the same cycle with the
//! same record, emit every UART and console byte in the same cycle, and end with the same
//! statistics.
//!
//! - The directed programs of `tests/directed.rs` and the SoC programs of `tests/soc.rs` are
//!   checked against the model by `common::run_with` / `common::check_model` as they run.
//! - Here: the seeded random streams of `common::stream` (with the external interrupt line
//!   toggled), device programs (UART receive timeout, trigger level and overrun, THR-empty
//!   interrupts, divisor changes, CLINT mtime/mtimecmp writes, PLIC priorities, threshold,
//!   claim and complete, AMOs on device registers, a store into the next instruction), the
//!   frame window written between runs, and the acceptance test: the `softcore` firmware
//!   (`VTB_FIRMWARE`) co-simulated with `lbc-emu` and a radio-mac ground station for more than
//!   10 M cycles, through bring-up and a group maneuver, replayed into the model.
mod common;
mod ground;

use common::stream::{stream, STREAM_LEN};
use common::*;
use ground::{Ground, GroundPeer};
use lbc_emu::{Lbc, LbcConfig};
use std::cell::RefCell;
use std::rc::Rc;
use ubc_app::program::console::{Reply, Request};
use verilator_tb::cosim::LbcCosim;
use verilator_tb::isa::{self, csr, reg::*};
use verilator_tb::lockstep::{Lockstep, Stimulus};
use verilator_tb::soc::{irq, map, Event, Exit, Soc, Uart, CLOCK_HZ, RAM_BASE};

const S2: u8 = 18;
const S3: u8 = 19;
const LSR: i32 = 5;

/// Runs `p` in lockstep on the RTL with `rx` queued at cycle 0 (each `(uart, at, bytes)`),
/// demands a pass, and checks the model against it.
fn rtl_and_model(p: &Prog, rx: &[(Uart, u64, &[u8])], stimuli: &[(u64, Stimulus)]) -> Lockstep {
    let mut ls = Lockstep::new();
    ls.keep_records();
    ls.load(RAM_BASE, &p.words).expect("program fits");
    for (u, at, bytes) in rx {
        ls.soc_mut().send_at(*u, *at, bytes);
    }
    let run = ls
        .run(1_000_000, 3_000_000, stimuli)
        .unwrap_or_else(|m| panic!("lockstep: {}", describe(&m)));
    assert_eq!(
        run.exit,
        Some(Exit::Pass),
        "no pass after {} cycles: pc {:#x}, a1 {}, a3 {}",
        run.cycles,
        run.hart.pc,
        run.hart.x[A1 as usize],
        run.hart.x[A3 as usize]
    );
    let sent = ls.soc_mut().rx_log().to_vec();
    check_model(&p.words, stimuli, &sent, &run);
    ls
}

#[test]
fn random_streams_retire_in_the_same_cycles() {
    for seed in 0..40 {
        let (p, stimuli) = stream(seed);
        let mut ls = Lockstep::new();
        ls.keep_records();
        ls.load(RAM_BASE, &p.words).expect("program fits");
        let run = ls
            .run(200_000, 2_000_000, &stimuli)
            .unwrap_or_else(|m| panic!("seed {seed}: {}", describe(&m)));
        assert_eq!(run.exit, Some(Exit::Pass), "seed {seed}");
        assert!(run.retired > STREAM_LEN as u64 / 2);
        check_model(&p.words, &stimuli, &[], &run);
    }
}

/// 8N1 at divisor `div` with the FIFOs on (trigger `trig`: FCR bits 7:6), for the UART whose
/// base is in `base`.
fn uart_init(p: &mut Prog, base: u8, div: u32, trig: u32) {
    p.li(T1, 0x80).i(isa::sb(T1, base, 3));
    p.li(T1, div & 0xff)
        .i(isa::sb(T1, base, 0))
        .li(T1, div >> 8)
        .i(isa::sb(T1, base, 1));
    p.li(T1, 3).i(isa::sb(T1, base, 3));
    p.li(T1, 7 | trig << 6).i(isa::sb(T1, base, 2));
}

/// Installs a handler at the start that stores (mcause, IIR of UART0, LSR of UART0, claim) to
/// the words at S3, advances S3, drains UART0's receiver to the console, completes the claim,
/// and counts the interrupts in A1. Returns the program positioned at `main`.
fn with_uart_handler() -> Prog {
    let mut p = Prog::new();
    let jump = p.hole(1);
    let handler = p.here();
    p.li(T2, map::PLIC + 0x20_0004).i(isa::lw(A2, T2, 0));
    p.i(isa::csrr(T1, csr::MCAUSE)).i(isa::sw(T1, S3, 0));
    p.i(isa::lbu(T1, S0, 2)).i(isa::sw(T1, S3, 4));
    p.i(isa::lbu(T1, S0, LSR)).i(isa::sw(T1, S3, 8));
    p.i(isa::sw(A2, S3, 12)).i(isa::addi(S3, S3, 16));
    let drain = p.here();
    p.i(isa::lbu(T1, S0, LSR))
        .i(isa::andi(T1, T1, 1))
        .i(isa::beq(T1, 0, 20));
    p.i(isa::lbu(A0, S0, 0))
        .i(isa::sw(A0, S1, 4))
        .i(isa::addi(A3, A3, 1));
    let here = p.here();
    p.i(isa::jal(0, drain as i32 - here as i32));
    // THR-empty: mask it again (IER = RX only)
    p.li(T1, 1).i(isa::sb(T1, S0, 1));
    p.i(isa::sw(A2, T2, 0)).i(isa::addi(A1, A1, 1)).i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(T1, handler).i(isa::csrrw(0, csr::MTVEC, T1));
    p.li(S0, map::UART0)
        .li(S1, map::SIM_CTRL)
        .li(S2, map::PLIC)
        .li(S3, RAM_BASE + 0x8_0000);
    p
}

/// Receive with the FIFO trigger at 4 and at 8 bytes (the RX-data interrupt after 4 bytes,
/// the timeout interrupt for the rest), then an overrun (20 bytes without reading), at
/// divisor 8 and then 4 (the character time and the timeout change), and a THR-empty
/// interrupt; all interrupt-driven through the PLIC with WFI between.
#[test]
fn uart_receive_timeout_trigger_overrun_and_thre() {
    let mut p = with_uart_handler();
    uart_init(&mut p, S0, 8, 1);
    p.li(T1, 1).i(isa::sb(T1, S0, 1)); // IER: RX
    p.li(T1, 3).i(isa::sw(T1, S2, 4 * irq::UART0 as i32));
    p.li(T2, map::PLIC + 0x2000)
        .li(T1, 1 << irq::UART0)
        .i(isa::sw(T1, T2, 0));
    p.li(T1, 1 << 11).i(isa::csrrw(0, csr::MIE, T1));
    p.i(isa::csrrsi(0, csr::MSTATUS, 8));
    // wait for 6 bytes (trigger 4, then the timeout for the last 2)
    let wait = p.here();
    p.i(isa::WFI).li(T1, 6);
    let here = p.here();
    p.i(isa::blt(A3, T1, wait as i32 - here as i32));
    // trigger 8, divisor 4: 3 bytes come by timeout only
    p.i(isa::csrrci(0, csr::MSTATUS, 8));
    uart_init(&mut p, S0, 4, 2);
    p.i(isa::csrrsi(0, csr::MSTATUS, 8));
    let wait = p.here();
    p.i(isa::WFI).li(T1, 9);
    let here = p.here();
    p.i(isa::blt(A3, T1, wait as i32 - here as i32));
    // overrun: interrupts off, 20 bytes arrive unread
    p.i(isa::csrrci(0, csr::MSTATUS, 8));
    p.li(T1, 120_000);
    let spin = p.here();
    p.i(isa::addi(T1, T1, -1));
    let here = p.here();
    p.i(isa::bne(T1, 0, spin as i32 - here as i32));
    p.i(isa::lbu(T1, S0, LSR)).i(isa::sw(T1, S3, 0)); // OE and DR
    p.i(isa::lbu(T1, S0, LSR)).i(isa::sw(T1, S3, 4)); // OE cleared by the read
    p.i(isa::addi(S3, S3, 8));
    // THR empty: clear the FIFOs, enable it while bytes are queued, sleep until they drain
    p.li(T1, 0x87).i(isa::sb(T1, S0, 2));
    p.li(T1, 0x41).i(isa::sb(T1, S0, 0)).i(isa::sb(T1, S0, 0));
    p.li(T1, 3).i(isa::sb(T1, S0, 1));
    p.i(isa::csrrsi(0, csr::MSTATUS, 8));
    let before = p.here();
    p.i(isa::addi(T0, A1, 0));
    let wait = p.here();
    p.i(isa::WFI);
    let here = p.here();
    p.i(isa::beq(A1, T0, wait as i32 - here as i32));
    let _ = before;
    p.exit_pass();
    let burst: Vec<u8> = (0..20).collect();
    let ls = rtl_and_model(
        &p,
        &[
            (Uart::Lbc, 3_000, b"abcdef"),
            (Uart::Lbc, 40_000, b"xyz"),
            (Uart::Lbc, 80_000, &burst),
        ],
        &[],
    );
    let _ = ls;
}

/// The CLINT: mtime written (low and high word, one byte lane), read back, mtimecmp set by
/// halves, timer interrupts from WFI, msip; the PLIC's priorities, threshold and pending
/// register with both UARTs' THR-empty lines; an AMO and LR/SC on device registers; a store
/// into the next instruction's word.
#[test]
fn clint_plic_and_amos_on_devices() {
    let mut p = Prog::new();
    let jump = p.hole(1);
    let handler = p.here();
    // (x26..x29 only) record mcause and mip; push mtimecmp to the far future, clear msip;
    // claim, mask both UARTs' interrupts, complete
    let (h0, h1, h2) = (26u8, 27u8, 28u8);
    p.i(isa::csrr(h0, csr::MCAUSE)).i(isa::sw(h0, S3, 0));
    p.i(isa::csrr(h0, csr::MIP)).i(isa::sw(h0, S3, 4));
    p.i(isa::addi(S3, S3, 8)).i(isa::addi(A1, A1, 1));
    p.li(h1, map::CLINT + 0x4000)
        .li(h0, u32::MAX)
        .i(isa::sw(h0, h1, 4));
    p.li(h1, map::CLINT).i(isa::sw(0, h1, 0));
    p.li(h1, map::PLIC + 0x20_0004).i(isa::lw(h2, h1, 0));
    p.i(isa::sw(h2, S3, 0)).i(isa::addi(S3, S3, 4));
    p.li(h0, map::UART0).i(isa::sb(0, h0, 1));
    p.li(h0, map::UART1).i(isa::sb(0, h0, 1));
    p.i(isa::sw(h2, h1, 0)).i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(T1, handler).i(isa::csrrw(0, csr::MTVEC, T1));
    p.li(S3, RAM_BASE + 0x8_0000).li(S1, map::SIM_CTRL);
    // mtime: write the high word, then one byte lane of the low word; read both
    p.li(S0, map::CLINT + 0xbff8).li(T1, 0x1234_5678);
    p.i(isa::sw(T1, S0, 4)).i(isa::sb(T1, S0, 1));
    p.i(isa::lw(T1, S0, 0)).i(isa::sw(T1, S3, 0));
    p.i(isa::lw(T1, S0, 4))
        .i(isa::sw(T1, S3, 4))
        .i(isa::addi(S3, S3, 8));
    // mtimecmp = mtime + 700 (by halves), timer interrupt from WFI
    p.i(isa::lw(T1, S0, 0)).i(isa::lw(T2, S0, 4));
    p.i(isa::addi(T1, T1, 700));
    p.li(S0, map::CLINT + 0x4000);
    p.li(T0, u32::MAX).i(isa::sw(T0, S0, 4));
    p.i(isa::sw(T1, S0, 0)).i(isa::sw(T2, S0, 4));
    p.li(T1, 1 << 7 | 1 << 11 | 1 << 3)
        .i(isa::csrrw(0, csr::MIE, T1));
    p.i(isa::csrrsi(0, csr::MSTATUS, 8)).i(isa::WFI);
    // msip: set and take it
    p.li(T1, map::CLINT).li(T0, 1).i(isa::sw(T0, T1, 0));
    p.i(isa::NOP).i(isa::sw(0, T1, 0));
    // PLIC: UART1 priority 2, UART0 priority 5, threshold 1; both THR-empty lines
    p.li(S2, map::PLIC);
    p.li(T1, 5).i(isa::sw(T1, S2, 4 * irq::UART0 as i32));
    p.li(T1, 2).i(isa::sw(T1, S2, 4 * irq::UART1 as i32));
    p.li(T1, 1)
        .li(T2, map::PLIC + 0x20_0000)
        .i(isa::sw(T1, T2, 0));
    p.li(T2, map::PLIC + 0x2000)
        .li(T1, 1 << irq::UART0 | 1 << irq::UART1)
        .i(isa::sw(T1, T2, 0));
    p.i(isa::csrrci(0, csr::MSTATUS, 8));
    p.li(T1, map::UART0).li(T0, 2).i(isa::sb(T0, T1, 1));
    p.li(T1, map::UART1).i(isa::sb(T0, T1, 1));
    p.li(T2, map::PLIC + 0x1000)
        .i(isa::lw(T1, T2, 0))
        .i(isa::sw(T1, S3, 0));
    p.i(isa::addi(S3, S3, 4));
    p.i(isa::csrrsi(0, csr::MSTATUS, 8)).i(isa::NOP).i(isa::NOP);
    // AMO and LR/SC on a UART's scratch register and the PLIC threshold
    p.li(T1, map::UART0 + 4).li(T0, 0x5a00_0000);
    p.i(isa::amo_w(isa::amo::OR, A0, T1, T0))
        .i(isa::sw(A0, S3, 0));
    p.i(isa::lr_w(A0, T1)).i(isa::sc_w(A2, T1, T0));
    p.i(isa::sw(A0, S3, 4)).i(isa::sw(A2, S3, 8));
    p.li(T1, map::PLIC + 0x20_0000).li(T0, 3);
    p.i(isa::amo_w(isa::amo::ADD, A0, T1, T0))
        .i(isa::sw(A0, S3, 12));
    p.i(isa::addi(S3, S3, 16));
    p.exit_pass();
    rtl_and_model(&p, &[], &[]);
}

/// Stores into the next instruction's word, which the core has already fetched: it runs the
/// old word, unless a counter-carry cycle comes between (which fetches again). Not in
/// lockstep: the golden model has no fetch stage.
#[test]
fn store_into_the_next_instruction() {
    let mut p = Prog::new();
    p.li(T0, isa::addi(A3, A3, 100))
        .li(29, isa::addi(A3, A3, 1))
        .li(A3, 0)
        .li(A0, 0)
        .li(T2, 150);
    let top = p.here();
    p.i(isa::auipc(T1, 0))
        .i(isa::sw(T0, T1, 8))
        .i(isa::addi(A3, A3, 1))
        .i(isa::sw(29, T1, 8))
        .i(isa::addi(A0, A0, 1));
    let here = p.here();
    p.i(isa::blt(A0, T2, top as i32 - here as i32));
    p.li(S1, map::SIM_CTRL)
        .i(isa::sw(A3, S1, 4))
        .i(isa::srli(A3, A3, 8));
    p.i(isa::sw(A3, S1, 4));
    p.exit_pass();
    let mut soc = Soc::new();
    soc.load_words(RAM_BASE, &p.words).unwrap();
    soc.release();
    let (records, events) = soc.run_records(100_000);
    assert!(matches!(
        events.last().map(|e| e.value),
        Some(Event::Exit(Exit::Pass))
    ));
    let mut m = soc_model::Soc::new();
    m.load_words(RAM_BASE, &p.words).unwrap();
    let (mut out, mut trace) = (Vec::new(), Vec::new());
    m.run_until_traced(soc.cycle(), &mut out, &mut trace);
    compare_records(&records, &trace);
    assert_eq!(rtl_events(&events), model_events(&out));
    assert_eq!(m.cycle(), soc.cycle());
    // most iterations ran the old word, some (after a carry cycle) the new one
    let a3 = events
        .iter()
        .filter_map(|e| match e.value {
            Event::Console(b) => Some(u32::from(b)),
            _ => None,
        })
        .fold((0, 0), |(v, k), b| (v | b << (8 * k), k + 1))
        .0;
    let new_runs = (a3 - 150) / 99;
    assert!(new_runs > 0 && new_runs < 150, "a3 = {a3}");
}

/// Stores into the halves of a 32-bit instruction at a halfword address right after them: the
/// upper half (in the next word) and the lower half (in the same word). The instruction was
/// fetched before the store landed, so it runs as it was, except after a counter carry cycle,
/// which fetches it again (the RTL keeps the word it has and applies the store).
#[test]
fn store_into_the_halves_of_the_next_instruction() {
    const C_NOP: u16 = 0x0001;
    const T3: u8 = 28;
    const T4: u8 = 29;
    const T5: u8 = 30;
    let x = isa::addi(A3, A3, 1);
    let x_new = isa::addi(A3, A3, 100);
    let y = isa::addi(A4, A4, 1);
    let y_new = isa::addi(A5, A4, 1); // another rd: the lower half changes
    let mut p = Prog::new();
    p.li(T0, x_new >> 16)
        .li(T3, x >> 16)
        .li(T4, y_new & 0xffff)
        .li(T5, y & 0xffff)
        .li(A3, 0)
        .li(A4, 0)
        .li(A5, 0)
        .li(A0, 0)
        .li(T2, 300);
    // the loop as halfwords from `top` (t1): offsets in bytes in the comments
    let halves = |w: u32| [w as u16, (w >> 16) as u16];
    let mut h: Vec<u16> = Vec::new();
    h.extend(halves(isa::auipc(T1, 0))); // 0
    h.push(C_NOP); // 4
    h.extend(halves(isa::sh(T0, T1, 12))); // 6: x's upper half
    h.extend(halves(x)); // 10
    h.push(C_NOP); // 14
    h.extend(halves(isa::sh(T3, T1, 12))); // 16: restore it
    h.push(C_NOP); // 20
    h.extend(halves(isa::sh(T4, T1, 26))); // 22: y's lower half
    h.extend(halves(y)); // 26
    h.extend(halves(isa::sh(T5, T1, 26))); // 30: restore it
    h.push(C_NOP); // 34: 13 instructions a turn, so carries land at every offset
    h.extend(halves(isa::addi(A0, A0, 1))); // 36
    h.extend(halves(isa::blt(A0, T2, -40))); // 40
    for pair in h.chunks(2) {
        p.i(u32::from(pair[0]) | u32::from(pair[1]) << 16);
    }
    p.li(S1, map::SIM_CTRL);
    for r in [A3, A4, A5] {
        p.i(isa::sw(r, S1, 4))
            .i(isa::srli(r, r, 8))
            .i(isa::sw(r, S1, 4));
    }
    p.exit_pass();
    let mut soc = Soc::new();
    soc.load_words(RAM_BASE, &p.words).unwrap();
    soc.release();
    let (records, events) = soc.run_records(100_000);
    assert!(matches!(
        events.last().map(|e| e.value),
        Some(Event::Exit(Exit::Pass))
    ));
    let mut m = soc_model::Soc::new();
    m.load_words(RAM_BASE, &p.words).unwrap();
    let (mut out, mut trace) = (Vec::new(), Vec::new());
    m.run_until_traced(soc.cycle(), &mut out, &mut trace);
    compare_records(&records, &trace);
    assert_eq!(rtl_events(&events), model_events(&out));
    assert_eq!(m.cycle(), soc.cycle());
    let bytes: Vec<u32> = events
        .iter()
        .filter_map(|e| match e.value {
            Event::Console(b) => Some(u32::from(b)),
            _ => None,
        })
        .collect();
    let [a3, a4, a5] = [0, 1, 2].map(|k| bytes[2 * k] | bytes[2 * k + 1] << 8);
    // both instructions ran as stored by some iterations and as fetched by most
    let x_new_runs = (a3 - 300) / 99;
    assert!(x_new_runs > 0 && x_new_runs < 300, "a3 = {a3}");
    assert!(a4 > 0 && a4 < 300 && a5 > 0, "a4 = {a4}, a5 = {a5}");
}

/// A DIV and CSR writes to every register-file CSR, with an interrupt line rising during the
/// divider, and a run of WFIs woken by the test bench's line.
#[test]
fn multi_cycle_instructions_and_the_interrupt_line() {
    let mut p = Prog::new();
    let jump = p.hole(1);
    let handler = p.here();
    // return with interrupts off (the line is a level): clear MPIE
    p.li(26, 0x80).i(isa::csrrc(0, csr::MSTATUS, 26));
    p.i(isa::addi(A1, A1, 1)).i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(T1, handler).i(isa::csrrw(0, csr::MTVEC, T1));
    p.li(A0, 1_000_000).li(T0, 7);
    p.li(T2, 1 << 11).i(isa::csrrw(0, csr::MIE, T2));
    for k in 0..40 {
        p.i(isa::csrrsi(0, csr::MSTATUS, 8));
        p.i(isa::div(A2, A0, T0))
            .i(isa::csrrw(0, csr::MSCRATCH, A2));
        p.i(isa::csrrw(A3, csr::MEPC, A2))
            .i(isa::csrrs(A3, csr::MTVAL, A0));
        if k % 3 == 0 {
            p.i(isa::WFI);
        }
        p.i(isa::muldiv(6, A2, A2, T0));
    }
    p.exit_pass();
    let mut stimuli = Vec::new();
    let mut at = 100;
    for k in 0..61u64 {
        at += 37 + (k * 53) % 97;
        stimuli.push((at, Stimulus::ExternalIrq(k % 2 == 0)));
    }
    rtl_and_model(&p, &[], &stimuli);
}

/// The harness writes the frame window between runs while the core polls it (as
/// `tests/soc.rs` does on the RTL alone): same console bytes at the same cycles.
#[test]
fn frame_window_written_between_runs() {
    use verilator_tb::soc::FRAME_WINDOW_LEN;
    let last = (FRAME_WINDOW_LEN - 4) as i32;
    let mut p = Prog::new();
    p.li(S0, map::FRAME_WINDOW + (last as u32 & !0x7ff))
        .li(S1, map::SIM_CTRL)
        .li(A1, 0);
    let top = p.here();
    p.i(isa::lbu(A0, S0, last & 0x7ff));
    let here = p.here();
    p.i(isa::beq(A0, A1, (top as i32) - (here as i32)));
    p.i(isa::sw(A0, S1, 4)).i(isa::addi(A1, A0, 0)).li(T1, 3);
    let here = p.here();
    p.i(isa::bne(A0, T1, (top as i32) - (here as i32)));
    p.exit_pass();
    let mut soc = Soc::new();
    soc.load_words(RAM_BASE, &p.words).unwrap();
    soc.release();
    let mut m = soc_model::Soc::new();
    m.load_words(RAM_BASE, &p.words).unwrap();
    let (mut rtl, mut out) = (Vec::new(), Vec::new());
    for v in 1..=3u8 {
        for step in [500, 100] {
            let bytes = [v, 0xee, 0xee, 0xee];
            if step == 100 {
                soc.write_frame_window(FRAME_WINDOW_LEN - 4, &bytes)
                    .unwrap();
                m.write_frame_window(FRAME_WINDOW_LEN - 4, &bytes).unwrap();
            }
            rtl.extend(soc.run(step));
            m.run_until(soc.cycle(), &mut out);
        }
    }
    assert_eq!(rtl_events(&rtl), model_events(&out));
    assert_eq!(m.halted(), Some(&soc_model::Halt::Exit { value: 0x5555 }));
    assert_eq!(m.cycle(), soc.cycle());
}

// ---------------------------------------------------------------------- the firmware

const CAR: u8 = 3;

/// Runs `cosim` in 10 ms steps until `done` or `max_ms` pass, collecting events.
fn run_until(
    cosim: &mut LbcCosim,
    events: &mut Vec<verilator_tb::soc::Stamped<Event>>,
    max_ms: u64,
    mut done: impl FnMut(&LbcCosim, &[verilator_tb::soc::Stamped<Event>]) -> bool,
) -> bool {
    let ten_ms = u64::from(CLOCK_HZ) / 100;
    for _ in 0..max_ms / 10 {
        if done(cosim, events) {
            return true;
        }
        events.extend(cosim.run(ten_ms));
    }
    done(cosim, events)
}

fn request(
    cosim: &mut LbcCosim,
    events: &mut Vec<verilator_tb::soc::Stamped<Event>>,
    ground: &Rc<RefCell<Ground>>,
    req: &Request,
) -> Reply {
    let h = ground.borrow_mut().request(cosim.now_us(), req);
    let mut reply = None;
    run_until(cosim, events, 3_000, |_, _| {
        reply = ground.borrow_mut().answer(h);
        reply.is_some()
    });
    reply.unwrap_or_else(|| panic!("no reply to {req:?}"))
}

/// The acceptance test: the `softcore` firmware on the RTL with `lbc-emu` (car 3) on the LBC
/// UART and a radio-mac ground station on the radio UART: bring-up, a status request, a
/// group maneuver (go-to) started over the radio and driven for a while, 10 M cycles and
/// more. Every byte the RTL received is replayed into the model at the cycle it was sent;
/// the model must retire every instruction in the same cycle, emit the same UART bytes (both
/// ports) and console bytes in the same cycles, and end with the same statistics.
#[test]
fn firmware_on_the_model_matches_the_rtl() {
    let Some(path) = std::env::var_os("VTB_FIRMWARE") else {
        eprintln!("VTB_FIRMWARE not set: skipping the firmware test (build it with `cargo xtask fw --board softcore`)");
        return;
    };
    let elf = std::fs::read(&path).expect("VTB_FIRMWARE is readable");
    let mut soc = Soc::new();
    soc.load_elf(&elf).expect("a softcore image");
    let ground = Rc::new(RefCell::new(Ground::new(CAR, false)));
    let mut cosim = LbcCosim::new(soc, Lbc::with_memory_eeprom(LbcConfig::default(), CAR))
        .with_radio(Box::new(GroundPeer(Rc::clone(&ground))))
        .with_records();
    let mut events = Vec::new();
    let wall = std::time::Instant::now();
    // bring-up: the LBC streams with the drive enabled
    let up = run_until(&mut cosim, &mut events, 3_000, |c, _| {
        c.lbc.streaming() && c.lbc.drive_enabled()
    });
    assert!(up, "the LBC was not brought up");
    events.extend(cosim.run(u64::from(CLOCK_HZ) / 5));
    let status = match request(&mut cosim, &mut events, &ground, &Request::Status) {
        Reply::Status(s) => s,
        other => panic!("status: {other:?}"),
    };
    assert_eq!(status.car_id, CAR);
    let go = Request::GroupStart(maneuvers::GoTo::params(300, 600, 200).unwrap());
    let reply = request(&mut cosim, &mut events, &ground, &go);
    assert_eq!(reply, Reply::GroupStarted);
    let pose0 = cosim.lbc.vehicle().pose();
    events.extend(cosim.run(u64::from(CLOCK_HZ) / 2));
    if cosim.soc.cycle() < 10_000_000 {
        events.extend(cosim.run(10_000_000 - cosim.soc.cycle()));
    }
    let pose1 = cosim.lbc.vehicle().pose();
    assert_ne!(
        (pose0.x_mm, pose0.y_mm),
        (pose1.x_mm, pose1.y_mm),
        "the car drove the maneuver"
    );
    let rtl_wall = wall.elapsed();
    assert!(
        !events.iter().any(|e| matches!(e.value, Event::Exit(_))),
        "the firmware exited"
    );
    let end = cosim.soc.cycle();
    let rtl_stats = soc_model::Stats {
        cycles: end,
        sleep_cycles: cosim.soc.sleep_cycles(),
        retired: cosim.soc.retired(),
    };

    // the model, fed the same bytes at the same cycles
    let wall = std::time::Instant::now();
    let mut m = soc_model::Soc::new();
    m.load_elf(&elf).expect("the model loads the image");
    let (mut out, mut trace) = (Vec::new(), Vec::new());
    for r in cosim.soc.rx_log() {
        let halt = m.run_until_traced(r.called_at, &mut out, &mut trace);
        assert_eq!(halt, None, "model halted at {}", m.cycle());
        m.send_at(model_port(r.uart), r.at, &[r.byte]);
    }
    let halt = m.run_until_traced(end, &mut out, &mut trace);
    let model_wall = wall.elapsed();
    assert_eq!(halt, None);
    compare_records(cosim.records(), &trace);
    let rtl_ev = rtl_events(&events);
    let model_ev = model_events(&out);
    if let Some(k) = (0..rtl_ev.len().min(model_ev.len())).find(|&k| rtl_ev[k] != model_ev[k]) {
        panic!(
            "event {k} differs: RTL {:?}, model {:?}",
            rtl_ev[k], model_ev[k]
        );
    }
    assert_eq!(rtl_ev.len(), model_ev.len(), "event counts");
    assert_eq!(m.stats(), rtl_stats, "statistics: model vs RTL");
    let count = |p: Uart| {
        rtl_ev
            .iter()
            .filter(|(_, e)| matches!(e, Event::Tx { uart, .. } if *uart == p))
            .count()
    };
    eprintln!(
        "{end} cycles, {} instructions, {} sleep cycles; {} LBC bytes, {} radio bytes, {} console \
         bytes, {} bytes received: identical. RTL {:.1} s, model {:.2} s",
        rtl_stats.retired,
        rtl_stats.sleep_cycles,
        count(Uart::Lbc),
        count(Uart::Radio),
        rtl_ev.len() - count(Uart::Lbc) - count(Uart::Radio),
        cosim.soc.rx_log().len(),
        rtl_wall.as_secs_f64(),
        model_wall.as_secs_f64(),
    );
}

/// CPU time of this thread in nanoseconds (the machine is shared: wall time depends on the
/// other load, CPU time much less).
fn cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse().ok())
        .unwrap_or(0)
}

/// The model alone (no RTL) as one car of the arena: the firmware with `lbc-emu` and a ground
/// station, exchanged every half character time, through bring-up, a status request and a
/// go-to group maneuver, for 60 M cycles (4.07 s of SoC time). Prints the model's speed: the
/// whole co-simulation, and the model alone (the same input replayed into a fresh SoC, best
/// of 3), in CPU time. `cargo test -p verilator-tb --release --test soc_model -- --ignored
/// --nocapture model_speed` (needs `VTB_FIRMWARE`).
#[test]
#[ignore]
fn model_speed_firmware_maneuver() {
    use verilator_tb::cosim::{cycles_to_us, us_to_cycles, SerialPeer, SLICE_CYCLES};
    let Some(path) = std::env::var_os("VTB_FIRMWARE") else {
        eprintln!("VTB_FIRMWARE not set: skipping");
        return;
    };
    let elf = std::fs::read(&path).expect("VTB_FIRMWARE is readable");
    let cycles = 60_000_000;
    let mut m = soc_model::Soc::new();
    m.load_elf(&elf).expect("a softcore image");
    let mut lbc = Lbc::with_memory_eeprom(LbcConfig::default(), CAR);
    let ground = Rc::new(RefCell::new(Ground::new(CAR, false)));
    let mut radio = GroundPeer(Rc::clone(&ground));
    let mut sends = Vec::new();
    let (mut out, mut scratch) = (Vec::new(), Vec::new());
    let mut pending: Option<radio_mac::RequestHandle> = None;
    let mut stage = 0;
    let cpu0 = cpu_ns();
    while m.cycle() < cycles {
        let end = (m.cycle() + SLICE_CYCLES).min(cycles);
        out.clear();
        assert_eq!(m.run_until(end, &mut out), None);
        for s in &out {
            let t = cycles_to_us(s.cycle);
            match s.output {
                soc_model::Output::Tx {
                    port: soc_model::Port::Lbc,
                    byte,
                } => lbc.receive(t, byte),
                soc_model::Output::Tx { byte, .. } => radio.receive(t, byte),
                soc_model::Output::Console(_) => {}
            }
        }
        let now = cycles_to_us(m.cycle());
        for (port, peer) in [
            (soc_model::Port::Lbc, &mut lbc as &mut dyn SerialPeer),
            (soc_model::Port::Radio, &mut radio),
        ] {
            scratch.clear();
            peer.advance(now, &mut scratch);
            for &(t, b) in &scratch {
                m.send_at(port, us_to_cycles(t), &[b]);
                sends.push((m.cycle(), port, us_to_cycles(t), b));
            }
        }
        // the script: status once the LBC streams, then the maneuver
        if let Some(h) = pending {
            if let Some(reply) = ground.borrow_mut().answer(h) {
                pending = None;
                if stage == 2 {
                    assert_eq!(reply, Reply::GroupStarted);
                }
            }
        } else if stage == 0 && lbc.streaming() && lbc.drive_enabled() {
            pending = Some(ground.borrow_mut().request(now, &Request::Status));
            stage = 1;
        } else if stage == 1 {
            let go = Request::GroupStart(maneuvers::GoTo::params(300, 600, 200).unwrap());
            pending = Some(ground.borrow_mut().request(now, &go));
            stage = 2;
        }
    }
    let all = (cpu_ns() - cpu0) as f64 / 1e9;
    assert_eq!(stage, 2, "the maneuver started");
    let st = m.stats();
    let mut alone = f64::MAX;
    for _ in 0..3 {
        let mut r = soc_model::Soc::new();
        r.load_elf(&elf).unwrap();
        let t0 = cpu_ns();
        for &(called, port, at, b) in &sends {
            r.run_until(called, &mut out);
            r.send_at(port, at, &[b]);
        }
        r.run_until(cycles, &mut out);
        alone = alone.min((cpu_ns() - t0) as f64 / 1e9);
        assert_eq!(r.stats(), st, "the replay is the same run");
    }
    let awake = st.cycles - st.sleep_cycles;
    println!(
        "firmware maneuver on the model: {cycles} cycles, {} instructions, {awake} awake cycles; \
         co-simulation {all:.3} s CPU ({:.0} M cycles/s, {:.0}x real time); the model alone \
         {alone:.3} s ({:.0} M cycles/s, {:.1} M instructions/s)",
        st.retired,
        cycles as f64 / all / 1e6,
        cycles as f64 / CLOCK_HZ as f64 / all,
        cycles as f64 / alone / 1e6,
        st.retired as f64 / alone / 1e6,
    );
    println!(
        "figures: mode=model-maneuver cycles={cycles} instructions={} sleep_cycles={} cpu_s={all:.3} model_cpu_s={alone:.3}",
        st.retired, st.sleep_cycles
    );
}
