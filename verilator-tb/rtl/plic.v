// PLIC-compatible interrupt controller, one context (hart 0, machine mode), sources 1..15,
// priorities 0..7. Same register layout as the SiFive PLIC: priority at 4*n, pending at
// 0x1000, enables at 0x2000, threshold at 0x20_0000, claim/complete at 0x20_0004. Sources are
// level triggered; a claimed source is not pending again until it is completed.
//
// SRC_REG = 1 (the pipelined core's SoC): the source lines are registered first, so a device's
// interrupt logic and the arbitration behind the claim register are not one path (a source
// is seen one cycle later).
`default_nettype none

module plic #(
    parameter integer SRC_REG = 0
) (
    input  wire        clk,
    input  wire        rst,
    input  wire        sel,
    input  wire [21:0] offset,
    input  wire        re,
    input  wire [3:0]  wstrb,
    input  wire [31:0] wdata,
    output reg  [31:0] rdata,
    input  wire [15:1] src,
    output wire        eip
);
    reg [2:0]  prio [1:15];
    reg [15:1] enable, in_service;
    reg [2:0]  threshold;
    reg  [15:1] src_q;
    always @(posedge clk) src_q <= src;
    wire [15:1] src_in = SRC_REG != 0 ? src_q : src;
    wire [15:1] pending = src_in & ~in_service;

    reg [3:0] best_id;
    reg [2:0] best_prio;
    integer i;
    always @(*) begin
        best_id = 4'd0;
        best_prio = 3'd0;
        for (i = 1; i <= 15; i = i + 1) begin
            if (pending[i] && enable[i] && prio[i] > best_prio) begin
                best_id = i[3:0];
                best_prio = prio[i];
            end
        end
    end
    // The best priority exceeds the threshold exactly when some pending, enabled source's
    // does (a flat OR, not through the arbitration chain, which only the claim needs).
    wire [15:1] above;
    genvar g;
    generate
        for (g = 1; g <= 15; g = g + 1) begin : cmp
            assign above[g] = pending[g] && enable[g] && prio[g] > threshold;
        end
    endgenerate
    assign eip = above != 15'd0;

    always @(*) begin
        if (offset < 22'h40 && offset[1:0] == 2'd0 && offset[5:2] != 4'd0)
            rdata = {29'd0, prio[offset[5:2]]};
        else if (offset == 22'h1000) rdata = {16'd0, pending, 1'b0};
        else if (offset == 22'h2000) rdata = {16'd0, enable, 1'b0};
        else if (offset == 22'h20_0000) rdata = {29'd0, threshold};
        else if (offset == 22'h20_0004) rdata = eip ? {28'd0, best_id} : 32'd0;
        else rdata = 32'd0;
    end

    wire claim = sel && re && offset == 22'h20_0004;
    wire wr = sel && wstrb != 4'd0;
    always @(posedge clk) begin
        if (rst) begin
            for (i = 1; i <= 15; i = i + 1) prio[i] <= 3'd0;
            enable <= 15'd0;
            in_service <= 15'd0;
            threshold <= 3'd0;
        end else begin
            if (claim && eip) in_service[best_id] <= 1'b1;
            if (wr) begin
                if (offset < 22'h40 && offset[5:2] != 4'd0) prio[offset[5:2]] <= wdata[2:0];
                if (offset == 22'h2000) enable <= wdata[15:1];
                if (offset == 22'h20_0000) threshold <= wdata[2:0];
                if (offset == 22'h20_0004 && wdata[3:0] != 4'd0 && wdata[31:4] == 28'd0)
                    in_service[wdata[3:0]] <= 1'b0;
            end
        end
    end
endmodule

`default_nettype wire
