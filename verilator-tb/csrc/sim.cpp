// vtb-sim: the Verilated SoC as a child process of the Rust harness. It reads requests on stdin
// and answers on stdout in a compact little-endian binary protocol (see `src/model.rs`, which
// holds the authoritative description). Work is batched: one RUN request advances the clock up
// to N cycles and returns every RVFI record and output event of the batch. End of input ends
// the process; on Linux it also asks to be killed when its parent dies.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <vector>
#include "Vsoc.h"
#include "Vsoc___024root.h"
#include "verilated.h"
#ifdef __linux__
#include <csignal>
#include <sys/prctl.h>
#endif

namespace {

enum Op : uint8_t {
    OP_LOAD = 1,
    OP_FRAME = 2,
    OP_RX = 3,
    OP_IRQ = 4,
    OP_RELEASE = 5,
    OP_RUN = 6,
    OP_HELLO = 7,
    OP_CAMERA = 8,
};

enum RunFlag : uint8_t {
    RUN_RVFI = 1,
    RUN_STOP_ON_EVENT = 2,
};

enum EventKind : uint8_t {
    EV_UART0_TX = 0,
    EV_UART1_TX = 1,
    EV_CONSOLE = 2,
    EV_EXIT = 3,
};

constexpr uint32_t PROTOCOL_VERSION = 2;
constexpr uint32_t RAM_WORDS = 1u << 18;
constexpr uint32_t FMEM_BYTES = 0x130000;

[[noreturn]] void die(const char* why) {
    std::fprintf(stderr, "vtb-sim: %s\n", why);
    std::exit(2);
}

bool read_exact(void* dst, size_t n) {
    return std::fread(dst, 1, n, stdin) == n;
}

template <typename T>
T get() {
    T v;
    if (!read_exact(&v, sizeof v)) std::exit(0);  // harness closed the pipe: done
    return v;
}

struct Out {
    std::vector<uint8_t> buf;
    template <typename T>
    void put(T v) {
        const uint8_t* p = reinterpret_cast<const uint8_t*>(&v);
        buf.insert(buf.end(), p, p + sizeof v);
    }
    void flush() {
        if (!buf.empty() && std::fwrite(buf.data(), 1, buf.size(), stdout) != buf.size())
            std::exit(0);
        if (std::fflush(stdout) != 0) std::exit(0);
        buf.clear();
    }
};

struct Rx {
    uint64_t cycle;
    uint8_t byte;
};

// A frame on the camera's pixel stream: pixel (x, y) in cycle first + y * line + x, the row's
// end in cycle first + y * line + width, the frame's end right after the last row's.
struct CamFrame {
    uint64_t first;
    uint32_t width, height, line;
    std::vector<uint8_t> codes;
};

struct Sim {
    VerilatedContext ctx;
    Vsoc* top = nullptr;
    uint64_t cycle = 0;  // clocks since reset was released
    uint64_t retired = 0;
    uint64_t sleep_cycles = 0;
    std::deque<Rx> rx[2];
    std::deque<CamFrame> cam;

    void tick() {
        top->clk = 1;
        top->eval();
        top->clk = 0;
        top->eval();
    }
};

void load(Sim& s) {
    uint32_t first = get<uint32_t>();
    uint32_t count = get<uint32_t>();
    Vsoc* t = s.top;
    t->rst = 1;
    for (uint32_t i = 0; i < count; i++) {
        t->bd_we = 1;
        t->bd_addr = (first + i) & (RAM_WORDS - 1);
        t->bd_wdata = get<uint32_t>();
        s.tick();
    }
    t->bd_we = 0;
}

void frame(Sim& s) {
    uint32_t offset = get<uint32_t>();
    uint32_t len = get<uint32_t>();
    auto& mem = s.top->rootp->soc__DOT__fmem;
    for (uint32_t i = 0; i < len; i++) {
        uint8_t b = get<uint8_t>();
        uint64_t at = uint64_t(offset) + i;
        if (at >= FMEM_BYTES) continue;  // the harness checks bounds; never write outside
        uint32_t shift = (at & 3) * 8;
        uint32_t& w = mem[at >> 2];
        w = (w & ~(0xffu << shift)) | (uint32_t(b) << shift);
    }
}

void camera(Sim& s) {
    CamFrame f;
    f.first = get<uint64_t>();
    f.width = get<uint16_t>();
    f.height = get<uint16_t>();
    uint32_t h_blank = get<uint32_t>();
    f.line = f.width + h_blank;
    f.codes.resize(size_t(f.width) * f.height);
    if (!f.codes.empty() && !read_exact(f.codes.data(), f.codes.size())) std::exit(0);
    if (f.width == 0 || f.height == 0 || h_blank == 0) die("empty camera frame");
    s.cam.push_back(std::move(f));
}

// The camera port's inputs for cycle `c` (frames queue in order and never overlap).
void drive_camera(Sim& s, uint64_t c) {
    Vsoc* t = s.top;
    t->cam_valid = 0;
    t->cam_eol = 0;
    t->cam_eof = 0;
    while (!s.cam.empty()) {
        const CamFrame& f = s.cam.front();
        if (c < f.first) return;
        uint64_t rel = c - f.first;
        uint64_t eof = uint64_t(f.height - 1) * f.line + f.width + 1;
        if (rel == eof) {
            t->cam_eof = 1;
            return;
        }
        if (rel < eof) {
            uint64_t x = rel % f.line;
            if (x < f.width) {
                t->cam_valid = 1;
                t->cam_data = f.codes[(rel / f.line) * f.width + x];
            } else if (x == f.width) {
                t->cam_eol = 1;
            }
            return;
        }
        s.cam.pop_front();
    }
}

void run(Sim& s, Out& out) {
    uint64_t max_cycles = get<uint64_t>();
    uint8_t flags = get<uint8_t>();
    Vsoc* t = s.top;
    const bool want_rvfi = flags & RUN_RVFI;
    const bool stop_on_event = flags & RUN_STOP_ON_EVENT;
    // Header is patched once the counts are known.
    out.buf.assign(8 + 8 + 8 + 4 + 4, 0);
    std::vector<uint8_t> rvfi;
    uint32_t n_events = 0, n_rvfi = 0;
    uint64_t n = 0;
    uint64_t next_rx[2];
    for (int u = 0; u < 2; u++) next_rx[u] = s.rx[u].empty() ? UINT64_MAX : s.rx[u].front().cycle;
    auto event = [&](uint8_t kind, uint8_t byte, uint32_t value) {
        out.put<uint64_t>(s.cycle);
        out.put<uint8_t>(kind);
        out.put<uint8_t>(byte);
        out.put<uint32_t>(value);
        n_events++;
    };
    while (n < max_cycles) {
        t->uart0_rx_valid = 0;
        t->uart1_rx_valid = 0;
        if (s.cycle >= next_rx[0]) {
            t->uart0_rx_valid = 1;
            t->uart0_rx_data = s.rx[0].front().byte;
            s.rx[0].pop_front();
            next_rx[0] = s.rx[0].empty() ? UINT64_MAX : s.rx[0].front().cycle;
        }
        if (s.cycle >= next_rx[1]) {
            t->uart1_rx_valid = 1;
            t->uart1_rx_data = s.rx[1].front().byte;
            s.rx[1].pop_front();
            next_rx[1] = s.rx[1].empty() ? UINT64_MAX : s.rx[1].front().cycle;
        }
        drive_camera(s, s.cycle);
        s.sleep_cycles += t->core_sleeping;  // state of the cycle that this edge ends
        s.tick();
        n++;
        s.cycle++;
        if (t->rvfi_valid) {
            s.retired++;
            if (want_rvfi) {
                Out r;
                r.buf.swap(rvfi);
                r.put<uint64_t>(s.cycle);
                r.put<uint64_t>(t->rvfi_order);
                r.put<uint32_t>(t->rvfi_insn);
                r.put<uint32_t>(t->rvfi_pc_rdata);
                r.put<uint32_t>(t->rvfi_pc_wdata);
                r.put<uint32_t>(t->rvfi_rd_wdata);
                r.put<uint32_t>(t->rvfi_mem_addr);
                r.put<uint32_t>(t->rvfi_mem_rdata);
                r.put<uint32_t>(t->rvfi_mem_wdata);
                r.put<uint8_t>(t->rvfi_trap);
                r.put<uint8_t>(t->rvfi_intr);
                r.put<uint8_t>(t->rvfi_rd_addr);
                r.put<uint8_t>(t->rvfi_mem_rmask);
                r.put<uint8_t>(t->rvfi_mem_wmask);
                r.put<uint8_t>(t->rvfi_ext_mip);
                r.put<uint8_t>(t->rvfi_ext_intr_mip);
                r.buf.swap(rvfi);
                n_rvfi++;
            }
        }
        if (t->uart0_tx_valid | t->uart1_tx_valid | t->console_valid | t->sim_exit_valid) {
            if (t->uart0_tx_valid) event(EV_UART0_TX, t->uart0_tx_data, 0);
            if (t->uart1_tx_valid) event(EV_UART1_TX, t->uart1_tx_data, 0);
            if (t->console_valid) event(EV_CONSOLE, t->console_data, 0);
            if (t->sim_exit_valid) {
                event(EV_EXIT, 0, t->sim_exit_value);
                break;
            }
            if (stop_on_event) break;
        }
    }
    uint8_t* h = out.buf.data();
    std::memcpy(h, &n, 8);
    std::memcpy(h + 8, &s.retired, 8);
    std::memcpy(h + 16, &s.sleep_cycles, 8);
    std::memcpy(h + 24, &n_events, 4);
    std::memcpy(h + 28, &n_rvfi, 4);
    out.buf.insert(out.buf.end(), rvfi.begin(), rvfi.end());
    out.flush();
}

}  // namespace

int main(int argc, char** argv) {
#ifdef __linux__
    prctl(PR_SET_PDEATHSIG, SIGKILL);
#endif
    static char inbuf[1 << 16];
    static char outbuf[1 << 16];
    std::setvbuf(stdin, inbuf, _IOFBF, sizeof inbuf);
    std::setvbuf(stdout, outbuf, _IOFBF, sizeof outbuf);

    Sim s;
    s.ctx.commandArgs(argc, argv);
    s.ctx.fatalOnError(false);
    s.top = new Vsoc(&s.ctx, "soc");
    Vsoc* t = s.top;
    t->clk = 0;
    t->rst = 1;
    t->eval();
    s.tick();
    s.tick();

    Out out;
    for (;;) {
        uint8_t op = get<uint8_t>();
        switch (op) {
            case OP_HELLO:
                out.put<uint32_t>(PROTOCOL_VERSION);
                out.flush();
                break;
            case OP_LOAD:
                load(s);
                break;
            case OP_FRAME:
                frame(s);
                break;
            case OP_RX: {
                uint8_t uart = get<uint8_t>();
                uint64_t at = get<uint64_t>();
                uint8_t byte = get<uint8_t>();
                if (uart > 1) die("RX for an unknown UART");
                s.rx[uart].push_back(Rx{at, byte});
                break;
            }
            case OP_IRQ:
                t->tb_meip = get<uint8_t>() != 0;
                break;
            case OP_RELEASE:
                // One more clock in reset fetches the first instruction of the loaded image.
                // Reset ends right after that rising edge, as from a register clocked by it:
                // the RAM reads on the falling edge, with the fetch address of a running core.
                t->rst = 1;
                t->clk = 1;
                t->eval();
                t->rst = 0;
                t->clk = 0;
                t->eval();
                s.cycle = 0;
                break;
            case OP_RUN:
                run(s, out);
                break;
            case OP_CAMERA:
                camera(s);
                break;
            default:
                die("unknown request");
        }
    }
}
