//! The SoC's devices as in `verilator-tb/rtl/`: the 16550 UART (`uart16550.v`), the CLINT
//! (`clint.v`) and the PLIC (`plic.v`).
//!
//! Each is a transcription of its RTL: the state after a clock edge is computed from the state
//! before it and that cycle's inputs, with the same rules in the same order. Timers are kept as
//! absolute cycle numbers instead of counters (the UART's shift timer as the cycle its stop bit
//! ends, its idle timer as a value at a given cycle, mtime as an offset from the cycle number),
//! so a device that nothing touches costs nothing: it is stepped only in the cycles where
//! something happens (a byte arrives, the shifter finishes or loads) and its state in between
//! follows from the cycle number.

use std::collections::VecDeque;

/// A bus access to a UART in one cycle (the RTL's `sel` is implied).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Access {
    /// Registers 4-7 (`dmem_addr[2]`).
    pub addr_hi: bool,
    /// A read with side effects (`dmem_re`).
    pub re: bool,
    /// Byte lanes read.
    pub rmask: u8,
    /// Byte lanes written.
    pub wstrb: u8,
    /// Write data (the store's lanes replicated as on the bus).
    pub wdata: u32,
}

/// 16550 UART with 16-byte FIFOs, byte-level but bit-timed line side (`uart16550.v`).
#[derive(Debug, Clone)]
pub(crate) struct Uart {
    /// The state held is the state during cycle `t` (after `t` clock edges).
    t: u64,
    ier: u8,
    lcr: u8,
    mcr: u8,
    scr: u8,
    dll: u8,
    dlm: u8,
    fifo_en: bool,
    rx_trig: u8,
    overrun: bool,
    thre_ip: bool,
    rxf: [u8; 16],
    rx_rd: u8,
    rx_wr: u8,
    rx_cnt: u8,
    txf: [u8; 16],
    tx_rd: u8,
    tx_wr: u8,
    tx_cnt: u8,
    sh_busy: bool,
    sh_data: u8,
    /// While `sh_busy`: the cycle in which the shift timer reads zero (the stop bit ends).
    sh_done_at: u64,
    /// Idle timer: `idle_base` in cycle `idle_at`, then one more per cycle until it reaches
    /// the timeout threshold (its value only matters while the receive FIFO holds bytes, and
    /// every byte that enters it restarts it).
    idle_at: u64,
    idle_base: u32,
    /// Bytes for the receiver: (cycle presented on `rx_valid`, byte), in order.
    rx_q: VecDeque<(u64, u8)>,
}

const IIR_NONE: u8 = 0x1;
const IIR_THRE: u8 = 0x2;
const IIR_RDA: u8 = 0x4;
const IIR_LS: u8 = 0x6;
const IIR_RTO: u8 = 0xc;

impl Uart {
    pub fn new() -> Self {
        Self {
            t: 0,
            ier: 0,
            lcr: 0,
            mcr: 0,
            scr: 0,
            dll: 0,
            dlm: 0,
            fifo_en: false,
            rx_trig: 0,
            overrun: false,
            thre_ip: false,
            rxf: [0; 16],
            rx_rd: 0,
            rx_wr: 0,
            rx_cnt: 0,
            txf: [0; 16],
            tx_rd: 0,
            tx_wr: 0,
            tx_cnt: 0,
            sh_busy: false,
            sh_data: 0,
            sh_done_at: 0,
            idle_at: 0,
            idle_base: 0,
            rx_q: VecDeque::new(),
        }
    }

    /// Queues a byte presented on `rx_valid` in cycle `at` (callers keep `at` increasing).
    pub fn push_rx(&mut self, at: u64, byte: u8) {
        self.rx_q.push_back((at, byte));
    }

    /// The cycles of the bytes queued for the receiver.
    #[cfg(test)]
    pub fn queued(&self) -> impl Iterator<Item = u64> + '_ {
        self.rx_q.iter().map(|q| q.0)
    }

    /// Clocks per character: 10 bits of 16 x divisor clocks.
    fn char_clk(&self) -> u32 {
        let d = u32::from(self.dlm) << 8 | u32::from(self.dll);
        d.max(1) * 160
    }

    /// Idle clocks after which received bytes raise the timeout: 4 character times.
    fn timeout_clk(&self) -> u32 {
        self.char_clk() * 4
    }

    fn idle(&self, t: u64) -> u32 {
        let thr = self.timeout_clk();
        if self.idle_base >= thr {
            self.idle_base
        } else {
            let dt = t.saturating_sub(self.idle_at);
            let v = u64::from(self.idle_base) + dt;
            v.min(u64::from(thr)) as u32
        }
    }

    fn rx_timeout(&self) -> bool {
        self.rx_cnt != 0 && self.idle(self.t) >= self.timeout_clk()
    }

    fn trig_level(&self) -> u8 {
        if !self.fifo_en {
            return 1;
        }
        match self.rx_trig {
            0 => 1,
            1 => 4,
            2 => 8,
            _ => 14,
        }
    }

    fn iir_id(&self, rx_timeout: bool) -> u8 {
        let ip_ls = self.ier & 4 != 0 && self.overrun;
        let ip_rda = self.ier & 1 != 0 && self.rx_cnt >= self.trig_level();
        let ip_rto = self.ier & 1 != 0 && rx_timeout;
        let ip_thre = self.ier & 2 != 0 && self.thre_ip;
        if ip_ls {
            IIR_LS
        } else if ip_rda {
            IIR_RDA
        } else if ip_rto {
            IIR_RTO
        } else if ip_thre {
            IIR_THRE
        } else {
            IIR_NONE
        }
    }

    /// The interrupt output in the current cycle.
    pub fn irq(&self) -> bool {
        self.iir_id(self.rx_timeout()) != IIR_NONE
    }

    /// Whether the interrupt output could ever rise without the core touching the UART:
    /// received bytes can always come (RX data, timeout, overrun), and the THR-empty flag
    /// rises when bytes still queued for transmission drain.
    pub fn irq_possible(&self) -> bool {
        self.irq() || self.ier & 0b101 != 0 || (self.ier & 2 != 0 && self.tx_cnt != 0)
    }

    /// Register read data in the current cycle (no side effects).
    pub fn rdata(&self, addr_hi: bool) -> u32 {
        if addr_hi {
            let lsr = (u8::from(self.tx_cnt == 0 && !self.sh_busy) << 6)
                | (u8::from(self.tx_cnt == 0) << 5)
                | (u8::from(self.overrun) << 1)
                | u8::from(self.rx_cnt != 0);
            u32::from(self.scr) << 24 | 0xb0 << 16 | u32::from(lsr) << 8 | u32::from(self.mcr)
        } else {
            let dlab = self.lcr & 0x80 != 0;
            let rbr = if self.rx_cnt != 0 {
                self.rxf[usize::from(self.rx_rd & 15)]
            } else {
                0
            };
            let iir = (if self.fifo_en { 0xc0 } else { 0 }) | self.iir_id(self.rx_timeout());
            u32::from(self.lcr) << 24
                | u32::from(iir) << 16
                | u32::from(if dlab { self.dlm } else { self.ier }) << 8
                | u32::from(if dlab { self.dll } else { rbr })
        }
    }

    /// The first cycle (at or after the current one) whose clock edge changes the state
    /// without the core: a byte arrives, the shifter finishes, or it loads a queued byte.
    fn next_step(&self) -> u64 {
        let mut e = u64::MAX;
        if let Some(&(at, _)) = self.rx_q.front() {
            e = at.max(self.t);
        }
        if self.sh_busy {
            e = e.min(self.sh_done_at);
        } else if self.tx_cnt != 0 {
            e = self.t;
        }
        e
    }

    /// The first cycle after the current one in which the interrupt output may differ from
    /// now without the core touching the UART.
    pub fn next_change(&self) -> u64 {
        let mut e = self.next_step().saturating_add(1);
        if self.ier & 1 != 0 && self.rx_cnt != 0 {
            let thr = self.timeout_clk();
            if self.idle_base < thr {
                let onset = self.idle_at + u64::from(thr - self.idle_base);
                if onset > self.t {
                    e = e.min(onset);
                }
            }
        }
        e
    }

    /// Advances to cycle `to` (the state during it), stepping the cycles in between where
    /// something happens; bytes the transmitter finishes go to `tx` with the cycle they
    /// appear in.
    pub fn advance_to(&mut self, to: u64, tx: &mut impl FnMut(u64, u8)) {
        loop {
            let e = self.next_step();
            if e >= to {
                break;
            }
            self.t = e;
            self.step(None, tx);
        }
        self.t = self.t.max(to);
    }

    /// The clock edge ending the current cycle, with the core's access if there is one.
    pub fn step(&mut self, acc: Option<Access>, tx: &mut impl FnMut(u64, u8)) {
        let t = self.t;
        let rx = match self.rx_q.front() {
            Some(&(at, b)) if at <= t => {
                self.rx_q.pop_front();
                Some(b)
            }
            _ => None,
        };
        let thr = self.timeout_clk();
        let idle = self.idle(t);
        let rx_timeout = self.rx_cnt != 0 && idle >= thr;
        let iir_id = self.iir_id(rx_timeout);
        let dlab = self.lcr & 0x80 != 0;
        let char_clk = self.char_clk();
        let sel = acc.is_some();
        let a = acc.unwrap_or_default();
        let lo = sel && !a.addr_hi;
        let rd_rbr = lo && a.re && a.rmask & 1 != 0 && !dlab;
        let rd_iir = lo && a.re && a.rmask & 4 != 0;
        let rd_lsr = sel && a.addr_hi && a.re && a.rmask & 2 != 0;
        let wr_thr = lo && a.wstrb & 1 != 0 && !dlab;
        let wr_fcr = lo && a.wstrb & 4 != 0;
        let rx_pop = rd_rbr && self.rx_cnt != 0;
        let rx_push = rx.is_some() && self.rx_cnt != 16;
        let tx_push = wr_thr && self.tx_cnt != 16;
        let sh_done = self.sh_busy && t == self.sh_done_at;
        let tx_pop = (!self.sh_busy || sh_done) && self.tx_cnt != 0;

        // receive side
        if let (true, Some(b)) = (rx_push, rx) {
            self.rxf[usize::from(self.rx_wr & 15)] = b;
            self.rx_wr = (self.rx_wr + 1) & 15;
        }
        let mut overrun = self.overrun;
        if rx.is_some() && self.rx_cnt == 16 {
            overrun = true;
        }
        if rx_pop {
            self.rx_rd = (self.rx_rd + 1) & 15;
        }
        let mut rx_cnt = self.rx_cnt + u8::from(rx_push) - u8::from(rx_pop);
        let idle_next = if rx_push || rx_pop {
            0
        } else if !rx_timeout {
            idle + 1
        } else {
            idle
        };
        if rd_lsr {
            overrun = false;
        }

        // transmit side
        let popped = self.txf[usize::from(self.tx_rd & 15)];
        if tx_push {
            self.txf[usize::from(self.tx_wr & 15)] = a.wdata as u8;
            self.tx_wr = (self.tx_wr + 1) & 15;
        }
        if sh_done {
            self.sh_busy = false;
            tx(t + 1, self.sh_data);
        }
        if tx_pop {
            self.sh_busy = true;
            self.sh_data = popped;
            self.sh_done_at = t + u64::from(char_clk);
            self.tx_rd = (self.tx_rd + 1) & 15;
        }
        let mut tx_cnt = self.tx_cnt + u8::from(tx_push) - u8::from(tx_pop);
        let mut thre = self.thre_ip;
        if tx_pop && self.tx_cnt == 1 && !tx_push {
            thre = true;
        }
        if rd_iir && iir_id == IIR_THRE {
            thre = false;
        }
        if wr_thr {
            thre = false;
        }

        // register writes
        if lo {
            if a.wstrb & 1 != 0 && dlab {
                self.dll = a.wdata as u8;
            }
            if a.wstrb & 2 != 0 {
                if dlab {
                    self.dlm = (a.wdata >> 8) as u8;
                } else {
                    if a.wdata & (1 << 9) != 0 && self.ier & 2 == 0 && self.tx_cnt == 0 {
                        thre = true;
                    }
                    self.ier = ((a.wdata >> 8) & 0xf) as u8;
                }
            }
            if wr_fcr {
                self.fifo_en = a.wdata & (1 << 16) != 0;
                self.rx_trig = ((a.wdata >> 22) & 3) as u8;
                if a.wdata & (1 << 17) != 0 {
                    self.rx_rd = 0;
                    self.rx_wr = 0;
                    rx_cnt = 0;
                }
                if a.wdata & (1 << 18) != 0 {
                    self.tx_rd = 0;
                    self.tx_wr = 0;
                    tx_cnt = 0;
                }
            }
            if a.wstrb & 8 != 0 {
                self.lcr = (a.wdata >> 24) as u8;
            }
        } else if sel {
            if a.wstrb & 1 != 0 {
                self.mcr = a.wdata as u8;
            }
            if a.wstrb & 8 != 0 {
                self.scr = (a.wdata >> 24) as u8;
            }
        }
        self.overrun = overrun;
        self.rx_cnt = rx_cnt;
        self.tx_cnt = tx_cnt;
        self.thre_ip = thre;
        // the idle timer restarts from its value after this edge (the threshold may change)
        self.idle_at = t + 1;
        self.idle_base = idle_next & ((1 << 26) - 1);
        self.t = t + 1;
    }
}

/// PLIC with one context, sources 1..=15, priorities 0..=7, level triggered (`plic.v`).
#[derive(Debug, Clone, Default)]
pub(crate) struct Plic {
    prio: [u8; 16],
    /// Bits 1..=15.
    enable: u16,
    in_service: u16,
    threshold: u8,
}

impl Plic {
    fn best(&self, src: u16) -> (u8, u8) {
        let pending = src & !self.in_service & self.enable;
        let (mut id, mut p) = (0u8, 0u8);
        if pending == 0 {
            return (0, 0);
        }
        for i in 1..16u8 {
            let pi = self.prio[usize::from(i)];
            if pending & (1 << i) != 0 && self.enable & (1 << i) != 0 && pi > p {
                id = i;
                p = pi;
            }
        }
        (id, p)
    }

    /// The machine external interrupt line for the source levels `src` (bit n = source n).
    pub fn eip(&self, src: u16) -> bool {
        let (id, p) = self.best(src);
        id != 0 && p > self.threshold
    }

    /// Whether source `s` could raise the line if its level rose (enabled, above the
    /// threshold, not claimed).
    pub fn can_signal(&self, s: u8) -> bool {
        let bit = 1u16 << s;
        self.enable & bit != 0
            && self.in_service & bit == 0
            && self.prio[usize::from(s)] > self.threshold
    }

    /// Read of the word at `offset` (`dmem_addr[21:0]`); a read with side effects (`re`) of
    /// the claim register claims the best source.
    pub fn read(&mut self, offset: u32, re: bool, src: u16) -> u32 {
        let eip = self.eip(src);
        let (best, _) = self.best(src);
        if re && offset == 0x20_0004 && eip {
            self.in_service |= 1 << best;
        }
        if offset < 0x40 && offset & 3 == 0 && (offset >> 2) & 15 != 0 {
            u32::from(self.prio[((offset >> 2) & 15) as usize])
        } else if offset == 0x1000 {
            u32::from((src & !self.in_service) & 0xfffe)
        } else if offset == 0x2000 {
            u32::from(self.enable & 0xfffe)
        } else if offset == 0x20_0000 {
            u32::from(self.threshold)
        } else if offset == 0x20_0004 {
            if eip {
                u32::from(best)
            } else {
                0
            }
        } else {
            0
        }
    }

    /// Write of the word at `offset` (any byte lane set).
    pub fn write(&mut self, offset: u32, wdata: u32) {
        if offset < 0x40 && (offset >> 2) & 15 != 0 {
            self.prio[((offset >> 2) & 15) as usize] = (wdata & 7) as u8;
        }
        if offset == 0x2000 {
            self.enable = (wdata & 0xfffe) as u16;
        }
        if offset == 0x20_0000 {
            self.threshold = (wdata & 7) as u8;
        }
        if offset == 0x20_0004 && wdata & 0xf != 0 && wdata >> 4 == 0 {
            self.in_service &= !(1 << (wdata & 0xf));
        }
    }
}

/// CLINT for one hart; mtime counts core clocks (`clint.v`).
#[derive(Debug, Clone)]
pub(crate) struct Clint {
    pub msip: bool,
    /// mtime in cycle t is `t + mtime_off` (wrapping).
    mtime_off: u64,
    pub mtimecmp: u64,
}

impl Clint {
    pub fn new() -> Self {
        Self {
            msip: false,
            mtime_off: 0,
            mtimecmp: u64::MAX,
        }
    }

    pub fn mtime(&self, t: u64) -> u64 {
        t.wrapping_add(self.mtime_off)
    }

    pub fn mtip(&self, t: u64) -> bool {
        self.mtime(t) >= self.mtimecmp
    }

    /// The first cycle after `t` in which mtip differs from cycle `t`, if nothing writes.
    pub fn next_change(&self, t: u64) -> u64 {
        let now = self.mtime(t);
        let dt = if now >= self.mtimecmp {
            // falls when mtime wraps to zero
            (u64::MAX - now).saturating_add(1)
        } else {
            self.mtimecmp - now
        };
        t.saturating_add(dt)
    }

    /// Read of the word at `offset` (`dmem_addr[15:0]`) in cycle `t`.
    pub fn read(&self, t: u64, offset: u32) -> u32 {
        match offset {
            0x0000 => u32::from(self.msip),
            0x4000 => self.mtimecmp as u32,
            0x4004 => (self.mtimecmp >> 32) as u32,
            0xbff8 => self.mtime(t) as u32,
            0xbffc => (self.mtime(t) >> 32) as u32,
            _ => 0,
        }
    }

    /// Write in cycle `t` (takes effect from cycle `t + 1`).
    pub fn write(&mut self, t: u64, offset: u32, wstrb: u8, wdata: u32) {
        let lane = (0..4).fold(0u32, |m, k| {
            if wstrb & (1 << k) != 0 {
                m | 0xff << (8 * k)
            } else {
                m
            }
        });
        let merge = |old: u32| (old & !lane) | (wdata & lane);
        match offset {
            0x0000 if wstrb & 1 != 0 => self.msip = wdata & 1 != 0,
            0x4000 => {
                let lo = merge(self.mtimecmp as u32);
                self.mtimecmp = (self.mtimecmp & !0xffff_ffff) | u64::from(lo);
            }
            0x4004 => {
                let hi = merge((self.mtimecmp >> 32) as u32);
                self.mtimecmp = (self.mtimecmp & 0xffff_ffff) | u64::from(hi) << 32;
            }
            0xbff8 | 0xbffc => {
                // the part written replaces its bits of mtime + 1; the other half keeps the
                // increment (with its carry)
                let now = self.mtime(t);
                let inc = now.wrapping_add(1);
                let next = if offset == 0xbff8 {
                    (inc & !0xffff_ffff) | u64::from(merge(now as u32))
                } else {
                    u64::from(merge((now >> 32) as u32)) << 32 | (inc & 0xffff_ffff)
                };
                self.mtime_off = next.wrapping_sub(t + 1);
            }
            _ => {}
        }
    }
}
