//! The guest's RAM as a shared file, so the host can write into it while the firmware runs: the
//! frame grabber's window (`docs/camera.md`) lives at guest address `0x8100_0000`, which is
//! [`FRAME_WINDOW_OFFSET`] into the file.
//!
//! QEMU maps the file `MAP_SHARED` (`-object memory-backend-file,...,share=on`), so plain
//! positioned reads and writes of the file ([`SharedRam::read_at`], [`SharedRam::write_at`]) go
//! through the same page-cache pages the guest reads; each call is one `pread`/`pwrite`, and calls
//! become visible to the guest in the order they are made.

use std::fs::{File, OpenOptions};
use std::io;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

/// Guest RAM base on `virt`.
pub const RAM_BASE: u64 = 0x8000_0000;
/// Offset of the frame grabber's window (guest `0x8100_0000`) in the RAM file.
pub const FRAME_WINDOW_OFFSET: u64 = 0x0100_0000;
/// Guest RAM size with a shared RAM file: the image's 16 MiB plus room for the window.
pub const SHARED_RAM_MIB: u32 = 32;

/// Where QEMU's RAM lives on the host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SharedRamSpec {
    /// The RAM file; created (and sized) if missing.
    pub path: PathBuf,
    /// Guest RAM in MiB (`-m`); at least [`SHARED_RAM_MIB`] for the frame window.
    pub mib: u32,
}

impl SharedRamSpec {
    /// A RAM file at `path` of the default size.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        SharedRamSpec {
            path: path.into(),
            mib: SHARED_RAM_MIB,
        }
    }

    /// Bytes of the RAM.
    pub fn len(&self) -> u64 {
        u64::from(self.mib) << 20
    }

    /// Whether the RAM has no bytes.
    pub fn is_empty(&self) -> bool {
        self.mib == 0
    }
}

/// The host's handle on a RAM file.
#[derive(Debug)]
pub struct SharedRam {
    file: File,
    path: PathBuf,
}

impl SharedRam {
    /// Creates (or opens) the RAM file and sizes it to `len` bytes, before QEMU starts. The
    /// frame window can be initialised right away; QEMU keeps the file's contents.
    pub fn create(path: impl AsRef<Path>, len: u64) -> io::Result<Self> {
        let path = path.as_ref();
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)?;
        file.set_len(len)?;
        Ok(SharedRam {
            file,
            path: path.to_path_buf(),
        })
    }

    /// Opens an existing RAM file (of a running QEMU) for reading and writing.
    pub fn open(path: impl AsRef<Path>) -> io::Result<Self> {
        let path = path.as_ref();
        let file = OpenOptions::new().read(true).write(true).open(path)?;
        Ok(SharedRam {
            file,
            path: path.to_path_buf(),
        })
    }

    /// Opens an existing RAM file read-only.
    pub fn open_read_only(path: impl AsRef<Path>) -> io::Result<Self> {
        let path = path.as_ref();
        Ok(SharedRam {
            file: File::open(path)?,
            path: path.to_path_buf(),
        })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Bytes of the file.
    pub fn file_len(&self) -> io::Result<u64> {
        Ok(self.file.metadata()?.len())
    }

    /// Writes all of `bytes` at file offset `offset` (one positioned write per chunk).
    pub fn write_at(&self, offset: u64, bytes: &[u8]) -> io::Result<()> {
        self.file.write_all_at(bytes, offset)
    }

    /// Fills `out` from file offset `offset`.
    pub fn read_at(&self, offset: u64, out: &mut [u8]) -> io::Result<()> {
        self.file.read_exact_at(out, offset)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn create_sizes_and_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ram");
        let spec = SharedRamSpec::new(&path);
        assert_eq!(spec.len(), 32 << 20);
        let ram = SharedRam::create(&path, spec.len()).unwrap();
        assert_eq!(ram.file_len().unwrap(), 32 << 20);
        ram.write_at(FRAME_WINDOW_OFFSET, b"ALFG").unwrap();
        let other = SharedRam::open_read_only(&path).unwrap();
        let mut back = [0u8; 4];
        other.read_at(FRAME_WINDOW_OFFSET, &mut back).unwrap();
        assert_eq!(&back, b"ALFG");
        // Re-creating keeps the contents.
        let again = SharedRam::create(&path, spec.len()).unwrap();
        again.read_at(FRAME_WINDOW_OFFSET, &mut back).unwrap();
        assert_eq!(&back, b"ALFG");
        assert!(SharedRam::open(dir.path().join("missing")).is_err());
    }
}
