//! The real-time hub with plain sockets: bytes cross the simulated channel, statistics count
//! them, listeners accept reconnects, and dropping the hub removes its socket files.

use arena::hub::{EndpointSpec, Hub, HubConfig, HubError, NodeConfig, SpecError};
use arena::radio_medium::MediumParams;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::time::{Duration, Instant};

fn sock_path(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("almc-hub-{}-{name}.sock", std::process::id()))
}

fn read_exactly(s: &mut impl Read, n: usize, within: Duration) -> Vec<u8> {
    let deadline = Instant::now() + within;
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    while got.len() < n && Instant::now() < deadline {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(k) => got.extend_from_slice(&buf[..k]),
            Err(_) => {}
        }
    }
    got
}

#[test]
fn spec_strings() {
    assert_eq!(
        "unix:/tmp/a".parse(),
        Ok(EndpointSpec::UnixConnect("/tmp/a".into()))
    );
    assert_eq!(
        "unix-listen:/tmp/a".parse(),
        Ok(EndpointSpec::UnixListen("/tmp/a".into()))
    );
    assert_eq!(
        "tcp-listen:127.0.0.1:0".parse(),
        Ok(EndpointSpec::TcpListen("127.0.0.1:0".parse().unwrap()))
    );
    assert_eq!(
        "/tmp/a".parse::<EndpointSpec>(),
        Err(SpecError::MissingScheme)
    );
    assert_eq!(
        "udp:1.2.3.4:5".parse::<EndpointSpec>(),
        Err(SpecError::UnknownScheme {
            scheme: "udp".into()
        })
    );
    assert_eq!(
        "unix:".parse::<EndpointSpec>(),
        Err(SpecError::EmptyAddress)
    );
    assert_eq!(
        "tcp:localhost".parse::<EndpointSpec>(),
        Err(SpecError::BadSocketAddr {
            value: "localhost".into()
        })
    );
    assert!(matches!(
        "tcp-listen:0.0.0.0:9".parse::<EndpointSpec>(),
        Err(SpecError::NotLoopback { .. })
    ));
}

#[test]
fn bytes_cross_the_channel_and_files_are_removed() {
    let (pa, pb) = (sock_path("a"), sock_path("b"));
    let hub = Hub::start(
        HubConfig::default(),
        vec![
            NodeConfig::new("a", EndpointSpec::UnixListen(pa.clone()), (0.0, 0.0)),
            NodeConfig::new("b", EndpointSpec::UnixListen(pb.clone()), (1.0, 0.0)),
        ],
    )
    .unwrap();
    assert!(pa.exists() && pb.exists());
    let mut a = UnixStream::connect(&pa).unwrap();
    let mut b = UnixStream::connect(&pb).unwrap();
    b.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
    // Let the hub accept both before sending: bytes for an absent client are discarded.
    std::thread::sleep(Duration::from_millis(30));
    let msg: Vec<u8> = (1..=40u8).chain([0]).collect();
    let t0 = Instant::now();
    a.write_all(&msg).unwrap();
    let got = read_exactly(&mut b, msg.len(), Duration::from_secs(2));
    assert_eq!(got, msg);
    // 41 bytes in, gap timeout, 45 byte times on air, 41 bytes out: about 11.4 ms.
    let latency = MediumParams::default().pipeline_latency_ns(msg.len());
    assert!(t0.elapsed() >= Duration::from_nanos(latency) - Duration::from_millis(2));

    let stats = hub.stats();
    let (sa, sb) = (stats.node("a").unwrap(), stats.node("b").unwrap());
    assert_eq!(sa.bytes_in, 41);
    assert_eq!(sa.frames_in, 1);
    assert_eq!(sb.bytes_out, 41);
    assert_eq!(sb.frames_out, 1);
    assert_eq!(sa.bytes_out, 0, "no echo to the sender");
    assert_eq!(stats.medium.packets_sent, 1);
    assert_eq!(stats.medium.deliveries, 1);

    drop(hub);
    assert!(!pa.exists() && !pb.exists(), "socket files removed");
}

#[test]
fn listener_accepts_a_reconnect_and_tcp_works() {
    let pa = sock_path("re");
    let hub = Hub::start(
        HubConfig::default(),
        vec![
            NodeConfig::new("a", EndpointSpec::UnixListen(pa.clone()), (0.0, 0.0)),
            NodeConfig::new("t", "tcp-listen:127.0.0.1:0".parse().unwrap(), (0.0, 1.0)),
        ],
    )
    .unwrap();
    let addr = hub.local_addr("t").unwrap();
    let mut t = TcpStream::connect(addr).unwrap();
    t.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
    {
        let _first = UnixStream::connect(&pa).unwrap();
        std::thread::sleep(Duration::from_millis(30));
    }
    let mut second = UnixStream::connect(&pa).unwrap();
    std::thread::sleep(Duration::from_millis(30));
    second.write_all(b"hello\0").unwrap();
    assert_eq!(read_exactly(&mut t, 6, Duration::from_secs(2)), b"hello\0");
    let s = hub.shutdown();
    let a = s.node("a").unwrap();
    assert_eq!(a.connects, 2);
    assert_eq!(
        a.disconnects, 2,
        "the first by its client, the second at shutdown"
    );
    assert!(!pa.exists());
}

#[test]
fn out_of_range_nodes_hear_nothing() {
    let (pa, pb) = (sock_path("far-a"), sock_path("far-b"));
    let params = MediumParams {
        range_m: 10.0,
        fade_start_m: 5.0,
        ..MediumParams::default()
    };
    let mut cfg = HubConfig::default();
    cfg.params = params;
    let hub = Hub::start(
        cfg,
        vec![
            NodeConfig::new("a", EndpointSpec::UnixListen(pa.clone()), (0.0, 0.0)),
            NodeConfig::new("b", EndpointSpec::UnixListen(pb.clone()), (1.0, 0.0)),
        ],
    )
    .unwrap();
    assert!(matches!(
        hub.set_position("nobody", (0.0, 0.0)),
        Err(HubError::UnknownNode { .. })
    ));
    hub.set_position("b", (100.0, 0.0)).unwrap();
    let mut a = UnixStream::connect(&pa).unwrap();
    let mut b = UnixStream::connect(&pb).unwrap();
    b.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
    std::thread::sleep(Duration::from_millis(30));
    a.write_all(b"far\0").unwrap();
    assert!(read_exactly(&mut b, 1, Duration::from_millis(200)).is_empty());
    hub.set_position("b", (2.0, 0.0)).unwrap();
    a.write_all(b"near\0").unwrap();
    assert_eq!(read_exactly(&mut b, 5, Duration::from_secs(2)), b"near\0");
    assert_eq!(hub.stats().medium.packets_sent, 2);
    assert_eq!(hub.stats().medium.deliveries, 1);
}

#[test]
fn bad_setups_are_errors() {
    let p = sock_path("dup");
    let r = Hub::start(
        HubConfig::default(),
        vec![
            NodeConfig::new("x", EndpointSpec::UnixListen(p.clone()), (0.0, 0.0)),
            NodeConfig::new("x", "unix:/nonexistent".parse().unwrap(), (0.0, 0.0)),
        ],
    );
    assert!(matches!(r, Err(HubError::DuplicateName { .. })));
    assert!(!p.exists(), "a failed start leaves no socket file");

    // A regular file is never replaced.
    let f = sock_path("regular");
    std::fs::write(&f, b"keep").unwrap();
    let r = Hub::start(
        HubConfig::default(),
        vec![NodeConfig::new(
            "x",
            EndpointSpec::UnixListen(f.clone()),
            (0.0, 0.0),
        )],
    );
    assert!(matches!(r, Err(HubError::PathInUse { .. })));
    assert_eq!(std::fs::read(&f).unwrap(), b"keep");
    std::fs::remove_file(&f).unwrap();
}
