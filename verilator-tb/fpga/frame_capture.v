// Frame-grabber port for a parallel (DVP) camera: 8-bit pixel data qualified by HREF, a pixel
// clock, and VSYNC between frames. The pins are synchronised to the SoC clock, so the pixel
// clock must be at most a quarter of it. Bytes of a frame are packed little-endian into words
// and written into the SoC's frame window from its start; VSYNC restarts at offset 0 and
// counts frames in `frames`. A frame longer than the window wraps around.
`default_nettype none

module frame_capture #(
    parameter integer AW = 9             // window words: 2^AW
) (
    input  wire          clk,
    input  wire          rst,
    input  wire          pclk,
    input  wire          href,
    input  wire          vsync,
    input  wire [7:0]    d,
    output reg           we,
    output reg  [AW-1:0] addr,
    output reg  [31:0]   wdata,
    output reg  [15:0]   frames
);
    reg [2:0] pclk_s;
    reg [1:0] vsync_s, href_s;
    reg [7:0] d_s1, d_s2;
    reg [1:0] lane;
    reg [AW-1:0] next;
    wire pclk_rise = pclk_s[2:1] == 2'b01;

    always @(posedge clk) begin
        pclk_s <= {pclk_s[1:0], pclk};
        vsync_s <= {vsync_s[0], vsync};
        href_s <= {href_s[0], href};
        d_s1 <= d;
        d_s2 <= d_s1;
        we <= 1'b0;
        if (rst) begin
            lane <= 2'd0;
            next <= {AW{1'b0}};
            frames <= 16'd0;
        end else if (vsync_s[1]) begin
            if (lane != 2'd0 || next != {AW{1'b0}}) frames <= frames + 16'd1;
            lane <= 2'd0;
            next <= {AW{1'b0}};
        end else if (pclk_rise && href_s[1]) begin
            wdata[8*lane +: 8] <= d_s2;
            lane <= lane + 2'd1;
            if (lane == 2'd3) begin
                we <= 1'b1;
                addr <= next;
                next <= next + {{(AW-1){1'b0}}, 1'b1};
            end
        end
    end
endmodule

`default_nettype wire
