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
    assign mtip = mtime >= mtimecmp;

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
    always @(posedge clk) begin
        if (rst) begin
            msip_r <= 1'b0;
            mtime <= 64'd0;
            mtimecmp <= 64'hffff_ffff_ffff_ffff;
        end else begin
            mtime <= mtime + 64'd1;
            if (sel && wstrb != 4'd0) begin
                case (offset)
                    16'h0000: if (wstrb[0]) msip_r <= wdata[0];
                    16'h4000: mtimecmp[31:0] <= (mtimecmp[31:0] & ~lane) | (wdata & lane);
                    16'h4004: mtimecmp[63:32] <= (mtimecmp[63:32] & ~lane) | (wdata & lane);
                    16'hbff8: mtime[31:0] <= (mtime[31:0] & ~lane) | (wdata & lane);
                    16'hbffc: mtime[63:32] <= (mtime[63:32] & ~lane) | (wdata & lane);
                    default: ;
                endcase
            end
        end
    end
endmodule

`default_nettype wire
