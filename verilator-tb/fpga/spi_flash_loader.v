// Boot loader: copies the program image from the configuration SPI flash into the SoC's RAM
// through its back-door port while the core is held in reset, then sets `done`. It wakes the
// flash (0xAB: the iCE40 may leave it in deep power-down after configuration), waits 256
// clocks, then reads WORDS words from byte offset OFFSET with one READ (0x03) command, SPI
// mode 0 at half the clock rate. Words are little-endian, as in an ELF's segments.
`default_nettype none

module spi_flash_loader #(
    parameter integer AW = 10,              // RAM word-address bits; WORDS = 2^AW
    parameter [23:0]  OFFSET = 24'h10_0000  // image offset in the flash (1 MiB)
) (
    input  wire          clk,
    input  wire          rst,
    output reg           sck,
    output reg           csn,
    output reg           mosi,
    input  wire          miso,
    output reg           bd_we,
    output reg  [AW-1:0] bd_addr,
    output reg  [31:0]   bd_wdata,
    output reg           done
);
    localparam [2:0] WAKE = 3'd0, GAP = 3'd1, CMD = 3'd2, DATA = 3'd3, FIN = 3'd4;
    reg [2:0]  state;
    reg [31:0] out;                 // bits still to send, MSB first
    reg [5:0]  nbits;               // bits left in the current transfer
    reg [8:0]  wait_n;
    reg [31:0] in;
    reg [AW:0] word;
    reg        phase;               // 0: SCK low half, 1: SCK high half

    always @(posedge clk) begin
        bd_we <= 1'b0;
        if (rst) begin
            state <= WAKE;
            csn <= 1'b1;
            sck <= 1'b0;
            mosi <= 1'b0;
            done <= 1'b0;
            out <= {8'hab, 24'd0};
            nbits <= 6'd8;
            phase <= 1'b0;
            wait_n <= 9'd0;
            word <= {(AW+1){1'b0}};
        end else begin
            case (state)
                WAKE, CMD: begin
                    // shift `out` out: MOSI changes while SCK is low, the flash samples on the rise
                    csn <= 1'b0;
                    if (!phase) begin
                        if (nbits == 6'd0) begin
                            sck <= 1'b0;
                            if (state == WAKE) begin
                                csn <= 1'b1;
                                state <= GAP;
                            end else begin
                                state <= DATA;
                                nbits <= 6'd32;
                            end
                        end else begin
                            sck <= 1'b0;
                            mosi <= out[31];
                            out <= {out[30:0], 1'b0};
                            nbits <= nbits - 6'd1;
                            phase <= 1'b1;
                        end
                    end else begin
                        sck <= 1'b1;
                        phase <= 1'b0;
                    end
                end
                GAP: begin
                    wait_n <= wait_n + 9'd1;
                    if (wait_n == 9'd255) begin
                        state <= CMD;
                        out <= {8'h03, OFFSET};
                        nbits <= 6'd32;
                    end
                end
                DATA: begin
                    // the flash shifts on the falling edge; the bit is read with the rise
                    if (!phase) begin
                        sck <= 1'b1;
                        phase <= 1'b1;
                    end else begin
                        sck <= 1'b0;
                        phase <= 1'b0;
                        // bytes arrive MSB first; the word is assembled little-endian
                        in <= {in[30:0], miso};
                        nbits <= nbits - 6'd1;
                        if (nbits == 6'd1) begin
                            bd_we <= 1'b1;
                            bd_addr <= word[AW-1:0];
                            bd_wdata <= {in[6:0], miso, in[14:7], in[22:15], in[30:23]};
                            word <= word + {{AW{1'b0}}, 1'b1};
                            nbits <= 6'd32;
                            if (word[AW-1:0] == {AW{1'b1}}) state <= FIN;
                        end
                    end
                end
                default: begin
                    csn <= 1'b1;
                    sck <= 1'b0;
                    done <= 1'b1;
                end
            endcase
        end
    end
endmodule

`default_nettype wire
