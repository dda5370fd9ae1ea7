//! The file under `run.mcap`, so that the file on disk is a complete MCAP file at every
//! moment a run can be killed, not only when the run ends.
//!
//! The MCAP writer streams each chunk into its output and seeks back to fill in the chunk's
//! length once the chunk is done, so a plain file killed mid-chunk ends in a record whose
//! length is a placeholder, and without the footer readers look for. Here everything the
//! writer writes after the last commit stays in memory; a commit (after the writer finished
//! a chunk, once a second of world time) appends it to the file followed by a provisional end
//! (a data-end record, a footer saying "no summary section" and the closing magic), which the
//! next commit overwrites. A killed run thus leaves a valid MCAP file up to its last commit,
//! which any reader opens (reading it linearly, as the footer says there is no index), and
//! the finished file is byte for byte what the writer wrote.

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};

/// The magic that starts and ends an MCAP file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// A data-end record (no CRC), a footer without a summary section, the magic.
fn provisional_end() -> Vec<u8> {
    let mut v = Vec::with_capacity(50);
    v.push(0x0F); // DataEnd
    v.extend_from_slice(&4u64.to_le_bytes());
    v.extend_from_slice(&0u32.to_le_bytes()); // data section CRC: not computed
    v.push(0x02); // Footer
    v.extend_from_slice(&20u64.to_le_bytes());
    v.extend_from_slice(&0u64.to_le_bytes()); // summary start: none
    v.extend_from_slice(&0u64.to_le_bytes()); // summary offset start: none
    v.extend_from_slice(&0u32.to_le_bytes()); // summary CRC
    v.extend_from_slice(MAGIC);
    v
}

#[derive(Debug)]
struct State {
    file: File,
    /// Bytes `[0, committed)` are in the file for good.
    committed: u64,
    /// Bytes from `committed` on, not yet in the file.
    pending: Vec<u8>,
    /// The writer's position.
    pos: u64,
}

impl State {
    fn len(&self) -> u64 {
        self.committed + self.pending.len() as u64
    }

    fn write(&mut self, buf: &[u8]) -> io::Result<()> {
        let mut buf = buf;
        if self.pos < self.committed {
            // Never done by the MCAP writer (it only goes back into the chunk it is writing),
            // but kept correct: the committed part goes straight to the file.
            let n = usize::try_from(self.committed - self.pos)
                .unwrap_or(usize::MAX)
                .min(buf.len());
            self.file.seek(SeekFrom::Start(self.pos))?;
            self.file.write_all(&buf[..n])?;
            self.pos += n as u64;
            buf = &buf[n..];
        }
        if buf.is_empty() {
            return Ok(());
        }
        let at = usize::try_from(self.pos - self.committed)
            .map_err(|_| io::Error::other("position out of range"))?;
        if at > self.pending.len() {
            self.pending.resize(at, 0);
        }
        let end = at + buf.len();
        let overlap = end.min(self.pending.len());
        self.pending[at..overlap].copy_from_slice(&buf[..overlap - at]);
        self.pending.extend_from_slice(&buf[overlap - at..]);
        self.pos += buf.len() as u64;
        Ok(())
    }

    fn commit(&mut self, provisional: bool) -> io::Result<()> {
        self.file.seek(SeekFrom::Start(self.committed))?;
        self.file.write_all(&self.pending)?;
        self.committed += self.pending.len() as u64;
        self.pending.clear();
        let end = if provisional {
            let tail = provisional_end();
            self.file.write_all(&tail)?;
            self.committed + tail.len() as u64
        } else {
            self.committed
        };
        self.file.set_len(end)?;
        self.file.flush()
    }
}

impl Drop for State {
    fn drop(&mut self) {
        // The writer was dropped without a final commit (an error path): keep what it wrote,
        // ending the file properly if the writer did not.
        if !self.pending.is_empty() {
            let finished = self.pending.ends_with(MAGIC);
            let _ = self.commit(!finished);
        }
    }
}

/// A file the MCAP writer writes to (`Write + Seek`), committed to disk by [`Spill::commit`].
/// Clones share the file.
#[derive(Debug, Clone)]
pub struct Spill(Arc<Mutex<State>>);

impl Spill {
    /// Creates (or truncates) the file at `path`.
    pub fn create(path: &Path) -> io::Result<Self> {
        Ok(Spill(Arc::new(Mutex::new(State {
            file: File::create(path)?,
            committed: 0,
            pending: Vec::new(),
            pos: 0,
        }))))
    }

    fn state(&self) -> io::Result<MutexGuard<'_, State>> {
        self.0
            .lock()
            .map_err(|_| io::Error::other("recording file lock poisoned"))
    }

    /// Writes everything written so far to the file; with `provisional`, followed by an end
    /// that makes the file a complete MCAP file until the next commit overwrites it (use
    /// after the writer finished a chunk); without, the file ends where the writer's data
    /// ends (after the writer finished the file).
    pub fn commit(&self, provisional: bool) -> io::Result<()> {
        self.state()?.commit(provisional)
    }
}

impl Write for Spill {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.state()?.write(buf)?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        // Commits are explicit: a flush may come mid-chunk.
        Ok(())
    }
}

impl Seek for Spill {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let mut s = self.state()?;
        let base = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => s.len().checked_add_signed(d),
            SeekFrom::Current(d) => s.pos.checked_add_signed(d),
        };
        let p = base.ok_or_else(|| io::Error::other("seek out of range"))?;
        s.pos = p;
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    fn read(path: &Path) -> Vec<u8> {
        let mut v = Vec::new();
        File::open(path).unwrap().read_to_end(&mut v).unwrap();
        v
    }

    #[test]
    fn commits_end_provisionally_and_patches_stay_in_memory() {
        let path = std::env::temp_dir().join(format!("spill-{}.bin", std::process::id()));
        let spill = Spill::create(&path).unwrap();
        let mut w = spill.clone();
        w.write_all(b"headerXXXXbody").unwrap();
        // Patch the placeholder, then go back to the end (as the MCAP writer does).
        w.seek(SeekFrom::Start(6)).unwrap();
        w.write_all(b"1234").unwrap();
        assert_eq!(w.seek(SeekFrom::End(0)).unwrap(), 14);
        assert!(read(&path).is_empty(), "nothing before a commit");
        spill.commit(true).unwrap();
        let on_disk = read(&path);
        assert_eq!(&on_disk[..14], b"header1234body");
        assert_eq!(&on_disk[14..], &provisional_end()[..]);
        w.write_all(b"+more").unwrap();
        assert_eq!(w.stream_position().unwrap(), 19);
        spill.commit(false).unwrap();
        assert_eq!(read(&path), b"header1234body+more");
        // Writing into the committed part goes to the file.
        w.seek(SeekFrom::Start(0)).unwrap();
        w.write_all(b"H").unwrap();
        assert_eq!(&read(&path)[..2], b"He");
        drop((w, spill));
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn dropped_unfinished_data_is_kept_with_an_end() {
        let path = std::env::temp_dir().join(format!("spill-drop-{}.bin", std::process::id()));
        let mut w = Spill::create(&path).unwrap();
        w.write_all(b"abc").unwrap();
        drop(w);
        let mut want = b"abc".to_vec();
        want.extend_from_slice(&provisional_end());
        assert_eq!(read(&path), want);
        let _ = std::fs::remove_file(&path);
    }
}
