//! Register access. Drivers talk to their devices through [`RegisterBus`], so the same driver
//! code runs against real memory-mapped registers ([`Mmio`]) on the target and against
//! device models in host tests.

/// Byte and word access to a block of device registers, addressed by offset from its base.
pub trait RegisterBus {
    /// Reads the 8-bit register at `offset`.
    fn read8(&self, offset: usize) -> u8;
    /// Writes the 8-bit register at `offset`.
    fn write8(&self, offset: usize, value: u8);
    /// Reads the 32-bit register at `offset` (4-byte aligned).
    fn read32(&self, offset: usize) -> u32;
    /// Writes the 32-bit register at `offset` (4-byte aligned).
    fn write32(&self, offset: usize, value: u32);
}

/// A block of memory-mapped device registers starting at a fixed physical address.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Mmio {
    base: usize,
}

impl Mmio {
    /// Creates an accessor for the registers at `base`.
    ///
    /// # Safety
    ///
    /// `base` must be the address of a device register block that is mapped for the whole range
    /// the driver using it will touch, and access to that device must not break memory safety
    /// (it must not be RAM that Rust code owns).
    pub const unsafe fn new(base: usize) -> Self {
        Self { base }
    }

    /// The physical base address.
    pub const fn base(&self) -> usize {
        self.base
    }
}

impl RegisterBus for Mmio {
    fn read8(&self, offset: usize) -> u8 {
        // SAFETY: `Mmio::new`'s contract makes `base + offset` a mapped device register.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u8) }
    }

    fn write8(&self, offset: usize, value: u8) {
        // SAFETY: as in `read8`.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u8, value) }
    }

    fn read32(&self, offset: usize) -> u32 {
        debug_assert_eq!((self.base + offset) % 4, 0);
        // SAFETY: as in `read8`; drivers only use 4-byte aligned offsets for word registers.
        unsafe { core::ptr::read_volatile((self.base + offset) as *const u32) }
    }

    fn write32(&self, offset: usize, value: u32) {
        debug_assert_eq!((self.base + offset) % 4, 0);
        // SAFETY: as in `read32`.
        unsafe { core::ptr::write_volatile((self.base + offset) as *mut u32, value) }
    }
}

impl<B: RegisterBus + ?Sized> RegisterBus for &B {
    fn read8(&self, offset: usize) -> u8 {
        (**self).read8(offset)
    }
    fn write8(&self, offset: usize, value: u8) {
        (**self).write8(offset, value)
    }
    fn read32(&self, offset: usize) -> u32 {
        (**self).read32(offset)
    }
    fn write32(&self, offset: usize, value: u32) {
        (**self).write32(offset, value)
    }
}

/// Plain register memory for host tests: reads return what was last written.
#[cfg(test)]
pub(crate) mod testing {
    use super::RegisterBus;
    use std::sync::Mutex;

    #[derive(Debug)]
    pub(crate) struct RamBus {
        pub(crate) mem: Mutex<Vec<u8>>,
    }

    impl RamBus {
        pub(crate) fn new(size: usize) -> Self {
            Self {
                mem: Mutex::new(vec![0; size]),
            }
        }
    }

    impl RegisterBus for RamBus {
        fn read8(&self, offset: usize) -> u8 {
            self.mem.lock().unwrap()[offset]
        }
        fn write8(&self, offset: usize, value: u8) {
            self.mem.lock().unwrap()[offset] = value;
        }
        fn read32(&self, offset: usize) -> u32 {
            assert_eq!(offset % 4, 0, "unaligned word access at {offset:#x}");
            let m = self.mem.lock().unwrap();
            u32::from_le_bytes([m[offset], m[offset + 1], m[offset + 2], m[offset + 3]])
        }
        fn write32(&self, offset: usize, value: u32) {
            assert_eq!(offset % 4, 0, "unaligned word access at {offset:#x}");
            self.mem.lock().unwrap()[offset..offset + 4].copy_from_slice(&value.to_le_bytes());
        }
    }
}
