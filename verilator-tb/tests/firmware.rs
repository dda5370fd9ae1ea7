//! Boots a `softcore` build of the firmware (path in `VTB_FIRMWARE`) against the emulated LBC:
//! the banner must name the board and the LBC link must come up. Without `VTB_FIRMWARE` the
//! test says so and does nothing (the image is built by `cargo xtask fw --board softcore`).
use lbc_emu::{Lbc, LbcConfig};
use qemu_harness::{Level, LineDecoder, LogFormat};
use std::time::Instant;
use verilator_tb::cosim::LbcCosim;
use verilator_tb::soc::{Event, Soc, CLOCK_HZ};

#[test]
fn softcore_firmware_boots_and_brings_up_the_lbc() {
    let Some(path) = std::env::var_os("VTB_FIRMWARE") else {
        eprintln!("VTB_FIRMWARE not set: skipping the firmware boot test");
        return;
    };
    let path = std::path::PathBuf::from(path);
    let elf = std::fs::read(&path).expect("VTB_FIRMWARE is readable");
    let format = LogFormat::from_elf_bytes(&elf, &path).expect("defmt table");
    let mut soc = Soc::new();
    soc.load_elf(&elf).expect("a softcore image");
    let mut cosim = LbcCosim::new(soc, Lbc::with_memory_eeprom(LbcConfig::default(), 3));
    let mut decoder = LineDecoder::new(&format);
    let mut lines = Vec::new();
    // bring-up retries with back-off; 2 simulated seconds are plenty
    for _ in 0..20 {
        for e in cosim.run(u64::from(CLOCK_HZ) / 10) {
            if let Event::Console(b) = e.value {
                decoder.push(&[b], Instant::now(), &mut lines);
            }
        }
        if lines.iter().any(|l| l.is(Level::Info, "lbc up")) {
            break;
        }
    }
    assert!(
        lines.iter().any(|l| l.is(Level::Info, "board=softcore")),
        "no banner: {lines:#?}"
    );
    assert!(
        lines.iter().any(|l| l.is(Level::Info, "lbc up: car=3")),
        "{lines:#?}"
    );
}
