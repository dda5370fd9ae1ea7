//! The end of a run: the cars' link statistics, the summary, and the output files.

use super::control::CarState;
use super::*;

/// What the run loop hands over once the maneuvers are over.
pub(super) struct Finished {
    pub(super) ran: f64,
    pub(super) aborted: bool,
    pub(super) cancelled: bool,
    pub(super) log: EventLog,
    pub(super) states: Vec<CarState>,
    pub(super) phases: Vec<PhaseResult>,
    pub(super) tracks: Vec<Vec<Sample>>,
    pub(super) failures: Vec<CarFailure>,
}

/// `v` rounded to `digits` decimals (summary values are given to what they mean).
pub fn round_to(v: f64, digits: i32) -> f64 {
    let f = 10f64.powi(digits);
    (v * f).round() / f
}

/// Asks every running car for its statistics, builds the summary and writes every output.
pub(super) fn finish(
    exp: &Experiment,
    world: &mut World,
    run: Finished,
    out: &Path,
) -> Result<Summary, ExperimentError> {
    let Finished {
        ran,
        aborted,
        cancelled,
        mut log,
        states,
        phases,
        tracks,
        failures,
    } = run;
    let ids: Vec<u8> = world.ids().to_vec();
    let truth_now = world.truth();
    // Link statistics: each running car's console stats.
    let mut stats = Vec::new();
    for (k, &id) in ids.iter().enumerate() {
        let mut pages = serde_json::Map::new();
        if truth_now[k].failure.is_none() {
            for page in StatsPage::ALL {
                if let Ok(Reply::Stats { values, .. }) =
                    world.request(id, &Request::Stats(page as u8), Duration::from_secs(3))
                {
                    let counters: serde_json::Map<String, Value> = page
                        .counters()
                        .iter()
                        .zip(values.iter())
                        .map(|(n, v)| ((*n).to_owned(), json!(v)))
                        .collect();
                    pages.insert(page.name().to_owned(), Value::Object(counters));
                }
            }
        }
        stats.push(Value::Object(pages));
    }
    // The camera cars' last frame counts.
    let mut states = states;
    if exp.camera_fps.is_some() {
        for (k, &id) in ids.iter().enumerate() {
            if truth_now[k].failure.is_none() {
                if let Ok(Reply::Camera(r)) =
                    world.request(id, &Request::Camera { blob: 255 }, Duration::from_secs(3))
                {
                    let t = world.now().as_secs_f64();
                    states[k].count_frames(t, r.frames);
                }
            }
        }
    }
    for ev in world.take_events() {
        log.push_at(ev.at, Some(ev.car), &ev.what);
    }
    let truth = world.truth();
    let ground = world.ground_counters();
    let gstats = world.ground_stats();
    let medium = world.medium_stats();

    // The last go-to points each car was given.
    let last_points = |id: u8| -> Vec<[u16; 2]> {
        exp.phases
            .iter()
            .rev()
            .map(|p| p.goto_points(id))
            .find(|p| !p.is_empty())
            .unwrap_or_default()
    };
    let mut cars = Vec::new();
    for (k, &id) in ids.iter().enumerate() {
        let targets = last_points(id);
        let t = &truth[k];
        let s = &states[k];
        let load = world.core_load(k);
        cars.push(CarResult {
            id,
            distance_mm: round_to(metrics::distance_travelled(&tracks[k]), 1),
            final_error_mm: s.goto_error_mm.map(|e| round_to(e, 1)),
            arrived: targets.is_empty()
                || (!s.goto_missed && !s.goto_running && s.arrival.is_some()),
            arrival_s: s.arrival.map(|a| round_to(a, 2)),
            wall_violations: metrics::wall_violations(&tracks[k])
                .into_iter()
                .map(|t| round_to(t, 3))
                .collect(),
            stats: stats[k].clone(),
            lbc: json!({
                "rx_bytes": t.lbc.rx_bytes, "tx_bytes": t.lbc.tx_bytes,
                "commands": t.lbc.commands, "replies": t.lbc.replies, "errors": t.lbc.errors,
                "cser": t.lbc.cser, "unkcmd": t.lbc.unkcmd,
                "stream_frames": t.lbc.stream_frames, "tx_overflow": t.lbc.tx_overflow,
                "resets": t.lbc.resets,
                "fault_dropped": t.lbc_faults.dropped, "fault_corrupted": t.lbc_faults.corrupted,
                "fault_suppressed": t.lbc_faults.suppressed, "fault_resets": t.lbc_faults.resets,
            }),
            tracking: json!({ "delivered": t.fixes_delivered, "dropped": t.fixes_dropped }),
            states_heard: t.states_heard,
            processor_load: load.map(|l| round_to(l.load(), 4)),
            camera_fps: s.frames.and_then(|f| f.fps()).map(|f| round_to(f, 2)),
            failed: failures.iter().find(|f| f.car == id).cloned(),
        });
    }
    let radio = json!({
        "ground": {
            "requests": ground.requests, "replies": ground.replies, "failed": ground.failed,
            "states_heard": ground.states_heard, "notices": ground.notices,
            "retries": gstats.retries, "rx_frames": gstats.rx_frames,
        },
        "medium": {
            "packets_sent": medium.packets_sent, "deliveries": medium.deliveries,
            "collisions": medium.collisions, "half_duplex": medium.half_duplex,
            "random_losses": medium.random_losses, "distance_losses": medium.distance_losses,
            "rx_overflows": medium.rx_overflows, "csma_drops": medium.csma_drops,
        },
        "nodes": world.node_counters().iter().map(|n| json!({
            "node": n.name, "bytes_in": n.bytes_in, "bytes_out": n.bytes_out,
        })).collect::<Vec<_>>(),
    });
    let phase_at = |t: f64| {
        phases
            .iter()
            .find(|p| t >= p.start_s && t <= p.end_s)
            .map(|p| p.phase)
    };
    let summary = Summary {
        name: exp.name.clone(),
        engine: world.engine_name(),
        duration_s: round_to(ran, 3),
        cancelled,
        aborted,
        completed: phases.len() == exp.phases.len() && phases.iter().all(|p| p.completed),
        all_arrived: cars.iter().all(|c| c.arrived),
        min_separation_mm: metrics::min_separation(&tracks).map(|e| round_to(e.distance_mm, 1)),
        collisions: metrics::collisions(&tracks)
            .iter()
            .map(|e| {
                json!({
                    "cars": [ids[e.cars.0], ids[e.cars.1]], "t_s": round_to(e.t, 3),
                    "distance_mm": round_to(e.distance_mm, 1), "phase": phase_at(e.t),
                })
            })
            .collect(),
        failed_cars: failures,
        phases,
        cars,
        radio,
    };

    log.finish()?;
    for &id in &exp.profile_cars {
        if let Some(rows) = world.profile(id) {
            let mut text = String::from("cycles,share,function\n");
            for (c, share, name) in rows {
                text.push_str(&format!("{c},{share:.5},\"{}\"\n", name.replace('"', "'")));
            }
            write_file(&out.join(format!("profile-car{id}.csv")), &text)?;
        }
    }
    let text = serde_json::to_string_pretty(&summary).unwrap_or_default();
    write_file(&out.join("summary.json"), &text)?;
    Ok(summary)
}

/// `run.json`: what a run depends on besides its inputs and what it cost (wall-clock times,
/// host, versions). The only output that differs between two runs of the same experiment.
pub(super) fn write_run_info(
    out: &Path,
    world: &World,
    cfg: &crate::world::WorldConfig,
    state: &str,
    started: std::time::SystemTime,
    wall: Duration,
) -> Result<(), ExperimentError> {
    let unix = started
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let host = fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_owned())
        .unwrap_or_default();
    let world_s = world.now().as_secs_f64();
    let info = json!({
        "state": state,
        "started_unix_s": unix,
        "wall_s": wall.as_secs_f64(),
        "world_s": world_s,
        "speed": if wall.as_secs_f64() > 0.0 { world_s / wall.as_secs_f64() } else { 0.0 },
        "engine": world.engine_name(),
        "host": host,
        "arena_version": env!("CARGO_PKG_VERSION"),
        "cars": world.ids().len(),
        "firmware": firmware_info(cfg),
        "load": (0..world.ids().len()).map(|k| world.core_load(k).map(|l| json!({
            "cycles": l.cycles, "awake_cycles": l.awake_cycles, "retired": l.retired,
        }))).collect::<Vec<_>>(),
    });
    let text = serde_json::to_string_pretty(&info).unwrap_or_default();
    write_file(&out.join("run.json"), &text)
}

/// Each car's firmware ELF with the SHA-256 of its bytes and of its image (`null` when it
/// cannot be read): the firmware is an input of the run as much as the experiment file.
fn firmware_info(cfg: &crate::world::WorldConfig) -> serde_json::Value {
    let mut digests: std::collections::BTreeMap<&Path, (Option<String>, Option<String>)> =
        Default::default();
    let cars: Vec<serde_json::Value> = cfg
        .cars
        .iter()
        .map(|c| {
            let elf = c.firmware.as_deref().unwrap_or(&cfg.firmware);
            let (sha, image) = digests
                .entry(elf)
                .or_insert_with(|| match fs::read(elf) {
                    Ok(b) => (Some(hex_sha256(&[&b])), image_sha256(&b)),
                    Err(_) => (None, None),
                })
                .clone();
            json!({
                "car": c.id, "elf": elf.display().to_string(),
                "sha256": sha, "image_sha256": image,
            })
        })
        .collect();
    serde_json::Value::Array(cars)
}

/// SHA-256 of the concatenated `parts`, in hex.
fn hex_sha256(parts: &[&[u8]]) -> String {
    use sha2::Digest;
    let mut h = sha2::Sha256::new();
    for p in parts {
        h.update(p);
    }
    h.finalize().iter().map(|x| format!("{x:02x}")).collect()
}

/// SHA-256 of the program an ELF loads: each loadable segment's virtual address, size in
/// memory, and bytes in the file, in the ELF's order (`None` when `elf` is not an ELF). Unlike
/// the file's hash it leaves out symbol names and debug information, which can differ
/// between two builds of the same sources in different directories while the program is the
/// same.
pub(crate) fn image_sha256(elf: &[u8]) -> Option<String> {
    use object::{Object, ObjectSegment};
    let file = object::File::parse(elf).ok()?;
    let mut parts: Vec<&[u8]> = Vec::new();
    let mut heads: Vec<[u8; 24]> = Vec::new();
    for seg in file.segments() {
        let data = seg.data().ok()?;
        let mut head = [0u8; 24];
        head[..8].copy_from_slice(&seg.address().to_le_bytes());
        head[8..16].copy_from_slice(&seg.size().to_le_bytes());
        head[16..].copy_from_slice(&(data.len() as u64).to_le_bytes());
        heads.push(head);
        parts.push(data);
    }
    let mut all: Vec<&[u8]> = Vec::with_capacity(2 * parts.len());
    for (head, data) in heads.iter().zip(parts) {
        all.push(head);
        all.push(data);
    }
    Some(hex_sha256(&all))
}

/// `[t, error_mm]` pairs as columns named with their units: `{"t_s": [...], "error_mm": [...]}`.
pub(super) fn series_columns<S: serde::Serializer>(
    v: &[[f64; 2]],
    s: S,
) -> Result<S::Ok, S::Error> {
    let t: Vec<f64> = v.iter().map(|p| p[0]).collect();
    let e: Vec<f64> = v.iter().map(|p| p[1]).collect();
    serde::Serialize::serialize(&json!({ "t_s": t, "error_mm": e }), s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On the firmware (`VTB_FIRMWARE`, which `cargo xtask test` sets): a byte changed in the
    /// debug information leaves the image's hash alone and changes the file's; one changed in
    /// the code changes both.
    #[test]
    fn image_hash_follows_the_loaded_bytes_only() {
        use object::{Object, ObjectSection};
        let Some(elf) = std::env::var_os("VTB_FIRMWARE").and_then(|p| fs::read(p).ok()) else {
            println!("SKIPPED: VTB_FIRMWARE does not name a firmware ELF");
            return;
        };
        let file = object::File::parse(&*elf).expect("an ELF");
        let offset_in = |name: &str| -> usize {
            let s = file.section_by_name(name).expect(name);
            let (start, len) = s.file_range().expect("bytes in the file");
            assert!(len > 8, "{name} is empty");
            (start + len / 2) as usize
        };
        let (debug, text) = (offset_in(".debug_str"), offset_in(".text"));
        let image = image_sha256(&elf).expect("an ELF");
        let whole = hex_sha256(&[&elf]);
        let mut changed = elf.clone();
        changed[debug] ^= 0x20;
        assert_eq!(image_sha256(&changed).as_deref(), Some(image.as_str()));
        assert_ne!(hex_sha256(&[&changed]), whole);
        let mut changed = elf.clone();
        changed[text] ^= 0x20;
        assert_ne!(image_sha256(&changed).as_deref(), Some(image.as_str()));
    }

    #[test]
    fn image_hash_needs_an_elf() {
        assert_eq!(image_sha256(b"not an ELF"), None);
        assert_eq!(image_sha256(&[]), None);
        assert_eq!(
            hex_sha256(&[b"ab", b"c"]),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}
