//! Acceptance: the firmware boots in QEMU and its defmt banner is decoded on the host.

mod common;

#[test]
fn banner_is_decoded() {
    let Some((qemu, banner)) = common::boot("banner_is_decoded", common::Firmware::Program) else {
        return;
    };
    let version = banner.word_after("ubc-app").unwrap_or_default();
    assert!(
        !version.is_empty() && version.split('.').all(|p| p.parse::<u32>().is_ok()),
        "version `{version}` in {banner}"
    );
    assert_eq!(banner.field("board"), Some("qemu_virt"), "{banner}");
    let hz: u64 = banner
        .field("timebase")
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("timebase in {banner}"));
    assert!(hz > 0, "{banner}");
    assert!(banner.message.ends_with(" Hz"), "{banner}");
    assert_eq!(qemu.log().malformed_frames(), 0, "undecodable log frames");
    eprintln!("boot: {banner}");
}
