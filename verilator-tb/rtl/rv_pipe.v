// RV32IMAC + Zcb + Zicsr machine-mode core, pipelined: the FPGA core variant (`docs/fpga.md`).
//
// Four stages, one instruction each:
//   F  fetch: `f_pc` addresses the instruction memory (the SoC's RAM answers with the 32 bits
//      at any halfword address in the same cycle); the word is captured into D.
//   D  decode: a compressed instruction is expanded, the immediate and the instruction's
//      class decoded (X takes the flags registered, `xd`), and the register file (block RAM,
//      synchronous read) read at the clock edge that ends the stage; whether X will forward
//      M's result is decided here too (`fwd_a`, `fwd_b`).
//   X  execute: operands forwarded from M or from the word written at the edge that began the
//      cycle; ALU, branches and jumps (resolved here: the instructions fetched behind a taken
//      one are discarded; a JAL's target, and a backward branch's, were already fetched from
//      D, see `d_guess`), CSRs (all in flip-flops), traps and interrupts (taken here, between
//      instructions), the multiplier, the iterative divider (the pipeline waits), load and
//      store addresses.
//   M  memory and write-back: the data bus is driven from M's registers; the SoC's memories
//      read the word at the edge that begins the stage, from X's address (`dmem_next`), so
//      the word is there early in the cycle; a loaded word is aligned and written back at the
//      edge that ends the stage, with every other result; an atomic read-modify-write takes
//      two cycles here (the second uses the word the first loaded). Every instruction retires
//      in M, in order, with its RVFI record (registered: valid in the cycle after).
// An instruction in X that reads the word an instruction in M loads waits one cycle. A store
// into an instruction already fetched (F, D or X) discards those and fetches them again, so a
// program sees its own stores as the golden model does. The interrupt lines are registered
// at the input (an interrupt is seen one cycle later); the CSRs, mcycle and minstret are
// flip-flops (`rv_core` keeps the wide ones in its register file's block RAM).
//
// Same ports as `rv_core` and one more, `dmem_next`: the SoC's data memories read at the
// rising edge from it (`rv_core`'s read on the falling edge from `dmem_addr`; the fetch port
// reads on the falling edge for both). Its cycles differ from the cycle-accurate model's, its
// retirements do not.
`default_nettype none

module rv_pipe #(
    parameter [31:0] RESET_PC = 32'h8000_0000,
    parameter [11:0] FETCH_REGION = 12'h800,
    parameter integer FETCH_AW = 18,
    // 0: MUL* in one cycle on a 32x32 multiplier; 1: in the divider's loop (11 cycles, 7 when
    // rs1 has at most 16 significant bits)
    parameter integer MUL_SEQ = 0,
    // conditional branches guessed in D from a table of 2^BHT_AW two-bit counters indexed by
    // the pc's halfword (one block RAM at 11); 0: backward ones taken, forward ones not
    parameter integer BHT_AW = 11
) (
    input  wire        clk,
    input  wire        rst,

    output wire [31:0] imem_addr,
    input  wire [31:0] imem_rdata,

    output wire [31:0] dmem_addr,
    output wire [31:0] dmem_next,     // the word the data port accesses in the next cycle
    output wire        dmem_re,
    output wire [3:0]  dmem_rmask,
    output wire [3:0]  dmem_wstrb,
    output wire [31:0] dmem_wdata,
    input  wire [31:0] dmem_rdata,
    output wire        dmem_rd_pre,
    output wire [FETCH_AW-1:0] last_st_word,
    output wire [31:0] last_st_data,
    output wire [3:0]  last_st_mask,

    input  wire        irq_software,
    input  wire        irq_timer,
    input  wire        irq_external,
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
    output reg  [2:0]  rvfi_ext_mip,
    output reg  [2:0]  rvfi_ext_intr_mip
);

    // ================================================================ state
    reg [31:0] regs [0:31];
    integer k;
    initial for (k = 0; k < 32; k = k + 1) regs[k] = 32'd0;

    // F
    reg [31:0] f_pc;
    // D
    reg        d_valid;
    reg [31:0] d_pc;
    reg [31:0] d_word;
    reg [1:0]  d_bht;     // the counter of D's pc, read as the word was fetched
    // X
    reg        x_valid;
    reg [31:0] x_pc;
    reg [31:0] x_ir;      // expanded
    reg        x_c;       // compressed (2 bytes)
    reg [31:0] x_imm;
    reg [31:0] x_raw;     // as fetched, for RVFI
    reg        x_jd;      // the fetch already went to the target from D (JAL, branch guessed)
    reg [1:0]  x_bht;     // the branch's counter as read for its guess
    reg [31:0] rf_a, rf_b;
    reg        byp_a, byp_b;
    reg [31:0] byp_val;
    // M
    reg        m_valid;
    reg        m_trap;    // a trap record only
    reg        m_intr;
    reg [2:0]  m_mip, m_intr_mip;
    reg [31:0] m_raw, m_pc, m_next;
    reg [4:0]  m_rd;      // 0: no write
    reg        m_load;    // rd gets the loaded word (loads, LR, AMOs)
    reg [2:0]  m_f3;
    reg [4:0]  m_f5;
    reg        m_amo, m_amo2;
    reg [31:0] m_result;  // rd for the others; the AMO's rs2
    reg [31:0] m_addr;
    reg        m_fetch;   // m_addr is in the fetch memory's region
    reg        m_rd_mem;  // reads memory (dmem_re)
    reg [3:0]  m_rmask, m_wstrb;
    reg [31:0] m_wdata;
    reg [31:0] m_loaded;  // an AMO's loaded word, from its first cycle
    reg        m_cnt_wr;  // writes a counter CSR at retirement
    reg [1:0]  m_cnt_sel; // {instret, high}
    reg [31:0] m_cnt_val;
    // CSRs
    reg        mstatus_mie, mstatus_mpie;
    reg        mie_e, mie_t, mie_s;
    reg        mcause_int;
    reg [3:0]  mcause_code;
    reg [31:0] mscratch, mepc, mtvec, mtval;
    reg [63:0] mcycle, minstret;
    reg        res_valid;
    reg [31:0] res_addr;
    reg        intr_pend;  // the next record is an interrupt handler's first instruction
    reg        t_int;      // the trap of the cycle before (written at `trap_q`)
    reg [3:0]  t_code;
    reg [31:0] t_pc, t_tval;
    reg [2:0]  intr_lines;
    // divider (and the sequential multiplier)
    reg        md_busy;
    reg [5:0]  md_cnt;
    reg [31:0] md_quo, md_rem, md_div;
    reg [33:0] md_div3;    // 3 x md_div (MUL_SEQ: the product takes four bits a cycle)
    reg        md_sq;      // the result's sign fix-up (negate), from the operands at the start
    // branch history: per halfword address a two-bit counter of how often the branch went
    // against the static guess (backward taken, forward not); guessed against it from 2 on.
    // Read as an instruction is fetched, updated a cycle after its branch leaves X. A counter
    // only steers a guess that X checks, so a read of the entry being written (the block
    // RAM's collision) can only cost a cycle, never change what the program does.
    localparam integer BHT_N = BHT_AW > 0 ? 1 << BHT_AW : 1;
    reg [1:0]  bht [0:BHT_N-1];
    initial for (k = 0; k < BHT_N; k = k + 1) bht[k] = 2'd0;
    reg        u_we;
    reg [BHT_AW > 0 ? BHT_AW - 1 : 0:0] u_idx;
    reg [1:0]  u_val;
    // the last store into the fetch memory (for RAMs with a write buffer)
    reg [FETCH_AW-1:0] st_w;
    reg [3:0]  st_m;
    reg [31:0] st_d;

    // ================================================================ D: expansion, decode
    wire [31:0] fr = d_word;
    wire [15:0] c = fr[15:0];
    wire        fi_c, f_j, f_b;
    wire [31:0] fi, fi_imm, fi_raw;
    rv_expand expand (
        .fr(fr), .is_c(fi_c), .insn(fi), .imm(fi_imm), .raw(fi_raw),
        .c_jal(f_j), .c_branch(f_b)
    );

    // ================================================================ D: decode
    // The instruction entering X is decoded here, and X takes the flags with it (`xd`): X's
    // cycle starts from registers, not from the instruction's bits.
    wire [6:0]  dop = fi[6:0];
    wire [2:0]  df3 = fi[14:12];
    wire [6:0]  df7 = fi[31:25];
    wire [4:0]  df5 = fi[31:27];
    wire d_lui     = dop == 7'b0110111;
    wire d_auipc   = dop == 7'b0010111;
    wire d_jal     = dop == 7'b1101111;
    wire d_jalr    = dop == 7'b1100111 && df3 == 3'd0;
    wire d_branch  = dop == 7'b1100011 && df3[2:1] != 2'b01;
    wire d_load    = dop == 7'b0000011 && df3 != 3'd3 && df3[2:1] != 2'b11;
    wire d_store   = dop == 7'b0100011 && df3[2] == 1'b0 && df3 != 3'd3;
    wire d_opimm   = dop == 7'b0010011 &&
                     (df3 == 3'd1 ? df7 == 7'd0 :
                      df3 == 3'd5 ? (df7 == 7'd0 || df7 == 7'h20) : 1'b1);
    wire d_op      = dop == 7'b0110011 &&
                     (df7 == 7'd0 || (df7 == 7'h20 && (df3 == 3'd0 || df3 == 3'd5)));
    wire d_muldiv  = dop == 7'b0110011 && df7 == 7'd1;
    wire d_fence   = dop == 7'b0001111 && df3 == 3'd0;
    wire d_ecall   = fi == 32'h0000_0073;
    wire d_ebreak  = fi == 32'h0010_0073;
    wire d_mret    = fi == 32'h3020_0073;
    wire d_wfi     = fi == 32'h1050_0073;
    wire d_csr     = dop == 7'b1110011 && df3 != 3'd0 && df3 != 3'd4;
    wire d_amo_ok  = df5 == 5'b00010 ? fi[24:20] == 5'd0 :
                     (df5 == 5'b00011 || df5 == 5'b00001 || df5 == 5'b00000 ||
                      df5 == 5'b00100 || df5 == 5'b01100 || df5 == 5'b01000 ||
                      df5 == 5'b10000 || df5 == 5'b10100 || df5 == 5'b11000 ||
                      df5 == 5'b11100);
    wire d_amo_any = dop == 7'b0101111 && df3 == 3'd2 && d_amo_ok;
    wire d_lr      = d_amo_any && df5 == 5'b00010;
    wire d_sc      = d_amo_any && df5 == 5'b00011;
    wire d_amo     = d_amo_any && !d_lr && !d_sc;
    wire d_div     = d_muldiv && df3[2];
    wire d_iter    = d_muldiv && (df3[2] || MUL_SEQ != 0);
    wire d_legal   = d_lui | d_auipc | d_jal | d_jalr | d_branch | d_load | d_store | d_opimm |
                     d_op | d_muldiv | d_fence | d_ecall | d_ebreak | d_mret | d_wfi | d_csr |
                     d_amo_any;
    // the CSRs that exist (X reads them: `csr_rdata`)
    wire [11:0] d_csr_addr = fi[31:20];
    reg         d_csr_exists;
    always @(*) begin
        case (d_csr_addr)
            12'h300, 12'h301, 12'h304, 12'h305, 12'h310, 12'h340, 12'h341, 12'h342, 12'h343,
            12'h344, 12'hb00, 12'hc00, 12'hb80, 12'hc80, 12'hb02, 12'hc02, 12'hb82, 12'hc82,
            12'hf11, 12'hf12, 12'hf13, 12'hf14, 12'hf15: d_csr_exists = 1'b1;
            default: d_csr_exists = 1'b0;
        endcase
    end
    wire d_csr_writes = df3[1:0] == 2'b01 || fi[19:15] != 5'd0;
    wire d_illegal = !d_legal || fi[1:0] != 2'b11 ||
                     (d_csr && (!d_csr_exists || (d_csr_addr[11:10] == 2'b11 && d_csr_writes)));
    wire d_shift   = (d_opimm | d_op) && df3[1:0] == 2'b01;
    wire d_writes_rd = d_lui | d_auipc | d_jal | d_jalr | d_load | d_opimm | d_op | d_muldiv |
                       d_csr | d_amo_any;
    wire d_csr_cnt = d_csr_addr[11] && d_csr_addr[10:8] != 3'b111;  // mcycle(h), minstret(h)
    reg  [25:0] xd;
    wire [25:0] d_dec = {d_csr_cnt, d_csr_writes, d_writes_rd, d_shift, d_illegal, d_iter, d_div,
                        d_amo, d_sc, d_lr, d_amo_any, d_csr, d_wfi, d_mret, d_ebreak, d_ecall,
                        d_muldiv, d_op, d_opimm, d_store, d_load, d_branch, d_jalr, d_jal,
                        d_auipc, d_lui};

    // ================================================================ X: decode (registered)
    wire [31:0] insn   = x_ir;
    wire [6:0]  opcode = insn[6:0];
    wire [4:0]  rd     = insn[11:7];
    wire [4:0]  rs1    = insn[19:15];
    wire [4:0]  rs2    = insn[24:20];
    wire [2:0]  f3     = insn[14:12];
    wire [6:0]  f7     = insn[31:25];
    wire [4:0]  f5     = insn[31:27];
    wire is_lui     = xd[0];
    wire is_auipc   = xd[1];
    wire is_jal     = xd[2];
    wire is_jalr    = xd[3];
    wire is_branch  = xd[4];
    wire is_load    = xd[5];
    wire is_store   = xd[6];
    wire is_opimm   = xd[7];
    wire is_op      = xd[8];
    wire is_muldiv  = xd[9];
    wire is_ecall   = xd[10];
    wire is_ebreak  = xd[11];
    wire is_mret    = xd[12];
    wire is_wfi     = xd[13];
    wire is_csr     = xd[14];
    wire is_amo_any = xd[15];
    wire is_lr      = xd[16];
    wire is_sc      = xd[17];
    wire is_amo     = xd[18];
    wire is_div     = xd[19];
    wire is_iter    = xd[20];
    wire x_illegal  = xd[21];
    wire is_shift   = xd[22];
    wire writes_rd  = xd[23];
    wire csr_writes = xd[24];
    wire csr_cnt    = xd[25];

    // ================================================================ X: operands
    // the instruction in M writes rd at the end of this cycle: forwarded (a loaded word is
    // not there yet: the instruction waits). Whether M's rd is rs1 or rs2 was worked out at
    // the edge that began the cycle (`fwd_a`, `fwd_b`, below).
    reg  fwd_a, fwd_b;
    wire [31:0] rs1v = fwd_a ? m_result : byp_a ? byp_val : rf_a;
    wire [31:0] rs2v = fwd_b ? m_result : byp_b ? byp_val : rf_b;
    wire load_use = (fwd_a || fwd_b) && m_load;

    // ================================================================ X: ALU
    wire op_u = !opcode[6] && opcode[4] && opcode[2];
    wire op_j = opcode[6] && opcode[3];
    wire op_b = opcode[6] && !opcode[4] && !opcode[2];
    wire op_s = !opcode[6] && opcode[5] && !opcode[4];
    wire op_r = opcode == 7'b0110011;
    wire op_amo = op_s && opcode[2];
    wire [31:0] imm = x_imm;
    wire        ex_pc  = (op_u && !opcode[5]) || op_j || op_b;
    wire        do_sub = op_r && f7[5];
    wire [31:0] add_a  = ex_pc ? x_pc : (op_u && opcode[5]) ? 32'd0 : rs1v;
    wire [31:0] alu_b  = op_r ? rs2v : imm;
    wire [31:0] add_b  = (op_amo ? 32'd0 : alu_b) ^ {32{do_sub}};
    wire [31:0] sum    = add_a + add_b + {31'd0, do_sub};

    // SLT(I)(U) on rs1 and the ALU's second operand; branches on a comparator of their own,
    // with no operand choice in front of it (their outcome ends X's longest paths)
    wire        cmp_signed = !f3[0];
    wire [32:0] cmp_diff   = {cmp_signed & rs1v[31], rs1v} - {cmp_signed & alu_b[31], alu_b};
    wire        lt         = cmp_diff[32];
    wire        br_signed  = !f3[1];
    wire [32:0] br_diff    = {br_signed & rs1v[31], rs1v} - {br_signed & rs2v[31], rs2v};
    wire        br_lt      = br_diff[32];
    wire        br_eq      = rs1v == rs2v;
    wire        br_taken   = f3[2] ? br_lt ^ f3[0] : br_eq ^ f3[0];
    wire [4:0]  shamt      = alu_b[4:0];
    reg  [31:0] logic_out;
    always @(*) begin
        case (f3)
            3'd4: logic_out = rs1v ^ alu_b;
            3'd6: logic_out = rs1v | alu_b;
            3'd7: logic_out = rs1v & alu_b;
            default: logic_out = {31'd0, lt};
        endcase
    end

    // multiply, divide, shifts (as rv_core: the shifts on the multiplier unless MUL_SEQ)
    wire        sh_zero  = shamt == 5'd0;
    wire        sign_a   = is_muldiv ? (f3[2] ? !f3[0] : f3[1] ^ f3[0]) :
                           is_shift && f3[2] && f7[5] && !sh_zero;
    wire        sign_b   = is_muldiv && (f3[2] ? !f3[0] : f3[1:0] == 2'd1);
    wire        neg_a    = sign_a && rs1v[31];
    wire        neg_b    = sign_b && rs2v[31];
    wire [31:0] abs_a    = (rs1v ^ {32{neg_a}}) + {31'd0, neg_a};
    wire [31:0] abs_b    = (rs2v ^ {32{neg_b}}) + {31'd0, neg_b};
    wire [4:0]  sh_pow   = f3[2] ? 5'd0 - shamt : shamt;
    wire [31:0] mul_b    = is_shift ? 32'd1 << sh_pow : abs_b;
    wire [63:0] prod_1c  = {32'd0, abs_a} * {32'd0, mul_b};
    wire [63:0] prod_u   = MUL_SEQ != 0 ? {md_rem, md_quo} : prod_1c;
    wire        prod_neg = neg_a ^ neg_b;
    wire        lo_zero  = prod_u[31:0] == 32'd0;
    wire        use_lo   = is_shift ? !f3[2] || sh_zero : f3[1:0] == 2'd0;
    wire [32:0] md_sh  = {md_rem, md_quo[31]};
    wire [32:0] md_dif = md_sh - {1'b0, md_div};
    // MUL_SEQ: four multiplier bits a cycle, as two digits of 0..3 times the multiplicand
    // (3 x in md_div3, worked out in the product's first cycle, when md_cnt is 60)
    wire [33:0] mq_d0  = md_quo[1:0] == 2'd0 ? 34'd0 : md_quo[1:0] == 2'd1 ? {2'd0, md_div} :
                         md_quo[1:0] == 2'd2 ? {1'd0, md_div, 1'd0} : md_div3;
    wire [33:0] mq_d1  = md_quo[3:2] == 2'd0 ? 34'd0 : md_quo[3:2] == 2'd1 ? {2'd0, md_div} :
                         md_quo[3:2] == 2'd2 ? {1'd0, md_div, 1'd0} : md_div3;
    wire [35:0] mq_sum = {4'd0, md_rem} + {2'd0, mq_d0} + {mq_d1, 2'd0};
    wire        mq_prep = md_cnt[5:4] == 2'b11;
    // after the fourth digit, nothing left of the multiplier (its high half is zero): the
    // last four steps would only shift, so they are taken at once (7 cycles a product)
    wire        mq_early = md_cnt == 6'd12 && md_quo[19:4] == 16'd0;
    // one right shifter: a left shift is the right shift of the reversed word, reversed
    function automatic [31:0] rev32(input [31:0] v);
        integer i;
        for (i = 0; i < 32; i = i + 1) rev32[i] = v[31 - i];
    endfunction
    wire [31:0] sh_in  = f3[2] ? rs1v : rev32(rs1v);
    wire [31:0] sh_r   = $unsigned($signed({f3[2] && f7[5] && rs1v[31], sh_in}) >>> shamt);
    wire [31:0] sh_out = f3[2] ? sh_r : rev32(sh_r);
    wire        md_done = md_busy && md_cnt == 6'd32;
    wire [31:0] md_res = f3[1] ? md_rem : md_quo;
    wire        md_neg = f3[1] ? neg_a : (neg_a ^ neg_b) && rs2v != 32'd0;
    wire [31:0] ng_in  = is_div ? md_res : prod_u[63:32];
    // an iterative result's sign fix-up as latched at its start (md_sq), off the operands'
    // forwarding; a one-cycle product's from the operands (with MUL_SEQ every product is
    // iterative: the operands' signs then reach no result but through md_sq)
    wire        ng     = MUL_SEQ != 0 || is_iter ? md_sq : prod_neg;
    wire [31:0] ng_out = (ng_in ^ {32{ng}}) + {31'd0, ng && (is_div || lo_zero)};
    wire [31:0] mul_out = MUL_SEQ != 0 && is_shift ? sh_out :
                          use_lo && !is_div ? prod_u[31:0] : ng_out;

    // memory access (address and checks in X)
    wire [31:0] ls_addr = sum;
    // the alignment from the address's two low bits, summed apart from the adder (it decides
    // whether the access traps, which the whole pipeline waits on)
    wire [1:0]  ls_low = rs1v[1:0] + (is_amo_any ? 2'd0 : x_imm[1:0]);
    wire        ls_misaligned = is_amo_any ? ls_low != 2'd0 :
                                f3[1:0] == 2'd1 ? ls_low[0] :
                                f3[1:0] == 2'd2 ? ls_low != 2'd0 : 1'b0;
    wire [3:0]  st_mask = f3[1:0] == 2'd0 ? (4'b0001 << ls_low) :
                          f3[1:0] == 2'd1 ? (4'b0011 << ls_low) : 4'b1111;
    wire [31:0] st_data = f3[1:0] == 2'd0 ? {4{rs2v[7:0]}} :
                          f3[1:0] == 2'd1 ? {2{rs2v[15:0]}} : rs2v;
    // SC's address is rs1 (an AMO adds nothing): compared without the adder
    wire        sc_ok = res_valid && res_addr == rs1v;

    // ================================================================ X: CSRs
    wire [11:0] csr_addr = insn[31:20];
    // The interrupt lines, registered: the devices' logic behind them stays out of the
    // execute stage's cycle (an interrupt is seen one cycle later).
    reg  [2:0]  lines;
    always @(posedge clk) lines <= {irq_external, irq_timer, irq_software};
    wire [31:0] mip_v    = {20'd0, lines[2], 3'd0, lines[1], 3'd0, lines[0], 3'd0};
    wire [31:0] mie_v    = {20'd0, mie_e, 3'd0, mie_t, 3'd0, mie_s, 3'd0};
    // minstret as an instruction here sees it: the one in M retires before it
    wire        m_counts = m_valid && !m_trap && !(m_amo && !m_amo2);
    wire [63:0] instret_now = minstret + {63'd0, m_counts};
    reg  [31:0] csr_rdata;
    always @(*) begin
        case (csr_addr)
            12'h300: csr_rdata = {19'd0, 2'b11, 3'd0, mstatus_mpie, 3'd0, mstatus_mie, 3'd0};
            12'h301: csr_rdata = 32'h4000_1105;
            12'h304: csr_rdata = mie_v;
            12'h305: csr_rdata = mtvec;
            12'h310: csr_rdata = 32'd0;
            12'h340: csr_rdata = mscratch;
            12'h341: csr_rdata = mepc;
            12'h342: csr_rdata = {mcause_int, 27'd0, mcause_code};
            12'h343: csr_rdata = mtval;
            12'h344: csr_rdata = mip_v;
            12'hb00, 12'hc00: csr_rdata = mcycle[31:0];
            12'hb80, 12'hc80: csr_rdata = mcycle[63:32];
            12'hb02, 12'hc02: csr_rdata = instret_now[31:0];
            12'hb82, 12'hc82: csr_rdata = instret_now[63:32];
            12'hf11, 12'hf12, 12'hf13, 12'hf14, 12'hf15: csr_rdata = 32'd0;
            default: csr_rdata = 32'd0;
        endcase
    end
    wire [31:0] csr_src    = f3[2] ? {27'd0, rs1} : rs1v;   // CSRR*I: the immediate
    wire        c_rw       = f3[1:0] == 2'b01, c_rc = f3[1:0] == 2'b11;
    wire [31:0] csr_wdata  = (csr_rdata & ~({32{c_rw}} | ({32{c_rc}} & csr_src))) |
                             (csr_src & ~{32{c_rc}});

    // ================================================================ X: control
    wire [31:0] pc_plus = x_pc + {29'd0, !x_c, x_c, 1'b0};
    wire jump_nb = is_jal | is_jalr;
    // the next pc if a conditional branch here is taken, and if not (`next_pc` picks)
    wire [31:0] next_t = (jump_nb | is_branch) ? {sum[31:1], 1'b0} : is_mret ? mepc : pc_plus;
    wire [31:0] next_n = jump_nb ? {sum[31:1], 1'b0} : is_mret ? mepc : pc_plus;
    wire [31:0] next_pc = br_taken ? next_t : next_n;

    wire exc_illegal = x_illegal;
    // (not while the address waits for a loaded word: the forwarded operand is not it yet)
    wire exc_load    = !exc_illegal && (is_load || is_lr) && ls_misaligned && !load_use;
    wire exc_store   = !exc_illegal && (is_store || is_sc || is_amo) && ls_misaligned &&
                       !load_use;
    wire exc_misal   = exc_load | exc_store;
    // the exceptions known from the instruction alone (registered), and the misaligned access
    wire exc_fixed = exc_illegal | is_ecall | is_ebreak;
    wire exc = exc_fixed | exc_misal;
    wire [3:0] exc_cause = exc_illegal ? 4'd2 : exc_load ? 4'd4 :
                           exc_store ? 4'd6 : is_ebreak ? 4'd3 : 4'd11;
    wire [31:0] exc_tval = exc_illegal ? insn : exc_misal ? ls_addr : 32'd0;

    wire [2:0]  irq_pend  = lines & {mie_e, mie_t, mie_s};
    wire [3:0]  irq_cause = irq_pend[2] ? 4'd11 : irq_pend[0] ? 4'd3 : 4'd7;

    // A store landing at the end of this cycle into an instruction already fetched: those
    // are fetched again (X, D and F discarded, F restarts at the oldest).
    wire        st_now  = m_valid && m_wstrb != 4'd0 && m_fetch;
    wire [FETCH_AW-1:0] st_word = m_addr[FETCH_AW+1:2];
    // (an instruction at a halfword address may end in the next word: the word before the
    // store's counts too)
    wire [FETCH_AW-1:0] st_prev = st_word - {{(FETCH_AW-1){1'b0}}, 1'b1};
    function automatic hits(input [31:0] pc);
        hits = pc[31:20] == FETCH_REGION &&
               (pc[FETCH_AW+1:2] == st_word || pc[FETCH_AW+1:2] == st_prev);
    endfunction
    wire        smc = st_now && ((x_valid && hits(x_pc)) || (d_valid && hits(d_pc)) ||
                                 hits(f_pc));
    wire [31:0] smc_pc = x_valid ? x_pc : d_valid ? d_pc : f_pc;

    // M accepts an instruction at the end of this cycle unless an AMO is in its first half
    // (then M holds it)
    wire m_holds = m_valid && m_amo && !m_amo2;
    wire m_free = !m_holds;
    // a counter CSR write retires in M: a CSR access waits for it
    wire csr_wait = is_csr && m_valid && m_cnt_wr;

    wire x_live    = x_valid && !smc && !rst;
    wire irq_take  = x_live && mstatus_mie && irq_pend != 3'd0 && !md_busy && !is_wfi;
    wire x_exc     = x_live && !irq_take && exc;
    // the instruction can complete this cycle
    wire iter_wait = is_iter && !md_done;
    wire wfi_wait  = is_wfi && irq_pend == 3'd0;
    wire x_stall   = load_use || !m_free || iter_wait || wfi_wait || csr_wait;
    wire x_ok      = x_live && !irq_take && !x_stall;  // completes unless it traps
    wire x_commit  = x_ok && !exc;
    // ... for instructions that are not memory accesses (no misaligned exception)
    wire x_done    = x_ok && !exc_fixed;
    wire x_trap    = irq_take || (x_exc && m_free);   // an exception's record needs M
    wire [31:0] trap_vec = {mtvec[31:6],
                            mtvec[5:2] | (irq_take && mtvec[0] ? irq_cause : 4'd0), 2'b00};
    // The fetch follows X in the cycle X resolves control flow: a jump the fetch did not take
    // from D, a backward branch it took that is not taken, an MRET (never an exception); a
    // store into a fetched instruction. A trap discards D and X at once but sends the fetch
    // to its handler in the next cycle (`trap_q`), and its CSRs are written then: so whether
    // an access is misaligned does not steer the fetch address or wide registers' enables.
    reg         trap_q;
    reg  [31:0] trap_pc_q;
    // Both outcomes of a conditional branch are worked out (`_t`: taken, `_n`: not) and the
    // comparison picks last, so its carry chain ends one selection before the fetch address.
    wire rf_t = smc || trap_q || (x_done && (((jump_nb | is_branch) ^ x_jd) || is_mret));
    wire rf_n = smc || trap_q || (x_done && ((jump_nb ^ x_jd) || is_mret));
    wire redirect_f = br_taken ? rf_t : rf_n;
    wire redirect = redirect_f || x_trap;

    // X result (everything but loaded words)
    wire t_sum   = is_lui || is_auipc || ((is_opimm || is_op) && f3 == 3'd0);
    wire t_link  = is_jal || is_jalr;
    wire t_logic = (is_opimm || is_op) && f3 != 3'd0 && f3[1:0] != 2'b01;
    wire t_mul   = (is_muldiv && !f3[2]) || is_shift;
    // M's result: the adder's sum (the last to arrive) ORed into the rest, an AMO's rs2
    // among the rest (its result comes from memory), so the sum is one selection from M
    (* keep *) wire [31:0] x_other = is_amo ? rs2v :
        ({32{t_link}} & pc_plus) | ({32{t_logic}} & logic_out) |
        ({32{t_mul | is_div}} & mul_out) | ({32{is_csr}} & csr_rdata) |
        {31'd0, is_sc && !sc_ok};
    wire [31:0] x_result = ({32{t_sum}} & sum) | x_other;
    wire [4:0] rd_eff = writes_rd ? rd : 5'd0;
    wire x_mem_rd = is_load | is_lr | is_amo;
    wire x_mem_wr = is_store | is_amo | (is_sc && sc_ok);

    // CSR writes (at commit). WARL as rv_core: mepc bit 0 reads zero; mtvec bit 1 reads zero,
    // and a vectored table is 64-byte aligned.
    wire wr_csr = x_done && is_csr && csr_writes;
    wire [31:0] csr_wval = {csr_wdata[31:6],
                            csr_wdata[5:2] & ~{4{csr_addr == 12'h305 && csr_wdata[0]}},
                            csr_wdata[1] & !(csr_addr == 12'h305),
                            csr_wdata[0] & !(csr_addr == 12'h341)};

    // ================================================================ D and F
    // X takes D's instruction when X is empty or its instruction leaves
    // (x_commit || x_trap, but without the misaligned check: an access that traps leaves
    // when M is free, as one that completes)
    wire x_leaves = !x_valid || smc ||
                    (x_live && (irq_take || (exc_fixed ? m_free : !x_stall)));
    wire d_to_x   = d_valid && x_leaves && !redirect;
    wire d_open   = !d_valid || x_leaves;     // D may take F's word (unless redirected)
    // JAL, C.J and C.JAL, and conditional branches guessed taken (backwards ones, loops,
    // unless their counter says otherwise; forward ones when it does), send the fetch to
    // their target as they leave D, from the fetched bits (not the expansion) so the sum
    // starts early: the word fetched behind them is discarded, one cycle instead of the two
    // of a jump resolved in X. X redirects a guessed branch that is not taken to the
    // instruction after it (two cycles).
    wire        d_is_jal = fi_c ? f_j : fr[6:0] == 7'b1101111;
    wire        d_is_br  = fi_c ? f_b : fr[6:0] == 7'b1100011;
    wire        d_back   = fi_c ? c[12] : fr[31];   // the offset's sign
    wire [31:0] d_jimm = fi_c ?
        (f_b ? {{24{c[12]}}, c[6:5], c[2], c[11:10], c[4:3], 1'b0} :
               {{21{c[12]}}, c[8], c[10:9], c[6], c[7], c[2], c[11], c[5:3], 1'b0}) :
        (fr[3] ? {{11{fr[31]}}, fr[31], fr[19:12], fr[20], fr[30:21], 1'b0} :
                 {{19{fr[31]}}, fr[31], fr[7], fr[30:25], fr[11:8], 1'b0});
    wire [31:0] d_target = d_pc + d_jimm;
    wire        d_guess  = d_is_jal || (d_is_br && (d_back ^ (BHT_AW > 0 && d_bht[1])));
    // the fetch's next address for each outcome in X (a trap's redirect comes a cycle later)
    wire        go_t = d_valid && x_leaves && !rf_t, go_n = d_valid && x_leaves && !rf_n;
    wire [31:0] rpc_t = trap_q ? trap_pc_q : smc ? smc_pc : next_t;
    wire [31:0] rpc_n = trap_q ? trap_pc_q : smc ? smc_pc : next_n;
    // the next fetch address: both sums from the register, the fetched word picks one
    wire [31:0] f_pc2 = f_pc + 32'd2, f_pc4 = f_pc + 32'd4;
    wire [31:0] f_next = imem_rdata[1:0] == 2'b11 ? f_pc4 : f_pc2;
    assign imem_addr = f_pc;
    // f_pc's next value: f_next (chosen by the fetched word, which comes half a cycle late:
    // last) or another (chosen by the branch's outcome, which comes late too)
    wire        sel_t = !rf_t && !(go_t && d_guess) && (!d_valid || go_t);
    wire        sel_n = !rf_n && !(go_n && d_guess) && (!d_valid || go_n);
    wire [31:0] oth_t = rf_t ? rpc_t : (go_t && d_guess) ? d_target : f_pc;
    wire [31:0] oth_n = rf_n ? rpc_n : (go_n && d_guess) ? d_target : f_pc;
    wire        f_sel = br_taken ? sel_t : sel_n;
    wire [31:0] f_oth = br_taken ? oth_t : oth_n;

    // register-file read ports: the instruction entering X, or X's again while it stays
    wire       x_stays = x_valid && !x_leaves;
    wire [4:0] port_a = x_stays ? rs1 : fi[19:15];
    wire [4:0] port_b = x_stays ? rs2 : fi[24:20];
    // the register M writes in the next cycle: its AMO's again, or X's instruction's
    wire [4:0] m_rd_next = m_holds ? m_rd : x_commit ? rd_eff : 5'd0;

    // ================================================================ M
    // the word read at the edge that began the stage (an AMO's second cycle: the first's)
    wire [31:0] m_rdata = m_amo2 ? m_loaded : dmem_rdata;
    wire [4:0]  ld_shift = {m_addr[1:0], 3'd0};
    wire [31:0] ld_shifted = m_rdata >> ld_shift;
    reg  [31:0] load_out;
    always @(*) begin
        case (m_f3)
            3'd0: load_out = {{24{ld_shifted[7]}}, ld_shifted[7:0]};
            3'd1: load_out = {{16{ld_shifted[15]}}, ld_shifted[15:0]};
            3'd4: load_out = {24'd0, ld_shifted[7:0]};
            3'd5: load_out = {16'd0, ld_shifted[15:0]};
            default: load_out = m_rdata;
        endcase
    end
    // the AMO's new word, from the word loaded in its first cycle and rs2
    wire        amo_signed = !m_f5[3];
    wire [32:0] amo_diff = {amo_signed & m_loaded[31], m_loaded} -
                           {amo_signed & m_result[31], m_result};
    wire        amo_lt = amo_diff[32];
    wire [31:0] amo_out = m_f5[4] ? ((amo_lt ^ m_f5[2]) ? m_loaded : m_result) :
                          m_f5[3:2] == 2'b01 ? m_loaded ^ m_result :
                          m_f5[3:2] == 2'b10 ? m_loaded | m_result :
                          m_f5[3:2] == 2'b11 ? m_loaded & m_result :
                          m_f5[0] ? m_result : m_loaded + m_result;

    wire m_act   = m_valid && !m_trap && !rst;
    wire m_done  = m_valid && !m_holds;   // retires at the end of this cycle
    assign dmem_addr   = {m_addr[31:2], 2'b00};
    assign dmem_next   = {ls_addr[31:2], 2'b00};
    assign dmem_re     = m_act && m_rd_mem && !(m_amo && m_amo2);
    assign dmem_rd_pre = m_valid && m_rd_mem && !(m_amo && m_amo2);
    assign dmem_rmask  = m_act ? m_rmask : 4'd0;
    assign dmem_wstrb  = m_act && (!m_amo || m_amo2) ? m_wstrb : 4'd0;
    assign dmem_wdata  = m_amo ? amo_out : m_wdata;
    assign last_st_word = st_w;
    assign last_st_data = st_d;
    assign last_st_mask = st_m;

    wire        wb_en   = m_act && m_done && m_rd != 5'd0;
    wire [31:0] wb_val  = m_load ? load_out : m_result;
    assign sleeping = !rst && x_valid && is_wfi && irq_pend == 3'd0;

    // ================================================================ clocked
    always @(posedge clk) begin
        // register file (write at the end of M; reads for the instruction entering X)
        if (wb_en) regs[m_rd] <= wb_val;
        rf_a <= regs[port_a];
        rf_b <= regs[port_b];
        byp_a <= wb_en && m_rd == port_a;
        byp_b <= wb_en && m_rd == port_b;
        fwd_a <= !rst && m_rd_next != 5'd0 && m_rd_next == port_a;
        fwd_b <= !rst && m_rd_next != 5'd0 && m_rd_next == port_b;
        byp_val <= wb_val;
    end

    always @(posedge clk) begin
        if (BHT_AW > 0) begin
            if (u_we) bht[u_idx] <= u_val;
            if (d_open) d_bht <= bht[f_pc[BHT_AW > 0 ? BHT_AW : 1:1]];
        end
    end

    always @(posedge clk) begin
        rvfi_valid <= 1'b0;
        mcycle <= mcycle + 64'd1;
        if (rst) begin
            f_pc <= RESET_PC;
            d_valid <= 1'b0;
            x_valid <= 1'b0;
            m_valid <= 1'b0;
            mstatus_mie <= 1'b0;
            mstatus_mpie <= 1'b0;
            mie_e <= 1'b0;
            mie_t <= 1'b0;
            mie_s <= 1'b0;
            mcause_int <= 1'b0;
            mcause_code <= 4'd0;
            mscratch <= 32'd0;
            mepc <= 32'd0;
            mtvec <= 32'd0;
            mtval <= 32'd0;
            mcycle <= 64'd0;
            minstret <= 64'd0;
            res_valid <= 1'b0;
            res_addr <= 32'd0;
            trap_q <= 1'b0;
            intr_pend <= 1'b0;
            intr_lines <= 3'd0;
            md_busy <= 1'b0;
            md_cnt <= 6'd0;
            rvfi_order <= 64'd0;
            m_amo2 <= 1'b0;
            u_we <= 1'b0;
        end else begin
            // ---------------------------------------------------- F, D
            f_pc <= f_sel ? f_next : f_oth;
            // D and X take their registers whenever they may take an instruction, without
            // waiting for X's branch outcome (a redirect only clears the valid bits): the
            // enables of these wide registers stay off the execute stage's longest path.
            if (d_open) begin
                d_pc <= f_pc;
                d_word <= imem_rdata;
            end
            // the branch's counter: against the static guess once more, or once less
            u_we <= x_done && is_branch;
            u_idx <= x_pc[BHT_AW > 0 ? BHT_AW : 1:1];
            u_val <= (br_taken ^ x_imm[31]) ? x_bht + {1'b0, x_bht != 2'd3} :
                                              x_bht - {1'b0, x_bht != 2'd0};
            d_valid <= !redirect && !(d_open && d_valid && d_guess);

            // ---------------------------------------------------- X
            if (x_leaves) begin
                x_pc <= d_pc;
                x_ir <= fi;
                x_c <= fi_c;
                x_imm <= fi_imm;
                x_raw <= fi_raw;
                x_jd <= d_guess;
                x_bht <= d_bht;
                xd <= d_dec;
                x_valid <= d_to_x;
            end
            // the divider runs while the instruction waits in X (not while it waits for M)
            if (smc || !x_valid || irq_take) begin
                md_busy <= 1'b0;
            end else if (is_iter && !exc_fixed) begin
                if (!md_busy && !load_use) begin
                    md_busy <= 1'b1;
                    // a product: one cycle for md_div3, then 8 of 4 bits (60, 0, 4, .. 32), or 4
                    // when the multiplier (rs1) has no more than 16 significant bits
                    md_cnt <= MUL_SEQ == 0 || is_div ? 6'd0 : 6'd60;
                    md_quo <= abs_a;
                    md_rem <= 32'd0;
                    md_div <= abs_b;
                    md_sq <= is_div ? md_neg : prod_neg;
                end else if (md_busy && !md_done) begin
                    if (MUL_SEQ == 0 || is_div) begin
                        md_cnt <= md_cnt + 6'd1;
                        md_quo <= {md_quo[30:0], !md_dif[32]};
                        md_rem <= md_dif[32] ? md_sh[31:0] : md_dif[31:0];
                    end else if (mq_prep) begin
                        md_cnt <= 6'd0;
                        md_div3 <= {2'd0, md_div} + {1'd0, md_div, 1'd0};
                    end else if (mq_early) begin
                        md_cnt <= 6'd32;
                        md_quo <= {mq_sum[19:0], md_quo[31:20]};
                        md_rem <= {16'd0, mq_sum[35:20]};
                    end else begin
                        md_cnt <= md_cnt + 6'd4;
                        md_quo <= {mq_sum[3:0], md_quo[31:4]};
                        md_rem <= mq_sum[35:4];
                    end
                end else if (x_done) begin
                    md_busy <= 1'b0;
                end
            end

            // a trap: the fetch and the CSRs in the next cycle (D and X are empty then)
            trap_q <= x_trap;
            trap_pc_q <= trap_vec;
            t_int <= irq_take;
            t_code <= irq_take ? irq_cause : exc_cause;
            t_pc <= x_pc;
            t_tval <= irq_take ? 32'd0 : exc_tval;
            if (trap_q) begin
                mcause_int <= t_int;
                mcause_code <= t_code;
                mstatus_mpie <= mstatus_mie;
                mstatus_mie <= 1'b0;
                mepc <= t_pc;
                mtval <= t_tval;
            end
            if (irq_take) begin
                intr_pend <= 1'b1;
                intr_lines <= lines;
            end
            if (x_commit) begin
                if (is_lr) begin
                    res_valid <= 1'b1;
                    res_addr <= ls_addr;
                end
                if (is_sc || is_amo) res_valid <= 1'b0;
            end
            if (x_done) begin
                if (is_mret) begin
                    mstatus_mie <= mstatus_mpie;
                    mstatus_mpie <= 1'b1;
                end
                if (wr_csr) begin
                    case (csr_addr)
                        12'h300: begin
                            mstatus_mie <= csr_wdata[3];
                            mstatus_mpie <= csr_wdata[7];
                        end
                        12'h304: begin
                            mie_e <= csr_wdata[11];
                            mie_t <= csr_wdata[7];
                            mie_s <= csr_wdata[3];
                        end
                        12'h305: mtvec <= csr_wval;
                        12'h340: mscratch <= csr_wval;
                        12'h341: mepc <= csr_wval;
                        12'h342: begin
                            mcause_int <= csr_wdata[31];
                            mcause_code <= csr_wdata[3:0];
                        end
                        12'h343: mtval <= csr_wval;
                        12'hb00: mcycle[31:0] <= csr_wdata;
                        12'hb80: mcycle[63:32] <= csr_wdata;
                        default: ;
                    endcase
                end
            end

            // ---------------------------------------------------- X -> M
            if (m_holds) begin
                // the AMO's first cycle: the word is loaded; the store follows
                m_amo2 <= 1'b1;
                m_loaded <= dmem_rdata;
            end else begin
                // M's registers take X's whether or not it comes (only the valid bit waits
                // for the commit decision)
                m_valid <= x_commit || x_exc;
                m_trap <= x_exc;
                m_intr <= intr_pend;
                m_mip <= lines;
                m_intr_mip <= intr_pend ? intr_lines : 3'd0;
                m_raw <= x_raw;
                m_pc <= x_pc;
                m_next <= x_exc ? trap_vec : next_pc;
                m_rd <= x_exc ? 5'd0 : rd_eff;
                m_load <= x_mem_rd;
                m_f3 <= f3;
                m_f5 <= f5;
                m_amo <= !x_exc && is_amo;
                m_amo2 <= 1'b0;
                m_result <= x_result;   // an AMO's rs2
                m_addr <= ls_addr;
                m_fetch <= ls_addr[31:20] == FETCH_REGION;
                m_rd_mem <= !x_exc && x_mem_rd;
                m_rmask <= x_exc || !x_mem_rd ? 4'd0 : is_load ? st_mask : 4'b1111;
                m_wstrb <= x_exc || !x_mem_wr ? 4'd0 : is_store ? st_mask : 4'b1111;
                m_wdata <= st_data;
                m_cnt_wr <= !x_exc && is_csr && csr_writes && csr_cnt;
                m_cnt_sel <= {csr_addr[1], csr_addr[7]};
                m_cnt_val <= csr_wdata;
                if (x_commit || x_exc) intr_pend <= 1'b0;
            end

            // ---------------------------------------------------- M: retirement
            if (m_done) begin
                if (!m_trap) begin
                    if (m_cnt_wr && m_cnt_sel[1]) begin
                        // written minstret: the increment, then the written half
                        if (m_cnt_sel[0])
                            minstret <= {m_cnt_val, minstret[31:0] + 32'd1};
                        else
                            minstret <= {minstret[63:32] + {31'd0, &minstret[31:0]},
                                         m_cnt_val};
                    end else begin
                        minstret <= minstret + 64'd1;
                    end
                end
                if (st_now) begin
                    st_w <= st_word;
                    st_m <= m_wstrb;
                    st_d <= m_amo ? amo_out : m_wdata;
                end
                rvfi_valid <= 1'b1;
                rvfi_order <= rvfi_order + 64'd1;
                rvfi_insn <= m_raw;
                rvfi_trap <= m_trap;
                rvfi_intr <= m_intr;
                rvfi_ext_mip <= m_mip;
                rvfi_ext_intr_mip <= m_intr_mip;
                rvfi_pc_rdata <= m_pc;
                rvfi_pc_wdata <= m_next;
                rvfi_rd_addr <= m_rd;
                rvfi_rd_wdata <= m_rd != 5'd0 ? wb_val : 32'd0;
                rvfi_mem_addr <= !m_trap && (m_rd_mem || m_wstrb != 4'd0) ? dmem_addr : 32'd0;
                rvfi_mem_rmask <= m_trap ? 4'd0 : m_rmask;
                rvfi_mem_wmask <= m_trap ? 4'd0 : m_wstrb;
                rvfi_mem_rdata <= !m_trap && m_rd_mem ? m_rdata : 32'd0;
                rvfi_mem_wdata <= !m_trap && m_wstrb != 4'd0 ? dmem_wdata : 32'd0;
            end
        end
    end

endmodule

`default_nettype wire
