//! A sweep on Slurm gives the same `runs.csv` as on this machine: the test starts a one-node
//! Slurm cluster (Debian's `slurm-wlm` and `munge`: munged, slurmctld and slurmd on 127.0.0.1
//! with their own key, configuration, ports and state in a temporary directory), submits the
//! script `almc sweep slurm` writes (a job array of two shares and a merge job after it), waits
//! for the merge, and compares its outputs with a local run of the same sweep byte for byte.
//!
//! Skipped (with a message saying why) where Slurm is not installed (`cargo xtask test`
//! installs it) or cannot be started (not root, daemons that do not come up). Every process it
//! starts is stopped when it ends, whatever happens: the daemons by their IDs, and the job
//! processes (slurmstepd, almc) by the marker variable they inherit.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const BASE: &str = r#"
name = "sweep-slurm"
duration_s = 3
seed = 1
[[cars]]
id = 1
x = 200
y = 300
heading_mrad = 1571
[[cars]]
id = 2
x = 400
y = 300
heading_mrad = 1571
[maneuver]
kind = "rendezvous"
radius_units = 40
speed_mm_s = 200
"#;

const SWEEP: &str = r#"
experiment = "base.toml"
seeds = 2
[[grid]]
path = "faults.radio_loss"
values = [0.0, 0.3]
"#;

/// Longest wait for the jobs.
const JOBS_TIMEOUT: Duration = Duration::from_secs(300);
/// Longest wait for the node to be idle.
const START_TIMEOUT: Duration = Duration::from_secs(30);
/// The variable every process of the cluster inherits, set to the cluster's directory.
const MARKER: &str = "ALMC_SWEEP_SLURM_TEST";

fn find(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin".into(), "/sbin".into()])
        .map(|d| d.join(program))
        .find(|p| p.is_file())
}

/// Two distinct free ports on 127.0.0.1 (both held until both are known).
fn free_ports() -> (u16, u16) {
    let bind = || std::net::TcpListener::bind("127.0.0.1:0");
    match (bind(), bind()) {
        (Ok(a), Ok(b)) => match (a.local_addr(), b.local_addr()) {
            (Ok(x), Ok(y)) => (x.port(), y.port()),
            _ => (16817, 16818),
        },
        _ => (16817, 16818),
    }
}

fn tail(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(15)..].join("\n")
}

/// A one-node Slurm cluster in a directory; dropping it stops everything it started.
struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
    daemons: Vec<(&'static str, Child)>,
}

impl Cluster {
    /// Starts munged, slurmctld and slurmd; `Err` says why Slurm cannot run here.
    fn start(dir: &Path) -> Result<Cluster, String> {
        for program in [
            "munged",
            "slurmctld",
            "slurmd",
            "sbatch",
            "scontrol",
            "sinfo",
            "scancel",
        ] {
            if find(program).is_none() {
                return Err(format!(
                    "`{program}` not found: install Debian's slurm-wlm and munge (cargo xtask test does)"
                ));
            }
        }
        let uid = Command::new("id")
            .arg("-u")
            .output()
            .map_err(|e| e.to_string())?;
        if String::from_utf8_lossy(&uid.stdout).trim() != "0" {
            return Err("slurmd must run as root".into());
        }
        for sub in ["state", "spool", "log"] {
            std::fs::create_dir_all(dir.join(sub)).map_err(|e| e.to_string())?;
        }
        let key = dir.join("munge.key");
        let mut bytes = vec![0u8; 1024];
        std::fs::File::open("/dev/urandom")
            .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut bytes))
            .and_then(|()| std::fs::write(&key, &bytes))
            .map_err(|e| e.to_string())?;
        Command::new("chmod")
            .arg("600")
            .arg(&key)
            .status()
            .map_err(|e| e.to_string())?;
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_owned())
            .map_err(|e| e.to_string())?;
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let (ctld, slurmd) = free_ports();
        let d = dir.display();
        let conf = dir.join("slurm.conf");
        let text = format!(
            "ClusterName=almcsweep\n\
             SlurmctldHost={host}(127.0.0.1)\n\
             SlurmctldPort={ctld}\n\
             SlurmdPort={slurmd}\n\
             SlurmUser=root\n\
             SlurmdUser=root\n\
             AuthType=auth/munge\n\
             CredType=cred/munge\n\
             AuthInfo=socket={d}/munge.sock\n\
             StateSaveLocation={d}/state\n\
             SlurmdSpoolDir={d}/spool\n\
             SlurmctldPidFile={d}/slurmctld.pid\n\
             SlurmdPidFile={d}/slurmd.pid\n\
             SlurmctldLogFile={d}/log/slurmctld.log\n\
             SlurmdLogFile={d}/log/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\n\
             TaskPlugin=task/none\n\
             SelectType=select/cons_tres\n\
             SelectTypeParameters=CR_Core\n\
             JobAcctGatherType=jobacct_gather/none\n\
             AccountingStorageType=accounting_storage/none\n\
             JobCompType=jobcomp/none\n\
             MpiDefault=none\n\
             ReturnToService=2\n\
             MinJobAge=600\n\
             NodeName={host} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory=1000 State=UNKNOWN\n\
             PartitionName=sweep Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
        );
        std::fs::write(&conf, text).map_err(|e| e.to_string())?;
        let mut cluster = Cluster {
            dir: dir.into(),
            conf,
            daemons: Vec::new(),
        };
        let s = |p: &str| format!("{d}/{p}");
        cluster.spawn(
            "munged",
            &[
                "-F",
                "-f",
                &format!("--socket={}", s("munge.sock")),
                &format!("--key-file={}", key.display()),
                &format!("--log-file={}", s("log/munged.log")),
                &format!("--pid-file={}", s("munged.pid")),
                &format!("--seed-file={}", s("munged.seed")),
            ],
        )?;
        cluster.wait_for(|| dir.join("munge.sock").exists(), "munged's socket")?;
        let conf_arg = cluster.conf.display().to_string();
        cluster.spawn("slurmctld", &["-D", "-i", "-f", &conf_arg])?;
        cluster.spawn("slurmd", &["-D", "-N", &host, "-f", &conf_arg])?;
        let conf = cluster.conf.clone();
        cluster.wait_for(
            || {
                cluster_cmd(dir, &conf, "sinfo", &["-h", "-o", "%t"])
                    .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).trim() == "idle")
            },
            "the node to be idle",
        )?;
        Ok(cluster)
    }

    fn spawn(&mut self, name: &'static str, args: &[&str]) -> Result<(), String> {
        let log = std::fs::File::create(self.dir.join("log").join(format!("{name}.out")))
            .map_err(|e| e.to_string())?;
        let child = Command::new(find(name).ok_or(format!("{name} not found"))?)
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .env(MARKER, &self.dir)
            .stdin(Stdio::null())
            .stdout(log.try_clone().map_err(|e| e.to_string())?)
            .stderr(log)
            .spawn()
            .map_err(|e| format!("{name}: {e}"))?;
        self.daemons.push((name, child));
        Ok(())
    }

    fn wait_for(&mut self, mut ready: impl FnMut() -> bool, what: &str) -> Result<(), String> {
        let end = Instant::now() + START_TIMEOUT;
        while Instant::now() < end {
            if ready() {
                return Ok(());
            }
            for (name, child) in &mut self.daemons {
                if let Ok(Some(status)) = child.try_wait() {
                    return Err(format!(
                        "{name} exited ({status}):\n{}",
                        tail(&self.dir.join("log").join(format!("{name}.out")))
                    ));
                }
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        Err(format!(
            "no {what} after {START_TIMEOUT:?}; slurmctld log:\n{}\nslurmd log:\n{}",
            tail(&self.dir.join("log/slurmctld.log")),
            tail(&self.dir.join("log/slurmd.log"))
        ))
    }

    /// A Slurm client command against this cluster.
    fn cmd(&self, program: &str, args: &[&str]) -> Output {
        cluster_cmd(&self.dir, &self.conf, program, args)
            .unwrap_or_else(|e| panic!("{program}: {e}"))
    }

    /// Waits for job `id` to end; its final state.
    fn wait_job(&self, id: &str) -> String {
        let end = Instant::now() + JOBS_TIMEOUT;
        loop {
            let o = self.cmd("scontrol", &["show", "job", id]);
            let text = String::from_utf8_lossy(&o.stdout).into_owned();
            let state = text
                .split_whitespace()
                .find_map(|w| w.strip_prefix("JobState="))
                .unwrap_or("")
                .to_owned();
            if !["PENDING", "RUNNING", "CONFIGURING", "COMPLETING", ""].contains(&state.as_str()) {
                return state;
            }
            assert!(
                Instant::now() < end,
                "job {id} still {state} after {JOBS_TIMEOUT:?}:\n{text}"
            );
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

fn cluster_cmd(dir: &Path, conf: &Path, program: &str, args: &[&str]) -> Result<Output, String> {
    Command::new(find(program).ok_or(format!("{program} not found"))?)
        .args(args)
        .env("SLURM_CONF", conf)
        .env(MARKER, dir)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| e.to_string())
}

/// Processes other than this one whose environment has the cluster's marker.
fn marked_processes(dir: &Path) -> Vec<u32> {
    let marker = format!("{MARKER}={}", dir.display());
    let me = std::process::id();
    std::fs::read_dir("/proc")
        .map(|rd| {
            rd.filter_map(Result::ok)
                .filter_map(|e| e.file_name().to_str()?.parse::<u32>().ok())
                .filter(|pid| *pid != me)
                .filter(|pid| {
                    std::fs::read(format!("/proc/{pid}/environ"))
                        .is_ok_and(|env| env.split(|b| *b == 0).any(|v| v == marker.as_bytes()))
                })
                .collect()
        })
        .unwrap_or_default()
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // Jobs first, while the daemons can still end them.
        let _ = cluster_cmd(&self.dir, &self.conf, "scancel", &["--user=root"]);
        let end = Instant::now() + Duration::from_secs(10);
        while Instant::now() < end {
            let queued = cluster_cmd(&self.dir, &self.conf, "squeue", &["-h"])
                .map(|o| o.stdout.is_empty())
                .unwrap_or(true);
            if queued {
                break;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        for (_, child) in self.daemons.iter_mut().rev() {
            let _ = Command::new("kill").arg(child.id().to_string()).status();
        }
        let end = Instant::now() + Duration::from_secs(10);
        for (_, child) in self.daemons.iter_mut().rev() {
            while Instant::now() < end && matches!(child.try_wait(), Ok(None)) {
                std::thread::sleep(Duration::from_millis(100));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        // Whatever a job left (slurmstepd, almc): started by us, found by the marker.
        for pid in marked_processes(&self.dir) {
            let _ = Command::new("kill").args(["-9", &pid.to_string()]).status();
        }
    }
}

fn almc(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_almc"))
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .output()
        .expect("almc runs")
}

#[test]
fn a_sweep_on_slurm_gives_the_local_runs_csv() {
    let d = std::env::temp_dir().join(format!("almc-sweep-slurm-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    std::fs::write(d.join("base.toml"), BASE).unwrap();
    std::fs::write(d.join("sweep.toml"), SWEEP).unwrap();
    let cluster = match Cluster::start(&d.join("cluster")) {
        Ok(c) => c,
        Err(why) => {
            let mut err = std::io::stderr();
            let _ = writeln!(
                err,
                "SKIPPED a_sweep_on_slurm_gives_the_local_runs_csv: Slurm cannot run here: {why}"
            );
            let _ = std::fs::remove_dir_all(&d);
            return;
        }
    };

    let local = almc(&["sweep", "run", "sweep.toml", "--out", "local"], &d);
    assert!(
        local.status.success(),
        "{}",
        String::from_utf8_lossy(&local.stderr)
    );

    let o = almc(
        &[
            "sweep",
            "slurm",
            "sweep.toml",
            "--shards",
            "2",
            "--out",
            "slurm",
        ],
        &d,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let submit = Command::new("bash")
        .arg(d.join("slurm/slurm.sh"))
        .env("SLURM_CONF", &cluster.conf)
        .env(MARKER, &cluster.dir)
        .current_dir(&d)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&submit.stdout).into_owned();
    assert!(
        submit.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&submit.stderr)
    );
    let job = |what: &str| {
        said.lines()
            .find_map(|l| l.strip_prefix(what))
            .unwrap_or_else(|| panic!("no `{what}` in {said}"))
            .trim()
            .to_owned()
    };
    let (array, merge) = (job("array job "), job("merge job "));
    let state = cluster.wait_job(&merge);
    let logs = || {
        ["shard-0.log", "shard-1.log", "merge.log"]
            .iter()
            .map(|l| format!("{l}:\n{}", tail(&d.join("slurm/slurm").join(l))))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(
        state,
        "COMPLETED",
        "merge job {merge} (after array {array}):\n{}",
        logs()
    );
    for f in ["runs.csv", "aggregate.csv"] {
        let a = std::fs::read_to_string(d.join("local").join(f)).unwrap();
        let b = std::fs::read_to_string(d.join("slurm").join(f)).unwrap_or_default();
        assert_eq!(a, b, "{f} differs:\n{}", logs());
    }
    let rows = std::fs::read_to_string(d.join("slurm/runs.csv")).unwrap();
    assert_eq!(
        rows.lines().filter(|l| l.contains(",complete,")).count(),
        4,
        "{rows}"
    );
    for i in 0..2 {
        assert!(d.join(format!("slurm/shards/{i}/runs.csv")).is_file());
    }
    drop(cluster);
    assert!(
        marked_processes(&d.join("cluster")).is_empty(),
        "processes of the cluster left behind"
    );
    let _ = std::fs::remove_dir_all(&d);
}
