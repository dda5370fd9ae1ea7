// RV32IMA + Zicsr machine-mode core.
//
// Single-issue, one instruction per cycle, two stages: the fetch stage presents the address of
// the next instruction; at the clock edge the instruction and its two source registers are
// captured (synchronous reads, so the register file and instruction memory fit block RAM; a
// result written in the same edge is forwarded). The execute stage decodes, executes, accesses
// data memory (read data returned in the same cycle) and writes back. Multiplication is a
// single-cycle 32x32 product (maps to DSP blocks) that also serves the shifts; division and
// remainder use an iterative restoring divider (34 cycles). WFI stalls until an enabled
// interrupt is pending. Interrupts are taken between instructions, never inside a division.
//
// The RVFI-style retirement port is registered: the record of an instruction is valid in the
// cycle after it completes.
`default_nettype none

module rv_core #(
    parameter [31:0] RESET_PC = 32'h8000_0000
) (
    input  wire        clk,
    input  wire        rst,

    // Instruction bus: word address out, instruction in (same cycle).
    output wire [31:0] imem_addr,
    input  wire [31:0] imem_rdata,

    // Data bus: word-aligned address, read data returned in the same cycle. Reads with side
    // effects and writes take effect at the clock edge when `dmem_re`/`dmem_wstrb` are set.
    output wire [31:0] dmem_addr,
    output wire        dmem_re,
    output wire [3:0]  dmem_rmask,
    output wire [3:0]  dmem_wstrb,
    output wire [31:0] dmem_wdata,
    input  wire [31:0] dmem_rdata,

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

    // ---------------------------------------------------------------- architectural state
    reg [31:0] pc;
    reg [31:0] regs [0:31];
    integer k;
    initial for (k = 0; k < 32; k = k + 1) regs[k] = 32'd0;  // block-RAM initial contents

    // fetch-stage outputs: the instruction in execute and its source registers
    reg [31:0] ir;
    reg [31:0] rf_rs1, rf_rs2;     // register file read data
    reg        byp1, byp2;         // forward the value written at the fetch edge instead
    reg [31:0] byp_val;

    reg        mstatus_mie, mstatus_mpie;
    reg [31:0] mie_r;        // only bits 3, 7, 11 are writable
    reg [31:0] mtvec, mscratch, mepc, mcause, mtval;
    reg [63:0] mcycle, minstret;

    reg        res_valid;    // LR/SC reservation
    reg [31:0] res_addr;

    reg        intr_flag;    // next record is the first instruction of an interrupt handler
    reg [2:0]  intr_mip;

    reg        md_busy;      // iterative divider
    reg [5:0]  md_cnt;
    reg [31:0] md_quo, md_rem, md_div;

    // ---------------------------------------------------------------- decode
    wire [31:0] insn   = ir;
    wire [6:0]  opcode = insn[6:0];
    wire [4:0]  rd     = insn[11:7];
    wire [4:0]  rs1    = insn[19:15];
    wire [4:0]  rs2    = insn[24:20];
    wire [2:0]  f3     = insn[14:12];
    wire [6:0]  f7     = insn[31:25];
    wire [4:0]  f5     = insn[31:27];

    // x0 is never written, so its block-RAM word keeps its initial zero; a write-back is
    // forwarded only for a nonzero rd.
    wire [31:0] rs1v = byp1 ? byp_val : rf_rs1;
    wire [31:0] rs2v = byp2 ? byp_val : rf_rs2;

    wire [31:0] imm_i = {{20{insn[31]}}, insn[31:20]};
    wire [31:0] imm_s = {{20{insn[31]}}, insn[31:25], insn[11:7]};
    wire [31:0] imm_b = {{19{insn[31]}}, insn[31], insn[7], insn[30:25], insn[11:8], 1'b0};
    wire [31:0] imm_u = {insn[31:12], 12'd0};
    wire [31:0] imm_j = {{11{insn[31]}}, insn[31], insn[19:12], insn[20], insn[30:21], 1'b0};

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

    // ---------------------------------------------------------------- ALU
    // One adder serves ADD/SUB/ADDI, load/store/AMO addresses and JALR targets; one 33-bit
    // subtractor serves branches and SLT*; shifts use the multiplier (below).
    wire [31:0] alu_b  = is_op ? rs2v : imm_i;
    wire [31:0] add_b  = is_op ? rs2v : is_store ? imm_s : is_amo_any ? 32'd0 : imm_i;
    wire        do_sub = is_op && f7[5];
    wire [31:0] sum    = rs1v + (do_sub ? ~add_b : add_b) + {31'd0, do_sub};

    wire [31:0] cmp_b      = is_branch ? rs2v : alu_b;
    wire        cmp_signed = is_branch ? !f3[1] : !f3[0];
    wire [32:0] cmp_diff   = {cmp_signed & rs1v[31], rs1v} - {cmp_signed & cmp_b[31], cmp_b};
    wire        lt         = cmp_diff[32];
    wire        eq         = rs1v == cmp_b;
    wire        br_taken   = f3[2] ? lt ^ f3[0] : eq ^ f3[0];

    wire [4:0]  shamt   = alu_b[4:0];

    reg  [31:0] alu_out;
    always @(*) begin
        case (f3)
            3'd0: alu_out = sum;
            3'd1, 3'd5: alu_out = mul_out;  // shifts run on the multiplier
            3'd2, 3'd3: alu_out = {31'd0, lt};
            3'd4: alu_out = rs1v ^ alu_b;
            3'd6: alu_out = rs1v | alu_b;
            default: alu_out = rs1v & alu_b;
        endcase
    end

    // ---------------------------------------------------------------- multiply / divide
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
    wire [31:0] abs_a    = (rs1v ^ {32{neg_a}}) + {31'd0, neg_a};  // conditional negation
    wire [31:0] abs_b    = (rs2v ^ {32{neg_b}}) + {31'd0, neg_b};
    wire [4:0]  sh_pow   = f3[2] ? 5'd0 - shamt : shamt;
    wire [31:0] mul_b    = is_shift ? 32'd1 << sh_pow : abs_b;
    wire [63:0] prod_u   = {32'd0, abs_a} * {32'd0, mul_b};
    wire        prod_neg = neg_a ^ neg_b;
    wire        lo_zero  = prod_u[31:0] == 32'd0;
    wire [31:0] hi_word  = (prod_u[63:32] ^ {32{prod_neg}}) + {31'd0, prod_neg & lo_zero};
    wire        use_lo   = is_shift ? !f3[2] || sh_zero : f3[1:0] == 2'd0;
    wire [31:0] mul_out  = use_lo ? prod_u[31:0] : hi_word;

    wire [32:0] md_sh  = {md_rem, md_quo[31]};
    wire [32:0] md_dif = md_sh - {1'b0, md_div};
    wire        md_done = md_busy && md_cnt == 6'd32;
    wire [31:0] md_res = f3[1] ? md_rem : md_quo;
    // Dividing by zero needs no special case: the loop yields an all-ones quotient and the
    // dividend's magnitude as remainder; only the quotient's sign fix-up is suppressed.
    wire        md_neg = f3[1] ? neg_a : (neg_a ^ neg_b) && rs2v != 32'd0;
    wire [31:0] div_out = (md_res ^ {32{md_neg}}) + {31'd0, md_neg};

    // ---------------------------------------------------------------- memory access
    wire [31:0] ls_addr = sum;
    wire        ls_misaligned = is_amo_any ? ls_addr[1:0] != 2'd0 :
                                f3[1:0] == 2'd1 ? ls_addr[0] :
                                f3[1:0] == 2'd2 ? ls_addr[1:0] != 2'd0 : 1'b0;
    wire [4:0]  ls_shift = {ls_addr[1:0], 3'd0};
    wire [31:0] ld_shifted = dmem_rdata >> ls_shift;
    reg  [31:0] load_out;
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

    // AMOMIN/MAX[U] share one 33-bit comparison (sign-extended for the signed pair).
    wire        amo_signed = !f5[3];
    wire [32:0] amo_diff = {amo_signed & dmem_rdata[31], dmem_rdata} -
                           {amo_signed & rs2v[31], rs2v};
    wire        amo_lt = amo_diff[32];
    reg  [31:0] amo_out;
    always @(*) begin
        case (f5)
            5'b00001: amo_out = rs2v;
            5'b00000: amo_out = dmem_rdata + rs2v;
            5'b00100: amo_out = dmem_rdata ^ rs2v;
            5'b01100: amo_out = dmem_rdata & rs2v;
            5'b01000: amo_out = dmem_rdata | rs2v;
            5'b10000: amo_out = amo_lt ? dmem_rdata : rs2v;
            5'b10100: amo_out = amo_lt ? rs2v : dmem_rdata;
            5'b11000: amo_out = amo_lt ? dmem_rdata : rs2v;
            default:  amo_out = amo_lt ? rs2v : dmem_rdata;
        endcase
    end
    wire sc_ok = res_valid && res_addr == ls_addr;

    // ---------------------------------------------------------------- CSRs
    wire [11:0] csr_addr = insn[31:20];
    wire [31:0] mip_v = {20'd0, irq_external, 3'd0, irq_timer, 3'd0, irq_software, 3'd0};
    wire [31:0] mstatus_v = {19'd0, 2'b11, 3'd0, mstatus_mpie, 3'd0, mstatus_mie, 3'd0};
    // The read mux decodes only the address bits that tell the implemented CSRs apart;
    // `csr_exists` decodes the whole address (anything else is an illegal instruction).
    reg  [31:0] csr_rdata;
    reg         csr_exists;
    always @(*) begin
        if (csr_addr[11])
            csr_rdata = csr_addr[10:8] == 3'b111 ? 32'd0 :
                        csr_addr[1] ? (csr_addr[7] ? minstret[63:32] : minstret[31:0]) :
                                      (csr_addr[7] ? mcycle[63:32] : mcycle[31:0]);
        else if (csr_addr[6])
            case (csr_addr[2:0])
                3'd0: csr_rdata = mscratch;
                3'd1: csr_rdata = mepc;
                3'd2: csr_rdata = mcause;
                3'd3: csr_rdata = mtval;
                default: csr_rdata = mip_v;
            endcase
        else if (csr_addr[4]) csr_rdata = 32'd0;
        else
            case (csr_addr[2:0])
                3'd0: csr_rdata = mstatus_v;
                3'd1: csr_rdata = 32'h4000_1101;
                3'd4: csr_rdata = mie_r;
                default: csr_rdata = mtvec;
            endcase
    end
    always @(*) begin
        case (csr_addr)
            12'h300, 12'h301, 12'h304, 12'h305, 12'h310, 12'h340, 12'h341, 12'h342, 12'h343,
            12'h344, 12'hb00, 12'hc00, 12'hb80, 12'hc80, 12'hb02, 12'hc02, 12'hb82, 12'hc82,
            12'hf11, 12'hf12, 12'hf13, 12'hf14, 12'hf15: csr_exists = 1'b1;
            default: csr_exists = 1'b0;
        endcase
    end
    wire        csr_writes = f3[1:0] == 2'b01 || rs1 != 5'd0;
    wire [31:0] csr_src    = f3[2] ? {27'd0, rs1} : rs1v;
    wire [31:0] csr_wdata  = f3[1:0] == 2'b01 ? csr_src :
                             f3[1:0] == 2'b10 ? csr_rdata | csr_src : csr_rdata & ~csr_src;
    wire        csr_illegal = !csr_exists || (csr_addr[11:10] == 2'b11 && csr_writes);

    // ---------------------------------------------------------------- control flow, traps
    wire legal = is_lui | is_auipc | is_jal | is_jalr | is_branch | is_load | is_store |
                 is_opimm | is_op | is_muldiv | is_fence | is_ecall | is_ebreak | is_mret |
                 is_wfi | is_csr | is_amo_any;
    wire [31:0] pc_plus4 = pc + 32'd4;
    wire [31:0] jalr_tgt = sum & ~32'd1;
    wire [31:0] pc_tgt   = pc + (is_jal ? imm_j : is_auipc ? imm_u : imm_b);
    wire        to_tgt   = is_jal | (is_branch && br_taken);
    wire [31:0] next_pc  = ({32{to_tgt}} & pc_tgt) | ({32{is_jalr}} & jalr_tgt) |
                           ({32{is_mret}} & mepc) |
                           ({32{!(to_tgt | is_jalr | is_mret)}} & pc_plus4);
    wire jump = is_jal | is_jalr | (is_branch && br_taken);

    wire exc_illegal = !legal || (is_csr && csr_illegal) || insn[1:0] != 2'b11;
    wire exc_fetch   = !exc_illegal && jump && next_pc[1:0] != 2'd0;
    wire exc_load    = !exc_illegal && (is_load || is_lr) && ls_misaligned;
    wire exc_store   = !exc_illegal && (is_store || is_sc || is_amo) && ls_misaligned;
    wire exc = exc_illegal | exc_fetch | exc_load | exc_store | is_ecall | is_ebreak;
    wire [31:0] exc_cause = exc_illegal ? 32'd2 : exc_fetch ? 32'd0 : exc_load ? 32'd4 :
                            exc_store ? 32'd6 : is_ebreak ? 32'd3 : 32'd11;
    wire [31:0] exc_tval  = exc_illegal ? insn : exc_fetch ? next_pc :
                            (exc_load | exc_store) ? ls_addr : is_ebreak ? pc : 32'd0;

    wire [31:0] irq_pend = mip_v & mie_r;
    wire        irq_take = mstatus_mie && irq_pend != 32'd0 && !md_busy && !is_wfi;
    wire [31:0] irq_cause = irq_pend[11] ? 32'd11 : irq_pend[3] ? 32'd3 : 32'd7;
    wire [31:0] tvec_base = {mtvec[31:2], 2'b00};
    wire [31:0] irq_target = mtvec[0] ? tvec_base + {irq_cause[29:0], 2'b00} : tvec_base;

    wire stall  = (is_div && !md_done) || (is_wfi && irq_pend == 32'd0);
    assign sleeping = !rst && is_wfi && irq_pend == 32'd0;
    wire commit = !rst && !irq_take && !stall && !exc;

    wire mem_rd = is_load | is_lr | is_amo;
    wire mem_wr = is_store | is_amo | (is_sc && sc_ok);

    // Address of the instruction after this cycle.
    wire [31:0] fetch_pc = rst ? RESET_PC : irq_take ? irq_target : stall ? pc :
                           exc ? tvec_base : next_pc;
    assign imem_addr  = fetch_pc;
    assign dmem_addr  = {ls_addr[31:2], 2'b00};
    assign dmem_re    = commit && mem_rd;
    assign dmem_rmask = mem_rd ? (is_load ? st_mask : 4'b1111) : 4'b0000;
    assign dmem_wstrb = (commit && mem_wr) ? (is_store ? st_mask : 4'b1111) : 4'b0000;
    assign dmem_wdata = is_amo ? amo_out : st_data;

    reg [31:0] rd_val;
    always @(*) begin
        // the decoded kinds are exclusive, so an AND-OR replaces a priority chain
        rd_val = ({32{is_lui}} & imm_u) | ({32{is_auipc}} & pc_tgt) |
                 ({32{is_jal | is_jalr}} & pc_plus4) | ({32{is_load}} & load_out) |
                 ({32{is_lr | is_amo}} & dmem_rdata) | {31'd0, is_sc & !sc_ok} |
                 ({32{is_csr}} & csr_rdata) | ({32{is_muldiv & f3[2]}} & div_out) |
                 ({32{is_muldiv & !f3[2]}} & mul_out) | ({32{is_opimm | is_op}} & alu_out);
    end
    wire writes_rd = is_lui | is_auipc | is_jal | is_jalr | is_load | is_opimm | is_op |
                     is_muldiv | is_csr | is_amo_any;
    wire [4:0] rd_eff = (writes_rd && rd != 5'd0) ? rd : 5'd0;

    // ---------------------------------------------------------------- fetch stage
    wire [4:0] f_rs1 = imem_rdata[19:15];
    wire [4:0] f_rs2 = imem_rdata[24:20];
    wire       wb    = commit && rd_eff != 5'd0;
    always @(posedge clk) begin
        pc <= fetch_pc;
        ir <= imem_rdata;
        rf_rs1 <= regs[f_rs1];
        rf_rs2 <= regs[f_rs2];
        byp1 <= wb && rd_eff == f_rs1;
        byp2 <= wb && rd_eff == f_rs2;
        byp_val <= rd_val;
        if (wb) regs[rd_eff] <= rd_val;
    end

    // ---------------------------------------------------------------- state update
    always @(posedge clk) begin
        rvfi_valid <= 1'b0;
        if (rst) begin
            mstatus_mie <= 1'b0;
            mstatus_mpie <= 1'b0;
            mie_r <= 32'd0;
            mtvec <= 32'd0;
            mscratch <= 32'd0;
            mepc <= 32'd0;
            mcause <= 32'd0;
            mtval <= 32'd0;
            mcycle <= 64'd0;
            minstret <= 64'd0;
            res_valid <= 1'b0;
            res_addr <= 32'd0;
            intr_flag <= 1'b0;
            intr_mip <= 3'd0;
            md_busy <= 1'b0;
            md_cnt <= 6'd0;
            rvfi_order <= 64'd0;
        end else begin
            mcycle <= mcycle + 64'd1;
            if (irq_take) begin
                mepc <= pc;
                mcause <= {1'b1, irq_cause[30:0]};
                mtval <= 32'd0;
                mstatus_mpie <= mstatus_mie;
                mstatus_mie <= 1'b0;
                intr_flag <= 1'b1;
                intr_mip <= {irq_external, irq_timer, irq_software};
            end else if (stall) begin
                if (is_div) begin
                    if (!md_busy) begin
                        md_busy <= 1'b1;
                        md_cnt <= 6'd0;
                        md_quo <= abs_a;
                        md_rem <= 32'd0;
                        md_div <= abs_b;
                    end else begin
                        md_cnt <= md_cnt + 6'd1;
                        md_quo <= {md_quo[30:0], !md_dif[32]};
                        md_rem <= md_dif[32] ? md_sh[31:0] : md_dif[31:0];
                    end
                end
            end else begin
                md_busy <= 1'b0;
                intr_flag <= 1'b0;
                rvfi_valid <= 1'b1;
                rvfi_order <= rvfi_order + 64'd1;
                rvfi_insn <= insn;
                rvfi_intr <= intr_flag;
                rvfi_ext_intr_mip <= intr_flag ? intr_mip : 3'd0;
                rvfi_ext_mip <= {irq_external, irq_timer, irq_software};
                rvfi_pc_rdata <= pc;
                rvfi_trap <= exc;
                if (exc) begin
                    mepc <= pc;
                    mcause <= exc_cause;
                    mtval <= exc_tval;
                    mstatus_mpie <= mstatus_mie;
                    mstatus_mie <= 1'b0;
                    rvfi_pc_wdata <= tvec_base;
                    rvfi_rd_addr <= 5'd0;
                    rvfi_rd_wdata <= 32'd0;
                    rvfi_mem_addr <= 32'd0;
                    rvfi_mem_rmask <= 4'd0;
                    rvfi_mem_wmask <= 4'd0;
                    rvfi_mem_rdata <= 32'd0;
                    rvfi_mem_wdata <= 32'd0;
                end else begin
                    minstret <= minstret + 64'd1;
                    rvfi_pc_wdata <= next_pc;
                    rvfi_rd_addr <= rd_eff;
                    rvfi_rd_wdata <= rd_eff != 5'd0 ? rd_val : 32'd0;
                    rvfi_mem_addr <= (mem_rd | mem_wr) ? dmem_addr : 32'd0;
                    rvfi_mem_rmask <= dmem_rmask;
                    rvfi_mem_wmask <= dmem_wstrb;
                    rvfi_mem_rdata <= mem_rd ? dmem_rdata : 32'd0;
                    rvfi_mem_wdata <= mem_wr ? dmem_wdata : 32'd0;
                    if (is_lr) begin
                        res_valid <= 1'b1;
                        res_addr <= ls_addr;
                    end
                    if (is_sc) res_valid <= 1'b0;
                    if (is_mret) begin
                        mstatus_mie <= mstatus_mpie;
                        mstatus_mpie <= 1'b1;
                    end
                    if (is_csr) begin
                        // A committing CSR instruction has a legal address, so the
                        // writes decode only the bits that tell the writable CSRs apart
                        // (misa, mstatush and mip ignore writes).
                        if (csr_writes) begin
                            if (csr_addr[11])  // mcycle(h), minstret(h)
                                case ({csr_addr[7], csr_addr[1]})
                                    2'b00: mcycle[31:0] <= csr_wdata;
                                    2'b10: mcycle[63:32] <= csr_wdata;
                                    2'b01: minstret[31:0] <= csr_wdata;
                                    default: minstret[63:32] <= csr_wdata;
                                endcase
                            else if (csr_addr[6])  // 0x340..0x344
                                case (csr_addr[2:0])
                                    3'd0: mscratch <= csr_wdata;
                                    3'd1: mepc <= {csr_wdata[31:2], 2'b00};
                                    3'd2: mcause <= csr_wdata & 32'h8000_000f;  // WLRL
                                    3'd3: mtval <= csr_wdata;
                                    default: ;
                                endcase
                            else if (!csr_addr[4])  // 0x300..0x305
                                case (csr_addr[2:0])
                                    3'd0: begin
                                        mstatus_mie <= csr_wdata[3];
                                        mstatus_mpie <= csr_wdata[7];
                                    end
                                    3'd4: mie_r <= csr_wdata & 32'h0000_0888;
                                    3'd5: mtvec <= {csr_wdata[31:2], 1'b0, csr_wdata[0]};
                                    default: ;
                                endcase
                        end
                    end
                end
            end
        end
    end

endmodule

`default_nettype wire
