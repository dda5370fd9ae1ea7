//! Arena benchmarks, ignored by default (`cargo xtask bench --only arena` runs them):
//!
//! - `virtual_time_speed`: N cars on the soft core's model (`ARENA_BENCH_N`, default
//!   4,16,64,100; `ARENA_BENCH_THREADS`, default 2), in groups of up to 8 driving a wedge
//!   formation behind their leader; world seconds per wall second during bring-up and during
//!   the maneuver, and the mean processor load.
//! - `state_delivery`: N idle cars (`ARENA_DELIVERY_N`, default 4,12,16) after bring-up, for
//!   `ARENA_DELIVERY_SECONDS` (30), with each world seed of `ARENA_DELIVERY_SEEDS` (default
//!   1,2,3,4,5); each car's state broadcasts as sent by its UART and received at every other
//!   node (cars and ground station), the same count as the radio model's (`radio_sim`) for the
//!   same schedule, car count and seed, next to it; then the mean over the seeds. One seed is
//!   one sample: where the cars start and how their slots settle differ from seed to seed.
//! - `qemu_realtime_capacity`: N QEMU cars in real time (`ARENA_QEMU_N`, default 1,4,8,16):
//!   whether each keeps its 30 Hz stream and answers its console.
//! - `formation_processor_load`: the 16-car formation of `virtual_time_speed` (two wedges of
//!   8), every car's processor profiled: each car's load and awake cycles per control step
//!   over 10 s of the maneuver, and the share of soft-float arithmetic in them.
//! - `vision_unit_load`: a car seeing two others (all standing still) on the soft core's
//!   model, with its camera at 30 and 10 fps, with the SoC's vision unit and without (the
//!   firmware's own pixel pipeline), against the same car without a camera: the awake cycles
//!   its vision costs per frame, the frames per second that allows at 14.7456 MHz, and the
//!   processor's share spent on vision at 30 fps.
//!
//! Lines starting with `figures:` are what `cargo xtask bench` reads.

use arena::camera_feed::FeedConfig;
use arena::radio_sim::{run_state_experiment, StateExperiment};
use arena::world::{CarSpec, EngineKind, Tap, TapConfig, World, WorldConfig};
use lbc_emu::Pose;
use maneuvers::Shape;
use radio_mac::{Deframer, Frame};
use std::time::{Duration, Instant};
use ubc_app::program::console::{flags, Reply, Request};

fn list(var: &str, default: &str) -> Vec<usize> {
    std::env::var(var)
        .unwrap_or_else(|_| default.into())
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect()
}

/// `n` cars on a grid filling the arena, facing up; 16 cars to a radio channel (one
/// channel's state schedule has 16 slots).
fn grid(n: usize) -> Vec<CarSpec> {
    let cols = (n as f64).sqrt().ceil() as usize;
    let rows = n.div_ceil(cols);
    (0..n)
        .map(|i| {
            let (c, r) = (i % cols, i / cols);
            let mut car = CarSpec::new(
                u8::try_from(i + 1).unwrap_or(126),
                Pose {
                    x_mm: 1500.0 * (c as f64 + 0.5) / cols as f64,
                    y_mm: 1000.0 * (r as f64 + 0.5) / rows as f64,
                    heading_rad: std::f64::consts::FRAC_PI_2,
                },
            );
            car.radio_channel = u8::try_from(i / 16).unwrap_or(0);
            car
        })
        .collect()
}

fn world(engine: EngineKind, cars: Vec<CarSpec>, threads: usize) -> World {
    World::start(&config(engine, cars, threads)).expect("world starts")
}

/// [`world`] with the world's seed (the seed of every random source: the LBCs, the radio
/// medium and ground station, the tracker).
fn world_seeded(engine: EngineKind, cars: Vec<CarSpec>, threads: usize, seed: u64) -> World {
    let mut cfg = config(engine, cars, threads);
    cfg.seed = seed;
    World::start(&cfg).expect("world starts")
}

fn world_profiled(
    engine: EngineKind,
    cars: Vec<CarSpec>,
    threads: usize,
    profile_cars: Vec<u8>,
) -> World {
    let mut cfg = config(engine, cars, threads);
    cfg.profile_cars = profile_cars;
    World::start(&cfg).expect("world starts")
}

/// The benchmarks' world: `cars` on `engine`'s default firmware, stepped by `threads`.
fn config(engine: EngineKind, cars: Vec<CarSpec>, threads: usize) -> WorldConfig {
    let elf = engine.default_firmware().expect("firmware ELF");
    let mut cfg = WorldConfig::new(elf, cars);
    cfg.engine = engine;
    cfg.threads = threads;
    cfg
}

/// Polls every car until its program runs with a valid pose; the number that did.
fn bring_up(w: &mut World, limit: Duration) -> usize {
    let deadline = w.now() + limit;
    let ids = w.ids().to_vec();
    let mut up = 0;
    for id in ids {
        loop {
            if let Ok(Reply::Status(s)) = w.request(id, &Request::Status, Duration::from_secs(5)) {
                if s.phase == 2 && s.flags & flags::POSE_VALID != 0 {
                    up += 1;
                    break;
                }
            }
            if w.now() > deadline {
                break;
            }
            w.run_for(Duration::from_millis(200));
        }
    }
    up
}

/// Groups of up to 8 cars (by ID) in a wedge behind the first of each, every leader sent to
/// (300, 700).
fn start_wedges(w: &mut World) {
    let ids = w.ids().to_vec();
    for group in ids.chunks(8) {
        let leader = group[0];
        let p = maneuvers::Formation::params(Shape::Wedge, leader, None, 60, 100).unwrap();
        for &id in group.iter().skip(1).chain(std::iter::once(&leader)) {
            let _ = w.request(id, &Request::GroupStart(p), Duration::from_secs(5));
        }
        let _ = w.request(
            leader,
            &Request::GroupWaypoint { x: 300, y: 700 },
            Duration::from_secs(5),
        );
    }
}

fn mean_load(w: &World) -> f64 {
    let n = w.ids().len();
    (0..n)
        .filter_map(|k| w.core_load(k))
        .map(|l| l.load())
        .sum::<f64>()
        / n as f64
}

#[test]
#[ignore = "benchmark: minutes; run explicitly"]
fn virtual_time_speed() {
    let threads = list("ARENA_BENCH_THREADS", "2")
        .first()
        .copied()
        .unwrap_or(2);
    println!("| cars | threads | bring-up: world s / wall s | formation: world s / wall s | cars up | mean processor load |");
    println!("|---:|---:|---:|---:|---:|---:|");
    for n in list("ARENA_BENCH_N", "4,16,64,100") {
        let mut w = world(EngineKind::Iss, grid(n), threads);
        let t = Instant::now();
        let up = bring_up(&mut w, Duration::from_secs(60));
        let bring = w.now().as_secs_f64() / t.elapsed().as_secs_f64();
        start_wedges(&mut w);
        let window = Duration::from_secs(10);
        let (w0, t0) = (w.now(), Instant::now());
        w.run_until(w0 + window);
        let speed = window.as_secs_f64() / t0.elapsed().as_secs_f64();
        let load = mean_load(&w);
        println!(
            "| {n} | {threads} | {bring:.1} | {speed:.2} | {up}/{n} | {:.1} % |",
            100.0 * load
        );
        println!("figures: mode=speed cars={n} threads={threads} bringup_speed={bring:.3} speed={speed:.3} up={up} load={load:.4}");
    }
}

/// State broadcasts in a stream of radio bytes: `(time of the delimiter, sender, sequence)`.
fn states_in(bytes: &[(u64, u8)]) -> Vec<(u64, u8, u8)> {
    let mut d = Deframer::new();
    let mut out = Vec::new();
    for &(t, b) in bytes {
        if let Some(Ok(Frame::State { src, seq, .. })) = d.push(b) {
            out.push((t, src.get(), seq));
        }
    }
    out
}

/// State delivery as the radio model counts it: every state broadcast a car's UART sent in
/// the window, at every other node (the other cars and the ground station), from what the
/// nodes wrote and received (no requests on the channel while measuring). Returns the ratio
/// over all cars and the worst car's.
fn delivery(tap: &Tap, nodes: usize) -> (f64, f64) {
    let received: Vec<Vec<(u64, u8, u8)>> =
        tap.radio.iter().map(|n| states_in(&n.received)).collect();
    let mut per_car = Vec::new();
    for (node, traffic) in tap.radio.iter().enumerate().skip(1) {
        let (mut heard, mut expected) = (0u64, 0u64);
        for (t, src, seq) in states_in(&traffic.wrote) {
            expected += (nodes - 1) as u64;
            // A reception of the same sequence number within the next frame period.
            heard += received
                .iter()
                .enumerate()
                .filter(|&(other, _)| other != node)
                .filter(|(_, rx)| {
                    rx.iter()
                        .any(|&(r, s, q)| s == src && q == seq && r > t && r < t + 40_000_000)
                })
                .count() as u64;
        }
        per_car.push((heard, expected));
    }
    let (h, e) = per_car
        .iter()
        .fold((0, 0), |(h, e), &(a, b)| (h + a, e + b));
    let worst = per_car
        .iter()
        .map(|&(a, b)| a as f64 / b.max(1) as f64)
        .fold(f64::INFINITY, f64::min);
    (h as f64 / e.max(1) as f64, worst)
}

#[test]
#[ignore = "benchmark: minutes; run explicitly"]
fn state_delivery() {
    println!("| cars | world seed | arena: all receivers (worst car) | radio model, same schedule (slotted, follow lowest ID): all receivers | difference, points |");
    println!("|---:|---:|---:|---:|---:|");
    let seconds = list("ARENA_DELIVERY_SECONDS", "30")
        .first()
        .copied()
        .unwrap_or(30) as u64;
    let seeds = list("ARENA_DELIVERY_SEEDS", "1,2,3,4,5");
    for n in list("ARENA_DELIVERY_N", "4,12,16") {
        let mut rows = Vec::new();
        for &seed in &seeds {
            let mut w = world_seeded(EngineKind::Iss, grid(n), 2, seed as u64);
            bring_up(&mut w, Duration::from_secs(60));
            w.run_for(Duration::from_secs(2));
            w.start_tap(TapConfig::default());
            w.run_for(Duration::from_secs(seconds));
            let (arena, worst) = delivery(&w.take_tap(), n + 1);
            let model = run_state_experiment(&StateExperiment::new(
                n,
                true,
                seconds * 1_000_000_000,
                seed as u64,
            ))
            .delivery_ratio();
            println!(
                "| {n} | {seed} | {:.2} % ({:.2} %) | {:.2} % | {:+.2} |",
                100.0 * arena,
                100.0 * worst,
                100.0 * model,
                100.0 * (arena - model)
            );
            rows.push((arena, worst, model));
        }
        let k = rows.len().max(1) as f64;
        let arena = rows.iter().map(|r| r.0).sum::<f64>() / k;
        let model = rows.iter().map(|r| r.2).sum::<f64>() / k;
        let lowest = rows.iter().map(|r| r.0).fold(f64::INFINITY, f64::min);
        let worst = rows.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
        println!(
            "| {n} | mean of {} | **{:.2} %** (lowest seed {:.2} %, worst car {:.2} %) | {:.2} % | **{:+.2}** |",
            rows.len(),
            100.0 * arena,
            100.0 * lowest,
            100.0 * worst,
            100.0 * model,
            100.0 * (arena - model)
        );
        println!(
            "figures: mode=delivery cars={n} seeds={} arena={arena:.5} lowest={lowest:.5} worst={worst:.5} model={model:.5}",
            rows.len()
        );
    }
}

#[test]
#[ignore = "benchmark: minutes of QEMU; run explicitly"]
fn qemu_realtime_capacity() {
    if qemu_harness::skip_qemu_tests("qemu_realtime_capacity") {
        return;
    }
    println!("| N | up | LBC stream Hz min | tracking fixes Hz min | radio states heard Hz per car min / mean |");
    println!("|---:|---:|---:|---:|---:|");
    for n in list("ARENA_QEMU_N", "1,4,8,16") {
        let mut w = world(EngineKind::Qemu, grid(n), 1);
        let up = bring_up(&mut w, Duration::from_secs(90));
        let a = w.truth();
        let t0 = w.now();
        w.run_for(Duration::from_secs(10));
        let b = w.truth();
        let dt = (w.now() - t0).as_secs_f64();
        let rate = |f: &dyn Fn(usize) -> u64| {
            let r: Vec<f64> = (0..n).map(|k| f(k) as f64 / dt).collect();
            (
                r.iter().copied().fold(f64::INFINITY, f64::min),
                r.iter().sum::<f64>() / n as f64,
            )
        };
        let lbc = rate(&|k| b[k].lbc.stream_frames - a[k].lbc.stream_frames);
        let fixes = rate(&|k| b[k].fixes_delivered - a[k].fixes_delivered);
        let states = rate(&|k| b[k].states_heard - a[k].states_heard);
        println!(
            "| {n} | {up}/{n} | {:.1} | {:.1} | {:.1} / {:.1} |",
            lbc.0, fixes.0, states.0, states.1
        );
    }
}

/// Whether a profiled function is soft-float arithmetic: `compiler_builtins`' `f32`/`f64`
/// routines and the `f32` helpers of `maneuvers` (`fmath`, `geom`).
fn soft_float(function: &str) -> bool {
    let name = function.rsplit("::").next().unwrap_or(function);
    let builtin = name.starts_with("__")
        && [
            "sf3", "df3", "sf2", "df2", "sfsi", "sfdi", "sisf", "unsisf", "sidf",
        ]
        .iter()
        .any(|end| name.ends_with(end));
    builtin
        || function.contains("compiler_builtins::float")
        || function.contains("maneuvers::fmath")
        || function.contains("maneuvers::geom")
}

/// Cycles by function of car `id` so far.
fn profile_of(w: &World, id: u8) -> std::collections::HashMap<String, u64> {
    w.profile(id)
        .unwrap_or_default()
        .into_iter()
        .map(|(cycles, _, f)| (f, cycles))
        .collect()
}

#[test]
#[ignore = "benchmark: minutes; run explicitly"]
fn formation_processor_load() {
    const N: usize = 16;
    const WINDOW_S: u64 = 10;
    const CONTROL_HZ: u64 = 30;
    let cars = grid(N);
    let ids: Vec<u8> = cars.iter().map(|c| c.id).collect();
    let mut w = world_profiled(EngineKind::Iss, cars, 2, ids.clone());
    let up = bring_up(&mut w, Duration::from_secs(60));
    assert_eq!(up, N, "every car up");
    start_wedges(&mut w);
    let before: Vec<_> = (0..N).map(|k| w.core_load(k).expect("load")).collect();
    let prof_before: Vec<_> = ids.iter().map(|&id| profile_of(&w, id)).collect();
    w.run_for(Duration::from_secs(WINDOW_S));
    println!("| car | processor load | awake cycles per control step | of which soft float |");
    println!("|---:|---:|---:|---:|");
    let (mut sum_load, mut sum_awake) = (0.0, 0u64);
    for (k, &id) in ids.iter().enumerate() {
        let after = w.core_load(k).expect("load");
        let cycles = after.cycles - before[k].cycles;
        let awake = after.awake_cycles - before[k].awake_cycles;
        let load = awake as f64 / cycles.max(1) as f64;
        let per_step = awake / (WINDOW_S * CONTROL_HZ);
        let soft: u64 = profile_of(&w, id)
            .iter()
            .filter(|(f, _)| soft_float(f))
            .map(|(f, c)| c - prof_before[k].get(f).copied().unwrap_or(0))
            .sum();
        println!(
            "| {id} | {:.1} % | {per_step} | {:.1} % |",
            100.0 * load,
            100.0 * soft as f64 / awake.max(1) as f64
        );
        sum_load += load;
        sum_awake += per_step;
    }
    // Where the first car's cycles went in the window.
    let (id, k) = (ids[0], 0);
    let mut top: Vec<(u64, String)> = profile_of(&w, id)
        .into_iter()
        .map(|(f, c)| (c - prof_before[k].get(&f).copied().unwrap_or(0), f))
        .filter(|(c, f)| *c > 0 && f != "(asleep in WFI)")
        .collect();
    top.sort_by(|a, b| b.0.cmp(&a.0).then_with(|| a.1.cmp(&b.1)));
    println!("\ncar {id}, largest awake shares in the window:\n");
    println!("| function | cycles per control step |");
    println!("|---|---:|");
    for (c, f) in top.iter().take(12) {
        println!("| `{f}` | {} |", c / (WINDOW_S * CONTROL_HZ));
    }
    let mean_load = sum_load / N as f64;
    let mean_step = sum_awake / N as u64;
    println!(
        "\nmean: load {:.1} %, {mean_step} awake cycles per control step",
        100.0 * mean_load
    );
    println!("figures: mode=profile cars={N} load={mean_load:.4} awake_per_step={mean_step}");
}

/// What the viewer of [`vision_scene`] did over the measuring window.
struct VisionRun {
    /// Awake cycles per second.
    awake_per_s: f64,
    /// Frames per second its firmware processed.
    frames_per_s: f64,
}

/// Three cars standing still, car 2 seeing cars 1 and 3 ahead (`camera_unit.rs`'s scene), the
/// camera at `fps` (none: no camera) with or without the vision unit; car 2 measured over
/// `window` after bring-up.
fn vision_scene(camera: Option<(f64, bool)>, window: Duration) -> VisionRun {
    const VIEWER: u8 = 2;
    let up = std::f64::consts::FRAC_PI_2;
    let pose = |x: f64, y: f64, heading_rad: f64| Pose {
        x_mm: x * 2.5,
        y_mm: y * 2.5,
        heading_rad,
    };
    let elf = EngineKind::Iss.default_firmware().expect("firmware ELF");
    let mut cfg = WorldConfig::new(
        elf,
        vec![
            CarSpec::new(1, pose(300.0, 330.0, up)),
            CarSpec::new(VIEWER, pose(300.0, 110.0, up)),
            CarSpec::new(3, pose(390.0, 290.0, 0.4)),
        ],
    );
    cfg.camera = camera.map(|(fps, vision_unit)| FeedConfig {
        fps,
        vision_unit,
        ..FeedConfig::default()
    });
    let mut w = World::start(&cfg).expect("world starts");
    assert_eq!(bring_up(&mut w, Duration::from_secs(60)), 3, "every car up");
    let frames = |w: &mut World| match w.request(
        VIEWER,
        &Request::Camera { blob: 0 },
        Duration::from_secs(5),
    ) {
        Ok(Reply::Camera(r)) => r.frames,
        other => panic!("{other:?}"),
    };
    let k = w.ids().iter().position(|&i| i == VIEWER).unwrap();
    // settle into the camera's rhythm, then measure
    w.run_for(Duration::from_secs(1));
    let (l0, f0, t0) = (w.core_load(k).unwrap(), frames(&mut w), w.now());
    w.run_for(window);
    let (l1, f1, t1) = (w.core_load(k).unwrap(), frames(&mut w), w.now());
    let dt = (t1 - t0).as_secs_f64();
    VisionRun {
        awake_per_s: (l1.awake_cycles - l0.awake_cycles) as f64 / dt,
        frames_per_s: f64::from(f1.wrapping_sub(f0)) / dt,
    }
}

#[test]
#[ignore = "benchmark: minutes; run explicitly"]
fn vision_unit_load() {
    const WINDOW: Duration = Duration::from_secs(4);
    let clock = soc_model::CLOCK_HZ as f64;
    let base = vision_scene(None, WINDOW);
    println!(
        "no camera: {:.0} awake cycles per second ({:.1} % of the processor)\n",
        base.awake_per_s,
        100.0 * base.awake_per_s / clock
    );
    println!("| vision | camera fps | frames processed per s | awake cycles per frame for vision | frames/s at 14.7456 MHz | processor on vision |");
    println!("|---|---:|---:|---:|---:|---:|");
    let mut per_frame = [0.0f64; 2];
    let mut share_30 = [0.0f64; 2];
    let mut fps_30 = [0.0f64; 2];
    for (i, unit) in [true, false].into_iter().enumerate() {
        for fps in [30.0, 10.0] {
            let r = vision_scene(Some((fps, unit)), WINDOW);
            let vision = (r.awake_per_s - base.awake_per_s).max(0.0);
            let cycles = vision / r.frames_per_s.max(1e-9);
            let share = vision / clock;
            println!(
                "| {} | {fps:.0} | {:.1} | {cycles:.0} | {:.0} | {:.1} % |",
                if unit {
                    "vision unit"
                } else {
                    "firmware pipeline"
                },
                r.frames_per_s,
                clock / cycles,
                100.0 * share
            );
            if fps == 30.0 {
                share_30[i] = share;
                fps_30[i] = r.frames_per_s;
            } else {
                // at 10 fps both paths keep up with every frame: the clean cost per frame
                per_frame[i] = cycles;
            }
        }
    }
    println!(
        "figures: mode=vision unit_cycles={:.0} sw_cycles={:.0} unit_fps30={:.2} sw_fps30={:.2} unit_share30={:.4} sw_share30={:.4} base_share={:.4}",
        per_frame[0],
        per_frame[1],
        fps_30[0],
        fps_30[1],
        share_30[0],
        share_30[1],
        base.awake_per_s / clock
    );
}
