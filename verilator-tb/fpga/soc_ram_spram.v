// The SoC's RAM on iCE40 UltraPlus single-port RAM (SB_SPRAM256KA, 16K x 16 each): 64 KiB,
// the same interface and timing as rtl/soc_ram.v (reads registered on the falling edge of
// `clk`; the UP5K build feeds the SoC an inverted clock, so the SPRAMs run on the rising edge
// of the PLL's clock and the logic on its falling edge: one clock, both edges timed).
//
// A single-port RAM does one access per cycle, and the core fetches and accesses data in the
// same cycle, so there are two copies: the fetch copy (two SPRAMs, one per halfword bank, read
// every cycle) and the data copy (two SPRAMs, read or written by the data port). The back-door
// port writes both; data-port stores reach only the data copy, so code the program writes
// into RAM is not what it fetches (the firmware never does that). A data-port write happens
// at the falling edge of `clk` instead of the rising one; nothing reads the data copy in
// between. During a store the data copy is not read, so its output keeps the last word read
// (the second cycle of an AMO reads back the word its first cycle loaded).
`default_nettype none

module soc_ram #(
    parameter integer AW = 14          // 16K words: fixed by the four SPRAMs
) (
    input  wire          clk,
    input  wire [AW:0]   i_half,
    output wire [31:0]   i_rdata,
    input  wire [AW-1:0] d_word,
    input  wire [3:0]    d_we,
    input  wire [31:0]   d_wdata,
    output wire [31:0]   d_rdata,
    input  wire          bd_we,
    input  wire [AW-1:0] bd_addr,
    input  wire [31:0]   bd_wdata
);
    wire [13:0] iw    = i_half[14:1];
    wire [13:0] iw_lo = iw + {13'd0, i_half[0]};
    wire [15:0] f_lo, f_hi, s_lo, s_hi;
    wire        d_wr = d_we != 4'd0;

    wire [13:0] f_lo_a = bd_we ? bd_addr : iw_lo;
    wire [13:0] f_hi_a = bd_we ? bd_addr : iw;
    wire [13:0] s_a    = bd_we ? bd_addr : d_word;
    wire [15:0] s_lo_d = bd_we ? bd_wdata[15:0] : d_wdata[15:0];
    wire [15:0] s_hi_d = bd_we ? bd_wdata[31:16] : d_wdata[31:16];
    wire [3:0]  s_lo_m = bd_we ? 4'hf : {d_we[1], d_we[1], d_we[0], d_we[0]};
    wire [3:0]  s_hi_m = bd_we ? 4'hf : {d_we[3], d_we[3], d_we[2], d_we[2]};

    SB_SPRAM256KA fetch_lo (
        .ADDRESS(f_lo_a), .DATAIN(bd_wdata[15:0]), .MASKWREN(4'hf), .WREN(bd_we),
        .CHIPSELECT(1'b1), .CLOCK(~clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
        .DATAOUT(f_lo)
    );
    SB_SPRAM256KA fetch_hi (
        .ADDRESS(f_hi_a), .DATAIN(bd_wdata[31:16]), .MASKWREN(4'hf), .WREN(bd_we),
        .CHIPSELECT(1'b1), .CLOCK(~clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
        .DATAOUT(f_hi)
    );
    SB_SPRAM256KA data_lo (
        .ADDRESS(s_a), .DATAIN(s_lo_d), .MASKWREN(s_lo_m), .WREN(bd_we || d_wr),
        .CHIPSELECT(1'b1), .CLOCK(~clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
        .DATAOUT(s_lo)
    );
    SB_SPRAM256KA data_hi (
        .ADDRESS(s_a), .DATAIN(s_hi_d), .MASKWREN(s_hi_m), .WREN(bd_we || d_wr),
        .CHIPSELECT(1'b1), .CLOCK(~clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
        .DATAOUT(s_hi)
    );

    reg        i_odd_q, d_rd_q;
    reg [31:0] d_last;
    always @(negedge clk) begin
        i_odd_q <= i_half[0];
        d_rd_q  <= !d_wr;
        if (d_rd_q) d_last <= {s_hi, s_lo};
    end
    assign i_rdata = i_odd_q ? {f_lo, f_hi} : {f_hi, f_lo};
    assign d_rdata = d_rd_q ? {s_hi, s_lo} : d_last;
endmodule

`default_nettype wire
