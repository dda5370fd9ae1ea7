//! The Verilated SoC behind a safe handle. This module holds the crate's only `unsafe`: the
//! calls into the C++ model through the C ABI of `csrc/shim.cpp`.
#![allow(unsafe_code)]

use crate::golden::Retire;

/// Port values exchanged with the model; layout shared with `struct VtbIo` in the shim.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Io {
    pub rst: u8,
    pub tb_meip: u8,
    pub uart0_rx_valid: u8,
    pub uart0_rx_data: u8,
    pub uart1_rx_valid: u8,
    pub uart1_rx_data: u8,
    pub uart0_tx_valid: u8,
    pub uart0_tx_data: u8,
    pub uart1_tx_valid: u8,
    pub uart1_tx_data: u8,
    pub sim_exit_valid: u8,
    pub console_valid: u8,
    pub console_data: u8,
    pub rvfi_valid: u8,
    pub rvfi_trap: u8,
    pub rvfi_intr: u8,
    pub rvfi_rd_addr: u8,
    pub rvfi_mem_rmask: u8,
    pub rvfi_mem_wmask: u8,
    pub rvfi_ext_mip: u8,
    pub rvfi_ext_intr_mip: u8,
    pub sim_exit_value: u32,
    pub rvfi_order: u64,
    pub rvfi_insn: u32,
    pub rvfi_pc_rdata: u32,
    pub rvfi_pc_wdata: u32,
    pub rvfi_rd_wdata: u32,
    pub rvfi_mem_addr: u32,
    pub rvfi_mem_rdata: u32,
    pub rvfi_mem_wdata: u32,
    pub retired: u64,
    pub sleep_cycles: u64,
}

impl Io {
    pub(crate) fn retire(&self) -> Option<Retire> {
        (self.rvfi_valid != 0).then_some(Retire {
            order: self.rvfi_order,
            insn: self.rvfi_insn,
            trap: self.rvfi_trap != 0,
            intr: self.rvfi_intr != 0,
            pc_rdata: self.rvfi_pc_rdata,
            pc_wdata: self.rvfi_pc_wdata,
            rd_addr: self.rvfi_rd_addr,
            rd_wdata: self.rvfi_rd_wdata,
            mem_addr: self.rvfi_mem_addr,
            mem_rmask: self.rvfi_mem_rmask,
            mem_wmask: self.rvfi_mem_wmask,
            mem_rdata: self.rvfi_mem_rdata,
            mem_wdata: self.rvfi_mem_wdata,
        })
    }
}

#[repr(C)]
struct RawModel {
    _private: [u8; 0],
}

extern "C" {
    fn vtb_new() -> *mut RawModel;
    fn vtb_free(m: *mut RawModel);
    fn vtb_load(m: *mut RawModel, first: u32, words: *const u32, len: u32);
    fn vtb_run(m: *mut RawModel, io: *mut Io, max_cycles: u64, stop_on_retire: u8) -> u64;
}

/// Owner of one Verilated SoC instance.
#[derive(Debug)]
pub(crate) struct Model {
    raw: *mut RawModel,
}

impl Model {
    pub(crate) fn new() -> Self {
        // SAFETY: vtb_new has no preconditions and returns a fresh heap object (new throws
        // rather than returning null).
        let raw = unsafe { vtb_new() };
        assert!(!raw.is_null(), "Verilated model allocation failed");
        Self { raw }
    }

    /// Writes words into RAM from word index `first` (wrapping in the 1 MiB RAM).
    pub(crate) fn load(&mut self, first: u32, words: &[u32]) {
        let len = u32::try_from(words.len()).unwrap_or(u32::MAX);
        // SAFETY: `raw` is live and exclusively borrowed; `len` never exceeds the length of
        // `words`, which outlives the call.
        unsafe { vtb_load(self.raw, first, words.as_ptr(), len) };
    }

    /// Runs up to `max_cycles` cycles; see `vtb_run` in the shim.
    pub(crate) fn run(&mut self, io: &mut Io, max_cycles: u64, stop_on_retire: bool) -> u64 {
        // SAFETY: `raw` is live and exclusively borrowed; `io` is a valid, exclusive pointer to
        // a `repr(C)` struct with the shim's layout for the duration of the call.
        unsafe { vtb_run(self.raw, io, max_cycles, u8::from(stop_on_retire)) }
    }
}

impl Drop for Model {
    fn drop(&mut self) {
        // SAFETY: `raw` came from vtb_new and is freed exactly once, here.
        unsafe { vtb_free(self.raw) };
    }
}
