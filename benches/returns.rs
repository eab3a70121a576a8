//! `cargo bench --bench returns [-- TIER]`: TD3, SAC and DDPG trained over seeds with their
//! published settings, then `locobench report` over the runs (`<out>/report/`): held-out
//! evaluation at each budget beside the published curves, the random policy and (Minitaur, Ant)
//! the controller across its speeds. LOCOBENCH_RETURNS_EPISODES and
//! LOCOBENCH_RETURNS_PUSH_EPISODES set the report's episodes.
//!
//! Tiers (`LOCOBENCH_RETURNS_TIER=quick|standard|full`, or the tier's name as an argument):
//!   quick     (default, about an hour on 2 cores) InvertedPendulum solved, HalfCheetah at 100k,
//!             Minitaur walking with SAC at 150k; 2 seeds each;
//!   standard  the budgets researchers quote: HalfCheetah and Ant with all three algorithms,
//!             Humanoid and Minitaur with TD3 and SAC, 300k steps, 2 seeds (about 40 hours);
//!   full      the published protocol: every env and algorithm, 1M steps, 5 seeds (weeks here;
//!             meant for a cluster, see LOCOBENCH_RETURNS_SLURM).
//! Runs live under `target/bench-returns/<tier>/<env>/runs/` and the bench resumes where it
//! stopped: finished runs are kept and tabulated, stopped ones continue (`LOCOBENCH_RETURNS_FRESH=1`
//! starts over). Other knobs: LOCOBENCH_RETURNS_JOBS (runs at a time, default 2),
//! LOCOBENCH_RETURNS_OUT, LOCOBENCH_RETURNS_ENVS (restrict to these envs).
//!
//! On a Slurm cluster, `LOCOBENCH_RETURNS_SLURM=1` submits every run as a `locobench sweep
//! --slurm` array instead of training here (LOCOBENCH_RETURNS_SLURM_CPUS, default 1, and
//! LOCOBENCH_RETURNS_SBATCH, further sbatch options separated by spaces, e.g.
//! "--partition=cpu --time=12:00:00"), returns at once and tabulates whatever has finished; run
//! it again later to submit what is missing and tabulate more.
use std::path::PathBuf;

use anyhow::{bail, Result};
use locobench::evaluation::{Protocol, DEFAULT_EPISODES};
use locobench::report::{write_report, ReportOptions, HELD_OUT_CSV};
use locobench::sweep::slurm::{submit, SlurmOptions, Submitted};
use locobench::sweep::{jobs, run_jobs, write_plan, SweepSpec};

/// One environment's share of a tier.
struct Block {
    env: &'static str,
    algos: &'static [&'static str],
    steps: u64,
    seeds: u64,
    /// Extra hyperparameters (only the smoke tier shrinks networks).
    set: &'static [&'static str],
}

const ALL: &[&str] = &["td3", "sac", "ddpg"];

fn tier(name: &str) -> Result<Vec<Block>> {
    let b = |env, algos, steps, seeds| Block { env, algos, steps, seeds, set: &[] };
    Ok(match name {
        // `cargo test --all-targets` runs this binary without `--bench`: the whole path on a
        // tiny budget.
        "smoke" => vec![Block {
            env: "inverted-pendulum",
            algos: &["td3"],
            steps: 300,
            seeds: 2,
            set: &["hidden=[16,16],batch_size=32,warmup_steps=100,learning_starts=100,eval_every=100,eval_episodes=2"],
        }],
        "quick" => vec![
            b("inverted-pendulum", ALL, 25_000, 2),
            b("half-cheetah", ALL, 100_000, 2),
            b("minitaur", &["sac"], 150_000, 2),
        ],
        "standard" => vec![
            b("inverted-pendulum", ALL, 25_000, 2),
            b("half-cheetah", ALL, 300_000, 2),
            b("ant", ALL, 300_000, 2),
            b("humanoid", &["td3", "sac"], 300_000, 2),
            b("minitaur", &["td3", "sac"], 300_000, 2),
        ],
        "full" => ["inverted-pendulum", "half-cheetah", "ant", "humanoid", "walker2d", "hopper", "minitaur"]
            .into_iter()
            .map(|env| b(env, ALL, if env == "inverted-pendulum" { 25_000 } else { 1_000_000 }, 5))
            .collect(),
        other => bail!("unknown returns tier '{other}'; tiers: quick, standard, full"),
    })
}

fn var<T: std::str::FromStr>(name: &str) -> Option<T> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let smoke = !args.iter().any(|a| a == "--bench");
    let tier_name = if smoke {
        "smoke".to_string()
    } else {
        args.iter()
            .find(|a| !a.starts_with('-'))
            .cloned()
            .or_else(|| std::env::var("LOCOBENCH_RETURNS_TIER").ok())
            .unwrap_or_else(|| "quick".into())
    };
    let mut blocks = tier(&tier_name)?;
    if let Ok(only) = std::env::var("LOCOBENCH_RETURNS_ENVS") {
        let only: Vec<&str> = only.split(',').map(str::trim).collect();
        blocks.retain(|b| only.contains(&b.env));
    }
    let parallel: usize = var("LOCOBENCH_RETURNS_JOBS").unwrap_or(2);
    let slurm = std::env::var("LOCOBENCH_RETURNS_SLURM").is_ok_and(|v| v == "1");
    let out = PathBuf::from(
        std::env::var("LOCOBENCH_RETURNS_OUT").unwrap_or_else(|_| format!("target/bench-returns/{tier_name}")),
    );
    if std::env::var("LOCOBENCH_RETURNS_FRESH").is_ok_and(|v| v == "1") || smoke {
        let _ = std::fs::remove_dir_all(&out);
    }
    let binary = PathBuf::from(env!("CARGO_BIN_EXE_locobench"));
    println!(
        "returns bench, tier {tier_name}: {} -> {}{}",
        blocks
            .iter()
            .map(|b| format!("{} {}x{}x{}", b.env, b.algos.len(), b.seeds, b.steps))
            .collect::<Vec<_>>()
            .join(", "),
        out.display(),
        if slurm { " (through Slurm)" } else { "" }
    );

    for block in &blocks {
        let spec = SweepSpec {
            env: block.env.to_string(),
            algos: block.algos.iter().map(|a| a.to_string()).collect(),
            grid: vec![],
            seeds: (0..block.seeds).collect(),
            steps: Some(block.steps),
            set: block.set.iter().map(|s| s.to_string()).collect(),
            options: vec![],
            tensorboard: false,
            device: locobench::device::ComputeDevice::Cpu,
        };
        let dir = out.join(block.env);
        let js = jobs(&spec, &dir)?;
        write_plan(&spec, &dir, &js)?;
        if slurm {
            let opts = SlurmOptions {
                cpus_per_task: var("LOCOBENCH_RETURNS_SLURM_CPUS").unwrap_or(1),
                extra: std::env::var("LOCOBENCH_RETURNS_SBATCH")
                    .unwrap_or_default()
                    .split_whitespace()
                    .map(String::from)
                    .collect(),
                ..SlurmOptions::default()
            };
            match submit(&dir, &js, &opts, &binary, false)? {
                Submitted::Submitted { submission, .. } => {
                    println!("  {}: submitted Slurm job {} (tasks {})", block.env, submission.job_id, submission.tasks)
                }
                Submitted::Nothing { finished, queued } => {
                    println!("  {}: {finished} runs finished, {queued} queued or running", block.env)
                }
                Submitted::DryRun { .. } => unreachable!("not a dry run"),
            }
        } else {
            let outcomes = run_jobs(&binary, &js, &dir, parallel, &|o| {
                println!("  {} {} {} in {:.0} s", block.env, o.name, if o.ok { "ok" } else { "FAILED" }, o.seconds)
            })?;
            for o in outcomes.iter().filter(|o| !o.ok) {
                eprintln!("job {} failed; see {}", o.name, o.log.display());
            }
        }
    }
    // The tables are the report's: the same protocol, statistics and rendering as
    // `locobench report --runs <out>`.
    let opts = ReportOptions {
        protocol: Protocol {
            episodes: var("LOCOBENCH_RETURNS_EPISODES").unwrap_or(if smoke { 2 } else { DEFAULT_EPISODES }),
            seed: 0,
        },
        push_episodes: var("LOCOBENCH_RETURNS_PUSH_EPISODES").unwrap_or(if smoke { 0 } else { 20 }),
        ..ReportOptions::default()
    };
    let dirs: Vec<PathBuf> = blocks.iter().map(|b| out.join(b.env)).filter(|d| d.exists()).collect();
    let report = write_report(&dirs, &out.join("report"), &opts)?;
    print!("\n{}", std::fs::read_to_string(&report.readme)?);
    println!("\nwrote {} ({} beside it); runs under {}", report.readme.display(), HELD_OUT_CSV, out.display());
    Ok(())
}
