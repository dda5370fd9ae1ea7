//! The camera-follow example experiment (`experiments/camera-follow.toml`) on the soft core's
//! model: both cars' firmware process their camera's 30 frames per second through the vision
//! unit, and car 2 closes up by its camera alone to about the law's 500 mm behind car 1, which
//! stands still. The phase has no end of its own (the law does not report convergence), so it
//! runs for its `timeout_s`, and that completes it.

#[path = "arena_common.rs"]
mod common;

const CAMERA_FOLLOW: &str = include_str!("../../experiments/camera-follow.toml");

#[test]
fn camera_follow_example_at_30_fps_on_the_vision_unit() {
    let exp = arena::experiment::Experiment::parse(CAMERA_FOLLOW).unwrap();
    assert_eq!(exp.camera_fps, Some(30.0));
    assert!(exp.vision_unit);
    let o = common::run_full(CAMERA_FOLLOW, "camera-follow");
    let doc = &o.doc;
    assert!(o.summary.collisions.is_empty(), "{doc:#}");
    // The camera follow's phase ends when its time is up, and that is not a timeout.
    assert!(o.summary.completed, "{doc:#}");
    let phase = &o.summary.phases[0];
    assert!(phase.completed && !phase.timed_out, "{doc:#}");
    for r in &o.summary.cars {
        let fps = r.camera_fps.expect("camera frames counted");
        assert!((29.0..=30.5).contains(&fps), "car {}: {fps} fps", r.id);
        // 30 frames a second leave the processor mostly idle with the unit.
        let load = r.processor_load.expect("cycle counts");
        assert!(load < 0.25, "car {}: load {load}", r.id);
    }
    let (lead, follow) = (&o.summary.cars[0], &o.summary.cars[1]);
    assert!(lead.distance_mm < 20.0, "car 1 moved: {doc:#}");
    assert!(
        follow.distance_mm > 200.0,
        "car 2 did not close up: {doc:#}"
    );
    let end = |k: usize| {
        let &(_, x, y) = o.tracks[k].last().unwrap();
        (x, y)
    };
    let ((ax, ay), (bx, by)) = (end(0), end(1));
    let gap = (ax - bx).hypot(ay - by);
    assert!((400.0..750.0).contains(&gap), "{gap:.0} mm apart: {doc:#}");
}
