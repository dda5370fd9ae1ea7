// Timing probe, not part of the SoC: the fetch stage of the six-stage core that
// `docs/fpga.md` plans ("What would reach 24 MHz on the UP5K and 60 on the HX8K"), alone
// between flip-flops, to learn what clock its loop reaches on each part and what it costs.
//
// The instruction memory is the SoC's (`rtl/soc_ram.v`: two halfword banks, so the 32 bits
// at any halfword address come in one read), but read at the rising edge from the next
// fetch address instead of at the falling edge from the current one; a branch target buffer
// of 256 entries (one entry per halfword address's low bits: a valid bit, a tag of the pc's
// next bits, the target's halfword address and its lower bank's word) is read at the same
// edge from the same address.
// In the cycle after, the fetched word's length bits, the buffer's tag comparison and a
// registered redirect (the execute stage's outcome, a cycle later) pick the next address:
//
//   redirect ? its target : hit ? the buffer's target : pc + 2 or pc + 4 (by the length).
//
// The lower bank's word address of each candidate (the word after when the address is odd)
// is worked out beside the candidate, so the choice ends at the memories' address pins with
// no adder behind it. The fetched word goes to the decode stage's register. An LFSR feeds
// the redirect and the buffer's writes so that nothing is constant.
`default_nettype none

module fetch_stage #(
    parameter integer AW = 11,       // word-address bits of the program memory (8 KiB here)
    parameter integer BTB_AW = 8     // 256 entries
) (
    input  wire clk,
    input  wire seed,
    output wire out0
);
    localparam integer HW = AW + 1;  // halfword-address bits
    localparam integer TW = HW - BTB_AW;

    reg [31:0] lfsr = 32'h1;
    always @(posedge clk) lfsr <= {lfsr[30:0], lfsr[31] ^ lfsr[21] ^ lfsr[1] ^ lfsr[0] ^ seed};

    // ---------------------------------------------------------------- memories
    localparam integer WORDS = 1 << AW;
    reg [15:0] lo [0:WORDS-1];
    reg [15:0] hi [0:WORDS-1];
    localparam integer BN = 1 << BTB_AW;
    localparam integer BE = 1 + TW + HW + AW;   // an entry's bits
    reg [BE-1:0] btb [0:BN-1];
    integer k;
    initial begin
        for (k = 0; k < WORDS; k = k + 1) begin
            lo[k] = 16'h0013 ^ k[15:0];
            hi[k] = 16'h0000 ^ {k[7:0], k[15:8]};
        end
        for (k = 0; k < BN; k = k + 1) btb[k] = 0;
    end

    // the address presented at the edge: halfword address, and the lower bank's word
    reg  [HW-1:0] n_half;
    reg  [AW-1:0] n_lo;
    reg  [15:0]   q_lo, q_hi;
    reg  [BE-1:0] q_btb;
    reg  [HW-1:0] pc;                // the halfword address the memories answer for
    // stores into the program memory (the data port's), so that it stays a RAM
    always @(posedge clk) begin
        if (lfsr[7] & lfsr[13]) lo[lfsr[AW+15:16]] <= lfsr[15:0];
        if (lfsr[8] & lfsr[13]) hi[lfsr[AW+15:16]] <= lfsr[31:16];
    end
    always @(posedge clk) begin
        q_lo  <= lo[n_lo];
        q_hi  <= hi[n_half[HW-1:1]];
        q_btb <= btb[n_half[BTB_AW-1:0]];
        pc    <= n_half;
    end
    wire [31:0] word = pc[0] ? {q_lo, q_hi} : {q_hi, q_lo};

    // the buffer's writes: the branch the execute stage resolved, a cycle later
    reg              u_we;
    reg [BTB_AW-1:0] u_idx;
    reg [BE-1:0]     u_val;
    always @(posedge clk) begin
        u_we  <= lfsr[3] & lfsr[9];
        u_idx <= lfsr[BTB_AW+10:11];
        u_val <= {lfsr[0], lfsr[TW+HW:1], lfsr[AW+4:5]};
        if (u_we) btb[u_idx] <= u_val;
    end

    // the registered redirect, with its target's lower-bank word worked out a cycle ahead
    reg          r_go;
    reg [HW-1:0] r_half;
    reg [AW-1:0] r_lo;
    always @(posedge clk) begin
        r_go   <= lfsr[5] & lfsr[17] & lfsr[29];
        r_half <= lfsr[HW+3:4];
        r_lo   <= lfsr[HW+3:5] + {{(AW-1){1'b0}}, lfsr[4]};
    end

    // ---------------------------------------------------------------- next address
    // the buffer's entry: {valid, tag, target's halfword address, its lower bank's word}
    wire          b_valid = q_btb[BE-1];
    wire [TW-1:0] b_tag   = q_btb[BE-2:HW+AW];
    wire [HW-1:0] b_half  = q_btb[HW+AW-1:AW];
    wire [AW-1:0] b_lo    = q_btb[AW-1:0];
    wire          hit     = b_valid && b_tag == pc[HW-1:BTB_AW];
    // the two sequential candidates from the register, beside the memories' read
    wire [HW-1:0] s2 = pc + 1, s4 = pc + 2;
    wire [AW-1:0] s2_lo = s2[HW-1:1] + {{(AW-1){1'b0}}, s2[0]};
    wire [AW-1:0] s4_lo = s4[HW-1:1] + {{(AW-1){1'b0}}, s4[0]};
    wire          len4 = word[1:0] == 2'b11;
    always @(*) begin
        if (r_go) begin
            n_half = r_half;
            n_lo   = r_lo;
        end else if (hit) begin
            n_half = b_half;
            n_lo   = b_lo;
        end else if (len4) begin
            n_half = s4;
            n_lo   = s4_lo;
        end else begin
            n_half = s2;
            n_lo   = s2_lo;
        end
    end

    // ---------------------------------------------------------------- decode's registers
    reg [31:0]   d_word;
    reg [HW-1:0] d_pc;
    reg          d_hit;
    always @(posedge clk) begin
        d_word <= word;
        d_pc   <= pc;
        d_hit  <= hit;
    end
    assign out0 = ^{d_word, d_pc, d_hit};
endmodule

`default_nettype wire
