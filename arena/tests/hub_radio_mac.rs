//! radio-mac endpoints over the real-time hub: two cars run by threads and a ground station
//! driven by the test share the simulated channel for a couple of seconds of wall time.

use arena::hub::{EndpointSpec, Hub, HubConfig, NodeConfig, RealtimeCar};
use radio_mac::{
    Address, CarConfig, CarId, CarState, Event, GroundConfig, GroundStation, Key, Mode, Role,
};
use std::io::{ErrorKind, Read, Write};
use std::os::unix::net::UnixStream;
use std::time::{Duration, Instant};

const KEY: [u8; 16] = *b"ALMC-testbed-key";

#[test]
fn cars_and_ground_station_over_the_hub() {
    let dir = std::env::temp_dir();
    let path = |n: &str| dir.join(format!("almc-hubmac-{}-{n}.sock", std::process::id()));
    let (p1, p2, pg) = (path("car1"), path("car2"), path("ground"));
    let hub = Hub::start(
        HubConfig::default(),
        vec![
            NodeConfig::new("car1", EndpointSpec::UnixListen(p1.clone()), (0.0, 0.0)),
            NodeConfig::new("car2", EndpointSpec::UnixListen(p2.clone()), (1.0, 0.0)),
            NodeConfig::new("ground", EndpointSpec::UnixListen(pg.clone()), (0.5, 3.0)),
        ],
    )
    .unwrap();
    let car = |id: u8, p: &std::path::Path, x: u16| {
        let mut cfg = CarConfig::new(CarId::new(id).unwrap());
        cfg.key = Some(Key::new(KEY));
        cfg.seed = u32::from(id) * 77;
        let state = CarState {
            x,
            y: 480,
            heading_mrad: 1571,
            velocity_mm_s: -200,
            mode: Mode {
                role: Role::Leader,
                phase: 2,
            },
        };
        RealtimeCar::spawn(
            EndpointSpec::UnixConnect(p.into()),
            cfg,
            state,
            Duration::from_secs(2),
        )
        .unwrap()
    };
    let c1 = car(1, &p1, 100);
    let c2 = car(2, &p2, 200);

    let mut s = UnixStream::connect(&pg).unwrap();
    s.set_nonblocking(true).unwrap();
    let mut gs = GroundStation::new(GroundConfig::new(Key::new(KEY), 10));
    let t0 = Instant::now();
    let mut buf = [0u8; 512];
    let mut reply = None;
    let mut handle = None;
    let mut states = [0u32; 3];
    while t0.elapsed() < Duration::from_millis(2500) {
        let now = t0.elapsed().as_micros() as u64;
        match s.read(&mut buf) {
            Ok(n) => gs.push_rx(now, &buf[..n]),
            Err(e) => assert_eq!(e.kind(), ErrorKind::WouldBlock),
        }
        gs.poll(now);
        if handle.is_none() && now > 1_000_000 {
            handle = Some(
                gs.command(now, Address::Car(CarId::new(2).unwrap()), 9, b"go")
                    .unwrap(),
            );
        }
        while let Some(ev) = gs.next_event() {
            match ev {
                Event::State { from, .. } => states[usize::from(from.get())] += 1,
                Event::Reply {
                    handle: h,
                    from,
                    tag,
                    payload,
                } => {
                    assert_eq!(Some(h), handle);
                    reply = Some((from, tag, payload.to_vec()));
                }
                Event::Failed { .. } => panic!("command failed"),
                _ => {}
            }
        }
        let n = gs.transmit(&mut buf);
        s.write_all(&buf[..n]).unwrap();
        std::thread::sleep(Duration::from_millis(1));
    }
    // 30 Hz for about 2.4 s after connecting; allow for start-up and scheduling jitter.
    assert!(states[1] > 40 && states[2] > 40, "{states:?}");
    assert_eq!(
        reply,
        Some((Address::Car(CarId::new(2).unwrap()), 9, b"go".to_vec()))
    );
    let car_ids: Vec<u8> = gs
        .cars()
        .filter_map(|n| match n.addr {
            Address::Car(id) => Some(id.get()),
            _ => None,
        })
        .collect();
    assert_eq!(car_ids.len(), 2);
    let (r1, r2) = (c1.stop(), c2.stop());
    assert!(r1.connected && r2.connected);
    assert!(r1.executed.is_empty());
    assert_eq!(r2.executed, vec![(9, b"go".to_vec(), true)]);
    assert!(r1.states_heard.iter().any(|&(id, n)| id == 2 && n > 40));
    let st = hub.shutdown();
    assert!(st.medium.packets_sent > 100);
    assert_eq!(st.node("car2").unwrap().connects, 1);
    assert!(st.node("ground").unwrap().frames_out > 80);
}
