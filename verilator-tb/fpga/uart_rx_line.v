// Serial receiver in front of a uart16550's byte port on an FPGA: 8N1 at 16 * divisor clocks
// per bit (the 16550's divisor, so the baud rate follows the driver's setting). The line is
// synchronised, the start bit is confirmed at its middle, each data bit is sampled at its
// middle, and a byte with a valid stop bit is handed on as a one-clock `valid` pulse (a byte
// with a broken stop bit, a framing error, is dropped).
`default_nettype none

module uart_rx_line (
    input  wire        clk,
    input  wire        rst,
    input  wire        rxd,          // the pin, asynchronous
    input  wire [15:0] divisor,
    output reg         valid,
    output reg  [7:0]  data
);
    reg [2:0]  sync;
    wire       line = sync[2];
    reg        busy;
    reg [3:0]  bit_n;                // 0: start bit, 1..8: data, 9: stop
    reg [19:0] timer;                // clocks to the middle of the current bit
    reg [7:0]  shift;
    wire [19:0] bit_clks = {divisor, 4'd0};

    always @(posedge clk) begin
        sync <= {sync[1:0], rxd};
        valid <= 1'b0;
        if (rst) begin
            sync <= 3'b111;
            busy <= 1'b0;
            bit_n <= 4'd0;
            timer <= 20'd0;
        end else if (!busy) begin
            if (!line) begin
                busy <= 1'b1;
                bit_n <= 4'd0;
                timer <= {1'b0, bit_clks[19:1]} - 20'd1;   // half a bit: the start bit's middle
            end
        end else if (timer != 20'd0) begin
            timer <= timer - 20'd1;
        end else begin
            timer <= bit_clks - 20'd1;
            bit_n <= bit_n + 4'd1;
            if (bit_n == 4'd0) begin
                if (line) busy <= 1'b0;                       // a glitch, not a start bit
            end else if (bit_n != 4'd9) begin
                shift <= {line, shift[7:1]};
            end else begin
                busy <= 1'b0;
                if (line) begin
                    valid <= 1'b1;
                    data <= shift;
                end
            end
        end
    end
endmodule

`default_nettype wire
