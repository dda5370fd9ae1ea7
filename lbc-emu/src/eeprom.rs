//! The LBC's 64 x 16-bit EEPROM (seed Table 1-3) and its persistence.
//!
//! [`EepromImage`] is the register array with the register map and factory defaults.
//! [`EepromStore`] is where committed images live: [`MemoryStore`] for tests and lockstep runs,
//! [`FileStore`] for a file on disk. A file commit is atomic: the new image is written to a
//! temporary file in the same directory, synced, renamed over the old file and the directory is
//! synced, so a process killed at any instant leaves either the old or the new image, never a mix.
//!
//! File format (text, one register per line, so a person can read and edit it):
//!
//! ```text
//! almc-lbc-eeprom 1
//! 00 0001
//! 01 0000
//! ...
//! 3f 0000
//! crc32 89abcdef
//! ```
//!
//! The CRC-32 (ISO-HDLC) covers the 64 values as big-endian bytes; a file that fails any check is
//! reported as a typed [`EepromFileError`] and never silently replaced.

use std::fmt;
use std::fs::{self, File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// Number of 16-bit registers.
pub const REGISTER_COUNT: usize = 64;

/// Register addresses from seed Table 1-3.
pub mod reg {
    /// Car ID (`RegCID`).
    pub const CID: u8 = 0x00;
    /// Motor encoder count to revolution ratio (`RegMERR`), first control parameter.
    pub const MERR: u8 = 0x04;
    /// Motor gear ratio (`RegMGR`).
    pub const MGR: u8 = 0x05;
    /// Motor proportional gain (`RegMPG`).
    pub const MPG: u8 = 0x06;
    /// Motor integral gain (`RegMIG`).
    pub const MIG: u8 = 0x07;
    /// Motor differential gain (`RegMDG`).
    pub const MDG: u8 = 0x08;
    /// Motor dead band (`RegMDB`).
    pub const MDB: u8 = 0x09;
    /// Servo offset (`RegSO`).
    pub const SO: u8 = 0x0A;
    /// Servo gain (`RegSG`).
    pub const SG: u8 = 0x0B;
    /// Servo proportional gain (`RegSPG`).
    pub const SPG: u8 = 0x0C;
    /// Servo integral gain (`RegSIG`).
    pub const SIG: u8 = 0x0D;
    /// Servo differential gain (`RegSDG`).
    pub const SDG: u8 = 0x0E;
    /// Servo dead band (`RegSDB`), last control parameter.
    pub const SDB: u8 = 0x0F;
    /// Gyro pitch zero-rate level (`RegGPO`).
    pub const GPO: u8 = 0x10;
    /// Gyro pitch sensitivity (`RegGPG`).
    pub const GPG: u8 = 0x11;
    /// Gyro roll zero-rate level (`RegGRO`).
    pub const GRO: u8 = 0x12;
    /// Gyro roll sensitivity (`RegGRG`).
    pub const GRG: u8 = 0x13;
    /// Gyro yaw zero-rate level (`RegGYO`).
    pub const GYO: u8 = 0x14;
    /// Gyro yaw sensitivity (`RegGYG`).
    pub const GYG: u8 = 0x15;
    /// Range sensor offset (`RegRO`).
    pub const RO: u8 = 0x16;
    /// Range sensor gain (`RegRG`), last calibration register.
    pub const RG: u8 = 0x17;
    /// First user register.
    pub const USER_FIRST: u8 = 0x20;
    /// Last user register.
    pub const USER_LAST: u8 = 0x3F;
}

/// Registers that CMEP writes and RSEP reads: the 12 control parameters (0x04..=0x0F) and the
/// gyro / range calibration (0x10..=0x17).
pub const SYSTEM_REGISTERS: core::ops::RangeInclusive<u8> = reg::MERR..=reg::RG;

/// Whether `addr` is a user register (WRIT_EP / READ_EP may touch it).
pub fn is_user_register(addr: u8) -> bool {
    (reg::USER_FIRST..=reg::USER_LAST).contains(&addr)
}

/// A full EEPROM image.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct EepromImage {
    regs: [u16; REGISTER_COUNT],
}

impl fmt::Debug for EepromImage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_map()
            .entries(
                self.regs
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| **v != 0)
                    .map(|(a, v)| (format!("{a:#04x}"), format!("{v:#06x}"))),
            )
            .finish()
    }
}

impl Default for EepromImage {
    fn default() -> Self {
        Self::factory(1)
    }
}

impl EepromImage {
    /// Factory defaults for a car with the given ID (docs/lbc-emulator.md lists every value and
    /// its unit).
    pub fn factory(car_id: u8) -> Self {
        let mut regs = [0u16; REGISTER_COUNT];
        let mut set = |a: u8, v: i32| regs[usize::from(a)] = v as u16;
        set(reg::CID, i32::from(car_id & 0x7F));
        set(reg::MERR, 800);
        set(reg::MGR, 2000);
        set(reg::MPG, 512);
        set(reg::MIG, 5120);
        set(reg::MDG, 0);
        set(reg::MDB, 50);
        set(reg::SO, 0);
        set(reg::SG, 1000);
        set(reg::SPG, 0);
        set(reg::SIG, 0);
        set(reg::SDG, 0);
        set(reg::SDB, 0);
        set(reg::GPO, 1504);
        set(reg::GPG, 2000);
        set(reg::GRO, 1504);
        set(reg::GRG, 2000);
        set(reg::GYO, 1504);
        set(reg::GYG, 2000);
        set(reg::RO, 26);
        set(reg::RG, 2585);
        Self { regs }
    }

    /// An image with every register zero.
    pub const fn zeroed() -> Self {
        Self {
            regs: [0; REGISTER_COUNT],
        }
    }

    /// Reads a register; addresses past 0x3F read as `None`.
    pub fn get(&self, addr: u8) -> Option<u16> {
        self.regs.get(usize::from(addr)).copied()
    }

    /// Writes a register; returns `false` (and changes nothing) for addresses past 0x3F.
    pub fn set(&mut self, addr: u8, value: u16) -> bool {
        match self.regs.get_mut(usize::from(addr)) {
            Some(r) => {
                *r = value;
                true
            }
            None => false,
        }
    }

    /// All registers in address order.
    pub fn registers(&self) -> &[u16; REGISTER_COUNT] {
        &self.regs
    }

    /// The car ID held in register 0x00 (7 bits on the wire).
    pub fn car_id(&self) -> u8 {
        (self.regs[usize::from(reg::CID)] & 0x7F) as u8
    }

    /// The CRC-32 the file format stores.
    pub fn crc32(&self) -> u32 {
        let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        let mut d = crc.digest();
        for r in &self.regs {
            d.update(&r.to_be_bytes());
        }
        d.finalize()
    }

    /// Renders the file format.
    pub fn to_file_text(&self) -> String {
        use std::fmt::Write as _;
        let mut s = String::with_capacity(32 + REGISTER_COUNT * 8);
        s.push_str(FILE_MAGIC);
        s.push('\n');
        for (a, v) in self.regs.iter().enumerate() {
            let _ = writeln!(s, "{a:02x} {v:04x}");
        }
        let _ = writeln!(s, "crc32 {:08x}", self.crc32());
        s
    }

    /// Parses the file format strictly.
    pub fn from_file_text(text: &str) -> Result<Self, EepromFileError> {
        let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
        match lines.next() {
            Some((_, l)) if l == FILE_MAGIC => {}
            _ => return Err(EepromFileError::BadMagic),
        }
        let mut regs = [0u16; REGISTER_COUNT];
        for (addr, slot) in regs.iter_mut().enumerate() {
            let (line, l) = lines.next().ok_or(EepromFileError::Truncated {
                registers: addr as u8,
            })?;
            let mut parts = l.split_ascii_whitespace();
            let (Some(a), Some(v), None) = (parts.next(), parts.next(), parts.next()) else {
                return Err(EepromFileError::BadLine { line });
            };
            let a = u8::from_str_radix(a, 16).map_err(|_| EepromFileError::BadLine { line })?;
            if usize::from(a) != addr {
                return Err(EepromFileError::AddressOutOfOrder {
                    line,
                    expected: addr as u8,
                    got: a,
                });
            }
            *slot = u16::from_str_radix(v, 16).map_err(|_| EepromFileError::BadLine { line })?;
        }
        let image = Self { regs };
        let (line, l) = lines.next().ok_or(EepromFileError::Truncated {
            registers: REGISTER_COUNT as u8,
        })?;
        let stored = l
            .strip_prefix("crc32 ")
            .and_then(|h| u32::from_str_radix(h.trim(), 16).ok())
            .ok_or(EepromFileError::BadLine { line })?;
        let computed = image.crc32();
        if stored != computed {
            return Err(EepromFileError::ChecksumMismatch {
                expected: stored,
                got: computed,
            });
        }
        if let Some((line, l)) = lines.find(|(_, l)| !l.is_empty()) {
            let _ = l;
            return Err(EepromFileError::TrailingData { line });
        }
        Ok(image)
    }
}

const FILE_MAGIC: &str = "almc-lbc-eeprom 1";

/// Why an EEPROM file could not be used.
#[derive(Debug)]
#[non_exhaustive]
pub enum EepromFileError {
    /// Reading, writing, syncing or renaming failed.
    Io(io::Error),
    /// The first line is not the format's magic line.
    BadMagic,
    /// The file ends after this many registers (or before the checksum line).
    Truncated {
        /// Registers read before the end.
        registers: u8,
    },
    /// A line is not `AA VVVV` (or `crc32 XXXXXXXX` at the end).
    BadLine {
        /// 1-based line number.
        line: usize,
    },
    /// Registers must be listed in address order.
    AddressOutOfOrder {
        /// 1-based line number.
        line: usize,
        /// Address this line must hold.
        expected: u8,
        /// Address it holds.
        got: u8,
    },
    /// The stored checksum does not match the registers.
    ChecksumMismatch {
        /// Checksum in the file.
        expected: u32,
        /// Checksum of the registers read.
        got: u32,
    },
    /// Non-empty lines after the checksum line.
    TrailingData {
        /// 1-based line number.
        line: usize,
    },
    /// Another process holds the file's lock: two emulators on one file would silently lose
    /// each other's writes.
    Locked {
        /// The lock file (`FILE.lock`) held by the other process.
        lock: PathBuf,
    },
}

impl fmt::Display for EepromFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "EEPROM file I/O error: {e}"),
            Self::BadMagic => write!(f, "not an EEPROM file (first line must be `{FILE_MAGIC}`)"),
            Self::Truncated { registers } => {
                write!(f, "EEPROM file truncated after {registers} registers")
            }
            Self::BadLine { line } => write!(f, "malformed EEPROM file line {line}"),
            Self::AddressOutOfOrder {
                line,
                expected,
                got,
            } => write!(
                f,
                "EEPROM file line {line}: register {got:#04x} where {expected:#04x} belongs"
            ),
            Self::ChecksumMismatch { expected, got } => write!(
                f,
                "EEPROM file checksum mismatch: file says {expected:08x}, registers give {got:08x}"
            ),
            Self::TrailingData { line } => {
                write!(f, "EEPROM file has data after the checksum (line {line})")
            }
            Self::Locked { lock } => write!(
                f,
                "EEPROM file is in use by another process (it holds the lock {}); \
                 stop that emulator or give this one another --eeprom file",
                lock.display()
            ),
        }
    }
}

impl std::error::Error for EepromFileError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io(e) => Some(e),
            _ => None,
        }
    }
}

impl From<io::Error> for EepromFileError {
    fn from(e: io::Error) -> Self {
        Self::Io(e)
    }
}

/// Where committed EEPROM images are kept.
pub trait EepromStore: Send {
    /// Makes `image` the committed content. On error the previously committed content stays.
    fn commit(&mut self, image: &EepromImage) -> Result<(), EepromFileError>;
}

/// Keeps the committed image in memory (tests, lockstep simulations).
#[derive(Debug, Clone, Default)]
pub struct MemoryStore {
    /// The last committed image, if any commit happened.
    pub committed: Option<EepromImage>,
    /// Number of commits.
    pub commits: u64,
    /// When set, every commit fails (for testing the LBC's error replies).
    pub fail: bool,
}

impl EepromStore for MemoryStore {
    fn commit(&mut self, image: &EepromImage) -> Result<(), EepromFileError> {
        if self.fail {
            return Err(EepromFileError::Io(io::Error::other(
                "simulated EEPROM failure",
            )));
        }
        self.committed = Some(*image);
        self.commits += 1;
        Ok(())
    }
}

/// Keeps the committed image in a file, replaced atomically on each commit.
///
/// The store holds an exclusive advisory lock (`flock`) on `FILE.lock` beside the image for
/// as long as it lives, so a second process opening the same file is refused with
/// [`EepromFileError::Locked`] instead of both silently overwriting each other's commits. The
/// lock file itself is left in place (it is empty); the lock ends with the process.
#[derive(Debug)]
pub struct FileStore {
    path: PathBuf,
    /// The open lock file; dropping it releases the lock.
    _lock: File,
    /// Pause between writing the first and second half of the temporary file; a test hook that
    /// widens the window in which a kill lands in the middle of a commit.
    write_pause: Option<Duration>,
}

impl FileStore {
    /// Opens the store at `path`: takes the file's lock (another process holding it is
    /// [`EepromFileError::Locked`]), then loads the image there, or writes `default`
    /// (atomically) when the file does not exist. A file that exists but does not parse is an
    /// error.
    pub fn open(
        path: impl Into<PathBuf>,
        default: &EepromImage,
    ) -> Result<(Self, EepromImage), EepromFileError> {
        let path = path.into();
        let lock = Self::lock(&path)?;
        let store = Self {
            path,
            _lock: lock,
            write_pause: None,
        };
        // Only once the lock is held: another live process's temporary file is not stale.
        store.remove_stale_temp_files();
        match fs::read_to_string(&store.path) {
            Ok(text) => {
                let image = EepromImage::from_file_text(&text)?;
                Ok((store, image))
            }
            Err(e) if e.kind() == io::ErrorKind::NotFound => {
                let mut store = store;
                store.commit(default)?;
                Ok((store, *default))
            }
            Err(e) => Err(e.into()),
        }
    }

    /// The lock file of the image at `path`: `FILE.lock` in the same directory.
    pub fn lock_path(path: &Path) -> PathBuf {
        let mut name = path
            .file_name()
            .map(|n| n.to_os_string())
            .unwrap_or_default();
        name.push(".lock");
        path.with_file_name(name)
    }

    fn lock(path: &Path) -> Result<File, EepromFileError> {
        use rustix::fs::{flock, FlockOperation};
        let lock_path = Self::lock_path(path);
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&lock_path)?;
        match flock(&file, FlockOperation::NonBlockingLockExclusive) {
            Ok(()) => Ok(file),
            Err(e) if e == rustix::io::Errno::WOULDBLOCK => {
                Err(EepromFileError::Locked { lock: lock_path })
            }
            Err(e) => Err(EepromFileError::Io(e.into())),
        }
    }

    /// Reads and parses the file at `path` without opening a store.
    pub fn load(path: &Path) -> Result<EepromImage, EepromFileError> {
        EepromImage::from_file_text(&fs::read_to_string(path)?)
    }

    /// The file this store writes.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Sets the test pause inside each commit (see the field doc).
    pub fn set_write_pause(&mut self, pause: Option<Duration>) {
        self.write_pause = pause;
    }

    /// Temporary files left by a process killed in the middle of a commit hold nothing that
    /// was ever committed; they are removed.
    fn remove_stale_temp_files(&self) {
        let (Some(dir), Some(name)) = (self.path.parent(), self.path.file_name()) else {
            return;
        };
        let dir = if dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            dir
        };
        let prefix = format!("{}.tmp.", name.to_string_lossy());
        if let Ok(entries) = fs::read_dir(dir) {
            for e in entries.flatten() {
                if e.file_name().to_string_lossy().starts_with(&prefix) {
                    let _ = fs::remove_file(e.path());
                }
            }
        }
    }

    fn temp_path(&self) -> PathBuf {
        let mut name = self
            .path
            .file_name()
            .map(|n| n.to_os_string())
            .unwrap_or_default();
        name.push(format!(".tmp.{}", std::process::id()));
        self.path.with_file_name(name)
    }
}

impl EepromStore for FileStore {
    fn commit(&mut self, image: &EepromImage) -> Result<(), EepromFileError> {
        let tmp = self.temp_path();
        let text = image.to_file_text();
        let result = (|| -> io::Result<()> {
            let mut f = OpenOptions::new()
                .write(true)
                .create(true)
                .truncate(true)
                .open(&tmp)?;
            let (a, b) = text.as_bytes().split_at(text.len() / 2);
            f.write_all(a)?;
            if let Some(p) = self.write_pause {
                f.flush()?;
                std::thread::sleep(p);
            }
            f.write_all(b)?;
            f.sync_all()?;
            drop(f);
            fs::rename(&tmp, &self.path)?;
            let dir = match self.path.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            File::open(dir)?.sync_all()?;
            Ok(())
        })();
        if result.is_err() {
            let _ = fs::remove_file(&tmp);
        }
        result.map_err(EepromFileError::Io)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn factory_defaults_are_the_documented_ones() {
        let img = EepromImage::factory(7);
        assert_eq!(img.car_id(), 7);
        assert_eq!(img.get(reg::MERR), Some(800));
        assert_eq!(img.get(reg::MGR), Some(2000));
        assert_eq!(img.get(reg::SG), Some(1000));
        assert_eq!(img.get(reg::GYO), Some(1504));
        assert_eq!(img.get(reg::RG), Some(2585));
        assert_eq!(img.get(0x40), None);
        assert!((0x20..=0x3F).all(|a| img.get(a) == Some(0)));
    }

    #[test]
    fn file_text_is_exact() {
        let mut img = EepromImage::zeroed();
        img.set(0x00, 0x0001);
        img.set(0x3F, 0xBEEF);
        let text = img.to_file_text();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 66);
        assert_eq!(lines[0], "almc-lbc-eeprom 1");
        assert_eq!(lines[1], "00 0001");
        assert_eq!(lines[64], "3f beef");
        assert_eq!(lines[65], format!("crc32 {:08x}", img.crc32()));
    }

    #[test]
    fn damaged_files_are_rejected_with_the_reason() {
        let img = EepromImage::factory(3);
        let good = img.to_file_text();
        assert!(matches!(
            EepromImage::from_file_text("hello\n"),
            Err(EepromFileError::BadMagic)
        ));
        let cut = &good[..good.len() / 2];
        assert!(matches!(
            EepromImage::from_file_text(cut),
            Err(EepromFileError::Truncated { .. } | EepromFileError::BadLine { .. })
        ));
        let flipped = good.replacen("04 0320", "04 0321", 1);
        assert!(matches!(
            EepromImage::from_file_text(&flipped),
            Err(EepromFileError::ChecksumMismatch { .. })
        ));
        let swapped = good.replacen("01 0000", "02 0000", 1);
        assert!(matches!(
            EepromImage::from_file_text(&swapped),
            Err(EepromFileError::AddressOutOfOrder {
                line: 3,
                expected: 1,
                got: 2
            })
        ));
        let trailing = format!("{good}junk\n");
        assert!(matches!(
            EepromImage::from_file_text(&trailing),
            Err(EepromFileError::TrailingData { line: 67 })
        ));
    }

    #[test]
    fn file_store_creates_commits_and_reloads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("car.eeprom");
        let (mut store, img) = FileStore::open(&path, &EepromImage::factory(9)).unwrap();
        assert_eq!(img.car_id(), 9);
        assert_eq!(FileStore::load(&path).unwrap(), img);
        let mut changed = img;
        changed.set(0x21, 0x1234);
        store.commit(&changed).unwrap();
        drop(store);
        let (store, reloaded) = FileStore::open(&path, &EepromImage::factory(1)).unwrap();
        assert_eq!(reloaded, changed);
        drop(store);
        let mut leftovers: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        leftovers.sort();
        assert_eq!(
            leftovers,
            ["car.eeprom", "car.eeprom.lock"],
            "temporary file left behind"
        );
        // A stale temporary file from a killed process is cleaned up on open.
        let stale = dir.path().join("car.eeprom.tmp.99999");
        fs::write(&stale, "almc-lbc-eeprom 1\n00 00").unwrap();
        let (_, again) = FileStore::open(&path, &EepromImage::factory(1)).unwrap();
        assert_eq!(again, changed);
        assert!(!stale.exists());
    }

    #[test]
    fn file_store_refuses_a_corrupt_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.eeprom");
        fs::write(&path, "almc-lbc-eeprom 1\n00 zz\n").unwrap();
        assert!(matches!(
            FileStore::open(&path, &EepromImage::factory(1)),
            Err(EepromFileError::BadLine { line: 2 })
        ));
    }

    #[test]
    fn a_second_store_on_the_same_file_is_refused_until_the_first_is_gone() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("car.eeprom");
        let (first, _) = FileStore::open(&path, &EepromImage::factory(4)).unwrap();
        match FileStore::open(&path, &EepromImage::factory(4)) {
            Err(EepromFileError::Locked { lock }) => {
                assert_eq!(lock, dir.path().join("car.eeprom.lock"))
            }
            other => panic!("{other:?}"),
        }
        drop(first);
        let (_, image) = FileStore::open(&path, &EepromImage::factory(9)).unwrap();
        assert_eq!(
            image.car_id(),
            4,
            "the first store's image, not a new default"
        );
    }

    proptest! {
        #[test]
        fn file_text_round_trips(regs in proptest::array::uniform32(any::<u16>()), hi in proptest::array::uniform32(any::<u16>())) {
            let mut img = EepromImage::zeroed();
            for (a, v) in regs.iter().chain(hi.iter()).enumerate() {
                img.set(a as u8, *v);
            }
            prop_assert_eq!(EepromImage::from_file_text(&img.to_file_text()).unwrap(), img);
        }

        #[test]
        fn parser_never_panics(text in ".{0,400}") {
            let _ = EepromImage::from_file_text(&text);
        }
    }
}
