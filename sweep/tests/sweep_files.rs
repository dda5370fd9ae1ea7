//! Sweep files: what a grid or a list of points expands to, and the error each kind of mistake
//! gives (no run, no firmware).

use std::path::Path;
use sweep::{PathProblem, Sweep, SweepError};

const BASE: &str = r#"
name = "base"
duration_s = 3
seed = 10
[[cars]]
id = 1
x = 200
y = 300
heading_mrad = 1571
[[cars]]
id = 2
x = 400
y = 300
heading_mrad = 1571
[[phases]]
kind = "rendezvous"
radius_units = 40
speed_mm_s = 200
"#;

fn parse(sweep: &str) -> Result<Sweep, SweepError> {
    Sweep::parse(sweep, Path::new("base.toml"), BASE)
}

fn error(sweep: &str) -> (SweepError, String) {
    let e = parse(sweep).expect_err("the sweep should be rejected");
    let text = e.to_string();
    (e, text)
}

#[test]
fn a_grid_is_the_cartesian_product_first_parameter_slowest() {
    let s = parse(
        r#"
experiment = "base.toml"
seeds = 3
[[grid]]
path = "faults.radio_loss"
values = [0.0, 0.1]
[[grid]]
path = "phases.0.speed_mm_s"
values = [100, 150, 200]
"#,
    )
    .unwrap();
    let p = &s.plan;
    assert_eq!(p.points.len(), 6);
    assert_eq!(p.point_labels(0), ["0", "100"]);
    assert_eq!(p.point_labels(2), ["0", "200"]);
    assert_eq!(p.point_labels(3), ["0.1", "100"]);
    assert_eq!(p.seeds, [10, 11, 12], "seeds count up from the base seed");
    assert_eq!(p.len(), 18);
    assert_eq!(p.plot_x, "faults.radio_loss");
    assert!(p.metrics.contains(&"phases.0.converged_s".to_owned()));
    // Run 4 is point 1 (speed 150), seed 11.
    let text = s.experiment_text(4);
    let exp = arena::experiment::Experiment::parse(&text).unwrap();
    assert_eq!(exp.seed, 11);
    assert_eq!(exp.faults.radio_loss, 0.0);
    assert!(text.contains("speed_mm_s = 150"), "{text}");
}

#[test]
fn points_cars_and_seed_lists() {
    let s = parse(
        r#"
experiment = "base.toml"
seeds = [7, 3]
metrics = ["completed", "phases.0.final_error_mm"]
plot_x = "cars"
parameters = ["cars", "duration_s"]
points = [[1, 2], [2, 4.5]]
"#,
    )
    .unwrap();
    assert_eq!(s.plan.seeds, [3, 7], "seeds are run in ascending order");
    assert_eq!(s.plan.plot_x, "cars");
    let one = arena::experiment::Experiment::parse(&s.experiment_text(0)).unwrap();
    assert_eq!(one.cars.len(), 1);
    assert_eq!(one.seed, 3);
    let two = arena::experiment::Experiment::parse(&s.experiment_text(3)).unwrap();
    assert_eq!((two.cars.len(), two.duration_s, two.seed), (2, 4.5, 7));
}

#[test]
fn an_unknown_field_is_named() {
    let (e, text) = error(
        r#"
experiment = "base.toml"
[[grid]]
path = "faults.radio_los"
values = [0.1]
"#,
    );
    assert!(
        matches!(&e, SweepError::Parameter { path, problem: PathProblem::Rejected(_), .. } if path == "faults.radio_los"),
        "{e:?}"
    );
    assert!(text.contains("`faults.radio_los`"), "{text}");
    assert!(text.contains("radio_los"), "{text}");
    let (_, text) = error(
        r#"
experiment = "base.toml"
[[grid]]
path = "phases.1.speed_mm_s"
values = [100]
"#,
    );
    assert!(
        text.contains("`phases.1`: the base experiment has only 1 elements there"),
        "{text}"
    );
    let (_, text) = error(
        r#"
experiment = "base.toml"
[[grid]]
path = "maneuver.0.speed_mm_s"
values = [100]
"#,
    );
    assert!(text.contains("no `maneuver` to index"), "{text}");
}

#[test]
fn a_wrong_type_or_value_is_named() {
    let (e, text) = error(
        r#"
experiment = "base.toml"
[[grid]]
path = "phases.0.radius_units"
values = [40, "wide"]
"#,
    );
    assert!(
        matches!(
            &e,
            SweepError::Parameter {
                problem: PathProblem::WrongType {
                    expected: "integer",
                    found: "string"
                },
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        text.contains("parameter `phases.0.radius_units` = \"wide\""),
        "{text}"
    );
    // A field the base file leaves out: the experiment's own check names the problem.
    let (_, text) = error(
        r#"
experiment = "base.toml"
[[grid]]
path = "faults.tracking_rate_hz"
values = ["fast"]
"#,
    );
    assert!(
        text.contains("`faults.tracking_rate_hz` = \"fast\""),
        "{text}"
    );
    assert!(text.contains("invalid type"), "{text}");
    // A value out of the experiment's range.
    let (_, text) = error(
        r#"
experiment = "base.toml"
[[grid]]
path = "phases.0.radius_units"
values = [0]
"#,
    );
    assert!(text.contains("radius_units"), "{text}");
    assert!(text.contains("1..=511"), "{text}");
}

#[test]
fn empty_grids_and_points_are_errors() {
    let (e, _) = error("experiment = \"base.toml\"\ngrid = []\n");
    assert!(matches!(e, SweepError::EmptyGrid { path: None }), "{e:?}");
    let (e, text) = error(
        r#"
experiment = "base.toml"
[[grid]]
path = "duration_s"
values = []
"#,
    );
    assert!(
        matches!(e, SweepError::EmptyGrid { path: Some(_) }),
        "{e:?}"
    );
    assert!(text.contains("`duration_s` has no values"), "{text}");
    let (e, _) = error("experiment = \"base.toml\"\n");
    assert!(matches!(e, SweepError::GridOrPoints), "{e:?}");
    let (e, _) = error("experiment = \"base.toml\"\nparameters = [\"duration_s\"]\npoints = []\n");
    assert!(matches!(e, SweepError::EmptyPoints), "{e:?}");
    let (e, _) =
        error("experiment = \"base.toml\"\nparameters = [\"duration_s\"]\npoints = [[1, 2]]\n");
    assert!(
        matches!(
            e,
            SweepError::PointWidth {
                point: 0,
                expected: 1,
                found: 2
            }
        ),
        "{e:?}"
    );
}

#[test]
fn other_mistakes() {
    let grid =
        |path: &str, values: &str| format!("[[grid]]\npath = \"{path}\"\nvalues = {values}\n");
    let error = |text: &str| error(&format!("experiment = \"base.toml\"\n{text}"));
    let (_, text) = error(&grid("cars", "[3]"));
    assert!(text.contains("only 2 [[cars]]"), "{text}");
    let (_, text) = error(&grid("seed", "[1]"));
    assert!(text.contains("`seed` is set per run"), "{text}");
    let (_, text) = error(&grid("faults..drop", "[1]"));
    assert!(text.contains("not a field path"), "{text}");
    let (e, _) = error(&format!("seeds = 0\n{}", grid("duration_s", "[2]")));
    assert!(matches!(e, SweepError::Seeds), "{e:?}");
    let (e, _) = error(&format!("seeds = [1, 1]\n{}", grid("duration_s", "[2]")));
    assert!(matches!(e, SweepError::Seeds), "{e:?}");
    let (e, _) = error(&format!("plot_x = \"cars\"\n{}", grid("duration_s", "[2]")));
    assert!(matches!(e, SweepError::PlotX { .. }), "{e:?}");
    let (e, _) = error(&format!("metrics = []\n{}", grid("duration_s", "[2]")));
    assert!(matches!(e, SweepError::Metrics), "{e:?}");
    let (e, text) = error(&format!("colour = 1\n{}", grid("duration_s", "[2]")));
    assert!(matches!(e, SweepError::Parse { .. }), "{e:?}");
    assert!(text.contains("colour"), "{text}");
    // Each value is fine alone, the combination is not: two cars with ID 3.
    let (e, text) = error(
        r#"
parameters = ["cars.0.id", "cars.1.id"]
points = [[3, 2], [3, 3]]
"#,
    );
    assert!(matches!(e, SweepError::Point { point: 1, .. }), "{e:?}");
    assert!(
        text.contains("point 1 (cars.0.id = 3, cars.1.id = 3)"),
        "{text}"
    );
}
