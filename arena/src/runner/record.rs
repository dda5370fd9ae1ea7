//! Outputs written as the run goes: the event log, every car's trajectory and the phase
//! errors are appended line by line and flushed at least once a second of world time (and at
//! every progress line), so a run that fails or is killed leaves its data up to that moment.
//! `run.json` says `"state": "incomplete"` until the run ends. Events also go to the run's
//! recording (`run.mcap`, [`crate::recording`]), which is flushed with the files.

use super::*;
use crate::recording::Channels;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::Arc;

/// Appends one output file.
#[derive(Debug)]
struct Sink {
    path: PathBuf,
    file: BufWriter<File>,
}

impl Sink {
    fn create(path: PathBuf, header: Option<&str>) -> Result<Self, ExperimentError> {
        // Large enough never to fill between two flushes, so a file only ever ends on a whole
        // line (a killed run leaves no torn row).
        let file = File::create(&path)
            .map(|f| BufWriter::with_capacity(1 << 20, f))
            .map_err(|source| ExperimentError::Write {
                path: path.clone(),
                source,
            })?;
        let mut s = Sink { path, file };
        if let Some(h) = header {
            s.line(h)?;
        }
        Ok(s)
    }

    fn line(&mut self, text: &str) -> Result<(), ExperimentError> {
        writeln!(self.file, "{text}").map_err(|source| ExperimentError::Write {
            path: self.path.clone(),
            source,
        })
    }

    fn flush(&mut self) -> Result<(), ExperimentError> {
        self.file.flush().map_err(|source| ExperimentError::Write {
            path: self.path.clone(),
            source,
        })
    }
}

/// The files a run appends to.
#[derive(Debug)]
pub(super) struct Recorder {
    events: Sink,
    cars: Vec<Sink>,
    phases: Sink,
    mcap: Option<Arc<Channels>>,
}

impl Recorder {
    /// Creates the files in `out` for cars `ids`.
    pub(super) fn create(out: &Path, ids: &[u8]) -> Result<Self, ExperimentError> {
        let cars = ids
            .iter()
            .map(|id| {
                Sink::create(
                    out.join(format!("car{id}.csv")),
                    Some("t,x_mm,y_mm,heading,v"),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Recorder {
            events: Sink::create(out.join("events.jsonl"), None)?,
            cars,
            phases: Sink::create(out.join("phases.csv"), Some("t,phase,error_mm"))?,
            mcap: None,
        })
    }

    /// Events also go to `channels` (the run's recording), flushed with the files.
    pub(super) fn attach(&mut self, channels: Arc<Channels>) {
        self.mcap = Some(channels);
    }

    /// One event line (JSON) at world time `at`.
    pub(super) fn event(&mut self, at: Duration, json: &str) -> Result<(), ExperimentError> {
        if let Some(m) = &self.mcap {
            let warning = [
                "failed",
                "stopped",
                "timeout",
                "restarted",
                "Lost",
                "Aborted",
            ]
            .iter()
            .any(|w| json.contains(w));
            m.event(
                u64::try_from(at.as_nanos()).unwrap_or(u64::MAX),
                json,
                warning,
            );
        }
        self.events.line(json)
    }

    /// One trajectory sample of car `k`.
    pub(super) fn sample(&mut self, k: usize, s: &Sample) -> Result<(), ExperimentError> {
        let line = format!(
            "{:.3},{:.1},{:.1},{:.0},{:.1}",
            s.t, s.x_mm, s.y_mm, s.heading_mrad, s.v_mm_s
        );
        match self.cars.get_mut(k) {
            Some(c) => c.line(&line),
            None => Ok(()),
        }
    }

    /// One phase-error row.
    pub(super) fn phase_row(
        &mut self,
        t: f64,
        phase: usize,
        e: f64,
    ) -> Result<(), ExperimentError> {
        self.phases.line(&format!("{t:.3},{phase},{e:.1}"))
    }

    /// Everything written so far reaches the files.
    pub(super) fn flush(&mut self) -> Result<(), ExperimentError> {
        self.events.flush()?;
        for c in &mut self.cars {
            c.flush()?;
        }
        if let Some(m) = &self.mcap {
            m.flush().map_err(|e| ExperimentError::Write {
                path: "run.mcap".into(),
                source: std::io::Error::other(e),
            })?;
        }
        self.phases.flush()
    }
}

/// `run.json`'s state while the run goes (what a killed run leaves).
pub(super) fn mark_incomplete(out: &Path) -> Result<(), ExperimentError> {
    write_file(
        &out.join("run.json"),
        &serde_json::to_string_pretty(&json!({ "state": "incomplete" })).unwrap_or_default(),
    )
}
