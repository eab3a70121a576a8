use std::path::PathBuf;

use anyhow::{Context, Result};
use locobench::agents::Algo;
use locobench::sweep::{jobs, parse_axis, run_jobs, write_plan, SweepSpec};

#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    #[arg(long)]
    pub env: String,
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
    /// Jobs run at once (each is one single-threaded process).
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// Total steps per run (default: the preset's).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Hyperparameters for every job, as `locobench train --set`.
    #[arg(long = "set", value_name = "KEY=VALUE,...")]
    pub set: Vec<String>,
    /// Env options for every job, as `locobench train --option`.
    #[arg(long = "option", value_name = "KEY=VALUE,...")]
    pub options: Vec<String>,
    /// The sweep directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Only write sweep.toml and jobs.txt.
    #[arg(long)]
    pub dry_run: bool,
}

pub fn run(args: SweepArgs) -> Result<()> {
    for a in &args.algo {
        Algo::parse(a)?;
    }
    locobench::envs::EnvConfig::new(&args.env).resolved_options()?;
    let spec = SweepSpec {
        env: args.env.clone(),
        algos: args.algo.clone(),
        grid: args.grid.iter().map(|g| parse_axis(g)).collect::<Result<_>>()?,
        seeds: (args.first_seed..args.first_seed + args.seeds).collect(),
        steps: args.steps,
        set: args.set.clone(),
        options: args.options.clone(),
    };
    let jobs = jobs(&spec, &args.out)?;
    write_plan(&spec, &args.out, &jobs)?;
    println!("{} jobs; commands in {}", jobs.len(), args.out.join("jobs.txt").display());
    if args.dry_run {
        return Ok(());
    }
    let binary = std::env::current_exe().context("finding the locobench binary")?;
    let total = jobs.len();
    let done = std::sync::atomic::AtomicUsize::new(0);
    let outcomes = run_jobs(&binary, &jobs, &args.out, args.jobs, &|o| {
        let n = done.fetch_add(1, std::sync::atomic::Ordering::SeqCst) + 1;
        let status = if o.ok { "ok" } else { "FAILED" };
        println!("[{n}/{total}] {} {status} in {:.0} s (log {})", o.name, o.seconds, o.log.display());
    })?;
    let failed: Vec<&str> = outcomes.iter().filter(|o| !o.ok).map(|o| o.name.as_str()).collect();
    println!(
        "runs in {}; report with `locobench report --runs {}`",
        args.out.join("runs").display(),
        args.out.display()
    );
    anyhow::ensure!(failed.is_empty(), "{} of {total} jobs failed: {}", failed.len(), failed.join(", "));
    Ok(())
}
