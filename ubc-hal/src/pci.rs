//! PCI configuration through ECAM, just enough to bring up simple devices behind a host
//! bridge that firmware must configure itself: scan a bus, size and place an I/O BAR,
//! enable I/O decoding, and report the device's interrupt pin.

use crate::mmio::RegisterBus;

/// Configuration header offsets (type 0).
pub mod reg {
    /// Vendor ID (16 bits) and device ID (16 bits).
    pub const ID: usize = 0x00;
    /// Command (16 bits) and status (16 bits).
    pub const COMMAND: usize = 0x04;
    /// Cache line, latency timer, header type (bits 23..16), BIST.
    pub const HEADER: usize = 0x0C;
    /// First base address register.
    pub const BAR0: usize = 0x10;
    /// Interrupt line (bits 7..0) and interrupt pin (bits 15..8).
    pub const INTERRUPT: usize = 0x3C;
}

/// Command register: respond to I/O space accesses.
pub const COMMAND_IO_SPACE: u32 = 1 << 0;
/// Command register: respond to memory space accesses.
pub const COMMAND_MEMORY_SPACE: u32 = 1 << 1;
/// Header type bit telling that function 0 has siblings.
const HEADER_MULTIFUNCTION: u32 = 0x80 << 16;
/// Vendor ID read from an empty slot.
const NO_DEVICE: u16 = 0xFFFF;
/// Devices per bus and functions per device.
const DEVICES: u8 = 32;
const FUNCTIONS: u8 = 8;
/// Type 0 headers have six BARs.
const BAR_COUNT: u8 = 6;

/// Bus, device and function of one PCI function.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Bdf {
    /// Bus number.
    pub bus: u8,
    /// Device (slot) number, 0..32.
    pub device: u8,
    /// Function number, 0..8.
    pub function: u8,
}

impl Bdf {
    /// Offset of this function's 4 KiB configuration space within the ECAM window.
    pub const fn ecam_offset(self) -> usize {
        ((self.bus as usize) << 20)
            | ((self.device as usize) << 15)
            | ((self.function as usize) << 12)
    }
}

/// PCI legacy interrupt pins.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IntPin {
    /// INTA#
    A,
    /// INTB#
    B,
    /// INTC#
    C,
    /// INTD#
    D,
}

impl IntPin {
    /// Decodes the interrupt pin register (1 = INTA .. 4 = INTD; 0 = none).
    pub const fn from_register(value: u8) -> Option<Self> {
        match value {
            1 => Some(Self::A),
            2 => Some(Self::B),
            3 => Some(Self::C),
            4 => Some(Self::D),
            _ => None,
        }
    }

    /// 0 for INTA .. 3 for INTD.
    pub const fn index(self) -> u8 {
        self as u8
    }

    /// The host bridge line this pin of a device in `slot` drives, with the standard
    /// rotation (slot + pin) mod 4 used by host bridges such as QEMU's GPEX.
    pub const fn swizzle(self, slot: u8) -> u8 {
        (slot % 4 + self.index()) % 4
    }
}

/// Why a device could not be set up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum PciError {
    /// No function with this vendor/device ID on the scanned bus.
    NotFound {
        /// Vendor ID searched for.
        vendor: u16,
        /// Device ID searched for.
        device: u16,
    },
    /// The BAR index is beyond the header.
    NoSuchBar {
        /// Index asked for.
        bar: u8,
    },
    /// The BAR decodes memory, not I/O.
    NotIoBar {
        /// Index of the BAR.
        bar: u8,
    },
    /// The BAR is not implemented (sizes to zero).
    BarUnimplemented {
        /// Index of the BAR.
        bar: u8,
    },
    /// The I/O window has no aligned room left for the BAR.
    IoWindowFull {
        /// Bytes the BAR needs.
        size: u32,
        /// Bytes left in the window.
        available: u32,
    },
    /// The function does not use a legacy interrupt pin.
    NoInterruptPin,
}

/// The part of the host bridge's I/O space that firmware hands out, and the CPU address it
/// appears at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IoWindow {
    /// CPU physical address of PCI I/O address 0.
    pub cpu_base: usize,
    /// First PCI I/O address to hand out.
    pub start: u32,
    /// One past the last PCI I/O address of the window.
    pub end: u32,
}

/// Simple bump allocator over an [`IoWindow`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IoAllocator {
    window: IoWindow,
    next: u32,
}

impl IoAllocator {
    /// Hands out addresses from `window.start` upwards.
    pub const fn new(window: IoWindow) -> Self {
        Self {
            window,
            next: window.start,
        }
    }

    /// Reserves `size` bytes (a power of two) aligned to `size`; returns the PCI address.
    pub fn allocate(&mut self, size: u32) -> Result<u32, PciError> {
        let full = PciError::IoWindowFull {
            size,
            available: self.window.end.saturating_sub(self.next),
        };
        let aligned = self
            .next
            .checked_next_multiple_of(size.max(1))
            .ok_or(full)?;
        let end = aligned.checked_add(size).ok_or(full)?;
        if end > self.window.end {
            return Err(full);
        }
        self.next = end;
        Ok(aligned)
    }

    /// CPU address of PCI I/O address `pci`.
    pub const fn cpu_address(&self, pci: u32) -> usize {
        self.window.cpu_base + pci as usize
    }
}

/// A device placed in I/O space.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IoDevice {
    /// Where it sits.
    pub bdf: Bdf,
    /// The PCI I/O address assigned to the BAR.
    pub pci_address: u32,
    /// The CPU address its registers appear at.
    pub cpu_address: usize,
    /// The BAR's size in bytes.
    pub size: u32,
    /// Its legacy interrupt pin.
    pub pin: IntPin,
}

/// PCI configuration space through an ECAM window.
#[derive(Debug)]
pub struct Ecam<B> {
    bus: B,
}

impl<B: RegisterBus> Ecam<B> {
    /// Wraps the ECAM window (bus 0 at offset 0).
    pub const fn new(bus: B) -> Self {
        Self { bus }
    }

    /// Reads a configuration word.
    pub fn read(&self, bdf: Bdf, offset: usize) -> u32 {
        self.bus.read32(bdf.ecam_offset() + (offset & 0xFFC))
    }

    /// Writes a configuration word.
    pub fn write(&self, bdf: Bdf, offset: usize, value: u32) {
        self.bus
            .write32(bdf.ecam_offset() + (offset & 0xFFC), value)
    }

    /// Vendor and device ID, or `None` for an empty slot.
    pub fn id(&self, bdf: Bdf) -> Option<(u16, u16)> {
        let id = self.read(bdf, reg::ID);
        let vendor = id as u16;
        (vendor != NO_DEVICE && vendor != 0).then_some((vendor, (id >> 16) as u16))
    }

    /// Every function present on `bus`, in slot order.
    pub fn scan(&self, bus: u8) -> impl Iterator<Item = (Bdf, u16, u16)> + '_ {
        (0..DEVICES).flat_map(move |device| {
            let f0 = Bdf {
                bus,
                device,
                function: 0,
            };
            let present = self.id(f0).is_some();
            let functions = if present && self.read(f0, reg::HEADER) & HEADER_MULTIFUNCTION != 0 {
                FUNCTIONS
            } else if present {
                1
            } else {
                0
            };
            (0..functions).filter_map(move |function| {
                let bdf = Bdf {
                    bus,
                    device,
                    function,
                };
                self.id(bdf).map(|(v, d)| (bdf, v, d))
            })
        })
    }

    /// The first function on `bus` with this vendor and device ID.
    pub fn find(&self, bus: u8, vendor: u16, device: u16) -> Result<Bdf, PciError> {
        self.scan(bus)
            .find(|&(_, v, d)| v == vendor && d == device)
            .map(|(bdf, _, _)| bdf)
            .ok_or(PciError::NotFound { vendor, device })
    }

    /// Size in bytes of I/O BAR `bar`, found by writing all ones and reading the mask back.
    /// Decoding is switched off meanwhile and the BAR's old value restored.
    pub fn io_bar_size(&self, bdf: Bdf, bar: u8) -> Result<u32, PciError> {
        if bar >= BAR_COUNT {
            return Err(PciError::NoSuchBar { bar });
        }
        let offset = reg::BAR0 + 4 * bar as usize;
        let command = self.read(bdf, reg::COMMAND);
        self.write(
            bdf,
            reg::COMMAND,
            command & !(COMMAND_IO_SPACE | COMMAND_MEMORY_SPACE) & 0xFFFF,
        );
        let old = self.read(bdf, offset);
        self.write(bdf, offset, u32::MAX);
        let mask = self.read(bdf, offset);
        self.write(bdf, offset, old);
        self.write(bdf, reg::COMMAND, command & 0xFFFF);
        io_bar_size_from_mask(mask, bar)
    }

    /// Places I/O BAR `bar` of `bdf` in the window and enables I/O decoding.
    pub fn assign_io_bar(
        &self,
        bdf: Bdf,
        bar: u8,
        alloc: &mut IoAllocator,
    ) -> Result<(u32, u32), PciError> {
        let size = self.io_bar_size(bdf, bar)?;
        let address = alloc.allocate(size)?;
        self.write(bdf, reg::BAR0 + 4 * bar as usize, address);
        let command = self.read(bdf, reg::COMMAND) & 0xFFFF;
        self.write(bdf, reg::COMMAND, command | COMMAND_IO_SPACE);
        Ok((address, size))
    }

    /// The function's legacy interrupt pin.
    pub fn interrupt_pin(&self, bdf: Bdf) -> Result<IntPin, PciError> {
        let pin = (self.read(bdf, reg::INTERRUPT) >> 8) as u8;
        IntPin::from_register(pin).ok_or(PciError::NoInterruptPin)
    }

    /// Finds `vendor:device` on bus 0, places its I/O BAR `bar` and reports where it is.
    pub fn setup_io_device(
        &self,
        vendor: u16,
        device: u16,
        bar: u8,
        alloc: &mut IoAllocator,
    ) -> Result<IoDevice, PciError> {
        let bdf = self.find(0, vendor, device)?;
        let pin = self.interrupt_pin(bdf)?;
        let (pci_address, size) = self.assign_io_bar(bdf, bar, alloc)?;
        Ok(IoDevice {
            bdf,
            pci_address,
            cpu_address: alloc.cpu_address(pci_address),
            size,
            pin,
        })
    }
}

/// Decodes the read-back of an all-ones write to an I/O BAR. I/O decoders may implement only
/// 16 address bits, in which case the upper half reads as zero.
pub fn io_bar_size_from_mask(mask: u32, bar: u8) -> Result<u32, PciError> {
    if mask == 0 {
        return Err(PciError::BarUnimplemented { bar });
    }
    if mask & 1 == 0 {
        return Err(PciError::NotIoBar { bar });
    }
    let mut address_bits = mask & !0x3;
    if address_bits & 0xFFFF_0000 == 0 {
        address_bits |= 0xFFFF_0000;
    }
    let size = (!address_bits).wrapping_add(1);
    if address_bits == 0xFFFF_0000 || size == 0 || !size.is_power_of_two() {
        return Err(PciError::BarUnimplemented { bar });
    }
    Ok(size)
}

/// A model of a bus-0 ECAM window for host tests: functions with I/O BARs that size like
/// hardware, a command register and an interrupt pin.
#[cfg(test)]
pub(crate) mod model {
    use super::*;
    use std::collections::HashMap;
    use std::sync::Mutex;

    #[derive(Debug, Clone)]
    pub(crate) struct Function {
        pub(crate) id: u32,
        pub(crate) header: u32,
        pub(crate) command: u32,
        /// (size, is_io) per BAR; size 0 = unimplemented.
        pub(crate) bars: [(u32, bool); 6],
        pub(crate) bar_values: [u32; 6],
        pub(crate) pin: u8,
    }

    impl Function {
        pub(crate) fn new(vendor: u16, device: u16) -> Self {
            Self {
                id: u32::from(vendor) | (u32::from(device) << 16),
                header: 0,
                command: 0,
                bars: [(0, false); 6],
                bar_values: [0; 6],
                pin: 0,
            }
        }
    }

    #[derive(Debug, Default)]
    pub(crate) struct EcamModel {
        pub(crate) functions: Mutex<HashMap<(u8, u8), Function>>,
    }

    impl EcamModel {
        pub(crate) fn add(&self, device: u8, function: u8, f: Function) {
            self.functions.lock().unwrap().insert((device, function), f);
        }
        pub(crate) fn get(&self, device: u8, function: u8) -> Function {
            self.functions.lock().unwrap()[&(device, function)].clone()
        }
        fn locate(offset: usize) -> (u8, u8, usize) {
            assert_eq!(offset >> 20, 0, "only bus 0 is modelled");
            (
                ((offset >> 15) & 31) as u8,
                ((offset >> 12) & 7) as u8,
                offset & 0xFFF,
            )
        }
    }

    impl RegisterBus for EcamModel {
        fn read8(&self, _offset: usize) -> u8 {
            panic!("ECAM is accessed by words here")
        }
        fn write8(&self, _offset: usize, _value: u8) {
            panic!("ECAM is accessed by words here")
        }
        fn read32(&self, offset: usize) -> u32 {
            let (d, f, reg) = Self::locate(offset);
            let fns = self.functions.lock().unwrap();
            let Some(func) = fns.get(&(d, f)) else {
                return u32::MAX;
            };
            match reg {
                reg::ID => func.id,
                reg::COMMAND => func.command,
                reg::HEADER => func.header,
                0x10..=0x24 => func.bar_values[(reg - 0x10) / 4],
                reg::INTERRUPT => u32::from(func.pin) << 8,
                _ => 0,
            }
        }
        fn write32(&self, offset: usize, value: u32) {
            let (d, f, reg) = Self::locate(offset);
            let mut fns = self.functions.lock().unwrap();
            let Some(func) = fns.get_mut(&(d, f)) else {
                return;
            };
            match reg {
                reg::COMMAND => func.command = value & 0xFFFF,
                0x10..=0x24 => {
                    let i = (reg - 0x10) / 4;
                    let (size, io) = func.bars[i];
                    func.bar_values[i] = if size == 0 {
                        0
                    } else if io {
                        // 16-bit I/O decoder: upper half reads as zero.
                        (value & !(size - 1) & 0xFFFC) | 1
                    } else {
                        value & !(size - 1) & !0xF
                    };
                }
                _ => {}
            }
        }
    }

    /// qemu virt with `-device pci-serial`: host bridge in slot 0, the serial card in `slot`.
    pub(crate) fn virt_with_pci_serial(slot: u8) -> EcamModel {
        let m = EcamModel::default();
        m.add(0, 0, Function::new(0x1b36, 0x0008));
        let mut serial = Function::new(0x1b36, 0x0002);
        serial.bars[0] = (8, true);
        serial.bar_values[0] = 1;
        serial.pin = 1;
        m.add(slot, 0, serial);
        m
    }
}

#[cfg(test)]
mod tests {
    use super::model::*;
    use super::*;
    use proptest::prelude::*;

    const WINDOW: IoWindow = IoWindow {
        cpu_base: 0x0300_0000,
        start: 0x1000,
        end: 0x1_0000,
    };

    #[test]
    fn ecam_offsets() {
        let bdf = Bdf {
            bus: 1,
            device: 2,
            function: 3,
        };
        assert_eq!(bdf.ecam_offset(), 0x0011_3000);
    }

    #[test]
    fn swizzle_matches_gpex() {
        assert_eq!(IntPin::A.swizzle(0), 0);
        assert_eq!(IntPin::A.swizzle(1), 1);
        assert_eq!(IntPin::D.swizzle(1), 0);
        assert_eq!(IntPin::B.swizzle(6), 3);
        assert_eq!(IntPin::from_register(0), None);
        assert_eq!(IntPin::from_register(3), Some(IntPin::C));
        assert_eq!(IntPin::from_register(5), None);
    }

    #[test]
    fn io_bar_masks() {
        assert_eq!(io_bar_size_from_mask(0x0000_FFF9, 0), Ok(8));
        assert_eq!(io_bar_size_from_mask(0xFFFF_FFF9, 0), Ok(8));
        assert_eq!(io_bar_size_from_mask(0xFFFF_FF01, 2), Ok(256));
        assert_eq!(
            io_bar_size_from_mask(0xFFFF_F000, 1),
            Err(PciError::NotIoBar { bar: 1 })
        );
        assert_eq!(
            io_bar_size_from_mask(0x0000_0001, 4),
            Err(PciError::BarUnimplemented { bar: 4 })
        );
        assert_eq!(
            io_bar_size_from_mask(0x0000_FF59, 0),
            Err(PciError::BarUnimplemented { bar: 0 })
        );
    }

    #[test]
    fn allocator_aligns_and_fills() {
        let mut a = IoAllocator::new(IoWindow {
            cpu_base: 0x0300_0000,
            start: 0x1004,
            end: 0x1020,
        });
        assert_eq!(a.allocate(8), Ok(0x1008));
        assert_eq!(a.allocate(16), Ok(0x1010));
        assert_eq!(
            a.allocate(8),
            Err(PciError::IoWindowFull {
                size: 8,
                available: 0
            })
        );
        assert_eq!(a.cpu_address(0x1008), 0x0300_1008);
    }

    proptest! {
        #[test]
        fn allocations_are_aligned_disjoint_and_inside(sizes in prop::collection::vec(0u32..12, 1..30)) {
            let mut a = IoAllocator::new(WINDOW);
            let mut taken: Vec<(u32, u32)> = Vec::new();
            for shift in sizes {
                let size = 1u32 << shift;
                if let Ok(addr) = a.allocate(size) {
                    prop_assert_eq!(addr % size, 0);
                    prop_assert!(addr >= WINDOW.start && addr + size <= WINDOW.end);
                    for &(s, e) in &taken {
                        prop_assert!(addr >= e || addr + size <= s);
                    }
                    taken.push((addr, addr + size));
                }
            }
        }
    }

    #[test]
    fn scan_lists_present_functions() {
        let m = virt_with_pci_serial(1);
        let mut multi = Function::new(0x8086, 0x1234);
        multi.header = 0x80 << 16;
        m.add(4, 0, multi);
        m.add(4, 2, Function::new(0x8086, 0x1235));
        m.add(5, 1, Function::new(0x8086, 0x9999)); // hidden: function 0 missing
        let ecam = Ecam::new(&m);
        let found: Vec<_> = ecam
            .scan(0)
            .map(|(b, v, d)| (b.device, b.function, v, d))
            .collect();
        assert_eq!(
            found,
            vec![
                (0, 0, 0x1b36, 0x0008),
                (1, 0, 0x1b36, 0x0002),
                (4, 0, 0x8086, 0x1234),
                (4, 2, 0x8086, 0x1235),
            ]
        );
    }

    #[test]
    fn sets_up_pci_serial() {
        let m = virt_with_pci_serial(2);
        let ecam = Ecam::new(&m);
        let mut alloc = IoAllocator::new(WINDOW);
        let dev = ecam.setup_io_device(0x1b36, 0x0002, 0, &mut alloc).unwrap();
        assert_eq!(
            dev,
            IoDevice {
                bdf: Bdf {
                    bus: 0,
                    device: 2,
                    function: 0
                },
                pci_address: 0x1000,
                cpu_address: 0x0300_1000,
                size: 8,
                pin: IntPin::A,
            }
        );
        let f = m.get(2, 0);
        assert_eq!(f.bar_values[0], 0x1001);
        assert_eq!(f.command & COMMAND_IO_SPACE, COMMAND_IO_SPACE);
        assert_eq!(dev.pin.swizzle(dev.bdf.device), 2);
    }

    #[test]
    fn missing_device_and_bad_bars() {
        let m = virt_with_pci_serial(1);
        let ecam = Ecam::new(&m);
        let mut alloc = IoAllocator::new(WINDOW);
        assert_eq!(
            ecam.setup_io_device(0x1b36, 0x0003, 0, &mut alloc),
            Err(PciError::NotFound {
                vendor: 0x1b36,
                device: 0x0003
            })
        );
        let serial = Bdf {
            bus: 0,
            device: 1,
            function: 0,
        };
        assert_eq!(
            ecam.assign_io_bar(serial, 1, &mut alloc),
            Err(PciError::BarUnimplemented { bar: 1 })
        );
        assert_eq!(
            ecam.assign_io_bar(serial, 6, &mut alloc),
            Err(PciError::NoSuchBar { bar: 6 })
        );
        let mut mem = Function::new(0x1234, 0x5678);
        mem.bars[0] = (0x1000, false);
        mem.pin = 2;
        m.add(3, 0, mem);
        let bdf = ecam.find(0, 0x1234, 0x5678).unwrap();
        assert_eq!(
            ecam.assign_io_bar(bdf, 0, &mut alloc),
            Err(PciError::NotIoBar { bar: 0 })
        );
        assert_eq!(
            m.get(3, 0).command,
            0,
            "a failed placement leaves decoding off"
        );
    }
}
