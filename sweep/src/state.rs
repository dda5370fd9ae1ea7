//! A run's state, read from its directory: the arena writes `run.json` with `"state":
//! "incomplete"` when a run starts and its final state (`complete`, `cancelled`, `aborted`,
//! `error`) when it ends, after `summary.json`. The sweep adds `interrupted` for runs it cut
//! short itself (Ctrl-C), which a later run of the sweep does again.

use serde_json::Value;
use std::path::Path;

/// Where a run stands.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunState {
    /// It ran to its end.
    Complete,
    /// It ended early by a cancel the sweep did not cause (finished, failed).
    Cancelled,
    /// A car failed with `on_car_failure = "abort"` (finished, failed).
    Aborted,
    /// It did not run: the arena's error. Done again by the next run of the sweep.
    Error(String),
    /// The sweep was stopped while it ran. Done again.
    Interrupted,
    /// It started but did not end (the process was killed). Done again.
    Incomplete,
    /// There is nothing of it.
    Missing,
}

impl RunState {
    /// Reads the state of the run in `dir`.
    pub fn read(dir: &Path) -> RunState {
        let info: Option<Value> = std::fs::read_to_string(dir.join("run.json"))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
        let Some(info) = info else {
            return if dir.is_dir() {
                RunState::Incomplete
            } else {
                RunState::Missing
            };
        };
        let summary = dir.join("summary.json").is_file();
        match info["state"].as_str() {
            Some("complete") if summary => RunState::Complete,
            Some("cancelled") if summary => RunState::Cancelled,
            Some("aborted") if summary => RunState::Aborted,
            Some("error") => RunState::Error(info["error"].as_str().unwrap_or("").to_owned()),
            Some("interrupted") => RunState::Interrupted,
            _ => RunState::Incomplete,
        }
    }

    /// The run has ended for good (with a summary): a later run of the sweep keeps it.
    pub fn is_finished(&self) -> bool {
        matches!(
            self,
            RunState::Complete | RunState::Cancelled | RunState::Aborted
        )
    }

    /// The run counts in the aggregates.
    pub fn is_complete(&self) -> bool {
        *self == RunState::Complete
    }

    /// Its name in `runs.csv`.
    pub fn name(&self) -> &'static str {
        match self {
            RunState::Complete => "complete",
            RunState::Cancelled => "cancelled",
            RunState::Aborted => "aborted",
            RunState::Error(_) => "error",
            RunState::Interrupted => "interrupted",
            RunState::Incomplete => "incomplete",
            RunState::Missing => "missing",
        }
    }
}

/// Rewrites `run.json` in `dir` with `"state": "interrupted"`, keeping its other fields.
pub(crate) fn mark_interrupted(dir: &Path) -> std::io::Result<()> {
    let path = dir.join("run.json");
    let mut info: Value = std::fs::read_to_string(&path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_else(|| Value::Object(serde_json::Map::new()));
    info["state"] = Value::from("interrupted");
    std::fs::write(
        &path,
        serde_json::to_string_pretty(&info).unwrap_or_default(),
    )
}

/// Writes `run.json` in `dir` with `"state": "error"` and the message.
pub(crate) fn mark_error(dir: &Path, error: &str) -> std::io::Result<()> {
    let info = serde_json::json!({ "state": "error", "error": error });
    std::fs::write(
        dir.join("run.json"),
        serde_json::to_string_pretty(&info).unwrap_or_default(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn states_follow_run_json_and_the_summary() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("r");
        assert_eq!(RunState::read(&d), RunState::Missing);
        std::fs::create_dir(&d).unwrap();
        assert_eq!(RunState::read(&d), RunState::Incomplete);
        std::fs::write(d.join("run.json"), r#"{"state":"complete"}"#).unwrap();
        assert_eq!(RunState::read(&d), RunState::Incomplete, "no summary");
        std::fs::write(d.join("summary.json"), "{}").unwrap();
        assert_eq!(RunState::read(&d), RunState::Complete);
        assert!(RunState::read(&d).is_finished());
        mark_interrupted(&d).unwrap();
        assert_eq!(RunState::read(&d), RunState::Interrupted);
        std::fs::write(d.join("run.json"), r#"{"state":"aborted"}"#).unwrap();
        assert!(RunState::read(&d).is_finished());
        assert!(!RunState::read(&d).is_complete());
        mark_error(&d, "boom").unwrap();
        assert_eq!(RunState::read(&d), RunState::Error("boom".into()));
        assert!(!RunState::read(&d).is_finished());
    }
}
