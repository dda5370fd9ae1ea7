//! The virtual-time engine: every car's firmware ELF (the `softcore` board build) runs on
//! `soc-model`, the soft core's cycle-accurate SoC model, so a car's clock is its cycle count
//! at [`CLOCK_HZ`]. All cars live in this process and are stepped a quantum at a time by a
//! fixed gang of threads ([`super::gang`]); each car only touches its own state inside a
//! quantum, so the result is the same for any number of threads.

use super::gang::Gang;
use super::{
    CarEngine, CarIo, CoreLoad, Failure, FailureKind, FrameWriteError, Nanos, WindowWriter,
};
use qemu_harness::{LineDecoder, LogFormat};
use soc_model::{Halt, Output, Port, Retired, Soc, Stamped, CLOCK_HZ};
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// Console bytes kept per car for its firmware log (the oldest are dropped beyond this).
const MAX_CONSOLE: usize = 1 << 20;

/// The cycle at which something that happens at world time `ns` is seen (rounded up).
pub fn cycle_at(ns: Nanos) -> u64 {
    let c = (u128::from(ns) * u128::from(CLOCK_HZ)).div_ceil(1_000_000_000);
    u64::try_from(c).unwrap_or(u64::MAX)
}

/// The last cycle that has ended by world time `ns` (rounded down).
pub fn cycle_by(ns: Nanos) -> u64 {
    let c = u128::from(ns) * u128::from(CLOCK_HZ) / 1_000_000_000;
    u64::try_from(c).unwrap_or(u64::MAX)
}

/// The world time of cycle `cycle` (rounded down).
pub fn time_of(cycle: u64) -> Nanos {
    let t = u128::from(cycle) * 1_000_000_000 / u128::from(CLOCK_HZ);
    u64::try_from(t).unwrap_or(u64::MAX)
}

/// Why the engine could not start.
#[derive(Debug)]
pub enum IssError {
    /// The firmware file could not be read.
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The firmware file is not a loadable image for the soft core.
    Load { path: PathBuf, reason: String },
    /// The firmware's defmt table could not be read.
    LogTable { path: PathBuf, reason: String },
    /// The worker threads could not be started.
    Threads(String),
}

impl fmt::Display for IssError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            IssError::Read { path, source } => {
                write!(f, "cannot read firmware {}: {source}", path.display())
            }
            IssError::Load { path, reason } => write!(
                f,
                "{} is not a softcore firmware image: {reason} (build it with `cargo xtask fw --board softcore`)",
                path.display()
            ),
            IssError::LogTable { path, reason } => {
                write!(f, "cannot read the log table of {}: {reason}", path.display())
            }
            IssError::Threads(e) => write!(f, "cannot start the engine's threads: {e}"),
        }
    }
}

impl std::error::Error for IssError {}

/// The WFI instruction.
const WFI: u32 = 0x1050_0073;
/// Profile key of the cycles spent waiting in WFI.
const WAITING: u32 = u32::MAX;

/// Cycles spent per instruction address of one car (see [`IssEngine::profile`]).
#[derive(Debug, Default, Clone)]
struct Profile {
    cycles: HashMap<u32, u64>,
    last: Option<u64>,
    trace: Vec<Retired>,
}

/// One car on the model.
struct IssCar {
    soc: Soc,
    profile: Option<Profile>,
    elf: Arc<Vec<u8>>,
    out: Vec<Stamped>,
    console: Vec<u8>,
    /// Console bytes with their world times, kept for the world's tap.
    console_tap: Option<Vec<(Nanos, u8)>>,
    log_format: Arc<LogFormat>,
    failure: Option<Failure>,
    /// World time up to which the car has run.
    ran_to: Nanos,
    /// The world's traffic for this car during a quantum (swapped in and out around it).
    io: CarIo,
    /// Cars of the engine that have failed (shared by all of them).
    failed: Arc<AtomicUsize>,
}

impl IssCar {
    fn step(&mut self, until: Nanos) {
        let mut io = std::mem::take(&mut self.io);
        self.advance(until, &mut io);
        self.io = io;
    }

    fn advance(&mut self, until: Nanos, io: &mut CarIo) {
        if self.failure.is_some() {
            io.lbc_in.clear();
            io.radio_in.clear();
            return;
        }
        for (port, bytes) in [(Port::Lbc, &mut io.lbc_in), (Port::Radio, &mut io.radio_in)] {
            for (t, b) in bytes.drain(..) {
                self.soc.send_at(port, cycle_at(t), &[b]);
            }
        }
        self.out.clear();
        let halt = match self.profile.as_mut() {
            None => self.soc.run_until(cycle_by(until), &mut self.out),
            Some(p) => {
                p.trace.clear();
                let h = self
                    .soc
                    .run_until_traced(cycle_by(until), &mut self.out, &mut p.trace);
                for r in &p.trace {
                    // Each instruction is charged the cycles since the one before it retired
                    // (so waiting in WFI is charged to the WFI, interrupt entry to the
                    // handler's first instruction).
                    let spent = r.cycle - p.last.unwrap_or(r.cycle).min(r.cycle);
                    let at = if r.retire.insn == WFI {
                        WAITING
                    } else {
                        r.retire.pc_rdata
                    };
                    *p.cycles.entry(at).or_default() += spent;
                    p.last = Some(r.cycle);
                }
                h
            }
        };
        for s in &self.out {
            let t = time_of(s.cycle);
            match s.output {
                Output::Tx {
                    port: Port::Lbc,
                    byte,
                } => io.lbc_out.push((t, byte)),
                Output::Tx {
                    port: Port::Radio,
                    byte,
                } => io.radio_out.push((t, byte)),
                Output::Console(b) => {
                    self.console.push(b);
                    if let Some(tap) = self.console_tap.as_mut() {
                        tap.push((t, b));
                    }
                }
            }
        }
        if self.console.len() > MAX_CONSOLE {
            let excess = self.console.len() - MAX_CONSOLE / 2;
            self.console.drain(..excess);
        }
        if let Some(h) = halt {
            let kind = match h {
                Halt::Exit { value } => FailureKind::Exited { value },
                Halt::Stuck { pc, reason } => FailureKind::Stuck {
                    pc,
                    why: format!("{reason:?}"),
                },
            };
            if self.failure.is_none() {
                self.failed.fetch_add(1, Ordering::Relaxed);
            }
            self.failure = Some(Failure {
                at: time_of(self.soc.cycle()),
                kind,
            });
        }
        self.ran_to = until;
    }
}

impl WindowWriter for IssCar {
    fn write_window(&mut self, offset: usize, bytes: &[u8]) -> Result<(), FrameWriteError> {
        self.soc
            .write_frame_window(offset, bytes)
            .map_err(|e| FrameWriteError(format!("{e:?}")))
    }

    fn camera_stream(
        &mut self,
        codes: &[u8],
        width: u16,
        height: u16,
    ) -> Result<bool, FrameWriteError> {
        if !self.soc.has_vision_unit() {
            return Ok(false);
        }
        self.soc
            .camera_frame(codes, width, height, soc_model::CameraTiming::default())
            .map(|_| true)
            .map_err(|e| FrameWriteError(e.to_string()))
    }

    fn set_vision_unit(&mut self, present: bool) {
        self.soc.set_vision_unit(present);
    }
}

/// The virtual-time engine.
pub struct IssEngine {
    cars: Gang<IssCar>,
    /// Cars that have failed (every car holds a clone).
    failed: Arc<AtomicUsize>,
}

impl fmt::Debug for IssEngine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("IssEngine")
            .field("cars", &self.cars.len())
            .field("threads", &self.cars.threads())
            .finish()
    }
}

/// A firmware image loaded once and shared by the cars that run it.
struct Image {
    soc: Soc,
    log_format: Arc<LogFormat>,
    bytes: Arc<Vec<u8>>,
}

fn load_image(path: &Path) -> Result<Image, IssError> {
    let bytes = std::fs::read(path).map_err(|source| IssError::Read {
        path: path.into(),
        source,
    })?;
    let mut soc = Soc::new();
    soc.load_elf(&bytes).map_err(|e| IssError::Load {
        path: path.into(),
        reason: format!("{e}"),
    })?;
    let log_format = LogFormat::from_elf_bytes(&bytes, path).map_err(|e| IssError::LogTable {
        path: path.into(),
        reason: e.to_string(),
    })?;
    Ok(Image {
        soc,
        log_format: Arc::new(log_format),
        bytes: Arc::new(bytes),
    })
}

impl IssEngine {
    /// Loads `firmware[k]` for car `k` (one load per distinct file) and prepares `threads`
    /// worker threads (1: the calling thread steps every car). Cars whose index is in
    /// `profiled` record where their processor spends its cycles ([`IssEngine::profile`]).
    pub fn new(firmware: &[PathBuf], threads: usize, profiled: &[usize]) -> Result<Self, IssError> {
        let mut images: HashMap<&Path, Image> = HashMap::new();
        let mut cars = Vec::with_capacity(firmware.len());
        let failed = Arc::new(AtomicUsize::new(0));
        for path in firmware {
            if !images.contains_key(path.as_path()) {
                images.insert(path, load_image(path)?);
            }
            let img = &images[path.as_path()];
            cars.push(IssCar {
                soc: img.soc.clone(),
                profile: profiled.contains(&cars.len()).then(Profile::default),
                elf: img.bytes.clone(),
                out: Vec::new(),
                console: Vec::new(),
                console_tap: None,
                log_format: img.log_format.clone(),
                failure: None,
                ran_to: 0,
                io: CarIo::default(),
                failed: failed.clone(),
            });
        }
        let cars = Gang::new(cars, threads, "arena-iss", IssCar::step)
            .map_err(|e| IssError::Threads(e.to_string()))?;
        Ok(IssEngine { cars, failed })
    }
}

/// Where a profiled car's processor spent its cycles, by function (symbols of its ELF), the
/// largest first: `(cycles, share of all cycles, function)`.
pub fn profile_table(elf: &[u8], cycles: &HashMap<u32, u64>) -> Vec<(u64, f64, String)> {
    use object::{Object, ObjectSymbol};
    let mut syms: Vec<(u64, u64, String)> = match object::File::parse(elf) {
        Ok(obj) => obj
            .symbols()
            .filter(|s| s.size() > 0)
            .map(|s| {
                let name = s.name().unwrap_or("?");
                (
                    s.address(),
                    s.size(),
                    format!("{:#}", rustc_demangle::demangle(name)),
                )
            })
            .collect(),
        Err(_) => Vec::new(),
    };
    syms.sort();
    let mut by_fn: HashMap<String, u64> = HashMap::new();
    for (&pc, &c) in cycles {
        let pc = u64::from(pc);
        let i = syms.partition_point(|s| s.0 <= pc);
        let name = match i.checked_sub(1).map(|j| &syms[j]) {
            _ if pc == u64::from(WAITING) => "(asleep in WFI)".to_owned(),
            Some((a, n, name)) if pc < a + n => name.clone(),
            _ => format!("{pc:#010x}"),
        };
        *by_fn.entry(name).or_default() += c;
    }
    let total: u64 = by_fn.values().sum::<u64>().max(1);
    let mut rows: Vec<(u64, f64, String)> = by_fn
        .into_iter()
        .map(|(n, c)| (c, c as f64 / total as f64, n))
        .collect();
    rows.sort_by(|a, b| b.0.cmp(&a.0).then_with(|| a.2.cmp(&b.2)));
    rows
}

impl IssEngine {
    /// Car `k`'s processor profile so far (see [`profile_table`]), if it is profiled.
    pub fn profile(&self, k: usize) -> Option<Vec<(u64, f64, String)>> {
        let car = self.cars.item(k)?;
        let p = car.profile.as_ref()?;
        Some(profile_table(&car.elf, &p.cycles))
    }
}

impl CarEngine for IssEngine {
    fn name(&self) -> &'static str {
        "iss"
    }

    fn wall_clock(&self) -> bool {
        false
    }

    fn advance(&mut self, until: Nanos, io: &mut [CarIo]) {
        for (k, io) in io.iter_mut().enumerate() {
            if let Some(mut car) = self.cars.item(k) {
                std::mem::swap(&mut car.io, io);
            }
        }
        self.cars.round(until);
        for (k, io) in io.iter_mut().enumerate() {
            if let Some(mut car) = self.cars.item(k) {
                std::mem::swap(&mut car.io, io);
            }
        }
    }

    fn failure(&self, k: usize) -> Option<Failure> {
        self.cars.item(k)?.failure.clone()
    }

    fn failures(&self) -> Option<usize> {
        // Read between rounds, when no car is running: every count made in the round is in.
        Some(self.failed.load(Ordering::Relaxed))
    }

    fn with_window(&mut self, k: usize, f: &mut dyn FnMut(&mut dyn WindowWriter)) -> bool {
        match self.cars.item(k) {
            Some(mut car) => {
                f(&mut *car);
                true
            }
            None => false,
        }
    }

    fn core_load(&self, k: usize) -> Option<CoreLoad> {
        let s = self.cars.item(k)?.soc.stats();
        Some(CoreLoad {
            cycles: s.cycles,
            awake_cycles: s.cycles.saturating_sub(s.sleep_cycles),
            retired: s.retired,
        })
    }

    fn firmware_log(&self, k: usize) -> Vec<String> {
        let Some(car) = self.cars.item(k) else {
            return Vec::new();
        };
        let mut dec = LineDecoder::new(&car.log_format);
        let mut lines = Vec::new();
        dec.push(&car.console, Instant::now(), &mut lines);
        lines.iter().map(|l| l.to_string()).collect()
    }

    fn profile(&self, k: usize) -> Option<Vec<(u64, f64, String)>> {
        IssEngine::profile(self, k)
    }

    fn tap_console(&mut self, on: bool) {
        for k in 0..self.cars.len() {
            if let Some(mut c) = self.cars.item(k) {
                c.console_tap = on.then(Vec::new);
            }
        }
    }

    fn take_console(&mut self, k: usize, out: &mut Vec<(Nanos, u8)>) {
        if let Some(mut c) = self.cars.item(k) {
            if let Some(tap) = c.console_tap.as_mut() {
                out.append(tap);
            }
        }
    }

    fn log_format(&self, k: usize) -> Option<Arc<LogFormat>> {
        self.cars.item(k).map(|c| c.log_format.clone())
    }

    fn kill(&mut self, k: usize, why: &str) {
        if let Some(mut c) = self.cars.item(k) {
            if c.failure.is_none() {
                c.failure = Some(Failure {
                    at: c.ran_to,
                    kind: FailureKind::Killed { why: why.into() },
                });
                self.failed.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    fn shutdown(&mut self) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_and_cycles_round_trip_without_drift() {
        for ns in [0u64, 1, 67, 68, 1_000_000, 86_806, 3_600_000_000_000] {
            let c = cycle_at(ns);
            assert!(time_of(c) >= ns.saturating_sub(68), "{ns}");
            assert!(cycle_by(ns) <= c);
            assert!(time_of(cycle_by(ns)) <= ns);
        }
        assert_eq!(cycle_by(1_000_000_000), CLOCK_HZ);
        assert_eq!(cycle_at(1_000_000_000), CLOCK_HZ);
        assert_eq!(time_of(CLOCK_HZ), 1_000_000_000);
    }
}
