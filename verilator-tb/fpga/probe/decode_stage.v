// Timing probe, not part of the SoC: the decode stage of the six-stage core that
// `docs/fpga.md` plans, alone between flip-flops (the companion of `execute_stage.v` and
// `fetch_stage.v`). The fetched word is expanded (`rtl/rv_expand.v`, the cores' own), its
// register fields address the register file's block RAMs (held while the stage ahead
// waits), compared with the destinations of the three instructions ahead (the forwarding
// and the waits the execute stage takes from registers), and the instruction's class is
// decoded into flags, all into the execute stage's registers. An LFSR feeds the inputs so
// that nothing is constant and the part's few pins suffice.
`default_nettype none

module decode_stage (
    input  wire clk,
    input  wire seed,
    output wire out0
);
    reg [31:0] lfsr = 32'h1;
    always @(posedge clk) lfsr <= {lfsr[30:0], lfsr[31] ^ lfsr[21] ^ lfsr[1] ^ lfsr[0] ^ seed};

    // the fetch stage's and the later stages' registers
    reg [31:0] d_word;
    reg        hold;                 // the execute stage waits: its operands are read again
    reg [4:0]  x_rs1, x_rs2;         // the instruction in X (read again while it waits)
    reg [4:0]  x_rd, m_rd, w_rd;     // destinations of the three instructions ahead
    reg        m_late;               // M's result comes at the end of M (load, shift, CSR)
    reg        wb_en;
    reg [4:0]  wb_rd;
    reg [31:0] wb_val;
    always @(posedge clk) begin
        d_word <= lfsr;
        hold   <= lfsr[3] & lfsr[11];
        x_rs1  <= lfsr[8:4];
        x_rs2  <= lfsr[13:9];
        x_rd   <= lfsr[18:14];
        m_rd   <= lfsr[23:19];
        w_rd   <= lfsr[28:24];
        m_late <= lfsr[29];
        wb_en  <= lfsr[30];
        wb_rd  <= lfsr[31:27];
        wb_val <= {lfsr[15:0], lfsr[31:16]};
    end

    wire        is_c, c_jal, c_branch;
    wire [31:0] fi, imm, raw;
    rv_expand expand (
        .fr(d_word), .is_c(is_c), .insn(fi), .imm(imm), .raw(raw),
        .c_jal(c_jal), .c_branch(c_branch)
    );
    wire [4:0] rs1 = fi[19:15], rs2 = fi[24:20], rd = fi[11:7];
    wire [6:0] op = fi[6:0];
    wire [2:0] f3 = fi[14:12];
    wire [6:0] f7 = fi[31:25];

    // the register file: two block RAMs, read at the edge that ends the stage
    reg [31:0] regs [0:31];
    integer k;
    initial for (k = 0; k < 32; k = k + 1) regs[k] = 32'd0;
    wire [4:0] port_a = hold ? x_rs1 : rs1;
    wire [4:0] port_b = hold ? x_rs2 : rs2;
    reg  [31:0] rf_a, rf_b;
    always @(posedge clk) begin
        if (wb_en) regs[wb_rd] <= wb_val;
        rf_a <= regs[port_a];
        rf_b <= regs[port_b];
    end

    // the class, as the execute stage takes it (rv_pipe's `d_dec` in kind)
    wire d_lui    = op == 7'b0110111;
    wire d_auipc  = op == 7'b0010111;
    wire d_jal    = op == 7'b1101111;
    wire d_jalr   = op == 7'b1100111 && f3 == 3'd0;
    wire d_branch = op == 7'b1100011 && f3[2:1] != 2'b01;
    wire d_load   = op == 7'b0000011 && f3 != 3'd3 && f3[2:1] != 2'b11;
    wire d_store  = op == 7'b0100011 && f3[2] == 1'b0 && f3 != 3'd3;
    wire d_opimm  = op == 7'b0010011 &&
                    (f3 == 3'd1 ? f7 == 7'd0 : f3 == 3'd5 ? (f7 == 7'd0 || f7 == 7'h20) : 1'b1);
    wire d_op     = op == 7'b0110011 &&
                    (f7 == 7'd0 || (f7 == 7'h20 && (f3 == 3'd0 || f3 == 3'd5)));
    wire d_muldiv = op == 7'b0110011 && f7 == 7'd1;
    wire d_csr    = op == 7'b1110011 && f3 != 3'd0 && f3 != 3'd4;
    wire d_amo    = op == 7'b0101111 && f3 == 3'd2;
    wire d_shift  = (d_opimm | d_op) && f3[1:0] == 2'b01;
    wire d_writes = d_lui | d_auipc | d_jal | d_jalr | d_load | d_opimm | d_op | d_muldiv |
                    d_csr | d_amo;
    wire d_legal  = d_writes | d_branch | d_store | fi == 32'h0000_0073 | fi == 32'h3020_0073;
    wire [15:0] d_dec = {d_legal, d_writes, d_shift, d_amo, d_csr, d_muldiv, d_op, d_opimm,
                         d_store, d_load, d_branch, d_jalr, d_jal, d_auipc, d_lui, is_c};

    // the forwarding and the waits, decided here: rs1/rs2 against X's, M's and W's rd (X's
    // instruction is in M when this one is in X, and so on)
    function automatic [2:0] fwd(input [4:0] r);
        fwd = {r != 5'd0 && r == x_rd, r != 5'd0 && r == m_rd, r != 5'd0 && r == w_rd};
    endfunction
    wire [2:0] fa = fwd(rs1), fb = fwd(rs2);
    // a late result (M's) read by the next instruction: one cycle
    wire late_use = m_late && (fa[2] || fb[2]) && !hold;

    reg [31:0] x_imm, x_raw;
    reg [15:0] xd;
    reg [5:0]  x_fwd;
    reg        x_wait;
    reg        x_guess;
    always @(posedge clk) begin
        if (!hold) begin
            x_imm   <= imm;
            x_raw   <= raw;
            xd      <= d_dec;
            x_fwd   <= {fa, fb};
            x_guess <= c_jal | c_branch;
        end
        x_wait <= late_use;
    end
    assign out0 = ^{rf_a, rf_b, x_imm, x_raw, xd, x_fwd, x_wait, x_guess, rd};
endmodule

`default_nettype wire
