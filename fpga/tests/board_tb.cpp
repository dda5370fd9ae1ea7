// Test bench for the board-level SoC (verilator-tb/fpga/fpga_soc.v), built by
// fpga/tests/board_sim.rs: a SPI flash that serves the program image at 1 MiB, both UARTs'
// serial lines decoded and driven at 16 * divisor clocks per bit, and a parallel camera that
// sends one small frame. Usage:
//   Vtb IMAGE BIT_CLOCKS MAX_CYCLES AFTER INPUT FRAME_HEX
// INPUT is sent on UART0, one byte every 40 character times, once AFTER bytes have come back
// on UART0. FRAME_HEX (bytes as hex) is sent by the camera once the SoC is out of reset.
// Prints `uart0 HEX`, `uart1 HEX`, `exit pass|none` and `cycles N`.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>
#include "Vfpga_soc.h"
#include "verilated.h"

namespace {

struct Flash {
    std::vector<uint8_t> image;  // at offset 1 MiB
    bool prev_sck = false, prev_csn = true;
    uint32_t bits = 0, cmd = 0, addr = 0;
    int miso = 1;

    uint8_t byte_at(uint32_t a) const {
        uint32_t off = a - 0x100000u;
        return a >= 0x100000u && off < image.size() ? image[off] : 0xff;
    }
    void step(bool csn, bool sck, bool mosi) {
        if (csn) {
            bits = 0;
            cmd = 0;
            addr = 0;
        } else if (sck && !prev_sck) {
            if (bits < 8) cmd = (cmd << 1) | (mosi ? 1u : 0u);
            else if (bits < 32) addr = (addr << 1) | (mosi ? 1u : 0u);
            bits++;
        } else if (!sck && prev_sck && cmd == 0x03 && bits >= 32) {
            uint32_t k = bits - 32;  // data bits already sent
            miso = (byte_at(addr + k / 8) >> (7 - k % 8)) & 1;
        }
        prev_sck = sck;
        prev_csn = csn;
    }
};

struct LineRx {
    int bit_clocks;
    int state = -1;  // -1 idle, else clocks into the byte
    uint8_t shift = 0;
    std::vector<uint8_t> bytes;
    void step(bool line) {
        if (state < 0) {
            if (!line) state = 0;
            return;
        }
        state++;
        int mid = bit_clocks / 2;
        if (state >= mid && (state - mid) % bit_clocks == 0) {
            int bit = (state - mid) / bit_clocks;  // 0 start, 1..8 data, 9 stop
            if (bit >= 1 && bit <= 8) shift = (shift >> 1) | (line ? 0x80 : 0);
            if (bit == 9) {
                if (line) bytes.push_back(shift);
                state = -1;
            }
        }
    }
};

struct LineTx {
    int bit_clocks;
    std::vector<uint8_t> queue;
    int gap = 0;
    size_t next = 0;
    long t = -1;  // clocks into the current byte
    bool line() const {
        if (t < 0) return true;
        long bit = t / bit_clocks;
        if (bit == 0) return false;
        if (bit <= 8) return (queue[next] >> (bit - 1)) & 1;
        return true;
    }
    void step() {
        if (t < 0) {
            if (next < queue.size() && gap-- <= 0) t = 0;
            return;
        }
        if (++t >= 10L * bit_clocks) {
            t = -1;
            next++;
            gap = 40 * 10 * bit_clocks;
        }
    }
};

std::string hex(const std::vector<uint8_t>& v) {
    std::string s;
    char b[3];
    for (uint8_t x : v) {
        std::snprintf(b, sizeof b, "%02x", x);
        s += b;
    }
    return s.empty() ? "-" : s;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 7) {
        std::fprintf(stderr, "usage: Vtb IMAGE BIT_CLOCKS MAX_CYCLES AFTER INPUT FRAME_HEX\n");
        return 2;
    }
    Flash flash;
    if (FILE* f = std::fopen(argv[1], "rb")) {
        int c;
        while ((c = std::fgetc(f)) != EOF) flash.image.push_back(uint8_t(c));
        std::fclose(f);
    } else {
        std::fprintf(stderr, "cannot read %s\n", argv[1]);
        return 2;
    }
    const int bit_clocks = std::atoi(argv[2]);
    const long max_cycles = std::atol(argv[3]);
    const size_t after = std::strtoul(argv[4], nullptr, 10);
    const std::string input = argv[5];
    std::vector<uint8_t> frame;
    for (size_t i = 0; i + 1 < std::string(argv[6]).size(); i += 2)
        frame.push_back(uint8_t(std::strtoul(std::string(argv[6]).substr(i, 2).c_str(), nullptr, 16)));

    VerilatedContext ctx;
    Vfpga_soc top(&ctx);
    LineRx rx0{bit_clocks}, rx1{bit_clocks};
    LineTx tx0{bit_clocks};
    bool queued = false;
    // camera: after reset, VSYNC for 16 clocks, then the bytes with HREF, 8 clocks a pixel
    long cam_t = -1;
    top.pll_locked = 1;
    top.uart0_rxd = 1;
    top.uart1_rxd = 1;
    top.flash_miso = 1;
    top.cam_pclk = 0;
    top.cam_href = 0;
    top.cam_vsync = 0;
    top.cam_d = 0;
    top.clk = 0;
    top.eval();
    long cycle = 0;
    long pass_cycle = -1;
    for (; cycle < max_cycles; cycle++) {
        top.uart0_rxd = tx0.line();
        top.flash_miso = flash.miso;
        if (cam_t < 0 && (top.leds & 2)) cam_t = 0;  // "program loaded"
        if (cam_t >= 0) {
            long p = cam_t - 32;
            top.cam_vsync = cam_t >= 8 && cam_t < 24;
            bool in_frame = p >= 0 && p < long(frame.size()) * 8;
            top.cam_href = in_frame;
            top.cam_pclk = in_frame && (p % 8) >= 4;
            top.cam_d = in_frame ? frame[p / 8] : 0;
            cam_t++;
        }
        top.clk = 1;
        top.eval();
        flash.step(top.flash_csn, top.flash_sck, top.flash_mosi);
        top.clk = 0;
        top.eval();
        rx0.step(top.uart0_txd);
        rx1.step(top.uart1_txd);
        tx0.step();
        if (!queued && rx0.bytes.size() >= after) {
            tx0.queue.assign(input.begin(), input.end());
            queued = true;
        }
        if ((top.leds & 0x40) && pass_cycle < 0) pass_cycle = cycle;
        // after the pass write, let the last bytes leave the transmitters
        if (pass_cycle >= 0 && cycle > pass_cycle + 30L * 10 * bit_clocks) break;
    }
    std::printf("uart0 %s\nuart1 %s\nexit %s\ncycles %ld\n", hex(rx0.bytes).c_str(),
                hex(rx1.bytes).c_str(), pass_cycle >= 0 ? "pass" : "none", cycle);
    return 0;
}
