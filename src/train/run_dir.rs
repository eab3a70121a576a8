//! Reading a run directory from its files (no process needed): how far it has got, which
//! checkpoint a path means, the policy it holds, and exporting that policy. Starting, resuming
//! and the loop itself live in `train/mod.rs`; the config file format in `run_config.rs`.
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::agents::{make_agent, Agent};
use crate::envs::make;
use crate::io::write_bytes_atomic;

use super::seeds::init_rng;
use super::{checkpoint, metrics, read_run_config, RunConfig};

/// How far a run directory has got, from its files alone (no process needed).
#[derive(Debug, Clone, PartialEq)]
pub struct RunProgress {
    /// The run's step budget.
    pub total_steps: u64,
    /// Steps of the newest checkpoint (what a resume starts from).
    pub checkpoint_step: Option<u64>,
    /// Newest step in metrics.csv (written at every evaluation, so ahead of the checkpoint
    /// while a run trains).
    pub metrics_step: Option<u64>,
    /// The latest evaluation mean.
    pub last_eval: Option<f64>,
}

impl RunProgress {
    /// The newest checkpoint is at the budget; or, for results kept without checkpoints
    /// (config.toml + metrics.csv, as under benches/results), the metrics reach it.
    pub fn finished(&self) -> bool {
        match self.checkpoint_step {
            Some(step) => step >= self.total_steps,
            None => self.metrics_step.is_some_and(|s| s >= self.total_steps),
        }
    }

    /// The newest step on disk (checkpoint or metrics).
    pub fn step(&self) -> u64 {
        self.checkpoint_step.max(self.metrics_step).unwrap_or(0)
    }
}

/// Reads a run directory's progress; fails when it has no `config.toml`.
pub fn run_progress(run_dir: &Path) -> Result<RunProgress> {
    let run = read_run_config(run_dir)?;
    let checkpoint_step =
        checkpoint::latest(run_dir).ok().and_then(|c| checkpoint::load_state(&c).ok()).map(|s| s.step);
    let rows = metrics::read(&run_dir.join("metrics.csv")).unwrap_or_default();
    Ok(RunProgress {
        total_steps: run.train.total_steps,
        checkpoint_step,
        metrics_step: rows.iter().map(|r| r.step).max(),
        last_eval: rows.iter().rev().find_map(|r| r.eval_mean),
    })
}

/// Accepts a checkpoint directory or a run directory (meaning its newest checkpoint).
pub fn resolve_checkpoint(path: &Path) -> Result<PathBuf> {
    if path.join("model.safetensors").exists() {
        Ok(path.to_path_buf())
    } else if path.join("checkpoints").exists() {
        checkpoint::latest(path)
    } else if path.file_name().is_some_and(|n| n == "model.safetensors") && path.exists() {
        Ok(path.parent().unwrap().to_path_buf())
    } else {
        bail!(
            "no checkpoint at {} (expected a checkpoint directory with model.safetensors, or a run directory)",
            path.display()
        )
    }
}

/// Writes a run's policy for sharing: `policy.safetensors` (the actor's weights only, a few
/// hundred KB where a checkpoint with critics, targets and optimiser state is several MB, or GB
/// with its buffer), the run's `config.toml` and `metrics.csv`. `eval`, `record` and `report`
/// take the directory like a run directory.
pub fn export_policy(checkpoint: &Path, out: &Path) -> Result<PathBuf> {
    let ckpt = resolve_checkpoint(checkpoint)?;
    let run_dir = ckpt.parent().and_then(Path::parent).context("checkpoint is not inside a run directory")?;
    let (_, agent) = load_policy(&ckpt)?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    checkpoint::save_actor(&out.join(checkpoint::POLICY_FILE), agent.as_ref())?;
    for file in ["config.toml", "metrics.csv"] {
        let bytes =
            std::fs::read(run_dir.join(file)).with_context(|| format!("reading {}", run_dir.join(file).display()))?;
        write_bytes_atomic(&out.join(file), &bytes)?;
    }
    let state = checkpoint::load_state(&ckpt)?;
    write_bytes_atomic(
        &out.join("source.toml"),
        format!("checkpoint = {:?}\nstep = {}\n", ckpt.display().to_string(), state.step).as_bytes(),
    )?;
    Ok(out.join(checkpoint::POLICY_FILE))
}

/// Whether a run directory (or exported policy) holds weights to act with.
pub fn has_policy(dir: &Path) -> bool {
    dir.join(checkpoint::POLICY_FILE).is_file() || dir.join("checkpoints").join("latest").is_file()
}

/// Builds the agent of a run and loads a checkpoint's weights into it. Also takes an exported
/// policy directory (`export_policy`): only the actor is loaded then, which is all acting needs.
pub fn load_policy(checkpoint: &Path) -> Result<(RunConfig, Box<dyn Agent>)> {
    if checkpoint.join(checkpoint::POLICY_FILE).is_file() {
        let (run, agent) = run_agent(checkpoint)?;
        checkpoint::load_actor(&checkpoint.join(checkpoint::POLICY_FILE), agent.as_ref())?;
        return Ok((run, agent));
    }
    let ckpt = resolve_checkpoint(checkpoint)?;
    let run_dir = ckpt.parent().and_then(Path::parent).context("checkpoint is not inside a run directory")?;
    let (run, agent) = run_agent(run_dir)?;
    checkpoint::load_weights(&ckpt, agent.as_ref())?;
    Ok((run, agent))
}

/// The actor a run wrote when it passed `step` (`train::POLICY_BUDGETS`, or its last step).
pub fn load_budget_policy(run_dir: &Path, step: u64) -> Result<(RunConfig, Box<dyn Agent>)> {
    let file = super::budget_policy_path(run_dir, step);
    if !file.is_file() {
        bail!("{} has no policy at step {step} (expected {})", run_dir.display(), file.display());
    }
    let (run, agent) = run_agent(run_dir)?;
    checkpoint::load_actor(&file, agent.as_ref())?;
    Ok((run, agent))
}

/// The steps at which a run directory holds a policy file (`policies/step-<N>.safetensors`).
pub fn budget_policy_steps(run_dir: &Path) -> Vec<u64> {
    let mut steps: Vec<u64> = std::fs::read_dir(run_dir.join(super::BUDGET_POLICY_DIR))
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            name.strip_prefix("step-")?.strip_suffix(".safetensors")?.parse().ok()
        })
        .collect();
    steps.sort_unstable();
    steps
}

/// The config of the run in `dir` and a freshly initialised agent of its shape.
fn run_agent(dir: &Path) -> Result<(RunConfig, Box<dyn Agent>)> {
    let run = read_run_config(dir)?;
    let env = make(&run.env)?;
    let (obs_dim, act_dim) = (env.spec().observation_space.dim(), env.spec().action_space.dim());
    let agent = make_agent(&run.train, obs_dim, act_dim, &mut init_rng(run.seed))?;
    Ok((run, agent))
}
