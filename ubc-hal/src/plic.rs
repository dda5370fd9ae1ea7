//! RISC-V Platform-Level Interrupt Controller (SiFive layout, as on qemu virt): per-source
//! priority and enable, per-context threshold and claim/complete.

use crate::mmio::RegisterBus;

/// Register block offsets.
pub mod reg {
    /// Priority of source `n` at `PRIORITY + 4 * n`.
    pub const PRIORITY: usize = 0x0000;
    /// Pending bits, 32 sources per word.
    pub const PENDING: usize = 0x1000;
    /// Enable bits of context `c` at `ENABLE + ENABLE_STRIDE * c`, 32 sources per word.
    pub const ENABLE: usize = 0x2000;
    /// Distance between two contexts' enable blocks.
    pub const ENABLE_STRIDE: usize = 0x80;
    /// Priority threshold of context `c` at `CONTEXT + CONTEXT_STRIDE * c`.
    pub const CONTEXT: usize = 0x20_0000;
    /// Distance between two contexts' threshold/claim blocks.
    pub const CONTEXT_STRIDE: usize = 0x1000;
    /// Claim/complete register, relative to the context block.
    pub const CLAIM: usize = 4;
}

/// Number of interrupt sources the register layout can describe (source 0 means "none").
pub const MAX_SOURCES: u32 = 1024;
/// Highest priority the driver will program (qemu virt implements 0..=7).
pub const MAX_PRIORITY: u8 = 7;

/// An interrupt source number, `1..MAX_SOURCES`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Source(u32);

impl Source {
    /// A valid source number, or `None` for 0 and numbers beyond the layout.
    pub const fn new(n: u32) -> Option<Self> {
        if n == 0 || n >= MAX_SOURCES {
            None
        } else {
            Some(Self(n))
        }
    }

    /// The source number.
    pub const fn number(self) -> u32 {
        self.0
    }
}

/// One hart context of a PLIC (for the UBC: hart 0, machine mode = context 0).
#[derive(Debug)]
pub struct Plic<B> {
    bus: B,
    context: usize,
}

impl<B: RegisterBus> Plic<B> {
    /// The controller seen from `context`.
    pub const fn new(bus: B, context: usize) -> Self {
        Self { bus, context }
    }

    fn enable_word(&self, source: Source) -> (usize, u32) {
        let n = source.0 as usize;
        (
            reg::ENABLE + reg::ENABLE_STRIDE * self.context + 4 * (n / 32),
            1 << (n % 32),
        )
    }

    fn context_base(&self) -> usize {
        reg::CONTEXT + reg::CONTEXT_STRIDE * self.context
    }

    /// Sets a source's priority (clamped to [`MAX_PRIORITY`]; 0 never interrupts).
    pub fn set_priority(&self, source: Source, priority: u8) {
        self.bus.write32(
            reg::PRIORITY + 4 * source.0 as usize,
            u32::from(priority.min(MAX_PRIORITY)),
        );
    }

    /// Gives source number `n` a priority and lets it interrupt this context; numbers that
    /// name no source (0, or beyond 1023) are left alone.
    pub fn route(&self, n: u32, priority: u8) {
        if let Some(source) = Source::new(n) {
            self.set_priority(source, priority);
            self.enable(source);
        }
    }

    /// Lets `source` interrupt this context.
    pub fn enable(&self, source: Source) {
        let (offset, bit) = self.enable_word(source);
        self.bus.write32(offset, self.bus.read32(offset) | bit);
    }

    /// Stops `source` from interrupting this context.
    pub fn disable(&self, source: Source) {
        let (offset, bit) = self.enable_word(source);
        self.bus.write32(offset, self.bus.read32(offset) & !bit);
    }

    /// Whether `source` is enabled for this context.
    pub fn is_enabled(&self, source: Source) -> bool {
        let (offset, bit) = self.enable_word(source);
        self.bus.read32(offset) & bit != 0
    }

    /// Whether `source` is pending.
    pub fn is_pending(&self, source: Source) -> bool {
        let n = source.0 as usize;
        self.bus.read32(reg::PENDING + 4 * (n / 32)) & (1 << (n % 32)) != 0
    }

    /// Only sources with a priority above `threshold` interrupt this context.
    pub fn set_threshold(&self, threshold: u8) {
        self.bus
            .write32(self.context_base(), u32::from(threshold.min(MAX_PRIORITY)));
    }

    /// Claims the highest-priority pending source, if any.
    pub fn claim(&self) -> Option<Source> {
        Source::new(self.bus.read32(self.context_base() + reg::CLAIM))
    }

    /// Signals that the claimed `source` has been serviced.
    pub fn complete(&self, source: Source) {
        self.bus.write32(self.context_base() + reg::CLAIM, source.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mmio::testing::RamBus;

    fn src(n: u32) -> Source {
        Source::new(n).unwrap()
    }

    #[test]
    fn source_range() {
        assert_eq!(Source::new(0), None);
        assert_eq!(Source::new(1).map(Source::number), Some(1));
        assert_eq!(Source::new(1023).map(Source::number), Some(1023));
        assert_eq!(Source::new(1024), None);
    }

    #[test]
    fn context0_register_addresses() {
        let bus = RamBus::new(0x20_2000);
        let plic = Plic::new(&bus, 0);
        plic.set_priority(src(10), 3);
        assert_eq!(bus.read32(40), 3);
        plic.set_priority(src(33), 200);
        assert_eq!(
            bus.read32(4 * 33),
            7,
            "priority clamps to the implemented range"
        );
        plic.enable(src(10));
        plic.enable(src(33));
        assert_eq!(bus.read32(0x2000), 1 << 10);
        assert_eq!(bus.read32(0x2004), 1 << 1);
        assert!(plic.is_enabled(src(33)));
        plic.disable(src(10));
        assert_eq!(bus.read32(0x2000), 0);
        assert!(plic.is_enabled(src(33)));
        plic.set_threshold(1);
        assert_eq!(bus.read32(0x20_0000), 1);
        bus.write32(0x1004, 1 << 3);
        assert!(plic.is_pending(src(35)));
        assert!(!plic.is_pending(src(34)));
    }

    #[test]
    fn route_sets_priority_and_enable_and_ignores_non_sources() {
        let bus = RamBus::new(0x20_2000);
        let plic = Plic::new(&bus, 0);
        plic.route(33, 2);
        assert_eq!(bus.read32(4 * 33), 2);
        assert!(plic.is_enabled(src(33)));
        plic.route(0, 5);
        assert_eq!(bus.read32(0), 0);
        assert_eq!(bus.read32(0x2000), 0);
    }

    #[test]
    fn other_context_offsets() {
        let bus = RamBus::new(0x20_3000);
        let plic = Plic::new(&bus, 1);
        plic.enable(src(1));
        assert_eq!(bus.read32(0x2080), 2);
        plic.set_threshold(2);
        assert_eq!(bus.read32(0x20_1000), 2);
    }

    #[test]
    fn claim_and_complete() {
        let bus = RamBus::new(0x20_2000);
        let plic = Plic::new(&bus, 0);
        assert_eq!(plic.claim(), None);
        bus.write32(0x20_0004, 10);
        assert_eq!(plic.claim(), Some(src(10)));
        bus.write32(0x20_0004, 0);
        plic.complete(src(34));
        assert_eq!(bus.read32(0x20_0004), 34);
    }
}
