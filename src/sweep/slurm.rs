//! A sweep on a Slurm cluster: one `sbatch` array whose task i runs line i of `jobs.txt`.
//!
//! Each array task asks Slurm for SIGUSR1 a while before its time limit (`--signal=B:USR1@N`,
//! delivered to the batch shell), passes it on to `locobench train`, which checkpoints at the end
//! of the episode it is in and exits (`train::stop`), and then requeues itself. The requeued task
//! runs the same job line, which continues the run directory (`--resume-if-exists`). Submitting
//! the same sweep again submits only the jobs that are neither finished nor queued.
//!
//! Files: `slurm.sh` (the array script, readable and usable by hand with `sbatch --array=...`),
//! `slurm.toml` (every submission: job id, array tasks, time).
use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::{shell_quote, Job};
use crate::io::write_bytes_atomic;
use crate::train::run_progress;

/// What the array asks of the scheduler.
#[derive(Debug, Clone, PartialEq)]
pub struct SlurmOptions {
    /// `--partition`.
    pub partition: Option<String>,
    /// `--time`, e.g. `2:00:00`.
    pub time: Option<String>,
    /// `--cpus-per-task`.
    pub cpus_per_task: u32,
    /// `--mem`, e.g. `4G`.
    pub mem: Option<String>,
    /// At most this many array tasks at once (`%N`).
    pub max_parallel: Option<u32>,
    /// Seconds before the time limit at which the task is told to checkpoint and requeue.
    pub warn_seconds: u32,
    /// Further `#SBATCH` arguments, as given (`--account=abc`, `--qos=long`).
    pub extra: Vec<String>,
}

impl Default for SlurmOptions {
    fn default() -> Self {
        SlurmOptions {
            partition: None,
            time: None,
            cpus_per_task: 1,
            mem: None,
            max_parallel: None,
            warn_seconds: 120,
            extra: Vec::new(),
        }
    }
}

/// One `sbatch` call.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Submission {
    /// The array job's id.
    pub job_id: String,
    /// Array task ids, as given to `--array` (without the `%N` throttle).
    pub tasks: String,
    /// When it was submitted (Unix seconds).
    pub submitted_unix: u64,
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
struct SubmissionLog {
    #[serde(default)]
    submissions: Vec<Submission>,
}

pub(crate) fn script_path(sweep_dir: &Path) -> PathBuf {
    sweep_dir.join("slurm.sh")
}

fn submissions_path(sweep_dir: &Path) -> PathBuf {
    sweep_dir.join("slurm.toml")
}

/// Every submission recorded for the sweep, oldest first.
pub(crate) fn submissions(sweep_dir: &Path) -> Result<Vec<Submission>> {
    let path = submissions_path(sweep_dir);
    if !path.exists() {
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let log: SubmissionLog = toml::from_str(&text).with_context(|| format!("{} is corrupt", path.display()))?;
    Ok(log.submissions)
}

fn record_submission(sweep_dir: &Path, s: Submission) -> Result<()> {
    let mut log = SubmissionLog { submissions: submissions(sweep_dir)? };
    log.submissions.push(s);
    write_bytes_atomic(&submissions_path(sweep_dir), toml::to_string(&log)?.as_bytes())
}

/// `0-3,5,7-8` for [0, 1, 2, 3, 5, 7, 8].
pub(crate) fn array_spec(indices: &[usize]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < indices.len() {
        let start = indices[i];
        let mut end = start;
        while i + 1 < indices.len() && indices[i + 1] == end + 1 {
            i += 1;
            end = indices[i];
        }
        parts.push(if start == end { start.to_string() } else { format!("{start}-{end}") });
        i += 1;
    }
    parts.join(",")
}

/// The array script. Paths are absolute so that it runs from any directory on a shared file
/// system; `jobs.txt` is read at run time, so the script's header shows what each task runs.
pub fn script(sweep_dir: &Path, jobs: &[Job], binary: &Path, workdir: &Path, opts: &SlurmOptions) -> String {
    let sweep = shell_quote(&sweep_dir.display().to_string());
    let name = sweep_dir.file_name().map_or("sweep".into(), |n| n.to_string_lossy().into_owned());
    let mut s = String::from("#!/bin/bash\n");
    let mut directive = |line: String| {
        s.push_str("#SBATCH ");
        s.push_str(&line);
        s.push('\n');
    };
    directive(format!("--job-name=locobench-{}", name.replace(char::is_whitespace, "_")));
    let throttle = opts.max_parallel.map_or(String::new(), |n| format!("%{n}"));
    directive(format!("--array=0-{}{throttle}", jobs.len().saturating_sub(1)));
    directive(format!("--chdir={}", workdir.display()));
    directive(format!("--output={}/logs/slurm-%A_%a.out", sweep_dir.display()));
    directive("--open-mode=append".into());
    directive(format!("--cpus-per-task={}", opts.cpus_per_task));
    directive(format!("--signal=B:USR1@{}", opts.warn_seconds));
    directive("--requeue".into());
    if let Some(p) = &opts.partition {
        directive(format!("--partition={p}"));
    }
    if let Some(t) = &opts.time {
        directive(format!("--time={t}"));
    }
    if let Some(m) = &opts.mem {
        directive(format!("--mem={m}"));
    }
    for a in &opts.extra {
        directive(a.clone());
    }
    let threads = opts.cpus_per_task.clamp(1, 2);
    let names: Vec<String> = jobs.iter().map(|j| shell_quote(&j.name)).collect();
    s.push_str(&format!(
        r#"
# A locobench sweep as a Slurm array: task i runs line i+1 of jobs.txt (`locobench sweep --slurm`
# wrote this file; it submits it as `sbatch --parsable --array=<unfinished tasks>%N slurm.sh`).
# Shortly before the time limit Slurm sends SIGUSR1 to this script, which passes it on:
# `locobench train` checkpoints at the end of its current episode and exits, and the task requeues
# itself. A requeued or resubmitted task continues its run directory (--resume-if-exists); a
# finished run is left alone.
set -uo pipefail
sweep={sweep}
bin={bin}
names=({names})
task=${{SLURM_ARRAY_TASK_ID:?submit with sbatch --array, see above}}
name=${{names[$task]:?no job $task in this sweep}}
line=$(sed -n "$((task + 1))p" "$sweep/jobs.txt")
[ -n "$line" ] || {{ echo "jobs.txt has no line $((task + 1))" >&2; exit 2; }}
eval "set -- $line"
shift # the program name; $bin is used instead
log="$sweep/logs/$name.log"
exit_file="$sweep/logs/$name.exit"
mkdir -p "$sweep/logs"
rm -f "$exit_file"
echo "== slurm job ${{SLURM_ARRAY_JOB_ID:-?}}_$task on $(hostname), restart ${{SLURM_RESTART_COUNT:-0}}, $(date -Is)" >>"$log"
"$bin" "$@" --threads {threads} >>"$log" 2>&1 &
child=$!
warned=0
trap 'warned=1; kill -USR1 "$child" 2>/dev/null' USR1
trap 'kill -TERM "$child" 2>/dev/null' TERM
while :; do
  wait "$child"
  status=$?
  # wait returns above 128 when a trapped signal interrupts it while the child still runs
  if [ "$status" -gt 128 ] && kill -0 "$child" 2>/dev/null; then continue; fi
  break
done
echo "$status" >"$exit_file"
if [ "$warned" = 1 ] && [ "$status" = 0 ]; then
  echo "== time limit near: checkpointed; requeueing ${{SLURM_ARRAY_JOB_ID:-?}}_$task" >>"$log"
  scontrol requeue "${{SLURM_ARRAY_JOB_ID}}_$task"
fi
exit "$status"
"#,
        bin = shell_quote(&binary.display().to_string()),
        names = names.join(" "),
    ));
    s
}

/// `program` found on `PATH`, if it is there.
pub(crate) fn on_path(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path).map(|d| d.join(program)).find(|p| p.is_file())
}

/// Array task index -> scheduler state (`PENDING`, `RUNNING`, ...), for every recorded
/// submission the scheduler still knows (squeue), then from accounting (sacct) where the
/// cluster keeps it. Later submissions win. Errors of the two commands (unknown job ids after
/// they leave the queue, accounting disabled) leave tasks out rather than failing.
pub(crate) fn task_states(sweep_dir: &Path) -> Result<Vec<(usize, TaskState)>> {
    let mut out: Vec<(usize, TaskState)> = Vec::new();
    for sub in submissions(sweep_dir)? {
        let mut states = sacct_states(&sub.job_id);
        // squeue is authoritative for what is still queued or running
        for (task, state) in squeue_states(&sub.job_id) {
            states.retain(|(t, _)| *t != task);
            states.push((task, state));
        }
        for (task, state) in states {
            out.retain(|(t, _)| *t != task);
            out.push((task, TaskState { job_id: format!("{}_{task}", sub.job_id), state }));
        }
    }
    Ok(out)
}

/// One array task as Slurm reports it (`squeue`/`sacct`).
#[derive(Debug, Clone, PartialEq)]
pub struct TaskState {
    /// `<array job id>_<task>`.
    pub job_id: String,
    /// Slurm's state name (`PENDING`, `RUNNING`, `COMPLETED`, ...).
    pub state: String,
}

fn command_lines(program: &str, args: &[&str]) -> Vec<String> {
    match Command::new(program).args(args).output() {
        Ok(o) if o.status.success() => String::from_utf8_lossy(&o.stdout).lines().map(str::to_string).collect(),
        _ => Vec::new(),
    }
}

/// Splits `123_4|RUNNING` into (4, RUNNING); array ranges such as `123_[5-7]` expand.
fn parse_task_line(line: &str, job_id: &str) -> Vec<(usize, String)> {
    let mut fields = line.split('|');
    let (Some(id), Some(state)) = (fields.next(), fields.next()) else { return Vec::new() };
    let Some(task) = id.trim().strip_prefix(&format!("{job_id}_")) else { return Vec::new() };
    // sacct writes `CANCELLED by 0`; keep the first word
    let state = state.split_whitespace().next().unwrap_or("").to_string();
    let task = task.trim_start_matches('[').trim_end_matches(']');
    let task = task.split('%').next().unwrap_or("");
    let mut out = Vec::new();
    for part in task.split(',') {
        match part.split_once('-') {
            Some((a, b)) => {
                if let (Ok(a), Ok(b)) = (a.parse::<usize>(), b.parse::<usize>()) {
                    out.extend((a..=b).map(|t| (t, state.clone())));
                }
            }
            None => {
                if let Ok(t) = part.parse() {
                    out.push((t, state.clone()));
                }
            }
        }
    }
    out
}

fn squeue_states(job_id: &str) -> Vec<(usize, String)> {
    command_lines("squeue", &["-h", "-r", "-t", "all", "-j", job_id, "-o", "%i|%T"])
        .iter()
        .flat_map(|l| parse_task_line(l, job_id))
        .collect()
}

fn sacct_states(job_id: &str) -> Vec<(usize, String)> {
    command_lines("sacct", &["-n", "-P", "-X", "-j", job_id, "-o", "JobID,State"])
        .iter()
        .flat_map(|l| parse_task_line(l, job_id))
        .collect()
}

/// Scheduler states of a task that runs now.
pub(crate) fn is_running(state: &str) -> bool {
    matches!(state, "RUNNING" | "COMPLETING" | "CONFIGURING" | "SIGNALING" | "STAGE_OUT")
}

/// Scheduler states of a task that will still run or runs now.
pub(crate) fn is_active(state: &str) -> bool {
    is_running(state)
        || matches!(state, "PENDING" | "REQUEUED" | "REQUEUE_HOLD" | "REQUEUE_FED" | "RESIZING" | "SUSPENDED")
}

/// Scheduler states that end a task without finishing its run.
pub(crate) fn is_failure(state: &str) -> bool {
    matches!(
        state,
        "FAILED" | "TIMEOUT" | "NODE_FAIL" | "OUT_OF_MEMORY" | "CANCELLED" | "BOOT_FAIL" | "DEADLINE" | "PREEMPTED"
    )
}

/// What `submit` did.
#[derive(Debug, Clone, PartialEq)]
pub enum Submitted {
    /// The script was written; nothing was submitted (`--dry-run`).
    DryRun {
        /// The script written.
        script: PathBuf,
        /// Array task ids it would submit.
        tasks: Vec<usize>,
    },
    /// Every job is finished or already queued.
    Nothing {
        /// Jobs already finished.
        finished: usize,
        /// Jobs already queued or running.
        queued: usize,
    },
    /// An array was submitted.
    Submitted {
        /// The script submitted.
        script: PathBuf,
        /// What `sbatch` returned.
        submission: Submission,
    },
}

/// Writes `slurm.sh` and submits the jobs that are neither finished nor queued. The sweep
/// directory stays consistent whatever fails: the script and plan are written first, and a
/// submission is recorded only once sbatch accepted it, so the same command can be run again.
pub fn submit(sweep_dir: &Path, jobs: &[Job], opts: &SlurmOptions, binary: &Path, dry_run: bool) -> Result<Submitted> {
    anyhow::ensure!(opts.cpus_per_task >= 1, "--cpus-per-task must be at least 1");
    anyhow::ensure!(opts.max_parallel != Some(0), "--max-parallel must be at least 1");
    let sweep_dir = std::path::absolute(sweep_dir)?;
    let workdir = std::env::current_dir()?;
    let binary = std::path::absolute(binary)?;
    std::fs::create_dir_all(sweep_dir.join("logs"))?;
    let script_file = script_path(&sweep_dir);
    write_bytes_atomic(&script_file, script(&sweep_dir, jobs, &binary, &workdir, opts).as_bytes())?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&script_file, std::fs::Permissions::from_mode(0o755))?;
    }

    let queued: Vec<usize> = if dry_run {
        Vec::new()
    } else {
        task_states(&sweep_dir)?.into_iter().filter(|(_, s)| is_active(&s.state)).map(|(t, _)| t).collect()
    };
    let mut finished = 0;
    let mut tasks = Vec::new();
    for (i, job) in jobs.iter().enumerate() {
        let run_dir = if job.run_dir.is_absolute() { job.run_dir.clone() } else { workdir.join(&job.run_dir) };
        if run_progress(&run_dir).is_ok_and(|p| p.finished()) {
            finished += 1;
        } else if !queued.contains(&i) {
            tasks.push(i);
        }
    }
    if dry_run {
        return Ok(Submitted::DryRun { script: script_file, tasks });
    }
    if tasks.is_empty() {
        return Ok(Submitted::Nothing { finished, queued: queued.len() });
    }
    let Some(sbatch) = on_path("sbatch") else {
        bail!(
            "--slurm needs Slurm's `sbatch` on the PATH, and there is none here. Nothing was submitted; {} is \
             written, so run the same command again on a machine with Slurm (or submit it by hand: sbatch --array={} {})",
            script_file.display(),
            array_spec(&tasks),
            script_file.display()
        );
    };
    let array = array_spec(&tasks);
    let throttle = opts.max_parallel.map_or(String::new(), |n| format!("%{n}"));
    let out = Command::new(&sbatch)
        .arg("--parsable")
        .arg(format!("--array={array}{throttle}"))
        .arg(&script_file)
        .current_dir(&workdir)
        .output()
        .with_context(|| format!("running {}", sbatch.display()))?;
    let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
    if !out.status.success() {
        bail!(
            "sbatch rejected the sweep ({}): {stderr}. Nothing was submitted; fix the cause (partition, time, \
             account, ...) and run the same command again",
            out.status
        );
    }
    let stdout = String::from_utf8_lossy(&out.stdout);
    let job_id = stdout.trim().split(';').next().unwrap_or("").trim().to_string();
    anyhow::ensure!(
        !job_id.is_empty() && job_id.chars().all(|c| c.is_ascii_digit()),
        "sbatch accepted the sweep but printed no job id ({stdout:?} {stderr:?}); check squeue before submitting again"
    );
    let submission = Submission {
        job_id,
        tasks: array,
        submitted_unix: std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()),
    };
    record_submission(&sweep_dir, submission.clone())?;
    Ok(Submitted::Submitted { script: script_file, submission })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_specs_compress_runs() {
        assert_eq!(array_spec(&[0, 1, 2, 3, 5, 7, 8]), "0-3,5,7-8");
        assert_eq!(array_spec(&[4]), "4");
        assert_eq!(array_spec(&[]), "");
    }

    #[test]
    fn queue_lines_parse_tasks_and_ranges() {
        assert_eq!(parse_task_line("123_4|RUNNING", "123"), vec![(4, "RUNNING".to_string())]);
        assert_eq!(
            parse_task_line("123_[5-7%2]|PENDING", "123"),
            vec![(5, "PENDING".into()), (6, "PENDING".into()), (7, "PENDING".into())]
        );
        assert_eq!(parse_task_line("123_2|CANCELLED by 0", "123"), vec![(2, "CANCELLED".to_string())]);
        assert!(parse_task_line("1234_2|RUNNING", "123").is_empty());
        assert!(parse_task_line("garbage", "123").is_empty());
    }

    #[test]
    fn the_script_carries_every_setting_and_the_requeue_path() {
        let spec = super::super::SweepSpec {
            env: "inverted-pendulum".into(),
            algos: vec!["td3".into()],
            grid: vec![],
            seeds: vec![0, 1],
            steps: Some(100),
            set: vec![],
            options: vec![],
            tensorboard: false,
            device: crate::device::ComputeDevice::Cpu,
        };
        let jobs = super::super::jobs(&spec, Path::new("/s/sw")).unwrap();
        let opts = SlurmOptions {
            partition: Some("cpu".into()),
            time: Some("1:00:00".into()),
            cpus_per_task: 2,
            mem: Some("4G".into()),
            max_parallel: Some(3),
            warn_seconds: 90,
            extra: vec!["--account=lab".into()],
        };
        let s = script(Path::new("/s/sw"), &jobs, Path::new("/opt/locobench"), Path::new("/s"), &opts);
        for needle in [
            "#SBATCH --array=0-1%3",
            "#SBATCH --partition=cpu",
            "#SBATCH --time=1:00:00",
            "#SBATCH --cpus-per-task=2",
            "#SBATCH --mem=4G",
            "#SBATCH --signal=B:USR1@90",
            "#SBATCH --requeue",
            "#SBATCH --account=lab",
            "#SBATCH --chdir=/s",
            "names=(td3-seed0 td3-seed1)",
            "--threads 2",
            "scontrol requeue",
        ] {
            assert!(s.contains(needle), "{needle} missing:\n{s}");
        }
    }
}
