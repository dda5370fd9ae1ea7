//! End-to-end tests of `almc lbc decode` and `almc lbc encode`.

use std::process::{Command, Output};

fn almc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_almc"))
        .args(args)
        .output()
        .expect("almc runs")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn decode_names_read_id() {
    let o = almc(&["lbc", "decode", "e8", "68", "ff"]);
    assert!(o.status.success(), "{o:?}");
    assert!(stdout(&o).contains("READ_ID command"), "{}", stdout(&o));
}

#[test]
fn decode_accepts_all_spellings() {
    for args in [
        &["lbc", "decode", "0xE8,0x05,0x6D,0xFF"][..],
        &["lbc", "decode", "e8056dff"][..],
        &["lbc", "decode", "e8", "05", "6d", "ff"][..],
    ] {
        let o = almc(args);
        assert!(o.status.success(), "{args:?}: {o:?}");
        assert!(stdout(&o).contains("id=5"), "{}", stdout(&o));
    }
}

#[test]
fn corrupted_checksum_is_reported_with_failure_exit() {
    let o = almc(&["lbc", "decode", "e8", "69", "ff"]);
    assert_eq!(o.status.code(), Some(1));
    let out = stdout(&o);
    assert!(out.contains("bad checksum"), "{out}");
    assert!(out.contains("expected 0x68, got 0x69"), "{out}");
    assert!(!out.contains("READ_ID command"), "{out}");
}

#[test]
fn seed_upd_sf_error_example_is_rejected() {
    let o = almc(&["lbc", "decode", "b1", "30", "ff"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(stdout(&o).contains("expected 0x31, got 0x30"));
}

#[test]
fn invalid_hex_is_a_usage_error() {
    let o = almc(&["lbc", "decode", "e8", "zz"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("`zz` is not a hex byte"));
    assert!(o.stdout.is_empty());
}

#[test]
fn json_output_is_machine_readable() {
    let o = almc(&["lbc", "decode", "--json", "c1 02 40 03 60 60 ff", "01"]);
    assert_eq!(o.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).expect("valid JSON");
    assert_eq!(v["ok"], false);
    let m = &v["messages"];
    assert_eq!(m[0]["symbol"], "MOVE_XY");
    assert_eq!(m[0]["role"], "command_or_ack");
    assert_eq!(m[0]["value"]["MoveXy"]["x"], 320);
    assert_eq!(m[1]["type"], "error");
    assert_eq!(m[1]["detail"]["Garbage"]["byte"], 1);
}

#[test]
fn stream_is_decoded_with_a_format() {
    let bytes = "fc 02 40 03 60 42 01 1e ff";
    let o = almc(&["lbc", "decode", "--stream-format", "8002", bytes]);
    assert!(o.status.success(), "{o:?}");
    let out = stdout(&o);
    assert!(out.contains("position.x=320"), "{out}");
    assert!(out.contains("chip_status.temperature=66"), "{out}");
    let o = almc(&["lbc", "decode", "--stream-format", "e0", bytes]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn encode_prints_bytes() {
    let o = almc(&["lbc", "encode", "move-xy", "320", "480"]);
    assert!(o.status.success());
    assert_eq!(stdout(&o).trim(), "c1 02 40 03 60 60 ff");
    let o = almc(&[
        "lbc", "encode", "writ-led", "--green", "0x35", "--red", "0x0a",
    ]);
    assert_eq!(stdout(&o).trim(), "d2 35 0a 6d ff");
    let o = almc(&["lbc", "encode", "stop"]);
    assert_eq!(stdout(&o).trim(), "c0 40 ff");
    let o = almc(&["lbc", "encode", "move-sv", "-1", "-8192"]);
    assert!(o.status.success(), "{o:?}");
    assert!(stdout(&o).starts_with("c2 7f 7f 40 00"));
}

#[test]
fn encode_rejects_out_of_range_fields() {
    let o = almc(&["lbc", "encode", "move-xy", "700", "0"]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("x: 700 is out of range"), "{err}");
    let o = almc(&["lbc", "encode", "writ-ep", "0x05", "1"]);
    assert_eq!(o.status.code(), Some(2));
    let o = almc(&["lbc", "encode", "move-xy", "ten", "0"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn encode_then_decode_round_trips() {
    let o = almc(&["lbc", "encode", "upd-par", "7", "-3"]);
    let bytes = stdout(&o);
    let o = almc(&["lbc", "decode", bytes.trim()]);
    assert!(o.status.success());
    let out = stdout(&o);
    assert!(
        out.contains("param=ServoOffset") && out.contains("value=-3"),
        "{out}"
    );
}
