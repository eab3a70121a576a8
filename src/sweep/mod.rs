//! Sweeps: a grid of reward weights (or hyperparameters, or env options) x algorithms x seeds,
//! each job a plain `locobench train` command line, run as separate processes a few at a time.
//!
//! Layout of a sweep directory: `sweep.toml` (what was asked), `jobs.txt` (one self-contained
//! command per line, for a cluster scheduler), `runs/<job>/` (run directories), `logs/<job>.log`
//! and `logs/<job>.exit` (the exit status of the job's last process). On Slurm (`slurm.rs`) also
//! `slurm.sh` (the array script) and `slurm.toml` (the submissions). Every job line carries
//! `--resume-if-exists`, so running it again (the same sweep again, a requeued array task, a
//! resubmission) continues a stopped run and leaves a finished one alone.
pub mod slurm;
pub mod status;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use crate::args::{EnvOptionArgs, SeedArg, TrainArgs};
use crate::io::write_bytes_atomic;

/// One axis of the grid: a reward term (e.g. `drift`), `set.<hyperparameter>` or
/// `option.<env option>`, with its values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Axis {
    /// The reward term, `set.<hyperparameter>` or `option.<env option>`.
    pub key: String,
    /// The values it takes.
    pub values: Vec<f64>,
}

/// Parses `drift=0:1:0.125` (start:end:step, end included) or `drift=0,0.5,1`.
pub fn parse_axis(spec: &str) -> Result<Axis> {
    let (key, values) = spec.split_once('=').with_context(|| format!("grid axis '{spec}' is not KEY=VALUES"))?;
    let key = key.trim();
    if key.is_empty() {
        bail!("grid axis '{spec}' has no key");
    }
    let number = |s: &str| -> Result<f64> {
        let v: f64 = s.trim().parse().with_context(|| format!("grid axis '{spec}': '{s}' is not a number"))?;
        anyhow::ensure!(v.is_finite(), "grid axis '{spec}': values must be finite");
        Ok(v)
    };
    let values = if values.contains(':') {
        let parts: Vec<&str> = values.split(':').collect();
        let [start, end, step] = parts[..] else { bail!("grid axis '{spec}': a range is START:END:STEP") };
        let (start, end, step) = (number(start)?, number(end)?, number(step)?);
        anyhow::ensure!(step > 0.0 && end >= start, "grid axis '{spec}': need STEP > 0 and END >= START");
        let n = ((end - start) / step + 1e-9).floor() as usize;
        anyhow::ensure!(n < 10_000, "grid axis '{spec}' has too many values");
        // Rounded so 0.1 steps print as 0.3, not 0.30000000000000004.
        (0..=n).map(|k| ((start + k as f64 * step) * 1e9).round() / 1e9).collect()
    } else {
        values.split(',').map(number).collect::<Result<Vec<f64>>>()?
    };
    anyhow::ensure!(!values.is_empty(), "grid axis '{spec}' has no values");
    Ok(Axis { key: key.to_string(), values })
}

/// What a sweep runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SweepSpec {
    /// The env every job trains on.
    pub env: String,
    /// Algorithms, by registered name.
    pub algos: Vec<String>,
    /// The grid's axes; jobs cover their product.
    pub grid: Vec<Axis>,
    /// Training seeds per grid point and algorithm.
    pub seeds: Vec<u64>,
    /// Total steps per run (None: the preset's).
    pub steps: Option<u64>,
    /// Extra `--set` and `--option` arguments given to every job.
    pub set: Vec<String>,
    /// Extra `--option` arguments given to every job.
    pub options: Vec<String>,
    /// Every job writes TensorBoard event files into `tensorboard/<job>/` of the sweep
    /// directory, so `tensorboard --logdir SWEEP/tensorboard` shows the runs side by side.
    #[serde(default)]
    pub tensorboard: bool,
    /// Where every job trains (`train --device`); sweeps written before this key train on the CPU.
    #[serde(default)]
    pub device: crate::device::ComputeDevice,
}

/// One training run of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// Unique name, also its run directory's name.
    pub name: String,
    /// Where the run writes.
    pub run_dir: PathBuf,
    /// Arguments after the program name, for a new run.
    pub args: Vec<String>,
}

impl Job {
    /// The command line as a shell would take it (program `locobench`).
    pub(crate) fn command_line(&self) -> String {
        std::iter::once("locobench".to_string())
            .chain(self.args.iter().map(|a| shell_quote(a)))
            .collect::<Vec<_>>()
            .join(" ")
    }
}

pub(crate) fn shell_quote(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=,:+".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// Every combination of grid values x algorithms x seeds, in a stable order.
pub fn jobs(spec: &SweepSpec, sweep_dir: &Path) -> Result<Vec<Job>> {
    anyhow::ensure!(!spec.algos.is_empty() && !spec.seeds.is_empty(), "a sweep needs an algorithm and a seed");
    let mut points: Vec<Vec<(String, f64)>> = vec![Vec::new()];
    for axis in &spec.grid {
        points = points
            .into_iter()
            .flat_map(|p| {
                axis.values.iter().map(move |&v| {
                    let mut q = p.clone();
                    q.push((axis.key.clone(), v));
                    q
                })
            })
            .collect();
    }
    let mut out = Vec::new();
    for point in &points {
        for algo in &spec.algos {
            for &seed in &spec.seeds {
                let tag: String =
                    point.iter().map(|(k, v)| format!("-{}{v}", k.rsplit('.').next().unwrap_or(k))).collect();
                let name = format!("{algo}{tag}-seed{seed}");
                let run_dir = sweep_dir.join("runs").join(&name);
                let (mut rewards, mut set, mut options) = (Vec::new(), spec.set.clone(), spec.options.clone());
                for (k, v) in point {
                    if let Some(h) = k.strip_prefix("set.") {
                        set.push(format!("{h}={v}"));
                    } else if let Some(o) = k.strip_prefix("option.") {
                        options.push(format!("{o}={v}"));
                    } else {
                        rewards.push(format!("{k}={v}"));
                    }
                }
                let train = TrainArgs {
                    env: Some(spec.env.clone()),
                    algo: Some(algo.clone()),
                    seed: SeedArg { seed },
                    steps: spec.steps,
                    set,
                    env_options: EnvOptionArgs {
                        env_config: None,
                        options,
                        reward: (!rewards.is_empty()).then(|| rewards.join(",")),
                    },
                    out: Some(run_dir.clone()),
                    tensorboard: spec.tensorboard.then(|| sweep_dir.join("tensorboard").join(&name)),
                    resume_if_exists: true,
                    quiet: true,
                    device: spec.device,
                    ..TrainArgs::default()
                };
                let args = train.to_args();
                out.push(Job { name, run_dir, args });
            }
        }
    }
    Ok(out)
}

/// Writes `sweep.toml` and `jobs.txt`. A directory that holds another sweep is refused: its
/// job numbers (lines of jobs.txt) would no longer mean the same runs.
pub fn write_plan(spec: &SweepSpec, sweep_dir: &Path, jobs: &[Job]) -> Result<()> {
    if let Ok(existing) = read_spec(sweep_dir) {
        anyhow::ensure!(
            existing == *spec,
            "{} holds another sweep (its sweep.toml differs from this command's grid, algorithms, seeds, steps, \
             --set or --option); choose another --out",
            sweep_dir.display()
        );
    }
    std::fs::create_dir_all(sweep_dir).with_context(|| format!("creating {}", sweep_dir.display()))?;
    write_bytes_atomic(&sweep_dir.join("sweep.toml"), toml::to_string(spec)?.as_bytes())?;
    let lines: String = jobs.iter().map(|j| j.command_line() + "\n").collect();
    write_bytes_atomic(&sweep_dir.join("jobs.txt"), lines.as_bytes())
}

/// The `sweep.toml` of a sweep directory.
pub(crate) fn read_spec(sweep_dir: &Path) -> Result<SweepSpec> {
    let path = sweep_dir.join("sweep.toml");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("{} is not a sweep directory (no sweep.toml)", sweep_dir.display()))?;
    toml::from_str(&text).with_context(|| format!("{} is corrupt", path.display()))
}

/// The plan of an existing sweep directory: its spec and jobs, in jobs.txt order.
pub(crate) fn read_plan(sweep_dir: &Path) -> Result<(SweepSpec, Vec<Job>)> {
    let spec = read_spec(sweep_dir)?;
    let jobs = jobs(&spec, sweep_dir)?;
    Ok((spec, jobs))
}

/// Where a job writes its output and, once its process ended, its exit status.
pub(crate) fn log_path(sweep_dir: &Path, job: &Job) -> PathBuf {
    sweep_dir.join("logs").join(format!("{}.log", job.name))
}

pub(crate) fn exit_path(sweep_dir: &Path, job: &Job) -> PathBuf {
    sweep_dir.join("logs").join(format!("{}.exit", job.name))
}

/// How one locally run job ended.
#[derive(Debug, Clone, PartialEq)]
pub struct JobOutcome {
    /// The job's name.
    pub name: String,
    /// Exited with status 0.
    pub ok: bool,
    /// Wall time (s).
    pub seconds: f64,
    /// Its log file.
    pub log: PathBuf,
}

/// Runs the jobs with `binary`, `parallel` at a time. A job whose run directory already holds
/// its run continues it (a finished run is left alone). `on_done` sees each outcome.
pub fn run_jobs(
    binary: &Path,
    jobs: &[Job],
    sweep_dir: &Path,
    parallel: usize,
    on_done: &(dyn Fn(&JobOutcome) + Sync),
) -> Result<Vec<JobOutcome>> {
    let logs = sweep_dir.join("logs");
    std::fs::create_dir_all(&logs)?;
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<JobOutcome>>> = Mutex::new(vec![None; jobs.len()]);
    std::thread::scope(|scope| {
        for _ in 0..parallel.max(1).min(jobs.len().max(1)) {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                let Some(job) = jobs.get(i) else { break };
                let log = log_path(sweep_dir, job);
                let exit = exit_path(sweep_dir, job);
                let _ = std::fs::remove_file(&exit);
                let started = std::time::Instant::now();
                let mut args = job.args.clone();
                if parallel > 1 {
                    // the cores go to the parallel jobs, not to helper threads
                    args.extend(["--threads".into(), "1".into()]);
                }
                let status = std::fs::File::create(&log).and_then(|f| {
                    let err = f.try_clone()?;
                    Command::new(binary).args(&args).stdin(Stdio::null()).stdout(f).stderr(err).status()
                });
                let code = status.as_ref().ok().and_then(|s| s.code()).unwrap_or(-1);
                let _ = write_bytes_atomic(&exit, format!("{code}\n").as_bytes());
                let ok = code == 0;
                let outcome = JobOutcome { name: job.name.clone(), ok, seconds: started.elapsed().as_secs_f64(), log };
                on_done(&outcome);
                results.lock().unwrap()[i] = Some(outcome);
            });
        }
    });
    Ok(results.into_inner().unwrap().into_iter().flatten().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_parse_ranges_and_lists() {
        assert_eq!(parse_axis("drift=0:1:0.25").unwrap().values, vec![0.0, 0.25, 0.5, 0.75, 1.0]);
        assert_eq!(parse_axis("x=0:0.3:0.1").unwrap().values, vec![0.0, 0.1, 0.2, 0.3]);
        assert_eq!(parse_axis("set.tau=0.005,0.01").unwrap().values, vec![0.005, 0.01]);
        for bad in ["drift", "=1", "drift=a", "drift=1:0:0.1", "drift=0:1:0", "drift=0:1", "drift=nan"] {
            assert!(parse_axis(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn jobs_are_the_full_product_with_self_contained_command_lines() {
        let spec = SweepSpec {
            env: "minitaur".into(),
            algos: vec!["sac".into(), "td3".into()],
            grid: vec![parse_axis("drift=0:1:0.5").unwrap(), parse_axis("set.tau=0.01").unwrap()],
            seeds: vec![0, 1],
            steps: Some(1000),
            set: vec!["hidden=[64,64]".into()],
            options: vec![],
            tensorboard: false,
            device: crate::device::ComputeDevice::Cpu,
        };
        let jobs = jobs(&spec, Path::new("sw")).unwrap();
        assert_eq!(jobs.len(), 3 * 2 * 2);
        let j = &jobs[0];
        assert_eq!(j.name, "sac-drift0-tau0.01-seed0");
        assert_eq!(
            j.command_line(),
            "locobench train --env minitaur --algo sac --seed 0 --steps 1000 --reward drift=0 \
             --set 'hidden=[64,64]' --set tau=0.01 --out sw/runs/sac-drift0-tau0.01-seed0 --resume-if-exists --quiet"
        );
        let names: std::collections::BTreeSet<_> = jobs.iter().map(|j| j.name.clone()).collect();
        assert_eq!(names.len(), jobs.len(), "names are unique");
        // Every line is a train command that parses back to its job.
        for job in &jobs {
            let train = TrainArgs::parse_from(&job.args).unwrap();
            assert_eq!(train.to_args(), job.args);
            assert_eq!(train.out.as_deref(), Some(job.run_dir.as_path()));
            assert!(train.resume_if_exists && train.quiet);
            assert_eq!(train.tensorboard, None);
        }
        // With --tensorboard, each job logs into its own directory under the sweep's.
        let logged = jobs_of(&SweepSpec { tensorboard: true, ..spec.clone() });
        for job in &logged {
            let train = TrainArgs::parse_from(&job.args).unwrap();
            assert_eq!(train.tensorboard, Some(Path::new("sw/tensorboard").join(&job.name)));
        }
        // With --device, each job trains there.
        for job in jobs_of(&SweepSpec { device: crate::device::ComputeDevice::Cuda(0), ..spec.clone() }) {
            assert_eq!(TrainArgs::parse_from(&job.args).unwrap().device, crate::device::ComputeDevice::Cuda(0));
        }
    }

    fn jobs_of(spec: &SweepSpec) -> Vec<Job> {
        jobs(spec, Path::new("sw")).unwrap()
    }
}
