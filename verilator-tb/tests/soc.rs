//! SoC peripherals driven by programs on the core (in lockstep): UART line timing, receive
//! with polling and with PLIC interrupts, the console and exit codes.
mod common;
use common::*;
use verilator_tb::golden::cause;
use verilator_tb::isa::{self, csr, reg::*};
use verilator_tb::lockstep::Lockstep;
use verilator_tb::soc::{irq, map, Event, Exit, Uart, CHAR_CYCLES, RAM_BASE};

const LSR: i32 = 5;
const S2: u8 = 18;

/// 8N1 at 115200 with the FIFOs on, for the UART whose base is in `base`.
fn uart_init(p: &mut Prog, base: u8) {
    p.li(T1, 0x80).i(isa::sb(T1, base, 3)); // DLAB
    p.li(T1, 8).i(isa::sb(T1, base, 0)).i(isa::sb(0, base, 1));
    p.li(T1, 3).i(isa::sb(T1, base, 3)); // 8N1, DLAB off
    p.li(T1, 7).i(isa::sb(T1, base, 2)); // FIFOs on and cleared
}

fn run_events(p: &Prog, rx: &[(Uart, &[u8])]) -> Vec<(u64, Event)> {
    let mut ls = Lockstep::new();
    ls.keep_records();
    ls.load(RAM_BASE, &p.words).unwrap();
    for (u, bytes) in rx {
        ls.soc_mut().send_at(*u, 2000, bytes);
    }
    let run = ls
        .run(1_000_000, 2_000_000, &[])
        .unwrap_or_else(|m| panic!("{}", describe(&m)));
    assert_eq!(run.exit, Some(Exit::Pass));
    let sent = ls.soc_mut().rx_log().to_vec();
    check_model(&p.words, &[], &sent, &run);
    run.events.iter().map(|e| (e.cycle, e.value)).collect()
}

#[test]
fn uart_transmit_is_bit_timed() {
    let mut p = Prog::new();
    p.li(S0, map::UART0);
    uart_init(&mut p, S0);
    for b in b"Hi!" {
        p.li(T1, u32::from(*b)).i(isa::sb(T1, S0, 0));
    }
    // wait for TEMT
    let wait = p.here();
    p.i(isa::lbu(T1, S0, LSR)).i(isa::andi(T1, T1, 0x40));
    let here = p.here();
    p.i(isa::beq(T1, 0, (wait as i32) - (here as i32)));
    p.exit_pass();
    let ev = run_events(&p, &[]);
    let tx: Vec<(u64, u8)> = ev
        .iter()
        .filter_map(|(c, e)| match e {
            Event::Tx {
                uart: Uart::Lbc,
                byte,
            } => Some((*c, *byte)),
            _ => None,
        })
        .collect();
    assert_eq!(tx.iter().map(|t| t.1).collect::<Vec<_>>(), b"Hi!");
    assert_eq!(tx[1].0 - tx[0].0, CHAR_CYCLES);
    assert_eq!(tx[2].0 - tx[1].0, CHAR_CYCLES);
}

#[test]
fn uart_receive_polled_echo_to_console() {
    let mut p = Prog::new();
    p.li(S0, map::UART1).li(S1, map::SIM_CTRL);
    uart_init(&mut p, S0);
    p.li(A1, 4); // bytes to echo
    let top = p.here();
    p.i(isa::lbu(T1, S0, LSR)).i(isa::andi(T1, T1, 1));
    let here = p.here();
    p.i(isa::beq(T1, 0, (top as i32) - (here as i32)));
    p.i(isa::lbu(A0, S0, 0))
        .i(isa::sw(A0, S1, 4))
        .i(isa::addi(A1, A1, -1));
    let here = p.here();
    p.i(isa::bne(A1, 0, (top as i32) - (here as i32)));
    p.exit_pass();
    let ev = run_events(&p, &[(Uart::Radio, b"ping")]);
    let console: Vec<u8> = ev
        .iter()
        .filter_map(|(_, e)| match e {
            Event::Console(b) => Some(*b),
            _ => None,
        })
        .collect();
    assert_eq!(console, b"ping");
    // bytes arrive one character time apart, so the last echo is at least 3 of them in
    let last = ev
        .iter()
        .rev()
        .find(|(_, e)| matches!(e, Event::Console(_)))
        .unwrap()
        .0;
    assert!(last >= 3 * CHAR_CYCLES, "{last}");
}

#[test]
fn uart_receive_interrupt_through_plic() {
    let mut p = Prog::new();
    p.li(S0, map::UART0).li(S1, map::SIM_CTRL).li(S2, map::PLIC);
    let jump = p.hole(1);
    let handler = p.here();
    // claim, drain the RX FIFO to the console, complete
    p.li(T2, map::PLIC + 0x20_0004).i(isa::lw(A2, T2, 0));
    p.i(isa::csrr(A3, csr::MCAUSE));
    let drain = p.here();
    p.i(isa::lbu(T1, S0, LSR))
        .i(isa::andi(T1, T1, 1))
        .i(isa::beq(T1, 0, 20));
    p.i(isa::lbu(A0, S0, 0))
        .i(isa::sw(A0, S1, 4))
        .i(isa::addi(A1, A1, 1));
    let here = p.here();
    p.i(isa::jal(0, (drain as i32) - (here as i32)));
    p.i(isa::sw(A2, T2, 0)).i(isa::MRET);
    let main = p.here();
    p.words[jump] = isa::jal(0, (main - p.addr_of(jump)) as i32);
    p.li(T1, handler).i(isa::csrrw(0, csr::MTVEC, T1));
    uart_init(&mut p, S0);
    p.li(T1, 1).i(isa::sb(T1, S0, 1)); // IER: RX available
    p.li(T1, 1).i(isa::sw(T1, S2, 4 * irq::UART0 as i32)); // priority 1
    p.li(T2, map::PLIC + 0x2000)
        .li(T1, 1 << irq::UART0)
        .i(isa::sw(T1, T2, 0));
    p.li(T1, 1 << 11).i(isa::csrrw(0, csr::MIE, T1));
    p.i(isa::csrrsi(0, csr::MSTATUS, 8));
    let sleep = p.here();
    p.i(isa::WFI).li(T1, 3);
    let here = p.here();
    p.i(isa::blt(A1, T1, (sleep as i32) - (here as i32)));
    p.li(T1, map::SIM_CTRL).li(T2, 0x5555).i(isa::sw(T2, T1, 0));
    let mut ls = Lockstep::new();
    ls.keep_records();
    ls.load(RAM_BASE, &p.words).unwrap();
    ls.soc_mut().send_at(Uart::Lbc, 2000, b"abc");
    let run = ls
        .run(1_000_000, 2_000_000, &[])
        .unwrap_or_else(|m| panic!("{}", describe(&m)));
    assert_eq!(run.exit, Some(Exit::Pass));
    let sent = ls.soc_mut().rx_log().to_vec();
    check_model(&p.words, &[], &sent, &run);
    let console: Vec<u8> = run
        .events
        .iter()
        .filter_map(|e| match e.value {
            Event::Console(b) => Some(b),
            _ => None,
        })
        .collect();
    assert_eq!(console, b"abc");
    assert_eq!(run.hart.x[A2 as usize], irq::UART0, "claimed source");
    assert_eq!(run.hart.x[A3 as usize], cause::M_EXTERNAL);
    assert!(
        run.retired < 2000,
        "the core slept between bytes: {} retired",
        run.retired
    );
}

#[test]
fn exit_codes() {
    for (value, want) in [(0x5555, Exit::Pass), (0x0007_3333, Exit::Fail(7))] {
        let mut p = Prog::new();
        p.li(T0, map::SIM_CTRL)
            .li(T1, value)
            .i(isa::sw(T1, T0, 0))
            .i(isa::jal(0, 0));
        let mut ls = Lockstep::new();
        ls.keep_records();
        ls.load(RAM_BASE, &p.words).unwrap();
        let run = ls.run(100, 1000, &[]).unwrap();
        assert_eq!(run.exit, Some(want));
        check_model(&p.words, &[], &[], &run);
    }
}

/// Simulation speed on a busy core (no WFI), free-running and in lockstep with the golden
/// model: `cargo test -p verilator-tb --release --test soc -- --ignored --nocapture
/// busy_speed`. Prints `figures:` lines that `cargo xtask bench --only softcore` reads.
#[test]
#[ignore]
fn busy_speed() {
    let mut p = Prog::new();
    p.li(S0, RAM_BASE + 0x8_0000).li(A0, 1);
    let top = p.here();
    p.i(isa::mul(A1, A0, A0))
        .i(isa::sw(A1, S0, 0))
        .i(isa::lw(A2, S0, 0));
    p.i(isa::xor(A0, A0, A2))
        .i(isa::addi(A0, A0, 7))
        .i(isa::srli(A3, A0, 3));
    let here = p.here();
    p.i(isa::jal(0, (top as i32) - (here as i32)));
    let mut soc = verilator_tb::soc::Soc::new();
    soc.load_words(RAM_BASE, &p.words).unwrap();
    soc.release();
    let cycles = 20_000_000;
    let start = std::time::Instant::now();
    soc.run(cycles);
    let s = start.elapsed().as_secs_f64();
    println!(
        "{cycles} cycles in {s:.2} s: {:.2} M cycles/s, CPI {:.3}",
        cycles as f64 / s / 1e6,
        soc.cycle() as f64 / soc.retired() as f64
    );
    println!(
        "figures: mode=busy cycles={cycles} instructions={} wall_s={s:.3}",
        soc.retired()
    );

    let mut ls = Lockstep::new();
    ls.load(RAM_BASE, &p.words).unwrap();
    let cycles = 4_000_000;
    let start = std::time::Instant::now();
    let run = ls
        .run(u64::MAX, cycles, &[])
        .unwrap_or_else(|m| panic!("{}", describe(&m)));
    let s = start.elapsed().as_secs_f64();
    println!(
        "lockstep: {} instructions in {s:.2} s: {:.2} M cycles/s",
        run.retired,
        run.cycles as f64 / s / 1e6
    );
    println!(
        "figures: mode=busy-lockstep cycles={} instructions={} wall_s={s:.3}",
        run.cycles, run.retired
    );
}

/// The harness writes the frame-grabber window while the core runs; the core polls a word and
/// echoes each new value to the console, and exits when it reads the last one.
#[test]
fn frame_window_is_written_while_the_core_runs() {
    use verilator_tb::soc::{FrameError, Soc, FRAME_WINDOW_LEN};
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
    let mut console = Vec::new();
    for v in 1..=3u8 {
        assert!(soc.run(500).is_empty(), "nothing before the write");
        soc.write_frame_window(FRAME_WINDOW_LEN - 4, &[v, 0xee, 0xee, 0xee])
            .unwrap();
        for e in soc.run(100) {
            match e.value {
                Event::Console(b) => console.push(b),
                Event::Exit(x) => assert_eq!(x, Exit::Pass),
                other => panic!("{other:?}"),
            }
        }
    }
    assert_eq!(console, [1, 2, 3]);
    assert_eq!(
        soc.write_frame_window(FRAME_WINDOW_LEN - 3, &[0; 4]),
        Err(FrameError::OutsideWindow {
            offset: FRAME_WINDOW_LEN - 3,
            len: 4
        })
    );
    assert!(soc.write_frame_window(usize::MAX, &[0]).is_err());
}

/// The simulator child process ends with its handle.
#[test]
fn simulator_process_ends_with_the_soc() {
    let soc = verilator_tb::soc::Soc::new();
    let proc_dir = std::path::PathBuf::from(format!("/proc/{}", soc.simulator_pid()));
    assert!(proc_dir.exists());
    drop(soc);
    assert!(!proc_dir.exists(), "child still there after drop");
}

/// End of input ends the simulator by itself (a harness that goes away without killing it
/// leaves nothing behind).
#[test]
fn simulator_process_ends_at_end_of_input() {
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("VTB_SIM_EXE"))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("vtb-sim starts");
    drop(child.stdin.take());
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("wait") {
            assert!(status.success(), "{status}");
            break;
        }
        if start.elapsed() > std::time::Duration::from_secs(10) {
            let _ = child.kill();
            panic!("vtb-sim still running after its input closed");
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}
