//! The outputs from run directories (made up here, no firmware): `runs.csv` rows in plan order
//! with the flattened summaries, `aggregate.csv` statistics over complete runs only, plots, and
//! the error for a metric that is no column.

use std::path::Path;
use sweep::{Sweep, SweepError};

const BASE: &str = r#"
name = "base"
duration_s = 3
[[cars]]
id = 1
x = 200
y = 300
[maneuver]
kind = "rendezvous"
radius_units = 40
speed_mm_s = 200
"#;

const SWEEP: &str = r#"
experiment = "base.toml"
seeds = 3
metrics = ["completed", "phases.0.converged_s", "collisions.count"]
[[grid]]
path = "maneuver.speed_mm_s"
values = [100, 200]
"#;

/// A run directory with a summary and a final state.
fn fake_run(runs: &Path, name: &str, state: &str, converged: Option<f64>, completed: bool) {
    let dir = runs.join(name);
    std::fs::create_dir_all(&dir).unwrap();
    let conv = converged.map_or("null".to_owned(), |c| format!("{c}"));
    let summary = format!(
        r#"{{"name":"base","engine":"iss","duration_s":3.0,"completed":{completed},
        "phases":[{{"phase":1,"kind":"rendezvous","converged_s":{conv},"error_after_settled":null}}],
        "collisions":[],"cars":[{{"id":1,"distance_mm":12.5,"failed":null}}]}}"#
    );
    std::fs::write(dir.join("summary.json"), summary).unwrap();
    std::fs::write(dir.join("run.json"), format!(r#"{{"state":"{state}"}}"#)).unwrap();
}

#[test]
fn tables_and_plots_from_run_directories() {
    let sweep = Sweep::parse(SWEEP, Path::new("base.toml"), BASE).unwrap();
    let plan = &sweep.plan;
    let out = tempfile::tempdir().unwrap();
    let runs = out.path().join("runs");
    // Point 0: seeds 1..=3 complete. Point 1: one complete, one aborted, one never run.
    fake_run(&runs, "0-s1", "complete", Some(2.0), true);
    fake_run(&runs, "0-s2", "complete", Some(3.0), true);
    fake_run(&runs, "0-s3", "complete", None, false);
    fake_run(&runs, "1-s1", "complete", Some(1.5), true);
    fake_run(&runs, "1-s2", "aborted", Some(9.0), false);
    let o = sweep::output::write_outputs(plan, &plan.runs(), out.path()).unwrap();
    let csv = std::fs::read_to_string(&o.runs_csv).unwrap();
    // `error_after_settled` and `failed` are null in every run: empty columns.
    let expected = "\
point,seed,status,maneuver.speed_mm_s,duration_s,completed,phases.0.phase,phases.0.converged_s,phases.0.error_after_settled,collisions.count,cars.0.id,cars.0.distance_mm,cars.0.failed
0,1,complete,100,3,true,1,2,,0,1,12.5,
0,2,complete,100,3,true,1,3,,0,1,12.5,
0,3,complete,100,3,false,1,,,0,1,12.5,
1,1,complete,200,3,true,1,1.5,,0,1,12.5,
1,2,aborted,200,3,false,1,9,,0,1,12.5,
1,3,missing,200,,,,,,,,,
";
    assert_eq!(csv, expected);
    let agg = std::fs::read_to_string(&o.aggregate_csv).unwrap();
    let lines: Vec<&str> = agg.lines().collect();
    assert_eq!(
        lines[0],
        "point,maneuver.speed_mm_s,metric,n,failures,mean,sd,ci95_low,ci95_high"
    );
    // completed: 1, 1, 0 -> mean 2/3, sd 0.57735, t(2) = 4.3027 -> half width 1.43422.
    assert_eq!(
        lines[1],
        "0,100,completed,3,0,0.666667,0.57735,-0.767551,2.10088"
    );
    // converged_s: 2 and 3 (the third run never converged).
    assert_eq!(
        lines[2],
        "0,100,phases.0.converged_s,2,0,2.5,0.707107,-3.85310,8.85310"
            .replace("3.85310", "3.8531")
            .replace("8.85310", "8.8531")
    );
    assert_eq!(lines[3], "0,100,collisions.count,3,0,0,0,0,0");
    // Point 1: only the complete run counts; the aborted and the missing one are failures.
    assert_eq!(lines[4], "1,200,completed,1,2,1,,,");
    assert_eq!(lines[5], "1,200,phases.0.converged_s,1,2,1.5,,,");
    assert_eq!(lines.len(), 7);
    for m in ["completed", "phases.0.converged_s", "collisions.count"] {
        let svg = std::fs::read_to_string(out.path().join(format!("plots/{m}.svg"))).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("maneuver.speed_mm_s"),
            "{m}"
        );
        let png = std::fs::read(out.path().join(format!("plots/{m}.png"))).unwrap();
        assert_eq!(&png[1..4], b"PNG", "{m}");
    }

    let bad = Sweep::parse(
        &SWEEP.replace("\"collisions.count\"", "\"phases.0.convergd_s\""),
        Path::new("base.toml"),
        BASE,
    )
    .unwrap();
    let e = sweep::output::write_outputs(&bad.plan, &bad.plan.runs(), out.path()).unwrap_err();
    assert!(
        matches!(&e, SweepError::UnknownMetric { metric, near } if metric == "phases.0.convergd_s" && near.contains(&"phases.0.converged_s".to_owned())),
        "{e:?}"
    );
}
