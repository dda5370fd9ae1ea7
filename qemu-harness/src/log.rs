//! The firmware's log: defmt frames (rzcobs by default) read from QEMU's stdout, decoded
//! with the ELF's `.defmt` table into lines stamped with their host arrival time, and
//! kept so tests can wait for a line matching a predicate.

use std::collections::VecDeque;
use std::fmt;
use std::io::Read;
use std::path::Path;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use defmt_decoder::{DecodeError, Table};

use crate::Error;

/// Severity of a log line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Level {
    /// `trace!`
    Trace,
    /// `debug!`
    Debug,
    /// `info!`
    Info,
    /// `warn!`
    Warn,
    /// `error!`
    Error,
}

impl Level {
    /// Upper-case name as printed in a line (`INFO`).
    pub fn as_str(self) -> &'static str {
        match self {
            Level::Trace => "TRACE",
            Level::Debug => "DEBUG",
            Level::Info => "INFO",
            Level::Warn => "WARN",
            Level::Error => "ERROR",
        }
    }
}

impl From<defmt_parser::Level> for Level {
    fn from(level: defmt_parser::Level) -> Self {
        match level {
            defmt_parser::Level::Trace => Level::Trace,
            defmt_parser::Level::Debug => Level::Debug,
            defmt_parser::Level::Info => Level::Info,
            defmt_parser::Level::Warn => Level::Warn,
            defmt_parser::Level::Error => Level::Error,
        }
    }
}

/// One decoded log line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogLine {
    /// When the harness received the frame.
    pub host_time: Instant,
    /// `None` for `println!` frames and for plain-text output.
    pub level: Option<Level>,
    /// The firmware's own timestamp, when it defines one.
    pub timestamp: Option<String>,
    /// The formatted message.
    pub message: String,
}

impl LogLine {
    /// True when the line has `level` and its message contains `needle`.
    pub fn is(&self, level: Level, needle: &str) -> bool {
        self.level == Some(level) && self.message.contains(needle)
    }

    /// Value of a `key=value` word in the message (`field("mtime")` on
    /// `tick 3 mtime=30000000` gives `Some("30000000")`).
    pub fn field(&self, key: &str) -> Option<&str> {
        self.message.split_whitespace().find_map(|word| {
            word.strip_prefix(key)
                .and_then(|rest| rest.strip_prefix('='))
        })
    }

    /// The word following `keyword` (`word_after("tick")` on `tick 3 mtime=...` gives `Some("3")`).
    pub fn word_after(&self, keyword: &str) -> Option<&str> {
        let mut words = self.message.split_whitespace();
        words.by_ref().find(|w| *w == keyword)?;
        words.next()
    }
}

impl fmt::Display for LogLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(ts) = &self.timestamp {
            write!(f, "{ts} ")?;
        }
        if let Some(level) = self.level {
            write!(f, "{:<5} ", level.as_str())?;
        }
        f.write_str(&self.message)
    }
}

/// How the firmware's log byte stream becomes lines.
#[derive(Debug, Clone)]
pub enum LogFormat {
    /// defmt frames, decoded with the ELF's table.
    Defmt(Box<Table>),
    /// The ELF has no `.defmt` section: the stream is newline-separated text.
    Text,
}

impl LogFormat {
    /// Loads the defmt table from ELF bytes; an ELF without `.defmt` gives `Text`.
    pub fn from_elf_bytes(elf: &[u8], path: &Path) -> Result<Self, Error> {
        match Table::parse(elf) {
            Ok(Some(table)) => Ok(LogFormat::Defmt(Box::new(table))),
            Ok(None) => Ok(LogFormat::Text),
            Err(e) => Err(Error::DefmtTable {
                path: path.to_owned(),
                reason: format!("{e:#}"),
            }),
        }
    }

    /// Reads and parses the ELF at `path`.
    pub fn from_elf(path: &Path) -> Result<Self, Error> {
        let bytes = std::fs::read(path).map_err(|source| Error::ReadElf {
            path: path.to_owned(),
            source,
        })?;
        Self::from_elf_bytes(&bytes, path)
    }
}

/// Longest plain-text log line kept whole; longer ones are split into pieces of this size.
pub const MAX_TEXT_LINE: usize = 4096;

/// Incremental bytes-to-lines conversion for one stream.
pub struct LineDecoder<'t> {
    inner: Inner<'t>,
    malformed: u64,
}

enum Inner<'t> {
    Defmt(Box<dyn defmt_decoder::StreamDecoder + Send + Sync + 't>),
    Text(Vec<u8>),
}

impl fmt::Debug for LineDecoder<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LineDecoder")
            .field("malformed", &self.malformed)
            .finish_non_exhaustive()
    }
}

impl<'t> LineDecoder<'t> {
    /// A decoder for `format`'s stream.
    pub fn new(format: &'t LogFormat) -> Self {
        let inner = match format {
            LogFormat::Defmt(table) => Inner::Defmt(table.new_stream_decoder()),
            LogFormat::Text => Inner::Text(Vec::new()),
        };
        LineDecoder {
            inner,
            malformed: 0,
        }
    }

    /// Frames that could not be decoded so far (skipped).
    pub fn malformed(&self) -> u64 {
        self.malformed
    }

    /// Feeds `data` received at `now` and appends every completed line to `out`.
    pub fn push(&mut self, data: &[u8], now: Instant, out: &mut Vec<LogLine>) {
        match &mut self.inner {
            Inner::Defmt(dec) => {
                dec.received(data);
                loop {
                    match dec.decode() {
                        Ok(frame) => out.push(LogLine {
                            host_time: now,
                            level: frame.level().map(Level::from),
                            timestamp: frame.display_timestamp().map(|t| t.to_string()),
                            message: frame.display_message().to_string(),
                        }),
                        Err(DecodeError::UnexpectedEof) => break,
                        Err(DecodeError::Malformed) => self.malformed += 1,
                    }
                }
            }
            Inner::Text(pending) => {
                pending.extend_from_slice(data);
                loop {
                    // A line longer than MAX_TEXT_LINE is cut there, so output that never
                    // ends a line cannot grow the buffer without bound.
                    let end = match pending.iter().position(|&b| b == b'\n') {
                        Some(pos) if pos <= MAX_TEXT_LINE => pos + 1,
                        _ if pending.len() > MAX_TEXT_LINE => MAX_TEXT_LINE,
                        _ => break,
                    };
                    let line: Vec<u8> = pending.drain(..end).collect();
                    let text = String::from_utf8_lossy(&line);
                    out.push(LogLine {
                        host_time: now,
                        level: None,
                        timestamp: None,
                        message: text
                            .trim_end_matches('\n')
                            .trim_end_matches('\r')
                            .to_owned(),
                    });
                }
            }
        }
    }
}

/// Lines a [`Log`] keeps by default; older ones are dropped first.
pub const DEFAULT_LOG_CAPACITY: usize = 100_000;

#[derive(Debug)]
struct State {
    /// The most recent lines; `lines[0]` has absolute index `dropped`.
    lines: VecDeque<LogLine>,
    dropped: usize,
    capacity: usize,
    closed: bool,
    /// Reader threads still running; the log closes when the last one ends.
    sources: usize,
    malformed: u64,
}

impl State {
    fn total(&self) -> usize {
        self.dropped + self.lines.len()
    }

    fn push(&mut self, line: LogLine) {
        if self.lines.len() == self.capacity {
            self.lines.pop_front();
            self.dropped += 1;
        }
        self.lines.push_back(line);
    }
}

#[derive(Debug)]
struct Shared {
    state: Mutex<State>,
    changed: Condvar,
}

/// Collected log lines of one QEMU run, filled by background threads. Cheap to clone;
/// all clones see the same lines. Lines are numbered from 0 in arrival order; only the
/// most recent `capacity` are kept, so a long run cannot exhaust memory.
#[derive(Debug, Clone)]
pub struct Log {
    shared: Arc<Shared>,
}

impl Default for Log {
    fn default() -> Self {
        Self::with_capacity(DEFAULT_LOG_CAPACITY)
    }
}

impl Log {
    /// An empty log with [`DEFAULT_LOG_CAPACITY`] that nothing feeds yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty log keeping at most `capacity` (at least 1) recent lines.
    pub fn with_capacity(capacity: usize) -> Self {
        Log {
            shared: Arc::new(Shared {
                state: Mutex::new(State {
                    lines: VecDeque::new(),
                    dropped: 0,
                    capacity: capacity.max(1),
                    closed: false,
                    sources: 0,
                    malformed: 0,
                }),
                changed: Condvar::new(),
            }),
        }
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic while holding the lock cannot leave `State` inconsistent (only pushes).
        self.shared
            .state
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Appends lines (used by the reader thread; also handy in tests).
    pub fn extend(&self, lines: impl IntoIterator<Item = LogLine>) {
        let mut state = self.lock();
        for line in lines {
            state.push(line);
        }
        drop(state);
        self.shared.changed.notify_all();
    }

    /// Marks the stream as ended: waits stop early instead of running into their timeout.
    pub fn close(&self) {
        self.lock().closed = true;
        self.shared.changed.notify_all();
    }

    /// Whether the stream has ended.
    pub fn is_closed(&self) -> bool {
        self.lock().closed
    }

    /// Number of frames the decoder had to skip.
    pub fn malformed_frames(&self) -> u64 {
        self.lock().malformed
    }

    /// A copy of the lines still kept (all of them unless more than the capacity arrived).
    pub fn lines(&self) -> Vec<LogLine> {
        self.lock().lines.iter().cloned().collect()
    }

    /// Lines received so far, kept or not: the index the next line will get, a cursor
    /// for [`wait_for_from`](Self::wait_for_from).
    pub fn len(&self) -> usize {
        self.lock().total()
    }

    /// Lines dropped because the log was full.
    pub fn dropped(&self) -> usize {
        self.lock().dropped
    }

    /// True before the first line.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Waits for the first line, anywhere in the log, that satisfies `pred`.
    pub fn wait_for(
        &self,
        pred: impl FnMut(&LogLine) -> bool,
        timeout: Duration,
    ) -> Result<LogLine, Error> {
        self.wait_for_from(0, pred, timeout).map(|(_, line)| line)
    }

    /// Waits for the first line at index `>= from` that satisfies `pred`; returns its
    /// index and the line. Fails with [`Error::LogClosed`] as soon as the stream ends
    /// without a match, with [`Error::LogTimeout`] when `timeout` passes.
    pub fn wait_for_from(
        &self,
        from: usize,
        mut pred: impl FnMut(&LogLine) -> bool,
        timeout: Duration,
    ) -> Result<(usize, LogLine), Error> {
        let deadline = crate::deadline_after(timeout);
        let mut next = from;
        let mut state = self.lock();
        loop {
            // Lines before `dropped` are gone; the search resumes at the oldest kept one.
            next = next.max(state.dropped);
            while next < state.total() {
                let line = &state.lines[next - state.dropped];
                if pred(line) {
                    return Ok((next, line.clone()));
                }
                next += 1;
            }
            let last = || state.lines.back().map(ToString::to_string);
            if state.closed {
                return Err(Error::LogClosed {
                    seen: state.total(),
                    last: last(),
                });
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(Error::LogTimeout {
                    timeout,
                    seen: state.total(),
                    last: last(),
                });
            }
            state = self
                .shared
                .changed
                .wait_timeout(state, deadline - now)
                .unwrap_or_else(|poisoned| poisoned.into_inner())
                .0;
        }
    }

    /// Starts a thread that decodes `source` into this log until it reaches EOF. The log
    /// is closed once every such reader has ended.
    pub(crate) fn spawn_reader(
        &self,
        name: &str,
        format: LogFormat,
        mut source: impl Read + Send + 'static,
    ) -> std::io::Result<JoinHandle<()>> {
        let log = self.clone();
        self.lock().sources += 1;
        let spawned = thread::Builder::new().name(name.into()).spawn(move || {
            let mut decoder = LineDecoder::new(&format);
            let mut buf = vec![0u8; 16 * 1024];
            let mut fresh = Vec::new();
            let mut counted = 0;
            loop {
                match source.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => {
                        decoder.push(&buf[..n], Instant::now(), &mut fresh);
                        let mut state = log.lock();
                        for line in fresh.drain(..) {
                            state.push(line);
                        }
                        state.malformed += decoder.malformed() - counted;
                        counted = decoder.malformed();
                        drop(state);
                        log.shared.changed.notify_all();
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
            let mut state = log.lock();
            state.sources -= 1;
            if state.sources == 0 {
                state.closed = true;
            }
            drop(state);
            log.shared.changed.notify_all();
        });
        if spawned.is_err() {
            self.lock().sources -= 1;
        }
        spawned
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(level: Option<Level>, msg: &str) -> LogLine {
        LogLine {
            host_time: Instant::now(),
            level,
            timestamp: None,
            message: msg.to_owned(),
        }
    }

    #[test]
    fn display_has_level_then_message() {
        let mut l = line(Some(Level::Info), "tick 3 mtime=30000000");
        assert_eq!(l.to_string(), "INFO  tick 3 mtime=30000000");
        l.timestamp = Some("0.000042".into());
        l.level = Some(Level::Error);
        assert_eq!(l.to_string(), "0.000042 ERROR tick 3 mtime=30000000");
        assert_eq!(line(None, "raw").to_string(), "raw");
    }

    #[test]
    fn matching_helpers() {
        let l = line(Some(Level::Info), "tick 12 mtime=120000000 extra");
        assert!(l.is(Level::Info, "tick 12"));
        assert!(!l.is(Level::Error, "tick 12"));
        assert!(!l.is(Level::Info, "tock"));
        assert_eq!(l.field("mtime"), Some("120000000"));
        assert_eq!(l.field("time"), None);
        assert_eq!(l.word_after("tick"), Some("12"));
        assert_eq!(l.word_after("extra"), None);
        let banner = line(
            Some(Level::Info),
            "ubc-app 0.1.0 board=qemu_virt timebase=10000000 Hz",
        );
        assert_eq!(banner.field("board"), Some("qemu_virt"));
        assert_eq!(banner.field("timebase"), Some("10000000"));
    }

    #[test]
    fn text_lines_split_across_chunks() {
        let format = LogFormat::Text;
        let mut dec = LineDecoder::new(&format);
        let mut out = Vec::new();
        let t = Instant::now();
        dec.push(b"hel", t, &mut out);
        assert!(out.is_empty());
        dec.push(b"lo\r\nwor", t, &mut out);
        dec.push(b"ld\npartial", t, &mut out);
        let msgs: Vec<&str> = out.iter().map(|l| l.message.as_str()).collect();
        assert_eq!(msgs, ["hello", "world"]);
    }

    #[test]
    fn endless_text_line_is_cut_not_buffered_forever() {
        let format = LogFormat::Text;
        let mut dec = LineDecoder::new(&format);
        let mut out = Vec::new();
        let t = Instant::now();
        let chunk = [b'x'; 1000];
        for _ in 0..10 {
            dec.push(&chunk, t, &mut out);
        }
        let Inner::Text(pending) = &dec.inner else {
            panic!("text decoder");
        };
        assert!(
            pending.len() <= MAX_TEXT_LINE,
            "{} bytes pending",
            pending.len()
        );
        assert_eq!(out.len(), 10_000 / MAX_TEXT_LINE);
        assert!(out.iter().all(|l| l.message.len() == MAX_TEXT_LINE));
        // A line of exactly MAX_TEXT_LINE bytes plus its newline stays one line.
        let mut dec = LineDecoder::new(&format);
        out.clear();
        let mut exact = vec![b'y'; MAX_TEXT_LINE];
        exact.extend_from_slice(b"\nnext\n");
        dec.push(&exact, t, &mut out);
        let lens: Vec<usize> = out.iter().map(|l| l.message.len()).collect();
        assert_eq!(lens, [MAX_TEXT_LINE, 4]);
    }

    #[test]
    fn huge_timeouts_do_not_overflow() {
        let log = Log::new();
        log.close();
        let err = log
            .wait_for(|_| true, Duration::MAX)
            .expect_err("closed and empty");
        assert!(matches!(err, Error::LogClosed { seen: 0, .. }), "{err:?}");
        assert!(crate::deadline_after(Duration::MAX) > Instant::now());
    }

    /// The stand-in ELF's table: index 1 = info "standin up timebase={=u32} Hz",
    /// index 2 = error "standin exit requested".
    const STANDIN_ELF: &[u8] = include_bytes!("../tests/fixtures/standin.elf");

    #[test]
    fn decodes_rzcobs_defmt_frames_byte_exact() {
        // A Vec is suitably aligned for the ELF parser; the static byte array may not be.
        let elf = STANDIN_ELF.to_vec();
        let format =
            LogFormat::from_elf_bytes(&elf, Path::new("standin.elf")).expect("stand-in table");
        assert!(matches!(format, LogFormat::Defmt(_)));
        let mut dec = LineDecoder::new(&format);
        let mut out = Vec::new();
        let t = Instant::now();
        // 00 | rzcobs(01 00 80 96 98 00) 00 | rzcobs(02 00) 00, split mid-frame.
        dec.push(&[0x00, 0x01, 0x80, 0x96], t, &mut out);
        assert!(out.is_empty(), "frame not complete yet");
        dec.push(&[0x98, 0x62, 0x00, 0x02, 0x7e, 0x00], t, &mut out);
        let shown: Vec<String> = out.iter().map(ToString::to_string).collect();
        assert_eq!(
            shown,
            [
                "INFO  standin up timebase=10000000 Hz",
                "ERROR standin exit requested"
            ]
        );
        assert_eq!(dec.malformed(), 0);

        // An unknown index (7) is skipped and counted; decoding resumes at the next frame.
        out.clear();
        dec.push(&[0x07, 0x7e, 0x00, 0x02, 0x7e, 0x00], t, &mut out);
        assert_eq!(dec.malformed(), 1);
        assert_eq!(out.len(), 1);
        assert!(out[0].is(Level::Error, "exit requested"));
    }

    #[test]
    fn elf_without_defmt_is_text_and_garbage_is_an_error() {
        let err = LogFormat::from_elf_bytes(b"not an elf", Path::new("x.elf"))
            .expect_err("garbage is not an ELF");
        assert!(matches!(err, Error::DefmtTable { .. }), "{err:?}");
    }

    #[test]
    fn full_log_drops_oldest_but_keeps_absolute_indices() {
        let log = Log::with_capacity(3);
        log.extend((0..5).map(|i| line(Some(Level::Info), &format!("l{i}"))));
        assert_eq!((log.len(), log.dropped()), (5, 2));
        let kept: Vec<String> = log.lines().into_iter().map(|l| l.message).collect();
        assert_eq!(kept, ["l2", "l3", "l4"]);
        let (idx, l) = log
            .wait_for_from(0, |_| true, Duration::ZERO)
            .expect("oldest kept line");
        assert_eq!((idx, l.message.as_str()), (2, "l2"));
        let (idx, _) = log
            .wait_for_from(4, |_| true, Duration::ZERO)
            .expect("last line");
        assert_eq!(idx, 4);
        let err = log
            .wait_for_from(5, |_| true, Duration::ZERO)
            .expect_err("nothing new");
        assert!(matches!(err, Error::LogTimeout { seen: 5, .. }), "{err:?}");
    }

    #[test]
    fn wait_for_from_sees_later_lines_and_closing() {
        let log = Log::new();
        log.extend([line(Some(Level::Info), "a"), line(Some(Level::Info), "b")]);
        let (idx, l) = log
            .wait_for_from(0, |l| l.message == "b", Duration::from_millis(10))
            .expect("b is there");
        assert_eq!((idx, l.message.as_str()), (1, "b"));
        let err = log
            .wait_for_from(2, |l| l.message == "a", Duration::from_millis(20))
            .expect_err("a is before the cursor");
        assert!(matches!(err, Error::LogTimeout { seen: 2, .. }), "{err:?}");

        let feeder = log.clone();
        let t = thread::spawn(move || {
            thread::sleep(Duration::from_millis(30));
            feeder.extend([line(Some(Level::Warn), "late")]);
            feeder.close();
        });
        let got = log
            .wait_for(|l| l.is(Level::Warn, "late"), Duration::from_secs(5))
            .expect("late line");
        assert_eq!(got.message, "late");
        t.join().expect("feeder");
        let err = log
            .wait_for(|l| l.message == "never", Duration::from_secs(5))
            .expect_err("closed");
        assert!(matches!(err, Error::LogClosed { seen: 3, .. }), "{err:?}");
    }
}
