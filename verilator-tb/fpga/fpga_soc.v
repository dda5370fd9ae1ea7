// The SoC as built for an FPGA board: `soc` (with the RAM implementation the build reads:
// rtl/soc_ram.v for block RAM, soc_ram_spram.v on UltraPlus), a boot loader that copies the
// program from the SPI flash into RAM, serial receivers in front of both UARTs, a parallel
// camera on the frame-grabber port and the vision unit's pixel stream, reset sequencing and
// status LEDs. `clk` is the SoC clock
// (logic on its rising edge, memories on its falling edge); reset is held until the PLL has
// locked, 255 more clocks have passed and the loader is done.
`default_nettype none

module fpga_soc #(
    parameter integer RAM_AW = 10,            // RAM words: 2^RAM_AW
    parameter integer FMEM_AW = 9,            // frame window words: 2^FMEM_AW
    parameter integer VISION = 1,             // 1: the SoC has the vision unit
    parameter integer VIS_CAP_AW = 9,         // vision unit: 2^VIS_CAP_AW words per run buffer
    parameter [23:0]  FLASH_OFFSET = 24'h10_0000,
    parameter integer MUL_SEQ = 0,            // 1: multiplication in the divider's loop (no DSP)
    parameter integer PIPE = 0                // 1: the pipelined core (rv_pipe)
) (
    input  wire       clk,
    input  wire       pll_locked,
    input  wire       uart0_rxd,
    output wire       uart0_txd,
    input  wire       uart1_rxd,
    output wire       uart1_txd,
    output wire       flash_sck,
    output wire       flash_csn,
    output wire       flash_mosi,
    input  wire       flash_miso,
    input  wire       cam_pclk,
    input  wire       cam_href,
    input  wire       cam_vsync,
    input  wire [7:0] cam_d,
    // heartbeat (toggled by camera frames too), program loaded, UART0 TX/RX, UART1 TX/RX
    // activity, exit pass, exit fail
    output wire [7:0] leds
);
    // ---------------------------------------------------------------- reset
    // The core leaves reset two clocks after the loader's last word: the clock in between
    // fetches the first instruction (on UltraPlus a SPRAM write takes the place of a read).
    reg [7:0] por = 8'd0;
    reg       sys_rst = 1'b1;
    reg       soc_rst = 1'b1;
    reg       loaded_q = 1'b0;
    wire      loaded;
    always @(posedge clk) begin
        if (!pll_locked) por <= 8'd0;
        else if (por != 8'hff) por <= por + 8'd1;
        sys_rst <= por != 8'hff;
        loaded_q <= loaded && !sys_rst;
        soc_rst <= sys_rst || !loaded_q;
    end

    // ---------------------------------------------------------------- loader
    wire              bd_we;
    wire [RAM_AW-1:0] bd_addr;
    wire [31:0]       bd_wdata;
    spi_flash_loader #(.AW(RAM_AW), .OFFSET(FLASH_OFFSET)) loader (
        .clk(clk), .rst(sys_rst), .sck(flash_sck), .csn(flash_csn), .mosi(flash_mosi),
        .miso(flash_miso), .bd_we(bd_we), .bd_addr(bd_addr), .bd_wdata(bd_wdata),
        .done(loaded)
    );

    // ---------------------------------------------------------------- line side, camera
    wire [15:0] div0, div1;
    wire        rx0_valid, rx1_valid;
    wire [7:0]  rx0_data, rx1_data;
    uart_rx_line rx0 (.clk(clk), .rst(soc_rst), .rxd(uart0_rxd), .divisor(div0),
                      .valid(rx0_valid), .data(rx0_data));
    uart_rx_line rx1 (.clk(clk), .rst(soc_rst), .rxd(uart1_rxd), .divisor(div1),
                      .valid(rx1_valid), .data(rx1_data));

    wire [3:0]         fg_we;
    wire [FMEM_AW-1:0] fg_addr;
    wire [31:0]        fg_wdata;
    wire               frame;
    wire               px_valid, px_eol, px_eof;
    wire [7:0]         px_data;
    frame_capture #(.AW(FMEM_AW)) camera (
        .clk(clk), .rst(soc_rst), .pclk(cam_pclk), .href(cam_href), .vsync(cam_vsync),
        .d(cam_d), .we(fg_we), .addr(fg_addr), .wdata(fg_wdata), .frame(frame),
        .px_valid(px_valid), .px_data(px_data), .px_eol(px_eol), .px_eof(px_eof)
    );

    // ---------------------------------------------------------------- the SoC
    wire        tx0_valid, tx1_valid, exit_valid;
    wire [31:0] exit_value;
    /* verilator lint_off PINCONNECTEMPTY */
    soc #(
        .RAM_AW(RAM_AW), .FMEM_WORDS(1 << FMEM_AW), .FMEM_AW(FMEM_AW), .FG_PORT(1),
        .VISION(VISION), .VIS_CAP_AW(VIS_CAP_AW), .MUL_SEQ(MUL_SEQ), .PIPE(PIPE)
    ) soc0 (
        .clk(clk), .rst(soc_rst),
        .bd_we(bd_we), .bd_addr({{(18-RAM_AW){1'b0}}, bd_addr}), .bd_wdata(bd_wdata),
        .fg_we(fg_we), .fg_addr(fg_addr), .fg_wdata(fg_wdata),
        .cam_valid(px_valid), .cam_data(px_data), .cam_eol(px_eol), .cam_eof(px_eof),
        .tb_meip(1'b0),
        .uart0_rx_valid(rx0_valid), .uart0_rx_data(rx0_data),
        .uart0_tx_valid(tx0_valid), .uart0_tx_data(),
        .uart1_rx_valid(rx1_valid), .uart1_rx_data(rx1_data),
        .uart1_tx_valid(tx1_valid), .uart1_tx_data(),
        .uart0_txd(uart0_txd), .uart1_txd(uart1_txd), .uart0_div(div0), .uart1_div(div1),
        .sim_exit_valid(exit_valid), .sim_exit_value(exit_value),
        .console_valid(), .console_data(), .core_sleeping(),
        .rvfi_valid(), .rvfi_order(), .rvfi_insn(), .rvfi_trap(), .rvfi_intr(),
        .rvfi_pc_rdata(), .rvfi_pc_wdata(), .rvfi_rd_addr(), .rvfi_rd_wdata(),
        .rvfi_mem_addr(), .rvfi_mem_rmask(), .rvfi_mem_wmask(), .rvfi_mem_rdata(),
        .rvfi_mem_wdata(), .rvfi_ext_mip(), .rvfi_ext_intr_mip()
    );
    /* verilator lint_on PINCONNECTEMPTY */

    // ---------------------------------------------------------------- LEDs
    reg [23:0] beat = 24'd0;
    reg [1:0]  exit_led = 2'b00;
    reg [3:0]  act = 4'd0;          // a byte went by in the last 2^19 .. 2^20 clocks
    reg [3:0]  seen = 4'd0;
    wire [3:0] pulse = {rx1_valid, tx1_valid, rx0_valid, tx0_valid};
    always @(posedge clk) begin
        beat <= beat + 24'd1;
        if (exit_valid) exit_led <= exit_value[15:0] == 16'h5555 ? 2'b01 : 2'b10;
        if (beat[18:0] == 19'd0) begin
            act <= seen | pulse;
            seen <= pulse;
        end else begin
            seen <= seen | pulse;
        end
    end
    assign leds = {exit_led[1], exit_led[0], act[3], act[2], act[1], act[0], !soc_rst,
                   beat[23] ^ frame};
endmodule


`default_nettype wire
