//! End-to-end tests of `almc cars` and `almc radio send` against cars running radio-mac on
//! the other side of the real-time radio hub.

use arena::hub::{CarReport, EndpointSpec, Hub, HubConfig, NodeConfig, RealtimeCar};
use radio_mac::{CarConfig, CarId, CarState, Key, Mode, Role};
use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Output};
use std::time::Duration;

const DEFAULT_KEY: [u8; 16] = *b"ALMC-testbed-key";

struct World {
    hub: Hub,
    cars: Vec<RealtimeCar>,
    radio: String,
    state: PathBuf,
}

impl World {
    fn new(tag: &str, car_key: [u8; 16]) -> Self {
        let path = |n: &str| {
            std::env::temp_dir().join(format!("almc-cli-{}-{tag}-{n}", std::process::id()))
        };
        let ground = path("ground.sock");
        let mut nodes = vec![NodeConfig::new(
            "ground",
            EndpointSpec::UnixListen(ground.clone()),
            (0.0, 2.0),
        )];
        let mut cars = Vec::new();
        for id in [3u8, 4] {
            let p = path(&format!("car{id}.sock"));
            nodes.push(NodeConfig::new(
                format!("car{id}"),
                EndpointSpec::UnixListen(p.clone()),
                (f64::from(id), 0.0),
            ));
            let mut cfg = CarConfig::new(CarId::new(id).unwrap());
            cfg.key = Some(Key::new(car_key));
            cfg.seed = u32::from(id);
            let state = CarState {
                x: 40 * u16::from(id),
                y: 800,
                heading_mrad: 3142,
                velocity_mm_s: 150,
                mode: Mode {
                    role: Role::Leader,
                    phase: 1,
                },
            };
            cars.push((p, cfg, state));
        }
        let hub = Hub::start(HubConfig::default(), nodes).unwrap();
        let cars = cars
            .into_iter()
            .map(|(p, cfg, state)| {
                RealtimeCar::spawn(
                    EndpointSpec::UnixConnect(p),
                    cfg,
                    state,
                    Duration::from_secs(2),
                )
                .unwrap()
            })
            .collect();
        World {
            hub,
            cars,
            radio: format!("unix:{}", ground.display()),
            state: path("counter"),
        }
    }

    fn stop(self) -> Vec<CarReport> {
        let _ = std::fs::remove_file(&self.state);
        let r = self.cars.into_iter().map(RealtimeCar::stop).collect();
        drop(self.hub);
        r
    }
}

fn almc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_almc"))
        .args(args)
        .env_remove("ALMC_RADIO_KEY")
        .output()
        .expect("almc runs")
}

fn json(o: &Output) -> Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {o:?}"))
}

#[test]
fn cars_json_lists_both_cars() {
    let w = World::new("cars", DEFAULT_KEY);
    let o = almc(&["cars", "--radio", &w.radio, "--listen", "1", "--json"]);
    assert!(o.status.success(), "{o:?}");
    let v = json(&o);
    let cars = v.as_array().unwrap();
    assert_eq!(cars.len(), 2, "{v}");
    assert_eq!(cars[0]["id"], 3);
    assert_eq!(cars[1]["id"], 4);
    let s = &cars[1]["state"];
    assert_eq!(s["x"], 160);
    assert_eq!(s["x_mm"], 400.0);
    assert_eq!(s["y_mm"], 2000.0);
    assert_eq!(s["heading_mrad"], 3142);
    assert_eq!(s["velocity_mm_s"], 150);
    assert_eq!(cars[1]["role"], "leader");
    assert_eq!(cars[1]["stale"], false);
    assert!(cars[1]["rssi"].is_null());
    assert!(cars[1]["last_heard_ms"].as_u64().unwrap() < 500);

    let o = almc(&["cars", "--radio", &w.radio, "--listen", "0.5"]);
    assert!(o.status.success(), "{o:?}");
    let table = String::from_utf8_lossy(&o.stdout);
    assert!(
        table.contains("leader/1") && table.contains("400.0"),
        "{table}"
    );
    w.stop();
}

#[test]
fn raw_request_gets_its_reply_and_the_counter_only_grows() {
    let w = World::new("send", DEFAULT_KEY);
    let state = w.state.to_str().unwrap();
    let send = |car: &str| {
        almc(&[
            "radio", "send", "--radio", &w.radio, "--car", car, "--tag", "0x21", "--hex",
            "0a 0b ff", "--json", "--state", state,
        ])
    };
    let o = send("4");
    assert!(o.status.success(), "{o:?}");
    let r = &json(&o)["results"][0];
    assert_eq!(r["ok"], true, "{r}");
    assert_eq!(r["car"], 4);
    assert_eq!(r["tag"], 0x21);
    assert_eq!(r["hex"], "0a 0b ff");
    let first = r["counter"].as_u64().unwrap();
    let stored: u64 = std::fs::read_to_string(&w.state)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    assert_eq!(stored, first + 1);

    let o = send("3");
    if !o.status.success() {
        let r = w.stop();
        panic!("{o:?}\n{r:#?}");
    }
    let second = json(&o)["results"][0]["counter"].as_u64().unwrap();
    assert!(second > first, "{second} after {first}");

    let o = almc(&[
        "radio", "send", "--radio", &w.radio, "--all", "--listen", "0.5", "--tag", "5", "--json",
        "--state", state,
    ]);
    assert!(o.status.success(), "{o:?}");
    let results = json(&o)["results"].as_array().unwrap().clone();
    assert_eq!(results.len(), 2);
    assert!(results.iter().all(|r| r["ok"] == true && r["hex"] == ""));
    assert!(results[0]["counter"].as_u64().unwrap() > second);

    let reports = w.stop();
    assert_eq!(reports[1].executed[0], (0x21, vec![0x0a, 0x0b, 0xff], true));
    assert_eq!(reports[0].executed.len(), 2);
    assert_eq!(reports[1].executed.len(), 2);
}

#[test]
fn wrong_key_is_rejected_by_the_car_and_reported() {
    let w = World::new("key", *b"some-other-key!!");
    let state = w.state.to_str().unwrap();
    // The timeout lies well beyond the ~6.4 s retry run, so a loaded machine still sees NoReply.
    let o = almc(&[
        "radio",
        "send",
        "--radio",
        &w.radio,
        "--car",
        "3",
        "--tag",
        "1",
        "--hex",
        "01",
        "--state",
        state,
        "--timeout",
        "20000",
    ]);
    assert_eq!(o.status.code(), Some(1), "{o:?}");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("no reply from car 3"), "{out}");
    assert!(out.contains("different key"), "{out}");
    let reports = w.stop();
    assert!(reports[0].executed.is_empty());
    assert!(reports[0].stats.auth_bad_mac >= 1, "{:?}", reports[0].stats);
}

#[test]
fn bad_arguments_fail_cleanly() {
    let cases: &[&[&str]] = &[
        &["cars", "--radio", "bogus"],
        &["cars", "--radio", "serial:/dev/x@fast"],
        &["cars", "--radio", "unix:/x", "--listen", "-3"],
        &["cars", "--radio", "unix:/x", "--key", "1234"],
        &["radio", "send", "--radio", "unix:/x", "--tag", "1"],
        &[
            "radio", "send", "--radio", "unix:/x", "--car", "0", "--tag", "1",
        ],
        &[
            "radio", "send", "--radio", "unix:/x", "--car", "1", "--tag", "256",
        ],
        &[
            "radio", "send", "--radio", "unix:/x", "--car", "1", "--tag", "1", "--hex", "0g",
        ],
        &["radio", "hub", "--node", "a=/tmp/x"],
        &["radio", "hub", "--node", "a=unix:/tmp/x"],
    ];
    for args in cases {
        let o = almc(args);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {o:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
    let o = almc(&["cars", "--radio", "unix:/nonexistent/radio.sock"]);
    assert_eq!(o.status.code(), Some(1), "{o:?}");
    assert!(String::from_utf8_lossy(&o.stderr).contains("cannot open unix:/nonexistent"));
}
