//! Board modules: the only code that knows the memory map. Each one brings its machine up
//! and hands out the same drivers at its own addresses.

#[cfg(feature = "qemu_virt")]
pub mod qemu_virt;
#[cfg(feature = "softcore")]
pub mod softcore;
