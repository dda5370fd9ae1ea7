// iCEBreaker (iCE40 UltraPlus UP5K, SG48): the SoC at 14.8125 MHz from the 12 MHz oscillator.
// The PLL runs its VCO at 948 MHz (12 MHz * 79) and gives 29.625 MHz; its half-rate output is
// the SoC clock, 0.45 % above the nominal 14.7456 MHz (115200 baud becomes 115723). The SoC
// gets the clock inverted (its logic on the falling edge, the SPRAMs on the rising one, see
// soc_ram_spram.v). RAM: 64 KiB in the four SPRAMs; frame window 2 KiB of block RAM.
`default_nettype none

module top_icebreaker #(
    // 0: the SoC clock is the PLL's 14.8125 MHz; N > 0: divided by 2^N, for bring-up where
    // timing is not met at the full rate (see docs/fpga.md)
    parameter integer CLK_DIV_LOG2 = 0,
    parameter integer VISION = 1             // the vision unit in the SoC (the flow sets it)
) (
    input  wire       clk_12m,      // pin 35
    input  wire       rx,           // FTDI channel B: UART0 (LBC link)
    output wire       tx,
    output wire       ledr_n,
    output wire       ledg_n,
    output wire       flash_sck,
    output wire       flash_ssb,
    output wire       flash_io0,    // to the flash (MOSI)
    input  wire       flash_io1,    // from the flash (MISO)
    input  wire [7:0] cam_d,        // PMOD1A
    input  wire       cam_pclk,     // PMOD1B
    input  wire       cam_href,
    input  wire       cam_vsync,
    output wire       uart1_tx,     // PMOD1B: UART1 (radio)
    input  wire       uart1_rx
);
    wire clk_pll, locked;
    SB_PLL40_2F_PAD #(
        .FEEDBACK_PATH("SIMPLE"),
        .DIVR(4'd0),
        .DIVF(7'd78),
        .DIVQ(3'd5),
        .FILTER_RANGE(3'd1),
        .PLLOUT_SELECT_PORTA("GENCLK"),
        .PLLOUT_SELECT_PORTB("GENCLK_HALF")
    ) pll (
        .PACKAGEPIN(clk_12m),
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

    wire [7:0] leds;
    fpga_soc #(.RAM_AW(14), .FMEM_AW(9), .VISION(VISION)) soc (
        .clk(~soc_clk), .pll_locked(locked),
        .uart0_rxd(rx), .uart0_txd(tx), .uart1_rxd(uart1_rx), .uart1_txd(uart1_tx),
        .flash_sck(flash_sck), .flash_csn(flash_ssb), .flash_mosi(flash_io0),
        .flash_miso(flash_io1),
        .cam_pclk(cam_pclk), .cam_href(cam_href), .cam_vsync(cam_vsync), .cam_d(cam_d),
        .leds(leds)
    );
    // green: heartbeat once loaded; red: exit with a failure code, or still loading
    assign ledg_n = !(leds[1] && leds[0]);
    assign ledr_n = !(leds[7] || !leds[1]);
endmodule

`default_nettype wire
