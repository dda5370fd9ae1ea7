//! `almc car`: the user's console to one car's UBC program over the radio.
//!
//! Connects to a car's radio byte stream (`--radio unix:PATH`, e.g. QEMU's `pci-serial`
//! chardev socket), runs a radio-mac ground station on it with the wall clock, sends one
//! console request (payload formats in `docs/ubc-app.md`) and prints the car's reply.

use std::fmt;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::{Args, Subcommand};
use radio_mac::{CarId, Event};
use serde_json::{json, Value};
use ubc_app::program::console::{
    flags, LbcOutcome, Notice, Point, Points, Reply, Request, StatsPage, Status, Tag, MAX_POINTS,
};

use crate::ground::{resolve_key, CounterError, CounterFile, GroundError, GroundLink, KeyError};
use crate::lbc::EncodeCommand;

/// `almc car ...`
#[derive(Debug, Args)]
pub struct CarArgs {
    /// The car's radio: `unix:PATH` (e.g. QEMU's pci-serial chardev socket),
    /// `tcp:127.0.0.1:PORT` or `serial:/dev/ttyUSB0[@115200]`.
    #[arg(long, value_name = "SPEC")]
    radio: String,
    /// Car ID (1..=126); default: the only car heard within two seconds.
    #[arg(long)]
    car: Option<u8>,
    /// Testbed key, 32 hex digits (default: `ALMC_RADIO_KEY`, else the documented testbed
    /// key `ALMC-testbed-key`).
    #[arg(long, value_name = "HEX")]
    key: Option<String>,
    /// Command counter file (default: `$XDG_STATE_HOME/almc/counter`).
    #[arg(long, value_name = "PATH")]
    state: Option<PathBuf>,
    /// How long to wait for the reply, ms.
    #[arg(long, default_value_t = 8000)]
    timeout_ms: u64,
    /// Stay connected this many seconds after the reply (the ground station's heartbeats keep
    /// the car's user link alive; the car stops 3 s after the ground station goes silent).
    #[arg(long, value_name = "SECS", default_value_t = 0)]
    hold: u64,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    #[command(subcommand)]
    command: CarCommand,
}

/// Console requests.
#[derive(Debug, Subcommand)]
pub enum CarCommand {
    /// Send an LBC command (as `almc lbc encode` takes it) and print the LBC's answer.
    #[command(subcommand)]
    Lbc(EncodeCommand),
    /// Pose, velocity, warnings, bring-up state and link summary.
    Status,
    /// Ask for extra stream variables (28-bit format word, e.g. 0x200 for the range sensor).
    StreamFormat {
        /// Format word (decimal or 0x hex).
        format: String,
    },
    /// Go-to-points maneuver.
    #[command(subcommand)]
    Maneuver(ManeuverCommand),
    /// Group maneuver: any registered law (`almc laws`).
    #[command(subcommand)]
    Group(GroupCommand),
    /// The car's own program loop (a firmware built from `cargo xtask new-program`).
    #[command(subcommand)]
    Program(ProgramCommand),
    /// The car's latest camera detections: frame, blob count, the followed marker's bearing and
    /// range, and one blob (0 = the largest).
    Camera {
        /// Which blob to report, largest first.
        #[arg(long, default_value_t = 0)]
        blob: u8,
    },
    /// Link and program counters (all pages, or one).
    Stats {
        /// Page 0..=3 (0 LBC requests, 1 LBC line, 2 radio, 3 program).
        #[arg(long)]
        page: Option<u8>,
    },
}

/// `almc car maneuver ...`
#[derive(Debug, Subcommand)]
pub enum ManeuverCommand {
    /// Drive through points `X,Y` (tracking units) in order, then stop.
    Start {
        /// Up to 7 points, each `X,Y`.
        #[arg(required = true, num_args = 1..=MAX_POINTS)]
        points: Vec<String>,
    },
    /// Abort the maneuver and stop the car.
    Stop,
}

/// `almc car program ...`
#[derive(Debug, Subcommand)]
pub enum ProgramCommand {
    /// Start the program loop with up to 14 arguments (-32768..=32767; their meaning is the
    /// program's).
    Start {
        /// The arguments.
        #[arg(allow_negative_numbers = true)]
        args: Vec<i16>,
    },
    /// Stop the program loop and the car.
    Stop,
}

/// `almc car group ...`
#[derive(Debug, Subcommand)]
pub enum GroupCommand {
    /// Start a group maneuver on this car (replaces any running maneuver): a registered law
    /// and its parameters as `key=value`, plus the options `reverse=allowed|turn|never`,
    /// `arrival_units=U`, `neighbours=all|none|K` (`almc laws` lists every law).
    Start {
        /// The law's name, e.g. `goto`.
        law: String,
        /// Its parameters, e.g. `x=300 y=600 speed_mm_s=200`.
        #[arg(value_name = "KEY=VALUE", allow_hyphen_values = true)]
        args: Vec<String>,
    },
    /// Next waypoint `X,Y` (tracking units) of the running law.
    Waypoint {
        /// `X,Y` with X 0..=640, Y 0..=960.
        point: String,
    },
    /// Stop the maneuver and the car.
    Stop,
}

/// Why a console exchange failed.
#[derive(Debug)]
pub enum CarError {
    /// A command-line argument is out of range or malformed.
    BadArgument(String),
    /// The key could not be read.
    Key(KeyError),
    /// The counter file could not be used.
    Counter(CounterError),
    /// The radio link failed (spec, socket, no reply, timeout).
    Ground(GroundError),
    /// No car was heard (or several, without `--car`).
    NoCar { heard: Vec<u8> },
    /// The reply did not decode.
    BadReply(ubc_app::program::console::DecodeError),
}

impl fmt::Display for CarError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CarError::BadArgument(s) => write!(f, "{s}"),
            CarError::Key(e) => write!(f, "{e}"),
            CarError::Counter(e) => write!(f, "{e}"),
            CarError::Ground(e) => write!(f, "{e}"),
            CarError::NoCar { heard } if heard.is_empty() => {
                write!(f, "no car heard on the radio (give --car N)")
            }
            CarError::NoCar { heard } => write!(f, "several cars heard {heard:?}: give --car N"),
            CarError::BadReply(e) => write!(f, "the car's reply does not decode: {e:?}"),
        }
    }
}

fn parse_int(s: &str) -> Result<i64, CarError> {
    let t = s.trim();
    let r = if let Some(h) = t.strip_prefix("0x").or_else(|| t.strip_prefix("0X")) {
        i64::from_str_radix(h, 16)
    } else {
        t.parse()
    };
    r.map_err(|_| CarError::BadArgument(format!("not a number: {s:?}")))
}

fn parse_point(s: &str) -> Result<Point, CarError> {
    let bad = || {
        CarError::BadArgument(format!(
            "point {s:?}: expected X,Y with X 0..=640, Y 0..=960"
        ))
    };
    let (x, y) = s.split_once(',').ok_or_else(bad)?;
    let x = parse_int(x).map_err(|_| bad())?;
    let y = parse_int(y).map_err(|_| bad())?;
    if !(0..=640).contains(&x) || !(0..=960).contains(&y) {
        return Err(bad());
    }
    Ok(Point {
        x: x as u16,
        y: y as u16,
    })
}

fn build_requests(cmd: &CarCommand) -> Result<Vec<Request>, CarError> {
    Ok(match cmd {
        CarCommand::Lbc(e) => {
            let c = e.to_command().map_err(|e| {
                CarError::BadArgument(format!("{}: {} is out of range", e.name, e.error.value))
            })?;
            vec![Request::Lbc(c)]
        }
        CarCommand::Status => vec![Request::Status],
        CarCommand::StreamFormat { format } => {
            let v = parse_int(format)?;
            let bits = u32::try_from(v)
                .ok()
                .filter(|b| lbc_link::StreamFormat::new(*b).is_ok())
                .ok_or_else(|| {
                    CarError::BadArgument(format!(
                        "stream format {format}: 28 bits with the NOT-IN-USE bits (0x002060E0) clear"
                    ))
                })?;
            vec![Request::StreamFormat(bits)]
        }
        CarCommand::Maneuver(ManeuverCommand::Start { points }) => {
            let mut p = Points::new();
            for s in points {
                p.push(parse_point(s)?)
                    .map_err(|_| CarError::BadArgument(format!("at most {MAX_POINTS} points")))?;
            }
            vec![Request::ManeuverStart(p)]
        }
        CarCommand::Maneuver(ManeuverCommand::Stop) => vec![Request::ManeuverStop],
        CarCommand::Group(GroupCommand::Start { law, args }) => vec![Request::GroupStart(
            crate::laws::group_params(law, args).map_err(CarError::BadArgument)?,
        )],
        CarCommand::Group(GroupCommand::Waypoint { point }) => {
            let p = parse_point(point)?;
            vec![Request::GroupWaypoint { x: p.x, y: p.y }]
        }
        CarCommand::Group(GroupCommand::Stop) => vec![Request::ManeuverStop],
        CarCommand::Program(ProgramCommand::Start { args }) => {
            if args.len() > ubc_app::program::user::MAX_ARGS {
                return Err(CarError::BadArgument(format!(
                    "at most {} program arguments",
                    ubc_app::program::user::MAX_ARGS
                )));
            }
            vec![Request::ProgramStart(args.iter().copied().collect())]
        }
        CarCommand::Program(ProgramCommand::Stop) => vec![Request::ProgramStop],
        CarCommand::Camera { blob } => vec![Request::Camera { blob: *blob }],
        CarCommand::Stats { page: Some(p) } => vec![Request::Stats(*p)],
        CarCommand::Stats { page: None } => (0..4).map(Request::Stats).collect(),
    })
}

/// Sends one console request to `car` over `link` and decodes the reply.
pub fn request(
    link: &GroundLink,
    car: CarId,
    req: &Request,
    timeout: Duration,
) -> Result<Reply, CarError> {
    let mut buf = [0u8; 32];
    let n = req
        .encode(&mut buf)
        .map_err(|e| CarError::BadArgument(format!("cannot encode the request: {e:?}")))?;
    let r = link
        .request(car, req.tag() as u8, &buf[..n], timeout)
        .map_err(CarError::Ground)?;
    Reply::decode(r.tag, &r.payload).map_err(CarError::BadReply)
}

/// Waits up to `window` for cars to be heard and returns their IDs.
pub fn discover(link: &GroundLink, window: Duration) -> Vec<u8> {
    let end = Instant::now() + window;
    loop {
        let ids: Vec<u8> = link.cars().iter().map(|c| c.id.get()).collect();
        if !ids.is_empty() || Instant::now() >= end {
            return ids;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn phase_name(p: u8) -> &'static str {
    match p {
        1 => "bringing-up",
        2 => "running",
        3 => "backoff",
        _ => "unknown",
    }
}

fn status_json(s: &Status) -> Value {
    let f = |bit| s.flags & bit != 0;
    json!({
        "phase": phase_name(s.phase),
        "car_id": s.car_id,
        "x": s.x, "y": s.y,
        "x_mm": f64::from(s.x) * 2.5, "y_mm": f64::from(s.y) * 2.5,
        "heading_mrad": s.heading_mrad,
        "steering_mrad": s.steering_mrad,
        "velocity_mm_s": s.velocity_mm_s,
        "temperature_c": if s.temperature_c == 0xFF { Value::Null } else { json!(s.temperature_c) },
        "drive_enabled": f(flags::DRIVE_ENABLED),
        "streaming": f(flags::STREAMING),
        "user_link": f(flags::USER_LINK),
        "battery_low": f(flags::BATTERY_LOW),
        "over_temperature": f(flags::OVER_TEMPERATURE),
        "maneuver": f(flags::MANEUVER),
        "maneuver_index": s.maneuver_index,
        "maneuver_len": s.maneuver_len,
        "lbc_error": f(flags::LBC_ERROR),
        "pose_valid": f(flags::POSE_VALID),
        "stream_age_ms": if s.stream_age_ms == u16::MAX { Value::Null } else { json!(s.stream_age_ms) },
        "bringups": s.bringups,
        "lbc_failures": s.lbc_failures,
        "uptime_s": s.uptime_s,
        "group": {
            "kind": maneuvers::registry::name_of(s.group_kind).to_string(),
            "phase": maneuvers::Phase::from_bits(s.group_phase).map_or("unknown", maneuvers::Phase::name),
            "converged": s.group_converged,
            "error_units": s.group_error_units,
        },
    })
}

/// The reply as JSON; `ok` is false for refusals and LBC failures.
pub fn reply_json(r: &Reply) -> (bool, Value) {
    match r {
        Reply::Refused(x) => (false, json!({ "refused": format!("{x:?}") })),
        Reply::Lbc(LbcOutcome::Answer(a)) => (
            true,
            json!({ "lbc": "answer", "reply": serde_json::to_value(a).unwrap_or(Value::Null) }),
        ),
        Reply::Lbc(LbcOutcome::Rejected(k)) => (
            false,
            json!({ "lbc": "error", "command": format!("{k:?}"), "error_header": format!("0x{:02x}", k.error_header()) }),
        ),
        Reply::Lbc(LbcOutcome::UnknownCommand) => (false, json!({ "lbc": "unknown-command" })),
        Reply::Lbc(LbcOutcome::TimedOut) => (false, json!({ "lbc": "timeout" })),
        Reply::Lbc(LbcOutcome::ChecksumErrors) => (false, json!({ "lbc": "checksum-errors" })),
        Reply::Status(s) => (true, status_json(s)),
        Reply::StreamFormat(b) => (true, json!({ "stream_format": format!("0x{b:07x}") })),
        Reply::ManeuverStarted(n) => (true, json!({ "maneuver": "started", "points": n })),
        Reply::ManeuverStopped => (true, json!({ "maneuver": "stopped" })),
        Reply::GroupStarted => (true, json!({ "group": "started" })),
        Reply::GroupWaypointSet => (true, json!({ "group": "waypoint-set" })),
        Reply::ProgramStarted => (true, json!({ "program": "started" })),
        Reply::ProgramStopped => (true, json!({ "program": "stopped" })),
        Reply::Stats { page, values } => {
            let known = StatsPage::from_number(*page);
            let names = known.map(StatsPage::counters);
            let mut m = serde_json::Map::new();
            for (i, v) in values.iter().enumerate() {
                let name = names
                    .and_then(|n| n.get(i).copied())
                    .map_or_else(|| format!("counter{i}"), str::to_string);
                m.insert(name, json!(v));
            }
            let page_name = known.map_or("unknown", StatsPage::name);
            (true, json!({ "page": page_name, "counters": m }))
        }
        Reply::Camera(c) => (true, camera_json(c)),
        // Replies a newer firmware may add.
        #[allow(unreachable_patterns)]
        other => (true, json!({ "reply": format!("{other:?}") })),
    }
}

/// A camera report as JSON: centroids in pixels, the leader only while one is followed.
fn camera_json(c: &ubc_app::program::console::CameraReport) -> Value {
    let mut v = json!({ "frame": c.sequence, "frames_processed": c.frames, "blobs": c.blobs });
    if c.leader_class != 0 {
        v["leader"] = json!({
            "class": c.leader_class,
            "follow_state": c.follow_state,
            "bearing_mrad": c.leader_bearing_mrad,
            "range_mm": (c.leader_range_mm != 0).then_some(c.leader_range_mm),
        });
    }
    if let Some((i, b)) = c.blob {
        v["blob"] = json!({
            "index": i,
            "class": b.class,
            "area": b.area,
            "centroid": [f64::from(b.cx_q2) / 4.0, f64::from(b.cy_q2) / 4.0],
            "box": [b.min_x, b.min_y, b.max_x, b.max_y],
        });
    }
    v
}

fn text_of(v: &Value) -> String {
    match v {
        Value::Object(m) => m
            .iter()
            .map(|(k, v)| match v {
                Value::Object(_) => format!("{k}: {}", text_of(v)),
                Value::String(s) => format!("{k}={s}"),
                other => format!("{k}={other}"),
            })
            .collect::<Vec<_>>()
            .join(" "),
        other => other.to_string(),
    }
}

fn run_inner(args: &CarArgs) -> Result<(bool, Vec<Value>, Vec<Notice>), CarError> {
    let (key, _) = resolve_key(args.key.as_deref()).map_err(CarError::Key)?;
    let requests = build_requests(&args.command)?;
    let counter = CounterFile::at_or_default(args.state.as_deref()).map_err(CarError::Counter)?;
    let first = counter.first_counter().map_err(CarError::Counter)?;
    let link = GroundLink::open(&args.radio, key, first)
        .map_err(CarError::Ground)?
        .with_counter_file(counter);
    let events = link.subscribe();
    let car = match args.car {
        Some(id) => CarId::new(id)
            .ok_or_else(|| CarError::BadArgument(format!("car {id}: expected 1..=126")))?,
        None => {
            let heard = discover(&link, Duration::from_millis(2_000));
            match heard.as_slice() {
                [one] => CarId::new(*one).ok_or(CarError::NoCar {
                    heard: heard.clone(),
                })?,
                _ => return Err(CarError::NoCar { heard }),
            }
        }
    };
    let timeout = Duration::from_millis(args.timeout_ms);
    let mut all_ok = true;
    let mut out = Vec::new();
    for req in &requests {
        let reply = request(&link, car, req, timeout)?;
        let (ok, v) = reply_json(&reply);
        all_ok &= ok;
        out.push(v);
    }
    std::thread::sleep(Duration::from_secs(args.hold));
    let notices = events
        .try_iter()
        .filter_map(|e| match e.event {
            Event::Request(inc) if inc.tag == Tag::Notice as u8 => {
                Notice::decode(&inc.payload).ok()
            }
            _ => None,
        })
        .collect();
    Ok((all_ok, out, notices))
}

/// Runs `almc car`.
pub fn run(args: &CarArgs) -> ExitCode {
    match run_inner(args) {
        Ok((ok, values, notices)) => {
            if args.json {
                let v = if values.len() == 1 {
                    values.into_iter().next().unwrap_or(Value::Null)
                } else {
                    Value::Array(values)
                };
                let mut doc = json!({ "ok": ok, "reply": v });
                if !notices.is_empty() {
                    doc["notices"] =
                        json!(notices.iter().map(|n| format!("{n:?}")).collect::<Vec<_>>());
                }
                println!("{doc}");
            } else {
                for v in &values {
                    println!("{}", text_of(v));
                }
                for n in &notices {
                    println!("notice: {n:?}");
                }
            }
            if ok {
                ExitCode::SUCCESS
            } else {
                ExitCode::FAILURE
            }
        }
        Err(e) => {
            if args.json {
                println!("{}", json!({ "ok": false, "error": e.to_string() }));
            } else {
                eprintln!("almc car: {e}");
            }
            match e {
                CarError::BadArgument(_)
                | CarError::Key(_)
                | CarError::Ground(GroundError::Spec(_)) => ExitCode::from(2),
                _ => ExitCode::FAILURE,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_parse_with_ranges() {
        assert_eq!(parse_point("320,480").unwrap(), Point { x: 320, y: 480 });
        assert_eq!(parse_point("0x10, 5").unwrap(), Point { x: 16, y: 5 });
        assert!(parse_point("641,0").is_err());
        assert!(parse_point("1").is_err());
        assert!(parse_point("a,b").is_err());
    }

    #[test]
    fn stream_format_arguments_are_checked() {
        let ok = build_requests(&CarCommand::StreamFormat {
            format: "0x200".into(),
        })
        .unwrap();
        assert_eq!(ok, vec![Request::StreamFormat(0x200)]);
        assert!(build_requests(&CarCommand::StreamFormat {
            format: "0x20".into()
        })
        .is_err());
        assert_eq!(
            build_requests(&CarCommand::Stats { page: None })
                .unwrap()
                .len(),
            4
        );
    }

    #[test]
    fn camera_request_and_reply() {
        use ubc_app::program::console::{BlobReport, CameraReport};
        assert_eq!(
            build_requests(&CarCommand::Camera { blob: 2 }).unwrap(),
            vec![Request::Camera { blob: 2 }]
        );
        let report = CameraReport {
            sequence: 42,
            blobs: 3,
            leader_class: 4,
            follow_state: 1,
            leader_bearing_mrad: -12,
            leader_range_mm: 0,
            frames: 40,
            blob: Some((
                0,
                BlobReport {
                    class: 4,
                    area: 729,
                    cx_q2: 1081,
                    cy_q2: 848,
                    min_x: 257,
                    min_y: 199,
                    max_x: 283,
                    max_y: 225,
                },
            )),
        };
        let (ok, v) = reply_json(&Reply::Camera(report));
        assert!(ok);
        assert_eq!(v["frame"], 42);
        assert_eq!(v["leader"]["bearing_mrad"], -12);
        assert!(v["leader"]["range_mm"].is_null());
        assert_eq!(v["blob"]["centroid"][0], 270.25);
        assert_eq!(v["blob"]["box"][3], 225);
        let (_, v) = reply_json(&Reply::Camera(CameraReport::default()));
        assert!(v.get("leader").is_none() && v.get("blob").is_none());
    }

    #[test]
    fn group_arguments_are_checked() {
        let start = |law: &str, args: &[&str]| {
            build_requests(&CarCommand::Group(GroupCommand::Start {
                law: law.into(),
                args: args.iter().map(|a| a.to_string()).collect(),
            }))
        };
        assert_eq!(
            start("goto", &["x=300", "y=600", "speed_mm_s=200"]).unwrap(),
            vec![Request::GroupStart(
                maneuvers::GoTo::params(300, 600, 200).unwrap()
            )]
        );
        assert!(start("rendezvous", &["radius_units=0"]).is_err());
        assert!(start("formation", &["leader=127"]).is_err());
        match start("formation", &["leader=1", "spacing=60"]) {
            Err(CarError::BadArgument(e)) => assert!(
                e.contains("its parameters are shape (default line), leader, slot"),
                "{e}"
            ),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            start("platoonx", &[]),
            Err(CarError::BadArgument(_))
        ));
        assert_eq!(
            build_requests(&CarCommand::Group(GroupCommand::Waypoint {
                point: "320,480".into()
            }))
            .unwrap(),
            vec![Request::GroupWaypoint { x: 320, y: 480 }]
        );
        assert!(build_requests(&CarCommand::Group(GroupCommand::Waypoint {
            point: "700,480".into()
        }))
        .is_err());
        let (ok, v) = reply_json(&Reply::Status(Status {
            group_kind: 2,
            group_phase: 3,
            group_converged: true,
            ..Status::default()
        }));
        assert!(ok);
        assert_eq!(v["group"]["kind"], "rendezvous");
        assert_eq!(v["group"]["phase"], "hold");
        let (_, v) = reply_json(&Reply::Status(Status {
            group_kind: 250,
            ..Status::default()
        }));
        assert_eq!(v["group"]["kind"], "law 250");
    }

    #[test]
    fn stats_replies_get_names() {
        let values = [1u32, 2, 3, 4, 5, 6, 7].into_iter().collect();
        let (ok, v) = reply_json(&Reply::Stats { page: 3, values });
        assert!(ok);
        assert_eq!(v["counters"]["bringups"], 1);
        assert_eq!(v["page"], "program");
        let (ok, v) = reply_json(&Reply::Lbc(LbcOutcome::Rejected(
            lbc_link::CommandKind::MoveXy,
        )));
        assert!(!ok);
        assert_eq!(v["error_header"], "0x81");
    }
}
