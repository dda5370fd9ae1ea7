//! What QEMU is started with: the builder callers fill in, and the pure translation of
//! that configuration into a `qemu-system-riscv32` command line.

use std::ffi::{OsStr, OsString};
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::shared_ram::SharedRamSpec;
use crate::spec::{SocketSpec, UartAttach};

/// Chardev id of the LBC link (the board's built-in NS16550A, `-serial`).
pub const LBC_CHARDEV: &str = "lbc";
/// Chardev id of the radio link (a `pci-serial` 16550).
pub const RADIO_CHARDEV: &str = "radio";
/// Chardev id of the semihosting console, which carries `SYS_WRITEC`/`SYS_WRITE0` output.
pub const SEMIHOST_CHARDEV: &str = "semihost";

/// Everything needed to start one QEMU instance.
#[derive(Debug, Clone)]
pub struct QemuConfig {
    /// The `qemu-system-riscv32` binary; `None` means look it up on `PATH`.
    pub qemu: Option<PathBuf>,
    /// Firmware ELF passed to `-kernel`; its `.defmt` table decodes the log.
    pub elf: PathBuf,
    /// QEMU machine (`-M`).
    pub machine: String,
    /// Attachment of the LBC UART.
    pub lbc: UartAttach,
    /// Attachment of the radio UART.
    pub radio: UartAttach,
    /// `-icount shift=N`: deterministic instruction counting instead of wall-clock time.
    pub icount_shift: Option<u8>,
    /// Appended verbatim after the generated arguments.
    pub extra_args: Vec<OsString>,
    /// How long `spawn` keeps retrying to connect to QEMU's sockets.
    pub connect_timeout: Duration,
    /// Have the kernel kill QEMU if the spawning thread dies (`setpriv --pdeathsig`),
    /// so not even a killed test process leaves it behind.
    pub kill_with_parent: bool,
    /// Guest RAM as a shared host file (the frame grabber's window); `None`: QEMU's own RAM.
    pub shared_ram: Option<SharedRamSpec>,
}

impl QemuConfig {
    /// A configuration with the project defaults for `elf`.
    pub fn new(elf: impl Into<PathBuf>) -> Self {
        QemuConfig {
            qemu: None,
            elf: elf.into(),
            machine: "virt".to_owned(),
            lbc: UartAttach::Harness,
            radio: UartAttach::Harness,
            icount_shift: None,
            extra_args: Vec::new(),
            connect_timeout: Duration::from_secs(10),
            kill_with_parent: true,
            shared_ram: None,
        }
    }

    /// Path of the socket QEMU serves for a harness-attached UART.
    pub fn harness_socket(sock_dir: &Path, chardev: &str) -> PathBuf {
        sock_dir.join(format!("{chardev}.sock"))
    }

    /// The QEMU arguments (without the program name). Harness-attached sockets are
    /// placed in `sock_dir`.
    pub fn args(&self, sock_dir: &Path) -> Vec<OsString> {
        let mut args: Vec<OsString> = Vec::new();
        let mut push = |items: &[&OsStr]| args.extend(items.iter().map(|s| s.to_os_string()));
        push(&[
            "-M".as_ref(),
            self.machine.as_ref(),
            "-bios".as_ref(),
            "none".as_ref(),
            "-kernel".as_ref(),
            self.elf.as_os_str(),
            "-display".as_ref(),
            "none".as_ref(),
            "-monitor".as_ref(),
            "none".as_ref(),
        ]);
        // The firmware's defmt frames reach the host by semihosting on either of two
        // routes, both read by the harness: SYS_WRITEC/SYS_WRITE0 go to the console
        // chardev (a harness socket), while SYS_WRITE on the ":tt" handle goes to QEMU's
        // own stdout (a pipe) in QEMU 7.2, whatever the console chardev is.
        args.push("-chardev".into());
        args.push(chardev_arg(
            SEMIHOST_CHARDEV,
            &UartAttach::Harness,
            sock_dir,
        ));
        args.push("-semihosting-config".into());
        args.push(format!("enable=on,target=native,chardev={SEMIHOST_CHARDEV}").into());
        for (id, attach) in [(LBC_CHARDEV, &self.lbc), (RADIO_CHARDEV, &self.radio)] {
            args.push("-chardev".into());
            args.push(chardev_arg(id, attach, sock_dir));
            if id == LBC_CHARDEV {
                args.push("-serial".into());
                args.push(format!("chardev:{id}").into());
            } else {
                args.push("-device".into());
                args.push(format!("pci-serial,chardev={id}").into());
            }
        }
        if let Some(ram) = &self.shared_ram {
            let mut backend = OsString::from(format!(
                "memory-backend-file,id=ram0,size={}M,mem-path=",
                ram.mib
            ));
            backend.push(escape_opt(ram.path.as_os_str()));
            backend.push(",share=on");
            args.push("-m".into());
            args.push(format!("{}M", ram.mib).into());
            args.push("-object".into());
            args.push(backend);
            args.push("-machine".into());
            args.push("memory-backend=ram0".into());
        }
        if let Some(shift) = self.icount_shift {
            args.push("-icount".into());
            args.push(format!("shift={shift}").into());
        }
        args.extend(self.extra_args.iter().cloned());
        args
    }
}

/// QEMU option values are comma-separated; a literal comma is written twice.
fn escape_opt(value: &OsStr) -> OsString {
    value.to_string_lossy().replace(',', ",,").into()
}

fn socket_target(spec: &SocketSpec) -> OsString {
    match spec {
        SocketSpec::Unix(path) => {
            let mut s = OsString::from("path=");
            s.push(escape_opt(path.as_os_str()));
            s
        }
        SocketSpec::Tcp { host, port } => {
            format!("host={},port={port}", host.replace(',', ",,")).into()
        }
    }
}

fn chardev_arg(id: &str, attach: &UartAttach, sock_dir: &Path) -> OsString {
    let mut s = OsString::new();
    match attach {
        UartAttach::Harness => {
            let path = QemuConfig::harness_socket(sock_dir, id);
            s.push(format!("socket,id={id},"));
            s.push(socket_target(&SocketSpec::Unix(path)));
            s.push(",server=on,wait=on");
        }
        UartAttach::Connect(spec) => {
            // Reconnect within a second when the peer (e.g. an emulated LBC) restarts.
            s.push(format!("socket,id={id},"));
            s.push(socket_target(spec));
            s.push(",reconnect=1");
        }
        UartAttach::Listen(spec) => {
            s.push(format!("socket,id={id},"));
            s.push(socket_target(spec));
            s.push(",server=on,wait=off");
        }
        UartAttach::Null => s.push(format!("null,id={id}")),
    }
    s
}

/// Fluent construction of a [`QemuConfig`], finished by [`spawn`](QemuBuilder::spawn).
#[derive(Debug, Clone)]
pub struct QemuBuilder {
    config: QemuConfig,
}

impl QemuBuilder {
    /// Starts from [`QemuConfig::new`].
    pub fn new(elf: impl Into<PathBuf>) -> Self {
        QemuBuilder {
            config: QemuConfig::new(elf),
        }
    }

    /// Use this QEMU binary instead of searching `PATH`.
    pub fn qemu_binary(mut self, path: impl Into<PathBuf>) -> Self {
        self.config.qemu = Some(path.into());
        self
    }

    /// QEMU machine name (default `virt`).
    pub fn machine(mut self, machine: impl Into<String>) -> Self {
        self.config.machine = machine.into();
        self
    }

    /// How the LBC UART is attached (default: [`UartAttach::Harness`]).
    pub fn lbc(mut self, attach: UartAttach) -> Self {
        self.config.lbc = attach;
        self
    }

    /// How the radio UART is attached (default: [`UartAttach::Harness`]).
    pub fn radio(mut self, attach: UartAttach) -> Self {
        self.config.radio = attach;
        self
    }

    /// Run with `-icount shift=N`.
    pub fn icount(mut self, shift: Option<u8>) -> Self {
        self.config.icount_shift = shift;
        self
    }

    /// Append one raw QEMU argument.
    pub fn arg(mut self, arg: impl Into<OsString>) -> Self {
        self.config.extra_args.push(arg.into());
        self
    }

    /// Back the guest RAM with a shared file the host can write (the frame grabber's window);
    /// the file is created and sized when QEMU is spawned, and left in place afterwards.
    pub fn shared_ram(mut self, ram: SharedRamSpec) -> Self {
        self.config.shared_ram = Some(ram);
        self
    }

    /// Bound on retrying the socket connections after QEMU starts.
    pub fn connect_timeout(mut self, timeout: Duration) -> Self {
        self.config.connect_timeout = timeout;
        self
    }

    /// Whether QEMU is tied to the life of the spawning thread (default true).
    pub fn kill_with_parent(mut self, on: bool) -> Self {
        self.config.kill_with_parent = on;
        self
    }

    /// The configuration built so far.
    pub fn config(&self) -> &QemuConfig {
        &self.config
    }

    /// Starts QEMU; see [`Qemu::spawn`](crate::Qemu::spawn).
    pub fn spawn(self) -> Result<crate::Qemu, crate::Error> {
        crate::Qemu::spawn(self.config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(args: &[OsString]) -> Vec<String> {
        args.iter()
            .map(|a| a.to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn default_command_line() {
        let cfg = QemuConfig::new("/fw/ubc-app");
        let args = strings(&cfg.args(Path::new("/tmp/q")));
        let expected = [
            "-M",
            "virt",
            "-bios",
            "none",
            "-kernel",
            "/fw/ubc-app",
            "-display",
            "none",
            "-monitor",
            "none",
            "-chardev",
            "socket,id=semihost,path=/tmp/q/semihost.sock,server=on,wait=on",
            "-semihosting-config",
            "enable=on,target=native,chardev=semihost",
            "-chardev",
            "socket,id=lbc,path=/tmp/q/lbc.sock,server=on,wait=on",
            "-serial",
            "chardev:lbc",
            "-chardev",
            "socket,id=radio,path=/tmp/q/radio.sock,server=on,wait=on",
            "-device",
            "pci-serial,chardev=radio",
        ];
        assert_eq!(args, expected);
        assert!(!args.iter().any(|a| a == "-nographic"));
    }

    #[test]
    fn client_listen_null_icount_and_extra() {
        let cfg = QemuBuilder::new("fw.elf")
            .lbc(UartAttach::Connect(SocketSpec::Unix(
                "/run/lbc,emu.sock".into(),
            )))
            .radio(UartAttach::Listen(SocketSpec::Tcp {
                host: "127.0.0.1".into(),
                port: 7000,
            }))
            .icount(Some(4))
            .arg("-s")
            .config()
            .clone();
        let args = strings(&cfg.args(Path::new("/unused")));
        let tail: Vec<&str> = args[14..].iter().map(String::as_str).collect();
        assert_eq!(
            tail,
            [
                "-chardev",
                "socket,id=lbc,path=/run/lbc,,emu.sock,reconnect=1",
                "-serial",
                "chardev:lbc",
                "-chardev",
                "socket,id=radio,host=127.0.0.1,port=7000,server=on,wait=off",
                "-device",
                "pci-serial,chardev=radio",
                "-icount",
                "shift=4",
                "-s",
            ]
        );

        let ram = QemuBuilder::new("fw.elf")
            .shared_ram(SharedRamSpec::new("/run/car 1,ram"))
            .config()
            .clone();
        let args = strings(&ram.args(Path::new("/d")));
        let tail: Vec<&str> = args[args.len() - 6..].iter().map(String::as_str).collect();
        assert_eq!(
            tail,
            [
                "-m",
                "32M",
                "-object",
                "memory-backend-file,id=ram0,size=32M,mem-path=/run/car 1,,ram,share=on",
                "-machine",
                "memory-backend=ram0",
            ]
        );

        let null = QemuBuilder::new("fw.elf")
            .radio(UartAttach::Null)
            .config()
            .clone();
        let args = strings(&null.args(Path::new("/d")));
        assert!(args.contains(&"null,id=radio".to_owned()));
        assert!(args.contains(&"pci-serial,chardev=radio".to_owned()));
    }
}
