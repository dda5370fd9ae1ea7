//! Every example message printed in seed chapter 3, byte for byte.

use lbc_link::{
    Command, CommandKind, DecodeError, DeframeError, Deframer, LbcMessage, RawMessage, Reply,
    MAX_FRAME_LEN,
};

/// Command examples: (symbol, bytes as printed).
const COMMANDS: &[(&str, [u8; 3])] = &[
    ("STOP", [0xC0, 0x40, 0xFF]),
    ("CALB_ST", [0xC8, 0x48, 0xFF]),
    ("CALB_DM", [0xC9, 0x49, 0xFF]),
    ("CALB_GS", [0xCA, 0x4A, 0xFF]),
    ("INIT", [0xE0, 0x60, 0xFF]),
    ("CMEP", [0xE1, 0x61, 0xFF]),
    ("RSEP", [0xE2, 0x62, 0xFF]),
    ("DRDS", [0xE3, 0x63, 0xFF]),
    ("DREN", [0xE4, 0x64, 0xFF]),
    ("STDS", [0xE5, 0x65, 0xFF]),
    ("STEN", [0xE6, 0x66, 0xFF]),
    ("READ_ID", [0xE8, 0x68, 0xFF]),
    ("READ_XY", [0xE9, 0x69, 0xFF]),
    ("READ_SV", [0xEA, 0x6A, 0xFF]),
    ("READ_AY", [0xEB, 0x6B, 0xFF]),
    ("READ_PRY", [0xEC, 0x6C, 0xFF]),
    ("READ_BT", [0xED, 0x6D, 0xFF]),
    ("READ_RS", [0xEE, 0x6E, 0xFF]),
    ("READ_HD", [0xEF, 0x6F, 0xFF]),
    ("READ_SF", [0xF0, 0x70, 0xFF]),
];

/// Specific-error examples: (symbol of the command, bytes as printed).
const ERRORS: &[(&str, [u8; 3])] = &[
    ("STOP", [0x80, 0x00, 0xFF]),
    ("MOVE_XY", [0x81, 0x01, 0xFF]),
    ("MOVE_SV", [0x82, 0x02, 0xFF]),
    ("CALB_ST", [0x88, 0x08, 0xFF]),
    ("CALB_DM", [0x89, 0x09, 0xFF]),
    ("CALB_GS", [0x8A, 0x0A, 0xFF]),
    ("WRIT_EP", [0x90, 0x10, 0xFF]),
    ("READ_EP", [0x91, 0x11, 0xFF]),
    ("WRIT_LED", [0x92, 0x12, 0xFF]),
    ("WRIT_GPO", [0x93, 0x13, 0xFF]),
    ("INIT", [0xA0, 0x20, 0xFF]),
    ("CMEP", [0xA1, 0x21, 0xFF]),
    ("RSEP", [0xA2, 0x22, 0xFF]),
    ("DRDS", [0xA3, 0x23, 0xFF]),
    ("DREN", [0xA4, 0x24, 0xFF]),
    ("STDS", [0xA5, 0x25, 0xFF]),
    ("STEN", [0xA6, 0x26, 0xFF]),
    ("READ_ID", [0xA8, 0x28, 0xFF]),
    ("READ_XY", [0xA9, 0x29, 0xFF]),
    ("READ_SV", [0xAA, 0x2A, 0xFF]),
    ("READ_AY", [0xAB, 0x2B, 0xFF]),
    ("READ_PRY", [0xAC, 0x2C, 0xFF]),
    ("READ_BT", [0xAD, 0x2D, 0xFF]),
    ("READ_RS", [0xAE, 0x2E, 0xFF]),
    ("READ_HD", [0xAF, 0x2F, 0xFF]),
    ("READ_SF", [0xB0, 0x30, 0xFF]),
    // UPD_SF error is printed as 0xB1, 0x30, 0xFF: see upd_sf_error_example below.
    ("READ_PAR", [0xB2, 0x32, 0xFF]),
    ("UPD_PAR", [0xB3, 0x33, 0xFF]),
];

fn kind(symbol: &str) -> CommandKind {
    *CommandKind::ALL
        .iter()
        .find(|k| k.symbol() == symbol)
        .unwrap_or_else(|| panic!("no command {symbol}"))
}

fn deframe_one(bytes: &[u8]) -> Result<(u8, Vec<u8>), DeframeError> {
    let mut d = Deframer::new();
    let mut found = None;
    for &b in bytes {
        if let Some(r) = d.push(b) {
            found = Some(r.map(|m| (m.header, m.data.to_vec())));
        }
    }
    found.expect("a complete message")
}

#[test]
fn command_examples_encode_and_decode() {
    for (symbol, bytes) in COMMANDS {
        let cmd = Command::without_data(kind(symbol)).unwrap();
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = cmd.emit(&mut out).unwrap();
        assert_eq!(&out[..n], bytes, "{symbol}");
        let (header, data) = deframe_one(bytes).unwrap();
        assert_eq!(Command::decode(header, &data), Ok(cmd), "{symbol}");
        // Where the ack repeats the command (CALB_ST and CALB_GS may too), the same bytes
        // decode as that ack; where the ack carries data, they are too short for one.
        let ack = LbcMessage::decode(header, &data);
        let k = cmd.kind();
        if k.ack_bits() == 0 || matches!(k, CommandKind::CalbSt | CommandKind::CalbGs) {
            assert_eq!(ack, Ok(LbcMessage::Reply(Reply::Echo(cmd))), "{symbol}");
        } else {
            assert!(
                matches!(ack, Err(DecodeError::Length { got: 0, .. })),
                "{symbol}: {ack:?}"
            );
        }
    }
}

#[test]
fn error_examples_encode_and_decode() {
    for (symbol, bytes) in ERRORS {
        let msg = LbcMessage::Error(kind(symbol));
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = msg.emit(&mut out).unwrap();
        assert_eq!(&out[..n], bytes, "{symbol}");
        let (header, data) = deframe_one(bytes).unwrap();
        assert_eq!(LbcMessage::decode(header, &data), Ok(msg), "{symbol}");
    }
}

#[test]
fn cser_example() {
    let mut out = [0u8; 8];
    let n = LbcMessage::ChecksumError.emit(&mut out).unwrap();
    assert_eq!(&out[..n], &[0xBD, 0x3D, 0xFF]);
    let (header, data) = deframe_one(&[0xBD, 0x3D, 0xFF]).unwrap();
    assert_eq!(
        LbcMessage::parse(&RawMessage {
            header,
            data: &data
        }),
        Ok(LbcMessage::ChecksumError)
    );
}

#[test]
fn upd_sf_error_example() {
    // The seed prints 0xB1, 0x30, 0xFF; the checksum rule gives 0x31. The encoder
    // follows the rule and the deframer rejects the printed bytes.
    let mut out = [0u8; 8];
    let n = LbcMessage::Error(CommandKind::UpdSf)
        .emit(&mut out)
        .unwrap();
    assert_eq!(&out[..n], &[0xB1, 0x31, 0xFF]);
    assert_eq!(
        deframe_one(&[0xB1, 0x30, 0xFF]),
        Err(DeframeError::ChecksumMismatch {
            header: 0xB1,
            expected: 0x31,
            got: 0x30
        })
    );
}

#[test]
fn general_error_header_ranges_of_3_4_3() {
    use lbc_link::HeaderClass;
    for b in (0x9C..=0x9F)
        .chain(0xBC..=0xBF)
        .chain(0xDC..=0xDF)
        .chain(0xFD..=0xFE)
    {
        assert!(
            HeaderClass::classify(b).unwrap().is_general_error(),
            "{b:#04x}"
        );
    }
    assert_eq!(HeaderClass::classify(0xFC), Some(HeaderClass::Stream));
}
