use std::path::PathBuf;

use anyhow::{bail, Result};
use locobench::envs::make;
use locobench::io::write_atomic;
use locobench::policy::{Policy, RandomPolicy, ReplayPolicy, ZeroPolicy};
use locobench::rollout::{run_episodes, StepView};

use super::EnvArgs;

#[derive(clap::Args, Debug)]
pub struct RolloutArgs {
    #[command(flatten)]
    pub env: EnvArgs,
    /// `random`, `zero`, or `actions:FILE.csv` to replay recorded actions.
    #[arg(long, default_value = "random")]
    pub policy: String,
    #[arg(long, default_value_t = 1)]
    pub episodes: usize,
    #[command(flatten)]
    pub seed: super::SeedArg,
    /// Scale of the reset noise (sets the env option `reset_noise_scale`).
    #[arg(long)]
    pub reset_noise: Option<f64>,
    /// CSV file to write, one row per step.
    #[arg(long)]
    pub out: PathBuf,
}

pub fn simple_policy(spec: &str, seed: u64) -> Result<Box<dyn Policy>> {
    Ok(match spec {
        "zero" => Box::new(ZeroPolicy),
        // The policy's stream is distinct from the environment's (which uses `seed` itself).
        "random" => Box::new(RandomPolicy::new(seed ^ 0x0005_eed0_fac7_10e5)),
        s if s.starts_with("actions:") => Box::new(ReplayPolicy::from_csv(&s["actions:".len()..])?),
        other => bail!("unknown policy '{other}': use random, zero or actions:FILE.csv"),
    })
}

pub fn run(args: RolloutArgs) -> Result<()> {
    let mut cfg = args.env.config()?;
    if let Some(x) = args.reset_noise {
        cfg = cfg.with_overrides(&[("reset_noise_scale".into(), x.to_string())])?;
    }
    let mut env = make(&cfg)?;
    let mut policy = simple_policy(&args.policy, args.seed.seed)?;
    let spec = env.spec().clone();
    let mut header: Vec<String> = vec!["episode".into(), "step".into()];
    header.extend((0..spec.action_space.dim()).map(|i| format!("action_{i}")));
    header.push("reward".into());
    header.extend(spec.reward_terms.iter().map(|t| t.to_string()));
    header.extend(["terminated", "truncated", "unstable", "clipped_actions"].map(String::from));
    header.extend((0..spec.observation_space.dim()).map(|i| format!("obs_{i}")));

    let mut summaries = Vec::new();
    write_atomic(&args.out, |w| {
        let mut csv = csv::Writer::from_writer(w);
        csv.write_record(&header)?;
        summaries = run_episodes(env.as_mut(), policy.as_mut(), args.episodes, args.seed.seed, &mut |v: &StepView| {
            let (action, step) = (v.action, v.step);
            let mut row: Vec<String> = vec![v.episode.to_string(), v.t.to_string()];
            // `{:?}` prints the shortest text that reads back as the same f64: replays are exact.
            row.extend(action.iter().map(|v| format!("{v:?}")));
            row.push(format!("{:?}", step.reward));
            row.extend(step.info.reward_terms.iter().map(|(_, v)| format!("{v:?}")));
            row.push((step.terminated as u8).to_string());
            row.push((step.truncated as u8).to_string());
            row.push((step.info.unstable as u8).to_string());
            row.push(step.info.clipped_actions.to_string());
            row.extend(step.observation.iter().map(|v| format!("{v:?}")));
            csv.write_record(&row)?;
            Ok(())
        })?;
        csv.flush()?;
        Ok(())
    })?;
    for s in &summaries {
        let terms: Vec<String> = s.term_totals.iter().map(|(n, v)| format!("{n} {v:.3}")).collect();
        let end = s.end_reason();
        println!(
            "{} episode {}: return {:.3} over {} steps ({end}); {}",
            spec.name,
            s.episode,
            s.episode_return,
            s.length,
            terms.join(", ")
        );
    }
    println!("wrote {}", args.out.display());
    Ok(())
}
