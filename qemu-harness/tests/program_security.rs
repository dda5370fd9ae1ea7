//! Acceptance, security: the real firmware in QEMU.
//!
//! * A late LBC: the car boots with no lower board. It keeps retrying the bring-up with
//!   growing delays (in its defmt log), its radio runs without a key meanwhile (no command is
//!   taken, under the public default key or any other), and once the LBC answers it takes the
//!   key provisioned in the EEPROM; no radio command can read that key.
//! * A replay after a reboot: a command recorded on the air before the firmware restarts is
//!   not executed when it is sent again after the restart, although the ground station that
//!   signed it is still running.

use std::time::Duration;

use lbc_emu::{EepromImage, Lbc, LbcConfig, MemoryStore};
use lbc_link::{Command, Duty, EepromAddress, GpioPattern, GpioRate};
use qemu_harness::{firmware_elf, skip_qemu_tests, Level, Qemu, SocketSpec, UartAttach};
use radio_mac::Key;
use ubc_app::program::console::{LbcOutcome, Refusal, Reply, Request};
use ubc_app::program::{BOOT_REGISTER, DEFAULT_KEY};

mod program_common;
use program_common::{Ground, LbcServer, Relay, BOOT_TIMEOUT, CAR};

const REAL_KEY: [u8; 16] = *b"provisioned-key!";

fn spawn(test: &str, front: &std::path::Path) -> Qemu {
    let elf = firmware_elf().unwrap_or_else(|e| panic!("{test}: no firmware: {e}"));
    let qemu = Qemu::builder(&elf)
        .lbc(UartAttach::Connect(SocketSpec::Unix(front.to_path_buf())))
        .spawn()
        .unwrap_or_else(|e| panic!("{test}: cannot start QEMU: {e}"));
    qemu.wait_for_log(
        |l| l.level == Some(Level::Info) && l.message.starts_with("ubc-app "),
        BOOT_TIMEOUT,
    )
    .unwrap_or_else(|e| panic!("{test}: no banner: {e}\n{}", qemu.stderr_text()));
    qemu
}

fn messages(qemu: &Qemu) -> Vec<String> {
    qemu.log().lines().into_iter().map(|l| l.message).collect()
}

#[test]
fn a_late_lbc_leaves_the_car_deaf_until_it_answers_and_the_key_stays_unreadable() {
    const TEST: &str =
        "a_late_lbc_leaves_the_car_deaf_until_it_answers_and_the_key_stays_unreadable";
    if skip_qemu_tests(TEST) {
        return;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let emu = dir.path().join("lbc-emu.sock");
    let front = dir.path().join("lbc-relay.sock");
    // The relay is up, the LBC is not: the UBC's UART talks into the void.
    let _relay = Relay::start(&front, &emu);
    let mut qemu = spawn(TEST, &front);
    let radio = qemu.take_radio().expect("radio uart");
    // Someone on the channel with the public default key, and the car's own station.
    let mut public = Ground::with_key(radio, DEFAULT_KEY);
    public.car = 126;
    public.run_for(Duration::from_secs(4));
    assert_eq!(
        public.try_request(&Request::Status, Duration::from_secs(3)),
        None,
        "a car without its LBC answered a default-key command"
    );
    let read_key = Request::Lbc(Command::ReadEp(EepromAddress::new(0x38).unwrap()));
    assert_eq!(public.try_request(&read_key, Duration::from_secs(2)), None);
    let log = messages(&qemu);
    assert!(
        log.iter().any(|m| m == "radio up: car=126 keyed=false"),
        "{log:#?}"
    );
    let retries: Vec<u32> = log
        .iter()
        .filter_map(|m| m.split("retry in ").nth(1))
        .filter_map(|r| r.trim_end_matches(" ms").parse().ok())
        .collect();
    assert!(retries.len() >= 4, "{log:#?}");
    assert!(retries.windows(2).all(|w| w[0] <= w[1]), "{retries:?}");
    assert_eq!(retries.last(), Some(&2_000), "{retries:?}");

    // The LBC appears, with a provisioned key.
    let mut image = EepromImage::factory(CAR);
    for (i, w) in Key::new(REAL_KEY).to_eeprom_words().into_iter().enumerate() {
        image.set(0x38 + i as u8, w);
    }
    let mut cfg = LbcConfig::default();
    cfg.log = true;
    let lbc = LbcServer::start_with(&emu, Lbc::new(cfg, image, Box::new(MemoryStore::default())));
    qemu.wait_for_log(
        |l| l.message == format!("radio up: car={CAR} keyed=true"),
        Duration::from_secs(20),
    )
    .unwrap_or_else(|e| panic!("{e}: {:#?}", messages(&qemu)));
    public.car = CAR;
    assert_eq!(
        public.try_request(&Request::Status, Duration::from_secs(3)),
        None,
        "the provisioned car answered the default key"
    );
    // The car's own station: answered, but the key registers are refused.
    let radio = qemu.take_radio();
    assert!(radio.is_none(), "one radio UART");
    let mut own = public;
    own = Ground::with_key(own.into_uart(), REAL_KEY);
    match own.request(&Request::Status, Duration::from_secs(10)) {
        Reply::Status(s) => assert_eq!(s.car_id, CAR),
        other => panic!("{other:?}"),
    }
    for reg in [0x38, 0x3F, BOOT_REGISTER] {
        let req = Request::Lbc(Command::ReadEp(EepromAddress::new(reg).unwrap()));
        assert_eq!(
            own.request(&req, Duration::from_secs(10)),
            Reply::Refused(Refusal::Protected),
            "READ_EP {reg:#x}"
        );
    }
    let reads: Vec<Command> = lbc
        .commands()
        .into_iter()
        .filter(|c| matches!(c, Command::ReadEp(a) if a.get() >= 0x38))
        .collect();
    assert_eq!(reads.len(), 8, "only the bring-up read the key: {reads:?}");
    let _ = qemu.kill();
}

#[test]
fn a_command_recorded_before_a_reboot_is_not_executed_after_it() {
    const TEST: &str = "a_command_recorded_before_a_reboot_is_not_executed_after_it";
    let Some(mut rig) = program_common::boot(TEST) else {
        return;
    };
    rig.ground
        .wait_status(Duration::from_secs(20), |s| s.phase == 2);
    let pattern = |d: u8| GpioPattern::new(GpioRate::Hz10, Duty::new(d).unwrap());
    let gpo = |d: u8| Command::WritGpo {
        gpio0: pattern(d),
        gpio1: pattern(d),
    };
    let start = rig.ground.tape.len();
    assert!(matches!(
        rig.ground
            .request(&Request::Lbc(gpo(7)), Duration::from_secs(10)),
        Reply::Lbc(LbcOutcome::Answer(_))
    ));
    let recorded = rig.ground.tape[start..].to_vec();

    let lbc = rig.lbc.as_ref().expect("lbc");
    let runs = |lbc: &LbcServer| lbc.commands().iter().filter(|c| **c == gpo(7)).count();
    assert_eq!(runs(lbc), 1);
    // The firmware restarts; the LBC and the ground station keep running.
    let _ = rig.qemu.kill();
    let front = rig.dir.path().join("lbc-relay.sock");
    rig.qemu = spawn(TEST, &front);
    rig.ground
        .reattach(rig.qemu.take_radio().expect("radio uart"));
    rig.qemu
        .wait_for_log(
            |l| l.message == format!("radio up: car={CAR} keyed=true"),
            Duration::from_secs(20),
        )
        .unwrap_or_else(|e| panic!("{e}: {:#?}", messages(&rig.qemu)));
    // The recorded frames again, right after the restart, and once the car rejoined the
    // station's session (its Hello is answered within a second) but before the station sent
    // it anything new.
    rig.ground.inject(&recorded);
    rig.ground.run_for(Duration::from_millis(1_500));
    assert!(
        rig.ground.stats().sessions_opened >= 2,
        "the car did not rejoin"
    );
    for _ in 0..20 {
        rig.ground.inject(&recorded);
    }
    rig.ground.run_for(Duration::from_millis(500));
    let lbc = rig.lbc.as_ref().expect("lbc");
    assert_eq!(
        runs(lbc),
        1,
        "the recorded command ran again after the reboot"
    );
    // The car did receive them (every radio frame counts), and the ground station still
    // commands it.
    match rig
        .ground
        .request(&Request::Stats(2), Duration::from_secs(10))
    {
        Reply::Stats { values, .. } => assert!(values[0] >= 21, "{values:?}"),
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        rig.ground
            .request(&Request::Lbc(gpo(5)), Duration::from_secs(10)),
        Reply::Lbc(LbcOutcome::Answer(_))
    ));
    rig.shutdown();
}
