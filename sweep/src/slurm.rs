//! A Slurm submission script for a sweep: one job array whose task `I` runs share `I/N`
//! (`almc sweep run --shard I/N`) into `OUT/shards/I`, then one merge job, dependent on the
//! whole array (`afterany`, so it also reports what failed), that joins the shares into `OUT`.
//! Every path in the script is absolute and must be the same on every node (a shared
//! filesystem), as Slurm clusters have.

use std::fmt::Write as _;
use std::path::PathBuf;

/// What the script runs.
#[derive(Debug, Clone)]
pub struct SlurmConfig {
    /// The `almc` program.
    pub almc: PathBuf,
    /// The sweep file.
    pub sweep_file: PathBuf,
    /// The sweep's name (job names).
    pub name: String,
    /// The merged output directory; shares go to `OUT/shards/I`, logs to `OUT/slurm/`.
    pub out: PathBuf,
    /// Number of shares (array tasks).
    pub shards: usize,
    /// The firmware ELF.
    pub firmware: PathBuf,
    /// CPUs of each array task (its workers).
    pub cpus_per_task: usize,
    /// `--time` of each array task, if any.
    pub time: Option<String>,
    /// More `sbatch` options for both jobs (`--partition=...`, `--account=...`).
    pub sbatch_args: Vec<String>,
}

/// `s` quoted for a POSIX shell.
pub fn quote(s: &str) -> String {
    if !s.is_empty()
        && s.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"/._-+=:,%@".contains(&b))
    {
        return s.to_owned();
    }
    format!("'{}'", s.replace('\'', r"'\''"))
}

fn q(p: &std::path::Path) -> String {
    quote(&p.to_string_lossy())
}

/// The submission script (bash). Running it submits both jobs and prints their IDs as
/// `array job <ID>` and `merge job <ID>` lines.
pub fn script(c: &SlurmConfig) -> String {
    let n = c.shards.max(1);
    let out = c.out.to_string_lossy();
    let shard_dir = |i: &str| quote(&format!("{out}/shards/{i}"));
    let extra: String = c
        .sbatch_args
        .iter()
        .map(|a| format!(" {}", quote(a)))
        .collect();
    let time = c
        .time
        .as_ref()
        .map(|t| format!(" --time={}", quote(t)))
        .unwrap_or_default();
    let name = quote(&format!("sweep-{}", c.name));
    let merge_name = quote(&format!("sweep-{}-merge", c.name));
    let mut s = String::new();
    let _ = writeln!(s, "#!/bin/bash");
    let _ = writeln!(
        s,
        "# Sweep {} ({}) on Slurm: {n} array tasks, task I running share I/{n} into\n\
         # {out}/shards/I, then a merge job into {out} once every task has ended.\n\
         # Written by `almc sweep slurm`; submit with `bash THIS_FILE` on a submit host. Every\n\
         # path must be the same on the compute nodes (a shared filesystem).",
        c.name,
        c.sweep_file.display(),
    );
    let _ = writeln!(s, "set -euo pipefail");
    let _ = writeln!(s, "mkdir -p {}", quote(&format!("{out}/slurm")));
    let _ = writeln!(
        s,
        "array=$(sbatch --parsable --job-name={name} --array=0-{} --cpus-per-task={}{time}{extra} \\\n    --output={} <<'JOB'",
        n - 1,
        c.cpus_per_task.max(1),
        quote(&format!("{out}/slurm/shard-%a.log")),
    );
    let _ = writeln!(s, "#!/bin/bash");
    let _ = writeln!(
        s,
        "exec {} sweep run {} --shard \"$SLURM_ARRAY_TASK_ID/{n}\" --workers \"${{SLURM_CPUS_PER_TASK:-1}}\" \\\n    --firmware {} --out {}\"/$SLURM_ARRAY_TASK_ID\"",
        q(&c.almc),
        q(&c.sweep_file),
        q(&c.firmware),
        quote(&format!("{out}/shards")),
    );
    let _ = writeln!(s, "JOB\n)");
    let _ = writeln!(s, "array=${{array%%;*}}");
    let shards: Vec<String> = (0..n).map(|i| shard_dir(&i.to_string())).collect();
    let _ = writeln!(
        s,
        "merge=$(sbatch --parsable --job-name={merge_name} --dependency=afterany:\"$array\"{extra} \\\n    --output={} <<'JOB'",
        quote(&format!("{out}/slurm/merge.log")),
    );
    let _ = writeln!(s, "#!/bin/bash");
    let _ = writeln!(
        s,
        "exec {} sweep merge {} --into {}",
        q(&c.almc),
        shards.join(" "),
        quote(&out),
    );
    let _ = writeln!(s, "JOB\n)");
    let _ = writeln!(s, "merge=${{merge%%;*}}");
    let _ = writeln!(s, "echo \"array job $array\"");
    let _ = writeln!(s, "echo \"merge job $merge\"");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quotes_only_when_needed() {
        assert_eq!(quote("/a/b-c_d.toml"), "/a/b-c_d.toml");
        assert_eq!(quote("a b"), "'a b'");
        assert_eq!(quote("it's"), r"'it'\''s'");
        assert_eq!(quote(""), "''");
    }

    #[test]
    fn script_has_the_array_the_shards_and_the_merge() {
        let s = script(&SlurmConfig {
            almc: "/opt/almc".into(),
            sweep_file: "/w/s.toml".into(),
            name: "loss".into(),
            out: "/w/out dir".into(),
            shards: 3,
            firmware: "/w/fw.elf".into(),
            cpus_per_task: 2,
            time: Some("00:30:00".into()),
            sbatch_args: vec!["--partition=short".into()],
        });
        assert!(s.contains("--array=0-2 --cpus-per-task=2 --time=00:30:00 --partition=short"));
        assert!(s.contains("--shard \"$SLURM_ARRAY_TASK_ID/3\""));
        assert!(s.contains("--dependency=afterany:\"$array\""));
        assert!(s.contains(
            "sweep merge '/w/out dir/shards/0' '/w/out dir/shards/1' '/w/out dir/shards/2' --into '/w/out dir'"
        ));
        assert!(s.contains("--out '/w/out dir/shards'\"/$SLURM_ARRAY_TASK_ID\""));
    }
}
