//! Byte vectors of the group command body and property tests of its encode/decode pair.

use super::*;
use crate::laws::LAWS;
use crate::{CameraFollow, Circle, Formation, GoTo, Rendezvous, Shape};
use proptest::prelude::*;

fn bytes(p: &ManeuverParams) -> Vec<u8> {
    let mut b = [0u8; MAX_LEN];
    let n = p.encode(&mut b).unwrap();
    assert_eq!(n, p.wire_len());
    b[..n].to_vec()
}

#[test]
fn vectors() {
    // go-to (300, 600) at 200 mm/s: law 4, no overrides, x and y in 2 bytes (0..=1023), speed
    // in 2 (0..=2047).
    let goto = GoTo::params(300, 600, 200).unwrap();
    assert_eq!(
        bytes(&goto),
        [4, 0, 0, 0, 0x2C, 0x01, 0x58, 0x02, 0xC8, 0x00]
    );
    // circle (300, 400), radius 150 (stored as 150 - 1), -200 mm/s (stored as -200 + 2048).
    let circle = Circle::params(300, 400, 150, -200).unwrap();
    assert_eq!(
        bytes(&circle),
        [3, 0, 0, 0, 0x2C, 0x01, 0x90, 0x01, 0x95, 0x00, 0x38, 0x07]
    );
    // wedge behind car 1, slot by rank (-1, stored as 0), spacing 60, 100 mm/s.
    let wedge = Formation::params(Shape::Wedge, 1, None, 60, 100).unwrap();
    assert_eq!(bytes(&wedge), [1, 0, 0, 0, 1, 0, 0, 0x3B, 0x00, 0x64, 0x00]);
    assert_eq!(
        bytes(&Rendezvous::params(60, 250).unwrap()),
        [2, 0, 0, 0, 0x3B, 0x00, 0xFA, 0x00]
    );
    assert_eq!(
        bytes(&CameraFollow::params(2, 80, 150).unwrap()),
        [5, 0, 0, 0, 2, 0x4F, 0x00, 0x96, 0x00]
    );
    assert_eq!(bytes(&ManeuverParams::IDLE), [0, 0, 0, 0]);
    // Options: reverse never (3), arrival 20 units, the 3 nearest neighbours.
    let o = goto.with_overrides(Overrides {
        reverse: Some(Reverse::Never),
        arrival_units: Some(20),
        neighbours: Some(Neighbours::Nearest(3)),
    });
    assert_eq!(&bytes(&o)[..4], [4, 3, 20, 3]);
    let none = goto.with_overrides(Overrides {
        neighbours: Some(Neighbours::None),
        ..Overrides::default()
    });
    assert_eq!(&bytes(&none)[..4], [4, 0, 0, 254]);
    for p in [goto, circle, wedge, o, none, ManeuverParams::IDLE] {
        assert_eq!(ManeuverParams::decode(&bytes(&p)), Ok(p));
    }
}

#[test]
fn bad_inputs_are_typed_errors() {
    use DecodeError::*;
    assert_eq!(
        ManeuverParams::decode(&[4, 0, 0]),
        Err(Length {
            expected: 4,
            got: 3
        })
    );
    assert_eq!(
        ManeuverParams::decode(&[200, 0, 0, 0]),
        Err(UnknownLaw { law: 200 })
    );
    assert_eq!(
        ManeuverParams::decode(&[4, 0, 0, 0, 1]),
        Err(Length {
            expected: 10,
            got: 5
        })
    );
    assert_eq!(
        ManeuverParams::decode(&[0, 1, 0, 0]),
        Err(BadOption { offset: 1 })
    );
    assert_eq!(
        ManeuverParams::decode(&[4, 4, 0, 0, 0, 0, 0, 0, 0, 0]),
        Err(BadOption { offset: 1 })
    );
    assert_eq!(
        ManeuverParams::decode(&[4, 0, 0, 17, 0, 0, 0, 0, 0, 0]),
        Err(BadOption { offset: 3 })
    );
    // x = 0x0400 = 1024 > 1023.
    assert_eq!(
        ManeuverParams::decode(&[4, 0, 0, 0, 0x00, 0x04, 0, 0, 0, 0]),
        Err(FieldOutOfRange { param: 0 })
    );
    // Rendezvous radius stored as 511: 512 is beyond 1..=511.
    assert_eq!(
        ManeuverParams::decode(&[2, 0, 0, 0, 0xFF, 0x01, 0, 0]),
        Err(FieldOutOfRange { param: 0 })
    );
    assert_eq!(
        ManeuverParams::new(4, &[1, 2]),
        Err(EncodeError::Count {
            expected: 3,
            got: 2
        })
    );
    assert_eq!(
        GoTo::params(1024, 0, 0),
        Err(EncodeError::FieldOutOfRange { param: 0 })
    );
    assert_eq!(
        ManeuverParams::new(99, &[]),
        Err(EncodeError::UnknownLaw { law: 99 })
    );
    let bad = GoTo::params(1, 1, 1).unwrap().with_overrides(Overrides {
        neighbours: Some(Neighbours::Nearest(0)),
        ..Overrides::default()
    });
    assert_eq!(bad.encode(&mut [0; MAX_LEN]), Err(EncodeError::BadOption));
    assert_eq!(
        GoTo::params(1, 1, 1).unwrap().encode(&mut [0; 5]),
        Err(EncodeError::BufferTooSmall { needed: 10 })
    );
}

/// Any registered law with values in its ranges and any overrides.
fn any_params() -> impl Strategy<Value = ManeuverParams> {
    let law = prop::sample::select(LAWS.to_vec());
    (
        law,
        any::<[u32; crate::param::MAX_PARAMS]>(),
        0u8..4,
        any::<u8>(),
        0u8..20,
    )
        .prop_map(|(law, raw, reverse, arrival, neighbours)| {
            let values: Vec<i32> = law
                .params
                .iter()
                .zip(raw)
                .map(|(p, r)| {
                    let span = (i64::from(p.max) - i64::from(p.min)) as u64 + 1;
                    (i64::from(p.min) + (u64::from(r) % span) as i64) as i32
                })
                .collect();
            ManeuverParams::new(law.id, &values)
                .unwrap()
                .with_overrides(Overrides {
                    reverse: Reverse::from_u8(reverse),
                    arrival_units: (arrival != 0).then_some(arrival),
                    neighbours: match neighbours {
                        0 => None,
                        17 => Some(Neighbours::All),
                        18 => Some(Neighbours::None),
                        19 => Some(Neighbours::Nearest(16)),
                        k => Some(Neighbours::Nearest(k)),
                    },
                })
        })
}

proptest! {
    #[test]
    fn encode_decode_round_trip(p in any_params()) {
        let b = bytes(&p);
        prop_assert_eq!(ManeuverParams::decode(&b), Ok(p));
    }

    #[test]
    fn decode_is_canonical(law in prop::sample::select(LAWS.to_vec()),
                           reverse in 0u8..5,
                           arrival in any::<u8>(),
                           neighbours in prop_oneof![0u8..20, Just(254), Just(255), any::<u8>()],
                           rest in proptest::collection::vec(any::<u8>(), 32)) {
        let mut b = vec![law.id, reverse, arrival, neighbours];
        b.extend_from_slice(&rest[..law.wire_len() - HEADER_LEN]);
        if let Ok(p) = ManeuverParams::decode(&b) {
            prop_assert_eq!(bytes(&p), b);
        }
    }

    #[test]
    fn decode_never_panics(b in proptest::collection::vec(any::<u8>(), 0..40)) {
        let _ = ManeuverParams::decode(&b);
    }
}
