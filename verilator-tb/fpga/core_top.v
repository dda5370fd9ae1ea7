// The core alone on an FPGA, for its area and clock figures: its buses end in flip-flops
// clocked like the SoC's memories and devices (falling edge: the addresses are captured and
// the read data leaves; rising edge: write data, strobes and read strobes are captured; the
// pipelined core's data word leaves at the rising edge, from `dmem_next`), fed
// by a 32-bit LFSR so nothing is constant, and folded into two output pins so nothing is
// removed. The RVFI port is left open (removed).
`default_nettype none

module core_top #(
    parameter integer MUL_SEQ = 0,  // the flow sets 1 for parts without DSP blocks (rv_core)
    parameter integer PIPE = 0      // the flow sets 1 where the board's SoC has rv_pipe
) (
    input  wire clk,
    input  wire rst_pin,
    input  wire seed,
    output wire out0,
    output wire out1
);
    reg rst = 1'b1;
    always @(posedge clk) rst <= rst_pin;

    // memory-side flip-flops (falling edge)
    reg [31:0] lfsr = 32'h1;
    reg [31:0] i_data, d_data;
    reg [31:0] i_addr_q, d_addr_q, d_wdata_q;
    reg [3:0]  d_rmask_q, d_wstrb_q;
    reg        d_re_q, d_pre_q;
    reg [2:0]  irq;
    wire [31:0] imem_addr, dmem_addr, dmem_wdata, dmem_next;
    reg  [31:0] d_next_q, d_data_e;
    wire [3:0]  dmem_rmask, dmem_wstrb;
    wire        dmem_re, dmem_rd_pre;
    wire [13:0] st_word;
    wire [31:0] st_data;
    wire [3:0]  st_mask;
    always @(negedge clk) begin
        lfsr <= {lfsr[30:0], lfsr[31] ^ lfsr[21] ^ lfsr[1] ^ lfsr[0] ^ seed};
        i_data <= lfsr ^ i_addr_q;
        d_data <= {lfsr[15:0], lfsr[31:16]} ^ d_addr_q;
        i_addr_q <= imem_addr;
        d_addr_q <= dmem_addr;
        d_pre_q <= dmem_rd_pre;
    end
    // the write port, read strobes (devices act on them) and the write buffer: rising edge
    always @(posedge clk) begin
        d_next_q <= dmem_next;
        d_data_e <= {lfsr[7:0], lfsr[31:8]} ^ d_next_q;
        irq <= lfsr[31:29];
        d_wdata_q <= dmem_wdata ^ st_data;
        d_rmask_q <= dmem_rmask ^ st_mask;
        d_wstrb_q <= dmem_wstrb;
        d_re_q <= dmem_re ^ (^st_word);
    end

    /* verilator lint_off PINCONNECTEMPTY */
    generate
        if (PIPE != 0) begin : g_pipe
            rv_pipe #(.FETCH_AW(14), .MUL_SEQ(MUL_SEQ)) core (
                .clk(clk), .rst(rst),
                .imem_addr(imem_addr), .imem_rdata(i_data),
                .dmem_addr(dmem_addr), .dmem_next(dmem_next), .dmem_re(dmem_re),
                .dmem_rmask(dmem_rmask),
                .dmem_wstrb(dmem_wstrb), .dmem_wdata(dmem_wdata), .dmem_rdata(d_data_e),
                .dmem_rd_pre(dmem_rd_pre),
                .last_st_word(st_word), .last_st_data(st_data), .last_st_mask(st_mask),
                .irq_software(irq[0]), .irq_timer(irq[1]), .irq_external(irq[2]),
                .sleeping(),
                .rvfi_valid(), .rvfi_order(), .rvfi_insn(), .rvfi_trap(), .rvfi_intr(),
                .rvfi_pc_rdata(), .rvfi_pc_wdata(), .rvfi_rd_addr(), .rvfi_rd_wdata(),
                .rvfi_mem_addr(), .rvfi_mem_rmask(), .rvfi_mem_wmask(), .rvfi_mem_rdata(),
                .rvfi_mem_wdata(), .rvfi_ext_mip(), .rvfi_ext_intr_mip()
            );
        end else begin : g_core
            assign dmem_next = dmem_addr;
            rv_core #(.FETCH_AW(14), .MUL_SEQ(MUL_SEQ)) core (
                .clk(clk), .rst(rst),
                .imem_addr(imem_addr), .imem_rdata(i_data),
                .dmem_addr(dmem_addr), .dmem_re(dmem_re), .dmem_rmask(dmem_rmask),
                .dmem_wstrb(dmem_wstrb), .dmem_wdata(dmem_wdata), .dmem_rdata(d_data),
                .dmem_rd_pre(dmem_rd_pre),
                .last_st_word(st_word), .last_st_data(st_data), .last_st_mask(st_mask),
                .irq_software(irq[0]), .irq_timer(irq[1]), .irq_external(irq[2]),
                .sleeping(),
                .rvfi_valid(), .rvfi_order(), .rvfi_insn(), .rvfi_trap(), .rvfi_intr(),
                .rvfi_pc_rdata(), .rvfi_pc_wdata(), .rvfi_rd_addr(), .rvfi_rd_wdata(),
                .rvfi_mem_addr(), .rvfi_mem_rmask(), .rvfi_mem_wmask(), .rvfi_mem_rdata(),
                .rvfi_mem_wdata(), .rvfi_ext_mip(), .rvfi_ext_intr_mip()
            );
        end
    endgenerate
    /* verilator lint_on PINCONNECTEMPTY */

    assign out0 = ^{i_addr_q, d_addr_q[31:16]};
    assign out1 = ^{d_addr_q[15:0], d_wdata_q, d_rmask_q, d_wstrb_q, d_re_q, d_pre_q};
endmodule

`default_nettype wire
