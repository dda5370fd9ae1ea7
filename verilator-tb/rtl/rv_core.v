// RV32IMAC + Zcb + Zicsr machine-mode core.
//
// Single-issue, two stages. The fetch stage presents the (halfword) address of the next
// instruction and gets the 32 bits starting there (the SoC's RAM is two halfword banks, so
// any halfword address reads in one cycle); a compressed instruction is expanded to its
// 32-bit form there, and at the clock edge the instruction and two register-file words are
// captured (synchronous reads, so the register file and instruction memory fit block RAM; a
// word written at the same edge is forwarded). The execute stage decodes, executes, accesses data memory (read data returned
// in the same cycle) and writes back; most instructions take one cycle.
//
// The register file has 64 words: x0..x31, then the wide CSRs (mscratch, mepc, mtvec, mtval
// and the four halves of mcycle and minstret), so they cost block RAM instead of logic. The
// second read port reads the CSR a SYSTEM instruction names (mepc for MRET); the one write
// port is shared in time, which gives a few short sequences (`seq`):
//   EXEC  execute the instruction in `ir`. A CSR instruction retires here (rd <- old value,
//         CSRs kept in registers written); a trap or interrupt writes mtval here.
//   EX2   second cycle of a CSR instruction that writes a register-file CSR (the new value,
//         computed in EXEC, is written), or of an AMO (the ALU combines the loaded word,
//         forwarded as rs1, with rs2; the result is stored; rd <- loaded word; it retires).
//   TRAP  second cycle of trap entry: mepc <- pc; fetch from mtvec (read in this cycle).
//   CNT   add a carry into a counter word in the register file (see below).
// The counters count in small registers (`cyc_lo`, `ins_lo`, CNT_P bits); when one wraps, a
// CNT cycle adds 2^CNT_P to the low word in the register file (and a second one carries into
// the high word). CNT cycles run only between instructions, so a read always sees a settled
// value: mcycle = {word[31:CNT_P], cyc_lo}.
//
// Multiplication is a single-cycle 32x32 product (maps to DSP blocks) that also serves the
// shifts; division and remainder use an iterative restoring divider (34 cycles). With
// MUL_SEQ = 1 (parts without DSP blocks, where a 32x32 product in logic is about 2 800 LUT4)
// MUL* run in the divider's loop instead, as a shift-and-add multiplier (34 cycles too),
// and the shifts on a barrel shifter. One adder
// computes ADD/SUB/ADDI/LUI/AUIPC, load/store addresses, jump and branch targets, trap values
// and counter carries. WFI stalls until an enabled interrupt is pending. Interrupts are taken
// between instructions, never inside a division (nor, with MUL_SEQ = 1, a product).
//
// The RVFI-style retirement port is registered: the record of an instruction is valid in the
// cycle after it completes.
`default_nettype none

module rv_core #(
    parameter [31:0] RESET_PC = 32'h8000_0000,
    parameter integer CNT_P = 6,
    // The memory the fetch port reads: the 1 MiB region whose address bits 31:20 are
    // FETCH_REGION, 2^FETCH_AW words repeated over it (stores there are snooped, below).
    parameter [11:0] FETCH_REGION = 12'h800,
    parameter integer FETCH_AW = 18,
    // 0: MUL* in one cycle on a 32x32 multiplier (DSP blocks); 1: in 34 cycles, shift and
    // add in the divider's registers (the shifts then have their own barrel shifter).
    parameter integer MUL_SEQ = 0
) (
    input  wire        clk,
    input  wire        rst,

    // Instruction bus: halfword address out, the 32 bits from there in (same cycle).
    output wire [31:0] imem_addr,
    input  wire [31:0] imem_rdata,

    // Data bus: word-aligned address, read data returned in the same cycle. Reads with side
    // effects and writes take effect at the clock edge when `dmem_re`/`dmem_wstrb` are set
    // (and `rst` is low: devices ignore the strobes during reset).
    output wire [31:0] dmem_addr,
    output wire        dmem_re,
    output wire [3:0]  dmem_rmask,
    output wire [3:0]  dmem_wstrb,
    output wire [31:0] dmem_wdata,
    input  wire [31:0] dmem_rdata,
    // The instruction executing may read memory this cycle (from its decode alone, so it
    // settles early; a cycle that writes memory never has it): for RAMs that must choose
    // between a read and a write before the access is known to commit.
    output wire        dmem_rd_pre,
    // The last store into the fetch memory (FETCH_REGION), kept until the next one: a RAM
    // with a write buffer holds that store (see fpga/soc_ram_spram.v).
    output wire [FETCH_AW-1:0] last_st_word,
    output wire [31:0] last_st_data,
    output wire [3:0]  last_st_mask,

    input  wire        irq_software,
    input  wire        irq_timer,
    input  wire        irq_external,
    // Stalled in WFI this cycle (for statistics).
    output wire        sleeping,

    output reg         rvfi_valid,
    output reg  [63:0] rvfi_order,
    output reg  [31:0] rvfi_insn,
    output reg         rvfi_trap,
    output reg         rvfi_intr,
    output reg  [31:0] rvfi_pc_rdata,
    output reg  [31:0] rvfi_pc_wdata,
    output reg  [4:0]  rvfi_rd_addr,
    output reg  [31:0] rvfi_rd_wdata,
    output reg  [31:0] rvfi_mem_addr,
    output reg  [3:0]  rvfi_mem_rmask,
    output reg  [3:0]  rvfi_mem_wmask,
    output reg  [31:0] rvfi_mem_rdata,
    output reg  [31:0] rvfi_mem_wdata,
    // Interrupt lines {external, timer, software} seen by this instruction (for mip reads) and,
    // on a record with rvfi_intr set, the lines at the interrupt entry before it.
    output reg  [2:0]  rvfi_ext_mip,
    output reg  [2:0]  rvfi_ext_intr_mip
);

    // Register-file words of the wide CSRs: 32 + {counter, high, instret} for the counters,
    // 32 + csr[1:0] for 0x340..0x343 (0x342, mcause, is a register), 32 + 2 for mtvec.
    localparam [5:0] W_MEPC = 6'd33, W_MTVEC = 6'd34, W_MTVAL = 6'd35;
    localparam [1:0] S_EXEC = 2'd0, S_EX2 = 2'd1, S_TRAP = 2'd2, S_CNT = 2'd3;

    // ---------------------------------------------------------------- state
    reg [31:0] pc;
    // A read of the word written at the same edge is never used (byp_a/byp_b forward the
    // written value instead), so synthesis need not give it a defined value: without
    // no_rw_check, yosys would emulate the read-before-write order in logic.
    (* no_rw_check *)
    reg [31:0] regs [0:63];
    integer k;
    initial for (k = 0; k < 64; k = k + 1) regs[k] = 32'd0;  // block-RAM initial contents

    reg [1:0]  seq;
    // fetch-stage outputs: the instruction in execute and two register-file words
    reg [31:0] ir;                 // the instruction, expanded if it was compressed
    reg        ir_c;               // ... it was compressed (2 bytes long)
    reg [31:0] ir_imm;             // its immediate (decoded in the fetch stage)
    reg [31:0] ir_raw;             // as fetched (16 bits zero-extended if compressed), for RVFI
    reg [31:0] rf_a, rf_b;
    reg        byp_a, byp_b;       // forward the word written at the fetch edge instead
    reg [31:0] byp_val;

    reg        mstatus_mie, mstatus_mpie;
    reg        mie_e, mie_t, mie_s;
    reg        mcause_int;
    reg [3:0]  mcause_code;
    reg [31:0] csr_new;            // register-file CSR value written in EX2
    reg [2:0]  seen_mip;           // interrupt lines of the last EXEC cycle

    reg [CNT_P-1:0] cyc_lo, ins_lo;
    reg        cyc_pl, cyc_ph;     // pending carry into the low / high word of mcycle
    reg        ins_pl, ins_ph;     // ... of minstret
    reg        ins_nohi;           // the pending minstret carry stops at the low word
    reg        cnt_ins, cnt_hi;    // the word a CNT cycle updates
    reg        cnt_wfi;            // ... while a WFI waits (for the sleep statistics)

    reg        res_valid;          // LR/SC reservation
    reg [31:0] res_addr;

    reg        intr_flag;          // next record is the first instruction of an interrupt handler
    reg [2:0]  intr_mip;

    reg        md_busy;            // iterative divider
    reg [5:0]  md_cnt;
    reg [31:0] md_quo, md_div;
    reg [31:0] md_rem_n;           // the remainder (or high product), inverted: see md_dif_n

    // The reset input enters only the register updates and the fetch address, so the
    // datapath's logic does not depend on a top-level input (which would make a simulator
    // re-evaluate it on every input change). The bus strobes are meaningless during reset:
    // the SoC ignores them then.
    wire ex = seq == S_EXEC;

    // ---------------------------------------------------------------- decode
    wire [31:0] insn   = ir;
    wire [6:0]  opcode = insn[6:0];
    wire [4:0]  rd     = insn[11:7];
    wire [4:0]  rs1    = insn[19:15];
    wire [4:0]  rs2    = insn[24:20];
    wire [2:0]  f3     = insn[14:12];
    wire [6:0]  f7     = insn[31:25];
    wire [4:0]  f5     = insn[31:27];

    wire [31:0] rs1v = byp_a ? byp_val : rf_a;
    wire [31:0] rs2v = byp_b ? byp_val : rf_b;   // rs2, or the CSR word of a SYSTEM instruction

    wire is_lui    = opcode == 7'b0110111;
    wire is_auipc  = opcode == 7'b0010111;
    wire is_jal    = opcode == 7'b1101111;
    wire is_jalr   = opcode == 7'b1100111 && f3 == 3'd0;
    wire is_branch = opcode == 7'b1100011 && f3[2:1] != 2'b01;
    wire is_load   = opcode == 7'b0000011 && f3 != 3'd3 && f3[2:1] != 2'b11;
    wire is_store  = opcode == 7'b0100011 && f3[2] == 1'b0 && f3 != 3'd3;
    wire is_opimm  = opcode == 7'b0010011 &&
                     (f3 == 3'd1 ? f7 == 7'd0 :
                      f3 == 3'd5 ? (f7 == 7'd0 || f7 == 7'h20) : 1'b1);
    wire is_op     = opcode == 7'b0110011 &&
                     (f7 == 7'd0 || (f7 == 7'h20 && (f3 == 3'd0 || f3 == 3'd5)));
    wire is_muldiv = opcode == 7'b0110011 && f7 == 7'd1;
    wire is_fence  = opcode == 7'b0001111 && f3 == 3'd0;
    wire is_ecall  = insn == 32'h0000_0073;
    wire is_ebreak = insn == 32'h0010_0073;
    wire is_mret   = insn == 32'h3020_0073;
    wire is_wfi    = insn == 32'h1050_0073;
    wire is_csr    = opcode == 7'b1110011 && f3 != 3'd0 && f3 != 3'd4;

    wire amo_op_ok = f5 == 5'b00010 ? rs2 == 5'd0 :
                     (f5 == 5'b00011 || f5 == 5'b00001 || f5 == 5'b00000 || f5 == 5'b00100 ||
                      f5 == 5'b01100 || f5 == 5'b01000 || f5 == 5'b10000 || f5 == 5'b10100 ||
                      f5 == 5'b11000 || f5 == 5'b11100);
    wire is_amo_any = opcode == 7'b0101111 && f3 == 3'd2 && amo_op_ok;
    wire is_lr     = is_amo_any && f5 == 5'b00010;
    wire is_sc     = is_amo_any && f5 == 5'b00011;
    wire is_amo    = is_amo_any && !is_lr && !is_sc;

    wire is_div    = is_muldiv && f3[2];
    // instructions that run in the divider's loop
    wire is_iter   = is_muldiv && (f3[2] || MUL_SEQ != 0);

    // ---------------------------------------------------------------- adder
    // Operand A: pc for AUIPC, JAL, branches and the TRAP cycle (mepc <- pc + 0), zero for LUI,
    // else rs1. Operand B: rs2 (inverted for SUB), the instruction's immediate, zero for
    // atomic addresses and TRAP, the carry for CNT. The immediate is picked by opcode only
    // (illegal encodings never use the sum). An AMO's second cycle: see below.
    wire op_u = !opcode[6] && opcode[4] && opcode[2];        // LUI, AUIPC
    wire op_j = opcode[6] && opcode[3];                      // JAL
    wire op_b = opcode[6] && !opcode[4] && !opcode[2];       // branches
    wire op_s = !opcode[6] && opcode[5] && !opcode[4];       // stores, atomics (zero)
    wire op_r = opcode == 7'b0110011;                        // OP
    wire op_amo = op_s && opcode[2];                         // atomics
    wire [31:0] imm = ir_imm;   // decoded in the fetch stage

    wire        ex_pc   = seq == S_TRAP || (!seq[1] && ((op_u && !opcode[5]) || op_j || op_b));
    wire        do_sub  = !seq[1] && op_r && f7[5];
    wire [31:0] alu_b   = op_r || op_amo ? rs2v : imm;

    // comparison: branches, SLT[U][I], AMOMIN/MAX[U]
    wire [31:0] cmp_b      = is_branch ? rs2v : alu_b;
    wire        cmp_signed = is_branch ? !f3[1] : op_amo ? !f5[3] : !f3[0];
    wire [32:0] cmp_diff   = {cmp_signed & rs1v[31], rs1v} - {cmp_signed & cmp_b[31], cmp_b};
    wire        lt         = cmp_diff[32];
    wire        eq         = rs1v == cmp_b;
    wire        br_taken   = f3[2] ? lt ^ f3[0] : eq ^ f3[0];

    // An AMO's new word (EX2) is the sum OR the logic unit's output, one of them zero: the
    // logic unit gives AMOXOR/OR/AND (the sum is 0 + 0) and zero for the others, which the
    // adder makes: AMOADD rs1 + rs2, AMOSWAP 0 + rs2, AMOMIN/MAX[U] rs1 + 0 or 0 + rs2 as the
    // comparison picks.
    wire        amo_b    = seq == S_EX2 && op_amo;
    wire        amo_lg   = !f5[4] && f5[3:2] != 2'b00;             // AMOXOR/OR/AND
    wire        amo_take = f5[4] && (lt ^ f5[2]);                 // keep the loaded word
    wire        a_zero  = (!seq[1] && op_u && opcode[5]) ||        // LUI
                          (amo_b && (f5[0] || amo_lg || (f5[4] && !amo_take)));
    wire [31:0] add_a   = ex_pc ? pc : a_zero ? 32'd0 : rs1v;
    // TRAP, CNT, atomic address, AMO operands above
    wire        b_zero  = seq[1] || (op_amo && seq == S_EXEC) || (amo_b && (amo_take || amo_lg));
    wire [31:0] cnt_inc = seq == S_CNT ? (cnt_hi ? 32'd1 : 32'd1 << CNT_P) : 32'd0;
    wire [31:0] add_b   = ((alu_b & ~{32{b_zero}}) ^ {32{do_sub}}) | cnt_inc;
    wire [32:0] sum33   = {1'b0, add_a} + {1'b0, add_b} + {32'd0, do_sub};
    wire [31:0] sum     = sum33[31:0];

    // ---------------------------------------------------------------- logic
    wire [4:0]  shamt   = alu_b[4:0];

    // SLT[U], XOR, OR, AND; AMOXOR/AMOOR/AMOAND map onto the same codes, other AMOs give 0
    wire [2:0]  logic_op = !op_amo ? f3 : amo_lg ? {1'b1, f5[3], f5[3] & f5[2]} : 3'd0;
    reg  [31:0] logic_out;
    always @(*) begin
        case (logic_op)
            3'd4: logic_out = rs1v ^ alu_b;
            3'd6: logic_out = rs1v | alu_b;
            3'd7: logic_out = rs1v & alu_b;
            default: logic_out = {31'd0, lt && !op_amo};
        endcase
    end

    // ---------------------------------------------------------------- multiply / divide
    // MUL_SEQ = 0 (with 1, the products run in the divider's loop and the shifts on the barrel
    // shifter below; the magnitudes and the negation are shared the same way):
    // One 32x32 unsigned multiplier (DSP blocks) serves MUL*, the shifts, and the operand
    // magnitudes below serve it and the divider. Signed products multiply magnitudes and
    // negate the 64-bit result when the signs differ; only its high word is needed then:
    // ~hi + (lo == 0). Shifts: x << n is the low word of x * 2^n; for n > 0, x >> n is the
    // high word of x * 2^(32-n), and x >>> n the same with x signed. A zero right shift takes
    // the low word of x * 1.
    wire        is_shift = (is_opimm | is_op) && f3[1:0] == 2'b01;
    wire        sh_zero  = shamt == 5'd0;
    // signed operands: DIV/REM (both), MULH (both), MULHSU (rs1), SRA/SRAI by n > 0 (rs1)
    wire        sign_a   = is_muldiv ? (f3[2] ? !f3[0] : f3[1] ^ f3[0]) :
                           is_shift && f3[2] && f7[5] && !sh_zero;
    wire        sign_b   = is_muldiv && (f3[2] ? !f3[0] : f3[1:0] == 2'd1);
    wire        neg_a    = sign_a && rs1v[31];
    wire        neg_b    = sign_b && rs2v[31];
    // Conditional negation as (x + s) ^ s, s all ones or zero (~(x - 1) = -x): the XOR after
    // the adder fits in the LUTs of its carry chain, where one before it would not.
    wire [31:0] abs_a    = (rs1v + {32{neg_a}}) ^ {32{neg_a}};
    wire [31:0] abs_b    = (rs2v + {32{neg_b}}) ^ {32{neg_b}};
    wire [4:0]  sh_pow   = f3[2] ? 5'd0 - shamt : shamt;
    wire [31:0] mul_b    = is_shift ? 32'd1 << sh_pow : abs_b;
    wire [63:0] prod_1c  = {32'd0, abs_a} * {32'd0, mul_b};
    // the magnitude of the product: the multiplier's, or the loop's {md_rem, md_quo}
    wire [63:0] prod_u   = MUL_SEQ != 0 ? {md_rem, md_quo} : prod_1c;
    wire        prod_neg = neg_a ^ neg_b;
    wire        lo_zero  = prod_u[31:0] == 32'd0;
    wire        use_lo   = is_shift ? !f3[2] || sh_zero : f3[1:0] == 2'd0;

    // The remainder is kept inverted so that the divider's subtraction needs no inverter in
    // front of its carry chain (~(~a + b) = a - b): md_dif_n = ~(md_sh - md_div).
    wire [31:0] md_rem   = ~md_rem_n;
    wire [32:0] md_sh_n  = {md_rem_n, !md_quo[31]};
    wire [32:0] md_dif_n = md_sh_n + {1'b0, md_div};
    // one step of the shift-and-add multiplier: {md_rem, md_quo} = (acc + b * bit) >> 1,
    // the multiplier's bits leaving md_quo at the bottom as the product's enter at the top
    // (inverted the same way: ~(a + b) = ~a - b)
    wire [32:0] mq_sum_n = {1'b1, md_rem_n} - (md_quo[0] ? {1'b0, md_div} : 33'd0);
    // barrel shifter (MUL_SEQ only)
    wire [31:0] sh_out = !f3[2] ? rs1v << shamt :
                         f7[5] ? $unsigned($signed(rs1v) >>> shamt) : rs1v >> shamt;
    wire        md_done = md_busy && md_cnt == 6'd32;
    wire [31:0] md_res = f3[1] ? md_rem : md_quo;
    // Dividing by zero needs no special case: the loop yields an all-ones quotient and the
    // dividend's magnitude as remainder; only the quotient's sign fix-up is suppressed.
    wire        md_neg = f3[1] ? neg_a : (neg_a ^ neg_b) && rs2v != 32'd0;
    // One conditional negation serves the signed high product and the divider's result:
    // (x - c) ^ s with s = ng, c = ng_c: -x when both are set, ~x with s alone (see abs_a).
    wire [31:0] ng_in  = is_div ? md_res : prod_u[63:32];
    wire        ng     = is_div ? md_neg : prod_neg;
    wire        ng_c   = is_div ? md_neg : prod_neg && lo_zero;   // (implies ng)
    wire [31:0] ng_out = (ng_in + {32{ng_c}}) ^ {32{ng}};
    wire [31:0] mul_out = MUL_SEQ != 0 && is_shift ? sh_out :
                          use_lo && !is_div ? prod_u[31:0] : ng_out;   // also DIV/REM

    // ---------------------------------------------------------------- memory access
    wire [31:0] ls_addr = sum;
    wire        ls_misaligned = is_amo_any ? ls_addr[1:0] != 2'd0 :
                                f3[1:0] == 2'd1 ? ls_addr[0] :
                                f3[1:0] == 2'd2 ? ls_addr[1:0] != 2'd0 : 1'b0;
    wire [4:0]  ls_shift = {ls_addr[1:0], 3'd0};
    wire [31:0] ld_shifted = dmem_rdata >> ls_shift;
    reg  [31:0] load_out;   // also LR and the old value of an AMO (f3 = 2)
    always @(*) begin
        case (f3)
            3'd0: load_out = {{24{ld_shifted[7]}}, ld_shifted[7:0]};
            3'd1: load_out = {{16{ld_shifted[15]}}, ld_shifted[15:0]};
            3'd4: load_out = {24'd0, ld_shifted[7:0]};
            3'd5: load_out = {16'd0, ld_shifted[15:0]};
            default: load_out = dmem_rdata;
        endcase
    end

    wire [3:0] st_mask = f3[1:0] == 2'd0 ? (4'b0001 << ls_addr[1:0]) :
                         f3[1:0] == 2'd1 ? (4'b0011 << ls_addr[1:0]) : 4'b1111;
    wire [31:0] st_data = f3[1:0] == 2'd0 ? {4{rs2v[7:0]}} :
                          f3[1:0] == 2'd1 ? {2{rs2v[15:0]}} : rs2v;

    // AMO, second cycle: rs1v is the loaded word; the logic unit (AMOXOR/OR/AND) or the
    // adder (the others, see above) gives the new one.
    wire [31:0] amo_out = logic_out | sum;
    wire sc_ok = res_valid && res_addr == ls_addr;

    // ---------------------------------------------------------------- CSRs
    wire [11:0] csr_addr = insn[31:20];
    wire [2:0]  lines    = {irq_external, irq_timer, irq_software};
    wire [31:0] mip_v    = {20'd0, irq_external, 3'd0, irq_timer, 3'd0, irq_software, 3'd0};
    wire [31:0] mie_v    = {20'd0, mie_e, 3'd0, mie_t, 3'd0, mie_s, 3'd0};
    // Classes of the implemented addresses (a committing CSR instruction has a legal one).
    wire c_cnt  = csr_addr[11] && csr_addr[10:8] != 3'b111;          // mcycle(h), minstret(h)
    wire c_34x  = !csr_addr[11] && csr_addr[6];                      // 0x340..0x344
    wire c_30x  = !csr_addr[11] && !csr_addr[6] && !csr_addr[4];     // 0x300..0x305
    wire in_rf  = c_cnt || (c_34x && !csr_addr[2] && csr_addr[1:0] != 2'd2) ||
                  (c_30x && csr_addr[2] && csr_addr[0]);
    wire cnt_lo = c_cnt && !csr_addr[7];
    wire [CNT_P-1:0] lo_bits = csr_addr[1] ? ins_lo : cyc_lo;
    reg  [31:0] csr_reg;    // CSRs kept in registers (and constants)
    always @(*) begin
        csr_reg = 32'd0;
        if (c_34x)
            csr_reg = csr_addr[2] ? mip_v : {mcause_int, 27'd0, mcause_code};
        else if (c_30x)
            case (csr_addr[2:0])
                3'd0: csr_reg = {19'd0, 2'b11, 3'd0, mstatus_mpie, 3'd0, mstatus_mie, 3'd0};
                3'd1: csr_reg = 32'h4000_1105;
                default: csr_reg = mie_v;
            endcase
    end
    wire [31:0] csr_rdata = !in_rf ? csr_reg :
                            cnt_lo ? {rs2v[31:CNT_P], lo_bits} : rs2v;
    reg         csr_exists;
    always @(*) begin
        case (csr_addr)
            12'h300, 12'h301, 12'h304, 12'h305, 12'h310, 12'h340, 12'h341, 12'h342, 12'h343,
            12'h344, 12'hb00, 12'hc00, 12'hb80, 12'hc80, 12'hb02, 12'hc02, 12'hb82, 12'hc82,
            12'hf11, 12'hf12, 12'hf13, 12'hf14, 12'hf15: csr_exists = 1'b1;
            default: csr_exists = 1'b0;
        endcase
    end
    wire        csr_writes = f3[1:0] == 2'b01 || rs1 != 5'd0;
    // immediate forms read x0 as rs1, so only the low five bits need the immediate
    wire [31:0] csr_src    = {rs1v[31:5], f3[2] ? rs1 : rs1v[4:0]};
    wire        c_rw       = f3[1:0] == 2'b01, c_rc = f3[1:0] == 2'b11;
    wire [31:0] csr_wdata  = (csr_rdata & ~({32{c_rw}} | ({32{c_rc}} & csr_src))) |
                             (csr_src & ~{32{c_rc}});
    wire        csr_illegal = !csr_exists || (csr_addr[11:10] == 2'b11 && csr_writes);
    // WARL on the way into the register file: mepc bit 0 reads zero; mtvec bit 1 reads zero,
    // and a vectored table (mode 1) is 64-byte aligned so that entry = base | cause << 2.
    wire        w_mepc  = c_34x && csr_addr[0] && !csr_addr[1];
    wire        w_mtvec = c_30x;
    wire [31:0] csr_wval = {csr_wdata[31:6],
                            csr_wdata[5:2] & ~{4{w_mtvec && csr_wdata[0]}},
                            csr_wdata[1] & !w_mtvec,
                            csr_wdata[0] & !w_mepc};
    // CSR writes that go to registers, decided by the address bits that tell them apart.
    wire        wr_csr     = csr_ex && csr_writes;
    wire        wr_mstatus = wr_csr && c_30x && csr_addr[2:0] == 3'd0;
    wire        wr_mie     = wr_csr && c_30x && csr_addr[2:0] == 3'd4;
    wire        wr_mcause  = wr_csr && c_34x && csr_addr[2:0] == 3'd2;
    wire        a_ins_lo   = csr_writes && cnt_lo && csr_addr[1];   // by the address only
    wire        a_ins_hi   = csr_writes && c_cnt && csr_addr[7] && csr_addr[1];
    wire        wr_cyc_lo  = wr_csr && cnt_lo && !csr_addr[1];
    wire        wr_ins_lo  = csr_ex && a_ins_lo;

    // ---------------------------------------------------------------- control flow, traps
    wire legal = is_lui | is_auipc | is_jal | is_jalr | is_branch | is_load | is_store |
                 is_opimm | is_op | is_muldiv | is_fence | is_ecall | is_ebreak | is_mret |
                 is_wfi | is_csr | is_amo_any;
    // With C every target is a halfword address (JALR clears bit 0, offsets are even, mepc
    // and mtvec keep bit 0 clear), so no jump can raise a misaligned-fetch exception.
    wire [31:0] pc_plus4 = pc + {29'd0, !ir_c, ir_c, 1'b0};   // pc + 2 or 4
    wire jump = is_jal | is_jalr | (is_branch && br_taken);
    wire [31:0] next_pc  = jump ? {sum[31:1], 1'b0} : is_mret ? rs2v : pc_plus4;

    // an illegal compressed instruction arrives as its 16 bits, zero-extended
    wire exc_illegal = !legal || (is_csr && csr_illegal) || insn[1:0] != 2'b11;
    wire exc_load    = !exc_illegal && (is_load || is_lr) && ls_misaligned;
    wire exc_store   = !exc_illegal && (is_store || is_sc || is_amo) && ls_misaligned;
    wire exc_misal   = exc_load | exc_store;
    wire exc = exc_illegal | exc_misal | is_ecall | is_ebreak;
    wire [3:0] exc_cause = exc_illegal ? 4'd2 : exc_load ? 4'd4 :
                           exc_store ? 4'd6 : is_ebreak ? 4'd3 : 4'd11;

    wire [2:0]  irq_pend = lines & {mie_e, mie_t, mie_s};
    wire        irq_take = ex && mstatus_mie && irq_pend != 3'd0 && !md_busy && !is_wfi;
    wire [3:0]  irq_cause = irq_pend[2] ? 4'd11 : irq_pend[0] ? 4'd3 : 4'd7;
    // in TRAP, rs2v is mtvec
    wire [31:0] trap_pc = {rs2v[31:6], rs2v[5:2] | (mcause_int && rs2v[0] ? mcause_code : 4'd0),
                           2'b00};

    wire stall     = (is_iter && !md_done) || (is_wfi && irq_pend == 3'd0);
    // CNT cycles taken while a WFI waits count as sleep too: the program is not running
    assign sleeping = !rst && ((ex && is_wfi && irq_pend == 3'd0) || (seq == S_CNT && cnt_wfi));
    wire trap_in   = ex && (irq_take || exc);
    wire csr_ex    = ex && !irq_take && !exc && is_csr;
    wire csr_rf_w  = csr_ex && in_rf && csr_writes;     // finishes in EX2
    wire amo_a     = ex && !irq_take && !exc && is_amo;
    wire two_ph    = csr_rf_w || amo_a;
    wire in_ex2    = seq == S_EX2;
    wire commit_ex = ex && !irq_take && !exc && !stall && !is_amo;
    wire retire    = commit_ex || (in_ex2 && is_amo);

    wire mem_rd = is_load | is_lr | is_amo;
    wire mem_wr = is_store | is_amo | (is_sc && sc_ok);

    // ---------------------------------------------------------------- counters
    // minstret: a write of the low word replaces this instruction's increment (if the old
    // value was all ones, that increment still carries into the high word); a write of the
    // high word replaces the carry of this instruction's increment.
    wire ins_inc   = retire && !(is_csr && a_ins_lo);
    wire cyc_wrap  = !wr_cyc_lo && cyc_lo == {CNT_P{1'b1}};
    wire ins_wrap  = ins_inc && ins_lo == {CNT_P{1'b1}};
    wire cnt_carry = sum33[32];
    wire in_cnt    = seq == S_CNT;
    wire cyc_pl_n  = (cyc_pl || cyc_wrap) && !(in_cnt && !cnt_ins && !cnt_hi);
    wire cyc_ph_n  = (cyc_ph || (in_cnt && !cnt_ins && !cnt_hi && cnt_carry)) &&
                     !(in_cnt && !cnt_ins && cnt_hi);
    wire ins_pl_n  = (ins_pl || ins_wrap) && !(in_cnt && cnt_ins && !cnt_hi);
    wire ins_ph_n  = (ins_ph || (in_cnt && cnt_ins && !cnt_hi && cnt_carry && !ins_nohi) ||
                      (wr_ins_lo && csr_rdata == 32'hffff_ffff)) &&
                     !(in_cnt && cnt_ins && cnt_hi);

    // ---------------------------------------------------------------- sequencing
    // A boundary: the next cycle may start an instruction (a WFI that waits is one too).
    wire boundary = !(ex && (trap_in || two_ph || (stall && !is_wfi)));
    wire to_cnt   = boundary && (cyc_pl_n || cyc_ph_n || ins_pl_n || ins_ph_n);
    wire n_ins    = !(cyc_pl_n || cyc_ph_n);
    wire n_hi     = n_ins ? !ins_pl_n : !cyc_pl_n;
    wire [1:0] seq_n = to_cnt ? S_CNT : trap_in ? S_TRAP :
                       two_ph ? S_EX2 : S_EXEC;

    wire hold = seq == S_CNT || trap_in || two_ph || (ex && stall);
    // MRET (rs2v = mepc) and TRAP (rs2v = mtvec) share one path from rs2v to the fetch address:
    // `seq_pc` is trap_pc in TRAP and next_pc otherwise. (next_pc and trap_pc above serve
    // only the retirement records, which are written outside TRAP and in it respectively.)
    wire        in_trap  = seq == S_TRAP;
    wire [31:0] rs2_pc   = {rs2v[31:6],
                            rs2v[5:2] | (in_trap && mcause_int && rs2v[0] ? mcause_code : 4'd0),
                            rs2v[1:0] & ~{2{in_trap}}};
    wire [31:0] seq_pc   = in_trap || (!jump && is_mret) ? rs2_pc :
                           jump ? {sum[31:1], 1'b0} : pc_plus4;
    // (pc takes the fetch address itself, so one reset gate serves both)
    wire [31:0] fetch_pc = hold && !in_trap && !rst ? pc : imem_addr;
    // The memory is read with the address of the next instruction whether or not this cycle
    // holds: `hold` depends on interrupt lines, traps and stalls, which settle late, while
    // the memory needs its address early (it reads on the falling edge). A holding cycle
    // instead keeps the instruction word it has, updated with a store that landed since it
    // was read, which is what reading it again at `pc` gives (see `refetch` below).
    assign imem_addr  = rst ? RESET_PC : seq_pc;
    // an AMO stores in EX2 to the address it loaded from
    assign dmem_addr  = seq == S_EX2 ? {res_addr[31:2], 2'b00} : {ls_addr[31:2], 2'b00};
    assign dmem_re    = (commit_ex && mem_rd) || amo_a;
    assign dmem_rd_pre = ex && mem_rd;
    assign dmem_rmask = mem_rd ? (is_load ? st_mask : 4'b1111) : 4'b0000;
    assign dmem_wstrb = (commit_ex && mem_wr) ? (is_store ? st_mask : 4'b1111) :
                        (in_ex2 && is_amo) ? 4'b1111 : 4'b0000;
    assign dmem_wdata = is_amo ? amo_out : st_data;

    // ---------------------------------------------------------------- write-back
    // One write per cycle: rd of a retiring instruction, the CSR word of a CSR instruction,
    // mtval at trap entry (the instruction, the faulting address or target, or zero), mepc in
    // TRAP, a counter word in CNT. The sources are exclusive, so an AND-OR picks the value.
    wire t_ex   = ex && !trap_in;
    wire t_sum  = (t_ex && (is_lui || is_auipc || ((is_opimm || is_op) && f3 == 3'd0))) ||
                  (trap_in && !irq_take && exc_misal) || seq == S_TRAP || seq == S_CNT;
    wire t_link = t_ex && (is_jal || is_jalr);
    // an AMO's loaded word: forwarded as rs1 to EX2 (not written), then rd in EX2
    wire t_load = (t_ex && (is_load || is_lr)) || ((amo_a || in_ex2) && is_amo);
    wire t_logic = t_ex && (is_opimm || is_op) && f3 != 3'd0 && f3[1:0] != 2'b01;
    wire t_mul  = t_ex && ((is_muldiv && !f3[2]) || is_shift);
    wire t_div  = t_ex && is_div;
    wire t_insn = trap_in && !irq_take && exc_illegal;
    wire t_csrr = t_ex && is_csr;
    wire t_new  = in_ex2 && is_csr;
    wire [31:0] wb_val =
        ({32{t_sum}} & sum) |
        ({32{t_link}} & pc_plus4) | ({32{t_load}} & load_out) |
        ({32{t_logic}} & logic_out) | ({32{t_mul | t_div}} & mul_out) |
        ({32{t_insn}} & insn) | ({32{t_csrr}} & csr_rdata) | ({32{t_new}} & csr_new) |
        {31'd0, t_ex && is_sc && !sc_ok};
    wire writes_rd = is_lui | is_auipc | is_jal | is_jalr | is_load | is_opimm | is_op |
                     is_muldiv | is_csr | is_amo_any;
    wire [4:0] rd_eff = (writes_rd && rd != 5'd0) ? rd : 5'd0;
    wire [5:0] wb_addr = seq == S_CNT ? {3'b100, 1'b1, cnt_hi, cnt_ins} :
                         seq == S_TRAP ? W_MEPC : trap_in ? W_MTVAL :
                         t_new ? {3'b100, c_cnt, c_cnt ? {csr_addr[7], csr_addr[1]} :
                                                c_34x ? csr_addr[1:0] : 2'b10} :
                         {1'b0, rd_eff};
    wire wb_en = (commit_ex && rd_eff != 5'd0) || (in_ex2 && is_amo && rd_eff != 5'd0) ||
                 t_new || trap_in || seq[1];

    // ---------------------------------------------------------------- fetch stage
    // Port A reads rs1, or the counter word of a coming CNT cycle. Port B reads rs2, the CSR
    // word of a SYSTEM instruction (mepc for MRET/ECALL/EBREAK/WFI), or mtvec for TRAP.
    // The instruction word in `ir` as the memory holds it now: `ir_word` was read half a
    // cycle before this cycle began, so only a store that landed at this cycle's start edge
    // (`st_q`, with the last store in `st_*`) can have changed it. Each of its halfwords lies in word `pw` (at a word
    // boundary both do; otherwise the low one) or `pw + 1`.
    reg  [31:0] ir_word;
    reg         st_q;
    reg  [FETCH_AW-1:0] st_w;
    reg  [3:0]  st_m;
    reg  [31:0] st_d;
    wire        pc_mem = pc[31:20] == FETCH_REGION;
    wire [FETCH_AW-1:0] pw = pc[FETCH_AW+1:2];
    wire        hit0 = st_q && pc_mem && st_w == pw;
    wire        hit1 = st_q && pc_mem && st_w == pw + {{(FETCH_AW-1){1'b0}}, 1'b1};
    wire [3:0]  pm   = pc[1] ? {st_m[1:0] & {2{hit1}}, st_m[3:2] & {2{hit0}}} :
                               st_m & {4{hit0}};
    wire [31:0] pd   = pc[1] ? {st_d[15:0], st_d[31:16]} : st_d;
    wire [31:0] refetch = {pm[3] ? pd[31:24] : ir_word[31:24], pm[2] ? pd[23:16] : ir_word[23:16],
                           pm[1] ? pd[15:8] : ir_word[15:8], pm[0] ? pd[7:0] : ir_word[7:0]};
    wire [31:0] fr = !rst && hold ? refetch : imem_rdata;
    wire        st_now = !rst && dmem_wstrb != 4'd0 && dmem_addr[31:20] == FETCH_REGION;
    assign last_st_word = st_w;
    assign last_st_data = st_d;
    assign last_st_mask = st_m;
    // RV32C expansion (`rv_expand.v`); the immediate goes straight to `ir_imm`
    wire        fi_c;
    wire [31:0] fi, fi_imm, fi_raw;
    /* verilator lint_off PINCONNECTEMPTY */
    rv_expand expand (
        .fr(fr), .is_c(fi_c), .insn(fi), .imm(fi_imm), .raw(fi_raw),
        .c_jal(), .c_branch()
    );
    /* verilator lint_on PINCONNECTEMPTY */
    wire        f_sys = fi[6:0] == 7'b1110011;
    // (x0 for the immediate CSR forms, whose rs1 field is the immediate)
    wire [5:0]  port_a = to_cnt ? {3'b100, 1'b1, n_hi, n_ins} :
                                  {1'b0, fi[19:15] & ~{5{f_sys && fi[14]}}};
    wire [5:0]  port_b = trap_in ? W_MTVEC :
                         !f_sys ? {1'b0, fi[24:20]} :
                         fi[14:12] == 3'd0 ? W_MEPC :
                         {3'b100, fi[31], fi[31] ? {fi[27], fi[21]} :
                                          fi[26] ? fi[21:20] : 2'b10};
    always @(posedge clk) begin
        pc <= fetch_pc;
        ir <= fi;
        ir_c <= fi_c;
        ir_imm <= fi_imm;
        ir_raw <= fi_raw;
        ir_word <= fr;
        st_q <= st_now;
        if (st_now) begin
            st_w <= dmem_addr[FETCH_AW+1:2];
            st_m <= dmem_wstrb;
            st_d <= dmem_wdata;
        end
        rf_a <= regs[port_a];
        rf_b <= regs[port_b];
        byp_a <= !rst && ((wb_en && wb_addr == port_a) || amo_a);
        byp_b <= !rst && wb_en && wb_addr == port_b;
        byp_val <= wb_val;
        if (wb_en && !rst) regs[wb_addr] <= wb_val;
    end

    // ---------------------------------------------------------------- state update
    always @(posedge clk) begin
        rvfi_valid <= 1'b0;
        seq <= seq_n;
        cyc_pl <= cyc_pl_n;
        cyc_ph <= cyc_ph_n;
        ins_pl <= ins_pl_n;
        ins_ph <= ins_ph_n;
        if (to_cnt) begin
            cnt_ins <= n_ins;
            cnt_hi <= n_hi;
            if (seq != S_CNT) cnt_wfi <= ex && stall && is_wfi;
        end
        if (ex) seen_mip <= lines;
        if (rst) begin
            seq <= S_EXEC;
            cyc_pl <= 1'b0;
            cyc_ph <= 1'b0;
            ins_pl <= 1'b0;
            ins_ph <= 1'b0;
            ins_nohi <= 1'b0;
            cyc_lo <= {CNT_P{1'b0}};
            ins_lo <= {CNT_P{1'b0}};
            mstatus_mie <= 1'b0;
            mstatus_mpie <= 1'b0;
            mie_e <= 1'b0;
            mie_t <= 1'b0;
            mie_s <= 1'b0;
            mcause_int <= 1'b0;
            mcause_code <= 4'd0;
            res_valid <= 1'b0;
            res_addr <= 32'd0;
            intr_flag <= 1'b0;
            intr_mip <= 3'd0;
            md_busy <= 1'b0;
            md_cnt <= 6'd0;
            rvfi_order <= 64'd0;
        end else begin
            cyc_lo <= wr_cyc_lo ? csr_wdata[CNT_P-1:0] : cyc_lo + 1'b1;
            if (wr_ins_lo) ins_lo <= csr_wdata[CNT_P-1:0];
            else if (ins_inc) ins_lo <= ins_lo + 1'b1;
            if (ins_wrap) ins_nohi <= is_csr && a_ins_hi;

            if (trap_in) begin
                mcause_int <= irq_take;
                mcause_code <= irq_take ? irq_cause : exc_cause;
                mstatus_mpie <= mstatus_mie;
                mstatus_mie <= 1'b0;
                if (irq_take) begin
                    intr_flag <= 1'b1;
                    intr_mip <= lines;
                end
            end else if (ex && stall) begin
                if (is_iter) begin
                    if (!md_busy) begin
                        md_busy <= 1'b1;
                        md_cnt <= 6'd0;
                        md_quo <= abs_a;
                        md_rem_n <= 32'hffff_ffff;
                        md_div <= abs_b;
                    end else if (MUL_SEQ == 0 || is_div) begin
                        md_cnt <= md_cnt + 6'd1;
                        md_quo <= {md_quo[30:0], md_dif_n[32]};   // no borrow
                        md_rem_n <= md_dif_n[32] ? md_dif_n[31:0] : md_sh_n[31:0];
                    end else begin
                        md_cnt <= md_cnt + 6'd1;
                        md_quo <= {!mq_sum_n[0], md_quo[31:1]};
                        md_rem_n <= mq_sum_n[32:1];
                    end
                end
            end else if (amo_a) begin
                // the AMO's address is kept for EX2; a reservation does not survive an AMO
                res_valid <= 1'b0;
                res_addr <= ls_addr;
            end else if (csr_ex) begin
                if (csr_rf_w) csr_new <= csr_wval;
                if (wr_mstatus) begin
                    mstatus_mie <= csr_wdata[3];
                    mstatus_mpie <= csr_wdata[7];
                end
                if (wr_mie) begin
                    mie_e <= csr_wdata[11];
                    mie_t <= csr_wdata[7];
                    mie_s <= csr_wdata[3];
                end
                if (wr_mcause) begin  // WLRL: the interrupt bit and a 4-bit code
                    mcause_int <= csr_wdata[31];
                    mcause_code <= csr_wdata[3:0];
                end
            end else if (commit_ex) begin
                md_busy <= 1'b0;
                if (is_lr) begin
                    res_valid <= 1'b1;
                    res_addr <= ls_addr;
                end
                if (is_sc) res_valid <= 1'b0;
                if (is_mret) begin
                    mstatus_mie <= mstatus_mpie;
                    mstatus_mpie <= 1'b1;
                end
            end

            // retirement records: an instruction that completes, or the trap it raised
            if (retire || (seq == S_TRAP && !mcause_int)) begin
                intr_flag <= 1'b0;
                rvfi_valid <= 1'b1;
                rvfi_order <= rvfi_order + 64'd1;
                rvfi_insn <= ir_raw;
                rvfi_intr <= intr_flag;
                rvfi_ext_intr_mip <= intr_flag ? intr_mip : 3'd0;
                rvfi_ext_mip <= ex ? lines : seen_mip;
                rvfi_pc_rdata <= pc;
                rvfi_trap <= !retire;
                rvfi_pc_wdata <= retire ? next_pc : trap_pc;
                rvfi_rd_addr <= retire ? rd_eff : 5'd0;
                rvfi_rd_wdata <= retire && rd_eff != 5'd0 ? wb_val : 32'd0;
                rvfi_mem_addr <= retire && (mem_rd | mem_wr) ? dmem_addr : 32'd0;
                rvfi_mem_rmask <= retire ? dmem_rmask : 4'd0;
                rvfi_mem_wmask <= retire ? dmem_wstrb : 4'd0;
                rvfi_mem_rdata <= retire && mem_rd ? dmem_rdata : 32'd0;
                rvfi_mem_wdata <= retire && mem_wr ? dmem_wdata : 32'd0;
            end
        end
    end

endmodule

`default_nettype wire
