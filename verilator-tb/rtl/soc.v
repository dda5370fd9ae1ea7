// The softcore SoC: core, 1 MiB RAM, CLINT, PLIC, two 16550 UARTs and the simulation-control
// device, on a single-cycle bus. Memory map (qemu virt's layout where the devices overlap):
//   0x0010_0000  sim control: +0 exit (SiFive test finisher values), +4 console byte
//   0x0200_0000  CLINT
//   0x0c00_0000  PLIC (UART0 = source 10, UART1 = source 11)
//   0x1000_0000  UART0 (LBC link)
//   0x1000_1000  UART1 (radio)
//   0x8000_0000  RAM, 1 MiB in two halfword banks; execution starts at its base
//   0x8100_0000  frame-grabber window, 0x13_0000 bytes (written by the harness, read by the core)
//   0x8113_0000  vision unit (registers, class table, run buffers; PLIC source 12), fed by the
//                camera's pixel stream (cam_*)
`default_nettype none

module soc #(
    parameter integer RAM_AW = 18,              // RAM: 2^RAM_AW words (1 MiB)
    parameter integer FMEM_WORDS = 32'h4_C000,  // frame window: vision::frame::WINDOW_LEN / 4
    parameter integer FMEM_AW = 19,             // address bits of the window's words
    parameter integer FG_PORT = 0,              // 1: the window is written by the fg_* port
    parameter integer VISION = 1,               // 1: the vision unit is there
    parameter integer VIS_CAP_AW = 12,          // its run buffers: 2^VIS_CAP_AW words each
    parameter integer MUL_SEQ = 0,              // 1: multiplication in the divider's loop (rv_core)
    parameter integer PIPE = 0                  // 1: the pipelined core (rv_pipe) instead of rv_core
) (
    input  wire        clk,
    input  wire        rst,

    // Backdoor RAM write port (used while the core is held in reset).
    input  wire        bd_we,
    input  wire [17:0] bd_addr,
    input  wire [31:0] bd_wdata,

    // Frame-grabber port (FG_PORT = 1): writes the byte lanes `fg_we` of a window word at the
    // rising edge.
    input  wire [3:0]  fg_we,
    input  wire [FMEM_AW-1:0] fg_addr,
    input  wire [31:0] fg_wdata,

    // The camera's pixel stream for the vision unit: one event a cycle, an RGB332 pixel
    // (`cam_valid`), the end of a line or the end of a frame.
    input  wire        cam_valid,
    input  wire [7:0]  cam_data,
    input  wire        cam_eol,
    input  wire        cam_eof,

    // Extra machine external interrupt line for test benches.
    input  wire        tb_meip,

    input  wire        uart0_rx_valid,
    input  wire [7:0]  uart0_rx_data,
    output wire        uart0_tx_valid,
    output wire [7:0]  uart0_tx_data,
    input  wire        uart1_rx_valid,
    input  wire [7:0]  uart1_rx_data,
    output wire        uart1_tx_valid,
    output wire [7:0]  uart1_tx_data,
    // The UARTs' serial lines and divisors (for an FPGA's line receivers).
    output wire        uart0_txd,
    output wire        uart1_txd,
    output wire [15:0] uart0_div,
    output wire [15:0] uart1_div,

    output reg         sim_exit_valid,
    output reg  [31:0] sim_exit_value,
    output reg         console_valid,
    output reg  [7:0]  console_data,

    output wire        core_sleeping,
    output wire        rvfi_valid,
    output wire [63:0] rvfi_order,
    output wire [31:0] rvfi_insn,
    output wire        rvfi_trap,
    output wire        rvfi_intr,
    output wire [31:0] rvfi_pc_rdata,
    output wire [31:0] rvfi_pc_wdata,
    output wire [4:0]  rvfi_rd_addr,
    output wire [31:0] rvfi_rd_wdata,
    output wire [31:0] rvfi_mem_addr,
    output wire [3:0]  rvfi_mem_rmask,
    output wire [3:0]  rvfi_mem_wmask,
    output wire [31:0] rvfi_mem_rdata,
    output wire [31:0] rvfi_mem_wdata,
    output wire [2:0]  rvfi_ext_mip,
    output wire [2:0]  rvfi_ext_intr_mip
);
    wire [31:0] imem_addr, imem_rdata;
    wire [31:0] dmem_addr, dmem_wdata;
    wire [31:0] dmem_next;      // rv_pipe: the next cycle's data address (early reads)
    reg  [31:0] dmem_rdata;
    wire        dmem_re, dmem_rd_pre;
    wire [RAM_AW-1:0] st_word;
    wire [31:0] st_data;
    wire [3:0]  st_mask;
    wire [3:0]  dmem_rmask, dmem_wstrb;
    wire        msip, mtip, meip;

    // The test bench's line is registered (it acts one cycle later), so no core logic depends
    // on a top-level input.
    reg tb_meip_q;
    always @(posedge clk) tb_meip_q <= tb_meip;

    generate
        if (PIPE != 0) begin : g_pipe
            rv_pipe #(.FETCH_AW(RAM_AW), .MUL_SEQ(MUL_SEQ)) core (
                .clk(clk), .rst(rst),
                .imem_addr(imem_addr), .imem_rdata(imem_rdata),
                .dmem_addr(dmem_addr), .dmem_next(dmem_next), .dmem_re(dmem_re),
                .dmem_rmask(dmem_rmask),
                .dmem_wstrb(dmem_wstrb), .dmem_wdata(dmem_wdata), .dmem_rdata(dmem_rdata),
                .dmem_rd_pre(dmem_rd_pre),
                .last_st_word(st_word), .last_st_data(st_data), .last_st_mask(st_mask),
                .irq_software(msip), .irq_timer(mtip), .irq_external(meip | tb_meip_q),
                .sleeping(core_sleeping),
                .rvfi_valid(rvfi_valid), .rvfi_order(rvfi_order), .rvfi_insn(rvfi_insn),
                .rvfi_trap(rvfi_trap), .rvfi_intr(rvfi_intr),
                .rvfi_pc_rdata(rvfi_pc_rdata), .rvfi_pc_wdata(rvfi_pc_wdata),
                .rvfi_rd_addr(rvfi_rd_addr), .rvfi_rd_wdata(rvfi_rd_wdata),
                .rvfi_mem_addr(rvfi_mem_addr), .rvfi_mem_rmask(rvfi_mem_rmask),
                .rvfi_mem_wmask(rvfi_mem_wmask), .rvfi_mem_rdata(rvfi_mem_rdata),
                .rvfi_mem_wdata(rvfi_mem_wdata), .rvfi_ext_mip(rvfi_ext_mip),
                .rvfi_ext_intr_mip(rvfi_ext_intr_mip)
            );
        end else begin : g_core
            assign dmem_next = dmem_addr;
            rv_core #(.FETCH_AW(RAM_AW), .MUL_SEQ(MUL_SEQ)) core (
                .clk(clk), .rst(rst),
                .imem_addr(imem_addr), .imem_rdata(imem_rdata),
                .dmem_addr(dmem_addr), .dmem_re(dmem_re), .dmem_rmask(dmem_rmask),
                .dmem_wstrb(dmem_wstrb), .dmem_wdata(dmem_wdata), .dmem_rdata(dmem_rdata),
                .dmem_rd_pre(dmem_rd_pre),
                .last_st_word(st_word), .last_st_data(st_data), .last_st_mask(st_mask),
                .irq_software(msip), .irq_timer(mtip), .irq_external(meip | tb_meip_q),
                .sleeping(core_sleeping),
                .rvfi_valid(rvfi_valid), .rvfi_order(rvfi_order), .rvfi_insn(rvfi_insn),
                .rvfi_trap(rvfi_trap), .rvfi_intr(rvfi_intr),
                .rvfi_pc_rdata(rvfi_pc_rdata), .rvfi_pc_wdata(rvfi_pc_wdata),
                .rvfi_rd_addr(rvfi_rd_addr), .rvfi_rd_wdata(rvfi_rd_wdata),
                .rvfi_mem_addr(rvfi_mem_addr), .rvfi_mem_rmask(rvfi_mem_rmask),
                .rvfi_mem_wmask(rvfi_mem_wmask), .rvfi_mem_rdata(rvfi_mem_rdata),
                .rvfi_mem_wdata(rvfi_mem_wdata), .rvfi_ext_mip(rvfi_ext_mip),
                .rvfi_ext_intr_mip(rvfi_ext_intr_mip)
            );
        end
    endgenerate

    // ------------------------------------------------------------------ RAM
    // `soc_ram` (rtl/soc_ram.v): two halfword banks, so the fetch port reads the 32 bits at any
    // halfword address in one cycle; both read ports are registered on the falling edge, or
    // with the pipelined core the data port on the rising edge from `dmem_next` (see there).
    // The RAM is 2^RAM_AW words, repeated over the 1 MiB region.
    wire imem_in_ram = imem_addr[31:20] == 12'h800;
    reg  imem_in_ram_q;
    wire [31:0] ram_idata;
    always @(negedge clk) imem_in_ram_q <= imem_in_ram;
    assign imem_rdata = imem_in_ram_q ? ram_idata : 32'd0;

    // the devices an address selects: {vision, UART1, UART0, PLIC, CLINT, frame window, RAM}
    function automatic [6:0] select(input [31:0] a);
        select = {VISION != 0 && a[31:16] == 16'h8113, a[31:3] == 29'h0200_0200,
                  a[31:3] == 29'h0200_0000, a[31:22] == 10'b0000_1100_00,
                  a[31:16] == 16'h0200, a[31:24] == 8'h81 && a[23:2] < FMEM_WORDS,
                  a[31:20] == 12'h800};
    endfunction
    wire [6:0] sel = select(dmem_addr);
    wire sel_ram   = sel[0];
    wire sel_fmem  = sel[1];
    wire sel_sim   = dmem_addr[31:4] == 28'h0010_000;
    wire sel_clint = sel[2];
    wire sel_plic  = sel[3];
    wire sel_uart0 = sel[4];
    wire sel_uart1 = sel[5];
    wire sel_vis   = sel[6];
    // The read data's selection: with the pipelined core, worked out at the edge that begins
    // the cycle from the address given a cycle ahead (`dmem_next`), so the address decode is
    // not on the load path.
    reg  [6:0] sel_next_q;
    always @(posedge clk) sel_next_q <= select(dmem_next);
    wire [6:0] rsel = PIPE != 0 ? sel_next_q : sel;

    wire [31:0] ram_rdata;
    soc_ram #(.AW(RAM_AW), .EARLY(PIPE)) ram (
        .clk(clk),
        .i_half(imem_addr[RAM_AW+1:1]), .i_rdata(ram_idata),
        .d_word(dmem_addr[RAM_AW+1:2]), .d_next(dmem_next[RAM_AW+1:2]), .d_pre(dmem_rd_pre),
        .st_word(st_word), .st_data(st_data), .st_mask(st_mask),
        .d_we(sel_ram && !rst ? dmem_wstrb : 4'd0),
        .d_wdata(dmem_wdata), .d_rdata(ram_rdata),
        .bd_we(bd_we), .bd_addr(bd_addr[RAM_AW-1:0]), .bd_wdata(bd_wdata)
    );

    // ------------------------------------------------------------------ frame-grabber window
    // Memory read by the core's data port. In simulation (FG_PORT = 0) the core may also store
    // into it and the harness writes it between clock cycles through the model's public view
    // of `fmem`, so it is read combinationally: a harness write is seen by loads from the next
    // cycle on. On an FPGA (FG_PORT = 1) the frame-grabber port `fg_*` writes it, core stores
    // are ignored, and the read is registered like the RAM's data port (block RAM): on the
    // falling edge, or with the pipelined core on the rising edge from `dmem_next`.
    integer k;
    reg [31:0] fmem [0:FMEM_WORDS-1] /*verilator public_flat*/;
    initial for (k = 0; k < FMEM_WORDS; k = k + 1) fmem[k] = 32'd0;

    wire [FMEM_AW-1:0] fw = dmem_addr[FMEM_AW+1:2];
    reg  [FMEM_AW-1:0] fw_next_q;
    reg  [31:0] fmem_q;
    always @(negedge clk) fmem_q <= fmem[fw];
    always @(posedge clk) fw_next_q <= dmem_next[FMEM_AW+1:2];
    wire [31:0] fmem_rdata = FG_PORT == 0 ? fmem[fw] : PIPE != 0 ? fmem[fw_next_q] : fmem_q;
    always @(posedge clk) begin
        if (FG_PORT != 0) begin
            if (fg_we[0]) fmem[fg_addr][7:0] <= fg_wdata[7:0];
            if (fg_we[1]) fmem[fg_addr][15:8] <= fg_wdata[15:8];
            if (fg_we[2]) fmem[fg_addr][23:16] <= fg_wdata[23:16];
            if (fg_we[3]) fmem[fg_addr][31:24] <= fg_wdata[31:24];
        end else if (sel_fmem && !rst) begin
            if (dmem_wstrb[0]) fmem[fw][7:0] <= dmem_wdata[7:0];
            if (dmem_wstrb[1]) fmem[fw][15:8] <= dmem_wdata[15:8];
            if (dmem_wstrb[2]) fmem[fw][23:16] <= dmem_wdata[23:16];
            if (dmem_wstrb[3]) fmem[fw][31:24] <= dmem_wdata[31:24];
        end
    end

    // ------------------------------------------------------------------ sim control
    always @(posedge clk) begin
        sim_exit_valid <= 1'b0;
        console_valid <= 1'b0;
        if (!rst && sel_sim && dmem_wstrb != 4'd0) begin
            if (dmem_addr[3:2] == 2'd0) begin
                sim_exit_valid <= 1'b1;
                sim_exit_value <= dmem_wdata;
            end else if (dmem_addr[3:2] == 2'd1 && dmem_wstrb[0]) begin
                console_valid <= 1'b1;
                console_data <= dmem_wdata[7:0];
            end
        end
    end

    // ------------------------------------------------------------------ peripherals
    wire [31:0] clint_rdata, plic_rdata, uart0_rdata, uart1_rdata;
    wire        uart0_irq, uart1_irq;
    wire [31:0] vis_rdata;
    wire        vis_irq;

    clint clint0 (
        .clk(clk), .rst(rst), .sel(sel_clint), .offset(dmem_addr[15:0]),
        .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(clint_rdata), .msip(msip), .mtip(mtip)
    );

    plic #(.SRC_REG(PIPE)) plic0 (
        .clk(clk), .rst(rst), .sel(sel_plic), .offset(dmem_addr[21:0]), .re(dmem_re),
        .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(plic_rdata),
        .src({3'd0, vis_irq, uart1_irq, uart0_irq, 9'd0}), .eip(meip)
    );

    generate
        if (VISION != 0) begin : vision
            vision_unit #(.CAP_AW(VIS_CAP_AW)) unit (
                .clk(clk), .rst(rst), .sel(sel_vis), .offset(dmem_addr[15:0]),
                .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(vis_rdata), .irq(vis_irq),
                .px_valid(cam_valid), .px_data(cam_data), .px_eol(cam_eol), .px_eof(cam_eof)
            );
        end else begin : no_vision
            assign vis_rdata = 32'd0;
            assign vis_irq = 1'b0;
        end
    endgenerate

    uart16550 uart0 (
        .clk(clk), .rst(rst), .sel(sel_uart0), .addr_hi(dmem_addr[2]), .re(dmem_re),
        .rmask(dmem_rmask), .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(uart0_rdata),
        .irq(uart0_irq), .rx_valid(uart0_rx_valid), .rx_data(uart0_rx_data),
        .tx_valid(uart0_tx_valid), .tx_data(uart0_tx_data),
        .txd(uart0_txd), .divisor_out(uart0_div)
    );

    uart16550 uart1 (
        .clk(clk), .rst(rst), .sel(sel_uart1), .addr_hi(dmem_addr[2]), .re(dmem_re),
        .rmask(dmem_rmask), .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(uart1_rdata),
        .irq(uart1_irq), .rx_valid(uart1_rx_valid), .rx_data(uart1_rx_data),
        .tx_valid(uart1_tx_valid), .tx_data(uart1_tx_data),
        .txd(uart1_txd), .divisor_out(uart1_div)
    );

    always @(*) begin
        if (rsel[0]) dmem_rdata = ram_rdata;
        else if (rsel[1]) dmem_rdata = fmem_rdata;
        else if (rsel[2]) dmem_rdata = clint_rdata;
        else if (rsel[3]) dmem_rdata = plic_rdata;
        else if (rsel[4]) dmem_rdata = uart0_rdata;
        else if (rsel[5]) dmem_rdata = uart1_rdata;
        else if (rsel[6]) dmem_rdata = vis_rdata;
        else dmem_rdata = 32'd0;
    end
endmodule

`default_nettype wire
