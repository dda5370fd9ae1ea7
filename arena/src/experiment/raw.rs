//! The experiment file as written, before it is checked.

use super::*;

/// The file as written (checked and normalised into [`Experiment`]).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawExperiment {
    pub(super) name: String,
    pub(super) duration_s: f64,
    #[serde(default = "one")]
    pub(super) seed: u64,
    #[serde(default = "bringup_default")]
    pub(super) bringup_s: f64,
    pub(super) cars: Vec<CarEntry>,
    pub(super) maneuver: Option<toml::Table>,
    #[serde(default)]
    pub(super) phases: Vec<toml::Table>,
    #[serde(default)]
    pub(super) faults: Faults,
    pub(super) camera_fps: Option<f64>,
    /// Whether the cars' vision unit computes the runs (default true).
    pub(super) vision_unit: Option<bool>,
    pub(super) engine: Option<EngineName>,
    pub(super) threads: Option<u64>,
    pub(super) on_car_failure: Option<FailurePolicy>,
    #[serde(default)]
    pub(super) profile_cars: Vec<u8>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum EngineName {
    Iss,
    Qemu,
}

pub(super) fn one() -> u64 {
    1
}

pub(super) fn bringup_default() -> f64 {
    40.0
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum KindName {
    Goto,
    Formation,
    Rendezvous,
    Circle,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(super) enum ShapeName {
    Line,
    Wedge,
}

/// One `[maneuver]` or `[[phases]]` table of the kinds `goto`, `formation`, `rendezvous` and
/// `circle`: every field of these kinds, checked per kind.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawPhase {
    pub(super) kind: Option<KindName>,
    pub(super) start_s: Option<f64>,
    pub(super) timeout_s: Option<f64>,
    pub(super) hold_s: Option<f64>,
    pub(super) tolerance_mm: Option<f64>,
    pub(super) cars: Option<Vec<GotoCar>>,
    pub(super) shape: Option<ShapeName>,
    pub(super) leader: Option<u8>,
    pub(super) followers: Option<Vec<u8>>,
    pub(super) spacing_units: Option<u16>,
    pub(super) speed_mm_s: Option<i64>,
    pub(super) waypoints: Option<Vec<[u16; 2]>>,
    pub(super) waypoint_at_s: Option<Vec<f64>>,
    pub(super) reach_units: Option<u16>,
    pub(super) radius_units: Option<u16>,
    pub(super) centre: Option<[u16; 2]>,
    pub(super) reverse: Option<String>,
    pub(super) arrival_units: Option<i64>,
    pub(super) neighbours: Option<toml::Value>,
}

/// A `program` phase: every car listed runs its firmware's program loop.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawProgramPhase {
    #[allow(dead_code)]
    pub(super) kind: String,
    pub(super) start_s: Option<f64>,
    pub(super) timeout_s: Option<f64>,
    pub(super) hold_s: Option<f64>,
    pub(super) cars: Option<Vec<u8>>,
    #[serde(default)]
    pub(super) args: Vec<i64>,
}
