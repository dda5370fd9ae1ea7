//! Feeds arbitrary text to the experiment loader: it must answer with an experiment or an
//! error, never panic; an experiment it accepts has finite, bounded numbers and a name that
//! stays inside the output folder, and maps to a world configuration.
#![no_main]

use arena::experiment::Experiment;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(e) = Experiment::parse(text) {
        assert!(e.duration_s.is_finite() && e.duration_s > 0.0 && e.duration_s <= 86_400.0);
        assert!(e.bringup_s.is_finite() && e.bringup_s > 0.0);
        assert!(!e.name.contains('/') && !e.name.contains("..") && !e.name.is_empty());
        assert!(!e.cars.is_empty() && !e.phases.is_empty());
        let cfg = e.world_config(std::path::Path::new("/nonexistent"));
        assert_eq!(cfg.cars.len(), e.cars.len());
        assert!(cfg.tracking.rate_hz.is_finite());
    }
});
