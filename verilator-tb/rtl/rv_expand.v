// RV32C expansion, shared by the cores (`rv_core`, `rv_pipe`): the fetched bits in, the
// instruction they stand for out. Each compressed instruction (RV32C and the Zcb forms the
// cores have) becomes the 32-bit one it stands for, except for its immediate, which comes
// out apart (`imm`: the expanded word has zeros in the immediate's fields, and execute takes
// every immediate from here, the 32-bit instructions' too). A reserved or unimplemented
// encoding (C.FLW & co., shifts by 32+, zero immediates where the spec reserves them)
// becomes its 16 bits zero-extended, which the decoder rejects (and mtval reports). Pure
// logic: the cores register what they need of it.
`default_nettype none

module rv_expand (
    input  wire [31:0] fr,        // as fetched (a compressed instruction in bits 15:0)
    output wire        is_c,      // compressed (2 bytes)
    output wire [31:0] insn,      // the instruction, expanded
    output wire [31:0] imm,       // its immediate
    output wire [31:0] raw,       // as fetched, its 16 bits only if compressed (RVFI)
    output wire        c_jal,     // C.J, C.JAL
    output wire        c_branch   // C.BEQZ, C.BNEZ
);
    assign is_c = fr[1:0] != 2'b11;
    wire [15:0] c = fr[15:0];
    wire [2:0]  cr_d = c[4:2], cr_s = c[9:7];      // x8..x15 fields
    wire        c_nz6 = c[12] || c[6:2] != 5'd0;   // 6-bit immediate not zero
    wire [4:0]  ck = {c[1:0], c[15:13]};
    wire        f_a4  = ck == 5'b00_000 && c[12:5] != 8'd0;               // C.ADDI4SPN
    wire        f_lw  = ck == 5'b00_010;                                  // C.LW
    wire        f_sw  = ck == 5'b00_110;                                  // C.SW
    wire        f_ad  = ck == 5'b01_000;                                  // C.ADDI, C.NOP
    wire        f_j   = c[1:0] == 2'b01 && c[14:13] == 2'b01;             // C.JAL, C.J
    wire        f_li  = ck == 5'b01_010;                                  // C.LI
    wire        f_a16 = ck == 5'b01_011 && c_nz6 && c[11:7] == 5'd2;      // C.ADDI16SP
    wire        f_lui = ck == 5'b01_011 && c_nz6 && c[11:7] != 5'd2;      // C.LUI
    wire        f_shi = ck == 5'b01_100 && c[11:10] != 2'b11 &&
                        (!c[12] || c[11]);                                // C.SRLI/SRAI/ANDI
    wire        f_alu = ck == 5'b01_100 && c[11:10] == 2'b11 && !c[12];   // C.SUB/XOR/OR/AND
    wire        f_b   = c[1:0] == 2'b01 && c[15:14] == 2'b11;             // C.BEQZ, C.BNEZ
    wire        f_sll = ck == 5'b10_000 && !c[12];                        // C.SLLI
    wire        f_lsp = ck == 5'b10_010 && c[11:7] != 5'd0;               // C.LWSP
    wire        f_mv  = ck == 5'b10_100 && c[6:2] != 5'd0;                // C.MV, C.ADD
    wire        f_jr  = ck == 5'b10_100 && c[6:2] == 5'd0 && c[11:7] != 5'd0;  // C.JR/JALR
    wire        f_eb  = ck == 5'b10_100 && c[12:2] == 11'h400;            // C.EBREAK
    wire        f_ssp = ck == 5'b10_110;                                  // C.SWSP
    // Zcb: C.LBU, C.LHU, C.LH, C.SB, C.SH; C.ZEXT.B, C.NOT, C.MUL (the forms that
    // need Zbb or RV64 stay reserved)
    wire        f_lb  = ck == 5'b00_100 && c[12:11] == 2'b00;             // C.LBU/LHU/LH
    wire        f_sb  = ck == 5'b00_100 && c[12:11] == 2'b01 && !(c[10] && c[6]); // C.SB/SH
    wire        f_zn  = ck == 5'b01_100 && c[12:10] == 3'b111 && c[6:5] == 2'b11 &&
                        (c[4:2] == 3'b000 || c[4:2] == 3'b101);     // C.ZEXT.B, C.NOT
    wire        f_mul = ck == 5'b01_100 && c[12:10] == 3'b111 && c[6:5] == 2'b10; // C.MUL
    wire        c_legal = f_a4 | f_lw | f_sw | f_ad | f_j | f_li | f_a16 | f_lui | f_shi |
                          f_alu | f_b | f_sll | f_lsp | f_mv | f_jr | f_eb | f_ssp |
                          f_lb | f_sb | f_zn | f_mul;
    wire [31:0] cx =
        ({32{f_a4}}  & {12'd0, 5'd2, 3'b000, 2'b01, cr_d, 7'b0010011}) |
        ({32{f_lw}}  & {12'd0, 2'b01, cr_s, 3'b010, 2'b01, cr_d, 7'b0000011}) |
        ({32{f_sw}}  & {7'd0, 2'b01, cr_d, 2'b01, cr_s, 3'b010, 5'd0, 7'b0100011}) |
        ({32{f_ad}}  & {12'd0, c[11:7], 3'b000, c[11:7], 7'b0010011}) |
        ({32{f_j}}   & {20'd0, 4'd0, !c[15], 7'b1101111}) |
        ({32{f_li}}  & {12'd0, 5'd0, 3'b000, c[11:7], 7'b0010011}) |
        ({32{f_a16}} & {12'd0, 5'd2, 3'b000, 5'd2, 7'b0010011}) |
        ({32{f_lui}} & {20'd0, c[11:7], 7'b0110111}) |
        ({32{f_shi}} & {1'b0, c[10] & !c[11], 10'd0, 2'b01, cr_s, 1'b1, c[11], 1'b1,
                        2'b01, cr_s, 7'b0010011}) |
        ({32{f_alu}} & {1'b0, c[6:5] == 2'b00, 5'd0, 2'b01, cr_d, 2'b01, cr_s,
                        c[6] | c[5], c[6], c[6] & c[5], 2'b01, cr_s, 7'b0110011}) |
        ({32{f_b}}   & {12'd0, 2'b01, cr_s, 2'b00, c[13], 5'd0, 7'b1100011}) |
        ({32{f_sll}} & {12'd0, c[11:7], 3'b001, c[11:7], 7'b0010011}) |
        ({32{f_lsp}} & {12'd0, 5'd2, 3'b010, c[11:7], 7'b0000011}) |
        ({32{f_mv}}  & {7'd0, c[6:2], c[12] ? c[11:7] : 5'd0, 3'b000, c[11:7], 7'b0110011}) |
        ({32{f_jr}}  & {12'd0, c[11:7], 3'b000, 4'd0, c[12], 7'b1100111}) |
        ({32{f_eb}}  & 32'h0010_0073) |
        ({32{f_ssp}} & {7'd0, c[6:2], 5'd2, 3'b010, 5'd0, 7'b0100011}) |
        ({32{f_lb}}  & {12'd0, 2'b01, cr_s, c[10] ? !c[6] : 1'b1, 1'b0, c[10], 2'b01, cr_d,
                        7'b0000011}) |
        ({32{f_sb}}  & {7'd0, 2'b01, cr_d, 2'b01, cr_s, 2'b00, c[10], 5'd0, 7'b0100011}) |
        ({32{f_zn}}  & {12'd0, 2'b01, cr_s, 1'b1, !c[2], !c[2], 2'b01, cr_s, 7'b0010011}) |
        ({32{f_mul}} & {7'd1, 2'b01, cr_d, 2'b01, cr_s, 3'b000, 2'b01, cr_s, 7'b0110011}) |
        ({32{!c_legal}} & {16'd0, c});
    // Immediates. 32-bit formats by opcode bits only (illegal encodings never use the sum;
    // atomics, decoded as S, never use the immediate: zero); compressed ones by format (the
    // register-register forms and C.JR/C.JALR take zero).
    wire [6:0]  fo = fr[6:0];
    wire [31:0] imm32 =
        (!fo[6] && fo[4] && fo[2]) ? {fr[31:12], 12'd0} :                            // U
        (fo[6] && fo[3]) ? {{11{fr[31]}}, fr[31], fr[19:12], fr[20], fr[30:21], 1'b0} : // J
        (fo[6] && !fo[4] && !fo[2]) ?
            {{19{fr[31]}}, fr[31], fr[7], fr[30:25], fr[11:8], 1'b0} :                 // B
        (!fo[6] && fo[5] && !fo[4]) ?
            (fo[2] ? 32'd0 : {{20{fr[31]}}, fr[31:25], fr[11:7]}) :                   // A, S
        {{20{fr[31]}}, fr[31:20]};                                                     // I
    wire [31:0] immc =
        ({32{f_a4}}  & {22'd0, c[10:7], c[12:11], c[5], c[6], 2'b00}) |
        ({32{f_lw | f_sw}} & {25'd0, c[5], c[12:10], c[6], 2'b00}) |
        ({32{f_ad | f_li | f_shi | f_sll}} & {{27{c[12]}}, c[6:2]}) |
        ({32{f_a16}} & {{23{c[12]}}, c[4:3], c[5], c[2], c[6], 4'd0}) |
        ({32{f_lui}} & {{15{c[12]}}, c[6:2], 12'd0}) |
        ({32{f_j}}   & {{21{c[12]}}, c[8], c[10:9], c[6], c[7], c[2], c[11], c[5:3], 1'b0}) |
        ({32{f_b}}   & {{24{c[12]}}, c[6:5], c[2], c[11:10], c[4:3], 1'b0}) |
        ({32{f_lsp}} & {24'd0, c[3:2], c[12], c[6:4], 2'b00}) |
        ({32{f_ssp}} & {24'd0, c[8:7], c[12:9], 2'b00}) |
        ({32{f_lb | f_sb}} & {30'd0, c[5], c[6] & !c[10]}) |
        ({32{f_zn}}  & {{24{c[2]}}, 8'hFF});
    assign insn = is_c ? cx : fr;
    assign imm = is_c ? immc : imm32;
    assign raw = is_c ? {16'd0, c} : fr;
    assign c_jal = f_j;
    assign c_branch = f_b;
endmodule

`default_nettype wire
