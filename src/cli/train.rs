use std::path::PathBuf;

use anyhow::{bail, Result};
use locobench::agents::Algo;
use locobench::envs::EnvConfig;
use locobench::train::{self, config::build_config, config::split_pairs, Outcome, RunControl};

pub use locobench::args::TrainArgs;

fn default_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get().min(2))
}

pub fn run(args: TrainArgs) -> Result<()> {
    let control = RunControl {
        show_progress: !args.quiet,
        record: args.record.clone(),
        record_every: args.record_every,
        video_every: args.video_every,
        tensorboard: args.tensorboard.clone(),
        threads: args.threads.map(usize::from).unwrap_or_else(default_threads),
        device: args.device,
        ..Default::default()
    };
    let summary = if let Some(dir) = &args.resume {
        if let Some(n) = args.steps {
            let exact = train::extend(dir, n)?;
            println!("budget of {} raised to {n} steps", dir.display());
            if !exact {
                println!("note: the newest checkpoint is mid-episode; that episode is cut short there");
            }
        }
        println!("resuming {}", dir.display());
        note_resume_caveat(dir, &control)?;
        train::resume(dir, &control)?
    } else {
        let env = args.env.as_deref().expect("clap requires --env");
        let algo = Algo::parse(args.algo.as_deref().expect("clap requires --algo"))?;
        let mut overrides = Vec::new();
        for s in &args.set {
            overrides.extend(split_pairs(s)?);
        }
        if let Some(n) = args.steps {
            overrides.push(("total_steps".into(), n.to_string()));
        }
        if args.init_from.is_some() && !overrides.iter().any(|(k, _)| k == "warmup_steps") {
            overrides.push(("warmup_steps".into(), "0".into()));
        }
        let cfg = build_config(env, algo, &overrides)?;
        let env_cfg = args.env_options.apply(EnvConfig::new(env))?;
        let out = args
            .out
            .clone()
            .unwrap_or_else(|| PathBuf::from(format!("runs/{env}-{}-seed{}", algo.name(), args.seed.seed)));
        // The policy reference as one path (a budget names its file), which config.toml keeps.
        let init_from = match &args.init_from {
            Some(p) => Some(train::resolve_policy(p, args.init_budget)?.path()),
            None => None,
        };
        if args.resume_if_exists && out.join("config.toml").exists() {
            same_run_or_error(&out, &env_cfg, &cfg, args.seed.seed)?;
            println!("{} holds this run already: resuming it", out.display());
            note_resume_caveat(&out, &control)?;
            let summary = train::resume(&out, &control)?;
            return report(&args, &summary);
        }
        println!(
            "training {} on {env}, seed {}, {} steps -> {}",
            algo.name(),
            args.seed.seed,
            cfg.total_steps,
            out.display()
        );
        train::train(env_cfg, cfg, args.seed.seed, &out, init_from.as_deref(), args.force, &control)?
    };
    report(&args, &summary)
}

/// Refuses to continue a run directory that holds a different run than the one asked for.
fn same_run_or_error(
    out: &std::path::Path,
    env: &EnvConfig,
    cfg: &locobench::agents::TrainConfig,
    seed: u64,
) -> Result<()> {
    let existing = train::read_run_config(out)?;
    let mut env = env.clone();
    env.options = env.resolved_options()?;
    let mut differs = Vec::new();
    if existing.seed != seed {
        differs.push(format!("seed {} (asked {seed})", existing.seed));
    }
    if existing.env != env {
        differs.push("environment or its options".to_string());
    }
    if existing.train != *cfg {
        differs.push("hyperparameters".to_string());
    }
    if !differs.is_empty() {
        bail!(
            "{} holds a different run (it differs in: {}); choose another --out, or --force to replace it",
            out.display(),
            differs.join(", ")
        );
    }
    Ok(())
}

fn report(args: &TrainArgs, summary: &train::RunSummary) -> Result<()> {
    if let Some(e) = &summary.last_eval {
        println!(
            "last evaluation at step {}: {:.2} ± {:.2} over {} episodes",
            summary.steps,
            e.mean(),
            e.std(),
            e.returns.len()
        );
    }
    match summary.outcome {
        Outcome::Finished => println!("finished; checkpoint {}", summary.checkpoint.display()),
        Outcome::AlreadyFinished => {
            println!("already finished at step {}; checkpoint {}", summary.steps, summary.checkpoint.display())
        }
        Outcome::Stopped => println!(
            "stopped at step {}; checkpoint {} (continue with `locobench train --resume {}`)",
            summary.steps,
            summary.checkpoint.display(),
            summary.run_dir.display()
        ),
    }
    println!("run directory: {}", summary.run_dir.display());
    if let Some(r) = &args.record {
        println!("recording: {} (open with `rerun {}`)", r.display(), r.display());
    }
    Ok(())
}

/// Says when resuming here will not continue the run bit for bit (another kernel path, commit or
/// MuJoCo; docs/reproducibility.md), unless the run has nothing left to train.
fn note_resume_caveat(dir: &std::path::Path, control: &RunControl) -> Result<()> {
    let finished = match (train::read_run_config(dir), train::checkpoint::latest(dir)) {
        (Ok(run), Ok(ckpt)) => train::checkpoint::load_state(&ckpt).is_ok_and(|s| s.step >= run.train.total_steps),
        _ => false,
    };
    if !finished {
        if let Some(note) = train::provenance::resume_caveat_for(dir, control.threads, control.device)? {
            println!("note: {note}");
        }
    }
    Ok(())
}
