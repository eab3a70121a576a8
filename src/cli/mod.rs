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

pub use locobench::args::{EnvArgs, EnvOptionArgs, SeedArg};
