//! Byte vectors and property tests of the console payloads.
use super::*;
use lbc_link::{Position, VehicleId};
use proptest::prelude::*;

fn req_bytes(r: &Request) -> ([u8; MAX_PAYLOAD], usize) {
    let mut b = [0u8; MAX_PAYLOAD];
    let n = r.encode(&mut b).unwrap();
    (b, n)
}

#[test]
fn lbc_request_carries_the_lbc_message_verbatim() {
    let r = Request::Lbc(Command::MoveXy(Position::new(320, 480).unwrap()));
    let (b, n) = req_bytes(&r);
    assert_eq!(&b[..n], &[1, 0xC1, 0x02, 0x40, 0x03, 0x60, 0x60, 0xFF]);
    assert_eq!(Request::decode(0x01, &b[..n]).unwrap(), r);
}

#[test]
fn maneuver_request_layout() {
    let mut pts = Points::new();
    pts.push(Point { x: 320, y: 480 }).unwrap();
    pts.push(Point { x: 0x102, y: 3 }).unwrap();
    let r = Request::ManeuverStart(pts);
    let (b, n) = req_bytes(&r);
    assert_eq!(
        &b[..n],
        &[1, 2, 0x40, 0x01, 0xE0, 0x01, 0x02, 0x01, 0x03, 0x00]
    );
    assert_eq!(Request::decode(0x04, &b[..n]).unwrap(), r);
}

#[test]
fn bad_requests_are_typed_errors() {
    assert_eq!(Request::decode(0x02, &[]), Err(DecodeError::Empty));
    assert_eq!(
        Request::decode(0x02, &[9]),
        Err(DecodeError::UnsupportedVersion { got: 9 })
    );
    assert_eq!(
        Request::decode(0x7E, &[1]),
        Err(DecodeError::UnknownTag { tag: 0x7E })
    );
    assert_eq!(
        Request::decode(0x02, &[1, 0]),
        Err(DecodeError::Length {
            tag: 2,
            expected: 0,
            got: 1
        })
    );
    // Bad checksum inside the carried LBC message.
    assert!(matches!(
        Request::decode(0x01, &[1, 0xC1, 0x02, 0x40, 0x03, 0x60, 0x61, 0xFF]),
        Err(DecodeError::LbcFrame(FrameError::ChecksumMismatch { .. }))
    ));
    // X beyond 640.
    assert_eq!(
        Request::decode(0x04, &[1, 1, 0x81, 0x02, 0, 0]),
        Err(DecodeError::Field { tag: 4, offset: 1 })
    );
}

#[test]
fn lbc_reply_vectors() {
    let mut b = [0u8; MAX_PAYLOAD];
    let r = Reply::Lbc(LbcOutcome::Answer(LbcReply::ReadId(
        VehicleId::new(7).unwrap(),
    )));
    let n = r.encode(&mut b).unwrap();
    assert_eq!(&b[..n], &[1, 0, 0xE8, 0x07, 0x6F, 0xFF]);
    assert_eq!(Reply::decode(0x01, &b[..n]).unwrap(), r);

    let r = Reply::Lbc(LbcOutcome::Rejected(CommandKind::MoveXy));
    let n = r.encode(&mut b).unwrap();
    assert_eq!(&b[..n], &[1, 0x10, 0x81]);
    assert_eq!(Reply::decode(0x01, &b[..n]).unwrap(), r);

    let r = Reply::Refused(Refusal::DriveDisabled);
    let n = r.encode(&mut b).unwrap();
    assert_eq!(&b[..n], &[1, 0x05]);
    assert_eq!(Reply::decode(0x01, &b[..n]).unwrap(), r);
}

#[test]
fn group_request_vectors() {
    let params = maneuvers::GoTo::params(300, 600, 200).unwrap();
    let r = Request::GroupStart(params);
    let (b, n) = req_bytes(&r);
    // Version 2, then law 4 (go-to), no option overrides, x, y, speed (u16 each).
    assert_eq!(
        &b[..n],
        &[2, 4, 0, 0, 0, 0x2C, 0x01, 0x58, 0x02, 0xC8, 0x00]
    );
    assert_eq!(Request::decode(0x07, &b[..n]).unwrap(), r);

    let r = Request::GroupWaypoint { x: 0x140, y: 0x3C0 };
    let (b, n) = req_bytes(&r);
    assert_eq!(&b[..n], &[1, 0x40, 0x01, 0xC0, 0x03]);
    assert_eq!(Request::decode(0x08, &b[..n]).unwrap(), r);

    let mut o = [0u8; MAX_PAYLOAD];
    let n = Reply::GroupStarted.encode(&mut o).unwrap();
    assert_eq!(&o[..n], &[1, 0]);
    assert_eq!(Reply::decode(0x07, &o[..n]).unwrap(), Reply::GroupStarted);
    assert_eq!(
        Reply::decode(0x08, &o[..n]).unwrap(),
        Reply::GroupWaypointSet
    );
}

#[test]
fn program_request_vectors() {
    let args: super::super::user::Args = [200, -1].into_iter().collect();
    let r = Request::ProgramStart(args);
    let (b, n) = req_bytes(&r);
    assert_eq!(&b[..n], &[1, 2, 0xC8, 0x00, 0xFF, 0xFF]);
    assert_eq!(Request::decode(0x0A, &b[..n]).unwrap(), r);
    let (b, n) = req_bytes(&Request::ProgramStop);
    assert_eq!(&b[..n], &[1]);
    assert_eq!(
        Request::decode(0x0B, &b[..n]).unwrap(),
        Request::ProgramStop
    );
    assert_eq!(
        Request::decode(0x0A, &[1, 15]),
        Err(DecodeError::Field { tag: 10, offset: 0 })
    );
    assert_eq!(
        Request::decode(0x0A, &[1, 1, 0]),
        Err(DecodeError::Length {
            tag: 10,
            expected: 3,
            got: 2
        })
    );
    let mut o = [0u8; MAX_PAYLOAD];
    let n = Reply::ProgramStarted.encode(&mut o).unwrap();
    assert_eq!(Reply::decode(0x0A, &o[..n]).unwrap(), Reply::ProgramStarted);
    assert_eq!(Reply::decode(0x0B, &o[..n]).unwrap(), Reply::ProgramStopped);
    let n = Reply::Refused(Refusal::NoProgram).encode(&mut o).unwrap();
    assert_eq!(&o[..n], &[1, 0x0C]);
}

#[test]
fn bad_group_requests_are_typed_errors() {
    // Law 200 is not registered.
    assert_eq!(
        Request::decode(0x07, &[2, 200, 0, 0, 0]),
        Err(DecodeError::Params {
            tag: 7,
            error: maneuvers::DecodeError::UnknownLaw { law: 200 }
        })
    );
    assert_eq!(
        Request::decode(0x07, &[2, 4, 0, 0, 0, 0]),
        Err(DecodeError::Params {
            tag: 7,
            error: maneuvers::DecodeError::Length {
                expected: 10,
                got: 5
            }
        })
    );
    // The version-1 layout (3-bit law selector) is refused as a version.
    assert_eq!(
        Request::decode(0x07, &[1, 0x64, 0x09, 0x4B, 0x64, 0x00, 0x00]),
        Err(DecodeError::UnsupportedVersion { got: 1 })
    );
    // Every other request stays at version 1.
    assert_eq!(
        Request::decode(0x02, &[2]),
        Err(DecodeError::UnsupportedVersion { got: 2 })
    );
    assert_eq!(
        Request::decode(0x08, &[1, 0x81, 0x02, 0, 0]),
        Err(DecodeError::Field { tag: 8, offset: 0 })
    );
    assert_eq!(
        Request::decode(0x08, &[1, 0, 0, 0xC1, 0x03]),
        Err(DecodeError::Field { tag: 8, offset: 2 })
    );
    assert_eq!(
        Request::GroupWaypoint { x: 641, y: 0 }.encode(&mut [0u8; MAX_PAYLOAD]),
        Err(EncodeError::Field)
    );
    assert_eq!(
        Request::GroupStart(maneuvers::GoTo::params(1, 2, 3).unwrap()).encode(&mut [0u8; 6]),
        Err(EncodeError::BufferTooSmall { needed: 11 })
    );
}

#[test]
fn status_layout_keeps_old_fields_first() {
    let s = Status {
        phase: 2,
        flags: 0x21,
        car_id: 7,
        x: 0x0102,
        uptime_s: 0x0A0B,
        group_kind: 4,
        group_phase: 1,
        group_converged: true,
        group_error_units: 0x0304,
        ..Status::default()
    };
    let mut o = [0u8; MAX_PAYLOAD];
    let n = Reply::Status(s).encode(&mut o).unwrap();
    assert_eq!(n, 2 + 29);
    assert_eq!(&o[..6], &[1, 0, 2, 0x21, 7, 0x02]);
    assert_eq!(&o[24..31], &[0x0B, 0x0A, 4, 1, 1, 0x04, 0x03]);
    // A converged byte other than 0 or 1 is refused.
    o[28] = 2;
    assert_eq!(
        Reply::decode(0x02, &o[..n]),
        Err(DecodeError::Field { tag: 2, offset: 26 })
    );
}

fn arb_params() -> impl Strategy<Value = ManeuverParams> {
    let laws = maneuvers::LAWS.len();
    prop_oneof![
        Just(ManeuverParams::IDLE),
        (0..laws, any::<[u32; maneuvers::param::MAX_PARAMS]>()).prop_map(|(k, raw)| {
            let law = &maneuvers::LAWS[k];
            let values: std::vec::Vec<i32> = law
                .params
                .iter()
                .zip(raw)
                .map(|(p, r)| {
                    let span = (i64::from(p.max) - i64::from(p.min)) as u64 + 1;
                    (i64::from(p.min) + (u64::from(r) % span) as i64) as i32
                })
                .collect();
            ManeuverParams::new(law.id, &values).unwrap()
        }),
    ]
}

fn arb_status() -> impl Strategy<Value = Status> {
    (
        any::<[u8; 3]>(),
        any::<[u16; 3]>(),
        any::<[i16; 2]>(),
        any::<[u8; 3]>(),
        any::<[u16; 4]>(),
        (any::<[u8; 2]>(), any::<bool>(), any::<u16>()),
    )
        .prop_map(|(a, b, c, d, e, g)| Status {
            phase: a[0],
            flags: a[1],
            car_id: a[2],
            x: b[0],
            y: b[1],
            heading_mrad: b[2],
            steering_mrad: c[0],
            velocity_mm_s: c[1],
            temperature_c: d[0],
            maneuver_index: d[1],
            maneuver_len: d[2],
            stream_age_ms: e[0],
            bringups: e[1],
            lbc_failures: e[2],
            uptime_s: e[3],
            group_kind: g.0[0],
            group_phase: g.0[1],
            group_converged: g.1,
            group_error_units: g.2,
        })
}

proptest! {
    #[test]
    fn status_round_trips(s in arb_status()) {
        let mut b = [0u8; MAX_PAYLOAD];
        let n = Reply::Status(s).encode(&mut b).unwrap();
        prop_assert_eq!(Reply::decode(0x02, &b[..n]).unwrap(), Reply::Status(s));
    }

    #[test]
    fn stats_round_trip(page in 0u8..4, vals in proptest::collection::vec(any::<u32>(), 0..=7)) {
        let values: Vec<u32, STATS_PER_PAGE> = vals.iter().copied().collect();
        let r = Reply::Stats { page, values };
        let mut b = [0u8; MAX_PAYLOAD];
        let n = r.encode(&mut b).unwrap();
        prop_assert_eq!(Reply::decode(0x06, &b[..n]).unwrap(), r);
    }

    #[test]
    fn maneuver_round_trips(pts in proptest::collection::vec((0u16..=640, 0u16..=960), 1..=7)) {
        let points: Points = pts.iter().map(|&(x, y)| Point { x, y }).collect();
        let r = Request::ManeuverStart(points);
        let (b, n) = req_bytes(&r);
        prop_assert_eq!(Request::decode(0x04, &b[..n]).unwrap(), r);
    }

    #[test]
    fn program_requests_round_trip(args in proptest::collection::vec(any::<i16>(), 0..=14)) {
        let r = Request::ProgramStart(args.into_iter().collect());
        let (b, n) = req_bytes(&r);
        prop_assert_eq!(Request::decode(r.tag() as u8, &b[..n]).unwrap(), r);
    }

    #[test]
    fn group_requests_round_trip(p in arb_params(), x in 0u16..=640, y in 0u16..=960) {
        for r in [Request::GroupStart(p), Request::GroupWaypoint { x, y }] {
            let (b, n) = req_bytes(&r);
            prop_assert_eq!(Request::decode(r.tag() as u8, &b[..n]).unwrap(), r);
        }
    }

    #[test]
    fn camera_requests_and_replies_round_trip(blob in any::<u8>(), seq in any::<u32>(), n in any::<u8>()) {
        let r = Request::Camera { blob };
        let mut out = [0u8; MAX_PAYLOAD];
        let len = r.encode(&mut out).unwrap();
        prop_assert_eq!(&out[..len], &[VERSION, blob][..]);
        prop_assert_eq!(Request::decode(Tag::Camera as u8, &out[..len]), Ok(r));
        let reply = Reply::Camera(CameraReport {
            sequence: seq,
            blobs: n,
            leader_class: 2,
            follow_state: 1,
            leader_bearing_mrad: -12,
            leader_range_mm: 640,
            frames: seq.rotate_left(7) as u16,
            blob: (n > 0).then_some((blob, BlobReport { class: 2, area: 1234, ..BlobReport::default() })),
        });
        let len = reply.encode(&mut out).unwrap();
        prop_assert!(len <= MAX_PAYLOAD);
        prop_assert_eq!(Reply::decode(Tag::Camera as u8, &out[..len]), Ok(reply));
        prop_assert!(Reply::decode(Tag::Camera as u8, &out[..len - 1]).is_err());
    }

    #[test]
    fn stream_format_round_trips(bits in any::<u32>()) {
        let r = Request::StreamFormat(bits);
        let (b, n) = req_bytes(&r);
        prop_assert_eq!(Request::decode(0x03, &b[..n]).unwrap(), r);
        let mut o = [0u8; MAX_PAYLOAD];
        let n = Reply::StreamFormat(bits).encode(&mut o).unwrap();
        prop_assert_eq!(Reply::decode(0x03, &o[..n]).unwrap(), Reply::StreamFormat(bits));
    }

    #[test]
    fn lbc_requests_round_trip(x in 0u16..=640, y in 0u16..=960, p in 1u8..=12, v in -100i16..=100, led in 0u8..0x80) {
        let pv = lbc_link::ParamValue::new(lbc_link::Param::from_number(p).unwrap(), v);
        let led = lbc_link::LedPattern::from_bits(led).unwrap();
        let mut cmds = vec![
            Command::MoveXy(Position::new(x, y).unwrap()),
            Command::WritLed { green: led, red: led },
            Command::ReadPar(lbc_link::Param::from_number(p).unwrap()),
        ];
        if let Ok(pv) = pv {
            cmds.push(Command::UpdPar(pv));
        }
        for c in cmds {
            let r = Request::Lbc(c);
            let (b, n) = req_bytes(&r);
            prop_assert_eq!(Request::decode(0x01, &b[..n]).unwrap(), r);
            if matches!(c, Command::ReadPar(_)) {
                continue; // answered with data, not an echo
            }
            let answer = Reply::Lbc(LbcOutcome::Answer(LbcReply::Echo(c)));
            let mut o = [0u8; MAX_PAYLOAD];
            let n = answer.encode(&mut o).unwrap();
            prop_assert_eq!(Reply::decode(0x01, &o[..n]).unwrap(), answer);
        }
    }

    #[test]
    fn decoders_never_panic(tag in any::<u8>(), bytes in proptest::collection::vec(any::<u8>(), 0..40)) {
        let _ = Request::decode(tag, &bytes);
        let _ = Reply::decode(tag, &bytes);
        let _ = Notice::decode(&bytes);
    }

    #[test]
    fn notices_round_trip(code in 0u8..6, w in 0u8..4) {
        let n = [Notice::LbcLost, Notice::LbcRecovered, Notice::Warnings(w),
                 Notice::UserLinkLost, Notice::ManeuverDone, Notice::ManeuverAborted][usize::from(code)];
        let mut b = [0u8; 4];
        let len = n.encode(&mut b).unwrap();
        prop_assert_eq!(Notice::decode(&b[..len]).unwrap(), n);
    }
}
