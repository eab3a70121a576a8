//! Checkpoints: `checkpoints/step_<N>/` holds `model.safetensors` (every network, targets
//! included), `optim.safetensors` (Adam moments), `state.toml` (counters, RNG position) and the
//! trainer's own state: `buffer.safetensors` (the off-policy replay buffer, only in the newest
//! checkpoint) or `rollout.safetensors` (PPO: where the environment copies and the reward
//! statistics stand). A checkpoint directory is
//! assembled under a temporary name and renamed into place, so a crash never leaves half of one.
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::agents::buffer::ReplayBuffer;
use crate::agents::Agent;
use crate::io::write_bytes_atomic;

use super::seeds::RngState;

/// Where a run stands, besides the tensors.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainState {
    /// Environment steps done.
    pub step: u64,
    /// Training episodes started so far (the next one gets this index).
    pub episodes: u64,
    /// True when saved at an episode boundary: resuming then continues exactly.
    pub at_episode_boundary: bool,
    /// Seconds trained so far, over every stretch.
    pub wall_time: f64,
    /// The training stream's position.
    pub rng: RngState,
    /// Each optimiser's update count.
    pub optimizer_steps: HashMap<String, u64>,
    /// The agent's counters (`Agent::counters`).
    pub counters: HashMap<String, u64>,
}

/// An exported policy: the actor's tensors only (`train::export_policy`).
pub(crate) const POLICY_FILE: &str = "policy.safetensors";

fn is_actor(name: &str) -> bool {
    name.starts_with("actor.")
}

/// Writes the actor's tensors (not its target) atomically.
pub(crate) fn save_actor(path: &Path, agent: &dyn Agent) -> Result<()> {
    let params: HashMap<String, Tensor> =
        agent.parameters().into_iter().filter(|(n, _)| is_actor(n)).map(|(n, v)| (n, v.as_tensor().clone())).collect();
    anyhow::ensure!(!params.is_empty(), "this agent has no actor to export");
    let dir = path.parent().unwrap_or(Path::new("."));
    let tmp = tempfile::Builder::new().prefix(".policy-").suffix(".safetensors").tempfile_in(dir)?;
    candle_core::safetensors::save(&params, tmp.path())?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file().set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.persist(path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Loads an exported actor into `agent`, checking every actor tensor's name and shape; the
/// agent's other networks keep their initial weights (acting does not use them).
pub(crate) fn load_actor(path: &Path, agent: &dyn Agent) -> Result<()> {
    let tensors = read_tensors(path)?;
    for (name, var) in agent.parameters().into_iter().filter(|(n, _)| is_actor(n)) {
        let t = tensors.get(&name).with_context(|| {
            format!("{} has no tensor '{name}': was it exported from another algorithm?", path.display())
        })?;
        anyhow::ensure!(
            t.dims() == var.dims(),
            "{} tensor '{name}' has shape {:?} but this agent needs {:?}",
            path.display(),
            t.dims(),
            var.dims()
        );
        var.set(&t.to_dtype(var.dtype())?)?;
    }
    Ok(())
}

pub(crate) fn checkpoints_dir(run_dir: &Path) -> PathBuf {
    run_dir.join("checkpoints")
}

/// Writes a checkpoint for `state.step` and makes it the latest. Older checkpoints keep their
/// weights but lose their replay buffer (the only large file).
pub fn save(run_dir: &Path, agent: &mut dyn Agent, buffer: &ReplayBuffer, state: &TrainState) -> Result<PathBuf> {
    save_with(run_dir, agent, state, |dir| super::buffer_file::write(buffer, &dir.join("buffer.safetensors")))
}

/// Writes a checkpoint like [`save`], with `trainer_files` writing the trainer's own state into
/// the checkpoint directory before it becomes visible.
pub(crate) fn save_with(
    run_dir: &Path,
    agent: &mut dyn Agent,
    state: &TrainState,
    trainer_files: impl FnOnce(&Path) -> Result<()>,
) -> Result<PathBuf> {
    let root = checkpoints_dir(run_dir);
    std::fs::create_dir_all(&root)?;
    let name = format!("step_{:09}", state.step);
    let tmp = tempfile::Builder::new().prefix(".incomplete-").tempdir_in(&root)?;

    let params: HashMap<String, Tensor> =
        agent.parameters().into_iter().map(|(n, v)| (n, v.as_tensor().clone())).collect();
    candle_core::safetensors::save(&params, tmp.path().join("model.safetensors"))?;

    let mut optim = HashMap::new();
    let mut optimizer_steps = HashMap::new();
    for (name, opt) in agent.optimizers() {
        let (tensors, steps) = opt.state(name)?;
        optim.extend(tensors);
        optimizer_steps.insert(name.to_string(), steps);
    }
    candle_core::safetensors::save(&optim, tmp.path().join("optim.safetensors"))?;
    trainer_files(tmp.path())?;

    let state = TrainState {
        optimizer_steps,
        counters: agent.counters().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
        ..state.clone()
    };
    std::fs::write(tmp.path().join("state.toml"), toml::to_string(&state)?)?;

    let dest = root.join(&name);
    if dest.exists() {
        std::fs::remove_dir_all(&dest)?;
    }
    let tmp_path = tmp.keep();
    std::fs::rename(&tmp_path, &dest).with_context(|| format!("moving checkpoint into {}", dest.display()))?;
    write_bytes_atomic(&root.join("latest"), name.as_bytes())?;
    for entry in std::fs::read_dir(&root)?.flatten() {
        let p = entry.path();
        if p != dest && p.is_dir() && entry.file_name().to_string_lossy().starts_with("step_") {
            let _ = std::fs::remove_file(p.join("buffer.safetensors"));
        }
    }
    Ok(dest)
}

/// The newest checkpoint of a run.
pub fn latest(run_dir: &Path) -> Result<PathBuf> {
    let root = checkpoints_dir(run_dir);
    let name = std::fs::read_to_string(root.join("latest"))
        .with_context(|| format!("{} has no checkpoint (missing checkpoints/latest)", run_dir.display()))?;
    Ok(root.join(name.trim()))
}

fn read_tensors(path: &Path) -> Result<HashMap<String, Tensor>> {
    if !path.exists() {
        bail!("checkpoint file {} is missing", path.display());
    }
    candle_core::safetensors::load(path, &Device::Cpu)
        .with_context(|| format!("checkpoint file {} is corrupt or unreadable", path.display()))
}

/// Loads network weights into `agent`, checking every name and shape.
pub(crate) fn load_weights(checkpoint: &Path, agent: &dyn Agent) -> Result<()> {
    let tensors = read_tensors(&checkpoint.join("model.safetensors"))?;
    let params = agent.parameters();
    if let Some((name, _)) = params.iter().find(|(n, _)| !tensors.contains_key(n)) {
        bail!("checkpoint {} has no tensor '{name}': was it written by another algorithm?", checkpoint.display());
    }
    for (name, var) in params {
        let t = &tensors[&name];
        if t.dims() != var.dims() {
            bail!(
                "checkpoint tensor '{name}' has shape {:?} but this agent needs {:?}: the checkpoint was trained with \
                 different observation/action sizes or network sizes",
                t.dims(),
                var.dims()
            );
        }
        var.set(&t.to_dtype(var.dtype())?)?;
    }
    Ok(())
}

/// Reads a checkpoint's `state.toml`.
pub fn load_state(checkpoint: &Path) -> Result<TrainState> {
    let path = checkpoint.join("state.toml");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("{} is corrupt", path.display()))
}

/// Restores weights, optimiser moments and counters, and returns the saved state and buffer.
pub(crate) fn load_all(checkpoint: &Path, agent: &mut dyn Agent) -> Result<(TrainState, ReplayBuffer)> {
    let state = load_training(checkpoint, agent)?;
    let buffer = super::buffer_file::read(&checkpoint.join("buffer.safetensors"))?;
    Ok((state, buffer))
}

/// Restores weights, optimiser moments and counters, and returns the saved state.
pub(crate) fn load_training(checkpoint: &Path, agent: &mut dyn Agent) -> Result<TrainState> {
    load_weights(checkpoint, agent)?;
    let state = load_state(checkpoint)?;
    let optim = read_tensors(&checkpoint.join("optim.safetensors"))?;
    for (name, opt) in agent.optimizers() {
        let steps =
            *state.optimizer_steps.get(name).with_context(|| format!("state.toml lacks the step count of {name}"))?;
        opt.load_state(name, &optim, steps)?;
    }
    for (name, value) in &state.counters {
        agent.set_counter(name, *value);
    }
    Ok(state)
}

/// Reads a checkpoint's tensor file other than the network's (a trainer's own state).
pub(crate) fn read_trainer_file(checkpoint: &Path, name: &str) -> Result<HashMap<String, Tensor>> {
    read_tensors(&checkpoint.join(name))
}
