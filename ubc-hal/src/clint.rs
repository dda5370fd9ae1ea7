//! CLINT machine timer: a monotonic clock from `mtime` and one-shot wakeups through
//! `mtimecmp` (hart 0). The program reads time as ticks or microseconds; the timer interrupt
//! only ends a WFI idle, it carries no work of its own.

use crate::mmio::RegisterBus;
use core::cell::Cell;

/// Register offsets for hart 0.
pub mod reg {
    /// `mtimecmp` of hart 0 (64 bits, low word first).
    pub const MTIMECMP: usize = 0x4000;
    /// `mtime` (64 bits, low word first).
    pub const MTIME: usize = 0xBFF8;
}

/// The last tick-to-microsecond conversion: `ticks * num = micros * den + rem`.
#[derive(Debug, Clone, Copy)]
struct Conversion {
    ticks: u64,
    micros: u64,
    rem: u32,
}

/// The machine timer and the rate `mtime` counts at.
///
/// [`Clint::micros`] converts incrementally from its previous answer with one 32-bit
/// multiply and a division by a constant (`1e6 / hz` as a reduced fraction `num / den`),
/// exactly; only a jump of more than a few hundred milliseconds since the last call takes the
/// 64-bit division. On the soft core a 64-bit division is a software loop of several hundred
/// cycles and a 32-bit one 34 cycles, and the program reads the time many times per loop, so
/// the divisions by `num` and `den` are multiplications ([`Divider`]).
#[derive(Debug)]
pub struct Clint<B> {
    bus: B,
    hz: u32,
    num: Divider,
    den: Divider,
    /// The longest tick step converted from the last answer (`step * num + rem` fits 32 bits).
    step_max: u32,
    /// The longest microsecond step to a wakeup worked out from the last answer
    /// (`us * den` fits 32 bits).
    us_max: u32,
    last: Cell<Conversion>,
}

/// Division of any `u32` by a divisor fixed in advance, exactly, with a multiplication
/// (the high word of a 32 x 32-bit product), a subtraction, an addition and two shifts: the
/// round-up method of Granlund and Montgomery ("Division by invariant integers using
/// multiplication", 1994, figure 4.1). The constants are worked out in a `const fn`, so a
/// board's timer has them at compile time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Divider {
    d: u32,
    m: u32,
    sh1: u8,
    sh2: u8,
}

impl Divider {
    /// Division by `d` (0 is taken as 1).
    pub const fn new(d: u32) -> Self {
        let d = if d == 0 { 1 } else { d };
        // l = ceil(log2 d), 0..=32
        let l = 32 - (d - 1).leading_zeros();
        // m = floor(2^32 (2^l - d) / d) + 1 < 2^32; the product is below 2^64 for l <= 32.
        let m = ((1u64 << 32) * ((1u64 << l) - d as u64) / d as u64 + 1) as u32;
        Self {
            d,
            m,
            sh1: if l > 0 { 1 } else { 0 },
            sh2: if l > 0 { (l - 1) as u8 } else { 0 },
        }
    }

    /// The divisor.
    pub const fn divisor(&self) -> u32 {
        self.d
    }

    /// `n / d`.
    #[inline]
    pub const fn div(&self, n: u32) -> u32 {
        let t = ((n as u64 * self.m as u64) >> 32) as u32;
        (t + ((n - t) >> self.sh1)) >> self.sh2
    }

    /// `(n / d, n % d)`.
    #[inline]
    pub const fn div_rem(&self, n: u32) -> (u32, u32) {
        let q = self.div(n);
        (q, n - q * self.d)
    }

    /// `n / d` rounded up.
    #[inline]
    pub const fn div_ceil(&self, n: u32) -> u32 {
        let (q, r) = self.div_rem(n);
        if r > 0 {
            q + 1
        } else {
            q
        }
    }
}

const fn gcd(mut a: u32, mut b: u32) -> u32 {
    while b != 0 {
        let t = a % b;
        a = b;
        b = t;
    }
    a
}

/// A timer rate and its microsecond ratio, worked out once (a `const` on the boards: the
/// reduction is a loop of divisions).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rate {
    hz: u32,
    num: u32,
    den: u32,
}

impl Rate {
    /// `mtime` counting at `hz` (0 is taken as 1).
    pub const fn of(hz: u32) -> Self {
        let hz = if hz == 0 { 1 } else { hz };
        let g = gcd(1_000_000, hz);
        Self {
            hz,
            num: 1_000_000 / g,
            den: hz / g,
        }
    }
}

impl<B: RegisterBus> Clint<B> {
    /// A timer whose `mtime` counts at `hz` (must be nonzero).
    pub const fn new(bus: B, hz: u32) -> Self {
        Self::with_rate(bus, Rate::of(hz))
    }

    /// A timer whose `mtime` counts at `rate`.
    pub const fn with_rate(bus: B, rate: Rate) -> Self {
        let num = Divider::new(rate.num);
        Self {
            bus,
            hz: rate.hz,
            num,
            den: Divider::new(rate.den),
            step_max: num.div(u32::MAX.saturating_sub(rate.den)),
            us_max: u32::MAX / rate.den,
            last: Cell::new(Conversion {
                ticks: 0,
                micros: 0,
                rem: 0,
            }),
        }
    }

    /// The `mtime` rate in Hz.
    pub const fn hz(&self) -> u32 {
        self.hz
    }

    /// Current `mtime`. The high word is read twice so a carry between the two word reads of
    /// this 32-bit hart cannot produce a time 2^32 ticks off.
    pub fn ticks(&self) -> u64 {
        loop {
            let hi = self.bus.read32(reg::MTIME + 4);
            let lo = self.bus.read32(reg::MTIME);
            if self.bus.read32(reg::MTIME + 4) == hi {
                return (u64::from(hi) << 32) | u64::from(lo);
            }
        }
    }

    /// The low 32 bits of `mtime` (one register read: for time stamps in interrupt handlers).
    pub fn ticks_lo(&self) -> u32 {
        self.bus.read32(reg::MTIME)
    }

    /// Current time in microseconds since reset (`floor(ticks * 1e6 / hz)`, exactly).
    pub fn micros(&self) -> u64 {
        self.micros_at(self.ticks())
    }

    /// `ticks` in microseconds, from the previous conversion when it is close.
    fn micros_at(&self, ticks: u64) -> u64 {
        let last = self.last.get();
        let (num, den) = (self.num.divisor(), self.den.divisor());
        let m = match ticks.checked_sub(last.ticks) {
            Some(d) if d <= u64::from(self.step_max) => {
                // d * num + rem < 2^32 by the bound on d.
                let (q, rem) = self.den.div_rem(d as u32 * num + last.rem);
                let micros = last.micros + u64::from(q);
                self.last.set(Conversion { ticks, micros, rem });
                return micros;
            }
            _ => ticks_to_micros(ticks, self.hz),
        };
        let rem = ((ticks % u64::from(den)) * u64::from(num) % u64::from(den)) as u32;
        self.last.set(Conversion {
            ticks,
            micros: m,
            rem,
        });
        m
    }

    /// Current time in milliseconds since reset.
    pub fn millis(&self) -> u64 {
        self.micros() / 1000
    }

    /// Ticks in `us` microseconds.
    pub fn ticks_from_micros(&self, us: u64) -> u64 {
        micros_to_ticks(us, self.hz)
    }

    /// The first tick at which the time reads `us` microseconds or later (at once when that
    /// is already past): the wakeup for a deadline. Like [`Clint::micros`] it works from the
    /// last conversion with 32-bit arithmetic when the deadline is less than a few hundred
    /// milliseconds after it.
    pub fn wakeup_tick(&self, us: u64) -> u64 {
        let last = self.last.get();
        // At `last`: ticks * num = micros * den + rem. Wanted: the least T >= last.ticks with
        // T * num >= us * den, i.e. (T - last.ticks) * num >= d * den - rem.
        let Some(d) = us.checked_sub(last.micros) else {
            return last.ticks;
        };
        if d <= u64::from(self.us_max) {
            let need = d as u32 * self.den.divisor();
            return last.ticks + u64::from(self.num.div_ceil(need.saturating_sub(last.rem)));
        }
        let t = micros_to_ticks(us, self.hz);
        if ticks_to_micros(t, self.hz) < us {
            t + 1
        } else {
            t
        }
    }

    /// The time in microseconds (as [`Clint::micros`] gives it) of a tick in the recent past,
    /// known by the low 32 bits of `mtime` (an interrupt handler's stamp).
    pub fn micros_of_recent(&self, tick_lo: u32) -> u64 {
        let now = self.ticks();
        let now_us = self.micros_at(now);
        let age = (now as u32).wrapping_sub(tick_lo);
        if age > u32::MAX / 2 {
            // From the future: a stamp cannot be, so take it as now.
            return now_us;
        }
        let last = self.last.get();
        // micros(now - age) = floor((now_us * den + rem - age * num) / den).
        match age.checked_mul(self.num.divisor()) {
            Some(a) if a <= last.rem => now_us,
            Some(a) => now_us.saturating_sub(u64::from(self.den.div_ceil(a - last.rem))),
            None => ticks_to_micros(now - u64::from(age), self.hz),
        }
    }

    /// Arms the timer interrupt for the moment `mtime` reaches `deadline`.
    ///
    /// The low word is parked at its maximum first, so no intermediate value lies in the past.
    pub fn set_wakeup(&self, deadline: u64) {
        self.bus.write32(reg::MTIMECMP, u32::MAX);
        self.bus.write32(reg::MTIMECMP + 4, (deadline >> 32) as u32);
        self.bus.write32(reg::MTIMECMP, deadline as u32);
    }

    /// Disarms the timer interrupt (clears a pending one).
    pub fn clear_wakeup(&self) {
        self.bus.write32(reg::MTIMECMP, u32::MAX);
        self.bus.write32(reg::MTIMECMP + 4, u32::MAX);
    }

    /// The armed deadline.
    pub fn wakeup(&self) -> u64 {
        (u64::from(self.bus.read32(reg::MTIMECMP + 4)) << 32)
            | u64::from(self.bus.read32(reg::MTIMECMP))
    }

    /// Busy-waits `us` microseconds (the hart stays awake).
    pub fn delay_us(&self, us: u64) {
        let end = self.ticks().saturating_add(self.ticks_from_micros(us));
        while self.ticks() < end {
            core::hint::spin_loop();
        }
    }
}

/// Converts ticks at `hz` to microseconds without overflow for any `u64` tick count.
// Out of line on the firmware: its two 64-bit divisions inlined into three conversions cost
// 192 bytes more.
#[cfg_attr(target_arch = "riscv32", inline(never))]
pub const fn ticks_to_micros(ticks: u64, hz: u32) -> u64 {
    let hz = hz as u64;
    (ticks / hz) * 1_000_000 + (ticks % hz) * 1_000_000 / hz
}

/// Converts microseconds to ticks at `hz` (rounding down), saturating at `u64::MAX`.
pub const fn micros_to_ticks(us: u64, hz: u32) -> u64 {
    let hz = hz as u64;
    let whole = (us / 1_000_000).saturating_mul(hz);
    whole.saturating_add((us % 1_000_000) * hz / 1_000_000)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mmio::testing::RamBus;
    use proptest::prelude::*;

    const HZ: u32 = 10_000_000;

    #[test]
    fn reads_64_bit_mtime() {
        let bus = RamBus::new(0xC000);
        bus.write32(reg::MTIME, 0x89AB_CDEF);
        bus.write32(reg::MTIME + 4, 0x0000_0012);
        let clint = Clint::new(&bus, HZ);
        assert_eq!(clint.ticks(), 0x12_89AB_CDEF);
        assert_eq!(clint.micros(), 0x12_89AB_CDEF / 10);
    }

    #[test]
    fn wakeup_registers() {
        let bus = RamBus::new(0xC000);
        let clint = Clint::new(&bus, HZ);
        clint.set_wakeup(0x1_0000_0005);
        assert_eq!(bus.read32(reg::MTIMECMP), 5);
        assert_eq!(bus.read32(reg::MTIMECMP + 4), 1);
        assert_eq!(clint.wakeup(), 0x1_0000_0005);
        clint.clear_wakeup();
        assert_eq!(clint.wakeup(), u64::MAX);
    }

    #[test]
    fn conversions() {
        assert_eq!(ticks_to_micros(10_000_000, HZ), 1_000_000);
        assert_eq!(ticks_to_micros(15, HZ), 1);
        assert_eq!(micros_to_ticks(50_000, HZ), 500_000);
        assert_eq!(micros_to_ticks(u64::MAX, HZ), u64::MAX);
        assert_eq!(ticks_to_micros(u64::MAX, HZ), u64::MAX / 10);
        assert_eq!(micros_to_ticks(1, 32_768), 0);
        assert_eq!(micros_to_ticks(1_000_000, 32_768), 32_768);
    }

    #[test]
    fn dividers_at_the_edges() {
        for d in [
            1,
            2,
            3,
            7,
            625,
            9216,
            1 << 31,
            (1 << 31) + 1,
            u32::MAX - 1,
            u32::MAX,
        ] {
            let div = Divider::new(d);
            for n in [0, 1, d - 1, d, d.wrapping_add(1), u32::MAX - 1, u32::MAX] {
                assert_eq!(div.div_rem(n), (n / d, n % d), "{n} / {d}");
                assert_eq!(div.div_ceil(n), n.div_ceil(d), "{n} / {d} up");
            }
        }
        assert_eq!(Divider::new(0).div(12), 12, "0 is taken as 1");
    }

    proptest! {
        #[test]
        fn dividers_divide_exactly(n in any::<u32>(), d in prop_oneof![1u32..100_000, any::<u32>()]) {
            let d = d.max(1);
            let div = Divider::new(d);
            prop_assert_eq!(div.div_rem(n), (n / d, n % d));
            prop_assert_eq!(div.div_ceil(n), n.div_ceil(d));
        }

        #[test]
        fn wakeup_ticks_are_the_first_at_the_deadline(
            start in 0u64..(1 << 48),
            ahead in prop_oneof![0u64..2_000_000, 0u64..(1 << 40)],
            hz in prop_oneof![Just(14_745_600u32), Just(10_000_000u32), 1_000_000u32..200_000_000],
        ) {
            let bus = RamBus::new(0xC000);
            let clint = Clint::new(&bus, hz);
            let now_us = clint.micros_at(start);
            let due = now_us + ahead;
            let t = clint.wakeup_tick(due);
            prop_assert!(ticks_to_micros(t, hz) >= due, "t {} hz {}", t, hz);
            if t > start {
                prop_assert!(ticks_to_micros(t - 1, hz) < due, "not the first: t {} hz {}", t, hz);
            }
            // A deadline already past wakes at once.
            if now_us > 0 {
                prop_assert!(clint.wakeup_tick(now_us - 1) <= start);
            }
        }

        #[test]
        fn recent_ticks_convert_like_micros(
            now in (1u64 << 33)..(1 << 48),
            age in prop_oneof![0u32..20_000_000, any::<u32>()],
            hz in prop_oneof![Just(14_745_600u32), Just(10_000_000u32), 1_000_000u32..200_000_000],
        ) {
            let bus = RamBus::new(0xC000);
            bus.write32(reg::MTIME, now as u32);
            bus.write32(reg::MTIME + 4, (now >> 32) as u32);
            let clint = Clint::new(&bus, hz);
            let stamp = (now as u32).wrapping_sub(age);
            let got = clint.micros_of_recent(stamp);
            if age <= u32::MAX / 2 {
                prop_assert_eq!(got, ticks_to_micros(now - u64::from(age), hz));
            } else {
                prop_assert_eq!(got, ticks_to_micros(now, hz));
            }
        }

        #[test]
        fn incremental_micros_are_exact(
            start in 0u64..(1 << 48),
            steps in proptest::collection::vec(0u64..20_000_000, 1..40),
            hz in prop_oneof![Just(14_745_600u32), Just(10_000_000u32), 1_000_000u32..200_000_000],
        ) {
            let bus = RamBus::new(0xC000);
            let clint = Clint::new(&bus, hz);
            let mut t = start;
            for d in steps {
                t += d;
                prop_assert_eq!(clint.micros_at(t), ticks_to_micros(t, hz), "t {} hz {}", t, hz);
            }
            // Backwards (a reset of mtime) falls back to the exact division too.
            prop_assert_eq!(clint.micros_at(start / 2), ticks_to_micros(start / 2, hz));
        }

        #[test]
        fn micros_round_trip_loses_under_a_microsecond(us in 0u64..(1 << 50), hz in 1_000_000u32..) {
            let back = ticks_to_micros(micros_to_ticks(us, hz), hz);
            prop_assert!(back <= us && us - back <= 1, "{} us -> {} us at {} Hz", us, back, hz);
        }

        #[test]
        fn micros_round_trip_exact_at_whole_megahertz(us in 0u64..(1 << 50), mhz in 1u32..4000) {
            let hz = mhz * 1_000_000;
            prop_assert_eq!(ticks_to_micros(micros_to_ticks(us, hz), hz), us);
        }
    }
}
