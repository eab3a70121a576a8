//! The `locobench` command line.
mod baseline;
mod envs;
mod eval;
mod export;
mod record;
mod report;
mod rollout;
mod sweep;
mod train;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "locobench", version, about = "Legged-locomotion RL and classical control on MuJoCo")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the environments with their observation/action sizes and control period.
    Envs,
    /// Run a simple policy (random, zero, or recorded actions) and write every step to CSV.
    Rollout(rollout::RolloutArgs),
    /// Train TD3, SAC or DDPG; resume a run; fine-tune from a checkpoint.
    Train(train::TrainArgs),
    /// Evaluate a checkpoint: mean and std of the return and of every reward term.
    Eval(eval::EvalArgs),
    /// Write a run's policy alone (actor weights, config, metrics) to share or ship.
    Export(export::ExportArgs),
    /// Run the Raibert/QP baseline controller and report how it walks.
    Baseline(baseline::BaselineArgs),
    /// Write a rerun recording (.rrd) of a policy's rollouts: checkpoint, raibert, random, zero.
    Record(record::RecordArgs),
    /// Write an HTML + Markdown report of runs: learning curves, baseline vs RL.
    Report(report::ReportArgs),
    /// Train a grid of reward weights x algorithms x seeds, each job a separate process.
    Sweep(sweep::SweepArgs),
}

pub fn run() -> Result<()> {
    match Cli::parse().command {
        Command::Envs => envs::run(),
        Command::Rollout(args) => rollout::run(args),
        Command::Train(args) => train::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Export(args) => export::run(args),
        Command::Baseline(args) => baseline::run(args),
        Command::Record(args) => record::run(args),
        Command::Report(args) => report::run(args),
        Command::Sweep(args) => sweep::run(args),
    }
}

/// How every command that builds an environment takes its options: a TOML file, `--option`
/// pairs and `--reward` weights by term name, applied in that order over the command's base
/// (an env's defaults, a checkpoint's run, the baseline's setup).
#[derive(clap::Args, Debug, Clone, Default)]
pub struct EnvOptionArgs {
    /// TOML file with environment options (an `[options]` table or bare keys).
    #[arg(long, value_name = "FILE")]
    pub env_config: Option<std::path::PathBuf>,
    /// Environment option overrides, e.g. `--option drift_weight=0.25,max_episode_steps=500`.
    #[arg(long = "option", value_name = "KEY=VALUE,...")]
    pub options: Vec<String>,
    /// Reward weights by term name, e.g. `--reward drift=0.25,shake=0.1`.
    #[arg(long, value_name = "TERM=WEIGHT,...")]
    pub reward: Option<String>,
}

impl EnvOptionArgs {
    /// `base` with the file's options, then `--option`, then `--reward` applied.
    pub fn apply(&self, base: locobench::envs::EnvConfig) -> Result<locobench::envs::EnvConfig> {
        let pairs = self.pairs(&base.name)?;
        Ok(base.with_overrides(&pairs)?)
    }

    /// The same settings as `key=value` pairs of env options, in the order they apply (what a
    /// sweep hands each job as `--option`).
    pub fn pairs(&self, env: &str) -> Result<Vec<(String, String)>> {
        use anyhow::Context;
        let mut pairs = Vec::new();
        if let Some(path) = &self.env_config {
            let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
            let table: toml::Table = text.parse().with_context(|| format!("parsing {}", path.display()))?;
            let options = match table.get("options") {
                Some(toml::Value::Table(t)) => t.clone(),
                _ => table,
            };
            pairs.extend(options.into_iter().map(|(k, v)| (k, v.to_string())));
        }
        for o in &self.options {
            pairs.extend(locobench::envs::parse_overrides(o)?);
        }
        if let Some(r) = &self.reward {
            for (term, value) in locobench::envs::parse_overrides(r)? {
                pairs.push((locobench::envs::reward_weight_option(env, &term)?.to_string(), value));
            }
        }
        Ok(pairs)
    }
}

/// An environment name and its options (`rollout`).
#[derive(clap::Args, Debug, Clone)]
pub struct EnvArgs {
    /// Environment name (see `locobench envs`).
    #[arg(long)]
    pub env: String,
    #[command(flatten)]
    pub options: EnvOptionArgs,
}

impl EnvArgs {
    pub fn config(&self) -> Result<locobench::envs::EnvConfig> {
        self.options.apply(locobench::envs::EnvConfig::new(&self.env))
    }
}
