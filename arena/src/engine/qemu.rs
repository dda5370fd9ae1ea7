//! The real-time engine: every car's firmware (the `qemu_virt` board build) in its own QEMU,
//! in wall-clock time. The car's LBC UART connects to a socket the engine listens on, its radio
//! UART listens on a socket the engine connects to, and with a camera its RAM is a shared file
//! whose frame-grabber window the world writes. Bytes cross at quantum boundaries: what the
//! world has due by then is written, what QEMU has sent is stamped with the quantum's end.
//! QEMU processes die with the process that started them.

use super::{CarEngine, CarIo, CoreLoad, Failure, FailureKind, Nanos, WindowWriter};
use crate::camera_feed::{init_run_window, ram_file_name};
use qemu_harness::{Qemu, SharedRam, SharedRamSpec, SocketSpec, UartAttach};
use std::collections::VecDeque;
use std::fmt;
use std::io::{self, ErrorKind, Read, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// Bytes queued towards one QEMU UART beyond which the oldest are dropped (a stalled guest).
const MAX_PENDING: usize = 64 * 1024;

/// Why the engine could not start.
#[derive(Debug)]
pub enum QemuEngineError {
    /// A socket or file in the run directory.
    Io(io::Error),
    /// QEMU for car `id` did not start or did not print its banner.
    Qemu { id: u8, source: qemu_harness::Error },
    /// QEMU for car `id` did not open its radio socket in time.
    NoRadioSocket { id: u8, path: PathBuf },
}

impl fmt::Display for QemuEngineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            QemuEngineError::Io(e) => write!(f, "{e}"),
            QemuEngineError::Qemu { id, source } => write!(f, "car {id}: {source}"),
            QemuEngineError::NoRadioSocket { id, path } => write!(
                f,
                "car {id}: QEMU did not open its radio socket {}",
                path.display()
            ),
        }
    }
}

impl std::error::Error for QemuEngineError {}

impl From<io::Error> for QemuEngineError {
    fn from(e: io::Error) -> Self {
        QemuEngineError::Io(e)
    }
}

/// One byte stream to a QEMU UART with what is still to be written.
#[derive(Debug, Default)]
struct Link {
    stream: Option<UnixStream>,
    held: VecDeque<(Nanos, u8)>,
    pending: Vec<u8>,
}

impl Link {
    /// Writes what is due by `until`; reads what QEMU sent, stamped `until`. Returns false
    /// when the connection ended.
    fn exchange(
        &mut self,
        until: Nanos,
        input: &mut Vec<(Nanos, u8)>,
        out: &mut Vec<(Nanos, u8)>,
    ) -> bool {
        self.held.extend(input.drain(..));
        let Some(s) = self.stream.as_mut() else {
            self.held.clear();
            return true;
        };
        while let Some(&(t, b)) = self.held.front() {
            if t > until {
                break;
            }
            self.held.pop_front();
            self.pending.push(b);
        }
        if self.pending.len() > MAX_PENDING {
            let excess = self.pending.len() - MAX_PENDING;
            self.pending.drain(..excess);
        }
        let mut alive = true;
        let mut done = 0;
        while done < self.pending.len() {
            match s.write(&self.pending[done..]) {
                Ok(0) => {
                    alive = false;
                    break;
                }
                Ok(n) => done += n,
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => {
                    alive = false;
                    break;
                }
            }
        }
        self.pending.drain(..done);
        let mut buf = [0u8; 4096];
        loop {
            match s.read(&mut buf) {
                Ok(0) => {
                    alive = false;
                    break;
                }
                Ok(n) => out.extend(buf[..n].iter().map(|&b| (until, b))),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => break,
            }
        }
        if !alive {
            self.stream = None;
            self.pending.clear();
        }
        alive
    }
}

struct QemuCar {
    id: u8,
    qemu: Qemu,
    lbc_listener: UnixListener,
    lbc: Link,
    radio: Link,
    ram: Option<SharedRam>,
    failure: Option<Failure>,
}

/// The real-time engine.
pub struct QemuEngine {
    cars: Vec<QemuCar>,
}

impl fmt::Debug for QemuEngine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("QemuEngine")
            .field("cars", &self.cars.iter().map(|c| c.id).collect::<Vec<_>>())
            .finish()
    }
}

fn wait_for_path(path: &Path, timeout: Duration) -> bool {
    let start = Instant::now();
    while !path.exists() {
        if start.elapsed() > timeout {
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    true
}

impl QemuEngine {
    /// Starts one QEMU per `(id, firmware)` with its sockets (and, with a `camera`, its RAM
    /// file; with `Some(true)` also the run window the host fills as the vision unit would,
    /// written before the firmware starts so it finds it) in `dir`; returns once every firmware
    /// printed its banner.
    pub fn start(
        dir: &Path,
        cars: &[(u8, PathBuf)],
        camera: Option<bool>,
        boot_timeout: Duration,
    ) -> Result<Self, QemuEngineError> {
        let mut engine = QemuEngine { cars: Vec::new() };
        for (id, firmware) in cars {
            let id = *id;
            let lbc_path = dir.join(format!("car{id}-lbc.sock"));
            let radio_path = dir.join(format!("car{id}-radio.sock"));
            let lbc_listener = UnixListener::bind(&lbc_path)?;
            lbc_listener.set_nonblocking(true)?;
            let mut builder = Qemu::builder(firmware)
                .lbc(UartAttach::Connect(SocketSpec::Unix(lbc_path)))
                .radio(UartAttach::Listen(SocketSpec::Unix(radio_path.clone())))
                .kill_with_parent(true);
            let mut ram = None;
            if let Some(unit) = camera {
                let spec = SharedRamSpec::new(dir.join(ram_file_name(id)));
                let mut file = SharedRam::create(&spec.path, spec.len())?;
                if unit {
                    init_run_window(&mut file)?;
                }
                ram = Some(file);
                builder = builder.shared_ram(spec);
            }
            let qemu = builder
                .spawn()
                .map_err(|source| QemuEngineError::Qemu { id, source })?;
            if !wait_for_path(&radio_path, Duration::from_secs(10)) {
                return Err(QemuEngineError::NoRadioSocket {
                    id,
                    path: radio_path,
                });
            }
            let radio = UnixStream::connect(&radio_path)?;
            radio.set_nonblocking(true)?;
            engine.cars.push(QemuCar {
                id,
                qemu,
                lbc_listener,
                lbc: Link::default(),
                radio: Link {
                    stream: Some(radio),
                    ..Link::default()
                },
                ram,
                failure: None,
            });
        }
        for c in &engine.cars {
            c.qemu
                .wait_for_log(|l| l.message.contains("ubc-app"), boot_timeout)
                .map_err(|source| QemuEngineError::Qemu { id: c.id, source })?;
        }
        Ok(engine)
    }

    /// Each car's QEMU process ID.
    pub fn pids(&self) -> Vec<(u8, u32)> {
        self.cars.iter().map(|c| (c.id, c.qemu.pid())).collect()
    }
}

impl CarEngine for QemuEngine {
    fn name(&self) -> &'static str {
        "qemu"
    }

    fn wall_clock(&self) -> bool {
        true
    }

    fn advance(&mut self, until: Nanos, io: &mut [CarIo]) {
        for (c, io) in self.cars.iter_mut().zip(io.iter_mut()) {
            if c.failure.is_some() {
                io.lbc_in.clear();
                io.radio_in.clear();
                continue;
            }
            if let Ok(Some(status)) = c.qemu.try_wait() {
                c.failure = Some(Failure {
                    at: until,
                    kind: FailureKind::Killed {
                        why: format!("QEMU {status}"),
                    },
                });
                continue;
            }
            if c.lbc.stream.is_none() {
                if let Ok((s, _)) = c.lbc_listener.accept() {
                    if s.set_nonblocking(true).is_ok() {
                        c.lbc = Link {
                            stream: Some(s),
                            ..Link::default()
                        };
                    }
                }
            }
            c.lbc.exchange(until, &mut io.lbc_in, &mut io.lbc_out);
            if !c.radio.exchange(until, &mut io.radio_in, &mut io.radio_out) {
                c.failure = Some(Failure {
                    at: until,
                    kind: FailureKind::Killed {
                        why: "radio UART socket closed".into(),
                    },
                });
            }
        }
    }

    fn failure(&self, k: usize) -> Option<Failure> {
        self.cars.get(k)?.failure.clone()
    }

    fn with_window(&mut self, k: usize, f: &mut dyn FnMut(&mut dyn WindowWriter)) -> bool {
        match self.cars.get_mut(k).and_then(|c| c.ram.as_mut()) {
            Some(r) => {
                f(r);
                true
            }
            None => false,
        }
    }

    fn core_load(&self, _k: usize) -> Option<CoreLoad> {
        None
    }

    fn firmware_log(&self, k: usize) -> Vec<String> {
        self.cars
            .get(k)
            .map(|c| c.qemu.log().lines().iter().map(|l| l.to_string()).collect())
            .unwrap_or_default()
    }

    fn kill(&mut self, k: usize, _why: &str) {
        if let Some(c) = self.cars.get_mut(k) {
            // The next quantum sees the process gone and records the failure.
            let _ = c.qemu.kill();
        }
    }

    fn shutdown(&mut self) {
        for c in &mut self.cars {
            let _ = c.qemu.kill();
        }
    }
}

impl Drop for QemuEngine {
    fn drop(&mut self) {
        self.shutdown();
    }
}
