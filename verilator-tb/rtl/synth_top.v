// Synthesis wrapper for area figures: the core with its buses only. The RVFI outputs are left
// unconnected, so synthesis removes the retirement-port registers (they exist for checking).
`default_nettype none

module synth_top (
    input  wire        clk,
    input  wire        rst,
    output wire [31:0] imem_addr,
    input  wire [31:0] imem_rdata,
    output wire [31:0] dmem_addr,
    output wire        dmem_re,
    output wire [3:0]  dmem_rmask,
    output wire [3:0]  dmem_wstrb,
    output wire [31:0] dmem_wdata,
    input  wire [31:0] dmem_rdata,
    input  wire        irq_software,
    input  wire        irq_timer,
    input  wire        irq_external
);
    /* verilator lint_off PINCONNECTEMPTY */
    rv_core core (
        .clk(clk), .rst(rst),
        .imem_addr(imem_addr), .imem_rdata(imem_rdata),
        .dmem_addr(dmem_addr), .dmem_re(dmem_re), .dmem_rmask(dmem_rmask),
        .dmem_wstrb(dmem_wstrb), .dmem_wdata(dmem_wdata), .dmem_rdata(dmem_rdata),
        .dmem_rd_pre(), .last_st_word(), .last_st_data(), .last_st_mask(),
        .irq_software(irq_software), .irq_timer(irq_timer), .irq_external(irq_external),
        .sleeping(),
        .rvfi_valid(), .rvfi_order(), .rvfi_insn(), .rvfi_trap(), .rvfi_intr(),
        .rvfi_pc_rdata(), .rvfi_pc_wdata(), .rvfi_rd_addr(), .rvfi_rd_wdata(),
        .rvfi_mem_addr(), .rvfi_mem_rmask(), .rvfi_mem_wmask(), .rvfi_mem_rdata(),
        .rvfi_mem_wdata(), .rvfi_ext_mip(), .rvfi_ext_intr_mip()
    );
    /* verilator lint_on PINCONNECTEMPTY */
endmodule

`default_nettype wire
