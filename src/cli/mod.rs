//! The `locobench` command line.
mod baseline;
mod device;
mod docgen;
mod docs;
mod envs;
mod eval;
mod export;
mod record;
mod report;
mod robustness;
mod rollout;
mod sweep;
mod track;
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
    #[command(after_help = "Example:\n  locobench envs")]
    Envs,
    /// Run a simple policy (random, zero, or recorded actions) and write every step to CSV.
    #[command(
        after_help = "Example:\n  locobench rollout --env ant --policy random --episodes 2 --seed 0 --out ant.csv"
    )]
    Rollout(rollout::RolloutArgs),
    /// Train TD3, SAC, DDPG, CrossQ, PPO or a branching DQN; resume a run; fine-tune a checkpoint.
    #[command(
        after_help = "Example:\n  locobench train --env inverted-pendulum --algo sac --seed 0 --out runs/pendulum-sac"
    )]
    Train(train::TrainArgs),
    /// Evaluate a checkpoint: mean and std of the return and of every reward term.
    #[command(after_help = "Example:\n  locobench eval --policy models/policies/minitaur-td3 --episodes 50 --seed 0")]
    Eval(eval::EvalArgs),
    /// Write a run's policy alone (actor weights, config, metrics) to share or ship.
    #[command(after_help = "Example:\n  locobench export --policy runs/pendulum-sac --out my-policy")]
    Export(export::ExportArgs),
    /// Run the Raibert/QP baseline controller and report how it walks.
    #[command(after_help = "Example:\n  locobench baseline --env minitaur --speed 0.5,1.0,1.5 --episodes 50 --seed 0")]
    Baseline(baseline::BaselineArgs),
    /// How closely the controller or a policy follows velocity commands on a command task.
    #[command(
        after_help = "Example:\n  locobench track --env minitaur-command --speeds 0.25,0.5,1.0,1.5 --yaw-rates -0.3,0,0.3 --episodes 10"
    )]
    Track(track::TrackArgs),
    /// Write a rerun recording (.rrd) of a policy's rollouts: checkpoint, raibert, random, zero.
    #[command(
        after_help = "Example:\n  locobench record --env minitaur --policy raibert --speed 1.0 --out minitaur.rrd"
    )]
    Record(record::RecordArgs),
    /// Write an HTML + Markdown report of runs: learning curves, baseline vs RL.
    #[command(
        after_help = "Example:\n  locobench report --runs models/policies/minitaur-td3 --out report --episodes 10"
    )]
    Report(report::ReportArgs),
    /// The robustness suite: the controller and trained policies under the same perturbations.
    #[command(
        after_help = "Example:\n  locobench robustness --env minitaur --policy ppo=models/policies/minitaur-ppo --episodes 50 --seed 100 --out robustness/"
    )]
    Robustness(robustness::RobustnessArgs),
    /// Train a grid of reward weights x algorithms x seeds, each job a separate process.
    #[command(
        after_help = "Example:\n  locobench sweep --env inverted-pendulum --algo td3,ddpg --seeds 2 --jobs 2 --out sweeps/pendulum"
    )]
    Sweep(sweep::SweepArgs),
    /// Rewrite the generated sections of README.md and docs/ from the committed result files.
    Docs(docs::DocsArgs),
    /// GPU checks: the device-generic path against the fused CPU path, and update speed.
    #[command(
        after_help = "Examples:\n  locobench device check --device cuda\n  locobench device speed --algo crossq --device cuda --critic-hidden 2048,2048"
    )]
    Device(device::DeviceArgs),
}

pub fn run() -> Result<()> {
    match Cli::parse().command {
        Command::Envs => envs::run(),
        Command::Rollout(args) => rollout::run(args),
        Command::Train(args) => train::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Export(args) => export::run(args),
        Command::Baseline(args) => baseline::run(args),
        Command::Track(args) => track::run(args),
        Command::Record(args) => record::run(args),
        Command::Report(args) => report::run(args),
        Command::Sweep(args) => sweep::run(args),
        Command::Robustness(args) => robustness::run(args),
        Command::Docs(args) => docs::run(args),
        Command::Device(args) => device::run(args),
    }
}

/// Prints a deprecation note when the command line uses an old spelling of a flag.
fn deprecated_flag(old: &str, new: &str) {
    if std::env::args().any(|a| a == old || a.starts_with(&format!("{old}="))) {
        eprintln!("note: {old} is deprecated; use {new} (same meaning)");
    }
}

pub use locobench::args::{EnvArgs, EnvOptionArgs, SeedArg};
