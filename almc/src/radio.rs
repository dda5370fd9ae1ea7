//! `almc cars` and `almc radio ...`: the ground station's transport-level tools.
//!
//! `cars` lists the cars heard on the radio; `radio send` sends one authenticated raw request
//! (tag and bytes opaque to the protocol) and prints the replies; `radio hub` runs the
//! real-time simulated radio channel between sockets (QEMU cars, emulated cars, a ground
//! station). Application-level commands live in `almc car`.

use crate::ground::{
    key, resolve_key, CarInfo, CounterFile, GroundError, GroundLink, KeyError, KeySource, Reply,
};
use arena::hub::{EndpointSpec, Hub, HubConfig, HubStats, NodeConfig};
use arena::radio_medium::MediumParams;
use clap::{ArgGroup, Args, Subcommand};
use radio_mac::{CarId, Mode, Role, MAX_PAYLOAD};
use serde_json::{json, Value};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Millimetres per tracking unit.
const MM_PER_UNIT: f64 = 2.5;

/// Exit status of a usage error (as clap's own).
const USAGE: u8 = 2;

/// Arguments of `almc cars`.
#[derive(Debug, Args)]
pub struct CarsArgs {
    /// Radio: unix:PATH, tcp:IP:PORT or serial:DEVICE[@BAUD] (115200 8N1 by default).
    #[arg(long, value_name = "SPEC")]
    radio: String,
    /// Listen this long before listing (seconds).
    #[arg(long, value_name = "SECS", default_value = "2", value_parser = parse_secs)]
    listen: Duration,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Radio key, 32 hex digits (default: $ALMC_RADIO_KEY, else the testbed default key).
    #[arg(long, value_name = "HEX32")]
    key: Option<String>,
}

/// `almc radio` subcommands.
#[derive(Debug, Subcommand)]
pub enum RadioCommand {
    /// Send one authenticated raw request and print the replies.
    Send(SendArgs),
    /// Print every radio event heard (states, heartbeats, requests) for a while.
    Monitor(MonitorArgs),
    /// Run the real-time simulated radio channel between sockets until Ctrl-C.
    Hub(HubArgs),
}

/// Arguments of `almc radio monitor`.
#[derive(Debug, Args)]
pub struct MonitorArgs {
    /// Radio: unix:PATH, tcp:IP:PORT or serial:DEVICE[@BAUD].
    #[arg(long, value_name = "SPEC")]
    radio: String,
    /// Stop after this long (seconds).
    #[arg(long, value_name = "SECS", default_value = "5", value_parser = parse_secs)]
    secs: Duration,
    /// Leave out state broadcasts (30 Hz per car).
    #[arg(long)]
    no_states: bool,
    /// Radio key, 32 hex digits (default: $ALMC_RADIO_KEY, else the testbed default key).
    #[arg(long, value_name = "HEX32")]
    key: Option<String>,
}

/// Raw request payload from `--hex`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct HexBytes(Vec<u8>);

/// Arguments of `almc radio send`.
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("target").required(true).args(["car", "all", "broadcast"])))]
pub struct SendArgs {
    /// Radio: unix:PATH, tcp:IP:PORT or serial:DEVICE[@BAUD].
    #[arg(long, value_name = "SPEC")]
    radio: String,
    /// Destination car ID (1..=126).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=126))]
    car: Option<u8>,
    /// Send to every car heard during --listen, one after the other, collecting replies.
    #[arg(long)]
    all: bool,
    /// Send one radio broadcast (repeated, unacknowledged: no replies).
    #[arg(long)]
    broadcast: bool,
    /// Application tag, 0..=255 (decimal or 0x hex).
    #[arg(long, value_name = "T", value_parser = parse_u8)]
    tag: u8,
    /// Payload bytes in hex, e.g. "01 02 ff" or 0102ff (at most 32 bytes; empty allowed).
    #[arg(long, value_name = "BYTES", default_value = "", value_parser = parse_hex)]
    hex: HexBytes,
    /// Give up on a car after this long (milliseconds).
    #[arg(long, value_name = "MS", default_value_t = 8000,
          value_parser = clap::value_parser!(u64).range(1..=600_000))]
    timeout: u64,
    /// With --all: listen this long for cars first (seconds).
    #[arg(long, value_name = "SECS", default_value = "1.5", value_parser = parse_secs)]
    listen: Duration,
    /// Print JSON.
    #[arg(long)]
    json: bool,
    /// Radio key, 32 hex digits (default: $ALMC_RADIO_KEY, else the testbed default key).
    #[arg(long, value_name = "HEX32")]
    key: Option<String>,
    /// Command-counter file (default: $XDG_STATE_HOME/almc/counter).
    #[arg(long, value_name = "PATH")]
    state: Option<PathBuf>,
}

/// Arguments of `almc radio hub`.
#[derive(Debug, Args)]
pub struct HubArgs {
    /// A node: NAME=unix:PATH (connect, e.g. QEMU's chardev socket), NAME=unix-listen:PATH,
    /// NAME=tcp:IP:PORT or NAME=tcp-listen:127.0.0.1:PORT. Repeat for every car.
    #[arg(long, value_name = "NAME=SPEC", value_parser = parse_node)]
    node: Vec<(String, EndpointSpec)>,
    /// Listen on this Unix socket for the ground station (node `ground`).
    #[arg(long, value_name = "PATH")]
    ground_listen: Option<PathBuf>,
    /// Position of a node in metres (default: nodes 1 m apart on X): NAME=X,Y.
    #[arg(long, value_name = "NAME=X,Y", value_parser = parse_pos)]
    pos: Vec<(String, (f64, f64))>,
    /// Probability that a receiver loses a packet, 0..=1.
    #[arg(long, value_name = "P", default_value_t = 0.0, value_parser = parse_probability)]
    loss: f64,
    /// Seed of the channel's randomness.
    #[arg(long, value_name = "N", default_value_t = 0)]
    seed: u64,
    /// Print statistics this often (seconds; 0: only at exit).
    #[arg(long, value_name = "SECS", default_value = "0", value_parser = parse_secs)]
    stats_every: Duration,
}

fn parse_secs(s: &str) -> Result<Duration, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("`{s}` is not a number of seconds"))?;
    if !(0.0..=3600.0).contains(&v) {
        return Err(format!("{v} s is outside 0..=3600"));
    }
    Ok(Duration::from_secs_f64(v))
}

fn parse_u8(s: &str) -> Result<u8, String> {
    let r = match s.strip_prefix("0x").or_else(|| s.strip_prefix("0X")) {
        Some(h) => u8::from_str_radix(h, 16),
        None => s.parse::<u8>(),
    };
    r.map_err(|_| format!("`{s}` is not a number in 0..=255"))
}

fn parse_hex(s: &str) -> Result<HexBytes, String> {
    let digits: String = s
        .split(|c: char| c == ',' || c.is_whitespace())
        .map(|t| t.strip_prefix("0x").unwrap_or(t))
        .collect();
    if let Some(c) = digits.chars().find(|c| !c.is_ascii_hexdigit()) {
        return Err(format!("`{c}` is not a hex digit"));
    }
    if !digits.len().is_multiple_of(2) {
        return Err("odd number of hex digits".into());
    }
    let bytes = (0..digits.len() / 2)
        .map(|i| u8::from_str_radix(&digits[2 * i..2 * i + 2], 16))
        .collect::<Result<Vec<u8>, _>>()
        .map_err(|_| "not hex".to_string())?;
    if bytes.len() > MAX_PAYLOAD {
        return Err(format!(
            "{} bytes exceed the {MAX_PAYLOAD}-byte payload limit",
            bytes.len()
        ));
    }
    Ok(HexBytes(bytes))
}

fn parse_probability(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(p) if (0.0..=1.0).contains(&p) => Ok(p),
        _ => Err(format!("`{s}` is not a probability in 0..=1")),
    }
}

fn split_name(s: &str) -> Result<(String, &str), String> {
    match s.split_once('=') {
        Some((n, rest)) if !n.is_empty() => Ok((n.to_string(), rest)),
        _ => Err(format!("`{s}` is not NAME=VALUE")),
    }
}

fn parse_node(s: &str) -> Result<(String, EndpointSpec), String> {
    let (name, spec) = split_name(s)?;
    let spec = spec.parse::<EndpointSpec>().map_err(|e| e.to_string())?;
    Ok((name, spec))
}

fn parse_pos(s: &str) -> Result<(String, (f64, f64)), String> {
    let (name, xy) = split_name(s)?;
    let bad = || format!("`{xy}` is not X,Y in metres");
    let (x, y) = xy.split_once(',').ok_or_else(bad)?;
    let x: f64 = x.trim().parse().map_err(|_| bad())?;
    let y: f64 = y.trim().parse().map_err(|_| bad())?;
    if !x.is_finite() || !y.is_finite() {
        return Err(bad());
    }
    Ok((name, (x, y)))
}

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn role_name(r: Role) -> &'static str {
    match r {
        Role::Idle => "idle",
        Role::Leader => "leader",
        Role::Follower => "follower",
        Role::Relay => "relay",
    }
}

fn open_link(radio: &str, key_flag: Option<&str>, first: u32) -> Result<GroundLink, ExitCode> {
    let resolved: Result<_, KeyError> = resolve_key(key_flag);
    let (key, source) = resolved.map_err(|e| {
        eprintln!("error: {e}");
        ExitCode::from(USAGE)
    })?;
    if source == KeySource::Default {
        eprintln!(
            "note: using the testbed default radio key (set --key or {})",
            key::KEY_ENV
        );
    }
    GroundLink::open(radio, key, first).map_err(|e| {
        eprintln!("error: {e}");
        match e {
            GroundError::Spec(_) => ExitCode::from(USAGE),
            _ => ExitCode::FAILURE,
        }
    })
}

fn car_json(c: &CarInfo) -> Value {
    let mode: Option<Mode> = c.state.map(|s| s.mode).or(c.heartbeat.map(|h| h.mode));
    let state = c.state.map(|s| {
        json!({
            "x": s.x,
            "y": s.y,
            "x_mm": f64::from(s.x) * MM_PER_UNIT,
            "y_mm": f64::from(s.y) * MM_PER_UNIT,
            "heading_mrad": s.heading_mrad,
            "heading_deg": (f64::from(s.heading_mrad) / 1000.0).to_degrees(),
            "velocity_mm_s": s.velocity_mm_s,
        })
    });
    json!({
        "id": c.id.get(),
        "state": state,
        "role": mode.map(|m| role_name(m.role)),
        "phase": mode.map(|m| m.phase),
        "last_heard_ms": c.last_heard.as_millis() as u64,
        "stale": c.stale,
        "states_heard": c.states_heard,
        "states_missed": c.states_missed,
        "rssi": Value::Null,
    })
}

fn print_cars(cars: &[CarInfo]) {
    if cars.is_empty() {
        println!("no cars heard");
        return;
    }
    println!(
        "{:>4} {:>6} {:>6} {:>8} {:>8} {:>8} {:>7} {:>9} {:>13} {:>8} {:>5}",
        "id", "x", "y", "x_mm", "y_mm", "hdg_mrad", "hdg_deg", "vel_mm/s", "mode", "heard", "rssi"
    );
    for c in cars {
        let mode = c
            .state
            .map(|s| s.mode)
            .or(c.heartbeat.map(|h| h.mode))
            .map(|m| format!("{}/{}", role_name(m.role), m.phase))
            .unwrap_or_else(|| "-".into());
        let heard = format!(
            "{}ms{}",
            c.last_heard.as_millis(),
            if c.stale { "!" } else { "" }
        );
        match c.state {
            Some(s) => println!(
                "{:>4} {:>6} {:>6} {:>8.1} {:>8.1} {:>8} {:>7.1} {:>9} {:>13} {:>8} {:>5}",
                c.id.get(),
                s.x,
                s.y,
                f64::from(s.x) * MM_PER_UNIT,
                f64::from(s.y) * MM_PER_UNIT,
                s.heading_mrad,
                (f64::from(s.heading_mrad) / 1000.0).to_degrees(),
                s.velocity_mm_s,
                mode,
                heard,
                "n/a"
            ),
            None => println!(
                "{:>4} {:>6} {:>6} {:>8} {:>8} {:>8} {:>7} {:>9} {:>13} {:>8} {:>5}",
                c.id.get(),
                "-",
                "-",
                "-",
                "-",
                "-",
                "-",
                "-",
                mode,
                heard,
                "n/a"
            ),
        }
    }
}

/// `almc cars`.
pub fn run_cars(args: CarsArgs) -> ExitCode {
    // Listening sends no command, so no counter is consumed.
    let link = match open_link(&args.radio, args.key.as_deref(), 0) {
        Ok(l) => l,
        Err(code) => return code,
    };
    eprintln!(
        "listening on {} for {:.1} s",
        link.spec(),
        args.listen.as_secs_f64()
    );
    std::thread::sleep(args.listen);
    let cars = link.cars();
    let closed = link.closed();
    print_link_summary(link);
    if args.json {
        let list: Vec<Value> = cars.iter().map(car_json).collect();
        println!("{}", Value::Array(list));
    } else {
        print_cars(&cars);
    }
    match closed {
        Some(c) => {
            eprintln!("error: {c}");
            ExitCode::FAILURE
        }
        None => ExitCode::SUCCESS,
    }
}

/// `almc radio ...`.
pub fn run(cmd: RadioCommand) -> ExitCode {
    match cmd {
        RadioCommand::Send(args) => run_send(args),
        RadioCommand::Monitor(args) => run_monitor(args),
        RadioCommand::Hub(args) => run_hub(args),
    }
}

fn print_link_summary(link: GroundLink) {
    let spec = link.spec().to_string();
    let (mac, io) = link.close();
    eprintln!(
        "{spec}: {} bytes in, {} out; {} frames, {} CRC errors, {} malformed, {} other-version; \
         {} car requests acknowledged",
        io.bytes_in,
        io.bytes_out,
        mac.rx_frames,
        mac.rx_checksum,
        mac.rx_malformed,
        mac.rx_version,
        io.requests_acknowledged
    );
}

fn run_monitor(args: MonitorArgs) -> ExitCode {
    let link = match open_link(&args.radio, args.key.as_deref(), 0) {
        Ok(l) => l,
        Err(code) => return code,
    };
    let events = link.subscribe();
    let until = Instant::now() + args.secs;
    while let Some(left) = until.checked_duration_since(Instant::now()) {
        let Ok(ev) = events.recv_timeout(left) else {
            break;
        };
        if args.no_states && matches!(ev.event, radio_mac::Event::State { .. }) {
            continue;
        }
        println!("{:>10.3} {:?}", ev.at.as_secs_f64(), ev.event);
    }
    let closed = link.closed();
    print_link_summary(link);
    match closed {
        Some(c) => {
            eprintln!("error: {c}");
            ExitCode::FAILURE
        }
        None => ExitCode::SUCCESS,
    }
}

fn reply_json(car: CarId, r: &Result<Reply, GroundError>) -> Value {
    match r {
        Ok(r) => json!({
            "car": car.get(),
            "ok": true,
            "counter": r.counter,
            "tag": r.tag,
            "hex": hex(&r.payload),
            "round_trip_ms": r.round_trip.as_secs_f64() * 1000.0,
        }),
        Err(e) => json!({
            "car": car.get(),
            "ok": false,
            "error": match e {
                GroundError::NoReply { .. } => "no_reply",
                GroundError::Timeout { .. } => "timeout",
                GroundError::Closed(_) => "closed",
                GroundError::Counter(_) => "counter",
                _ => "send",
            },
            "message": e.to_string(),
        }),
    }
}

fn run_send(args: SendArgs) -> ExitCode {
    let counter_file = match CounterFile::at_or_default(args.state.as_deref()) {
        Ok(f) => f,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let first = match counter_file.first_counter() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let counter_path = counter_file.path().display().to_string();
    let link = match open_link(&args.radio, args.key.as_deref(), first) {
        Ok(l) => l.with_counter_file(counter_file),
        Err(code) => return code,
    };
    let timeout = Duration::from_millis(args.timeout);
    let payload = &args.hex.0;

    if args.broadcast {
        return match link.broadcast(args.tag, payload, timeout) {
            Ok(b) => {
                if args.json {
                    println!(
                        "{}",
                        json!({"broadcast": true, "counter": b.counter,
                               "took_ms": b.took.as_secs_f64() * 1000.0})
                    );
                } else {
                    println!(
                        "broadcast sent (counter {}, {} ms); broadcasts are not answered",
                        b.counter,
                        b.took.as_millis()
                    );
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        };
    }

    let results: Vec<(CarId, Result<Reply, GroundError>)> = match args.car.and_then(CarId::new) {
        Some(id) => vec![(id, link.request(id, args.tag, payload, timeout))],
        None => {
            let until = Instant::now() + args.listen;
            while Instant::now() < until && link.closed().is_none() {
                std::thread::sleep(Duration::from_millis(20));
            }
            link.request_each(args.tag, payload, timeout)
        }
    };
    if results.is_empty() {
        if let Some(c) = link.closed() {
            eprintln!("error: {c}");
        } else {
            eprintln!(
                "error: no cars heard within {} s",
                args.listen.as_secs_f64()
            );
        }
        return ExitCode::FAILURE;
    }
    let all_ok = results.iter().all(|(_, r)| r.is_ok());
    eprintln!(
        "next command counter {} (kept in {counter_path})",
        link.next_counter()
    );
    if args.json {
        let list: Vec<Value> = results.iter().map(|(c, r)| reply_json(*c, r)).collect();
        println!("{}", json!({ "results": list }));
    } else {
        for (car, r) in &results {
            match r {
                Ok(r) => println!(
                    "car {}: reply tag {} [{}] ({} ms, counter {})",
                    car.get(),
                    r.tag,
                    hex(&r.payload),
                    r.round_trip.as_millis(),
                    r.counter
                ),
                Err(e) => println!("car {}: error: {e}", car.get()),
            }
        }
    }
    if all_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

fn print_hub_stats(s: &HubStats) {
    eprintln!(
        "after {:.1} s: {} packets, {} deliveries, {} collisions, {} half-duplex, {} lost \
         (random), {} lost (distance), {} rx overflows, {} csma drops",
        s.elapsed.as_secs_f64(),
        s.medium.packets_sent,
        s.medium.deliveries,
        s.medium.collisions,
        s.medium.half_duplex,
        s.medium.random_losses,
        s.medium.distance_losses,
        s.medium.rx_overflows,
        s.medium.csma_drops
    );
    for (name, n) in &s.nodes {
        eprintln!(
            "  {name:>10}: {} in ({} frames), {} out ({} frames), {} refused, {} discarded, \
             {} connects, {}",
            n.bytes_in,
            n.frames_in,
            n.bytes_out,
            n.frames_out,
            n.bytes_refused,
            n.bytes_discarded,
            n.connects,
            if n.connected { "connected" } else { "waiting" }
        );
    }
}

fn run_hub(args: HubArgs) -> ExitCode {
    let mut nodes: Vec<(String, EndpointSpec)> = args.node;
    if let Some(p) = args.ground_listen {
        nodes.push(("ground".into(), EndpointSpec::UnixListen(p)));
    }
    if nodes.len() < 2 {
        eprintln!("error: a hub needs at least two nodes (--node ..., --ground-listen ...)");
        return ExitCode::from(USAGE);
    }
    if let Some((name, _)) = args
        .pos
        .iter()
        .find(|(n, _)| !nodes.iter().any(|(m, _)| m == n))
    {
        eprintln!("error: --pos names an unknown node `{name}`");
        return ExitCode::from(USAGE);
    }
    let configs: Vec<NodeConfig> = nodes
        .into_iter()
        .enumerate()
        .map(|(i, (name, spec))| {
            let pos = args
                .pos
                .iter()
                .rev()
                .find(|(n, _)| *n == name)
                .map(|(_, p)| *p)
                .unwrap_or((i as f64, 0.0));
            NodeConfig::new(name, spec, pos)
        })
        .collect();
    let mut config = HubConfig::default();
    config.params = MediumParams {
        loss_probability: args.loss,
        ..MediumParams::default()
    };
    config.seed = args.seed;
    let stop = Arc::new(AtomicBool::new(false));
    let s = stop.clone();
    if let Err(e) = ctrlc::set_handler(move || s.store(true, Ordering::Relaxed)) {
        eprintln!("error: cannot install the signal handler: {e}");
        return ExitCode::FAILURE;
    }
    let summary: Vec<String> = configs
        .iter()
        .map(|c| {
            format!(
                "{}={} at ({}, {}) m",
                c.name, c.endpoint, c.position.0, c.position.1
            )
        })
        .collect();
    let hub = match Hub::start(config, configs) {
        Ok(h) => h,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    eprintln!(
        "radio hub running (loss {}, seed {}); Ctrl-C stops",
        args.loss, args.seed
    );
    for s in summary {
        eprintln!("  {s}");
    }
    let mut last = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(50));
        if !args.stats_every.is_zero() && last.elapsed() >= args.stats_every {
            last = Instant::now();
            print_hub_stats(&hub.stats());
        }
    }
    print_hub_stats(&hub.shutdown());
    ExitCode::SUCCESS
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn argument_parsers() {
        assert_eq!(parse_u8("0x7f"), Ok(0x7f));
        assert_eq!(parse_u8("200"), Ok(200));
        assert!(parse_u8("256").is_err());
        assert_eq!(parse_hex("01 02,ff"), Ok(HexBytes(vec![1, 2, 0xff])));
        assert_eq!(parse_hex("0x0102"), Ok(HexBytes(vec![1, 2])));
        assert_eq!(parse_hex(""), Ok(HexBytes(vec![])));
        assert!(parse_hex("012").is_err());
        assert!(parse_hex("zz").is_err());
        assert!(parse_hex(&"00".repeat(33)).is_err());
        assert!(parse_hex("é1").is_err());
        assert_eq!(parse_secs("1.5"), Ok(Duration::from_millis(1500)));
        assert!(parse_secs("-1").is_err());
        assert!(parse_secs("NaN").is_err());
        assert!(parse_secs("inf").is_err());
        assert_eq!(parse_probability("0.25"), Ok(0.25));
        assert!(parse_probability("1.5").is_err());
        assert_eq!(
            parse_pos("car1=1.5,-2"),
            Ok(("car1".to_string(), (1.5, -2.0)))
        );
        assert!(parse_pos("car1=1").is_err());
        assert!(parse_pos("=1,2").is_err());
        assert!(parse_node("a=unix:/tmp/x").is_ok());
        assert!(parse_node("a=/tmp/x").is_err());
    }

    proptest::proptest! {
        #[test]
        fn hex_parser_never_panics(s in "\\PC{0,80}") {
            let _ = parse_hex(&s);
            let _ = parse_pos(&s);
            let _ = parse_node(&s);
        }

        #[test]
        fn hex_round_trips(bytes in proptest::collection::vec(0u8.., 0..=32)) {
            proptest::prop_assert_eq!(parse_hex(&hex(&bytes)), Ok(HexBytes(bytes)));
        }
    }
}
