//! Crate-level tests: property tests for every encode/decode pair and end-to-end exchanges
//! between endpoints over an in-memory link.

use crate::auth;
use crate::wire::*;
use crate::*;
use proptest::prelude::*;

fn arb_car() -> impl Strategy<Value = CarId> {
    (1u8..=126).prop_map(|v| CarId::new(v).unwrap())
}

fn arb_addr() -> impl Strategy<Value = Address> {
    prop_oneof![
        Just(Address::Ground),
        Just(Address::Broadcast),
        arb_car().prop_map(Address::Car)
    ]
}

fn arb_unicast() -> impl Strategy<Value = Address> {
    prop_oneof![Just(Address::Ground), arb_car().prop_map(Address::Car)]
}

fn arb_role() -> impl Strategy<Value = Role> {
    prop_oneof![
        Just(Role::Idle),
        Just(Role::Leader),
        Just(Role::Follower),
        Just(Role::Relay)
    ]
}

fn arb_mode() -> impl Strategy<Value = Mode> {
    (arb_role(), 0u8..16).prop_map(|(role, phase)| Mode { role, phase })
}

fn arb_state() -> impl Strategy<Value = CarState> {
    (
        0..=MAX_COORD,
        0..=MAX_COORD,
        0..=MAX_HEADING_MRAD,
        any::<i16>(),
        arb_mode(),
    )
        .prop_map(|(x, y, heading_mrad, velocity_mm_s, mode)| CarState {
            x,
            y,
            heading_mrad,
            velocity_mm_s,
            mode,
        })
}

fn arb_payload() -> impl Strategy<Value = Payload> {
    proptest::collection::vec(any::<u8>(), 0..=MAX_PAYLOAD)
        .prop_map(|v| Payload::from_slice(&v).unwrap())
}

fn arb_group_msg() -> impl Strategy<Value = GroupMsg> {
    prop_oneof![
        arb_role().prop_map(|role| GroupMsg::Role { role }),
        (any::<u8>(), any::<u8>()).prop_map(|(slot, count)| GroupMsg::Slot { slot, count }),
        (0..=MAX_COORD, 0..=MAX_COORD, 0..=MAX_HEADING_MRAD).prop_map(|(x, y, h)| {
            GroupMsg::Target {
                x,
                y,
                heading_mrad: h,
            }
        }),
        any::<u16>().prop_map(|delay_ms| GroupMsg::Start { delay_ms }),
        Just(GroupMsg::Stop),
    ]
}

fn arb_frame() -> impl Strategy<Value = Frame> {
    prop_oneof![
        (arb_car(), any::<u8>(), arb_state()).prop_map(|(src, seq, state)| Frame::State {
            src,
            seq,
            state
        }),
        (arb_unicast(), arb_mode(), any::<u8>(), any::<u16>()).prop_map(
            |(src, mode, neighbours, uptime_s)| Frame::Heartbeat {
                src,
                beat: Heartbeat {
                    mode,
                    neighbours,
                    uptime_s
                }
            }
        ),
        (
            arb_unicast(),
            arb_unicast(),
            any::<u16>(),
            any::<u8>(),
            arb_payload(),
            any::<bool>()
        )
            .prop_map(|(src, dst, seq, tag, payload, req)| if req {
                Frame::Request {
                    src,
                    dst,
                    seq,
                    tag,
                    payload,
                }
            } else {
                Frame::Reply {
                    src,
                    dst,
                    seq,
                    tag,
                    payload,
                }
            }),
        (
            arb_unicast(),
            arb_addr(),
            any::<u8>(),
            any::<u8>(),
            arb_group_msg()
        )
            .prop_map(|(src, dst, group, gseq, msg)| Frame::Group {
                src,
                dst,
                group,
                gseq,
                msg
            }),
        (
            prop_oneof![Just(Address::Broadcast), arb_car().prop_map(Address::Car)],
            any::<u32>(),
            any::<u8>(),
            arb_payload(),
            any::<[u8; AUTH_TAG_LEN]>()
        )
            .prop_map(|(dst, counter, tag, payload, mac)| Frame::AuthCommand {
                dst,
                counter,
                tag,
                payload,
                mac
            }),
    ]
}

proptest! {
    #[test]
    fn frame_round_trip(f in arb_frame()) {
        let mut raw = [0u8; MAX_RAW];
        let n = f.emit_raw(&mut raw).unwrap();
        prop_assert_eq!(n, f.raw_len());
        prop_assert_eq!(Frame::parse(&raw[..n]), Ok(f.clone()));
        let enc = encode_frame(&f).unwrap();
        prop_assert_eq!(enc.len(), f.encoded_len());
        prop_assert_eq!(enc.iter().filter(|b| **b == 0).count(), 1);
        let mut d = Deframer::new();
        let out: std::vec::Vec<_> = enc.iter().filter_map(|b| d.push(*b)).collect();
        prop_assert_eq!(out, std::vec![Ok(f)]);
    }

    #[test]
    fn state_frames_are_16_bytes(src in arb_car(), seq in any::<u8>(), state in arb_state()) {
        let enc = encode_frame(&Frame::State { src, seq, state }).unwrap();
        prop_assert_eq!(enc.len(), STATE_FRAME_LEN);
    }

    #[test]
    fn parse_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..80)) {
        let _ = Frame::parse(&bytes);
    }

    /// Any garbage before a frame costs at most that frame: the frame after the next
    /// delimiter is always decoded.
    #[test]
    fn deframer_resyncs(garbage in proptest::collection::vec(any::<u8>(), 0..200), f in arb_frame()) {
        let mut d = Deframer::new();
        for b in &garbage {
            let _ = d.push(*b);
        }
        let _ = d.push(0);
        let enc = encode_frame(&f).unwrap();
        let out: std::vec::Vec<_> = enc.iter().filter_map(|b| d.push(*b)).collect();
        prop_assert_eq!(out, std::vec![Ok(f)]);
    }

    #[test]
    fn single_bit_flips_are_detected(f in arb_frame(), pos in any::<prop::sample::Index>(), bit in 0u8..8) {
        let mut raw = [0u8; MAX_RAW];
        let n = f.emit_raw(&mut raw).unwrap();
        raw[pos.index(n)] ^= 1 << bit;
        prop_assert!(Frame::parse(&raw[..n]).is_err());
    }
}

// ---- end-to-end over an in-memory link ----

const KEY: [u8; 16] = *b"almc-testbed-key";

fn car(n: u8) -> CarId {
    CarId::new(n).unwrap()
}

/// Moves bytes between endpoints; drops whole frames by a deterministic pattern.
struct Link {
    drop_every: u32,
    count: u32,
}

impl Link {
    fn carry(&mut self, bytes: &[u8]) -> std::vec::Vec<u8> {
        // Split at delimiters and drop every n-th frame.
        let mut out = std::vec::Vec::new();
        for chunk in bytes.split_inclusive(|b| *b == 0) {
            self.count += 1;
            if self.drop_every != 0 && self.count.is_multiple_of(self.drop_every) {
                continue;
            }
            out.extend_from_slice(chunk);
        }
        out
    }
}

fn drain(mac: &mut CarMac) -> std::vec::Vec<u8> {
    let mut buf = [0u8; 1024];
    let n = mac.transmit(&mut buf);
    buf[..n].to_vec()
}

fn drain_ground(g: &mut GroundStation) -> std::vec::Vec<u8> {
    let mut buf = [0u8; 1024];
    let n = g.transmit(&mut buf);
    buf[..n].to_vec()
}

fn events(mac: &mut CarMac) -> std::vec::Vec<Event> {
    std::iter::from_fn(|| mac.next_event()).collect()
}

fn ground_events(g: &mut GroundStation) -> std::vec::Vec<Event> {
    std::iter::from_fn(|| g.next_event()).collect()
}

#[test]
fn request_reply_exactly_once_under_loss() {
    let mut a = CarMac::new(CarConfig::new(car(1)));
    let mut b = CarMac::new(CarConfig::new(car(2)));
    let mut ab = Link {
        drop_every: 3,
        count: 0,
    };
    let mut ba = Link {
        drop_every: 2,
        count: 0,
    };
    let mut executed = std::collections::HashMap::new();
    let mut replies = std::collections::HashMap::new();
    let mut handles = std::vec::Vec::new();
    let mut now = 0u64;
    for i in 0..20u8 {
        handles.push((a.request(now, Address::Car(car(2)), 9, &[i]).unwrap(), i));
        // Run until the reply arrives.
        for _ in 0..400 {
            now += 5_000;
            a.poll(now);
            b.poll(now);
            let x = ab.carry(&drain(&mut a));
            b.push_rx(now, &x);
            for e in events(&mut b) {
                if let Event::Request(inc) = e {
                    *executed.entry(inc.payload[0]).or_insert(0) += 1;
                    b.reply(inc.id, 10, &[inc.payload[0], 0xAA]).unwrap();
                }
            }
            let y = ba.carry(&drain(&mut b));
            a.push_rx(now, &y);
            for e in events(&mut a) {
                if let Event::Reply {
                    handle, payload, ..
                } = e
                {
                    replies.insert(handle, payload.to_vec());
                }
            }
            if replies.len() == handles.len() {
                break;
            }
        }
    }
    for (h, i) in &handles {
        assert_eq!(replies.get(h), Some(&std::vec![*i, 0xAA]));
        assert_eq!(executed.get(i), Some(&1), "request {i} executed once");
    }
    assert!(a.stats().retries > 0);
    assert!(b.stats().duplicates > 0);
    assert!(b.stats().replies_resent > 0);
}

#[test]
fn request_fails_after_max_attempts() {
    let mut a = CarMac::new(CarConfig::new(car(1)));
    let h = a.request(0, Address::Car(car(2)), 1, &[]).unwrap();
    let mut sent = 0;
    let mut failed = false;
    let mut now = 0;
    while now < 5_000_000 {
        now += 1_000;
        a.poll(now);
        sent += drain(&mut a).iter().filter(|b| **b == 0).count();
        for e in events(&mut a) {
            if e == (Event::Failed {
                handle: h,
                dst: Address::Car(car(2)),
            }) {
                failed = true;
            }
        }
    }
    assert!(failed);
    // Heartbeats also go out; count requests by stats instead.
    assert_eq!(a.stats().retries, u32::from(endpoint::MAX_ATTEMPTS - 1));
    assert_eq!(a.stats().failures, 1);
    assert!(sent >= usize::from(endpoint::MAX_ATTEMPTS));
}

#[test]
fn request_validation() {
    let mut a = CarMac::new(CarConfig::new(car(1)));
    assert_eq!(
        a.request(0, Address::Broadcast, 1, &[]),
        Err(SendError::InvalidDestination)
    );
    assert_eq!(
        a.request(0, Address::Car(car(1)), 1, &[]),
        Err(SendError::InvalidDestination)
    );
    assert_eq!(
        a.request(0, Address::Car(car(2)), 1, &[0; MAX_PAYLOAD + 1]),
        Err(SendError::PayloadTooLong {
            len: MAX_PAYLOAD + 1
        })
    );
    a.request(0, Address::Car(car(2)), 1, &[]).unwrap();
    assert_eq!(
        a.request(0, Address::Car(car(2)), 1, &[]),
        Err(SendError::Busy)
    );
    for i in 1..endpoint::MAX_PENDING as u8 {
        a.request(0, Address::Car(car(2 + i)), 1, &[]).unwrap();
    }
    assert_eq!(
        a.request(0, Address::Car(car(20)), 1, &[]),
        Err(SendError::Busy)
    );
}

fn keyed_car(id: u8) -> CarMac {
    let mut c = CarConfig::new(car(id));
    c.key = Some(Key::new(KEY));
    CarMac::new(c)
}

#[test]
fn authenticated_command_round_trip_and_attacks() {
    let mut g = GroundStation::new(GroundConfig::new(Key::new(KEY), 100));
    let mut c = keyed_car(5);
    let h = g.command(0, Address::Car(car(5)), 3, b"go").unwrap();
    let captured = drain_ground(&mut g);
    c.push_rx(10, &captured);
    let ev = events(&mut c);
    let inc = match &ev[..] {
        [Event::Request(inc)] => inc.clone(),
        other => panic!("unexpected {other:?}"),
    };
    assert_eq!(inc.id.counter, Some(100));
    assert_eq!(&inc.payload[..], b"go");
    c.reply(inc.id, 4, b"ok").unwrap();
    let rep = drain(&mut c);
    g.push_rx(20, &rep);
    assert_eq!(
        ground_events(&mut g),
        std::vec![Event::Reply {
            handle: h,
            from: Address::Car(car(5)),
            tag: 4,
            payload: Payload::from_slice(b"ok").unwrap()
        }]
    );

    // Retransmission of the same command: answered again, not executed again.
    c.push_rx(30, &captured);
    assert!(events(&mut c).is_empty());
    assert_eq!(c.stats().auth_repeat, 1);
    assert_eq!(c.stats().replies_resent, 1);

    // A newer command, then a replay of the old capture: rejected.
    g.poll(40);
    let _ = drain_ground(&mut g);
    g.push_rx(41, &[]);
    let _h2 = g.command(50, Address::Car(car(5)), 3, b"stop");
    // The ground is busy until the first reply; it was answered, so this succeeds.
    let second = drain_ground(&mut g);
    c.push_rx(60, &second);
    assert_eq!(events(&mut c).len(), 1);
    c.push_rx(70, &captured);
    assert!(events(&mut c).is_empty());
    assert_eq!(c.stats().auth_replay, 1);

    // Altered payload with a valid CRC: MAC check fails.
    let mut frame = Frame::AuthCommand {
        dst: Address::Car(car(5)),
        counter: 500,
        tag: 3,
        payload: Payload::from_slice(b"go").unwrap(),
        mac: [0; AUTH_TAG_LEN],
    };
    auth::sign(&Key::new(KEY), &mut frame).unwrap();
    if let Frame::AuthCommand { payload, .. } = &mut frame {
        payload[0] = b'n';
    }
    c.push_rx(80, &encode_frame(&frame).unwrap());
    // Forged with another key.
    auth::sign(&Key::new([1; 16]), &mut frame).unwrap();
    c.push_rx(90, &encode_frame(&frame).unwrap());
    assert!(events(&mut c).is_empty());
    assert_eq!(c.stats().auth_bad_mac, 2);

    // A car without the key rejects everything.
    let mut nokey = CarMac::new(CarConfig::new(car(5)));
    nokey.push_rx(0, &captured);
    assert!(events(&mut nokey).is_empty());
    assert_eq!(nokey.stats().auth_no_key, 1);
}

#[test]
fn broadcast_command_executes_once_per_car() {
    let mut g = GroundStation::new(GroundConfig::new(Key::new(KEY), 7));
    let mut cars: std::vec::Vec<CarMac> = (1..=3).map(keyed_car).collect();
    let h = g.command(0, Address::Broadcast, 1, &[42]).unwrap();
    let mut executed = [0; 3];
    let mut done = false;
    let mut now = 0;
    while now < 500_000 {
        now += 1_000;
        g.poll(now);
        let bytes = drain_ground(&mut g);
        for (i, c) in cars.iter_mut().enumerate() {
            c.push_rx(now, &bytes);
            for e in events(c) {
                if let Event::Request(inc) = e {
                    assert!(inc.id.broadcast);
                    assert_eq!(c.reply(inc.id, 0, &[]), Err(ReplyError::Broadcast));
                    executed[i] += 1;
                }
            }
        }
        done |= ground_events(&mut g).contains(&Event::RepeatsDone { handle: h });
    }
    assert!(done);
    assert_eq!(executed, [1, 1, 1]);
    assert_eq!(
        cars[0].stats().auth_repeat,
        u32::from(endpoint::REPEATS - 1)
    );
}

#[test]
fn group_messages_deduplicated() {
    let mut a = CarMac::new(CarConfig::new(car(1)));
    let mut b = CarMac::new(CarConfig::new(car(2)));
    let msg = GroupMsg::Target {
        x: 300,
        y: 400,
        heading_mrad: 1000,
    };
    a.send_group(0, Address::Broadcast, 3, msg).unwrap();
    let mut got = std::vec::Vec::new();
    let mut now = 0;
    while now < 300_000 {
        now += 1_000;
        a.poll(now);
        let x = drain(&mut a);
        b.push_rx(now, &x);
        got.extend(
            events(&mut b)
                .into_iter()
                .filter(|e| matches!(e, Event::Group { .. })),
        );
    }
    assert_eq!(
        got,
        std::vec![Event::Group {
            from: Address::Car(car(1)),
            group: 3,
            msg,
            broadcast: true
        }]
    );
    assert_eq!(b.stats().group_duplicates, u32::from(endpoint::REPEATS - 1));
}

#[test]
fn state_broadcast_heartbeat_and_neighbours() {
    let mut a = CarMac::new(CarConfig::new(car(1)));
    let mut g = GroundStation::new(GroundConfig::new(Key::new(KEY), 1));
    let st = CarState {
        x: 10,
        y: 20,
        heading_mrad: 30,
        velocity_mm_s: -40,
        mode: Mode::default(),
    };
    // Without a state the car only sends heartbeats.
    a.poll(0);
    g.push_rx(0, &drain(&mut a));
    assert!(matches!(
        ground_events(&mut g)[..],
        [Event::Heartbeat { .. }]
    ));
    a.set_state(st);
    let mut states = 0;
    let mut now = 0;
    while now < 1_000_000 {
        now = a.poll_at(now).max(now + 1);
        a.poll(now);
        g.push_rx(now, &drain(&mut a));
        for e in ground_events(&mut g) {
            match e {
                Event::State { from, state, .. } => {
                    assert_eq!(from, car(1));
                    assert_eq!(state, st);
                    states += 1;
                }
                Event::Heartbeat { .. } => panic!("heartbeat while broadcasting state"),
                _ => {}
            }
        }
    }
    // 30 Hz for one second.
    assert!((29..=31).contains(&states), "{states}");
    let n: std::vec::Vec<_> = g.cars().collect();
    assert_eq!(n.len(), 1);
    assert_eq!(n[0].state.map(|s| s.0), Some(st));
    assert_eq!(n[0].states_missed, 0);
    assert!(!n[0].is_stale(now, g.stale_after_us()));
    assert!(n[0].is_stale(now + 2_000_000, g.stale_after_us()));
}

#[test]
fn version_mismatch_counted() {
    let mut a = CarMac::new(CarConfig::new(car(1)));
    let body = [0x42u8, 0x02, 0, 0, 0, 0];
    let mut raw = body.to_vec();
    raw.extend_from_slice(&CRC16.checksum(&body).to_le_bytes());
    let mut enc = [0u8; 32];
    let n = cobs::encode(&raw, &mut enc);
    a.push_rx(0, &enc[..n]);
    a.push_rx(0, &[0]);
    assert_eq!(a.stats().rx_version, 1);
    a.push_rx(0, &[1, 2, 3, 0]);
    assert_eq!(a.stats().rx_version, 1);
    assert_eq!(
        a.stats().rx_checksum + a.stats().rx_cobs + a.stats().rx_too_short,
        1
    );
}

fn on_air(frame: &Frame) -> std::vec::Vec<u8> {
    encode_frame(frame).unwrap().to_vec()
}

fn request_from(src: u8, dst: u8, seq: u16) -> std::vec::Vec<u8> {
    on_air(&Frame::Request {
        src: Address::Car(car(src)),
        dst: Address::Car(car(dst)),
        seq,
        tag: 1,
        payload: Payload::from_slice(&[seq as u8]).unwrap(),
    })
}

fn state_from(src: u8, seq: u8) -> std::vec::Vec<u8> {
    on_air(&Frame::State {
        src: car(src),
        seq,
        state: CarState::default(),
    })
}

fn requests_delivered(evs: &[Event]) -> std::vec::Vec<u16> {
    evs.iter()
        .filter_map(|e| match e {
            Event::Request(inc) => Some(inc.id.seq),
            _ => None,
        })
        .collect()
}

/// A request the application could not take (event queue full) is not marked as seen: its
/// retransmission delivers it.
#[test]
fn request_dropped_by_a_full_event_queue_is_delivered_on_retry() {
    let mut c = CarMac::new(CarConfig::new(car(1)));
    for s in 0..endpoint::EVENT_QUEUE as u8 {
        c.push_rx(1_000, &state_from(3, s));
    }
    c.push_rx(2_000, &request_from(2, 1, 40));
    assert_eq!(c.stats().event_overflow, 1);
    let evs = events(&mut c);
    assert_eq!(evs.len(), endpoint::EVENT_QUEUE);
    assert!(requests_delivered(&evs).is_empty());
    c.push_rx(3_000, &request_from(2, 1, 40));
    assert_eq!(requests_delivered(&events(&mut c)), [40]);
    assert_eq!(c.stats().duplicates, 0);
}

/// A full neighbour table of fresh entries does not track the newcomer, but its state still
/// reaches the application; once an entry is stale it is replaced.
#[test]
fn full_neighbour_table_still_delivers_states() {
    let mut c = CarMac::new(CarConfig::new(car(1)));
    for id in 2..2 + NEIGHBOURS as u8 {
        c.push_rx(1_000, &state_from(id, 0));
    }
    let _ = events(&mut c);
    c.push_rx(2_000, &state_from(100, 0));
    assert_eq!(c.stats().neighbour_table_full, 1);
    assert!(matches!(
        events(&mut c).as_slice(),
        [Event::State { from, .. }] if *from == car(100)
    ));
    assert!(c
        .neighbours()
        .iter()
        .all(|n| n.addr != Address::Car(car(100))));
    // Everybody else went silent: the newcomer takes a stale entry.
    let later = 1_000 + c.stale_after_us() + 1;
    c.push_rx(later, &state_from(100, 1));
    assert_eq!(c.stats().neighbour_table_full, 1);
    assert!(c
        .neighbours()
        .iter()
        .any(|n| n.addr == Address::Car(car(100))));
}

/// Sequence numbers older than the window are dropped; a peer silent for longer than
/// `DEDUP_RESET_US` (a restart) starts a new window.
#[test]
fn too_old_requests_and_window_reset_after_silence() {
    let mut c = CarMac::new(CarConfig::new(car(1)));
    c.push_rx(1_000, &request_from(2, 1, 100));
    let evs = events(&mut c);
    assert_eq!(requests_delivered(&evs), [100]);
    let Some(Event::Request(inc)) = evs.into_iter().next() else {
        unreachable!()
    };
    c.reply(inc.id, 1, &[]).unwrap();
    let old = 100 - neighbours::DEDUP_WINDOW;
    c.push_rx(2_000, &request_from(2, 1, old));
    assert!(events(&mut c).is_empty());
    assert_eq!(c.stats().too_old, 1);
    // The peer restarted and reuses an old number after a long silence.
    let later = 2_000 + endpoint::DEDUP_RESET_US + 1;
    c.push_rx(later, &request_from(2, 1, old));
    assert_eq!(requests_delivered(&events(&mut c)), [old]);
    assert_eq!(c.stats().too_old, 1);
}
