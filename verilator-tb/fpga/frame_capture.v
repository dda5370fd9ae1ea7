// Frame-grabber port for a parallel (DVP) camera: 8-bit pixel data qualified by HREF, a pixel
// clock, and VSYNC between frames. The pins are synchronised to the SoC clock, so the pixel
// clock must be at most a quarter of it. The bytes of a frame are written one by one into the
// SoC's frame window from its start (little-endian: byte n at offset n); VSYNC restarts at
// offset 0 and toggles `frame`. A frame longer than the window wraps around.
//
// The same bytes also leave as the vision unit's pixel stream, each byte an RGB332 code
// (`px_valid`, `px_data`), with the end of a line when HREF falls (`px_eol`) and the end of a
// frame when VSYNC comes after pixels (`px_eof`): one event a clock at most.
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
    output reg  [3:0]    we,             // byte lane
    output wire [AW-1:0] addr,
    output wire [31:0]   wdata,
    output reg           frame,
    output reg           px_valid,
    output reg  [7:0]    px_data,
    output reg           px_eol,
    output reg           px_eof
);
    reg [2:0] pclk_s;
    reg [1:0] vsync_s, href_s;
    reg [7:0] d_s1, d_s2, byte_q;
    reg [AW+1:0] at;                    // byte offset of the next pixel byte
    reg [AW-1:0] word_q;
    reg href_q;
    // the data pins' sample taken right after the pixel clock's rising edge
    wire pclk_rise = pclk_s[2:1] == 2'b01;
    assign addr = word_q;
    assign wdata = {4{byte_q}};

    always @(posedge clk) begin
        pclk_s <= {pclk_s[1:0], pclk};
        vsync_s <= {vsync_s[0], vsync};
        href_s <= {href_s[0], href};
        d_s1 <= d;
        d_s2 <= d_s1;
        href_q <= href_s[1];
        we <= 4'd0;
        px_valid <= 1'b0;
        px_eol <= 1'b0;
        px_eof <= 1'b0;
        px_data <= d_s2;
        if (rst) begin
            at <= {(AW+2){1'b0}};
            frame <= 1'b0;
        end else if (vsync_s[1]) begin
            if (at != {(AW+2){1'b0}}) begin
                frame <= !frame;
                px_eof <= 1'b1;
            end
            at <= {(AW+2){1'b0}};
        end else if (href_q && !href_s[1]) begin
            px_eol <= 1'b1;
        end else if (pclk_rise && href_s[1]) begin
            we <= 4'b0001 << at[1:0];
            word_q <= at[AW+1:2];
            byte_q <= d_s2;
            at <= at + {{(AW+1){1'b0}}, 1'b1};
            px_valid <= 1'b1;
        end
    end
endmodule

`default_nettype wire
