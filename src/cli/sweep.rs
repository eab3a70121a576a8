use std::path::PathBuf;

use anyhow::{Context, Result};
use locobench::agents::Algo;
use locobench::sweep::slurm::{submit, SlurmOptions, Submitted};
use locobench::sweep::status::{render, sweep_status};
use locobench::sweep::{jobs, parse_axis, run_jobs, write_plan, SweepSpec};

#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct SweepArgs {
    #[command(subcommand)]
    pub command: Option<SweepCommand>,
    #[arg(long, required = true)]
    pub env: Option<String>,
    /// Algorithms, comma-separated: `--algo sac,td3`.
    #[arg(long, value_delimiter = ',', required = true)]
    pub algo: Vec<String>,
    /// A grid axis, repeatable: a reward term (`drift=0:1:0.125`), a hyperparameter
    /// (`set.tau=0.005,0.01`) or an env option (`option.max_episode_steps=500,1000`).
    #[arg(long)]
    pub grid: Vec<String>,
    /// Number of seeds per grid point (seeds 0..N-1, offset by --first-seed).
    #[arg(long, default_value_t = 3)]
    pub seeds: u64,
    #[arg(long, default_value_t = 0)]
    pub first_seed: u64,
    /// Jobs run at once on this machine (each is one single-threaded process).
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// Total steps per run (default: the preset's).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Hyperparameters for every job, as `locobench train --set`.
    #[arg(long = "set", value_name = "KEY=VALUE,...")]
    pub set: Vec<String>,
    /// Env options for every job (file, `--option`, `--reward`), as `locobench train` takes
    /// them; each job gets them as `--option` pairs.
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
    /// The sweep directory.
    #[arg(long, required = true)]
    pub out: Option<PathBuf>,
    /// Only write the plan (sweep.toml, jobs.txt; with --slurm also slurm.sh), run nothing.
    #[arg(long)]
    pub dry_run: bool,
    /// Every job writes TensorBoard event files into SWEEP/tensorboard/<job>/
    /// (`tensorboard --logdir SWEEP/tensorboard`).
    #[arg(long)]
    pub tensorboard: bool,
    /// Where every job trains: cpu, or cuda / cuda:N (`train --device`; jobs side by side share
    /// the GPU).
    #[arg(long, default_value = "cpu", value_name = "cpu|cuda[:N]")]
    pub device: locobench::device::ComputeDevice,
    #[command(flatten)]
    pub slurm: SlurmArgs,
}

/// Handing the jobs to a Slurm cluster instead of running them here.
#[derive(clap::Args, Debug)]
pub struct SlurmArgs {
    /// Submit the jobs as one `sbatch` array (one task per job) and return.
    #[arg(long)]
    pub slurm: bool,
    #[arg(long, requires = "slurm")]
    pub partition: Option<String>,
    /// Time limit per task, as sbatch takes it (`4:00:00`). Runs that need longer checkpoint
    /// before the limit and requeue themselves.
    #[arg(long, requires = "slurm")]
    pub time: Option<String>,
    /// CPUs per task; 2 or more gives each training its helper thread (`train --threads 2`).
    #[arg(long, default_value_t = 1, requires = "slurm")]
    pub cpus_per_task: u32,
    /// Memory per task, as sbatch takes it (`4G`).
    #[arg(long, requires = "slurm")]
    pub mem: Option<String>,
    /// At most this many tasks at once (the array's `%N`).
    #[arg(long, requires = "slurm")]
    pub max_parallel: Option<u32>,
    /// Seconds before the time limit at which a task checkpoints and requeues.
    #[arg(long, default_value_t = 120, requires = "slurm")]
    pub warn_seconds: u32,
    /// Any further sbatch option, repeatable: `--sbatch-arg=--account=lab`.
    #[arg(long = "sbatch-arg", value_name = "ARG", allow_hyphen_values = true, requires = "slurm")]
    pub sbatch_args: Vec<String>,
}

impl SlurmArgs {
    pub fn options(&self) -> SlurmOptions {
        SlurmOptions {
            partition: self.partition.clone(),
            time: self.time.clone(),
            cpus_per_task: self.cpus_per_task,
            mem: self.mem.clone(),
            max_parallel: self.max_parallel,
            warn_seconds: self.warn_seconds,
            extra: self.sbatch_args.clone(),
        }
    }
}

#[derive(clap::Subcommand, Debug)]
pub enum SweepCommand {
    /// Where each job stands: finished, running, pending, stopped or failed, its steps, the
    /// scheduler's state for Slurm sweeps, and the last log lines of failed jobs.
    Status {
        /// The sweep directory.
        dir: PathBuf,
    },
}

pub fn run(args: SweepArgs) -> Result<()> {
    if let Some(SweepCommand::Status { dir }) = &args.command {
        print!("{}", render(&sweep_status(dir)?));
        return Ok(());
    }
    let env = args.env.clone().expect("clap requires --env");
    let out = args.out.clone().expect("clap requires --out");
    for a in &args.algo {
        Algo::parse(a)?;
    }
    locobench::envs::EnvConfig::new(&env).resolved_options()?;
    let env_name = env.clone();
    let spec = SweepSpec {
        env,
        algos: args.algo.clone(),
        grid: args.grid.iter().map(|g| parse_axis(g)).collect::<Result<_>>()?,
        seeds: (args.first_seed..args.first_seed + args.seeds).collect(),
        steps: args.steps,
        set: args.set.clone(),
        options: args.env_options.pairs(&env_name)?.into_iter().map(|(k, v)| format!("{k}={v}")).collect(),
        tensorboard: args.tensorboard,
        device: args.device,
    };
    let jobs = jobs(&spec, &out)?;
    write_plan(&spec, &out, &jobs)?;
    println!("{} jobs; commands in {}", jobs.len(), out.join("jobs.txt").display());
    let binary = std::env::current_exe().context("finding the locobench binary")?;
    if args.slurm.slurm {
        match submit(&out, &jobs, &args.slurm.options(), &binary, args.dry_run)? {
            Submitted::DryRun { script, tasks } => println!(
                "wrote {}; would submit {} of {} jobs (dry run: nothing submitted)",
                script.display(),
                tasks.len(),
                jobs.len()
            ),
            Submitted::Nothing { finished, queued } => {
                println!("nothing to submit: {finished} jobs finished, {queued} queued or running")
            }
            Submitted::Submitted { script, submission } => println!(
                "submitted {} as Slurm job {} (array tasks {}); follow it with `locobench sweep status {}`",
                script.display(),
                submission.job_id,
                submission.tasks,
                out.display()
            ),
        }
        return Ok(());
    }
    if args.dry_run {
        return Ok(());
    }
    let total = jobs.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let outcomes = run_jobs(&binary, &jobs, &out, args.jobs, &|o| {
        let n = done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        let status = if o.ok { "ok" } else { "FAILED" };
        println!("[{n}/{total}] {} {status} in {:.0} s (log {})", o.name, o.seconds, o.log.display());
    })?;
    let failed: Vec<&str> = outcomes.iter().filter(|o| !o.ok).map(|o| o.name.as_str()).collect();
    println!("runs in {}; report with `locobench report --runs {}`", out.join("runs").display(), out.display());
    anyhow::ensure!(failed.is_empty(), "{} of {total} jobs failed: {}", failed.len(), failed.join(", "));
    Ok(())
}
