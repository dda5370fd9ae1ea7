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
        (arb_car(), arb_mode(), any::<u8>(), any::<u16>()).prop_map(
            |(src, mode, neighbours, uptime_s)| Frame::Heartbeat {
                src: Address::Car(src),
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
        (any::<u32>(), any::<u32>(), any::<[u8; AUTH_TAG_LEN]>())
            .prop_map(|(epoch, beat, mac)| Frame::GroundBeat { epoch, beat, mac }),
        (arb_car(), any::<u64>(), any::<[u8; AUTH_TAG_LEN]>())
            .prop_map(|(src, nonce, mac)| Frame::Hello { src, nonce, mac }),
        (
            arb_car(),
            any::<u64>(),
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
            any::<[u8; AUTH_TAG_LEN]>()
        )
            .prop_map(|(dst, nonce, epoch, command_min, beat_min, mac)| {
                Frame::SessionOpen {
                    dst,
                    nonce,
                    epoch,
                    command_min,
                    beat_min,
                    mac,
                }
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

/// The car's Hello to the ground station and its answer: the car joins the session.
fn join(g: &mut GroundStation, c: &mut CarMac, now: u64) {
    // The first Hello goes out within 50 ms of the car's start.
    c.poll(now);
    c.poll(now + endpoint::HELLO_FIRST_JITTER_US);
    g.push_rx(now, &drain(c));
    let _ = ground_events(g);
    c.push_rx(now, &drain_ground(g));
    assert_eq!(
        c.session().map(|s| s.epoch),
        Some(g.epoch()),
        "{:?}",
        c.stats()
    );
}

#[test]
fn authenticated_command_round_trip_and_attacks() {
    let mut g = GroundStation::new(GroundConfig::new(Key::new(KEY), 100));
    let mut c = keyed_car(5);
    join(&mut g, &mut c, 0);
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
    auth::sign(&Key::new(KEY), g.epoch(), &mut frame).unwrap();
    if let Frame::AuthCommand { payload, .. } = &mut frame {
        payload[0] = b'n';
    }
    c.push_rx(80, &encode_frame(&frame).unwrap());
    // Forged with another key.
    auth::sign(&Key::new([1; 16]), g.epoch(), &mut frame).unwrap();
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
    for c in &mut cars {
        join(&mut g, c, 0);
    }
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
    let body = [0x62u8, 0x02, 0, 0, 0, 0];
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

// ---- sessions (protocol version 2) ----

/// A ground station and cars on a lossless in-memory channel, stepped 1 ms at a time; cars
/// answer every command with its payload and record what they executed.
struct Net {
    g: GroundStation,
    cars: std::vec::Vec<CarMac>,
    now: u64,
    executed: std::vec::Vec<(u8, u32, std::vec::Vec<u8>)>,
    replies: std::vec::Vec<RequestHandle>,
    ground_beats: std::vec::Vec<u8>,
}

impl Net {
    fn new(first_counter: u32, cars: &[u8]) -> Self {
        Net {
            g: GroundStation::new(GroundConfig::new(Key::new(KEY), first_counter)),
            cars: cars.iter().map(|&id| keyed_car(id)).collect(),
            now: 0,
            executed: std::vec::Vec::new(),
            replies: std::vec::Vec::new(),
            ground_beats: std::vec::Vec::new(),
        }
    }

    /// Everything sent on the channel during the run is appended to `tape`.
    fn run_ms(&mut self, ms: u64, tape: &mut std::vec::Vec<u8>) {
        for _ in 0..ms {
            self.now += 1_000;
            let now = self.now;
            self.g.poll(now);
            let from_ground = drain_ground(&mut self.g);
            tape.extend_from_slice(&from_ground);
            let mut from_cars = std::vec::Vec::new();
            for c in &mut self.cars {
                c.push_rx(now, &from_ground);
                c.poll(now);
                for e in events(c) {
                    match e {
                        Event::Request(inc) if inc.id.counter.is_some() => {
                            let counter = inc.id.counter.unwrap();
                            self.executed
                                .push((c.id().get(), counter, inc.payload.to_vec()));
                            let _ = c.reply(inc.id, inc.tag, &inc.payload);
                        }
                        Event::Heartbeat {
                            from: Address::Ground,
                            ..
                        } => self.ground_beats.push(c.id().get()),
                        _ => {}
                    }
                }
                from_cars.extend(drain(c));
            }
            tape.extend_from_slice(&from_cars);
            self.g.push_rx(now, &from_cars);
            for e in ground_events(&mut self.g) {
                if let Event::Reply { handle, .. } = e {
                    self.replies.push(handle);
                }
            }
        }
    }

    fn command(&mut self, car_id: u8, payload: &[u8]) -> RequestHandle {
        self.g
            .command(self.now, Address::Car(car(car_id)), 1, payload)
            .unwrap()
    }
}

fn frames_of(tape: &[u8]) -> std::vec::Vec<Frame> {
    let mut d = Deframer::new();
    tape.iter()
        .filter_map(|b| d.push(*b))
        .filter_map(Result::ok)
        .collect()
}

#[test]
fn a_car_joins_a_session_before_any_command_is_executed() {
    let mut net = Net::new(10, &[4]);
    let mut tape = std::vec::Vec::new();
    // Sent before the car has a session: executed after its Hello was answered, once.
    let h = net.command(4, b"first");
    net.run_ms(500, &mut tape);
    assert!(net.replies.contains(&h));
    assert_eq!(net.executed, [(4, 10, b"first".to_vec())]);
    let frames = frames_of(&tape);
    let hello = frames.iter().position(|f| matches!(f, Frame::Hello { .. }));
    let open = frames
        .iter()
        .position(|f| matches!(f, Frame::SessionOpen { .. }));
    assert!(hello.unwrap() < open.unwrap(), "{frames:?}");
    let c = &net.cars[0];
    assert_eq!(c.session().unwrap().epoch, net.g.epoch());
    assert_eq!(c.stats().sessions_opened, 1);
}

#[test]
fn commands_recorded_before_a_restart_are_not_executed_after_it() {
    let mut net = Net::new(100, &[4]);
    let mut tape = std::vec::Vec::new();
    net.run_ms(100, &mut tape);
    net.command(4, b"go");
    net.run_ms(200, &mut tape);
    assert_eq!(net.executed.len(), 1);
    let recorded: std::vec::Vec<u8> = frames_of(&tape)
        .iter()
        .filter(|f| matches!(f, Frame::AuthCommand { .. } | Frame::GroundBeat { .. }))
        .flat_map(|f| encode_frame(f).unwrap())
        .collect();
    // The car restarts: a new endpoint with the next boot count.
    let mut cfg = CarConfig::new(car(4));
    cfg.key = Some(Key::new(KEY));
    cfg.boot = 1;
    net.cars[0] = CarMac::new(cfg);
    // Replayed before it has a session: nothing can be verified, it asks for one.
    let now = net.now;
    net.cars[0].push_rx(now, &recorded);
    assert!(events(&mut net.cars[0]).is_empty());
    assert!(net.cars[0].stats().auth_no_session >= 1);
    // Replayed again once the live ground station gave it a session: too old.
    net.run_ms(300, &mut tape);
    assert!(net.cars[0].session().is_some());
    let now = net.now;
    net.cars[0].push_rx(now, &recorded);
    assert!(events(&mut net.cars[0]).is_empty());
    assert!(net.cars[0].stats().auth_replay >= 1);
    // The ground station's next command still works.
    net.command(4, b"next");
    net.run_ms(300, &mut tape);
    assert_eq!(
        net.executed
            .iter()
            .map(|e| e.1)
            .collect::<std::vec::Vec<_>>(),
        [100, 101]
    );
}

#[test]
fn the_last_counter_leads_to_a_new_session_not_a_deaf_car() {
    let mut net = Net::new(u32::MAX - 1, &[2, 3]);
    let mut tape = std::vec::Vec::new();
    net.run_ms(100, &mut tape);
    let first_epoch = net.g.epoch();
    for (i, car_id) in [2u8, 3, 2, 3].into_iter().enumerate() {
        let h = net.command(car_id, &[i as u8]);
        net.run_ms(600, &mut tape);
        assert!(
            net.replies.contains(&h),
            "command {i} not answered: {:?} {:?} {:?} g {:?} epoch {}",
            net.cars[0].stats(),
            net.cars[0].session(),
            net.cars[1].session(),
            net.g.stats(),
            net.g.epoch()
        );
    }
    assert_eq!(net.g.epoch(), first_epoch.wrapping_add(1));
    let counters: std::vec::Vec<u32> = net.executed.iter().map(|e| e.1).collect();
    assert_eq!(counters, [u32::MAX - 1, u32::MAX, 1, 2]);
    for c in &net.cars {
        assert_eq!(c.session().unwrap().epoch, net.g.epoch());
    }
}

#[test]
fn only_authentic_fresh_ground_heartbeats_are_heard() {
    let mut net = Net::new(1, &[6]);
    let mut tape = std::vec::Vec::new();
    net.run_ms(2_500, &mut tape);
    let heard = net.ground_beats.len();
    assert!((2..=3).contains(&heard), "{heard}");
    let recorded: std::vec::Vec<Frame> = frames_of(&tape)
        .into_iter()
        .filter(|f| matches!(f, Frame::GroundBeat { .. }))
        .collect();
    let beats: std::vec::Vec<u8> = recorded
        .iter()
        .flat_map(|f| encode_frame(f).unwrap())
        .collect();
    let c = &mut net.cars[0];
    let now = net.now;
    let before = *c.stats();
    // Replayed heartbeats.
    c.push_rx(now, &beats);
    // A plain heartbeat from the ground station's address (what anybody can send).
    let mut raw = [0x42u8, 0x00, 0x00, 0x00, 0x00, 0x00, 0, 0];
    let crc = CRC16.checksum(&raw[..6]).to_le_bytes();
    raw[6..].copy_from_slice(&crc);
    let mut enc = [0u8; 16];
    let n = cobs::encode(&raw, &mut enc);
    c.push_rx(now, &enc[..n]);
    c.push_rx(now, &[0]);
    // A heartbeat of a ground station with another key, and one of our key in another epoch
    // (a recording from an earlier session).
    for (key, epoch) in [([9u8; 16], net.g.epoch()), (KEY, net.g.epoch() ^ 1)] {
        let mut f = Frame::GroundBeat {
            epoch,
            beat: 1_000,
            mac: [0; AUTH_TAG_LEN],
        };
        auth::sign(&Key::new(key), 0, &mut f).unwrap();
        c.push_rx(now, &encode_frame(&f).unwrap());
    }
    assert!(
        !events(c).iter().any(|e| matches!(
            e,
            Event::Heartbeat {
                from: Address::Ground,
                ..
            }
        )),
        "a heartbeat that is not fresh and authentic was heard"
    );
    let after = *c.stats();
    assert_eq!(
        after.auth_replay - before.auth_replay,
        recorded.len() as u32
    );
    assert_eq!(after.rx_malformed - before.rx_malformed, 1);
    assert_eq!(after.auth_bad_mac - before.auth_bad_mac, 1);
    assert_eq!(after.auth_no_session - before.auth_no_session, 1);
    // The live ground station is still heard.
    net.run_ms(1_000, &mut tape);
    assert!(net.ground_beats.len() > heard);
}

#[test]
fn a_session_opening_is_good_for_one_hello_only() {
    let mut net = Net::new(1, &[8]);
    let mut tape = std::vec::Vec::new();
    net.run_ms(50, &mut tape);
    let open = frames_of(&tape)
        .into_iter()
        .find(|f| matches!(f, Frame::SessionOpen { .. }))
        .expect("session opened");
    let c = &mut net.cars[0];
    let refused = c.stats().sessions_refused;
    c.push_rx(net.now, &encode_frame(&open).unwrap());
    assert_eq!(c.stats().sessions_refused, refused + 1);
    // A forged one for the car's next Hello is refused too.
    if let Frame::SessionOpen { nonce, mac, .. } = open {
        let forged = Frame::SessionOpen {
            dst: car(8),
            nonce: nonce + 1,
            epoch: 77,
            command_min: 0,
            beat_min: 0,
            mac,
        };
        c.push_rx(net.now, &encode_frame(&forged).unwrap());
    }
    assert_eq!(c.stats().sessions_refused, refused + 2);
    assert_eq!(c.session().unwrap().epoch, net.g.epoch());
}

proptest! {
    /// Every authenticated kind verifies with its key and epoch and with nothing else.
    #[test]
    fn signed_frames_verify_only_under_their_key(f in arb_frame(), epoch in any::<u32>(), k in any::<[u8; 16]>()) {
        let key = Key::new(k);
        let mut f = f;
        auth::sign(&key, epoch, &mut f).unwrap();
        let authenticated = matches!(
            f,
            Frame::AuthCommand { .. } | Frame::GroundBeat { .. } | Frame::Hello { .. } | Frame::SessionOpen { .. }
        );
        prop_assert_eq!(auth::verify(&key, epoch, &f), authenticated);
        let mut other = k;
        other[0] ^= 1;
        prop_assert!(!auth::verify(&Key::new(other), epoch, &f));
        // Only a command is bound to the epoch (the heartbeat carries it on air).
        let bound = matches!(f, Frame::AuthCommand { .. });
        prop_assert_eq!(auth::verify(&key, epoch ^ 1, &f), authenticated && !bound);
    }
}

/// A station that restarts (a new `almc` process, a new epoch) while the cars still hold the
/// old session: its first heartbeat reaches every car at the same instant. On a channel
/// where two frames sent in the same millisecond destroy each other, the cars' Hellos must
/// not all go out at once, or they collide at that heartbeat and at every one after it.
#[test]
fn cars_answer_a_restarted_station_without_colliding() {
    let ids = [2u8, 3, 4, 5, 6];
    let mut net = Net::new(10, &ids);
    let mut tape = std::vec::Vec::new();
    net.run_ms(300, &mut tape);
    assert!(net.cars.iter().all(|c| c.session().is_some()));
    let mut cfg = GroundConfig::new(Key::new(KEY), 500);
    cfg.epoch = 77;
    net.g = GroundStation::new(cfg);
    let mut hello_ms: std::vec::Vec<(u64, u8)> = std::vec::Vec::new();
    for _ in 0..3_000 {
        net.now += 1_000;
        let now = net.now;
        net.g.poll(now);
        let from_ground = drain_ground(&mut net.g);
        let mut senders = 0;
        let mut from_cars = std::vec::Vec::new();
        for c in &mut net.cars {
            let before = c.stats().hellos_sent;
            c.push_rx(now, &from_ground);
            c.poll(now);
            let _ = events(c);
            if c.stats().hellos_sent != before {
                hello_ms.push((now / 1_000, c.id().get()));
            }
            let out = drain(c);
            if !out.is_empty() {
                senders += 1;
                from_cars.extend(out);
            }
        }
        // Two senders in one millisecond: nothing arrives.
        if senders == 1 {
            net.g.push_rx(now, &from_cars);
        }
        let _ = ground_events(&mut net.g);
        if net
            .cars
            .iter()
            .all(|c| c.session().map(|s| s.epoch) == Some(77))
        {
            break;
        }
    }
    for c in &net.cars {
        assert_eq!(
            c.session().map(|s| s.epoch),
            Some(77),
            "car {} did not join the new epoch; Hellos at {hello_ms:?}",
            c.id().get()
        );
    }
    // The first heartbeat's Hellos went out at different instants.
    let first: std::vec::Vec<u64> = ids
        .iter()
        .filter_map(|id| hello_ms.iter().find(|h| h.1 == *id).map(|h| h.0))
        .collect();
    let mut distinct = first.clone();
    distinct.sort_unstable();
    distinct.dedup();
    assert_eq!(distinct.len(), ids.len(), "{hello_ms:?}");
}
