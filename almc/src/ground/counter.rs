//! Persistence of the authenticated-command counter.
//!
//! Cars execute a command only if its counter is above the last one they accepted in their
//! session. Every run has its own random session epoch, which already keeps runs apart; the
//! counter file keeps the counters growing across runs as well. The next counter is kept in
//! a small text file (default `$XDG_STATE_HOME/almc/counter`, else
//! `~/.local/state/almc/counter`), replaced atomically (write a temporary file, sync,
//! rename) before each command goes out. A new session starts at the larger of the stored
//! value and the seconds elapsed since 2025-01-01, so a lost file still yields counters
//! above those of earlier sessions unless they sent more than one command per second.

use std::fmt;
use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

/// 2025-01-01T00:00:00Z, the origin of the clock-derived counter floor.
const COUNTER_EPOCH_UNIX_S: u64 = 1_735_689_600;

/// Why the counter file could not be used.
#[derive(Debug)]
pub enum CounterError {
    /// Neither `XDG_STATE_HOME` nor `HOME` is set; pass `--state PATH`.
    NoStateDir,
    /// Reading or writing failed.
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: io::Error,
    },
    /// The file does not hold a decimal counter.
    Corrupt {
        /// The file.
        path: PathBuf,
    },
}

impl fmt::Display for CounterError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NoStateDir => write!(
                f,
                "no state directory (set XDG_STATE_HOME or HOME, or pass --state PATH)"
            ),
            Self::Io { path, source } => write!(f, "counter file {}: {source}", path.display()),
            Self::Corrupt { path } => write!(
                f,
                "counter file {} does not hold a number; fix or delete it",
                path.display()
            ),
        }
    }
}

impl std::error::Error for CounterError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// The file holding the next command counter.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CounterFile {
    path: PathBuf,
}

impl CounterFile {
    /// A counter file at `path` (created on first store).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self { path: path.into() }
    }

    /// `$XDG_STATE_HOME/almc/counter`, else `$HOME/.local/state/almc/counter`.
    pub fn default_location() -> Result<Self, CounterError> {
        let non_empty = |v: &str| std::env::var_os(v).filter(|s| !s.is_empty());
        let base = match (non_empty("XDG_STATE_HOME"), non_empty("HOME")) {
            (Some(x), _) => PathBuf::from(x),
            (None, Some(h)) => PathBuf::from(h).join(".local").join("state"),
            (None, None) => return Err(CounterError::NoStateDir),
        };
        Ok(Self::new(base.join("almc").join("counter")))
    }

    /// `path` if given, else [`CounterFile::default_location`].
    pub fn at_or_default(path: Option<&Path>) -> Result<Self, CounterError> {
        match path {
            Some(p) => Ok(Self::new(p)),
            None => Self::default_location(),
        }
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn io(&self, source: io::Error) -> CounterError {
        CounterError::Io {
            path: self.path.clone(),
            source,
        }
    }

    /// The stored next counter, `None` if the file does not exist.
    pub fn load(&self) -> Result<Option<u32>, CounterError> {
        match fs::read_to_string(&self.path) {
            Ok(text) => text
                .trim()
                .parse::<u32>()
                .map(Some)
                .map_err(|_| CounterError::Corrupt {
                    path: self.path.clone(),
                }),
            Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(self.io(e)),
        }
    }

    /// Replace the stored next counter atomically.
    pub fn store(&self, next: u32) -> Result<(), CounterError> {
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            fs::create_dir_all(dir).map_err(|e| self.io(e))?;
        }
        let mut tmp = self.path.clone().into_os_string();
        tmp.push(format!(".tmp{}", std::process::id()));
        let tmp = PathBuf::from(tmp);
        let write = || -> io::Result<()> {
            let mut f = fs::File::create(&tmp)?;
            writeln!(f, "{next}")?;
            f.sync_all()?;
            fs::rename(&tmp, &self.path)
        };
        write().map_err(|e| {
            let _ = fs::remove_file(&tmp);
            self.io(e)
        })
    }

    /// Counter of the first command of a new session: the larger of the stored value and
    /// the clock floor (seconds since 2025-01-01).
    pub fn first_counter(&self) -> Result<u32, CounterError> {
        let stored = self.load()?.unwrap_or(0);
        Ok(stored.max(clock_floor()))
    }
}

/// Seconds since 2025-01-01, saturated to `u32`.
pub fn clock_floor() -> u32 {
    let now = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    u32::try_from(now.saturating_sub(COUNTER_EPOCH_UNIX_S)).unwrap_or(u32::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("almc-counter-{}-{name}", std::process::id()))
    }

    #[test]
    fn store_then_load_and_no_temp_left() {
        let dir = temp("a");
        let f = CounterFile::new(dir.join("sub").join("counter"));
        assert_eq!(f.load().unwrap(), None);
        f.store(41).unwrap();
        assert_eq!(f.load().unwrap(), Some(41));
        f.store(u32::MAX).unwrap();
        assert_eq!(f.load().unwrap(), Some(u32::MAX));
        let entries = fs::read_dir(dir.join("sub")).unwrap().count();
        assert_eq!(entries, 1, "the temporary file was renamed");
        fs::remove_dir_all(dir).unwrap();
    }

    #[test]
    fn first_counter_is_at_least_stored_and_clock() {
        let p = temp("b");
        let f = CounterFile::new(&p);
        let floor = clock_floor();
        assert!(floor > 30_000_000, "clock floor {floor}");
        assert!(f.first_counter().unwrap() >= floor);
        f.store(floor + 1000).unwrap();
        assert_eq!(f.first_counter().unwrap(), floor + 1000);
        fs::remove_file(p).unwrap();
    }

    #[test]
    fn corrupt_file_is_an_error_not_a_reset() {
        let p = temp("c");
        fs::write(&p, "twelve\n").unwrap();
        assert!(matches!(
            CounterFile::new(&p).load(),
            Err(CounterError::Corrupt { .. })
        ));
        fs::remove_file(p).unwrap();
    }
}
