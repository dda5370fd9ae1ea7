// The vision unit alone on an FPGA, for its area and clock figures: its bus and camera inputs
// come from flip-flops fed by a 32-bit LFSR (the bus side on the falling edge, as the core
// drives it; the camera side on the rising edge), and its outputs are folded into two pins so
// nothing is removed. The run buffers have the board SoC's size (CAP_AW).
`default_nettype none

module vision_top #(
    parameter integer CAP_AW = 9
) (
    input  wire clk,
    input  wire rst_pin,
    input  wire seed,
    output wire out0,
    output wire out1
);
    reg rst = 1'b1;
    always @(posedge clk) rst <= rst_pin;

    reg [31:0] lfsr = 32'h1;
    reg [15:0] offset;
    reg [31:0] wdata;
    reg [3:0]  wstrb;
    reg        sel;
    always @(negedge clk) begin
        lfsr <= {lfsr[30:0], lfsr[31] ^ lfsr[21] ^ lfsr[1] ^ lfsr[0] ^ seed};
        offset <= lfsr[15:0];
        wdata <= {lfsr[7:0], lfsr[31:8]};
        wstrb <= lfsr[19:16] & {4{lfsr[30]}};
        sel <= lfsr[29];
    end
    reg        px_valid, px_eol, px_eof;
    reg [7:0]  px_data;
    always @(posedge clk) begin
        px_valid <= lfsr[3];
        px_eol <= lfsr[12:4] == 9'd0;
        px_eof <= lfsr[28:10] == 19'd0;
        px_data <= lfsr[27:20];
    end

    wire [31:0] rdata;
    wire        irq;
    vision_unit #(.CAP_AW(CAP_AW)) unit (
        .clk(clk), .rst(rst), .sel(sel), .offset(offset), .wstrb(wstrb), .wdata(wdata),
        .rdata(rdata), .irq(irq),
        .px_valid(px_valid), .px_data(px_data), .px_eol(px_eol), .px_eof(px_eof)
    );

    reg [31:0] rdata_q;
    always @(posedge clk) rdata_q <= rdata;
    assign out0 = ^rdata_q[15:0] ^ irq;
    assign out1 = ^rdata_q[31:16];
endmodule

`default_nettype wire
