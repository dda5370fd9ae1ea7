//! Medium simulations of radio-mac: state broadcast with and without the slot schedule,
//! acknowledged commands under packet loss, and attacks on authenticated commands.

use arena::radio_medium::{MediumParams, RadioMedium};
use arena::radio_sim::*;
use radio_mac::wire::{encode_frame, Frame, Payload, AUTH_TAG_LEN};
use radio_mac::{Address, CarConfig, CarId, Deframer, Event, GroundConfig, Key};

const SECOND: u64 = 1_000_000_000;

#[test]
fn state_broadcast_1_to_16_cars() {
    let mut slotted = Vec::new();
    let mut csma = Vec::new();
    for n in 1..=16 {
        for scheduled in [true, false] {
            let e = StateExperiment::new(n, scheduled, 2 * SECOND, 7 + n as u64);
            let r = run_state_experiment(&e);
            // 30 Hz per car.
            let per_car = r.sent as f64 / n as f64 / 2.0;
            assert!((29.0..=31.0).contains(&per_car), "n={n} rate {per_car}");
            assert!(r.delivery_ratio() <= 1.0);
            if scheduled {
                slotted.push(r.delivery_ratio());
            } else {
                csma.push(r.delivery_ratio());
            }
        }
    }
    for (i, r) in slotted.iter().enumerate() {
        // Up to 15 cars leave a free slot for the ground station's heartbeat, 16 a ground
        // frame now and then.
        assert!(*r >= 0.995, "slotted, {} cars: {r}", i + 1);
    }
    // The tracking broadcast as time base works as well.
    for n in [6, 12, 16] {
        let mut e = StateExperiment::new(n, true, 2 * SECOND, 3);
        e.tracking_time_base = true;
        let r = run_state_experiment(&e);
        assert!(r.delivery_ratio() >= 0.98, "tracking tick, {n} cars: {r:?}");
    }
    // With many cars, plain CSMA loses clearly more than the schedule.
    let heavy = |v: &[f64]| v[11..].iter().sum::<f64>() / 5.0;
    assert!(
        heavy(&slotted) > heavy(&csma) + 0.03,
        "slotted {slotted:?} csma {csma:?}"
    );
}

#[test]
fn ground_station_heartbeats_reach_every_car_at_full_occupancy() {
    // Every slot taken: the ground station's heartbeats go in ground frames, which the cars
    // of slots 0 and 1 leave silent, so none collides and every car hears nearly all of them.
    let e = StateExperiment::new(16, true, 8 * SECOND, 5);
    let r = run_state_experiment(&e);
    assert!(r.delivery_ratio() >= 0.999, "{r:?}");
    let beats = 9; // in 9 s (1 s warm-up), one a ground frame (32 frames, 1.07 s) at most
    for (k, &heard) in r.beats_per_car.iter().enumerate() {
        assert!(
            heard >= beats - 2,
            "car {}: {heard} heartbeats of about {beats}",
            k + 1
        );
    }
    // Two slots in 32 frames are left out: the cars of slots 0 and 1 send 31 of 32.
    let per_car = r.sent as f64 / 16.0 / 8.0;
    assert!(per_car < 30.0 && per_car > 29.5, "{per_car}");
}

#[test]
fn commands_exactly_once_under_20_percent_loss() {
    let r = run_command_experiment(3, 30, 0.2, 11);
    assert_eq!(r.issued, 30);
    assert_eq!(r.failed, 0, "{r:?}");
    assert_eq!(r.replied, 30);
    assert_eq!(r.executions.len(), 30);
    assert!(r.executions.values().all(|&n| n == 1), "{r:?}");
    assert!(r.peer_issued >= 15, "{r:?}");
    assert_eq!(r.peer_replied, r.peer_issued, "{r:?}");
    assert_eq!(r.peer_executions.len() as u32, r.peer_issued);
    assert!(r.peer_executions.values().all(|&n| n == 1), "{r:?}");
}

fn car(n: u8) -> CarId {
    CarId::new(n).unwrap()
}

#[test]
fn tampered_and_replayed_commands_rejected() {
    let mut sim = Sim::new(RadioMedium::new(MediumParams::default(), 5));
    let mut cfg = CarConfig::new(car(3));
    cfg.key = Some(Key::new(SIM_KEY));
    sim.add_car(cfg, (0.5, 0.5), Clock::IDEAL);
    sim.add_ground(GroundConfig::new(Key::new(SIM_KEY), 77), (0.0, 0.0));
    let attacker = sim.medium.add_node((1.0, 1.0));

    let mut executed = Vec::new();
    let mut replies = 0;
    let mut handler = |actor: Actor<'_>, _now: u64, ev: Event| match (actor, ev) {
        (Actor::Car { mac, .. }, Event::Request(inc)) => {
            executed.push(inc.id.counter);
            mac.reply(inc.id, 0, b"done").unwrap();
        }
        (Actor::Ground(_), Event::Reply { .. }) => replies += 1,
        _ => {}
    };

    // Two genuine commands; the attacker records the air.
    for (i, t) in [(0u8, SECOND / 10), (1, SECOND / 2)] {
        let g = sim.ground.as_mut().unwrap();
        g.station
            .command(t / 1000, Address::Car(car(3)), 1, &[i])
            .unwrap();
        sim.run_until(t + SECOND / 5, &mut handler);
    }
    let recorded = sim.medium.read(attacker, sim.now);
    let mut d = Deframer::new();
    let mut captured: Vec<Frame> = recorded
        .iter()
        .filter_map(|b| d.push(*b))
        .filter_map(Result::ok)
        .filter(|f| matches!(f, Frame::AuthCommand { .. }))
        .collect();
    // Retransmissions look alike; keep one per counter.
    captured.dedup();
    assert_eq!(captured.len(), 2);

    // Replay the first command (older counter).
    let t = sim.now;
    sim.medium
        .write(attacker, t, &encode_frame(&captured[0]).unwrap());
    // Alter the second one's payload and counter; the CRC is recomputed, the MAC cannot be.
    let Frame::AuthCommand {
        dst,
        counter,
        tag,
        mac,
        ..
    } = captured[1].clone()
    else {
        unreachable!()
    };
    let forged = Frame::AuthCommand {
        dst,
        counter: counter + 1,
        tag,
        payload: Payload::from_slice(&[9]).unwrap(),
        mac,
    };
    sim.medium
        .write(attacker, t + SECOND / 10, &encode_frame(&forged).unwrap());
    // A made-up tag.
    let guessed = Frame::AuthCommand {
        dst,
        counter: counter + 2,
        tag,
        payload: Payload::new(),
        mac: [0x5A; AUTH_TAG_LEN],
    };
    sim.medium
        .write(attacker, t + SECOND / 5, &encode_frame(&guessed).unwrap());
    sim.run_until(t + SECOND, &mut handler);

    assert_eq!(executed, vec![Some(77), Some(78)]);
    assert_eq!(replies, 2);
    let st = sim.cars[0].mac.stats();
    assert_eq!(st.auth_replay, 1);
    assert_eq!(st.auth_bad_mac, 2);
    assert_eq!(sim.cars[0].mac.replay_guard().last(), Some(78));
}

#[test]
fn garbage_on_air_is_counted_not_fatal() {
    let mut sim = Sim::new(RadioMedium::new(MediumParams::default(), 9));
    sim.add_car(CarConfig::new(car(1)), (0.0, 0.0), Clock::IDEAL);
    sim.add_car(CarConfig::new(car(2)), (0.5, 0.0), Clock::IDEAL);
    let noise = sim.medium.add_node((1.0, 0.0));
    sim.cars[0].mac.set_state(Default::default());
    sim.run_until(SECOND / 2, |_, _, _| {});
    let garbage: Vec<u8> = (0..60u8).map(|i| i.wrapping_mul(37) | 1).collect();
    let t = sim.now;
    sim.medium.write(noise, t, &garbage);
    sim.medium.write(noise, t + 1_000, &[0]);
    let mut states = 0;
    sim.run_until(SECOND * 2, |_, _, ev| {
        if matches!(ev, Event::State { .. }) {
            states += 1;
        }
    });
    let st = sim.cars[1].mac.stats();
    assert!(
        st.rx_cobs + st.rx_checksum + st.rx_oversize + st.rx_too_short >= 1,
        "{st:?}"
    );
    assert!(states > 40);
}

#[test]
fn follower_takes_the_slot_after_its_reference() {
    use radio_mac::schedule::{default_slot, StateTiming, TimeBase, FRAME_US, SLOT_US};
    let params = MediumParams::default();
    let latency_us = (params.pipeline_latency_ns(radio_mac::wire::STATE_FRAME_LEN) / 1000) as u32;
    let mut sim = Sim::new(RadioMedium::new(params, 1));
    for (id, offset_us, ppm) in [(1u8, 5_000u64, 40), (3, 917_777, -40)] {
        let mut cfg = CarConfig::new(car(id));
        cfg.timing = StateTiming::Slotted {
            slot: default_slot(car(id)),
            time_base: TimeBase::FollowLowest { latency_us },
        };
        let i = sim.add_car(cfg, (f64::from(id), 0.0), Clock { offset_us, ppm });
        sim.cars[i].mac.set_state(Default::default());
    }
    sim.run_until(SECOND, |_, _, _| {});
    let sent_at = |c: &SimCar| {
        c.clock
            .sim_time(c.mac.schedule().unwrap().last_sent().unwrap())
    };
    let (a, b) = (sent_at(&sim.cars[0]) / 1000, sent_at(&sim.cars[1]) / 1000);
    let gap = (b + u64::from(FRAME_US) - a % u64::from(FRAME_US)) % u64::from(FRAME_US);
    let want = 2 * u64::from(SLOT_US);
    assert!(
        gap.abs_diff(want) <= 20,
        "car 3 sends {gap} us after car 1, want {want}"
    );
    assert_eq!(
        sim.cars[1].mac.schedule().unwrap().reference(),
        Some(car(1))
    );
    assert_eq!(sim.medium.stats().collisions, 0);
}
