// The softcore SoC: core, 1 MiB RAM, CLINT, PLIC, two 16550 UARTs and the simulation-control
// device, on a single-cycle bus. Memory map (qemu virt's layout where the devices overlap):
//   0x0010_0000  sim control: +0 exit (SiFive test finisher values), +4 console byte
//   0x0200_0000  CLINT
//   0x0c00_0000  PLIC (UART0 = source 10, UART1 = source 11)
//   0x1000_0000  UART0 (LBC link)
//   0x1000_1000  UART1 (radio)
//   0x8000_0000  RAM, 1 MiB in two halfword banks; execution starts at its base
//   0x8100_0000  frame-grabber window, 0x13_0000 bytes (written by the harness, read by the core)
`default_nettype none

module soc (
    input  wire        clk,
    input  wire        rst,

    // Backdoor RAM write port (used while the core is held in reset).
    input  wire        bd_we,
    input  wire [17:0] bd_addr,
    input  wire [31:0] bd_wdata,

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
    reg  [31:0] dmem_rdata;
    wire        dmem_re;
    wire [3:0]  dmem_rmask, dmem_wstrb;
    wire        msip, mtip, meip;

    // The test bench's line is registered (it acts one cycle later), so no core logic depends
    // on a top-level input.
    reg tb_meip_q;
    always @(posedge clk) tb_meip_q <= tb_meip;

    rv_core core (
        .clk(clk), .rst(rst),
        .imem_addr(imem_addr), .imem_rdata(imem_rdata),
        .dmem_addr(dmem_addr), .dmem_re(dmem_re), .dmem_rmask(dmem_rmask),
        .dmem_wstrb(dmem_wstrb), .dmem_wdata(dmem_wdata), .dmem_rdata(dmem_rdata),
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

    // ------------------------------------------------------------------ RAM
    // Two halfword banks: `ram_lo` holds bits 15:0 of each word, `ram_hi` bits 31:16. The
    // data port reads and writes both at the same word; the fetch port reads the 32 bits at
    // any halfword address in one cycle: at a word boundary {hi[w], lo[w]}, in the middle of
    // a word {lo[w + 1], hi[w]} (the low bank's address is w + addr[1]).
    reg [15:0] ram_lo [0:262143];
    reg [15:0] ram_hi [0:262143];
    wire imem_in_ram = imem_addr[31:20] == 12'h800;
    wire [17:0] iw = imem_addr[19:2];
    wire [15:0] i_lo = ram_lo[iw + {17'd0, imem_addr[1]}];
    wire [15:0] i_hi = ram_hi[iw];
    assign imem_rdata = !imem_in_ram ? 32'd0 : imem_addr[1] ? {i_lo, i_hi} : {i_hi, i_lo};

    wire sel_ram   = dmem_addr[31:20] == 12'h800;
    localparam [21:0] FMEM_WORDS = 22'h4_C000;  // vision::frame::WINDOW_LEN / 4
    wire sel_fmem  = dmem_addr[31:24] == 8'h81 && dmem_addr[23:2] < FMEM_WORDS;
    wire sel_sim   = dmem_addr[31:4] == 28'h0010_000;
    wire sel_clint = dmem_addr[31:16] == 16'h0200;
    wire sel_plic  = dmem_addr[31:22] == 10'b0000_1100_00;
    wire sel_uart0 = dmem_addr[31:3] == 29'h0200_0000;
    wire sel_uart1 = dmem_addr[31:3] == 29'h0200_0200;

    integer k;
    initial for (k = 0; k < 262144; k = k + 1) begin
        ram_lo[k] = 16'd0;
        ram_hi[k] = 16'd0;
    end

    wire [17:0] dw = dmem_addr[19:2];
    wire [31:0] ram_rdata = {ram_hi[dw], ram_lo[dw]};
    always @(posedge clk) begin
        if (bd_we) begin
            ram_lo[bd_addr] <= bd_wdata[15:0];
            ram_hi[bd_addr] <= bd_wdata[31:16];
        end else if (sel_ram && !rst) begin
            if (dmem_wstrb[0]) ram_lo[dw][7:0] <= dmem_wdata[7:0];
            if (dmem_wstrb[1]) ram_lo[dw][15:8] <= dmem_wdata[15:8];
            if (dmem_wstrb[2]) ram_hi[dw][7:0] <= dmem_wdata[23:16];
            if (dmem_wstrb[3]) ram_hi[dw][15:8] <= dmem_wdata[31:24];
        end
    end

    // ------------------------------------------------------------------ frame-grabber window
    // Ordinary memory for the core (data port only); the harness writes it between clock
    // cycles through the model's public view of `fmem`.
    reg [31:0] fmem [0:FMEM_WORDS-1] /*verilator public_flat*/;
    initial for (k = 0; k < FMEM_WORDS; k = k + 1) fmem[k] = 32'd0;

    wire [31:0] fmem_rdata = fmem[dmem_addr[20:2]];
    always @(posedge clk) begin
        if (sel_fmem && !rst) begin
            if (dmem_wstrb[0]) fmem[dmem_addr[20:2]][7:0] <= dmem_wdata[7:0];
            if (dmem_wstrb[1]) fmem[dmem_addr[20:2]][15:8] <= dmem_wdata[15:8];
            if (dmem_wstrb[2]) fmem[dmem_addr[20:2]][23:16] <= dmem_wdata[23:16];
            if (dmem_wstrb[3]) fmem[dmem_addr[20:2]][31:24] <= dmem_wdata[31:24];
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

    clint clint0 (
        .clk(clk), .rst(rst), .sel(sel_clint), .offset(dmem_addr[15:0]),
        .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(clint_rdata), .msip(msip), .mtip(mtip)
    );

    plic plic0 (
        .clk(clk), .rst(rst), .sel(sel_plic), .offset(dmem_addr[21:0]), .re(dmem_re),
        .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(plic_rdata),
        .src({4'd0, uart1_irq, uart0_irq, 9'd0}), .eip(meip)
    );

    uart16550 uart0 (
        .clk(clk), .rst(rst), .sel(sel_uart0), .addr_hi(dmem_addr[2]), .re(dmem_re),
        .rmask(dmem_rmask), .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(uart0_rdata),
        .irq(uart0_irq), .rx_valid(uart0_rx_valid), .rx_data(uart0_rx_data),
        .tx_valid(uart0_tx_valid), .tx_data(uart0_tx_data)
    );

    uart16550 uart1 (
        .clk(clk), .rst(rst), .sel(sel_uart1), .addr_hi(dmem_addr[2]), .re(dmem_re),
        .rmask(dmem_rmask), .wstrb(dmem_wstrb), .wdata(dmem_wdata), .rdata(uart1_rdata),
        .irq(uart1_irq), .rx_valid(uart1_rx_valid), .rx_data(uart1_rx_data),
        .tx_valid(uart1_tx_valid), .tx_data(uart1_tx_data)
    );

    always @(*) begin
        if (sel_ram) dmem_rdata = ram_rdata;
        else if (sel_fmem) dmem_rdata = fmem_rdata;
        else if (sel_clint) dmem_rdata = clint_rdata;
        else if (sel_plic) dmem_rdata = plic_rdata;
        else if (sel_uart0) dmem_rdata = uart0_rdata;
        else if (sel_uart1) dmem_rdata = uart1_rdata;
        else dmem_rdata = 32'd0;
    end
endmodule

`default_nettype wire
