//! The SoC co-simulated with the emulated lower board: a program on the core sends READ_ID
//! over UART0 and echoes what comes back to the console; the reply must be the emulator's.
mod common;
use common::*;
use lbc_emu::{Lbc, LbcConfig};
use lbc_link::{Command, Deframer, LbcMessage, Reply};
use verilator_tb::cosim::{cycles_to_us, LbcCosim};
use verilator_tb::isa::{self, reg::*};
use verilator_tb::soc::{map, Event, Soc, RAM_BASE};

const CAR_ID: u8 = 7;

#[test]
fn read_id_round_trip_through_the_emulated_lbc() {
    let mut cmd = [0u8; 16];
    let n = Command::ReadId.emit(&mut cmd).expect("READ_ID fits");
    let mut p = Prog::new();
    p.li(S0, map::UART0).li(S1, map::SIM_CTRL);
    p.li(T1, 0x80).i(isa::sb(T1, S0, 3));
    p.li(T1, 8).i(isa::sb(T1, S0, 0)).i(isa::sb(0, S0, 1));
    p.li(T1, 3)
        .i(isa::sb(T1, S0, 3))
        .li(T1, 7)
        .i(isa::sb(T1, S0, 2));
    for b in &cmd[..n] {
        let wait = p.here();
        p.i(isa::lbu(T1, S0, 5)).i(isa::andi(T1, T1, 0x20));
        let here = p.here();
        p.i(isa::beq(T1, 0, wait as i32 - here as i32));
        p.li(T1, u32::from(*b)).i(isa::sb(T1, S0, 0));
    }
    let top = p.here();
    p.i(isa::lbu(T1, S0, 5)).i(isa::andi(T1, T1, 1));
    let here = p.here();
    p.i(isa::beq(T1, 0, top as i32 - here as i32));
    p.i(isa::lbu(A0, S0, 0)).i(isa::sw(A0, S1, 4));
    let here = p.here();
    p.i(isa::jal(0, top as i32 - here as i32));

    let mut soc = Soc::new();
    soc.load_words(RAM_BASE, &p.words).unwrap();
    let mut cfg = LbcConfig::default();
    cfg.boot_time_us = 0;
    let mut cosim = LbcCosim::new(soc, Lbc::with_memory_eeprom(cfg, CAR_ID));
    let events = cosim.run(400_000);
    let sent: Vec<u64> = events
        .iter()
        .filter(|e| matches!(e.value, Event::Tx { .. }))
        .map(|e| e.cycle)
        .collect();
    assert_eq!(sent.len(), n, "the whole command left UART0");
    let mut deframer = Deframer::new();
    let mut reply = None;
    let mut first_echo = None;
    for e in &events {
        if let Event::Console(b) = e.value {
            first_echo.get_or_insert(e.cycle);
            if let Some(Ok(m)) = deframer.push(b) {
                reply = LbcMessage::parse(&m).ok();
            }
        }
    }
    assert!(
        matches!(reply, Some(LbcMessage::Reply(Reply::ReadId(id))) if id.get() == CAR_ID),
        "{reply:?}"
    );
    // the answer cannot come back before the command finished going out
    let first = first_echo.expect("some reply byte");
    assert!(first > *sent.last().unwrap());
    assert!(
        cycles_to_us(first) < 20_000,
        "reply within 20 ms, got {} us",
        cycles_to_us(first)
    );
}

/// A program echoes what arrives on the radio UART; a byte peer on that UART sends a message
/// and gets it back, one character time per byte, after the whole message arrived.
#[test]
fn radio_uart_talks_to_a_byte_peer() {
    use verilator_tb::cosim::BytePeer;
    use verilator_tb::soc::CHAR_CYCLES;
    let mut p = Prog::new();
    p.li(S0, map::UART1);
    p.li(T1, 0x80).i(isa::sb(T1, S0, 3));
    p.li(T1, 8).i(isa::sb(T1, S0, 0)).i(isa::sb(0, S0, 1));
    p.li(T1, 3)
        .i(isa::sb(T1, S0, 3))
        .li(T1, 7)
        .i(isa::sb(T1, S0, 2));
    let top = p.here();
    p.i(isa::lbu(T1, S0, 5)).i(isa::andi(T1, T1, 1));
    let here = p.here();
    p.i(isa::beq(T1, 0, top as i32 - here as i32));
    p.i(isa::lbu(A0, S0, 0)).i(isa::sb(A0, S0, 0));
    let here = p.here();
    p.i(isa::jal(0, top as i32 - here as i32));

    let mut soc = Soc::new();
    soc.load_words(RAM_BASE, &p.words).unwrap();
    let mut peer = BytePeer::default();
    peer.send_at(100, b"radio!");
    let mut cosim = LbcCosim::new(soc, Lbc::with_memory_eeprom(LbcConfig::default(), CAR_ID))
        .with_radio(Box::new(peer));
    let events = cosim.run(20 * CHAR_CYCLES);
    let echoed: Vec<(u64, u8)> = events
        .iter()
        .filter_map(|e| match e.value {
            Event::Tx {
                uart: verilator_tb::soc::Uart::Radio,
                byte,
            } => Some((e.cycle, byte)),
            _ => None,
        })
        .collect();
    assert_eq!(
        echoed.iter().map(|e| e.1).collect::<Vec<_>>(),
        b"radio!",
        "{echoed:?}"
    );
    // line-paced echo: the polling loop (5 instructions) sees each byte within one pass, and
    // the core's counter-carry cycles shift a pass by a cycle now and then
    for w in echoed.windows(2) {
        let gap = w[1].0 - w[0].0;
        assert!(
            gap.abs_diff(CHAR_CYCLES) <= 8,
            "line-paced echo: {gap} cycles"
        );
    }
    // the first byte is in the receiver at 100 us (a peer's times are when a byte is complete
    // on the line) and takes one character time to go back out
    let first = verilator_tb::cosim::us_to_cycles(100) + CHAR_CYCLES;
    assert!(
        (first..first + CHAR_CYCLES / 2).contains(&echoed[0].0),
        "{echoed:?}"
    );
}
