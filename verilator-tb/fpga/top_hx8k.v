// iCE40-HX8K breakout board (HX8K, CT256): the SoC at 14.8125 MHz from the 12 MHz oscillator
// (PLL VCO 948 MHz, 29.625 MHz out, half-rate output as the SoC clock; 0.45 % above the
// nominal 14.7456 MHz). RAM: 4 KiB of block RAM (each halfword bank twice, for the fetch and
// the data port); frame window 1 KiB. No DSP blocks: the core multiplies in its divider's
// loop (MUL_SEQ, 34 cycles a product) instead of on a 32x32 multiplier of about 2 800 LUT4.
// The core is the pipelined one (PIPE, rtl/rv_pipe.v): the SoC reaches about 45 MHz.
`default_nettype none

module top_hx8k #(
    // 0: the SoC clock is the PLL's 14.8125 MHz; N > 0: divided by 2^N, for bring-up where
    // timing is not met at the full rate (see docs/fpga.md)
    parameter integer CLK_DIV_LOG2 = 0,
    parameter integer VISION = 1             // the vision unit in the SoC (the flow sets it)
) (
    input  wire       clk_12m,      // J3
    input  wire       rx,           // FTDI channel B: UART0 (LBC link)
    output wire       tx,
    output wire [7:0] led,          // D2..D9
    output wire       flash_sck,
    output wire       flash_csb,
    output wire       flash_mosi,
    input  wire       flash_miso,
    input  wire [7:0] cam_d,        // header J2
    input  wire       cam_pclk,
    input  wire       cam_href,
    input  wire       cam_vsync,
    output wire       uart1_tx,     // UART1 (radio), header J2
    input  wire       uart1_rx
);
    wire clk_pll, locked;
    SB_PLL40_2F_CORE #(
        .FEEDBACK_PATH("SIMPLE"),
        .DIVR(4'd0),
        .DIVF(7'd78),
        .DIVQ(3'd5),
        .FILTER_RANGE(3'd1),
        .PLLOUT_SELECT_PORTA("GENCLK"),
        .PLLOUT_SELECT_PORTB("GENCLK_HALF")
    ) pll (
        .REFERENCECLK(clk_12m),
        .PLLOUTGLOBALA(),
        .PLLOUTGLOBALB(clk_pll),
        .RESETB(1'b1),
        .BYPASS(1'b0),
        .LOCK(locked)
    );

    // the SoC clock: the PLL's output, or a counter's top bit on a global buffer
    wire soc_clk;
    generate
        if (CLK_DIV_LOG2 == 0) begin : full
            assign soc_clk = clk_pll;
        end else begin : divided
            reg [CLK_DIV_LOG2-1:0] div = 0;
            always @(posedge clk_pll) div <= div + 1'b1;
            SB_GB gb (.USER_SIGNAL_TO_GLOBAL_BUFFER(div[CLK_DIV_LOG2-1]),
                      .GLOBAL_BUFFER_OUTPUT(soc_clk));
        end
    endgenerate

    // The frame window is 1 KiB (two block RAMs), which leaves the vision unit its five.
    fpga_soc #(.RAM_AW(10), .FMEM_AW(8), .VISION(VISION), .VIS_CAP_AW(8), .MUL_SEQ(1),
              .PIPE(1)) soc (
        .clk(soc_clk), .pll_locked(locked),
        .uart0_rxd(rx), .uart0_txd(tx), .uart1_rxd(uart1_rx), .uart1_txd(uart1_tx),
        .flash_sck(flash_sck), .flash_csn(flash_csb), .flash_mosi(flash_mosi),
        .flash_miso(flash_miso),
        .cam_pclk(cam_pclk), .cam_href(cam_href), .cam_vsync(cam_vsync), .cam_d(cam_d),
        .leds(led)
    );
endmodule

`default_nettype wire
