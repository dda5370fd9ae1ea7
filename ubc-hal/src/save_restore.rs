//! The register save and restore routines that LLVM calls in function prologues and epilogues
//! when the target has the `save-restore` feature (the firmware's target specification turns
//! it on: `xtask/src/fw.rs`). A function that keeps `ra` and `s0..s(N-1)` starts with
//! `jal t0, __riscv_save_N` and ends with `j __riscv_restore_N` instead of storing and loading
//! each register itself: one routine for the whole image instead of a copy in every function
//! (2.3 KB of the firmware's text; `docs/benchmarks.md` section 1).
//!
//! The frame layout is the one LLVM assumes (`RISCVFrameLowering`): the routine lowers `sp`
//! by `(N + 1) * 4` rounded up to 16 bytes and stores `ra` in the highest word, `s0` below it,
//! then `s1`, ... down to `s(N-1)`. The four frame sizes (16, 32, 48, 64 bytes) have one save
//! routine each, straight-line code with no jump inside (a taken jump costs the pipelined core
//! two cycles); a routine of smaller `N` in the same size stores a few more `s` registers than
//! it needs, into padding of its own frame that nothing else uses. The restore routines fall
//! through from the largest frame to the smallest, giving back 16 bytes at each step. Every
//! word is stored and loaded above the `sp` of the moment, so an interrupt in the middle
//! overwrites nothing.
//!
//! The save routines return through `t0` (the alternate link register), which holds no
//! argument at a function's entry. The restore routines are reached by a tail jump, return
//! through the restored `ra` to the function's caller, and leave `a0`/`a1` (the return value)
//! alone.
//!
//! Linked only when called: the save and the restore routines are a section each, and
//! `--gc-sections` drops them from a build without the feature.

macro_rules! routines {
    () => {
        r#"
    .section .text.__riscv_save, "ax", @progbits
    .p2align 1
    .globl __riscv_save_0, __riscv_save_1, __riscv_save_2, __riscv_save_3
    .globl __riscv_save_4, __riscv_save_5, __riscv_save_6, __riscv_save_7
    .globl __riscv_save_8, __riscv_save_9, __riscv_save_10, __riscv_save_11
    .globl __riscv_save_12
    .irp n, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12
    .type __riscv_save_\n, @function
    .endr
__riscv_save_12:
    addi sp, sp, -64
    sw ra, 60(sp)
    sw s0, 56(sp)
    sw s1, 52(sp)
    sw s2, 48(sp)
    sw s3, 44(sp)
    sw s4, 40(sp)
    sw s5, 36(sp)
    sw s6, 32(sp)
    sw s7, 28(sp)
    sw s8, 24(sp)
    sw s9, 20(sp)
    sw s10, 16(sp)
    sw s11, 12(sp)
    jr t0
    .size __riscv_save_12, . - __riscv_save_12
__riscv_save_11:
__riscv_save_10:
__riscv_save_9:
__riscv_save_8:
    addi sp, sp, -48
    sw ra, 44(sp)
    sw s0, 40(sp)
    sw s1, 36(sp)
    sw s2, 32(sp)
    sw s3, 28(sp)
    sw s4, 24(sp)
    sw s5, 20(sp)
    sw s6, 16(sp)
    sw s7, 12(sp)
    sw s8, 8(sp)
    sw s9, 4(sp)
    sw s10, 0(sp)
    jr t0
    .irp n, 11, 10, 9, 8
    .size __riscv_save_\n, . - __riscv_save_\n
    .endr
__riscv_save_7:
__riscv_save_6:
__riscv_save_5:
__riscv_save_4:
    addi sp, sp, -32
    sw ra, 28(sp)
    sw s0, 24(sp)
    sw s1, 20(sp)
    sw s2, 16(sp)
    sw s3, 12(sp)
    sw s4, 8(sp)
    sw s5, 4(sp)
    sw s6, 0(sp)
    jr t0
    .irp n, 7, 6, 5, 4
    .size __riscv_save_\n, . - __riscv_save_\n
    .endr
__riscv_save_3:
__riscv_save_2:
__riscv_save_1:
__riscv_save_0:
    addi sp, sp, -16
    sw ra, 12(sp)
    sw s0, 8(sp)
    sw s1, 4(sp)
    sw s2, 0(sp)
    jr t0
    .irp n, 3, 2, 1, 0
    .size __riscv_save_\n, . - __riscv_save_\n
    .endr

    .section .text.__riscv_restore, "ax", @progbits
    .p2align 1
    .globl __riscv_restore_0, __riscv_restore_1, __riscv_restore_2, __riscv_restore_3
    .globl __riscv_restore_4, __riscv_restore_5, __riscv_restore_6, __riscv_restore_7
    .globl __riscv_restore_8, __riscv_restore_9, __riscv_restore_10, __riscv_restore_11
    .globl __riscv_restore_12
    .irp n, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12
    .type __riscv_restore_\n, @function
    .endr
__riscv_restore_12:
    lw s11, 12(sp)
    addi sp, sp, 16
__riscv_restore_11:
__riscv_restore_10:
__riscv_restore_9:
__riscv_restore_8:
    lw s10, 0(sp)
    lw s9, 4(sp)
    lw s8, 8(sp)
    lw s7, 12(sp)
    addi sp, sp, 16
__riscv_restore_7:
__riscv_restore_6:
__riscv_restore_5:
__riscv_restore_4:
    lw s6, 0(sp)
    lw s5, 4(sp)
    lw s4, 8(sp)
    lw s3, 12(sp)
    addi sp, sp, 16
__riscv_restore_3:
__riscv_restore_2:
__riscv_restore_1:
__riscv_restore_0:
    lw s2, 0(sp)
    lw s1, 4(sp)
    lw s0, 8(sp)
    lw ra, 12(sp)
    addi sp, sp, 16
    ret
    .irp n, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12
    .size __riscv_restore_\n, . - __riscv_restore_\n
    .endr
"#
    };
}

// The routines, as assembly: they run in place of a prologue or epilogue, outside any Rust
// function, so they cannot be written in Rust. They only move the callee-saved registers
// between the registers and the stack frame the calling function is setting up or tearing
// down, exactly as LLVM's own prologue would, and touch no other memory.
//
// `.option rvc`: module-level assembly is assembled with the target's base features, without
// the C extension that the functions get; every core this runs on has it, so the routines
// use the 16-bit forms (84 bytes less).
#[cfg(target_feature = "c")]
core::arch::global_asm!(".option push", ".option rvc", routines!(), ".option pop");
#[cfg(not(target_feature = "c"))]
core::arch::global_asm!(routines!());
