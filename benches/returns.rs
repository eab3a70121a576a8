//! `cargo bench --bench returns [-- TIER]`: TD3, SAC and DDPG trained over seeds with their
//! published settings, one table per environment: our evaluation at the published curves' step
//! marks with the published mean ± std beside it, the final evaluation, the random policy and
//! (Minitaur, Ant) the Raibert/QP baseline.
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
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use locobench::controller::baseline::{baseline_controller, baseline_env, RAMP_TIME};
use locobench::controller::command::SpeedProfile;
use locobench::controller::measure::measure;
use locobench::envs::{make, EnvConfig};
use locobench::io::write_bytes_atomic;
use locobench::policy::RandomPolicy;
use locobench::report::anchors::{bundled_anchors, bundled_curves, published_curve};
use locobench::report::curves::mean_std;
use locobench::report::runs::{find_runs, Run};
use locobench::report::{fmt_return, group_runs, summarise};
use locobench::rollout::{run_episodes, StepView};
use locobench::sweep::slurm::{submit, SlurmOptions, Submitted};
use locobench::sweep::{jobs, run_jobs, write_plan, SweepSpec};
use locobench::train::run_progress;

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
    let tables = tabulate(&blocks, &out, &tier_name)?;
    write_bytes_atomic(&out.join("returns.md"), tables.markdown.as_bytes())?;
    write_bytes_atomic(&out.join("returns.csv"), tables.csv.as_bytes())?;
    print!("\n{}", tables.markdown);
    println!(
        "\nwrote {} and {}; runs under {} (`locobench report --runs {}`)",
        out.join("returns.md").display(),
        out.join("returns.csv").display(),
        out.display(),
        out.display()
    );
    Ok(())
}

struct Tables {
    markdown: String,
    csv: String,
}

/// Step marks for the columns: the published curves' marks within the budget, or quarters of
/// the budget when it is below the first mark.
fn marks(steps: u64) -> Vec<u64> {
    let mut published: Vec<u64> = bundled_curves().into_iter().flat_map(|c| c.steps).filter(|&m| m <= steps).collect();
    published.sort_unstable();
    published.dedup();
    if published.is_empty() {
        vec![steps / 4, steps / 2, steps]
    } else {
        published
    }
}

fn k(steps: u64) -> String {
    if steps % 1000 == 0 {
        format!("{}k", steps / 1000)
    } else {
        steps.to_string()
    }
}

/// Mean return of the uniform random policy over 10 episodes (seed 0).
fn random_return(env: &str) -> Result<(f64, f64)> {
    let mut e = make(&EnvConfig::new(env))?;
    let mut policy = RandomPolicy::new(0);
    let eps = run_episodes(e.as_mut(), &mut policy, 10, 0, &mut |_: &StepView| Ok(()))?;
    Ok(mean_std(&eps.iter().map(|x| x.episode_return).collect::<Vec<_>>()))
}

fn tabulate(blocks: &[Block], out: &Path, tier_name: &str) -> Result<Tables> {
    let anchors = bundled_anchors();
    let fmt = |v: Option<f64>| v.map_or("–".to_string(), fmt_return);
    let mut md = format!(
        "# Returns bench, tier `{tier_name}`\n\nPublished hyperparameters (src/agents/config.rs, src/train/presets.toml). \
         Evaluation: mean return of the deterministic policy over 10 episodes (InvertedPendulum: 5) every 5k steps \
         (1k); each cell is the mean over seeds of that evaluation, with the published learning curve's mean ± std \
         over seeds at the same step in brackets (baselines/published_curves.toml). Only finished runs are \
         tabulated.\n\n"
    );
    let mut csv = String::from("env,policy,seeds,steps,mark,mean,std,published_mean,published_std\n");
    let mut total_wall = 0.0;
    for block in blocks {
        let runs: Vec<Run> = find_runs(&[out.join(block.env)])
            .unwrap_or_default()
            .into_iter()
            .filter(|r| run_progress(&r.dir).is_ok_and(|p| p.finished()))
            .collect();
        let marks = marks(block.steps);
        let _ = write!(md, "## {}\n\n| policy | seeds |", block.env);
        for m in &marks {
            let _ = write!(md, " @{} |", k(*m));
        }
        let _ = writeln!(md, " final | wall min (mean) | steps/s | published at the end |");
        let _ = writeln!(md, "|---|---|{}---|---|---|---|", "---|".repeat(marks.len()));
        for (group, rs) in group_runs(&runs) {
            let s = summarise(&group, &rs);
            total_wall += rs.iter().map(|r| r.wall_time()).sum::<f64>();
            let curve = published_curve(block.env, &group.algo);
            let _ = write!(md, "| {} | {} |", group.algo, s.seeds);
            for &m in &marks {
                let ours = (s.steps >= m).then(|| s.curve.at(m)).flatten();
                let theirs = curve.as_ref().and_then(|c| c.at(m));
                let published = theirs.map_or(String::new(), |(pm, ps)| format!(" ({pm:.0} ± {ps:.0})"));
                let sd = ours.and_then(|_| s.curve.steps.iter().rposition(|&t| t <= m).map(|i| s.curve.std[i]));
                let _ = write!(md, " {}{} |", fmt(ours), published);
                let _ = writeln!(
                    csv,
                    "{},{},{},{},{m},{},{},{},{}",
                    block.env,
                    group.algo,
                    s.seeds,
                    block.steps,
                    ours.unwrap_or(f64::NAN),
                    sd.unwrap_or(f64::NAN),
                    theirs.map_or(f64::NAN, |t| t.0),
                    theirs.map_or(f64::NAN, |t| t.1),
                );
            }
            let end: Vec<String> = anchors
                .iter()
                .filter(|a| a.env == block.env && a.algo == group.algo && a.steps >= 1_000_000)
                .map(|a| {
                    let sd = a.std.map_or(String::new(), |s| format!(" ± {s}"));
                    let source = a.source.split([',', '(']).next().unwrap_or("").trim();
                    format!("{}{sd} @{} ({source})", a.value, k(a.steps))
                })
                .collect();
            let rate = if s.wall_time > 0.0 { s.steps as f64 / s.wall_time } else { f64::NAN };
            let _ = writeln!(
                md,
                " {} ± {} | {:.1} | {:.0} | {} |",
                fmt(Some(s.final_mean)),
                fmt(Some(s.final_std)),
                s.wall_time / 60.0,
                rate,
                if end.is_empty() { "–".into() } else { end.join("; ") }
            );
        }
        // Reference rows: no learning, and the controller.
        let mut reference = |label: &str, (m, sd): (f64, f64), note: &str| {
            let empty = "| – ".repeat(marks.len());
            let _ = writeln!(
                md,
                "| {label} | 10 episodes {empty}| {} ± {} | – | – | {note} |",
                fmt_return(m),
                fmt_return(sd)
            );
            let _ = writeln!(csv, "{},{label},10 episodes,0,0,{m},{sd},,", block.env);
        };
        reference("random policy", random_return(block.env)?, "–");
        if block.env == "minitaur" || block.env == "ant" {
            let speed = if block.env == "minitaur" { 0.35 } else { 0.5 };
            let mut e = make(&baseline_env(block.env)?)?;
            let mut c = baseline_controller(block.env, speed, None)?;
            let eps = measure(e.as_mut(), c.as_mut(), 10, 0, &SpeedProfile::ramp(speed, RAMP_TIME))?;
            let falls = eps.iter().filter(|x| x.fell).count();
            let v = mean_std(&eps.iter().map(|x| x.mean_speed).collect::<Vec<_>>()).0;
            reference(
                &format!("raibert @{speed} m/s"),
                mean_std(&eps.iter().map(|x| x.episode_return).collect::<Vec<_>>()),
                &format!("mean speed {v:.2} m/s, falls {falls}/10"),
            );
        }
        md.push('\n');
    }
    let _ = writeln!(md, "The tabulated runs' wall times add up to {:.0} min.", total_wall / 60.0);
    let _ = std::fs::create_dir_all(out).context("creating the output directory");
    Ok(Tables { markdown: md, csv })
}
