// The SoC's RAM: two halfword banks (`lo` holds bits 15:0 of each word, `hi` bits 31:16), so
// the fetch port reads the 32 bits at any halfword address in one cycle: at a word boundary
// {hi[w], lo[w]}, in the middle of a word {lo[w + 1], hi[w]}. The data port reads and writes
// both banks at one word.
//
// Timing: both read ports are registered on the falling clock edge. The core's addresses
// come from its registers (stable in the first half of the cycle), and the data it reads is
// used at the rising edge that ends the cycle, so to the core the RAM still answers in the
// same cycle; on an FPGA the reads map onto block RAM with an inverted read clock. Writes
// (the data port and the back-door port) happen at the rising edge.
//
// EARLY = 1 (the pipelined core): the data port reads at the rising edge that begins the
// cycle instead, the word `d_next` (the core's next data address, known a cycle ahead), so
// the word is there from early in the cycle, as the store at that edge left it; it has its
// own copy of the banks, so each copy's reads are on one clock edge.
//
// This file is the behavioural model (simulation, and iCE40 block RAM through inference:
// each bank is duplicated there for its two read ports); fpga/soc_ram_spram.v is the
// UltraPlus version.
`default_nettype none

module soc_ram #(
    parameter integer AW = 18,         // word-address bits: 2^AW words
    parameter integer EARLY = 0        // 1: the data port reads `d_next` at the rising edge
) (
    input  wire          clk,
    input  wire [AW:0]   i_half,       // fetch: halfword address (byte address bits AW+1:1)
    output wire [31:0]   i_rdata,      // ... the 32 bits from there, from the falling edge on
    input  wire [AW-1:0] d_word,       // data port: word address
    input  wire [AW-1:0] d_next,       // EARLY: the word the data port reads at the edge
    input  wire          d_pre,        // the core may read this cycle (unused here)
    input  wire [AW-1:0] st_word,      // the core's last store (unused here)
    input  wire [31:0]   st_data,
    input  wire [3:0]    st_mask,
    input  wire [3:0]    d_we,         // byte lanes written at the rising edge
    input  wire [31:0]   d_wdata,
    output wire [31:0]   d_rdata,      // read data, from the falling edge on
    input  wire          bd_we,        // back-door word write (has priority)
    input  wire [AW-1:0] bd_addr,
    input  wire [31:0]   bd_wdata
);
    localparam integer WORDS = 1 << AW;
    reg [15:0] lo [0:WORDS-1];
    reg [15:0] hi [0:WORDS-1];

    integer k;
    initial for (k = 0; k < WORDS; k = k + 1) begin
        lo[k] = 16'd0;
        hi[k] = 16'd0;
    end

    wire [AW-1:0] iw    = i_half[AW:1];
    wire [AW-1:0] iw_lo = iw + {{(AW-1){1'b0}}, i_half[0]};
    reg  [15:0]   i_lo_q, i_hi_q;
    reg           i_odd_q;
    always @(negedge clk) begin
        i_lo_q  <= lo[iw_lo];
        i_hi_q  <= hi[iw];
        i_odd_q <= i_half[0];
    end
    assign i_rdata = i_odd_q ? {i_lo_q, i_hi_q} : {i_hi_q, i_lo_q};

    generate
        if (EARLY != 0) begin : early
            // A copy of the banks for the data port (written like them), so each copy's
            // reads are on one clock edge: block RAM inference keeps them apart.
            reg [15:0] dlo [0:WORDS-1];
            reg [15:0] dhi [0:WORDS-1];
            integer j;
            initial for (j = 0; j < WORDS; j = j + 1) begin
                dlo[j] = 16'd0;
                dhi[j] = 16'd0;
            end
            always @(posedge clk) begin
                if (bd_we) begin
                    dlo[bd_addr] <= bd_wdata[15:0];
                    dhi[bd_addr] <= bd_wdata[31:16];
                end else begin
                    if (d_we[0]) dlo[d_word][7:0]  <= d_wdata[7:0];
                    if (d_we[1]) dlo[d_word][15:8] <= d_wdata[15:8];
                    if (d_we[2]) dhi[d_word][7:0]  <= d_wdata[23:16];
                    if (d_we[3]) dhi[d_word][15:8] <= d_wdata[31:24];
                end
            end
            // the read at the rising edge, of the word as written at that edge (a read of
            // a registered address: block RAM, and a bypass of the store's bytes)
            reg [AW-1:0] word_q;
            always @(posedge clk) word_q <= d_next;
            assign d_rdata = {dhi[word_q], dlo[word_q]};
        end else begin : late
            reg [15:0] lo_q, hi_q;
            always @(negedge clk) begin
                lo_q <= lo[d_word];
                hi_q <= hi[d_word];
            end
            assign d_rdata = {hi_q, lo_q};
        end
    endgenerate

    always @(posedge clk) begin
        if (bd_we) begin
            lo[bd_addr] <= bd_wdata[15:0];
            hi[bd_addr] <= bd_wdata[31:16];
        end else begin
            if (d_we[0]) lo[d_word][7:0]  <= d_wdata[7:0];
            if (d_we[1]) lo[d_word][15:8] <= d_wdata[15:8];
            if (d_we[2]) hi[d_word][7:0]  <= d_wdata[23:16];
            if (d_we[3]) hi[d_word][15:8] <= d_wdata[31:24];
        end
    end
endmodule

`default_nettype wire
