//! Unit tests of experiment files.

use super::*;

const TWO: &str = r#"
name = "two"
duration_s = 30
[[cars]]
id = 1
x = 150
y = 200
heading_mrad = 1571
[[cars]]
id = 2
x = 450
y = 200
heading_mrad = 1571
[maneuver]
kind = "goto"
[[maneuver.cars]]
id = 1
points = [[150, 500]]
[[maneuver.cars]]
id = 2
points = [[450, 500], [400, 600]]
[faults]
radio_loss = 0.2
[faults.lbc]
drop = 0.001
"#;

const CARS4: &str = r#"
name = "four"
duration_s = 60
[[cars]]
id = 1
x = 300
y = 300
heading_mrad = 1571
[[cars]]
id = 2
x = 200
y = 150
[[cars]]
id = 3
x = 400
y = 150
[[cars]]
id = 4
x = 300
y = 100
"#;

const SEQUENCE: &str = r#"
[[phases]]
kind = "formation"
shape = "wedge"
leader = 1
followers = [3, 2, 4]
spacing_units = 100
speed_mm_s = 100
waypoints = [[300, 450], [300, 600]]
timeout_s = 40

[[phases]]
kind = "rendezvous"
radius_units = 60
speed_mm_s = 200
hold_s = 3

[[phases]]
kind = "circle"
centre = [300, 400]
radius_units = 150
speed_mm_s = -120
start_s = 90
"#;

fn seq() -> String {
    format!("{CARS4}{SEQUENCE}")
}

fn invalid(text: &str) -> Invalid {
    match Experiment::parse(text) {
        Err(ExperimentError::Invalid(i)) => i,
        other => panic!("{other:?}"),
    }
}

#[test]
fn parses_and_maps_to_a_world() {
    let e = Experiment::parse(TWO).unwrap();
    assert_eq!(e.cars.len(), 2);
    assert_eq!(e.phases.len(), 1);
    assert_eq!(e.phases[0].goto_points(2), vec![[450, 500], [400, 600]]);
    assert_eq!(e.phases[0].start, Start::AfterPrevious);
    assert_eq!(e.phases[0].params_for(1), None);
    let w = e.world_config(Path::new("/fw"));
    assert_eq!(w.cars[1].start.x_mm, 1125.0);
    assert_eq!(w.radio.loss_probability, 0.2);
    assert_eq!(w.lbc_faults.drop, 0.001);
    assert_eq!(w.tracking.rate_hz, 30.0);
    assert!(w.camera.is_none());
}

#[test]
fn camera_feed_from_the_file() {
    let e = Experiment::parse(&TWO.replace("duration_s = 30", "duration_s = 30\ncamera_fps = 10"))
        .unwrap();
    let feed = e.world_config(Path::new("/fw")).camera.unwrap();
    assert_eq!(feed.fps, 10.0);
    assert!(
        e.vision_unit && feed.vision_unit,
        "the vision unit by default"
    );
    let off = Experiment::parse(&TWO.replace(
        "duration_s = 30",
        "duration_s = 30\ncamera_fps = 30\nvision_unit = false",
    ))
    .unwrap();
    let feed = off.world_config(Path::new("/fw")).camera.unwrap();
    assert_eq!((feed.fps, feed.vision_unit), (30.0, false));
    assert!(Experiment::parse(
        &TWO.replace("duration_s = 30", "duration_s = 30\nvision_unit = \"yes\"")
    )
    .is_err());
    for v in ["0", "-5", "61", "nan"] {
        let text = TWO.replace(
            "duration_s = 30",
            &format!("duration_s = 30\ncamera_fps = {v}"),
        );
        assert!(matches!(invalid(&text), Invalid::CameraFps { .. }), "{v}");
    }
}

#[test]
fn a_sequence_of_group_phases() {
    let e = Experiment::parse(&seq()).unwrap();
    assert_eq!(e.phases.len(), 3);
    let f = &e.phases[0];
    assert_eq!(f.timeout_s, Some(40.0));
    assert_eq!(f.hold_s, DEFAULT_HOLD_S);
    assert_eq!(f.tolerance_mm, DEFAULT_FORMATION_TOLERANCE_MM);
    // Slots follow the `followers` order; the leader has none.
    // Values: shape, leader, slot (-1: none), spacing, speed.
    let slot = |id: u8| {
        let p = f.params_for(id).unwrap();
        let v = p.values().as_slice();
        assert_eq!(p.law(), 1);
        assert_eq!((v[0], v[1], v[3], v[4]), (Shape::Wedge as i32, 1, 100, 100));
        v[2]
    };
    assert_eq!((slot(1), slot(2), slot(3), slot(4)), (-1, 1, 0, 2));
    let r = &e.phases[1];
    assert_eq!(
        r.params_for(4),
        Some(maneuvers::Rendezvous::params(60, 200).unwrap())
    );
    assert_eq!(r.tolerance_mm, 475.0);
    assert_eq!(r.hold_s, 3.0);
    let c = &e.phases[2];
    assert_eq!(c.start, Start::At(90.0));
    assert_eq!(
        c.params_for(2),
        Some(maneuvers::Circle::params(300, 400, 150, -120).unwrap())
    );
    // Every car's parameters encode.
    for p in &e.phases {
        for car in &e.cars {
            p.params_for(car.id)
                .unwrap()
                .encode(&mut [0; maneuvers::params::MAX_LEN])
                .unwrap();
        }
    }
}

#[test]
fn goto_with_a_speed_uses_the_group_law() {
    let t = TWO.replace("kind = \"goto\"", "kind = \"goto\"\nspeed_mm_s = 200");
    // One point per car with the group law.
    assert_eq!(invalid(&t), Invalid::Points { phase: 1, id: 2 });
    let t = t.replace("[[450, 500], [400, 600]]", "[[450, 500]]");
    let e = Experiment::parse(&t).unwrap();
    let p = &e.phases[0];
    assert_eq!(
        p.params_for(2),
        Some(maneuvers::GoTo::params(450, 500, 200).unwrap())
    );
    assert_eq!(p.tolerance_mm, DEFAULT_GOTO_TOLERANCE_MM);
    // Without a speed: the console go-to, no group parameters.
    let e = Experiment::parse(TWO).unwrap();
    assert_eq!(e.phases[0].params_for(2), None);
}

#[test]
fn cars_outside_the_formation_stand_still() {
    let t = seq().replace("followers = [3, 2, 4]", "followers = [3]");
    let e = Experiment::parse(&t).unwrap();
    assert_eq!(e.phases[0].params_for(2), None);
    assert!(e.phases[0].params_for(1).is_some());
    assert!(e.phases[0].params_for(3).is_some());
}

#[test]
fn default_followers_are_the_other_cars_by_id() {
    let t = seq().replace("followers = [3, 2, 4]\n", "");
    let e = Experiment::parse(&t).unwrap();
    match &e.phases[0].kind {
        PhaseKind::Formation(f) => assert_eq!(f.followers, vec![2, 3, 4]),
        other => panic!("{other:?}"),
    }
}

#[test]
fn bad_experiments_are_rejected_with_reasons() {
    let bad = |from: &str, to: &str| {
        assert!(TWO.contains(from), "{from}");
        Experiment::parse(&TWO.replace(from, to)).unwrap_err()
    };
    assert!(matches!(
        bad("id = 2\nx", "id = 1\nx"),
        ExperimentError::Invalid(Invalid::CarId { id: 1 })
    ));
    assert!(matches!(
        bad("[[150, 500]]", "[[150, 5000]]"),
        ExperimentError::Invalid(Invalid::Points { phase: 1, id: 1 })
    ));
    assert!(matches!(
        bad("radio_loss = 0.2", "radio_loss = 2.0"),
        ExperimentError::Invalid(Invalid::Fault {
            field: "radio_loss",
            ..
        })
    ));
    assert!(matches!(
        bad("duration_s = 30", "duration_s = -1"),
        ExperimentError::Invalid(Invalid::Duration)
    ));
    assert!(matches!(bad("name =", "nom ="), ExperimentError::Parse(_)));
    assert!(matches!(
        bad("x = 150", "x = 70000"),
        ExperimentError::Parse(_)
    ));
    match bad("kind = \"goto\"", "kind = \"orbit\"") {
        ExperimentError::Invalid(i @ Invalid::UnknownKind { phase: 1, .. }) => {
            let text = i.to_string();
            assert!(
                text.contains("unknown kind `orbit`; the kinds are program and the registered laws: formation, rendezvous, circle, goto"),
                "{text}"
            );
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        bad(
            "[faults]",
            "[[phases]]\nkind = \"rendezvous\"\nradius_units = 60\nspeed_mm_s = 100\n[faults]"
        ),
        ExperimentError::Invalid(Invalid::Maneuvers)
    ));
    let none = TWO[..TWO.find("[maneuver]").unwrap()].to_owned();
    assert!(matches!(
        Experiment::parse(&none),
        Err(ExperimentError::Invalid(Invalid::Maneuvers))
    ));
    assert!(matches!(
        bad("kind = \"goto\"\n", ""),
        ExperimentError::Invalid(Invalid::MissingKind { phase: 1 })
    ));
}

#[test]
fn bad_phases_name_the_phase_and_the_field() {
    let bad = |from: &str, to: &str| {
        let t = seq();
        assert!(t.contains(from), "{from}");
        invalid(&t.replace(from, to))
    };
    assert_eq!(
        bad("radius_units = 60\n", "radius_units = 0\n"),
        Invalid::OutOfRange {
            phase: 2,
            field: "radius_units",
            value: 0.0,
            min: 1.0,
            max: 511.0
        }
    );
    assert_eq!(
        bad("radius_units = 60\n", ""),
        Invalid::Missing {
            phase: 2,
            kind: "rendezvous",
            field: "radius_units"
        }
    );
    assert_eq!(
        bad("hold_s = 3", "hold_s = 3\nleader = 1"),
        Invalid::NotApplicable {
            phase: 2,
            kind: "rendezvous",
            field: "leader"
        }
    );
    assert_eq!(
        bad("followers = [3, 2, 4]", "followers = [3, 2, 9]"),
        Invalid::Car {
            phase: 1,
            field: "followers",
            id: 9,
            problem: CarProblem::NotInExperiment
        }
    );
    assert_eq!(
        bad("followers = [3, 2, 4]", "followers = [3, 1]"),
        Invalid::Car {
            phase: 1,
            field: "followers",
            id: 1,
            problem: CarProblem::IsLeader
        }
    );
    assert_eq!(
        bad("followers = [3, 2, 4]", "followers = [3, 3]"),
        Invalid::Car {
            phase: 1,
            field: "followers",
            id: 3,
            problem: CarProblem::Duplicate
        }
    );
    assert_eq!(
        bad("leader = 1", "leader = 7"),
        Invalid::Car {
            phase: 1,
            field: "leader",
            id: 7,
            problem: CarProblem::NotInExperiment
        }
    );
    assert_eq!(
        bad("timeout_s = 40", "waypoint_at_s = [0.0]"),
        Invalid::WaypointTimes { phase: 1 }
    );
    assert_eq!(
        bad("timeout_s = 40", "waypoint_at_s = [5.0, 1.0]"),
        Invalid::WaypointTimes { phase: 1 }
    );
    assert!(Experiment::parse(&seq().replace("timeout_s = 40", "waypoint_at_s = [0, 8]")).is_ok());
    assert_eq!(
        bad("speed_mm_s = -120", "speed_mm_s = -3000"),
        Invalid::OutOfRange {
            phase: 3,
            field: "speed_mm_s",
            value: -3000.0,
            min: -2048.0,
            max: 2047.0
        }
    );
    assert_eq!(
        bad("speed_mm_s = 200", "speed_mm_s = -1"),
        Invalid::OutOfRange {
            phase: 2,
            field: "speed_mm_s",
            value: -1.0,
            min: 0.0,
            max: 2047.0
        }
    );
    assert_eq!(
        bad("spacing_units = 100", "spacing_units = 600"),
        Invalid::OutOfRange {
            phase: 1,
            field: "spacing_units",
            value: 600.0,
            min: 1.0,
            max: 511.0
        }
    );
    assert_eq!(
        bad("centre = [300, 400]", "centre = [300, 1000]"),
        Invalid::OutOfRange {
            phase: 3,
            field: "centre",
            value: 1000.0,
            min: 0.0,
            max: 960.0
        }
    );
    assert_eq!(
        bad("start_s = 90", "start_s = -1"),
        Invalid::OutOfRange {
            phase: 3,
            field: "start_s",
            value: -1.0,
            min: 0.0,
            max: 1e6
        }
    );
    assert_eq!(
        bad("hold_s = 3", "hold_s = 3\nstart_s = 100"),
        Invalid::StartOrder { phase: 3 }
    );
    assert_eq!(
        bad("kind = \"rendezvous\"\n", ""),
        Invalid::MissingKind { phase: 2 }
    );
    // Every message names the phase and the field.
    let msg = bad("radius_units = 60\n", "radius_units = 0\n").to_string();
    assert_eq!(msg, "phase 2: `radius_units` = 0 is outside 1..=511");
}

#[test]
fn load_names_the_file() {
    let dir = std::env::temp_dir().join(format!("arena-exp-load-{}", std::process::id()));
    fs::create_dir_all(&dir).unwrap();
    let p = dir.join("bad.toml");
    fs::write(
        &p,
        seq().replace("radius_units = 60\n", "radius_units = 0\n"),
    )
    .unwrap();
    let e = Experiment::load(&p).unwrap_err();
    let _ = fs::remove_dir_all(&dir);
    assert!(
        matches!(&e, ExperimentError::InFile { path, source }
            if path == &p && matches!(**source, ExperimentError::Invalid(Invalid::OutOfRange { phase: 2, .. }))),
        "{e:?}"
    );
    assert!(e.to_string().starts_with(&p.display().to_string()));
    assert!(e.to_string().contains("radius_units"));
}

#[test]
fn shipped_experiments_parse() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../experiments");
    let mut n = 0;
    for entry in fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            Experiment::load(&p).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 3);
}

#[test]
fn every_number_is_checked_and_named() {
    let bad = |from: &str, to: &str| {
        assert!(TWO.contains(from), "{from}");
        invalid(&TWO.replace(from, to))
    };
    for huge in ["1e308", "inf", "nan", "86401"] {
        let e = bad("duration_s = 30", &format!("duration_s = {huge}"));
        assert!(
            matches!(
                e,
                Invalid::Duration
                    | Invalid::OutOfRange {
                        field: "duration_s",
                        ..
                    }
            ),
            "{huge}: {e:?}"
        );
    }
    assert!(matches!(
        bad("duration_s = 30", "duration_s = 30\nbringup_s = 1e9"),
        Invalid::OutOfRange {
            field: "bringup_s",
            ..
        }
    ));
    assert!(matches!(
        bad("duration_s = 30", "duration_s = 30\nthreads = 0"),
        Invalid::OutOfRange {
            field: "threads",
            ..
        }
    ));
    for (field, value) in [
        ("tracking_latency_ms", "99999999"),
        ("tracking_noise_mm", "1e300"),
        ("tracking_rate_hz", "nan"),
    ] {
        let e = bad(
            "radio_loss = 0.2",
            &format!("radio_loss = 0.2\n{field} = {value}"),
        );
        assert!(
            matches!(e, Invalid::Fault { field: f, .. } if f == field),
            "{field}: {e:?}"
        );
        assert!(e.to_string().contains(field), "{e}");
    }
    let e = bad(
        "[faults.lbc]",
        "[[faults.crash]]\ncar = 9\nat_s = 1\n[faults.lbc]",
    );
    assert!(matches!(e, Invalid::CarId { id: 9 }), "{e:?}");
    let e = bad(
        "[faults.lbc]",
        "[[faults.crash]]\ncar = 1\nat_s = -1\n[faults.lbc]",
    );
    assert!(
        matches!(
            e,
            Invalid::Fault {
                field: "crash.at_s",
                ..
            }
        ),
        "{e:?}"
    );
}

#[test]
fn names_stay_inside_the_output_folder() {
    for name in [
        "../escape",
        "/etc/passwd",
        "..",
        ".hidden",
        "a/b",
        "a\\\\b",
        "",
        "sp ace",
    ] {
        let text = TWO.replace("name = \"two\"", &format!("name = \"{name}\""));
        assert!(
            matches!(invalid(&text), Invalid::Name { .. }),
            "{name:?} accepted"
        );
    }
    for name in ["two", "formation-wedge-four", "run_1.2"] {
        let text = TWO.replace("name = \"two\"", &format!("name = \"{name}\""));
        assert_eq!(Experiment::parse(&text).unwrap().name, name);
    }
}

#[test]
fn engine_threads_failure_policy_and_profiles_from_the_file() {
    let text = TWO.replace(
        "duration_s = 30",
        "duration_s = 30\nengine = \"qemu\"\nthreads = 2\non_car_failure = \"abort\"\nprofile_cars = [2]",
    );
    let e = Experiment::parse(&text).unwrap();
    assert_eq!(e.engine, EngineKind::Qemu);
    assert_eq!((e.threads, e.on_car_failure), (2, FailurePolicy::Abort));
    assert_eq!(e.profile_cars, vec![2]);
    let cfg = e.world_config(Path::new("fw.elf"));
    assert_eq!(
        (cfg.engine, cfg.threads, cfg.profile_cars),
        (EngineKind::Qemu, 2, vec![2])
    );
    let d = Experiment::parse(TWO).unwrap();
    assert_eq!((d.engine, d.threads), (EngineKind::Iss, 1));
    assert_eq!(d.on_car_failure, FailurePolicy::Stop);
    assert!(matches!(
        invalid(&TWO.replace("duration_s = 30", "duration_s = 30\nprofile_cars = [7]")),
        Invalid::CarId { id: 7 }
    ));
    assert!(matches!(
        Experiment::parse(&TWO.replace("duration_s = 30", "duration_s = 30\nengine = \"fpga\"")),
        Err(ExperimentError::Parse(_))
    ));
}

mod laws;

#[test]
fn radio_channels_per_car() {
    let text = TWO.replacen("id = 2", "id = 2\nradio_channel = 3", 1);
    let e = Experiment::parse(&text).unwrap();
    let w = e.world_config(Path::new("/fw"));
    assert_eq!(
        w.cars.iter().map(|c| c.radio_channel).collect::<Vec<_>>(),
        [0, 3]
    );
    let bad = TWO.replacen("id = 2", "id = 2\nradio_channel = 16", 1);
    let err = invalid(&bad);
    assert_eq!(err, Invalid::RadioChannel { id: 2, channel: 16 });
    assert_eq!(err.to_string(), "car 2: radio_channel 16 is outside 0..=15");
}
