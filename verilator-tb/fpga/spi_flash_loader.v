// Boot loader: copies the program image from the configuration SPI flash into the SoC's RAM
// through its back-door port while the core is held in reset, then sets `done`. It wakes the
// flash (0xAB: the iCE40 may leave it in deep power-down after configuration), waits 256
// clocks, then reads 2^AW words from byte offset OFFSET with one READ (0x03) command, SPI
// mode 0 at half the clock rate. Words are little-endian, as in an ELF's segments. One shift
// register sends the commands and receives the words.
`default_nettype none

module spi_flash_loader #(
    parameter integer AW = 10,              // RAM word-address bits; 2^AW words are copied
    parameter [23:0]  OFFSET = 24'h10_0000  // image offset in the flash (1 MiB)
) (
    input  wire          clk,
    input  wire          rst,
    output reg           sck,
    output reg           csn,
    output wire          mosi,
    input  wire          miso,
    output reg           bd_we,
    output wire [AW-1:0] bd_addr,
    output wire [31:0]   bd_wdata,
    output reg           done
);
    localparam [1:0] WAKE = 2'd0, GAP = 2'd1, SEND = 2'd2, READ = 2'd3;
    reg [1:0]  state;
    reg [31:0] sr;                  // MSB leaves first on MOSI, MISO enters at bit 0
    reg [4:0]  nbits;               // bits left in the current transfer, minus one
    reg [7:0]  gap;
    reg [AW:0] word;                // words written so far
    reg        phase;               // SCK high half

    assign mosi = sr[31];
    assign bd_addr = word[AW-1:0];
    // bytes arrive MSB first, the first at the top of `sr`; the word is little-endian
    assign bd_wdata = {sr[7:0], sr[15:8], sr[23:16], sr[31:24]};

    always @(posedge clk) begin
        if (bd_we) word <= word + {{AW{1'b0}}, 1'b1};
        bd_we <= 1'b0;
        if (rst) begin
            state <= WAKE;
            csn <= 1'b1;
            sck <= 1'b0;
            done <= 1'b0;
            sr <= {8'hab, 24'd0};
            nbits <= 5'd7;
            phase <= 1'b0;
            gap <= 8'd0;
            word <= {(AW+1){1'b0}};
        end else if (done) begin
            csn <= 1'b1;
            sck <= 1'b0;
        end else if (state == GAP) begin
            // wake-up time (tRES1), then READ and the 24-bit address
            gap <= gap + 8'd1;
            if (gap == 8'hff) begin
                state <= SEND;
                sr <= {8'h03, OFFSET};
                nbits <= 5'd31;
            end
        end else if (csn) begin
            csn <= 1'b0;            // select a clock before the first SCK edge
        end else if (!phase) begin
            // SCK rises: the flash samples MOSI; the bit it drives is read at the fall
            sck <= 1'b1;
            phase <= 1'b1;
        end else begin
            sck <= 1'b0;
            phase <= 1'b0;
            sr <= {sr[30:0], miso};
            nbits <= nbits - 5'd1;
            if (nbits == 5'd0) begin
                case (state)
                    WAKE: begin
                        csn <= 1'b1;
                        state <= GAP;
                    end
                    SEND: state <= READ;   // the flash drives its first bit at this fall
                    default: begin
                        bd_we <= 1'b1;     // `sr` holds the word in the cycle after
                        if (word[AW-1:0] == {AW{1'b1}}) done <= 1'b1;
                    end
                endcase
            end
        end
    end
endmodule

`default_nettype wire
