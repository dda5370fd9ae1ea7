// 16550-compatible UART, byte-spaced registers, 16-byte FIFOs.
//
// The line side is byte-level but bit-timed: a byte leaves the transmitter 10 bit times
// (8N1, bit time = 16 * divisor clocks) after it enters the shifter, and appears on
// `tx_valid`/`tx_data` when its stop bit ends. Received bytes are handed in on
// `rx_valid`/`rx_data`; the driver of that port paces them at the line rate. RX FIFO overflow
// sets the overrun flag; the RX timeout interrupt fires after 4 character times of silence.
`default_nettype none

module uart16550 (
    input  wire        clk,
    input  wire        rst,
    input  wire        sel,          // bus cycle addressed to this device
    input  wire        addr_hi,      // 0: registers 0-3, 1: registers 4-7
    input  wire        re,
    input  wire [3:0]  rmask,
    input  wire [3:0]  wstrb,
    input  wire [31:0] wdata,
    output wire [31:0] rdata,
    output wire        irq,
    input  wire        rx_valid,
    input  wire [7:0]  rx_data,
    output reg         tx_valid,
    output reg  [7:0]  tx_data,
    // The transmitter's serial line (8N1, idle high), driven by the shifter, and the divisor,
    // for a line receiver in front of rx_valid/rx_data (FPGA builds).
    output reg         txd,
    output wire [15:0] divisor_out
);
    reg [7:0] ier, lcr, mcr, scr, dll, dlm;
    reg       fifo_en;
    reg [1:0] rx_trig;
    reg       overrun;
    reg       thre_ip;

    reg [7:0] rxf [0:15];
    reg [3:0] rx_rd, rx_wr;
    reg [4:0] rx_cnt;
    reg [7:0] txf [0:15];
    reg [3:0] tx_rd, tx_wr;
    reg [4:0] tx_cnt;

    reg        sh_busy;
    reg [7:0]  sh_data;
    reg [15:0] sh_div;           // the divisor the byte in the shifter is sent with
    reg [19:0] bit_timer;        // clocks left of the bit on the line, minus one
    reg [3:0]  bit_idx;          // 0: start bit, 1..8: data bits, 9: stop bit
    reg [25:0] idle_timer;

    wire        dlab     = lcr[7];
    wire [15:0] divisor  = {dlm, dll} == 16'd0 ? 16'd1 : {dlm, dll};
    // The RX timeout's threshold: 4 character times (640 * divisor clocks).
    wire [25:0] rto_clks = {1'b0, divisor, 9'd0} + {3'd0, divisor, 7'd0};
    wire [4:0] trig_level = !fifo_en ? 5'd1 : rx_trig == 2'd0 ? 5'd1 : rx_trig == 2'd1 ? 5'd4 :
                            rx_trig == 2'd2 ? 5'd8 : 5'd14;
    assign divisor_out = divisor;
    wire rx_timeout = rx_cnt != 5'd0 && idle_timer >= rto_clks;

    wire ip_ls   = ier[2] && overrun;
    wire ip_rda  = ier[0] && rx_cnt >= trig_level;
    wire ip_rto  = ier[0] && rx_timeout;
    wire ip_thre = ier[1] && thre_ip;
    wire [3:0] iir_id = ip_ls ? 4'h6 : ip_rda ? 4'h4 : ip_rto ? 4'hc : ip_thre ? 4'h2 : 4'h1;
    wire [7:0] iir = {fifo_en ? 2'b11 : 2'b00, 2'b00, iir_id};
    assign irq = ip_ls || ip_rda || ip_rto || ip_thre;

    wire [7:0] lsr = {1'b0, tx_cnt == 5'd0 && !sh_busy, tx_cnt == 5'd0, 3'b000, overrun,
                      rx_cnt != 5'd0};
    wire [7:0] rbr = rx_cnt != 5'd0 ? rxf[rx_rd] : 8'd0;
    wire [7:0] msr = 8'hb0;

    assign rdata = addr_hi ? {scr, msr, lsr, mcr} : {lcr, iir, dlab ? dlm : ier, dlab ? dll : rbr};

    wire rd_rbr = sel && re && !addr_hi && rmask[0] && !dlab;
    wire rd_iir = sel && re && !addr_hi && rmask[2];
    wire rd_lsr = sel && re && addr_hi && rmask[1];
    wire wr_thr = sel && !addr_hi && wstrb[0] && !dlab;
    wire wr_fcr = sel && !addr_hi && wstrb[2];

    wire rx_pop  = rd_rbr && rx_cnt != 5'd0;
    wire rx_push = rx_valid && rx_cnt != 5'd16;
    wire tx_push = wr_thr && tx_cnt != 5'd16;
    // a byte takes 10 bit times of 16 * divisor clocks
    wire sh_done = sh_busy && bit_idx == 4'd9 && bit_timer == 20'd0;
    wire tx_pop  = (!sh_busy || sh_done) && tx_cnt != 5'd0;

    always @(posedge clk) begin
        tx_valid <= 1'b0;
        if (rst) begin
            ier <= 8'd0; lcr <= 8'd0; mcr <= 8'd0; scr <= 8'd0; dll <= 8'd0; dlm <= 8'd0;
            fifo_en <= 1'b0; rx_trig <= 2'd0; overrun <= 1'b0; thre_ip <= 1'b0;
            rx_rd <= 4'd0; rx_wr <= 4'd0; rx_cnt <= 5'd0;
            tx_rd <= 4'd0; tx_wr <= 4'd0; tx_cnt <= 5'd0;
            sh_busy <= 1'b0; idle_timer <= 26'd0; tx_data <= 8'd0;
            bit_timer <= 20'd0; bit_idx <= 4'd0; txd <= 1'b1;
        end else begin
            // receive side
            if (rx_push) begin
                rxf[rx_wr] <= rx_data;
                rx_wr <= rx_wr + 4'd1;
            end
            if (rx_valid && rx_cnt == 5'd16) overrun <= 1'b1;
            if (rx_pop) rx_rd <= rx_rd + 4'd1;
            rx_cnt <= rx_cnt + {4'd0, rx_push} - {4'd0, rx_pop};
            if (rx_push || rx_pop) idle_timer <= 26'd0;
            else if (!rx_timeout) idle_timer <= idle_timer + 26'd1;
            if (rd_lsr) overrun <= 1'b0;

            // transmit side
            if (tx_push) begin
                txf[tx_wr] <= wdata[7:0];
                tx_wr <= tx_wr + 4'd1;
            end
            // the serial line `txd` shows the bit in flight
            if (sh_done) begin
                sh_busy <= 1'b0;
                tx_valid <= 1'b1;
                tx_data <= sh_data;
                txd <= 1'b1;
            end else if (sh_busy) begin
                if (bit_timer == 20'd0) begin
                    bit_idx <= bit_idx + 4'd1;
                    bit_timer <= {sh_div, 4'd0} - 20'd1;
                    txd <= bit_idx >= 4'd8 ? 1'b1 : sh_data[bit_idx[2:0]];
                end else begin
                    bit_timer <= bit_timer - 20'd1;
                end
            end
            if (tx_pop) begin
                sh_busy <= 1'b1;
                sh_data <= txf[tx_rd];
                sh_div <= divisor;
                bit_idx <= 4'd0;
                bit_timer <= {divisor, 4'd0} - 20'd1;
                txd <= 1'b0;
                tx_rd <= tx_rd + 4'd1;
            end
            tx_cnt <= tx_cnt + {4'd0, tx_push} - {4'd0, tx_pop};
            // THR-empty interrupt: raised when the FIFO drains, cleared by a THR write or by
            // reading IIR while it is the reported source.
            if (tx_pop && tx_cnt == 5'd1 && !tx_push) thre_ip <= 1'b1;
            if (rd_iir && iir_id == 4'h2) thre_ip <= 1'b0;
            if (wr_thr) thre_ip <= 1'b0;

            // register writes
            if (sel && !addr_hi) begin
                if (wstrb[0] && dlab) dll <= wdata[7:0];
                if (wstrb[1]) begin
                    if (dlab) dlm <= wdata[15:8];
                    else begin
                        ier <= {4'd0, wdata[11:8]};
                        if (wdata[9] && !ier[1] && tx_cnt == 5'd0) thre_ip <= 1'b1;
                    end
                end
                if (wr_fcr) begin
                    fifo_en <= wdata[16];
                    rx_trig <= wdata[23:22];
                    if (wdata[17]) begin rx_rd <= 4'd0; rx_wr <= 4'd0; rx_cnt <= 5'd0; end
                    if (wdata[18]) begin tx_rd <= 4'd0; tx_wr <= 4'd0; tx_cnt <= 5'd0; end
                end
                if (wstrb[3]) lcr <= wdata[31:24];
            end
            if (sel && addr_hi) begin
                if (wstrb[0]) mcr <= wdata[7:0];
                if (wstrb[3]) scr <= wdata[31:24];
            end
        end
    end

endmodule

`default_nettype wire
