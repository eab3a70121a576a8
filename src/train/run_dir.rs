//! Reading a run directory from its files (no process needed): how far it has got, which
//! checkpoint a path means, the policy it holds, and exporting that policy. Starting and resuming
//! live in `train/mod.rs`, the loops in `off_policy.rs` and `on_policy.rs`, the config file
//! format in `run_config.rs`.
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use crate::agents::{make_agent, Agent};
use crate::io::write_bytes_atomic;

use super::checkpoint::{budget_policy_path, budget_policy_steps};
use super::policy_ref::{resolve_policy, PolicyRef};
use super::run_config::{read_run_config, RunConfig};
use super::seeds::init_rng;
use super::{checkpoint, metrics};
use crate::envs::make;

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

/// Writes a policy for sharing: `policy.safetensors` (the actor's weights only, a few hundred KB
/// where a checkpoint with critics, targets and optimiser state is several MB, or GB with its
/// buffer), the run's `config.toml` and `metrics.csv`, and `source.toml` (what it was exported
/// from, and its step). `policy` and `budget` are a policy reference
/// ([`super::policy_ref::resolve_policy`]): a run directory (with a budget, or its newest
/// policy), a committed result run, a checkpoint, a budget policy file or an exported policy.
/// `eval`, `record` and `report` take the directory like a run directory.
pub fn export_policy(policy: &Path, budget: Option<u64>, out: &Path) -> Result<PathBuf> {
    let source = resolve_policy(policy, budget)?;
    let run_dir = source.run_dir()?;
    if out.exists() && same_dir(out, &run_dir) {
        bail!("--out {} is the policy's own directory; export into another", out.display());
    }
    let (_, agent) = source.load()?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    checkpoint::save_actor(&out.join(checkpoint::POLICY_FILE), agent.as_ref())?;
    let config = run_dir.join("config.toml");
    let bytes = std::fs::read(&config).with_context(|| format!("reading {}", config.display()))?;
    write_bytes_atomic(&out.join("config.toml"), &bytes)?;
    let metrics = run_dir.join("metrics.csv");
    if metrics.is_file() {
        let bytes = std::fs::read(&metrics).with_context(|| format!("reading {}", metrics.display()))?;
        write_bytes_atomic(&out.join("metrics.csv"), &bytes)?;
    }
    let mut text = format!("source = {:?}\n", source.path().display().to_string());
    if let Some(step) = source.step() {
        text.push_str(&format!("step = {step}\n"));
    }
    write_bytes_atomic(&out.join("source.toml"), text.as_bytes())?;
    Ok(out.join(checkpoint::POLICY_FILE))
}

/// Writes a policy trained elsewhere (`locobench.import_sb3`) as an exported policy in `out`:
/// `policy.safetensors` from `tensors` (the actor's, by locobench's names), `config.toml` from
/// `config` (a run config naming the env and the agent's shape) and `source.toml` from `source`.
/// Every tensor is checked against the agent the config builds, by name and shape, before
/// anything is written; `out` must not hold a policy already.
pub fn import_policy(
    out: &Path,
    tensors: std::collections::HashMap<String, candle_core::Tensor>,
    config: &str,
    source: &str,
) -> Result<PathBuf> {
    let run = RunConfig::parse(config, &out.join("config.toml"))?;
    if has_policy(out) {
        bail!("{} already holds a policy; import into another directory", out.display());
    }
    let env = make(&run.env)?;
    let (obs_dim, act_dim) = (env.spec().observation_space.dim(), env.spec().action_space.dim());
    let agent = make_agent(&run.train, obs_dim, act_dim, &mut init_rng(run.seed))?;
    let actor: Vec<(String, candle_core::Var)> =
        agent.parameters().into_iter().filter(|(n, _)| n.starts_with("actor.")).collect();
    for (name, var) in &actor {
        let t = tensors.get(name).with_context(|| format!("the imported policy lacks the tensor {name}"))?;
        if t.dims() != var.dims() {
            bail!(
                "the imported tensor {name} has shape {:?}, but a {} policy for {} ({obs_dim} observations, {act_dim} \
                 actions) needs {:?}",
                t.dims(),
                run.train.algo.name(),
                run.env.name,
                var.dims()
            );
        }
        var.set(&t.to_dtype(var.dtype())?)?;
    }
    if let Some(extra) = tensors.keys().find(|k| !actor.iter().any(|(n, _)| n == *k)) {
        bail!("the imported policy has a tensor {extra} that a {} actor does not have", run.train.algo.name());
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    checkpoint::save_actor(&out.join(checkpoint::POLICY_FILE), agent.as_ref())?;
    write_bytes_atomic(&out.join("config.toml"), run.to_toml()?.as_bytes())?;
    write_bytes_atomic(&out.join("source.toml"), source.as_bytes())?;
    Ok(out.join(checkpoint::POLICY_FILE))
}

fn same_dir(a: &Path, b: &Path) -> bool {
    matches!((a.canonicalize(), b.canonicalize()), (Ok(x), Ok(y)) if x == y)
}

/// Whether a run directory (or exported policy) holds weights to act with.
pub fn has_policy(dir: &Path) -> bool {
    dir.join(checkpoint::POLICY_FILE).is_file()
        || dir.join("checkpoints").join("latest").is_file()
        || !budget_policy_steps(dir).is_empty()
}

/// Builds the agent of a run and loads the policy `path` names into it (a policy reference
/// without a budget, [`super::policy_ref::resolve_policy`]): every network from a checkpoint, the
/// actor alone from an exported or budget policy, which is all acting needs.
pub fn load_policy(path: &Path) -> Result<(RunConfig, Box<dyn Agent>)> {
    resolve_policy(path, None)?.load()
}

/// The actor a run wrote when it passed `step` (`train::POLICY_BUDGETS`, or its last step).
pub fn load_budget_policy(run_dir: &Path, step: u64) -> Result<(RunConfig, Box<dyn Agent>)> {
    let file = budget_policy_path(run_dir, step);
    if !file.is_file() {
        bail!("{} has no policy at step {step} (expected {})", run_dir.display(), file.display());
    }
    PolicyRef::Budget { run_dir: run_dir.to_path_buf(), step }.load()
}
