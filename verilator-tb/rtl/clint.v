// CLINT-compatible timer for one hart: msip at +0x0, mtimecmp at +0x4000, mtime at +0xbff8.
// mtime counts core clock cycles.
`default_nettype none

module clint (
    input  wire        clk,
    input  wire        rst,
    input  wire        sel,
    input  wire [15:0] offset,
    input  wire [3:0]  wstrb,
    input  wire [31:0] wdata,
    output reg  [31:0] rdata,
    output wire        msip,
    output wire        mtip
);
    reg        msip_r;
    reg [63:0] mtime, mtimecmp;
    assign msip = msip_r;
    // mtip is a register that follows mtime and mtimecmp in the same clock (compared from
    // their next values), so the interrupt line leaves a flip-flop.
    reg         mtip_r;
    assign mtip = mtip_r;

    always @(*) begin
        case (offset)
            16'h0000: rdata = {31'd0, msip_r};
            16'h4000: rdata = mtimecmp[31:0];
            16'h4004: rdata = mtimecmp[63:32];
            16'hbff8: rdata = mtime[31:0];
            16'hbffc: rdata = mtime[63:32];
            default:  rdata = 32'd0;
        endcase
    end

    wire [31:0] lane = {wstrb[3] ? 8'hff : 8'h00, wstrb[2] ? 8'hff : 8'h00,
                        wstrb[1] ? 8'hff : 8'h00, wstrb[0] ? 8'hff : 8'h00};
    wire        wr   = sel && wstrb != 4'd0;
    wire [63:0] mtime_inc = mtime + 64'd1;
    wire [63:0] mtime_n =
        rst ? 64'd0 :
        wr && offset == 16'hbff8 ? {mtime_inc[63:32], (mtime[31:0] & ~lane) | (wdata & lane)} :
        wr && offset == 16'hbffc ? {(mtime[63:32] & ~lane) | (wdata & lane), mtime_inc[31:0]} :
        mtime_inc;
    wire [63:0] mtimecmp_n =
        rst ? 64'hffff_ffff_ffff_ffff :
        wr && offset == 16'h4000 ? {mtimecmp[63:32], (mtimecmp[31:0] & ~lane) | (wdata & lane)} :
        wr && offset == 16'h4004 ? {(mtimecmp[63:32] & ~lane) | (wdata & lane), mtimecmp[31:0]} :
        mtimecmp;
    always @(posedge clk) begin
        mtime <= mtime_n;
        mtimecmp <= mtimecmp_n;
        mtip_r <= mtime_n >= mtimecmp_n;
        if (rst) msip_r <= 1'b0;
        else if (wr && offset == 16'h0000 && wstrb[0]) msip_r <= wdata[0];
    end
endmodule

`default_nettype wire
