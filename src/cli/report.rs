use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use locobench::evaluation::{EvalCache, Protocol};
use locobench::report::format::{budget, interval};
use locobench::report::{fmt_return, write_report, ReportOptions};

#[derive(clap::Args, Debug)]
pub struct ReportArgs {
    /// Run directories, or directories holding them (e.g. a sweep).
    #[arg(long, num_args = 1.., required_unless_present = "progress")]
    pub runs: Vec<PathBuf>,
    /// Instead of a report: RUN's training clips (`train --video-every N`) in training order,
    /// each beside its evaluation, written to --out.
    #[arg(long, value_name = "RUN", conflicts_with = "runs")]
    pub progress: Option<PathBuf>,
    #[arg(long, default_value = "report")]
    pub out: PathBuf,
    /// Held-out episodes per policy and seed.
    #[arg(long, default_value_t = locobench::evaluation::DEFAULT_EPISODES)]
    pub episodes: usize,
    /// Episodes per push level (0: no push table).
    #[arg(long, default_value_t = 20)]
    pub push_episodes: usize,
    /// Evaluations at once (default: every core); the report is the same for any number.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Film each algorithm's best row on the first held-out episode (beside the controller at its
    /// speed, and under a push, on Minitaur and Ant) into OUT/videos/: MP4s with poster frames for
    /// index.html, GIFs for README.md. Needs OpenGL (OSMesa) and ffmpeg, as `record --video`.
    #[arg(long)]
    pub videos: bool,
    /// Directories of episodes evaluated outside locobench (`locobench.evaluate(..., out=DIR)` in
    /// Python): each label becomes a row beside the runs', marked as external, with the same
    /// statistics and the controller at its speed. They must follow this report's protocol
    /// (--episodes, --seed) and env options.
    #[arg(long, num_args = 1.., value_name = "DIR")]
    pub external: Vec<PathBuf>,
    /// Directories holding a robustness suite's robustness.csv and robustness.toml (`locobench
    /// robustness`, `cargo bench --bench robustness`): each env's section gains the suite's
    /// summary, goal check and one chart per axis.
    #[arg(long, num_args = 1.., value_name = "DIR")]
    pub robustness: Vec<PathBuf>,
    /// Where held-out episodes, controller speeds and clips are kept between reports (default
    /// OUT/.cache): each entry is keyed by everything that decides its numbers (the policy's
    /// bytes, the env and its options and reward, the protocol, the push, the kernels and the
    /// version of the code), so a report with little new evaluates only what is new.
    #[arg(long, value_name = "DIR", conflicts_with = "no_cache")]
    pub cache: Option<PathBuf>,
    /// Compute everything again and keep nothing (the report is the same bytes as a cached one).
    #[arg(long)]
    pub no_cache: bool,
    /// After the report, remove the cache entries it did not use (older code, runs or options).
    #[arg(long, conflicts_with = "no_cache")]
    pub prune_cache: bool,
    /// Protocol seed: picks the held-out reset seeds.
    #[command(flatten)]
    pub seed: super::SeedArg,
}

pub fn run(args: ReportArgs) -> Result<()> {
    anyhow::ensure!(args.episodes > 0, "--episodes must be at least 1");
    let started = Instant::now();
    if let Some(run) = &args.progress {
        let (index, clips) = locobench::report::progress::write_progress(run, &args.out)?;
        println!("wrote {} ({clips} clips in training order)", index.display());
        return Ok(());
    }
    let cache = if args.no_cache {
        EvalCache::off()
    } else {
        EvalCache::open(&args.cache.clone().unwrap_or_else(|| args.out.join(".cache")))?
    };
    let opts = ReportOptions {
        protocol: Protocol { episodes: args.episodes, seed: args.seed.seed },
        push_episodes: args.push_episodes,
        threads: args.threads.unwrap_or_else(locobench::evaluation::parallel::default_threads),
        videos: args.videos,
        external: args.external.clone(),
        robustness: args.robustness.clone(),
        cache: cache.clone(),
    };
    let report = write_report(&args.runs, &args.out, &opts)?;
    for (env, rows) in &report.rows {
        for r in rows.iter().filter(|r| r.seeds() > 0) {
            println!(
                "{env:<14} {:<40} {:>5}  seeds {:>2}  held-out return {}",
                r.group.label(),
                budget(r.budget),
                r.seeds(),
                interval(r.mean_return(locobench::report::BOOTSTRAP_SEED).interval, fmt_return)
            );
        }
    }
    if let Some(dir) = cache.dir() {
        let (read, computed, damaged) = cache.counts();
        let pruned = if args.prune_cache { cache.prune_unused()? } else { 0 };
        println!(
            "evaluation cache {}: {read} read, {computed} computed{}{}; {:.2} s on keys, lookups and writes (summed \
             over threads)",
            dir.display(),
            if damaged > 0 { format!(" ({damaged} damaged entries recomputed)") } else { String::new() },
            if args.prune_cache { format!(", {pruned} unused removed") } else { String::new() },
            cache.overhead_seconds()
        );
    }
    println!(
        "wrote {} and {} in {:.0} s",
        report.index.display(),
        report.readme.display(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}
