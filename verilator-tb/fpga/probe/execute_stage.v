// Timing probe, not part of the SoC: the execute stage of a pipelined core alone between
// flip-flops, to learn what clock such a stage reaches on each part (`docs/fpga.md`, "What
// would reach 24 MHz on the UP5K and 60 on the HX8K"). Two operands from the register file,
// each forwarded from the two stages ahead; the adder (ADD/SUB, addresses), the signed and
// unsigned comparison and equality (branches, SLT), the logic unit, a barrel shifter, the
// branch target adder and the result selection, into the next stage's registers. An LFSR
// feeds the inputs so that nothing is constant and the part's few pins suffice.
`default_nettype none

module execute_stage (
    input  wire clk,
    input  wire seed,
    output wire out0
);
    reg [31:0] lfsr = 32'h1;
    always @(posedge clk) lfsr <= {lfsr[30:0], lfsr[31] ^ lfsr[21] ^ lfsr[1] ^ lfsr[0] ^ seed};

    // decode-stage outputs
    reg [31:0] rf_a, rf_b, imm, pc;
    reg [15:0] ctl;
    always @(posedge clk) begin
        rf_a <= lfsr;
        rf_b <= {lfsr[15:0], lfsr[31:16]};
        imm  <= {lfsr[7:0], lfsr[31:8]};
        pc   <= lfsr ^ {lfsr[7:0], lfsr[31:8]};
        ctl  <= lfsr[27:12];
    end
    wire       fa_m = ctl[0], fa_w = ctl[1], fb_m = ctl[2], fb_w = ctl[3];
    wire       use_imm = ctl[4], use_pc = ctl[5], sub = ctl[6];
    wire [2:0] f3 = ctl[9:7];
    wire       sra = ctl[10];
    wire [1:0] rsel = ctl[12:11];
    wire       is_br = ctl[13];

    reg  [31:0] m_res, w_res;   // results of the two instructions ahead
    wire [31:0] a    = fa_m ? m_res : fa_w ? w_res : rf_a;
    wire [31:0] b    = fb_m ? m_res : fb_w ? w_res : rf_b;
    wire [31:0] op_a = use_pc ? pc : a;
    wire [31:0] op_b = use_imm ? imm : b;
    wire [31:0] sum  = op_a + (sub ? ~op_b : op_b) + {31'd0, sub};
    wire [32:0] diff = {~f3[1] & a[31], a} - {~f3[1] & b[31], b};
    wire        taken = f3[2] ? diff[32] ^ f3[0] : (a == b) ^ f3[0];
    wire [31:0] target = pc + imm;
    wire [31:0] sh = f3[2] ? (sra ? $unsigned($signed(a) >>> op_b[4:0]) : a >> op_b[4:0]) :
                             a << op_b[4:0];
    reg  [31:0] lg;
    always @(*) begin
        case (f3)
            3'd4: lg = a ^ op_b;
            3'd6: lg = a | op_b;
            3'd7: lg = a & op_b;
            default: lg = {31'd0, diff[32]};
        endcase
    end
    wire [31:0] res = rsel == 2'd0 ? sum : rsel == 2'd1 ? lg : rsel == 2'd2 ? sh : pc + 32'd4;

    // memory-stage registers
    reg        redirect;
    reg [31:0] target_q, addr_q;
    always @(posedge clk) begin
        m_res    <= res;
        w_res    <= m_res ^ rf_b;
        redirect <= is_br & taken;
        target_q <= target;
        addr_q   <= sum;
    end
    assign out0 = ^{m_res, w_res, redirect, target_q, addr_q};
endmodule

`default_nettype wire
