// The SoC's RAM on iCE40 UltraPlus single-port RAM (SB_SPRAM256KA, 16K x 16 each): 64 KiB,
// the same interface and timing as rtl/soc_ram.v (reads registered on the falling edge of
// `clk`; the UP5K build feeds the SoC an inverted clock, so the SPRAMs run on the rising edge
// of the PLL's clock and the logic on its falling edge: one clock, both edges timed).
//
// A single-port RAM does one access per cycle, and the core fetches and accesses data in the
// same cycle, so there are two copies: the fetch copy (two SPRAMs, one per halfword bank, read
// every cycle) and the data copy (two SPRAMs, read or written by the data port). The back-door
// port writes both; data-port stores reach only the data copy, so code the program writes
// into RAM is not what it fetches (the firmware never does that).
//
// The data copy must choose between a read and a write at its clock edge, half a cycle into
// the core's cycle, before the core knows whether a store commits (that waits for interrupt
// lines and traps). So a committed store goes into a one-word write buffer at the end of its
// cycle, and the buffer is written in a later cycle whose instruction does not read memory
// (`d_pre` low; a storing cycle never reads, so the buffer is always free for the next
// store). Until then, reads of that word take the buffered bytes. While the data copy is
// written, the output keeps the last word read (the second cycle of an AMO reads back the
// word its first cycle loaded).
`default_nettype none

module soc_ram #(
    parameter integer AW = 14,         // 16K words: fixed by the four SPRAMs
    parameter integer EARLY = 0        // must be 0: rv_core's timing only (see rtl/soc_ram.v)
) (
    input  wire          clk,
    input  wire [AW:0]   i_half,
    output wire [31:0]   i_rdata,
    input  wire [AW-1:0] d_word,
    input  wire [AW-1:0] d_next,       // unused (EARLY)
    input  wire          d_pre,
    input  wire [AW-1:0] st_word,      // the core's last store: the write buffer's contents
    input  wire [31:0]   st_data,
    input  wire [3:0]    st_mask,
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

    // Write buffer (logic edge: the rising edge of `clk`). Its contents are the core's last
    // store (`st_*`, loaded by the same condition as `d_we`); only whether it still has to be
    // written is kept here.
    reg         b_valid = 1'b0;
    wire [13:0] b_addr = st_word;
    wire [31:0] b_data = st_data;
    wire [3:0]  b_mask = st_mask;
    wire        drain = b_valid && !d_pre;     // written at this cycle's memory edge
    always @(posedge clk) begin
        if (d_we != 4'd0) b_valid <= 1'b1;
        else if (drain) b_valid <= 1'b0;
    end

    wire        s_wr   = bd_we || drain;
    wire [13:0] f_lo_a = bd_we ? bd_addr : iw_lo;
    wire [13:0] f_hi_a = bd_we ? bd_addr : iw;
    wire [13:0] s_a    = bd_we ? bd_addr : drain ? b_addr : d_word;
    wire [15:0] s_lo_d = bd_we ? bd_wdata[15:0] : b_data[15:0];
    wire [15:0] s_hi_d = bd_we ? bd_wdata[31:16] : b_data[31:16];
    wire [3:0]  s_lo_m = bd_we ? 4'hf : {b_mask[1], b_mask[1], b_mask[0], b_mask[0]};
    wire [3:0]  s_hi_m = bd_we ? 4'hf : {b_mask[3], b_mask[3], b_mask[2], b_mask[2]};

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
        .ADDRESS(s_a), .DATAIN(s_lo_d), .MASKWREN(s_lo_m), .WREN(s_wr),
        .CHIPSELECT(1'b1), .CLOCK(~clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
        .DATAOUT(s_lo)
    );
    SB_SPRAM256KA data_hi (
        .ADDRESS(s_a), .DATAIN(s_hi_d), .MASKWREN(s_hi_m), .WREN(s_wr),
        .CHIPSELECT(1'b1), .CLOCK(~clk), .STANDBY(1'b0), .SLEEP(1'b0), .POWEROFF(1'b1),
        .DATAOUT(s_hi)
    );

    // memory edge: the falling edge of `clk`. The output is the data copy's word with the
    // bytes in `fwd_m` replaced by `fwd_d`: the buffered store's bytes when it holds the word
    // read, all four bytes of the last word read when the data copy is written instead.
    reg        i_odd_q;
    reg [3:0]  fwd_m;
    reg [31:0] fwd_d;
    wire [31:0] s_out = {s_hi, s_lo};
    always @(negedge clk) begin
        i_odd_q <= i_half[0];
        if (s_wr) begin
            fwd_m <= 4'hf;
            fwd_d <= d_rdata;
        end else begin
            fwd_m <= b_valid && b_addr == d_word ? b_mask : 4'd0;
            fwd_d <= b_data;
        end
    end
    assign i_rdata = i_odd_q ? {f_lo, f_hi} : {f_hi, f_lo};
    assign d_rdata = {fwd_m[3] ? fwd_d[31:24] : s_out[31:24],
                      fwd_m[2] ? fwd_d[23:16] : s_out[23:16],
                      fwd_m[1] ? fwd_d[15:8] : s_out[15:8],
                      fwd_m[0] ? fwd_d[7:0] : s_out[7:0]};
endmodule

`default_nettype wire
