// C ABI around the Verilated SoC model: one call advances the clock by one or more cycles and
// exchanges all port values through a plain struct.
#include <cstdint>
#include "Vsoc.h"
#include "verilated.h"

extern "C" {

struct VtbIo {
    // inputs
    uint8_t rst;
    uint8_t tb_meip;
    uint8_t uart0_rx_valid;
    uint8_t uart0_rx_data;
    uint8_t uart1_rx_valid;
    uint8_t uart1_rx_data;
    // outputs
    uint8_t uart0_tx_valid;
    uint8_t uart0_tx_data;
    uint8_t uart1_tx_valid;
    uint8_t uart1_tx_data;
    uint8_t sim_exit_valid;
    uint8_t console_valid;
    uint8_t console_data;
    uint8_t rvfi_valid;
    uint8_t rvfi_trap;
    uint8_t rvfi_intr;
    uint8_t rvfi_rd_addr;
    uint8_t rvfi_mem_rmask;
    uint8_t rvfi_mem_wmask;
    uint8_t rvfi_ext_mip;
    uint8_t rvfi_ext_intr_mip;
    uint32_t sim_exit_value;
    uint64_t rvfi_order;
    uint32_t rvfi_insn;
    uint32_t rvfi_pc_rdata;
    uint32_t rvfi_pc_wdata;
    uint32_t rvfi_rd_wdata;
    uint32_t rvfi_mem_addr;
    uint32_t rvfi_mem_rdata;
    uint32_t rvfi_mem_wdata;
    // retirements counted by vtb_run since the model was created
    uint64_t retired;
    // cycles the core spent asleep in WFI
    uint64_t sleep_cycles;
};

struct VtbModel {
    VerilatedContext ctx;
    Vsoc* top;
};

VtbModel* vtb_new() {
    VtbModel* m = new VtbModel;
    m->ctx.fatalOnError(false);
    m->top = new Vsoc(&m->ctx, "soc");
    m->top->clk = 0;
    m->top->rst = 1;
    m->top->eval();
    return m;
}

void vtb_free(VtbModel* m) {
    if (!m) return;
    m->top->final();
    delete m->top;
    delete m;
}

static inline void tick(Vsoc* t) {
    t->clk = 1;
    t->eval();
    t->clk = 0;
    t->eval();
}

static inline void read_outputs(const Vsoc* t, VtbIo* io) {
    io->uart0_tx_valid = t->uart0_tx_valid;
    io->uart0_tx_data = t->uart0_tx_data;
    io->uart1_tx_valid = t->uart1_tx_valid;
    io->uart1_tx_data = t->uart1_tx_data;
    io->sim_exit_valid = t->sim_exit_valid;
    io->sim_exit_value = t->sim_exit_value;
    io->console_valid = t->console_valid;
    io->console_data = t->console_data;
    io->rvfi_valid = t->rvfi_valid;
    io->rvfi_trap = t->rvfi_trap;
    io->rvfi_intr = t->rvfi_intr;
    io->rvfi_rd_addr = t->rvfi_rd_addr;
    io->rvfi_mem_rmask = t->rvfi_mem_rmask;
    io->rvfi_mem_wmask = t->rvfi_mem_wmask;
    io->rvfi_ext_mip = t->rvfi_ext_mip;
    io->rvfi_ext_intr_mip = t->rvfi_ext_intr_mip;
    io->rvfi_order = t->rvfi_order;
    io->rvfi_insn = t->rvfi_insn;
    io->rvfi_pc_rdata = t->rvfi_pc_rdata;
    io->rvfi_pc_wdata = t->rvfi_pc_wdata;
    io->rvfi_rd_wdata = t->rvfi_rd_wdata;
    io->rvfi_mem_addr = t->rvfi_mem_addr;
    io->rvfi_mem_rdata = t->rvfi_mem_rdata;
    io->rvfi_mem_wdata = t->rvfi_mem_wdata;
}

// Writes `len` words into RAM starting at word index `first` (one clock per word, core held in
// reset). Leaves the core in reset.
void vtb_load(VtbModel* m, uint32_t first, const uint32_t* words, uint32_t len) {
    Vsoc* t = m->top;
    t->rst = 1;
    for (uint32_t i = 0; i < len; i++) {
        t->bd_we = 1;
        t->bd_addr = (first + i) & 0x3ffff;
        t->bd_wdata = words[i];
        tick(t);
    }
    t->bd_we = 0;
}

// Runs up to `max_cycles` cycles with the inputs in `io`. The RX strobes are applied in the
// first cycle only. Stops after the first cycle that produced any output event, or any
// retirement when `stop_on_retire` is set. Returns the number of cycles run.
uint64_t vtb_run(VtbModel* m, VtbIo* io, uint64_t max_cycles, uint8_t stop_on_retire) {
    Vsoc* t = m->top;
    t->rst = io->rst;
    t->tb_meip = io->tb_meip;
    t->uart0_rx_valid = io->uart0_rx_valid;
    t->uart0_rx_data = io->uart0_rx_data;
    t->uart1_rx_valid = io->uart1_rx_valid;
    t->uart1_rx_data = io->uart1_rx_data;
    uint64_t n = 0;
    while (n < max_cycles) {
        io->sleep_cycles += t->core_sleeping;  // state of the cycle that this edge ends
        tick(t);
        n++;
        io->retired += t->rvfi_valid;
        t->uart0_rx_valid = 0;
        t->uart1_rx_valid = 0;
        if (t->uart0_tx_valid || t->uart1_tx_valid || t->sim_exit_valid || t->console_valid ||
            (stop_on_retire && t->rvfi_valid))
            break;
    }
    read_outputs(t, io);
    return n;
}

}  // extern "C"
