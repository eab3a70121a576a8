//! Training runs. This file checks a new run, writes nothing until it is sound, and hands it to
//! one of the two loops: `off_policy.rs` (TD3, DDPG, SAC, CrossQ, the branching DQN) or
//! `on_policy.rs` (PPO); each holds its loop and its resume. What both loops share is in
//! `scaffold.rs`, what a caller sets and gets back in `control.rs`.
//!
//! Run directory: `config.toml` (every hyperparameter, env options, seed, crate version, git
//! commit), `metrics.csv`, `provenance.csv` (the machine of every stretch), `checkpoints/`.
//! Everything is written atomically.
mod buffer_file;
pub mod checkpoint;
pub mod config;
pub mod control;
pub mod evaluate;
pub(crate) mod fault;
pub mod metrics;
mod off_policy;
mod on_policy;
pub mod policy_ref;
pub mod provenance;
mod recording;
pub mod run_config;
pub mod run_dir;
pub(crate) mod run_lock;
mod scaffold;
pub mod seeds;
pub mod selection;
pub mod stop;
mod tensorboard;

use std::path::Path;

use anyhow::{bail, Context, Result};

use crate::agents::TrainConfig;
use crate::envs::EnvConfig;
use crate::io::write_bytes_atomic;

pub use checkpoint::budget_policy_steps;
pub(crate) use checkpoint::{budget_policy_path, POLICY_BUDGETS};
pub use control::{EvaluationEvent, EvaluationHook, Outcome, RunControl, RunSummary};
pub use policy_ref::{resolve_policy, PolicyRef};
pub(crate) use provenance::git_commit;
pub use run_config::{read_run_config, RunConfig};
pub use run_dir::{
    export_policy, has_policy, import_policy, load_budget_policy, load_policy, run_progress, RunProgress,
};

/// Starts a new run in `run_dir`. An existing non-empty directory is an error unless `force`.
pub fn train(
    env: EnvConfig,
    train: TrainConfig,
    seed: u64,
    run_dir: &Path,
    init_from: Option<&Path>,
    force: bool,
    control: &RunControl,
) -> Result<RunSummary> {
    train.validate()?;
    if env.name == crate::envs::notch::NAME && train.algo != crate::agents::Algo::Dqn {
        bail!(
            "{} moves joint targets by notches (down, hold, up): only the branching DQN (--algo dqn) acts in it, \
             not {}",
            env.name,
            train.algo.name()
        );
    }
    let mut env = env;
    env.options = env.resolved_options()?;
    // Before --force may remove the directory under a running trainer.
    run_lock::refuse_if_running(run_dir)?;
    // A lock that no process holds and a half-written temporary file (a trainer killed before
    // it wrote its config) are no run.
    let holds_something = |dir: &Path| -> Result<bool> {
        Ok(std::fs::read_dir(dir)?.flatten().any(|e| {
            let name = e.file_name();
            name != run_lock::LOCK_FILE && !crate::io::is_temporary_name(&name.to_string_lossy())
        }))
    };
    if run_dir.exists() && holds_something(run_dir)? {
        if !force {
            bail!(
                "run directory {} already exists; use --force to overwrite it or --resume to continue it",
                run_dir.display()
            );
        }
        std::fs::remove_dir_all(run_dir).with_context(|| format!("removing {}", run_dir.display()))?;
    }
    // Any policy reference: a checkpoint fine-tunes every network, an actor alone (a budget or
    // exported policy) starts the critics afresh.
    let init = init_from.map(|p| resolve_policy(p, None)).transpose()?;
    let run = RunConfig {
        format: run_config::FORMAT,
        seed,
        crate_version: env!("CARGO_PKG_VERSION").to_string(),
        git_commit: git_commit(),
        init_from: init.as_ref().map(|p| p.path().display().to_string()),
        env,
        train,
    };
    if run.train.algo.is_on_policy() {
        on_policy::train(run_dir, &run, init.as_ref(), control)
    } else {
        off_policy::train(run_dir, &run, init.as_ref(), control)
    }
}

/// Raises a run's step budget so that `resume` trains it on, e.g. a finished 100k run to 300k.
/// Nothing in training depends on the budget, so the result equals a run started with the larger
/// budget when the newest checkpoint ends an episode (HalfCheetah's 1000-step episodes at any
/// multiple of 1000); otherwise the episode in progress at that checkpoint is cut short there.
/// Returns whether the continuation is exact.
pub fn extend(run_dir: &Path, total_steps: u64) -> Result<bool> {
    let _lock = run_lock::RunLock::acquire(run_dir)?;
    let mut run = read_run_config(run_dir)?;
    if total_steps < run.train.total_steps {
        bail!(
            "{} already has a budget of {} steps; --steps {total_steps} would shorten it",
            run_dir.display(),
            run.train.total_steps
        );
    }
    // No checkpoint yet: the resume starts the run afresh, with the larger budget from the start.
    let exact = if checkpoint::any(run_dir) {
        checkpoint::load_state(&checkpoint::newest_intact(run_dir, trainer_file(&run))?)?.at_episode_boundary
    } else {
        true
    };
    run.train.total_steps = total_steps;
    write_bytes_atomic(&run_dir.join("config.toml"), run.to_toml()?.as_bytes())?;
    Ok(exact)
}

/// The file a checkpoint of this run needs besides the networks to resume.
fn trainer_file(run: &RunConfig) -> &'static str {
    if run.train.algo.is_on_policy() {
        on_policy::ROLLOUT_FILE
    } else {
        checkpoint::BUFFER_FILE
    }
}

/// Continues a run from its newest intact checkpoint (`checkpoint::newest_intact`). A run with
/// no checkpoint yet (stopped before its first) starts afresh from its `config.toml`, which is
/// what an unbroken run computes too.
pub fn resume(run_dir: &Path, control: &RunControl) -> Result<RunSummary> {
    let run = read_run_config(run_dir)?;
    if !checkpoint::any(run_dir)
        && (run_dir.join(checkpoint::POLICY_FILE).is_file() || !budget_policy_steps(run_dir).is_empty())
    {
        bail!(
            "{} has no checkpoint to resume from: it holds a policy without its training state (an exported policy, \
             or a result kept without checkpoints); train anew into another --out (it can --init-from this one)",
            run_dir.display()
        );
    }
    let lock = run_lock::RunLock::acquire(run_dir)?;
    if !checkpoint::any(run_dir) {
        eprintln!(
            "{} has no checkpoint yet (it stopped before its first): starting it afresh from its config.toml",
            run_dir.display()
        );
        drop(lock);
        let init_from = run.init_from.as_deref().map(Path::new);
        return train(run.env, run.train, run.seed, run_dir, init_from, true, control);
    }
    // Everything is checked before anything is changed: a resume that stops on bad input leaves
    // the run directory as it found it.
    let ckpt = checkpoint::newest_intact(run_dir, trainer_file(&run))?;
    let saved = checkpoint::load_state(&ckpt)?;
    let metrics = metrics::restore(run_dir, &ckpt, saved.step)?;
    checkpoint::remove_leftovers(run_dir)?;
    checkpoint::prune_buffers(run_dir)?;
    checkpoint::make_latest(run_dir, &ckpt)?;
    if saved.step >= run.train.total_steps {
        return Ok(RunSummary {
            run_dir: run_dir.to_path_buf(),
            outcome: Outcome::AlreadyFinished,
            steps: saved.step,
            last_eval: None,
            best_eval_mean: saved.best_eval_mean,
            checkpoint: ckpt,
        });
    }
    if run.train.algo.is_on_policy() {
        on_policy::resume(run_dir, &run, &ckpt, metrics, control)
    } else {
        off_policy::resume(run_dir, &run, &ckpt, metrics, control)
    }
}
