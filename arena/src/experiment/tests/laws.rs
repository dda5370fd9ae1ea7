//! Phases of any registered law, options, programs and per-car firmware.

use super::*;

/// A phase of a registered law without fields of its own: parameters by name, per-car values,
/// options, waypoints.
const LAW_PHASE: &str = r#"
[[phases]]
kind = "camera-follow"
marker = 2
speed_mm_s = 300
reverse = "never"
waypoints = [[300, 500]]
waypoint_cars = [1]
timeout_s = 20

[[phases.cars]]
id = 3
marker = 4
neighbours = 2
"#;

#[test]
fn any_registered_law_by_name() {
    let e = Experiment::parse(&format!("{CARS4}{LAW_PHASE}")).unwrap();
    let p = &e.phases[0];
    assert_eq!(p.kind.name(), "camera-follow");
    assert_eq!(p.tolerance_mm, law_phase::DEFAULT_LAW_TOLERANCE_MM);
    let c1 = p.params_for(1).unwrap();
    assert_eq!(c1.law(), 5);
    // marker, distance (default 80), speed.
    assert_eq!(c1.values().as_slice(), &[2, 80, 300]);
    assert_eq!(c1.options().unwrap().reverse, maneuvers::Reverse::Never);
    let c3 = p.params_for(3).unwrap();
    assert_eq!(c3.values().as_slice(), &[4, 80, 300]);
    let o = c3.options().unwrap();
    assert_eq!(
        (o.reverse, o.neighbours),
        (maneuvers::Reverse::Never, maneuvers::Neighbours::Nearest(2))
    );
    let plan = p.waypoint_plan().unwrap();
    assert_eq!((plan.waypoints, plan.cars), (&[[300, 500]][..], &[1u8][..]));
    // Every car takes part; without waypoint_cars every car gets the waypoints.
    let e = Experiment::parse(&format!(
        "{CARS4}{}",
        LAW_PHASE.replace("waypoint_cars = [1]\n", "")
    ))
    .unwrap();
    assert_eq!(e.phases[0].waypoint_plan().unwrap().cars, &[1, 2, 3, 4]);
}

#[test]
fn law_phase_errors_list_what_the_law_takes() {
    let text = |from: &str, to: &str| format!("{CARS4}{}", LAW_PHASE.replace(from, to));
    let msg = |t: String| invalid(&t).to_string();
    let m = msg(text("speed_mm_s = 300", "sped = 300"));
    assert_eq!(
        m,
        "phase 1 (camera-follow): `sped` is not a parameter of law `camera-follow`: its parameters are marker, distance_units (default 80), speed_mm_s (default 150); every law also takes reverse, arrival_units and neighbours"
    );
    let m = msg(text("marker = 2\n", ""));
    assert!(
        m.starts_with("phase 1 (camera-follow): law `camera-follow` needs `marker`"),
        "{m}"
    );
    let m = msg(text("marker = 4", "marker = 400"));
    assert_eq!(
        m,
        "phase 1 (camera-follow), car 3: `marker` = 400 is not a number in 0..=255"
    );
    let m = msg(text("id = 3", "id = 9"));
    assert!(m.contains("car 9 in `cars` is not one of"), "{m}");
    let m = msg(text("reverse = \"never\"", "reverse = \"back\""));
    assert!(
        m.contains("`reverse` = \"back\" is not allowed, turn or never"),
        "{m}"
    );
    let m = msg(text("marker = 2", "marker = 2.5"));
    assert!(m.contains("`marker` must be an integer or a word"), "{m}");
    let m = msg(text("waypoint_cars = [1]", "waypoint_cars = [7]"));
    assert!(m.contains("car 7 in `waypoint_cars`"), "{m}");
}

#[test]
fn options_of_the_kinds_with_their_own_fields() {
    let e = Experiment::parse(&seq().replace(
        "kind = \"rendezvous\"",
        "kind = \"rendezvous\"\nreverse = \"turn\"\narrival_units = 20",
    ))
    .unwrap();
    let o = e.phases[1].params_for(2).unwrap().options().unwrap();
    assert_eq!((o.reverse, o.arrival_units), (maneuvers::Reverse::Turn, 20));
    let t = TWO.replace("kind = \"goto\"", "kind = \"goto\"\nreverse = \"never\"");
    assert!(matches!(
        invalid(&t),
        Invalid::NotApplicable {
            field: "reverse",
            ..
        }
    ));
}

#[test]
fn program_phases_and_per_car_firmware() {
    let text = TWO
        .replace(
            "heading_mrad = 1571\n[[cars]]",
            "heading_mrad = 1571\nfirmware = \"square\"\n[[cars]]",
        )
        .replace(
            "[maneuver]\nkind = \"goto\"\n[[maneuver.cars]]\nid = 1\npoints = [[150, 500]]\n[[maneuver.cars]]\nid = 2\npoints = [[450, 500], [400, 600]]\n",
            "[maneuver]\nkind = \"program\"\ncars = [1]\nargs = [200, -150]\ntimeout_s = 60\n",
        );
    let e = Experiment::parse(&text).unwrap();
    let p = &e.phases[0];
    assert_eq!(
        p.kind,
        PhaseKind::Program(ProgramPhase {
            cars: vec![1],
            args: vec![200, -150]
        })
    );
    assert!(p.runs_program(1) && !p.runs_program(2));
    assert_eq!(p.params_for(1), None);
    assert_eq!(e.cars[0].firmware(None), Firmware::Program("square".into()));
    assert_eq!(e.cars[1].firmware(None), Firmware::Stock);
    let elf = CarEntry {
        firmware: Some("fw/car.elf".into()),
        ..e.cars[0].clone()
    };
    assert_eq!(
        elf.firmware(Some(Path::new("/exp"))),
        Firmware::Elf("/exp/fw/car.elf".into())
    );
    assert!(matches!(
        invalid(&text.replace("\"square\"", "\"Square!\"")),
        Invalid::Firmware { id: 1, .. }
    ));
    assert!(matches!(
        invalid(&text.replace("args = [200, -150]", "args = [40000]")),
        Invalid::OutOfRange { field: "args", .. }
    ));
    assert!(matches!(
        invalid(&text.replace("cars = [1]", "cars = [1, 1]")),
        Invalid::Car {
            problem: CarProblem::Duplicate,
            ..
        }
    ));
    assert!(matches!(
        invalid(&text.replace("args =", "argz =")),
        Invalid::PhaseTable { phase: 1, .. }
    ));
}
