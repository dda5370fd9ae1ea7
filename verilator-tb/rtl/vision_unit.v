// Vision unit: the per-pixel work of blob detection in the fabric. Pixels arrive as RGB332
// codes on a stream (one event a cycle at most: a pixel, the end of a line, or the end of a
// frame); each is classified through a 256-entry table of 4-bit classes and the classes are
// run-length encoded per line into one of two run buffers (the word format of
// `vision::runs`: a word per run, a row-end word after each row that has runs). At the end of
// a frame the buffers swap, the published registers change in one clock edge, and the FRAME
// status bit (the interrupt, when enabled) is set. The register block reads like the
// `vision::run_window` layout, so the firmware's reader is the same on every board.
//
// Timing (the model in soc-model/src/vision_unit.rs computes the same cycles):
//   an event in cycle t is classified at the edge ending t (table read),
//   in t+1 a pixel closes the open run or a line end closes it (one buffer write),
//   in t+2 a line end writes its row-end word and a frame end publishes the frame:
//   registers, the swapped buffer and the interrupt line show it from cycle t+3.
// The first pixel of a line never closes a run, so the two writes never meet.
//
// Enable: CTRL.ENABLE starts processing at the end of the next frame (`active`); clearing it
// stops at once and drops the frame in progress. The class table takes writes only while
// CTRL.ENABLE is clear, so it never changes under a frame.
`default_nettype none

module vision_unit #(
    parameter integer CAP_AW = 12            // run buffer: 2^CAP_AW words each (at most 12)
) (
    input  wire        clk,
    input  wire        rst,
    // data bus (the SoC decodes the unit's 64 KiB region)
    input  wire        sel,
    input  wire [15:0] offset,
    input  wire [3:0]  wstrb,
    input  wire [31:0] wdata,
    output wire [31:0] rdata,                // registers: combinational; buffers: falling edge
    output wire        irq,
    // pixel stream
    input  wire        px_valid,
    input  wire [7:0]  px_data,
    input  wire        px_eol,
    input  wire        px_eof
);
    localparam integer CAP = 1 << CAP_AW;
    localparam [31:0] MAGIC = 32'h4E52_4C41;     // "ALRN"
    localparam [31:0] WRITING = 32'hFFFF_FFFF;

    // ------------------------------------------------------------------ registers
    reg        en, irq_en, active, frame_flag;
    reg        front;                            // buffer holding frame `seq`
    reg [31:0] seq;
    reg [CAP_AW:0] pub_count;
    reg [15:0] pub_dropped;
    reg [12:0] pub_w, pub_h;

    wire wr = sel && !rst && wstrb != 4'd0;
    wire wr_ctrl = wr && offset == 16'h0040 && wstrb[0];
    wire en_next = wr_ctrl ? wdata[0] : en;

    // ------------------------------------------------------------------ class table
    // 64 words of four 4-bit classes: code c is nibble c[1:0] of word c[7:2].
    reg [15:0] lut [0:63];
    integer k;
    initial for (k = 0; k < 64; k = k + 1) lut[k] = 16'd0;
    wire wr_lut = wr && offset[15:8] == 8'h01 && !en;
    always @(posedge clk) begin
        if (wr_lut) begin
            if (wstrb[0]) lut[offset[7:2]][3:0]   <= wdata[3:0];
            if (wstrb[1]) lut[offset[7:2]][7:4]   <= wdata[11:8];
            if (wstrb[2]) lut[offset[7:2]][11:8]  <= wdata[19:16];
            if (wstrb[3]) lut[offset[7:2]][15:12] <= wdata[27:24];
        end
    end

    // ------------------------------------------------------------------ stage 1: classify
    reg [15:0] lut_q;
    reg [1:0]  sub_q;
    reg        s1_px, s1_eol, s1_eof;
    always @(posedge clk) begin
        lut_q <= lut[px_data[7:2]];
        sub_q <= px_data[1:0];
        s1_eof <= active && px_eof;
        s1_eol <= active && px_eol && !px_eof;
        s1_px  <= active && px_valid && !px_eol && !px_eof;
    end
    wire [3:0] cls = sub_q == 2'd0 ? lut_q[3:0]  : sub_q == 2'd1 ? lut_q[7:4]
                   : sub_q == 2'd2 ? lut_q[11:8] : lut_q[15:12];

    // ------------------------------------------------------------------ stage 2: runs
    reg [3:0]  cur;                              // class of the open run (0: none)
    reg [12:0] x, start;
    reg [12:0] y;
    reg [11:0] row_n;                            // runs stored in this row
    reg [CAP_AW:0] widx;                         // words written into the back buffer
    reg [15:0] dropped;
    reg [12:0] last_w;                           // pixels in the last line
    reg        s2_line, s2_eof;

    wire line_end = s1_eol || (s1_eof && x != 13'd0);
    wire closing = cur != 4'd0 && ((s1_px && cls != cur) || line_end);
    wire room = {{(31-CAP_AW){1'b0}}, widx} <= CAP - 2;  // the run and its row end
    wire run_we = closing && room;
    wire [12:0] last_x = x - 13'd1;
    wire [31:0] run_word = {cur, 4'd0, start[11:0], last_x[11:0]};

    // ------------------------------------------------------------------ stage 3: row ends, publish
    wire end_we = s2_line && row_n != 12'd0;
    wire [31:0] end_word = {4'd0, row_n, 4'd0, y[11:0]};
    wire [CAP_AW:0] widx_after_end = widx + {{CAP_AW{1'b0}}, end_we};
    wire [31:0] seq_next = seq >= 32'hFFFF_FFFE ? 32'd1 : seq + 32'd1;

    // ------------------------------------------------------------------ run memory
    reg [31:0] runs [0:2*CAP-1];
    initial for (k = 0; k < 2 * CAP; k = k + 1) runs[k] = 32'd0;
    wire mem_we = active && (run_we || end_we);
    wire [CAP_AW-1:0] mem_wi = widx[CAP_AW-1:0];
    always @(posedge clk) begin
        if (mem_we) runs[{~front, mem_wi}] <= end_we ? end_word : run_word;
    end
    // the processor's read port (block RAM read on the falling edge, as the SoC's memories)
    wire       rd_buf = offset[15];
    reg [31:0] runs_q;
    reg        rd_buf_q;
    always @(negedge clk) begin
        runs_q <= runs[{rd_buf, offset[CAP_AW+1:2]}];
        rd_buf_q <= rd_buf;
    end

    always @(posedge clk) begin
        if (rst) begin
            en <= 1'b0;
            irq_en <= 1'b0;
            active <= 1'b0;
            frame_flag <= 1'b0;
            front <= 1'b1;
            seq <= 32'd0;
            pub_count <= {(CAP_AW+1){1'b0}};
            pub_dropped <= 16'd0;
            pub_w <= 13'd0;
            pub_h <= 13'd0;
        end else begin
            if (wr_ctrl) begin
                en <= wdata[0];
                irq_en <= wdata[1];
            end
            if (!en_next) active <= 1'b0;
            else if (en && !active && px_eof) active <= 1'b1;
            if (wr && offset == 16'h0044 && wstrb[0] && wdata[0]) frame_flag <= 1'b0;
            if (active && s2_eof) begin
                frame_flag <= 1'b1;
                front <= ~front;
                seq <= seq_next;
                pub_count <= widx_after_end;
                pub_dropped <= dropped;
                pub_w <= last_w;
                pub_h <= y + {12'd0, s2_line};
            end
        end
        // the pipeline: cleared while not active
        if (rst || !active) begin
            cur <= 4'd0;
            x <= 13'd0;
            start <= 13'd0;
            y <= 13'd0;
            row_n <= 12'd0;
            widx <= {(CAP_AW+1){1'b0}};
            dropped <= 16'd0;
            last_w <= 13'd0;
            s2_line <= 1'b0;
            s2_eof <= 1'b0;
        end else begin
            s2_line <= line_end;
            s2_eof <= s1_eof;
            // stage 2
            if (closing) begin
                if (room) row_n <= row_n + 12'd1;
                else if (dropped != 16'hFFFF) dropped <= dropped + 16'd1;
            end
            if (s1_px) begin
                if (cls != cur) begin
                    cur <= cls;
                    start <= x;
                end
                x <= x + 13'd1;
            end
            if (line_end) begin
                last_w <= x;
                x <= 13'd0;
                cur <= 4'd0;
            end
            // stage 3 (never in a cycle where stage 2 writes)
            if (s2_line) begin
                y <= y + 13'd1;
                row_n <= 12'd0;
            end
            if (s2_eof) begin
                y <= 13'd0;
                widx <= {(CAP_AW+1){1'b0}};
                dropped <= 16'd0;
            end else begin
                widx <= widx + {{CAP_AW{1'b0}}, run_we} + {{CAP_AW{1'b0}}, end_we};
            end
        end
    end

    assign irq = frame_flag && irq_en;

    // ------------------------------------------------------------------ read data
    reg [31:0] reg_rdata;
    always @(*) begin
        reg_rdata = 32'd0;
        if (offset[15:8] == 8'h00) begin
            case (offset[7:2])
                6'h00: reg_rdata = MAGIC;
                6'h01: reg_rdata = {16'd64, 16'd1};
                6'h02: reg_rdata = CAP;
                6'h03: reg_rdata = 32'h0000_4000;
                6'h04: reg_rdata = 32'h0000_8000;
                6'h05: reg_rdata = seq;
                6'h06: reg_rdata = {31'd0, front};
                6'h07: reg_rdata = !front ? seq : WRITING;
                6'h08: reg_rdata = front ? seq : WRITING;
                6'h09: reg_rdata = !front ? {{(31-CAP_AW){1'b0}}, pub_count} : 32'd0;
                6'h0a: reg_rdata = front ? {{(31-CAP_AW){1'b0}}, pub_count} : 32'd0;
                6'h0b: reg_rdata = !front ? {16'd0, pub_dropped} : 32'd0;
                6'h0c: reg_rdata = front ? {16'd0, pub_dropped} : 32'd0;
                6'h0d: reg_rdata = !front ? {3'd0, pub_h, 3'd0, pub_w} : 32'd0;
                6'h0e: reg_rdata = front ? {3'd0, pub_h, 3'd0, pub_w} : 32'd0;
                6'h10: reg_rdata = {30'd0, irq_en, en};
                6'h11: reg_rdata = {30'd0, active, frame_flag};
                default: reg_rdata = 32'd0;
            endcase
        end
    end
    wire in_buf = offset[15:14] == 2'b01 || offset[15:14] == 2'b10;
    assign rdata = in_buf ? (rd_buf_q == front ? runs_q : 32'd0) : reg_rdata;
endmodule

`default_nettype wire
