//! Unit and property tests of the model. The model is checked against the RTL itself in
//! `verilator-tb` (`tests/soc_model.rs` and every directed and SoC test there); these tests
//! pin the device timing rules, that waiting in WFI by jumps equals waiting cycle by cycle,
//! that no input makes the model panic, and that the executor agrees with the reference
//! [`Hart`] on random instruction streams.

use crate::hart::{Bus, Hart};
use crate::isa::{self, csr, reg::*};
use crate::*;
use proptest::prelude::*;

/// A program assembled at RAM_BASE.
#[derive(Default)]
struct P(Vec<u32>);

impl P {
    fn here(&self) -> u32 {
        RAM_BASE + 4 * self.0.len() as u32
    }
    fn i(&mut self, w: u32) -> &mut Self {
        self.0.push(w);
        self
    }
    fn li(&mut self, rd: u8, v: u32) -> &mut Self {
        self.0.extend(isa::li(rd, v));
        self
    }
    /// Branch/jump offset from here to `to`.
    fn off(&self, to: u32) -> i32 {
        to.wrapping_sub(self.here()) as i32
    }
    fn exit_pass(&mut self) -> &mut Self {
        self.li(T0, map::SIM_CTRL)
            .li(T1, 0x5555)
            .i(isa::sw(T1, T0, 0))
            .i(isa::jal(0, 0))
    }
    fn soc(&self) -> Soc {
        let mut s = Soc::new();
        s.load_words(RAM_BASE, &self.0).expect("fits");
        s
    }
}

const S2: u8 = 18;

fn uart_init(p: &mut P, base: u8) {
    p.li(T1, 0x80).i(isa::sb(T1, base, 3));
    p.li(T1, 8).i(isa::sb(T1, base, 0)).i(isa::sb(0, base, 1));
    p.li(T1, 3).i(isa::sb(T1, base, 3));
    p.li(T1, 7).i(isa::sb(T1, base, 2));
}

fn run_all(s: &mut Soc, until: u64) -> (Vec<Stamped>, Vec<Retired>, Option<Halt>) {
    let (mut out, mut trace) = (Vec::new(), Vec::new());
    let h = s.run_until_traced(until, &mut out, &mut trace);
    (out, trace, h)
}

#[test]
fn uart_bytes_leave_when_their_stop_bit_ends() {
    let mut p = P::default();
    p.li(S0, map::UART1);
    uart_init(&mut p, S0);
    let store_at = p.0.len() + 2;
    p.li(T1, u32::from(b'A')).i(isa::sb(T1, S0, 0));
    p.li(T1, u32::from(b'B')).i(isa::sb(T1, S0, 0));
    p.exit_pass();
    // the program exits before the bytes leave: run it without the exit
    let n = p.0.len();
    p.0.truncate(n - 5);
    p.i(isa::jal(0, 0));
    let mut s = p.soc();
    let (out, trace, _) = run_all(&mut s, 5000);
    let first = trace
        .iter()
        .find(|r| r.retire.pc_rdata == RAM_BASE + 4 * store_at as u32)
        .expect("the first store retired");
    let tx: Vec<(u64, Output)> = out.iter().map(|o| (o.cycle, o.output)).collect();
    // written in cycle c (stamp c + 1), in the FIFO at c + 1, in the shifter at c + 2, out
    // 1280 clocks later
    assert_eq!(
        tx,
        [
            (
                first.cycle + CHAR_CYCLES + 1,
                Output::Tx {
                    port: Port::Radio,
                    byte: b'A'
                }
            ),
            (
                first.cycle + 2 * CHAR_CYCLES + 1,
                Output::Tx {
                    port: Port::Radio,
                    byte: b'B'
                }
            ),
        ]
    );
    assert!(matches!(
        s.halted(),
        Some(Halt::Stuck {
            reason: StuckReason::SpinWithoutInterrupt,
            ..
        })
    ));
}

/// Polls LSR and stores LSR, IIR and the byte for each of `n` bytes to 0x8008_0000...
fn rx_probe(n: u32, lsr_wait: bool) -> P {
    let mut p = P::default();
    p.li(S0, map::UART0).li(S1, RAM_BASE + 0x8_0000).li(A1, n);
    uart_init(&mut p, S0);
    p.li(T1, 1).i(isa::sb(T1, S0, 1)); // IER: RX (for the IIR)
    let top = p.here();
    if lsr_wait {
        p.i(isa::lbu(T1, S0, 5)).i(isa::andi(T1, T1, 1));
        let o = p.off(top);
        p.i(isa::beq(T1, 0, o));
    }
    p.i(isa::lbu(T2, S0, 2)).i(isa::sw(T2, S1, 0));
    p.i(isa::lbu(T2, S0, 0)).i(isa::sw(T2, S1, 4));
    p.i(isa::addi(S1, S1, 8)).i(isa::addi(A1, A1, -1));
    let o = p.off(top);
    p.i(isa::bne(A1, 0, o));
    p.exit_pass();
    p
}

#[test]
fn uart_receive_timeout_after_four_character_times() {
    // trigger level 1 (FCR 7): a byte raises RX data at once
    let p = rx_probe(2, true);
    let mut s = p.soc();
    s.send_at(Port::Lbc, 1000, b"xy");
    let (_, _, h) = run_all(&mut s, 100_000);
    assert_eq!(h, Some(Halt::Exit { value: 0x5555 }));
    let w = |a: u32| s.ram_word(RAM_BASE + 0x8_0000 + a).unwrap();
    assert_eq!(
        [w(0), w(4), w(8), w(12)],
        [0xc4, u32::from(b'x'), 0xc4, u32::from(b'y')]
    );

    // trigger 4 (FCR 0x47): one byte waits for the timeout, 4 x 1280 clocks after it arrived
    let mut p = P::default();
    p.li(S0, map::UART0);
    uart_init(&mut p, S0);
    p.li(T1, 0x47).i(isa::sb(T1, S0, 2));
    p.li(T1, 1).i(isa::sb(T1, S0, 1));
    let top = p.here();
    p.i(isa::lbu(T1, S0, 2))
        .i(isa::andi(T1, T1, 0xf))
        .li(T2, 0xc);
    let o = p.off(top);
    p.i(isa::bne(T1, T2, o));
    p.li(S1, map::SIM_CTRL).i(isa::sw(T1, S1, 4));
    p.exit_pass();
    let mut s = p.soc();
    s.send_at(Port::Lbc, 2000, b"z");
    let (out, _, _) = run_all(&mut s, 100_000);
    // the byte enters the FIFO at 2001; the timeout holds from 2001 + 5120 on; the poll
    // loop sees it within its 5-cycle period, the console write a cycle later
    let at = out[0].cycle;
    assert!(
        (2001 + 4 * CHAR_CYCLES..2001 + 4 * CHAR_CYCLES + 16).contains(&at),
        "{at}"
    );
}

#[test]
fn uart_overrun_is_flagged_and_cleared_by_reading_lsr() {
    let mut p = P::default();
    p.li(S0, map::UART0).li(S1, RAM_BASE + 0x8_0000);
    uart_init(&mut p, S0);
    p.li(T1, 30_000);
    let top = p.here();
    p.i(isa::addi(T1, T1, -1));
    let o = p.off(top);
    p.i(isa::bne(T1, 0, o));
    p.i(isa::lbu(T2, S0, 5)).i(isa::sw(T2, S1, 0));
    p.i(isa::lbu(T2, S0, 5)).i(isa::sw(T2, S1, 4));
    p.exit_pass();
    let mut s = p.soc();
    s.send_at(Port::Lbc, 100, &[0x55; 18]);
    let (_, _, h) = run_all(&mut s, 1_000_000);
    assert_eq!(h, Some(Halt::Exit { value: 0x5555 }));
    let lsr0 = s.ram_word(RAM_BASE + 0x8_0000).unwrap();
    let lsr1 = s.ram_word(RAM_BASE + 0x8_0004).unwrap();
    assert_eq!(lsr0 & 0x03, 0x03, "DR and OE: {lsr0:#x}");
    assert_eq!(lsr1 & 0x03, 0x01, "OE cleared by the read: {lsr1:#x}");
}

#[test]
fn send_at_paces_bytes_one_character_apart() {
    let mut s = Soc::new();
    s.send_at(Port::Radio, 10, b"ab");
    s.send_at(Port::Radio, 0, b"c");
    let q: Vec<u64> = s.uart[1].queued().collect();
    assert_eq!(q, [10, 10 + CHAR_CYCLES, 10 + 2 * CHAR_CYCLES]);
    let mut out = Vec::new();
    s.run_until(20_000, &mut out);
    s.send_at(Port::Lbc, 5, b"d");
    assert_eq!(s.uart[0].queued().collect::<Vec<_>>(), [20_000]);
}

/// The timer interrupt wakes a WFI: mtime counts cycles from reset, and the handler runs two
/// cycles after the WFI retires in the cycle mtime reaches mtimecmp.
#[test]
fn clint_timer_wakes_wfi_at_mtimecmp() {
    let mut p = P::default();
    let jump = p.0.len();
    p.i(0);
    let handler = p.here();
    p.li(T2, map::CLINT + 0xbff8).i(isa::lw(A0, T2, 0));
    p.li(T2, map::CLINT + 0x4000)
        .li(T1, u32::MAX)
        .i(isa::sw(T1, T2, 4));
    p.i(isa::MRET);
    let main = p.here();
    p.0[jump] = isa::jal(0, (main - RAM_BASE) as i32);
    p.li(T1, handler).i(isa::csrrw(0, csr::MTVEC, T1));
    p.li(T2, map::CLINT + 0x4000).li(T1, 50_000);
    p.i(isa::sw(0, T2, 4)).i(isa::sw(T1, T2, 0));
    p.li(T1, 1 << 7).i(isa::csrrw(0, csr::MIE, T1));
    p.i(isa::csrrsi(0, csr::MSTATUS, 8));
    let wfi = p.here();
    p.i(isa::WFI);
    p.exit_pass();
    let mut s = p.soc();
    let (_, trace, h) = run_all(&mut s, 100_000);
    assert_eq!(h, Some(Halt::Exit { value: 0x5555 }));
    let w = trace.iter().find(|r| r.retire.pc_rdata == wfi).unwrap();
    assert_eq!(
        w.cycle, 50_001,
        "WFI retires in cycle 50 000, when mtip rises"
    );
    // a carry cycle may come after it; the handler's first instruction is intr
    let h0 = trace.iter().find(|r| r.retire.intr).unwrap();
    assert_eq!(h0.retire.pc_rdata, handler);
    assert!(
        (w.cycle + 3..=w.cycle + 5).contains(&h0.cycle),
        "{}",
        h0.cycle
    );
    // mtime read by the handler: the cycle of that load
    let load = trace
        .iter()
        .find(|r| r.retire.pc_rdata == handler + 8)
        .unwrap();
    assert_eq!(u64::from(load.retire.rd_wdata), load.cycle - 1);
    // the core slept from the WFI's first cycle to the wake-up
    assert!(s.stats().sleep_cycles > 49_900);
}

#[test]
fn plic_claims_the_highest_priority_above_the_threshold() {
    let mut plic = dev::Plic::default();
    plic.write(4 * 10, 2);
    plic.write(4 * 11, 5);
    plic.write(0x2000, 1 << 10 | 1 << 11);
    let both = 1 << 10 | 1 << 11;
    assert!(plic.eip(both));
    assert_eq!(plic.read(0x1000, false, both), both.into());
    assert_eq!(plic.read(0x20_0004, true, both), 11, "priority 5 wins");
    assert_eq!(plic.read(0x20_0004, true, both), 10, "11 is claimed");
    assert!(!plic.eip(both), "both claimed");
    plic.write(0x20_0004, 11);
    assert!(plic.eip(both));
    plic.write(0x20_0000, 5);
    assert!(!plic.eip(both), "threshold 5 masks priority 5");
    plic.write(0x20_0000, 4);
    assert!(plic.eip(1 << 11) && !plic.eip(1 << 10));
    plic.write(4 * 10, 5);
    assert_eq!(plic.read(0x20_0004, false, both), 11, "10 is still claimed");
    plic.write(4 * 11, 1);
    assert_eq!(
        plic.read(0x20_0004, false, both),
        0,
        "11 under the threshold"
    );
    plic.write(0x20_0004, 10);
    assert_eq!(
        plic.read(0x20_0004, false, both),
        10,
        "equal priorities: lowest id"
    );
    assert_eq!(plic.read(4 * 10, false, 0), 5);
    assert_eq!(plic.read(0x20_0000, false, 0), 4);
}

#[test]
fn clint_mtime_writes_keep_the_other_half_incremented() {
    let mut c = dev::Clint::new();
    assert_eq!(c.mtime(7), 7);
    c.write(10, 0xbff8, 0xf, 0xffff_ffff);
    assert_eq!(
        c.mtime(11),
        0xffff_ffff,
        "the low word as written, no carry"
    );
    assert_eq!(c.mtime(12), 0x1_0000_0000);
    c.write(20, 0xbffc, 0x1, 0x0000_0005);
    // high word: lane 0 replaced, the low word is mtime(20) + 1
    assert_eq!(
        c.mtime(21),
        0x5_0000_0000 | (0x1_0000_0000u64 + 9) & 0xffff_ffff
    );
    c.write(30, 0x4000, 0x3, 0x1234);
    assert_eq!(c.mtimecmp, 0xffff_ffff_ffff_1234, "lanes 0 and 1 only");
    c.write(30, 0x4000, 0xf, 0x1234);
    c.write(30, 0x4004, 0xf, 0);
    assert_eq!(c.mtimecmp, 0x1234);
    assert!(c.mtip(30));
    c.write(31, 0x0000, 0x2, 1);
    assert!(!c.msip, "msip takes lane 0 only");
}

/// A program that sleeps in WFI between timer interrupts, receives bytes and echoes them,
/// and counts. Run in one call, in slices of one cycle (so no wait is ever jumped over) and
/// in slices of odd lengths, it gives the same records, outputs and statistics.
#[test]
fn waiting_by_jumps_equals_waiting_cycle_by_cycle() {
    let mut p = P::default();
    let jump = p.0.len();
    p.i(0);
    let handler = p.here();
    // mcause code 11 (external) has bit 3, 7 (timer) has not
    p.i(isa::csrr(A2, csr::MCAUSE)).i(isa::andi(A2, A2, 8));
    let to_ext = p.0.len();
    p.i(0);
    // timer: next tick 3000 cycles on, count
    p.li(T2, map::CLINT + 0x4000).i(isa::lw(T1, T2, 0));
    p.li(A3, 3000).i(isa::add(T1, T1, A3)).i(isa::sw(T1, T2, 0));
    p.i(isa::addi(A1, A1, 1)).i(isa::MRET);
    let ext_at = p.here();
    p.0[to_ext] = isa::bne(A2, 0, (ext_at - (RAM_BASE + 4 * to_ext as u32)) as i32);
    // external: claim, echo every byte, complete
    p.li(T2, map::PLIC + 0x20_0004).i(isa::lw(A2, T2, 0));
    let drain = p.here();
    p.i(isa::lbu(T1, S0, 5)).i(isa::andi(T1, T1, 1));
    p.i(isa::beq(T1, 0, 16));
    p.i(isa::lbu(A0, S0, 0)).i(isa::sb(A0, S0, 0));
    let o = p.off(drain);
    p.i(isa::jal(0, o));
    p.i(isa::sw(A2, T2, 0)).i(isa::MRET);
    let main = p.here();
    p.0[jump] = isa::jal(0, (main - RAM_BASE) as i32);
    p.li(T1, handler).i(isa::csrrw(0, csr::MTVEC, T1));
    p.li(S0, map::UART0).li(S2, map::PLIC);
    uart_init(&mut p, S0);
    p.li(T1, 1).i(isa::sb(T1, S0, 1));
    p.li(T1, 1).i(isa::sw(T1, S2, 40));
    p.li(T2, map::PLIC + 0x2000)
        .li(T1, 1 << 10)
        .i(isa::sw(T1, T2, 0));
    p.li(T2, map::CLINT + 0x4000).li(T1, 3000);
    p.i(isa::sw(0, T2, 4)).i(isa::sw(T1, T2, 0));
    p.li(T1, 1 << 7 | 1 << 11).i(isa::csrrw(0, csr::MIE, T1));
    p.i(isa::csrrsi(0, csr::MSTATUS, 8));
    let idle = p.here();
    p.i(isa::WFI).li(T1, 60);
    let o = p.off(idle);
    p.i(isa::blt(A1, T1, o));
    p.exit_pass();
    let run = |slices: &dyn Fn(u64) -> u64| {
        let mut s = p.soc();
        let (mut out, mut trace) = (Vec::new(), Vec::new());
        s.send_at(Port::Lbc, 60_000, b"hello");
        while s.halted().is_none() && s.cycle() < 400_000 {
            let c = s.cycle();
            s.run_until_traced(c + slices(c), &mut out, &mut trace);
        }
        (out, trace, s.stats(), s.halted().cloned())
    };
    let whole = run(&|_| 1_000_000);
    assert_eq!(whole.3, Some(Halt::Exit { value: 0x5555 }));
    assert_eq!(whole.0.len(), 5, "{:?}", whole.0);
    assert!(whole.2.sleep_cycles > 150_000, "{:?}", whole.2);
    let (out, trace, stats, halt) = run(&|_| 1);
    assert_eq!(halt, whole.3);
    assert_eq!(stats, whole.2);
    assert_eq!(out, whole.0);
    assert_eq!(trace, whole.1);
    let (out, trace, stats, _) = run(&|c| 1 + (c * 7919) % 997);
    assert_eq!((out, trace, stats), (whole.0, whole.1, whole.2));
}

/// A minimal ELF32 image: one PT_LOAD segment with `data` at `paddr`.
fn elf(machine: u16, entry: u32, paddr: u32, data: &[u8]) -> Vec<u8> {
    let mut f = Vec::new();
    f.extend_from_slice(&[0x7f, b'E', b'L', b'F', 1, 1, 1, 0]);
    f.extend_from_slice(&[0; 8]);
    f.extend_from_slice(&2u16.to_le_bytes()); // ET_EXEC
    f.extend_from_slice(&machine.to_le_bytes());
    f.extend_from_slice(&1u32.to_le_bytes());
    f.extend_from_slice(&entry.to_le_bytes());
    f.extend_from_slice(&52u32.to_le_bytes()); // phoff
    f.extend_from_slice(&0u32.to_le_bytes()); // shoff
    f.extend_from_slice(&0u32.to_le_bytes()); // flags
    f.extend_from_slice(&52u16.to_le_bytes());
    f.extend_from_slice(&32u16.to_le_bytes());
    f.extend_from_slice(&1u16.to_le_bytes());
    f.extend_from_slice(&40u16.to_le_bytes());
    f.extend_from_slice(&0u16.to_le_bytes());
    f.extend_from_slice(&0u16.to_le_bytes());
    let off = 52 + 32u32;
    for v in [
        1,
        off,
        paddr,
        paddr,
        data.len() as u32,
        data.len() as u32,
        5,
        4,
    ] {
        f.extend_from_slice(&v.to_le_bytes());
    }
    f.extend_from_slice(data);
    f
}

#[test]
fn elf_images_load_and_bad_ones_are_refused() {
    const RISCV: u16 = 243;
    let prog: Vec<u8> = [isa::li(A0, 42).as_slice(), &[isa::jal(0, 0)]]
        .concat()
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    let good = elf(RISCV, RAM_BASE, RAM_BASE, &prog);
    let mut s = Soc::new();
    s.load_elf(&good).unwrap();
    let mut out = Vec::new();
    s.run_until(100, &mut out);
    assert_eq!(s.reg(10), 42);

    assert!(matches!(
        Soc::new().load_elf(b"not an elf"),
        Err(LoadError::Parse(_))
    ));
    assert!(matches!(
        Soc::new().load_elf(&elf(62, RAM_BASE, RAM_BASE, &prog)),
        Err(LoadError::WrongMachine { .. })
    ));
    assert_eq!(
        Soc::new().load_elf(&elf(RISCV, RAM_BASE + 4, RAM_BASE, &prog)),
        Err(LoadError::Entry {
            entry: u64::from(RAM_BASE) + 4
        })
    );
    let end = RAM_BASE + RAM_SIZE - 4;
    assert_eq!(
        Soc::new().load_elf(&elf(RISCV, RAM_BASE, end, &prog)),
        Err(LoadError::OutsideRam {
            addr: u64::from(end),
            len: prog.len() as u64
        })
    );
    assert!(matches!(
        Soc::new().load_elf(&elf(RISCV, RAM_BASE, 0x1000, &prog)),
        Err(LoadError::OutsideRam { .. })
    ));
    // every truncation and single-byte corruption of a good image: an error or a load, no
    // panic
    for n in 0..good.len() {
        let _ = Soc::new().load_elf(&good[..n]);
    }
    for k in 0..good.len() {
        for v in [0u8, 0xff, 0x80] {
            let mut bad = good.clone();
            bad[k] = v;
            let _ = Soc::new().load_elf(&bad);
        }
    }
    assert_eq!(
        Soc::new().load_words(RAM_BASE + 2, &[0]),
        Err(WordsError::Unaligned { addr: RAM_BASE + 2 })
    );
    assert!(Soc::new()
        .load_words(RAM_BASE + RAM_SIZE - 4, &[0, 0])
        .is_err());
    assert!(Soc::new().load_words(0, &[0]).is_err());
}

#[test]
fn frame_window_writes_are_bounded() {
    let mut s = Soc::new();
    assert!(s
        .write_frame_window(FRAME_WINDOW_LEN - 4, &[1, 2, 3, 4])
        .is_ok());
    assert_eq!(
        s.write_frame_window(FRAME_WINDOW_LEN - 3, &[0; 4]),
        Err(FrameError::OutsideWindow {
            offset: FRAME_WINDOW_LEN - 3,
            len: 4
        })
    );
    assert!(s.write_frame_window(usize::MAX, &[0]).is_err());
    // the core sees the bytes
    let mut p = P::default();
    p.li(S0, map::FRAME_WINDOW + (FRAME_WINDOW_LEN as u32 - 4))
        .i(isa::lw(A0, S0, 0))
        .i(isa::jal(0, 0));
    let mut s2 = p.soc();
    s2.write_frame_window(FRAME_WINDOW_LEN - 4, &[1, 2, 3, 4])
        .unwrap();
    s2.run_until(50, &mut Vec::new());
    assert_eq!(s2.reg(10), 0x0403_0201);
}

#[test]
fn wfi_with_nothing_enabled_is_stuck_and_costs_nothing() {
    let mut p = P::default();
    p.i(isa::WFI);
    let mut s = p.soc();
    let mut out = Vec::new();
    let h = s.run_until(10 * CLOCK_HZ, &mut out);
    assert_eq!(
        h,
        Some(Halt::Stuck {
            pc: RAM_BASE,
            reason: StuckReason::WfiWithoutWakeup
        })
    );
    assert_eq!(s.cycle(), 10 * CLOCK_HZ, "time still passes");
    let st = s.stats();
    assert_eq!(st.sleep_cycles, st.cycles, "every cycle sleeps");
    assert_eq!(st.retired, 0);
}

/// Reference bus for the [`Hart`]: RAM, other addresses read zero.
struct Ram(Vec<u32>);

impl Bus for Ram {
    fn load(&mut self, addr: u32) -> u32 {
        let off = addr.wrapping_sub(RAM_BASE);
        if off < RAM_SIZE {
            self.0[(off / 4) as usize]
        } else {
            0
        }
    }
    fn store(&mut self, addr: u32, mask: u8, data: u32) {
        let off = addr.wrapping_sub(RAM_BASE);
        if off < RAM_SIZE {
            let w = &mut self.0[(off / 4) as usize];
            for lane in 0..4 {
                if mask & (1 << lane) != 0 {
                    let m = 0xffu32 << (8 * lane);
                    *w = (*w & !m) | (data & m);
                }
            }
        }
    }
}

/// Registers the random streams do not write: the data pointers and the handler's.
const DATA: u8 = 8;
const AMO: u8 = 9;
const SP_DATA: u8 = 2;
const SCRATCH: u8 = 29;
const LINK: u8 = 30;
const HANDLER: u8 = 31;

fn free_reg(r: u8) -> u8 {
    match r {
        DATA | AMO | SP_DATA | SCRATCH | LINK | HANDLER => 5,
        r => r,
    }
}

/// One instruction (or a short sequence) of a random stream from `g` (a random word
/// stream); `room` words remain before the stream's end.
fn random_insn(
    g: &mut impl FnMut() -> u32,
    p: &mut P,
    room: usize,
    targets: &mut std::collections::HashSet<usize>,
) {
    let r = |g: &mut dyn FnMut() -> u32| free_reg((g() % 32) as u8);
    let s = |g: &mut dyn FnMut() -> u32| (g() % 32) as u8;
    let imm = |g: &mut dyn FnMut() -> u32| (g() % 4096) as i32 - 2048;
    match g() % 24 {
        0..=4 => {
            let f7 = [0, 0x20, 1][(g() % 3) as usize];
            let f3 = g() % 8;
            let w = (f7 << 25)
                | (u32::from(s(g)) << 20)
                | (u32::from(s(g)) << 15)
                | (f3 << 12)
                | (u32::from(r(g)) << 7)
                | 0b011_0011;
            p.i(w);
        }
        5..=8 => {
            let f3 = g() % 8;
            let mut i = imm(g);
            if f3 == 1 || f3 == 5 {
                i = (i & 31) | if g().is_multiple_of(2) { 0x400 } else { 0 };
            }
            let w = ((i as u32 & 0xfff) << 20)
                | (u32::from(s(g)) << 15)
                | (f3 << 12)
                | (u32::from(r(g)) << 7)
                | 0b001_0011;
            p.i(w);
        }
        9 => {
            p.i(isa::lui(r(g), g()));
            p.i(isa::auipc(r(g), g()));
        }
        10..=12 => {
            let off = (g() % 512) as i32 - 256;
            p.i(match g() % 8 {
                0 => isa::lb(r(g), DATA, off),
                1 => isa::lh(r(g), DATA, off),
                2 => isa::lw(r(g), DATA, off),
                3 => isa::lbu(r(g), DATA, off),
                4 => isa::lhu(r(g), DATA, off),
                5 => isa::sb(s(g), DATA, off),
                6 => isa::sh(s(g), DATA, off),
                _ => isa::sw(s(g), DATA, off),
            });
        }
        13..=14 => {
            let words = 1 + (g() as usize % room.clamp(1, 6)) as i32;
            let off = 4 * words;
            let kind = g() % 8;
            if kind == 7 {
                // the JALR must not be a branch target: its base comes from the AUIPC
                while targets.contains(&(p.0.len() + 1)) {
                    p.i(isa::NOP);
                }
            }
            let at = p.0.len() + usize::from(kind == 7);
            targets.insert(at + words as usize);
            let w = match kind {
                0 => isa::beq(s(g), s(g), off),
                1 => isa::bne(s(g), s(g), off),
                2 => isa::blt(s(g), s(g), off),
                3 => isa::bge(s(g), s(g), off),
                4 => isa::bltu(s(g), s(g), off),
                5 => isa::bgeu(s(g), s(g), off),
                6 => isa::jal(r(g), off),
                _ => {
                    p.i(isa::auipc(LINK, 0));
                    isa::jalr(r(g), LINK, off + 4 + (g() % 2) as i32)
                }
            };
            p.i(w);
        }
        15 => {
            let f5 = isa::amo::ALL[(g() % 11) as usize];
            let src = if f5 == isa::amo::LR { 0 } else { s(g) };
            p.i(isa::amo_w(f5, r(g), AMO, src));
        }
        16..=17 => {
            let c = [
                csr::MSCRATCH,
                csr::MTVAL,
                csr::MCAUSE,
                csr::MISA,
                csr::MINSTRET,
                csr::MINSTRETH,
                csr::INSTRET,
                csr::MHARTID,
                csr::MSTATUSH,
                0x7c0,
            ][(g() % 10) as usize];
            let f3 = [1, 2, 3, 5, 6, 7][(g() % 6) as usize];
            p.i(isa::csr_op(f3, r(g), c, s(g)));
        }
        18 => {
            // an opcode no instruction has: illegal
            p.i((g() & !0x7f) | 0x7f);
        }
        19..=20 => {
            // compressed instructions, and a 32-bit one at a halfword address between two
            let pair = isa::c_random::pair(g, &|r| free_reg(r) == r);
            if g().is_multiple_of(2) {
                p.i(pair);
            } else {
                let w = match g() % 4 {
                    0 => isa::add(r(g), s(g), s(g)),
                    1 => isa::lw(r(g), DATA, (g() % 64) as i32 * 4),
                    2 => isa::mul(r(g), s(g), s(g)),
                    _ => isa::addi(r(g), s(g), imm(g)),
                };
                // the second word is no instruction boundary: no branch may land there
                while targets.contains(&(p.0.len() + 1)) {
                    p.i(isa::NOP);
                }
                p.i((pair & 0xffff) | w << 16)
                    .i(w >> 16 | (pair & 0xffff_0000));
            }
        }
        21 => {
            // compressed branches and jumps to a word boundary ahead
            let words = 1 + (g() as usize % room.clamp(1, 6)) as i32;
            let second = g().is_multiple_of(2);
            let off = 4 * words - if second { 2 } else { 0 };
            let cb = match g() % 4 {
                0 => isa::c::beqz(8 + (g() % 8) as u8, off),
                1 => isa::c::bnez(8 + (g() % 8) as u8, off),
                2 => isa::c::j(off),
                _ => isa::c::jal(off),
            };
            targets.insert(p.0.len() + words as usize);
            let nop = u32::from(isa::c::NOP);
            p.i(if second {
                nop | u32::from(cb) << 16
            } else {
                u32::from(cb) | nop << 16
            });
        }
        22 => {
            // C.JR / C.JALR to LINK + off: neither the ADDI nor the jump may be a target
            let words = 1 + (g() as usize % room.clamp(1, 6)) as i32;
            while (1..=2).any(|k| targets.contains(&(p.0.len() + k))) {
                p.i(isa::NOP);
            }
            let at = p.0.len();
            targets.insert(at + 2 + words as usize);
            let j = if g().is_multiple_of(2) {
                isa::c::jr(LINK)
            } else {
                isa::c::jalr(LINK)
            };
            p.i(isa::auipc(LINK, 0))
                .i(isa::addi(LINK, LINK, 4 * (2 + words)))
                .i(u32::from(j) | u32::from(isa::c::NOP) << 16);
        }
        _ => {
            p.i([isa::ECALL, isa::EBREAK, isa::fence(), isa::NOP][(g() % 4) as usize]);
        }
    }
}

/// A random stream with a handler that skips trapping instructions, as a program.
fn random_program(seed: u64, len: usize) -> P {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut g = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 16) as u32
    };
    let mut p = P::default();
    let jump = p.0.len();
    p.i(0);
    let handler = p.here();
    // skip the trapping instruction: 2 or 4 bytes by its low bits
    p.i(isa::csrr(HANDLER, csr::MEPC))
        .i(isa::lhu(SCRATCH, HANDLER, 0))
        .i(isa::andi(SCRATCH, SCRATCH, 3))
        .i(isa::addi(SCRATCH, SCRATCH, -3))
        .i(isa::addi(HANDLER, HANDLER, 2))
        .i(isa::bne(SCRATCH, 0, 8))
        .i(isa::addi(HANDLER, HANDLER, 2))
        .i(isa::csrrw(0, csr::MEPC, HANDLER))
        .i(isa::MRET);
    let main = p.here();
    p.0[jump] = isa::jal(0, (main - RAM_BASE) as i32);
    p.li(HANDLER, handler).i(isa::csrrw(0, csr::MTVEC, HANDLER));
    p.li(SP_DATA, RAM_BASE + 0x8_0100);
    p.li(DATA, RAM_BASE + 0x8_0000)
        .li(AMO, RAM_BASE + 0x8_0400 + 4 * (g() % 2));
    for r in 1..32u8 {
        if free_reg(r) == r {
            p.li(r, g());
        }
    }
    let start = p.0.len();
    let mut targets = std::collections::HashSet::new();
    while p.0.len() - start < len {
        let room = len + 8 - (p.0.len() - start);
        random_insn(&mut g, &mut p, room, &mut targets);
    }
    for _ in 0..8 {
        p.i(isa::NOP);
    }
    p.exit_pass();
    p
}

/// Runs `p` on the model (traced) and on the reference hart; every record must agree.
fn model_vs_hart(p: &P) {
    let mut s = p.soc();
    let (_, trace, h) = run_all(&mut s, 2_000_000);
    assert_eq!(h, Some(Halt::Exit { value: 0x5555 }));
    let mut ram = Ram(vec![0; RAM_WORDS]);
    ram.0[..p.0.len()].copy_from_slice(&p.0);
    let mut hart = Hart::new(RAM_BASE);
    for (k, r) in trace.iter().enumerate() {
        let want = hart.step(&mut ram);
        assert_eq!(r.retire, want, "record {k}");
    }
    assert_eq!(&s.x[..32], &hart.x[..]);
    assert_eq!(s.pc, hart.pc);
}

#[test]
fn random_streams_agree_with_the_reference_hart() {
    for seed in 0..30 {
        model_vs_hart(&random_program(seed, 2000));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn short_random_streams_agree_with_the_reference_hart(seed: u64, len in 1usize..200) {
        model_vs_hart(&random_program(seed, len));
    }

    /// Any words at all, run from reset with random registers: no panic, whatever they
    /// touch (devices, unmapped addresses, the frame window, the exit register).
    #[test]
    fn arbitrary_programs_never_panic(words in proptest::collection::vec(any::<u32>(), 1..64),
                                      regs in proptest::collection::vec(any::<u32>(), 31),
                                      rx in proptest::collection::vec(any::<u8>(), 0..8)) {
        let mut p = P::default();
        for (k, v) in regs.iter().enumerate() {
            p.li(k as u8 + 1, *v);
        }
        p.0.extend(&words);
        let mut s = p.soc();
        s.send_at(Port::Lbc, 100, &rx);
        s.send_at(Port::Radio, 50, &rx);
        let mut out = Vec::new();
        s.run_until(20_000, &mut out);
        s.run_until(40_000, &mut out);
        let st = s.stats();
        let exited = matches!(s.halted(), Some(Halt::Exit { .. }));
        prop_assert!(st.cycles >= 20_000 || exited);
    }
}

#[test]
fn soc_is_send_clone_and_a_clone_runs_the_same() {
    fn send_clone<T: Send + Clone + core::fmt::Debug>() {}
    send_clone::<Soc>();
    let p = random_program(7, 300);
    let mut a = p.soc();
    let mut out_a = Vec::new();
    a.run_until(500, &mut out_a);
    let mut b = a.clone();
    let mut out_b = Vec::new();
    a.run_until(200_000, &mut out_a);
    b.run_until(200_000, &mut out_b);
    assert_eq!(a.stats(), b.stats());
    assert_eq!(a.halted(), b.halted());
    assert!(format!("{a:?}").contains("Soc"));
}

/// AMOs and LR/SC on device registers (a UART's scratch register, the PLIC threshold and
/// claim), the same whether a run boundary falls between an AMO's two cycles or not.
#[test]
fn amos_on_devices_across_run_boundaries() {
    let mut p = P::default();
    p.li(T1, map::UART0 + 4)
        .li(T0, 0x5a00_0000)
        .li(A3, map::PLIC + 0x20_0000);
    p.li(S1, 3).i(isa::sw(S1, A3, 0));
    for _ in 0..5 {
        p.i(isa::amo_w(isa::amo::OR, A0, T1, T0));
        p.i(isa::amo_w(isa::amo::ADD, A1, A3, S1));
        p.i(isa::lr_w(A2, T1)).i(isa::sc_w(A2, T1, T0));
        p.i(isa::amo_w(isa::amo::SWAP, A2, A3, 0));
    }
    p.exit_pass();
    let run = |slice: u64| {
        let mut s = p.soc();
        let (mut out, mut trace) = (Vec::new(), Vec::new());
        while s.halted().is_none() && s.cycle() < 10_000 {
            let c = s.cycle();
            s.run_until_traced(c + slice, &mut out, &mut trace);
        }
        (trace, s.stats(), s.reg(10), s.reg(11))
    };
    let whole = run(100_000);
    assert_eq!(whole.2 >> 24, 0x5a, "SCR keeps the OR");
    for slice in [1, 2, 3] {
        assert_eq!(run(slice), whole, "slices of {slice}");
    }
}

/// `p` as the executable segment of an ELF image, loaded (its code shared with clones).
fn elf_soc(p: &P) -> Soc {
    let bytes: Vec<u8> = p.0.iter().flat_map(|w| w.to_le_bytes()).collect();
    let mut s = Soc::new();
    s.load_elf(&elf(243, RAM_BASE, RAM_BASE, &bytes))
        .expect("loads");
    s
}

#[test]
fn shared_code_runs_like_private_code() {
    for seed in 100..110 {
        let p = random_program(seed, 1500);
        let mut shared = elf_soc(&p);
        assert!(shared.shares_code());
        let clone = shared.clone();
        let mut private = p.soc();
        assert!(!private.shares_code());
        let a = run_all(&mut shared, 2_000_000);
        let b = run_all(&mut private, 2_000_000);
        assert_eq!(a.1, b.1, "seed {seed}: records");
        assert_eq!((a.0, a.2), (b.0, b.2), "seed {seed}: outputs and halt");
        assert_eq!(shared.stats(), private.stats());
        // The programs store only into their data area: the code stays shared.
        assert!(shared.shares_code() && clone.shares_code());
    }
}

#[test]
fn a_store_into_shared_code_is_seen_and_ends_sharing_for_that_soc_only() {
    // a0 counts a loop of 10; after the first pass the loop patches its own increment from
    // 1 to 5 (`addi a0, a0, 5`), so the total is 1 + 9 * 5 = 46.
    let mut p = P::default();
    p.li(A0, 0).li(T1, 10);
    let patch_at = p.here() + 16; // after the two two-word loads below
    p.li(T2, patch_at);
    p.li(S2, isa::addi(A0, A0, 5));
    let top = p.here();
    p.i(isa::addi(A0, A0, 1));
    p.i(isa::sw(S2, T2, 0));
    p.i(isa::addi(T1, T1, -1));
    let off = p.off(top);
    p.i(isa::bne(T1, 0, off));
    p.exit_pass();
    assert_eq!(
        top, patch_at,
        "the patched word is the loop's first instruction"
    );
    let mut s = elf_soc(&p);
    let sibling = s.clone();
    let (_, trace, h) = run_all(&mut s, 100_000);
    assert_eq!(h, Some(Halt::Exit { value: 0x5555 }));
    assert_eq!(s.reg(10), 46);
    assert!(!s.shares_code());
    assert!(sibling.shares_code(), "a clone keeps the shared decoding");
    // The same program privately, and on the reference hart.
    let mut private = p.soc();
    let (_, trace2, _) = run_all(&mut private, 100_000);
    assert_eq!(trace, trace2);
    let mut ram = Ram(vec![0; RAM_WORDS]);
    ram.0[..p.0.len()].copy_from_slice(&p.0);
    let mut hart = Hart::new(RAM_BASE);
    for (k, r) in trace.iter().enumerate() {
        assert_eq!(r.retire, hart.step(&mut ram), "record {k}");
    }
}

#[test]
fn shared_code_untraced_in_odd_slices_runs_like_the_traced_private_run() {
    // Untraced runs of shared code take their own lean loop: run it in slices of odd
    // lengths (deadlines falling inside divisions and anywhere else) against the traced run
    // of the same program from private code.
    for seed in 200..212 {
        let p = random_program(seed, 1500);
        let mut private = p.soc();
        let (want_out, _, want_halt) = run_all(&mut private, 2_000_000);
        let mut shared = elf_soc(&p);
        let mut out = Vec::new();
        let mut halt = None;
        let mut t = 0u64;
        let mut k = 0u64;
        while t < 2_000_000 && halt.is_none() {
            k += 1;
            t = (t + 1 + (k * 7919 + seed) % 97).min(2_000_000);
            halt = shared.run_until(t, &mut out);
        }
        if halt.is_none() {
            halt = shared.run_until(2_000_000, &mut out);
        }
        assert_eq!(halt, want_halt, "seed {seed}");
        assert_eq!(out, want_out, "seed {seed}: outputs");
        assert_eq!(shared.stats(), private.stats(), "seed {seed}");
        assert_eq!(&shared.x[..32], &private.x[..32], "seed {seed}");
        assert_eq!(shared.pc, private.pc, "seed {seed}");
    }
}

#[test]
fn a_jump_into_the_middle_of_a_shared_instruction_runs_what_is_there() {
    // The upper half of a `lui` is a compressed `addi a0, a0, 1`: the executor's line of the
    // code (a sweep from its start) holds the `lui`, so a jump to its middle leaves the line
    // and must still run the compressed instruction there, then the rest. The second pass
    // runs the `lui` itself.
    let mut p = P::default();
    p.li(A0, 0).li(A2, 0);
    p.i(isa::jal(0, 6));
    let w = p.here();
    let half = u32::from(isa::c::addi(A0, 1));
    p.i(half << 16 | 11 << 7 | 0x37); // lui a1, (half << 4 | 0)
    p.i(isa::addi(A0, A0, 10));
    p.i(isa::addi(A2, A2, 1));
    p.i(isa::addi(T1, 0, 2));
    let back = p.off(w);
    p.i(isa::blt(A2, T1, back));
    p.exit_pass();
    let mut private = p.soc();
    let (want_out, _, want_halt) = run_all(&mut private, 10_000);
    assert_eq!(want_halt, Some(Halt::Exit { value: 0x5555 }));
    assert_eq!(private.reg(10), 21, "1 off the line, then 10 on each pass");
    assert_eq!(private.reg(11), half << 16);
    let mut shared = elf_soc(&p);
    let mut out = Vec::new();
    let halt = shared.run_until(10_000, &mut out);
    assert_eq!((halt, out), (want_halt, want_out));
    assert_eq!(shared.stats(), private.stats());
    assert_eq!(&shared.x[..32], &private.x[..32]);
}
