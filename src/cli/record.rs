use std::path::PathBuf;

use anyhow::{Context, Result};
use locobench::controller::baseline::{baseline_controller_for, baseline_env, parse_gait};
use locobench::envs::make;
use locobench::policy::{AgentPolicy, Policy};
use locobench::record::{spawn_viewer, Recording, RolloutRecorder};
use locobench::rollout::run_episodes;
use locobench::train::resolve_policy;

use super::rollout::simple_policy;

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// Environment name (see `locobench envs`); optional with a checkpoint (its run's env).
    #[arg(long)]
    pub env: Option<String>,
    /// A trained policy (a run directory, a committed result run, a checkpoint, a budget
    /// policy file or an exported policy), `raibert` (the controller), `random`, `zero`, or
    /// `actions:FILE.csv`.
    #[arg(long)]
    pub policy: String,
    /// With a run directory as --policy: the actor the run saved at this step budget.
    #[arg(long)]
    pub budget: Option<u64>,
    /// Episodes to record, one after another (reset seeds from --seed on).
    #[arg(long, default_value_t = 1)]
    pub episodes: usize,
    #[command(flatten)]
    pub seed: super::SeedArg,
    /// The controller's commanded forward speed (m/s), reached over the first second (as in
    /// `baseline`).
    #[arg(long, default_value_t = 0.35)]
    pub speed: f64,
    #[command(flatten)]
    pub command: super::baseline::CommandArgs,
    /// Gait of the Raibert controller (Minitaur: bound, trot, pace; Ant: row, trot).
    #[arg(long)]
    pub gait: Option<String>,
    /// Options over the policy's environment, e.g. `--option max_episode_steps=200`.
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
    /// The recording to write.
    #[arg(long, default_value = "rollout.rrd")]
    pub out: PathBuf,
    /// Open the recording in the rerun viewer (needs `rerun` on the PATH).
    #[arg(long)]
    pub spawn: bool,
}

pub fn run(args: RecordArgs) -> Result<()> {
    let agent_holder;
    let simple = ["raibert", "random", "zero"].contains(&args.policy.as_str()) || args.policy.starts_with("actions:");
    anyhow::ensure!(
        !(simple && args.budget.is_some()),
        "--budget applies to a trained policy, not to --policy {}",
        args.policy
    );
    let (cfg, mut policy): (_, Box<dyn Policy>) = match args.policy.as_str() {
        "raibert" => {
            let env = args.env.as_deref().context("--policy raibert needs --env minitaur or --env ant")?;
            let gait = args.gait.as_deref().map(parse_gait).transpose()?;
            let command = args.command.commands(&[args.speed])?.remove(0);
            (baseline_env(env)?, baseline_controller_for(env, command, gait)?)
        }
        p if p == "random" || p == "zero" || p.starts_with("actions:") => {
            let env = args.env.as_deref().with_context(|| format!("--policy {p} needs --env"))?;
            (locobench::envs::EnvConfig::new(env), simple_policy(p, args.seed.seed)?)
        }
        checkpoint => {
            let path = std::path::Path::new(checkpoint);
            let (run, agent) = resolve_policy(path, args.budget).and_then(|p| p.load()).with_context(|| {
                format!("--policy '{checkpoint}' is not raibert, random, zero, actions:FILE.csv or a trained policy")
            })?;
            if let Some(env) = &args.env {
                anyhow::ensure!(*env == run.env.name, "the checkpoint was trained on {}, not {env}", run.env.name);
            }
            agent_holder = agent;
            let label = format!("{} ({checkpoint})", run.train.algo.name());
            (run.env, Box::new(AgentPolicy { agent: agent_holder.as_ref(), label }) as Box<dyn Policy>)
        }
    };
    let cfg = args.env_options.apply(cfg)?;
    let mut env = make(&cfg)?;
    let recording = Recording::create(&args.out)?;
    let mut recorder = RolloutRecorder::new(recording.stream(), env.data().model())?;
    let summaries = run_episodes(env.as_mut(), policy.as_mut(), args.episodes, args.seed.seed, &mut recorder)?;
    let frames = recorder.frames();
    drop(recorder);
    let path = recording.finish()?;
    for s in &summaries {
        println!(
            "{} with {}: episode {} return {:.3} over {} steps",
            cfg.name,
            policy.name(),
            s.episode,
            s.episode_return,
            s.length
        );
    }
    println!("wrote {} ({frames} frames); view it with `rerun {}`", path.display(), path.display());
    if args.spawn {
        spawn_viewer(&path)?;
    }
    Ok(())
}
