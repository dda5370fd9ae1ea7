//! A running QEMU: the child process, its private socket directory, the UART handles
//! and the log reader. Dropping it always kills and reaps QEMU and removes the directory.

use std::io::Read;
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::{Arc, Mutex};
use std::thread::{self, JoinHandle};
use std::time::{Duration, Instant};

use crate::config::{QemuConfig, LBC_CHARDEV, RADIO_CHARDEV, SEMIHOST_CHARDEV};
use crate::log::{Log, LogFormat, LogLine};
use crate::spec::{SocketSpec, UartAttach};
use crate::{find_qemu, Error, QemuBuilder, Uart};

/// Bytes of QEMU's stderr kept for error reports.
const STDERR_KEEP: usize = 64 * 1024;

/// One QEMU instance running the firmware.
#[derive(Debug)]
pub struct Qemu {
    child: Child,
    exit: Option<ExitStatus>,
    sock_dir: tempfile::TempDir,
    lbc: Option<Uart>,
    radio: Option<Uart>,
    log: Log,
    stderr: Arc<Mutex<Vec<u8>>>,
    threads: Vec<JoinHandle<()>>,
    started: Instant,
    /// Unix sockets QEMU serves outside `sock_dir`; removed once QEMU is gone.
    listen_paths: Vec<PathBuf>,
}

impl Qemu {
    /// A builder for booting `elf`.
    pub fn builder(elf: impl Into<PathBuf>) -> QemuBuilder {
        QemuBuilder::new(elf)
    }

    /// Starts QEMU with `config`, begins decoding its log and connects to every
    /// harness-attached UART socket, retrying until `config.connect_timeout`.
    ///
    /// With `kill_with_parent` (the default) the kernel kills QEMU when the thread that
    /// called `spawn` ends, so keep the `Qemu` on that thread (UART handles and the log
    /// may move freely).
    pub fn spawn(config: QemuConfig) -> Result<Qemu, Error> {
        let format = LogFormat::from_elf(&config.elf)?;
        let qemu_bin = match &config.qemu {
            Some(path) => path.clone(),
            None => find_qemu()?,
        };
        if let Some(ram) = &config.shared_ram {
            crate::SharedRam::create(&ram.path, ram.len()).map_err(|source| Error::Io {
                action: "creating the shared RAM file",
                source,
            })?;
        }
        let sock_dir = tempfile::Builder::new()
            .prefix("ubc-qemu-")
            .tempdir()
            .map_err(|source| Error::Io {
                action: "creating QEMU socket directory",
                source,
            })?;

        let mut cmd = match setpriv().filter(|_| config.kill_with_parent) {
            Some(setpriv) => {
                let mut c = Command::new(setpriv);
                c.args(["--pdeathsig", "KILL", "--"]).arg(&qemu_bin);
                c
            }
            None => Command::new(&qemu_bin),
        };
        cmd.args(config.args(sock_dir.path()))
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = cmd.spawn().map_err(|source| Error::Io {
            action: "starting qemu-system-riscv32",
            source,
        })?;
        let stdout = child.stdout.take();
        let stderr_pipe = child.stderr.take();

        let mut qemu = Qemu {
            child,
            exit: None,
            sock_dir,
            lbc: None,
            radio: None,
            log: Log::new(),
            stderr: Arc::new(Mutex::new(Vec::new())),
            threads: Vec::new(),
            started: Instant::now(),
            listen_paths: [&config.lbc, &config.radio]
                .into_iter()
                .filter_map(|attach| match attach {
                    UartAttach::Listen(SocketSpec::Unix(path)) => Some(path.clone()),
                    _ => None,
                })
                .collect(),
        };
        // From here on, any early return drops `qemu`, which kills the child.
        if let Some(stdout) = stdout {
            let t = qemu
                .log
                .spawn_reader("qemu-stdout-log", format.clone(), stdout)
                .map_err(|source| Error::Io {
                    action: "starting log reader thread",
                    source,
                })?;
            qemu.threads.push(t);
        }
        if let Some(stderr_pipe) = stderr_pipe {
            let t = spawn_stderr_reader(stderr_pipe, qemu.stderr.clone()).map_err(|source| {
                Error::Io {
                    action: "starting stderr reader thread",
                    source,
                }
            })?;
            qemu.threads.push(t);
        }

        let deadline = crate::deadline_after(config.connect_timeout);
        // QEMU creates (and, with wait=on, blocks on) the sockets in command-line order.
        let console = qemu.connect(SEMIHOST_CHARDEV, deadline, config.connect_timeout)?;
        let t = qemu
            .log
            .spawn_reader("qemu-semihost-log", format, console.into_stream())
            .map_err(|source| Error::Io {
                action: "starting log reader thread",
                source,
            })?;
        qemu.threads.push(t);
        if config.lbc == UartAttach::Harness {
            qemu.lbc = Some(qemu.connect(LBC_CHARDEV, deadline, config.connect_timeout)?);
        }
        if config.radio == UartAttach::Harness {
            qemu.radio = Some(qemu.connect(RADIO_CHARDEV, deadline, config.connect_timeout)?);
        }
        qemu.started = Instant::now();
        Ok(qemu)
    }

    fn connect(
        &mut self,
        uart: &'static str,
        deadline: Instant,
        timeout: Duration,
    ) -> Result<Uart, Error> {
        let path = QemuConfig::harness_socket(self.sock_dir.path(), uart);
        loop {
            match UnixStream::connect(&path) {
                Ok(stream) => return Uart::new(uart, stream),
                Err(source) => {
                    if let Some(status) = self.try_wait()? {
                        return Err(Error::ExitedDuringStartup {
                            status,
                            stderr: self.stderr_text_after_exit(),
                        });
                    }
                    if Instant::now() >= deadline {
                        return Err(Error::Connect {
                            uart,
                            path,
                            timeout,
                            source,
                        });
                    }
                    thread::sleep(Duration::from_millis(10));
                }
            }
        }
    }

    /// QEMU's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// When the sockets were connected (the firmware started right after).
    pub fn started(&self) -> Instant {
        self.started
    }

    /// The private directory holding QEMU's sockets.
    pub fn sock_dir(&self) -> &Path {
        self.sock_dir.path()
    }

    /// The LBC UART, if it is harness-attached and not taken.
    pub fn lbc(&mut self) -> Option<&mut Uart> {
        self.lbc.as_mut()
    }

    /// The radio UART, if it is harness-attached and not taken.
    pub fn radio(&mut self) -> Option<&mut Uart> {
        self.radio.as_mut()
    }

    /// Moves the LBC UART handle out (e.g. into a thread).
    pub fn take_lbc(&mut self) -> Option<Uart> {
        self.lbc.take()
    }

    /// Moves the radio UART handle out.
    pub fn take_radio(&mut self) -> Option<Uart> {
        self.radio.take()
    }

    /// The decoded log of this run.
    pub fn log(&self) -> &Log {
        &self.log
    }

    /// Waits for a log line matching `pred`; see [`Log::wait_for`].
    pub fn wait_for_log(
        &self,
        pred: impl FnMut(&LogLine) -> bool,
        timeout: Duration,
    ) -> Result<LogLine, Error> {
        self.log.wait_for(pred, timeout)
    }

    /// What QEMU has written to stderr so far (lossy UTF-8, at most 64 KiB).
    pub fn stderr_text(&self) -> String {
        let buf = self
            .stderr
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        String::from_utf8_lossy(&buf).into_owned()
    }

    fn stderr_text_after_exit(&mut self) -> String {
        // Give the reader a moment to drain the pipe QEMU just closed.
        let deadline = Instant::now() + Duration::from_millis(500);
        while Instant::now() < deadline && self.threads.iter().any(|t| !t.is_finished()) {
            thread::sleep(Duration::from_millis(5));
        }
        self.stderr_text()
    }

    /// QEMU's exit status if it has exited, without waiting.
    pub fn try_wait(&mut self) -> Result<Option<ExitStatus>, Error> {
        if self.exit.is_none() {
            self.exit = self.child.try_wait().map_err(|source| Error::Io {
                action: "polling QEMU",
                source,
            })?;
        }
        Ok(self.exit)
    }

    /// Waits up to `timeout` for QEMU to exit by itself and returns its status; on
    /// timeout QEMU keeps running (it is still killed on drop).
    pub fn wait_exit(&mut self, timeout: Duration) -> Result<ExitStatus, Error> {
        let deadline = crate::deadline_after(timeout);
        loop {
            if let Some(status) = self.try_wait()? {
                return Ok(status);
            }
            if Instant::now() >= deadline {
                return Err(Error::ExitTimeout { timeout });
            }
            thread::sleep(Duration::from_millis(10));
        }
    }

    /// Kills QEMU (if still running), reaps it and waits for the log readers to finish.
    pub fn kill(&mut self) -> Result<ExitStatus, Error> {
        let status = match self.exit {
            Some(status) => status,
            None => {
                // Not reaped yet, so the pid is still ours even if QEMU already exited; a
                // failed kill means exactly that, and `wait` collects the status either way.
                let _ = self.child.kill();
                let status = self.child.wait().map_err(|source| Error::Io {
                    action: "reaping QEMU",
                    source,
                })?;
                self.exit = Some(status);
                status
            }
        };
        self.join_threads();
        Ok(status)
    }

    fn join_threads(&mut self) {
        for t in self.threads.drain(..) {
            // The readers end at EOF, which QEMU's exit guarantees.
            let _ = t.join();
        }
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        // Nothing to propagate from a destructor; the process is gone either way.
        let _ = self.kill();
        for path in &self.listen_paths {
            // QEMU unlinks its socket only on a clean exit; a missing file is fine.
            let _ = std::fs::remove_file(path);
        }
        // `sock_dir` (a TempDir) removes itself after this.
    }
}

fn spawn_stderr_reader(
    mut pipe: impl Read + Send + 'static,
    sink: Arc<Mutex<Vec<u8>>>,
) -> std::io::Result<JoinHandle<()>> {
    thread::Builder::new()
        .name("qemu-stderr".into())
        .spawn(move || {
            let mut buf = [0u8; 4096];
            loop {
                match pipe.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => {
                        let mut kept = sink.lock().unwrap_or_else(|p| p.into_inner());
                        let room = STDERR_KEEP.saturating_sub(kept.len());
                        kept.extend_from_slice(&buf[..n.min(room)]);
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                    Err(_) => break,
                }
            }
        })
}

/// `setpriv` from util-linux, used to give QEMU a parent-death signal.
fn setpriv() -> Option<PathBuf> {
    crate::firmware::which("setpriv")
}
