//! Shared pieces of the program's end-to-end tests: the firmware in QEMU with its LBC UART on
//! an in-process `lbc-emu` server (through a relay that survives the emulator's restarts and
//! can corrupt bytes) and its radio UART driven by a radio-mac ground station.

#![allow(dead_code)]

use std::io::{self, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use lbc_emu::lbc::LogEvent;
use lbc_emu::server::{ListenAddr, Server};
use lbc_emu::{Lbc, LbcConfig, LogEntry};
use lbc_link::Command;
use qemu_harness::{
    firmware_elf, skip_qemu_tests, Error, Level, LogLine, Qemu, SocketSpec, Uart, UartAttach,
};
use radio_mac::{Address, CarId, Event, GroundConfig, GroundStation, Key};
use ubc_app::program::console::{Notice, Reply, Request, Status, Tag};
use ubc_app::program::DEFAULT_KEY;

/// The emulated car's ID.
pub const CAR: u8 = 7;
/// Bound on QEMU start plus the firmware's banner.
pub const BOOT_TIMEOUT: Duration = Duration::from_secs(20);

/// An `lbc-emu` server on a Unix socket, run in a thread; commands it executed are recorded.
pub struct LbcServer {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// Everything the LBC logged (commands received, replies sent, resets).
    pub log: Arc<Mutex<Vec<LogEntry>>>,
}

impl LbcServer {
    /// Binds `path` and runs a freshly powered-up LBC behind it.
    pub fn start(path: &Path) -> Self {
        let mut cfg = LbcConfig::default();
        cfg.log = true;
        Self::start_with(path, Lbc::with_memory_eeprom(cfg, CAR))
    }

    /// Binds `path` and runs `lbc` behind it (its log should be enabled).
    pub fn start_with(path: &Path, mut lbc: Lbc) -> Self {
        let server = Server::bind(&ListenAddr::Unix(path.to_path_buf()))
            .unwrap_or_else(|e| panic!("cannot bind the LBC socket {}: {e}", path.display()));
        let stop = Arc::new(AtomicBool::new(false));
        let log = Arc::new(Mutex::new(Vec::new()));
        let (s, l) = (Arc::clone(&stop), Arc::clone(&log));
        let thread = thread::spawn(move || {
            let _ = server.run(
                &mut lbc,
                &s,
                &mut |e| l.lock().unwrap_or_else(|p| p.into_inner()).push(e.clone()),
                &mut |_| {},
            );
        });
        Self {
            stop,
            thread: Some(thread),
            log,
        }
    }

    /// Commands the LBC received and decoded.
    pub fn commands(&self) -> Vec<Command> {
        self.log
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .filter_map(|e| match &e.event {
                LogEvent::Command(c) => Some(*c),
                _ => None,
            })
            .collect()
    }

    /// Stops the emulator (the socket closes; the relay sees the LBC go away).
    pub fn kill(mut self) {
        self.halt();
    }

    fn halt(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for LbcServer {
    fn drop(&mut self) {
        self.halt();
    }
}

/// Relays QEMU's LBC UART (QEMU connects here) to the emulator's socket, reconnecting when the
/// emulator restarts, and corrupts one byte in `corrupt_every` in each direction when set.
pub struct Relay {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    /// Corrupt one byte in this many (0: none).
    pub corrupt_every: Arc<AtomicU32>,
    /// Bytes corrupted so far.
    pub corrupted: Arc<AtomicU64>,
}

impl Relay {
    /// Listens at `front` (for QEMU) and forwards to `back` (the emulator).
    pub fn start(front: &Path, back: &Path) -> Self {
        let listener = UnixListener::bind(front).expect("bind relay socket");
        listener.set_nonblocking(true).expect("nonblocking");
        let stop = Arc::new(AtomicBool::new(false));
        let corrupt_every = Arc::new(AtomicU32::new(0));
        let corrupted = Arc::new(AtomicU64::new(0));
        let (s, c, n) = (
            Arc::clone(&stop),
            Arc::clone(&corrupt_every),
            Arc::clone(&corrupted),
        );
        let back = back.to_path_buf();
        let thread = thread::spawn(move || relay(&listener, &back, &s, &c, &n));
        Self {
            stop,
            thread: Some(thread),
            corrupt_every,
            corrupted,
        }
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn read_some(s: &mut UnixStream, buf: &mut [u8]) -> io::Result<usize> {
    match s.read(buf) {
        Ok(0) => Err(io::ErrorKind::UnexpectedEof.into()),
        Ok(n) => Ok(n),
        Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(0),
        Err(e) => Err(e),
    }
}

fn relay(
    listener: &UnixListener,
    back: &Path,
    stop: &AtomicBool,
    corrupt_every: &AtomicU32,
    corrupted: &AtomicU64,
) {
    let mut front: Option<UnixStream> = None;
    let mut emu: Option<UnixStream> = None;
    let mut buf = [0u8; 4096];
    let mut rng: u32 = 0x9E37_79B9;
    let mut corrupt = |bytes: &mut [u8]| {
        let every = corrupt_every.load(Ordering::Relaxed);
        if every == 0 {
            return;
        }
        for b in bytes {
            rng ^= rng << 13;
            rng ^= rng >> 17;
            rng ^= rng << 5;
            if rng.is_multiple_of(every) {
                *b ^= ((rng >> 8) as u8) | 1;
                corrupted.fetch_add(1, Ordering::Relaxed);
            }
        }
    };
    while !stop.load(Ordering::Relaxed) {
        if front.is_none() {
            if let Ok((s, _)) = listener.accept() {
                let _ = s.set_nonblocking(true);
                front = Some(s);
            }
        }
        if emu.is_none() {
            if let Ok(s) = UnixStream::connect(back) {
                let _ = s.set_nonblocking(true);
                emu = Some(s);
            }
        }
        if let (Some(f), Some(e)) = (front.as_mut(), emu.as_mut()) {
            match read_some(f, &mut buf) {
                Ok(n) => {
                    corrupt(&mut buf[..n]);
                    if e.write_all(&buf[..n]).is_err() {
                        emu = None;
                    }
                }
                Err(_) => front = None,
            }
        }
        if let (Some(f), Some(e)) = (front.as_mut(), emu.as_mut()) {
            match read_some(e, &mut buf) {
                Ok(n) => {
                    corrupt(&mut buf[..n]);
                    let _ = f.write_all(&buf[..n]);
                }
                Err(_) => emu = None,
            }
        } else if let Some(f) = front.as_mut() {
            // No LBC behind the relay: what the UBC sends is lost, as on an open wire.
            let _ = read_some(f, &mut buf);
        }
        thread::sleep(Duration::from_millis(1));
    }
}

/// A radio-mac ground station on the firmware's radio UART, run by the calling thread.
pub struct Ground {
    uart: Uart,
    gs: GroundStation,
    start: Instant,
    /// Notices the car sent.
    pub notices: Vec<Notice>,
    /// The car requests go to.
    pub car: u8,
    /// Every byte the ground station sent (what a listener on the channel records).
    pub tape: Vec<u8>,
}

impl Ground {
    /// A ground station with the testbed default key.
    pub fn new(uart: Uart) -> Self {
        Self::with_key(uart, DEFAULT_KEY)
    }

    /// A ground station with `key`.
    pub fn with_key(uart: Uart, key: [u8; 16]) -> Self {
        Self {
            uart,
            gs: GroundStation::new(GroundConfig::new(Key::new(key), 1)),
            start: Instant::now(),
            notices: Vec::new(),
            car: CAR,
            tape: Vec::new(),
        }
    }

    /// The radio UART, to go on with another station.
    pub fn into_uart(self) -> Uart {
        self.uart
    }

    /// Goes on with the radio UART of a restarted firmware (same station, same session).
    pub fn reattach(&mut self, uart: Uart) {
        self.uart = uart;
    }

    /// The radio-mac station's counters.
    pub fn stats(&self) -> radio_mac::Stats {
        *self.gs.stats()
    }

    fn now(&self) -> u64 {
        self.start.elapsed().as_micros() as u64
    }

    /// Exchanges bytes for a few milliseconds and returns the events.
    pub fn pump(&mut self) -> Vec<Event> {
        let mut buf = [0u8; 1024];
        match self
            .uart
            .read_some_timeout(&mut buf, Duration::from_millis(5))
        {
            Ok(n) => {
                let now = self.now();
                self.gs.push_rx(now, &buf[..n]);
            }
            Err(Error::UartTimeout { .. }) => {}
            Err(e) => panic!("radio uart: {e}"),
        }
        let now = self.now();
        self.gs.poll(now);
        let mut events = Vec::new();
        while let Some(ev) = self.gs.next_event() {
            match ev {
                Event::Request(inc) if inc.tag == Tag::Notice as u8 => {
                    if let Ok(n) = Notice::decode(&inc.payload) {
                        self.notices.push(n);
                    }
                    let _ = self.gs.reply(inc.id, inc.tag, &[]);
                }
                other => events.push(other),
            }
        }
        loop {
            let n = self.gs.transmit(&mut buf);
            if n == 0 {
                break;
            }
            self.tape.extend_from_slice(&buf[..n]);
            self.uart.write_all(&buf[..n]).expect("radio write");
        }
        events
    }

    /// Keeps the link alive for `d`.
    pub fn run_for(&mut self, d: Duration) {
        let end = Instant::now() + d;
        while Instant::now() < end {
            self.pump();
        }
    }

    /// Raw bytes straight onto the radio UART (noise).
    pub fn inject(&mut self, bytes: &[u8]) {
        self.uart.write_all(bytes).expect("radio write");
    }

    /// Sends a console request and waits for the reply; `None` if the radio gave up or
    /// `timeout` passed.
    pub fn try_request(&mut self, req: &Request, timeout: Duration) -> Option<Reply> {
        let mut buf = [0u8; 32];
        let n = req.encode(&mut buf).expect("encode");
        let tag = req.tag() as u8;
        let dst = Address::Car(CarId::new(self.car).expect("car id"));
        let end = Instant::now() + timeout;
        let h = loop {
            let now = self.now();
            match self.gs.command(now, dst, tag, &buf[..n]) {
                Ok(h) => break h,
                Err(_) if Instant::now() < end => {
                    self.pump();
                }
                Err(e) => panic!("ground command: {e:?}"),
            }
        };
        while Instant::now() < end {
            for ev in self.pump() {
                match ev {
                    Event::Reply {
                        handle,
                        tag: t,
                        payload,
                        ..
                    } if handle == h => {
                        return Some(Reply::decode(t, &payload).expect("reply decodes"));
                    }
                    Event::Failed { handle, .. } if handle == h => return None,
                    _ => {}
                }
            }
        }
        None
    }

    /// Like [`Ground::try_request`], retried until `timeout`; panics without an answer.
    pub fn request(&mut self, req: &Request, timeout: Duration) -> Reply {
        let end = Instant::now() + timeout;
        loop {
            let left = end.saturating_duration_since(Instant::now());
            if let Some(r) = self.try_request(req, left.min(Duration::from_secs(3))) {
                return r;
            }
            assert!(
                Instant::now() < end,
                "no reply to {req:?} within {timeout:?}"
            );
        }
    }

    /// The car's status.
    pub fn status(&mut self) -> Status {
        match self.request(&Request::Status, Duration::from_secs(10)) {
            Reply::Status(s) => s,
            other => panic!("status: {other:?}"),
        }
    }

    /// Polls the status until `done` holds (or panics after `timeout`).
    pub fn wait_status(&mut self, timeout: Duration, done: impl Fn(&Status) -> bool) -> Status {
        let end = Instant::now() + timeout;
        loop {
            let s = self.status();
            if done(&s) {
                return s;
            }
            assert!(Instant::now() < end, "status never as expected: {s:?}");
            self.run_for(Duration::from_millis(200));
        }
    }
}

/// A booted firmware with the LBC relay and emulator and the ground station.
pub struct Rig {
    pub qemu: Qemu,
    pub ground: Ground,
    pub relay: Relay,
    pub lbc: Option<LbcServer>,
    pub dir: tempfile::TempDir,
}

impl Rig {
    /// Path of the emulator's socket.
    pub fn lbc_path(&self) -> PathBuf {
        self.dir.path().join("lbc-emu.sock")
    }

    /// Restarts the emulator: a freshly powered-up LBC on the same socket.
    pub fn restart_lbc(&mut self) {
        if let Some(old) = self.lbc.take() {
            old.kill();
        }
        self.lbc = Some(LbcServer::start(&self.lbc_path()));
    }

    /// Kills QEMU and returns its log (for failure messages).
    pub fn shutdown(mut self) -> Vec<LogLine> {
        let _ = self.qemu.kill();
        self.qemu.log().lines()
    }
}

/// Boots the firmware for `test`; `None` when `UBC_SKIP_QEMU=1`.
pub fn boot(test: &str) -> Option<Rig> {
    if skip_qemu_tests(test) {
        return None;
    }
    let elf = firmware_elf().unwrap_or_else(|e| panic!("{test}: no firmware: {e}"));
    let dir = tempfile::tempdir().expect("temp dir");
    let emu = dir.path().join("lbc-emu.sock");
    let front = dir.path().join("lbc-relay.sock");
    let lbc = LbcServer::start(&emu);
    let relay = Relay::start(&front, &emu);
    let mut qemu = Qemu::builder(&elf)
        .lbc(UartAttach::Connect(SocketSpec::Unix(front)))
        .spawn()
        .unwrap_or_else(|e| panic!("{test}: cannot start QEMU: {e}"));
    qemu.wait_for_log(
        |l| l.level == Some(Level::Info) && l.message.starts_with("ubc-app "),
        BOOT_TIMEOUT,
    )
    .unwrap_or_else(|e| panic!("{test}: no banner: {e}\n{}", qemu.stderr_text()));
    let radio = qemu.take_radio().expect("harness radio uart");
    Some(Rig {
        qemu,
        ground: Ground::new(radio),
        relay,
        lbc: Some(lbc),
        dir,
    })
}
