//! Typed command-line argument groups. The `locobench` subcommands flatten them (so `--env`,
//! `--option`, `--env-config`, `--reward` and `--seed` read the same everywhere), and sweeps
//! build each job as a [`TrainArgs`] value rendered by [`TrainArgs::to_args`]: what a job runs
//! is exactly what `locobench train` parses back (tested).
use std::path::PathBuf;

use anyhow::Result;

use crate::envs::EnvConfig;

/// The seed of a command's random streams (environment resets, exploration, initial weights).
#[derive(clap::Args, Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SeedArg {
    /// Seed of the run or of the episodes.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// How every command that builds an environment takes its options: a TOML file, `--option`
/// pairs and `--reward` weights by term name, applied in that order over the command's base
/// (an env's defaults, a checkpoint's run, the baseline's setup).
#[derive(clap::Args, Debug, Clone, Default, PartialEq)]
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
    pub fn apply(&self, base: EnvConfig) -> Result<EnvConfig> {
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
            pairs.extend(crate::envs::parse_overrides(o)?);
        }
        if let Some(r) = &self.reward {
            for (term, value) in crate::envs::parse_overrides(r)? {
                pairs.push((crate::envs::reward_weight_option(env, &term)?.to_string(), value));
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
    /// `--option` and `--reward` settings.
    #[command(flatten)]
    pub options: EnvOptionArgs,
}

impl EnvArgs {
    /// The environment configuration these arguments describe; fails on a bad option.
    pub fn config(&self) -> Result<crate::envs::EnvConfig> {
        self.options.apply(crate::envs::EnvConfig::new(&self.env))
    }
}

/// `locobench train`'s arguments, shared with the sweep (which writes them for each job).
#[derive(clap::Args, Debug, Clone, PartialEq)]
pub struct TrainArgs {
    /// Environment name (see `locobench envs`).
    #[arg(long, required_unless_present = "resume")]
    pub env: Option<String>,
    /// td3, sac, ddpg, crossq, ppo or dqn.
    #[arg(long, required_unless_present = "resume")]
    pub algo: Option<String>,
    /// The run's seed.
    #[command(flatten)]
    pub seed: SeedArg,
    /// Total environment steps (same as --set total_steps=N). With --resume: raise the run's
    /// budget to N steps and train on (a finished 100k run to 300k, say).
    #[arg(long)]
    pub steps: Option<u64>,
    /// Hyperparameter overrides, e.g. `--set batch_size=256,hidden=[64,64]`.
    #[arg(long = "set", value_name = "KEY=VALUE,...")]
    pub set: Vec<String>,
    /// `--option` and `--reward` settings.
    #[command(flatten)]
    pub env_options: EnvOptionArgs,
    /// Run directory (default runs/<env>-<algo>-seed<seed>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Start from a trained policy (fine-tuning); warm-up defaults to 0 steps then. Any policy
    /// reference: a checkpoint or a run directory (its newest checkpoint) continues every
    /// network; a budget policy, a committed result run or an exported policy gives the actor
    /// alone, and the critics start afresh.
    #[arg(long, value_name = "RUN_DIR|CHECKPOINT|POLICY")]
    pub init_from: Option<PathBuf>,
    /// With --init-from RUN_DIR: the actor the run saved at this step budget.
    #[arg(long, requires = "init_from")]
    pub init_budget: Option<u64>,
    /// Continue a stopped run from its newest checkpoint.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["env", "algo", "set", "options", "reward", "env_config", "init_from", "out"])]
    pub resume: Option<PathBuf>,
    /// Replace an existing run directory.
    #[arg(long)]
    pub force: bool,
    /// If --out already holds this same run (same env, options, hyperparameters and seed),
    /// continue it instead of refusing; a finished run is left as it is. What sweep jobs use,
    /// so that a requeued or resubmitted job never starts over.
    #[arg(long, conflicts_with = "force")]
    pub resume_if_exists: bool,
    /// Hide the progress bar.
    #[arg(long)]
    pub quiet: bool,
    /// Also write a rerun recording (learning curves and an evaluation rollout at every
    /// evaluation), e.g. `--record training.rrd`.
    #[arg(long, value_name = "FILE.rrd")]
    pub record: Option<PathBuf>,
    /// Film the deterministic evaluation episode at every N-th evaluation into the run's
    /// videos/eval-step-<STEP>.mp4 (320x240, rendered offscreen on an env of its own: the run's
    /// numbers are the same with or without).
    #[arg(long, value_name = "N")]
    pub video_every: Option<u64>,
    /// Write TensorBoard event files into DIR: every metrics.csv value as a scalar
    /// (`tensorboard --logdir DIR`; `wandb sync --sync-tensorboard DIR` for Weights & Biases).
    #[arg(long, value_name = "DIR")]
    pub tensorboard: Option<PathBuf>,
    /// With --record: a rollout at every N-th evaluation only (the curves are always complete).
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub record_every: u64,
    /// 2: the large layers of each update run on two cores (same results, bit for bit); 1: one
    /// core, for running several trainings side by side. Default: 2 on a machine with 2 or
    /// more cores.
    #[arg(long, value_name = "1|2", value_parser = clap::value_parser!(u8).range(1..=2))]
    pub threads: Option<u8>,
    /// Where the networks train: cpu (the exact fused path), or cuda / cuda:N (a GPU, through
    /// the device-generic path; needs a build with the `cuda` feature, docs/gpu.md). TD3, DDPG,
    /// SAC and CrossQ.
    #[arg(long, default_value = "cpu", value_name = "cpu|cuda[:N]")]
    pub device: crate::device::ComputeDevice,
}

impl Default for TrainArgs {
    /// What `train` reads when a flag is not given.
    fn default() -> Self {
        TrainArgs {
            env: None,
            algo: None,
            seed: SeedArg::default(),
            steps: None,
            set: Vec::new(),
            env_options: EnvOptionArgs::default(),
            out: None,
            init_from: None,
            init_budget: None,
            resume: None,
            force: false,
            resume_if_exists: false,
            quiet: false,
            record: None,
            video_every: None,
            tensorboard: None,
            record_every: 1,
            threads: None,
            device: crate::device::ComputeDevice::Cpu,
        }
    }
}

impl TrainArgs {
    /// The command line (`train ...`, without the program) that parses back into `self`.
    pub(crate) fn to_args(&self) -> Vec<String> {
        let mut a: Vec<String> = vec!["train".into()];
        let mut push = |flag: &str, value: String| a.extend([flag.to_string(), value]);
        if let Some(env) = &self.env {
            push("--env", env.clone());
        }
        if let Some(algo) = &self.algo {
            push("--algo", algo.clone());
        }
        push("--seed", self.seed.seed.to_string());
        if let Some(n) = self.steps {
            push("--steps", n.to_string());
        }
        if let Some(r) = &self.env_options.reward {
            push("--reward", r.clone());
        }
        for s in &self.set {
            push("--set", s.clone());
        }
        if let Some(path) = &self.env_options.env_config {
            push("--env-config", path.display().to_string());
        }
        for o in &self.env_options.options {
            push("--option", o.clone());
        }
        for (flag, path) in [("--out", &self.out), ("--init-from", &self.init_from), ("--resume", &self.resume)] {
            if let Some(p) = path {
                push(flag, p.display().to_string());
            }
        }
        if let Some(b) = self.init_budget {
            push("--init-budget", b.to_string());
        }
        if let Some(r) = &self.record {
            push("--record", r.display().to_string());
        }
        if let Some(d) = &self.tensorboard {
            push("--tensorboard", d.display().to_string());
        }
        if let Some(n) = self.video_every {
            push("--video-every", n.to_string());
        }
        if self.record_every != 1 {
            push("--record-every", self.record_every.to_string());
        }
        if let Some(t) = self.threads {
            push("--threads", t.to_string());
        }
        if self.device != crate::device::ComputeDevice::Cpu {
            push("--device", self.device.to_string());
        }
        for (flag, on) in
            [("--force", self.force), ("--resume-if-exists", self.resume_if_exists), ("--quiet", self.quiet)]
        {
            if on {
                a.push(flag.to_string());
            }
        }
        a
    }

    /// Parses `train ...` arguments (as `to_args` writes them) without the rest of the CLI.
    #[cfg(test)]
    pub(crate) fn parse_from(args: &[String]) -> Result<TrainArgs> {
        use clap::{Args, FromArgMatches};
        let command = TrainArgs::augment_args(clap::Command::new("train"));
        let matches = command.try_get_matches_from(args)?;
        Ok(TrainArgs::from_arg_matches(&matches)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn train_arguments_round_trip_through_the_command_line() {
        let full = TrainArgs {
            env: Some("minitaur".into()),
            algo: Some("td3".into()),
            seed: SeedArg { seed: 7 },
            steps: Some(300_000),
            set: vec!["hidden=[64,64],tau=0.01".into(), "batch_size=32".into()],
            env_options: EnvOptionArgs {
                env_config: Some("my env.toml".into()),
                options: vec!["max_episode_steps=500".into()],
                reward: Some("drift=0.25,shake=0.1".into()),
            },
            out: Some("runs/a b".into()),
            init_from: Some("runs/x/checkpoints/step_000001000".into()),
            quiet: true,
            record: Some("t.rrd".into()),
            record_every: 3,
            threads: Some(1),
            device: crate::device::ComputeDevice::Cuda(1),
            resume_if_exists: true,
            ..TrainArgs::default()
        };
        let resume = TrainArgs { resume: Some("runs/a".into()), steps: Some(10), ..TrainArgs::default() };
        for args in [full, resume] {
            let line = args.to_args();
            let parsed = TrainArgs::parse_from(&line).unwrap();
            assert_eq!(parsed, args, "{line:?}");
        }
        // What clap refuses, parse_from refuses too.
        let bad = ["train", "--resume", "r", "--env", "ant"].map(String::from);
        assert!(TrainArgs::parse_from(&bad).is_err());
    }
}
