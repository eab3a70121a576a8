use std::path::PathBuf;

use anyhow::Result;
use locobench::envs::make;
use locobench::train::{evaluate::evaluate, load_policy};

#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// A checkpoint directory, or a run directory (its newest checkpoint).
    #[arg(long)]
    pub checkpoint: PathBuf,
    #[arg(long, default_value_t = 10)]
    pub episodes: usize,
    /// Seed for the evaluation episodes (default: the run's seed, as during training).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Options over the run's own environment, e.g. `--reward drift=1,shake=1,energy=0.005` to
    /// evaluate under other reward weights.
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
}

pub fn run(args: EvalArgs) -> Result<()> {
    let (run, agent) = load_policy(&args.checkpoint)?;
    let env_cfg = args.env_options.apply(run.env.clone())?;
    let mut env = make(&env_cfg)?;
    let e = evaluate(agent.as_ref(), env.as_mut(), args.episodes, args.seed.unwrap_or(run.seed))?;
    println!(
        "{} {} on {}: return {:.2} ± {:.2} over {} episodes (mean length {:.1})",
        args.checkpoint.display(),
        run.train.algo.name(),
        run.env.name,
        e.mean(),
        e.std(),
        e.returns.len(),
        e.lengths.iter().sum::<usize>() as f64 / e.lengths.len() as f64
    );
    for (term, v) in &e.term_means {
        println!("  {term:<14} {v:>12.3}");
    }
    println!("  {:<14} {:>12.3}  (share of action components at |a| >= 0.99)", "saturated", e.saturation);
    if e.unstable_episodes > 0 {
        println!("  {} episode(s) ended by a physics blow-up", e.unstable_episodes);
    }
    Ok(())
}
