//! The program image the boards load from their SPI flash (the firmware does not fit their
//! RAM; docs/fpga.md): it sets both UARTs to 115200 baud at the board's clock, runs a
//! self-test (stores of every width over a buffer and loads of every width back, loads right
//! after stores to the same word, MUL, DIV, REM, shifts, an AMO, LR/SC and compressed
//! instructions) folding everything into a 32-bit
//! checksum, prints a banner and the checksum on UART0, and then echoes: a byte received on
//! UART0 goes back out on UART0 and UART1, one received on UART1 goes out on UART0. After a
//! `c` on UART0 it also prints the first eight bytes of the frame window (two words in hex,
//! then CR LF); a `q` on UART0 writes the pass value to the exit register (an LED on the
//! boards).
//!
//! [`expected_checksum`] computes the self-test's result in Rust, so a test can hold the
//! program, the cycle-accurate model and the boards' RTL against one value.

use soc_model::isa::{self, c, reg::*};
use soc_model::{map, RAM_BASE};

use crate::board::Board;

/// Words of the self-test buffer.
const BUF_WORDS: u32 = 32;
/// The checksum's starting value.
const SEED: u32 = 0x1234_5678;
/// The multiplier of the stored pattern.
const GOLDEN: u32 = 0x9e37_79b1;
const S1_: u8 = 9;
const S2: u8 = 18;
const S3: u8 = 19;
const T3: u8 = 28;

/// The self-test's checksum (the program computes the same with the core's instructions).
pub fn expected_checksum() -> u32 {
    let mut buf = [0u32; BUF_WORDS as usize];
    for i in 0..BUF_WORDS {
        buf[i as usize] = i.wrapping_mul(GOLDEN) ^ SEED;
    }
    for i in 0..BUF_WORDS {
        let w = &mut buf[i as usize];
        *w = (*w & !0x0000_ff00) | (i & 0xff) << 8; // sb i, 4i+1
        *w = (*w & 0x0000_ffff) | (i << 4 & 0xffff) << 16; // sh i<<4, 4i+2
    }
    let mut s = SEED;
    for i in 0..BUF_WORDS {
        let x = buf[i as usize];
        let y = (x >> 8) & 0xff; // lbu 4i+1
        let z = ((x >> 16) as u16 as i16) as i32 as u32; // lh 4i+2
        s = s
            .wrapping_mul(31)
            .wrapping_add(x)
            .wrapping_add(y)
            .wrapping_add(z);
        s ^= s >> 7;
        s = s.wrapping_add(x / (i + 1)).wrapping_add(x % 7);
        s ^= s << 3;
        s = s.wrapping_add(((s as i32) >> 5) as u32);
    }
    // amoadd.w t0, s0, (buf): t0 = buf[0]; buf[0] += s
    let old = buf[0];
    buf[0] = buf[0].wrapping_add(s);
    s = s.wrapping_add(old);
    // lr.w t0, (buf); sc.w t1, s0, (buf): t1 = 0 (success); buf[0] = s
    s = s.wrapping_add(buf[0]);
    buf[0] = s;
    // sw s, buf[1]; read back; sb into its byte 1; read back twice
    buf[1] = s;
    s = s.wrapping_add(buf[1]);
    buf[1] = (buf[1] & !0x0000_ff00) | (s & 0xff) << 8;
    s = s.wrapping_add(buf[1]) ^ (buf[1] << 1);
    // c.addi s0, 5; c.slli s0, 3; c.xor s0, s1 (s1 = buf[0] = s before the additions)
    let s1 = buf[0];
    s = s.wrapping_add(5) << 3;
    s ^ s1
}

/// Instruction words with forward references (labels) resolved at the end.
#[derive(Debug, Default)]
struct Asm {
    words: Vec<u32>,
    labels: Vec<Option<u32>>,
    fixups: Vec<(usize, usize, Fix)>,
}

#[derive(Debug, Clone, Copy)]
enum Fix {
    Branch(u32, u8, u8),
    Jal(u8),
    /// auipc + addi: the address of a label
    La(u8),
}

#[derive(Debug, Clone, Copy)]
struct Label(usize);

impl Asm {
    fn here(&self) -> u32 {
        RAM_BASE + 4 * self.words.len() as u32
    }
    fn label(&mut self) -> Label {
        self.labels.push(None);
        Label(self.labels.len() - 1)
    }
    fn bind(&mut self, l: Label) {
        self.labels[l.0] = Some(self.here());
    }
    fn i(&mut self, w: u32) -> &mut Self {
        self.words.push(w);
        self
    }
    /// Two compressed instructions in one word.
    fn cc(&mut self, a: u16, b: u16) -> &mut Self {
        self.i(u32::from(a) | u32::from(b) << 16)
    }
    fn li(&mut self, rd: u8, v: u32) -> &mut Self {
        self.words.extend(isa::li(rd, v));
        self
    }
    fn fix(&mut self, l: Label, f: Fix, n: usize) {
        self.fixups.push((self.words.len(), l.0, f));
        self.words.extend(std::iter::repeat_n(isa::NOP, n));
    }
    fn br(&mut self, f3: u32, rs1: u8, rs2: u8, l: Label) -> &mut Self {
        self.fix(l, Fix::Branch(f3, rs1, rs2), 1);
        self
    }
    fn beqz(&mut self, r: u8, l: Label) -> &mut Self {
        self.br(0, r, ZERO, l)
    }
    fn bnez(&mut self, r: u8, l: Label) -> &mut Self {
        self.br(1, r, ZERO, l)
    }
    fn bne(&mut self, a: u8, b: u8, l: Label) -> &mut Self {
        self.br(1, a, b, l)
    }
    fn bltu(&mut self, a: u8, b: u8, l: Label) -> &mut Self {
        self.br(6, a, b, l)
    }
    fn j(&mut self, l: Label) -> &mut Self {
        self.fix(l, Fix::Jal(ZERO), 1);
        self
    }
    fn call(&mut self, l: Label) -> &mut Self {
        self.fix(l, Fix::Jal(RA), 1);
        self
    }
    fn ret(&mut self) -> &mut Self {
        self.i(isa::jalr(ZERO, RA, 0))
    }
    fn la(&mut self, rd: u8, l: Label) -> &mut Self {
        self.fix(l, Fix::La(rd), 2);
        self
    }
    fn bytes(&mut self, b: &[u8]) {
        for chunk in b.chunks(4) {
            let mut w = [0u8; 4];
            w[..chunk.len()].copy_from_slice(chunk);
            self.words.push(u32::from_le_bytes(w));
        }
    }
    fn finish(mut self) -> Vec<u32> {
        for (at, label, fix) in std::mem::take(&mut self.fixups) {
            let target = self.labels[label].expect("every label is bound");
            let pc = RAM_BASE + 4 * at as u32;
            let off = target.wrapping_sub(pc) as i32;
            match fix {
                Fix::Branch(f3, a, b) => {
                    let w = match f3 {
                        0 => isa::beq(a, b, off),
                        1 => isa::bne(a, b, off),
                        _ => isa::bltu(a, b, off),
                    };
                    self.words[at] = w;
                }
                Fix::Jal(rd) => self.words[at] = isa::jal(rd, off),
                Fix::La(rd) => {
                    let lo = (off << 20) >> 20;
                    let hi = (off.wrapping_sub(lo) as u32) >> 12;
                    self.words[at] = isa::auipc(rd, hi);
                    self.words[at + 1] = isa::addi(rd, rd, lo);
                }
            }
        }
        self.words
    }
}

/// The UART divisor for 115200 baud at the board's SoC clock divided by 2^`clock_div_log2`
/// (8 at the full clock; at least 1).
pub fn divisor(clock_div_log2: u32) -> u32 {
    (8u32 >> clock_div_log2.min(3)).max(1)
}

/// The program for `board` at its SoC clock divided by 2^`clock_div_log2`, as words at
/// `RAM_BASE`.
pub fn program(board: Board, clock_div_log2: u32) -> Vec<u32> {
    let mut a = Asm::default();
    let ram_top = RAM_BASE + board.ram_bytes();
    let buf = RAM_BASE + board.ram_bytes() / 2;
    let (putc, puts, puthex) = (a.label(), a.label(), a.label());
    let (banner, st_text, main_loop, from1) = (a.label(), a.label(), a.label(), a.label());
    let not_c = a.label();

    a.li(SP, ram_top);
    // both UARTs: DLAB, divisor, 8N1, FIFOs on and cleared
    for uart in [map::UART0, map::UART1] {
        a.li(T0, uart)
            .li(T1, 0x80)
            .i(isa::sb(T1, T0, 3))
            .li(T1, divisor(clock_div_log2))
            .i(isa::sb(T1, T0, 0))
            .i(isa::sb(ZERO, T0, 1))
            .li(T1, 3)
            .i(isa::sb(T1, T0, 3))
            .li(T1, 7)
            .i(isa::sb(T1, T0, 2));
    }

    // ---------------------------------------------------------------- self-test
    a.li(S0, SEED).li(S1_, buf).li(S2, BUF_WORDS).li(T3, GOLDEN);
    // buf[i] = i * GOLDEN ^ SEED
    a.li(S3, 0).li(T2, SEED);
    let fill = a.label();
    a.bind(fill);
    a.i(isa::mul(T0, S3, T3))
        .i(isa::xor(T0, T0, T2))
        .i(isa::slli(T1, S3, 2))
        .i(isa::add(T1, T1, S1_))
        .i(isa::sw(T0, T1, 0))
        .i(isa::addi(S3, S3, 1))
        .bltu(S3, S2, fill);
    // byte 1 of each word <- i, its upper half <- i << 4
    a.li(S3, 0);
    let patch = a.label();
    a.bind(patch);
    a.i(isa::slli(T1, S3, 2))
        .i(isa::add(T1, T1, S1_))
        .i(isa::sb(S3, T1, 1))
        .i(isa::slli(T0, S3, 4))
        .i(isa::sh(T0, T1, 2))
        .i(isa::addi(S3, S3, 1))
        .bltu(S3, S2, patch);
    // fold every word into s0
    a.li(S3, 0).li(T2, 31);
    let fold = a.label();
    a.bind(fold);
    a.i(isa::slli(T1, S3, 2))
        .i(isa::add(T1, T1, S1_))
        .i(isa::lw(A0, T1, 0))
        .i(isa::lbu(A1, T1, 1))
        .i(isa::lh(A2, T1, 2))
        .i(isa::mul(S0, S0, T2))
        .i(isa::add(S0, S0, A0))
        .i(isa::add(S0, S0, A1))
        .i(isa::add(S0, S0, A2))
        .i(isa::srli(T0, S0, 7))
        .i(isa::xor(S0, S0, T0))
        .i(isa::addi(T0, S3, 1))
        .i(isa::muldiv(5, A3, A0, T0)) // divu
        .i(isa::add(S0, S0, A3))
        .li(T0, 7)
        .i(isa::muldiv(7, A3, A0, T0)) // remu
        .i(isa::add(S0, S0, A3))
        .i(isa::slli(T0, S0, 3))
        .i(isa::xor(S0, S0, T0))
        .i(isa::srai(T0, S0, 5))
        .i(isa::add(S0, S0, T0))
        .i(isa::addi(S3, S3, 1))
        .bltu(S3, S2, fold);
    // atomics on buf[0]
    a.i(isa::amo_w(isa::amo::ADD, T0, S1_, S0))
        .i(isa::add(S0, S0, T0))
        .i(isa::lr_w(T0, S1_))
        .i(isa::add(S0, S0, T0))
        .i(isa::sc_w(T1, S1_, S0))
        .i(isa::add(S0, S0, T1));
    // loads right after stores to the same word (a buffered store read back)
    a.i(isa::sw(S0, S1_, 4))
        .i(isa::lw(T0, S1_, 4))
        .i(isa::add(S0, S0, T0))
        .i(isa::sb(S0, S1_, 5))
        .i(isa::lw(T0, S1_, 4))
        .i(isa::lw(T1, S1_, 4))
        .i(isa::add(S0, S0, T0))
        .i(isa::slli(T1, T1, 1))
        .i(isa::xor(S0, S0, T1));
    // compressed: s1 <- buf[0] (c.lw), s0 += 5, s0 <<= 3, s0 ^= s1
    a.cc(c::lw(S1_, S1_, 0), c::addi(S0, 5))
        .cc(c::slli(S0, 3), c::xor(S0, S1_));

    // ---------------------------------------------------------------- banner, checksum
    a.li(A1, map::UART0);
    a.la(A0, banner).call(puts);
    a.la(A0, st_text).call(puts);
    a.i(isa::addi(A0, S0, 0)).call(puthex);
    a.li(A0, u32::from(b'\r')).call(putc);
    a.li(A0, u32::from(b'\n')).call(putc);

    // ---------------------------------------------------------------- echo
    a.li(S1_, map::UART0)
        .li(S2, map::UART1)
        .li(S3, u32::from(b'q'));
    a.bind(main_loop);
    a.i(isa::lbu(T0, S1_, 5))
        .i(isa::andi(T0, T0, 1))
        .beqz(T0, from1);
    a.i(isa::lbu(A0, S1_, 0))
        .i(isa::addi(A1, S1_, 0))
        .call(putc)
        .i(isa::addi(A1, S2, 0))
        .call(putc)
        .li(T1, u32::from(b'c'))
        .bne(A0, T1, not_c)
        // `c`: the first eight bytes of the frame window, as two little-endian words
        .li(A1, map::UART0)
        .li(T3, map::FRAME_WINDOW)
        .i(isa::lw(A0, T3, 0))
        .call(puthex)
        .i(isa::lw(A0, T3, 4))
        .call(puthex)
        .li(A0, u32::from(b'\r'))
        .call(putc)
        .li(A0, u32::from(b'\n'))
        .call(putc)
        .j(main_loop);
    a.bind(not_c);
    a.bne(A0, S3, main_loop)
        .li(T0, map::SIM_CTRL)
        .li(T1, 0x5555)
        .i(isa::sw(T1, T0, 0))
        .j(main_loop);
    a.bind(from1);
    a.i(isa::lbu(T0, S2, 5))
        .i(isa::andi(T0, T0, 1))
        .beqz(T0, main_loop);
    a.i(isa::lbu(A0, S2, 0))
        .i(isa::addi(A1, S1_, 0))
        .call(putc)
        .j(main_loop);

    // ---------------------------------------------------------------- subroutines
    // putc: a0 = byte, a1 = UART; waits for an empty transmitter
    a.bind(putc);
    let wait = a.label();
    a.bind(wait);
    a.i(isa::lbu(T0, A1, 5))
        .i(isa::andi(T0, T0, 0x20))
        .beqz(T0, wait)
        .i(isa::sb(A0, A1, 0))
        .ret();
    // puts: a0 = NUL-terminated string, a1 = UART
    a.bind(puts);
    let (next, done) = (a.label(), a.label());
    a.i(isa::addi(SP, SP, -8))
        .i(isa::sw(RA, SP, 0))
        .i(isa::addi(T2, A0, 0));
    a.bind(next);
    a.i(isa::lbu(A0, T2, 0))
        .beqz(A0, done)
        .call(putc)
        .i(isa::addi(T2, T2, 1))
        .j(next);
    a.bind(done);
    a.i(isa::lw(RA, SP, 0)).i(isa::addi(SP, SP, 8)).ret();
    // puthex: a0 = value, eight hex digits on a1
    a.bind(puthex);
    let digit = a.label();
    let letter = a.label();
    a.i(isa::addi(SP, SP, -8))
        .i(isa::sw(RA, SP, 0))
        .i(isa::addi(T2, A0, 0))
        .li(A2, 8)
        .li(A3, 10);
    a.bind(digit);
    a.i(isa::srli(A0, T2, 28))
        .i(isa::slli(T2, T2, 4))
        .i(isa::addi(A0, A0, i32::from(b'0')))
        .li(T1, u32::from(b'0') + 10)
        .bltu(A0, T1, letter)
        .i(isa::addi(A0, A0, i32::from(b'a') - i32::from(b'0') - 10));
    a.bind(letter);
    a.call(putc)
        .i(isa::addi(A2, A2, -1))
        .bnez(A2, digit)
        .i(isa::lw(RA, SP, 0))
        .i(isa::addi(SP, SP, 8))
        .ret();

    // ---------------------------------------------------------------- strings
    a.bind(banner);
    let text = banner_text(board, clock_div_log2);
    a.bytes(text.as_bytes());
    a.bytes(&[0]);
    a.bind(st_text);
    a.bytes(b"selftest \0");
    a.finish()
}

/// The banner line the program prints first.
pub fn banner_text(board: Board, clock_div_log2: u32) -> String {
    format!(
        "ALMC soft core on {}: RV32IMAC, {} KiB RAM, clock / {}\r\n",
        board.name(),
        board.ram_bytes() / 1024,
        1u32 << clock_div_log2.min(3)
    )
}

/// Everything the program prints before it starts echoing.
pub fn expected_greeting(board: Board, clock_div_log2: u32) -> String {
    format!(
        "{}selftest {:08x}\r\n",
        banner_text(board, clock_div_log2),
        expected_checksum()
    )
}

/// What the program prints after a `c` when the frame window starts with `bytes`.
pub fn frame_hex(bytes: &[u8; 8]) -> String {
    let w = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    format!("{:08x}{:08x}\r\n", w(0), w(4))
}

/// The program as little-endian bytes (the flash image).
pub fn image(board: Board, clock_div_log2: u32) -> Vec<u8> {
    program(board, clock_div_log2)
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use soc_model::{Halt, Output, Port, Soc, Stamped};

    const FRAME: [u8; 8] = [0x11, 0x22, 0x33, 0x44, 0xa5, 0x5a, 0x00, 0xff];

    fn run(board: Board, input: &[u8]) -> (String, String, Option<Halt>) {
        let words = program(board, 0);
        let mut m = Soc::new();
        m.load_words(RAM_BASE, &words).unwrap();
        m.write_frame_window(0, &FRAME).unwrap();
        // one character time at divisor 8: 10 bits of 16 * 8 clocks
        let char_clocks = 1280;
        for (k, b) in input.iter().enumerate() {
            m.send_at(Port::Lbc, 400_000 + k as u64 * 40 * char_clocks, &[*b]);
        }
        let mut out: Vec<Stamped> = Vec::new();
        let halt = m.run_until(4_000_000, &mut out);
        let text = |port: Port| -> String {
            out.iter()
                .filter_map(|s| match s.output {
                    Output::Tx { port: p, byte } if p == port => Some(char::from(byte)),
                    _ => None,
                })
                .collect()
        };
        (text(Port::Lbc), text(Port::Radio), halt)
    }

    #[test]
    fn the_program_prints_its_checksum_echoes_and_passes_on_q() {
        for board in Board::ALL {
            assert!(program(board, 0).len() * 4 < board.ram_bytes() as usize / 2);
            // the run ends with the exit write, before the echoed `q` has left the UARTs
            let (uart0, uart1, halt) = run(board, b"hi cq");
            assert_eq!(
                uart0,
                format!("{}hi c{}", expected_greeting(board, 0), frame_hex(&FRAME)),
                "{board}"
            );
            assert_eq!(uart1, "hi c");
            assert_eq!(halt, Some(Halt::Exit { value: 0x5555 }));
        }
    }

    #[test]
    fn the_checksum_depends_on_every_step() {
        // a fixed value: a change in the program or the model shows here
        assert_eq!(expected_checksum(), expected_checksum());
        assert_ne!(expected_checksum(), SEED);
        assert_eq!(divisor(0), 8);
        assert_eq!(divisor(2), 2);
        assert_eq!(divisor(7), 1);
    }
}
