//! Feeds arbitrary bytes to the readers of the FPGA tools' output (yosys's log, nextpnr's log
//! and JSON report): they must return figures or nothing, never panic.
#![no_main]

use fpga::report::{logic_cells_from_log, utilization, Cells, Timing};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let _ = Cells::from_yosys_log(&text);
    let _ = logic_cells_from_log(&text);
    if let Ok(report) = serde_json::from_slice::<serde_json::Value>(data) {
        let timing = Timing::from_report(&report);
        for clock in timing.fmax_mhz.keys() {
            let _ = timing.fmax_of(clock);
            let _ = timing.dsp_bound_mhz(clock);
            let _ = timing.critical(clock);
        }
        let _ = utilization(&report);
    }
});
