//! Checkpoints: `checkpoints/step_<N>/` holds `model.safetensors` (every network, targets
//! included), `optim.safetensors` (Adam moments), `state.toml` (counters, RNG position, the
//! latest losses), `metrics.csv` (the run's rows up to step N) and the trainer's own state:
//! `buffer.safetensors` (the off-policy replay buffer, kept in the newest two checkpoints) or
//! `rollout.safetensors` (PPO: where the environment copies and the reward statistics stand).
//! `checksums.toml`, written last, holds every other file's length and CRC-32.
//!
//! A checkpoint directory is assembled under a temporary name, synced to disk and renamed into
//! place, so a crash never leaves half of one; the run's own `metrics.csv` is brought up to the
//! checkpoint before it, so it never lags the newest checkpoint. A resume takes the newest
//! checkpoint whose files match their checksums, and says so when it has to pass over a damaged
//! one ([`newest_intact`]).
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use candle_core::{Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::agents::common::buffer::ReplayBuffer;
use crate::agents::{Agent, Losses};
use crate::io::write_bytes_atomic;

use super::fault::{self, Point};
use super::metrics::{self, MetricsRow};
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
    /// Each optimiser's update count (ordered, so that the file is the same bytes every time).
    pub optimizer_steps: BTreeMap<String, u64>,
    /// The agent's counters (`Agent::counters`).
    pub counters: BTreeMap<String, u64>,
    /// The latest update's losses, which the next metrics rows carry until the next update
    /// (a delayed actor update keeps the actor's). Absent in checkpoints written before it.
    #[serde(default)]
    pub losses: Option<Losses>,
    /// The best in-training evaluation mean so far.
    #[serde(default)]
    pub best_eval_mean: Option<f64>,
    /// The actor `budget_policy = "best"` keeps so far (`train::selection`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub best_policy: Option<super::selection::Snapshot>,
}

/// The step budgets results are reported at (Henderson et al. 2018 and the TD3/SAC papers report
/// 100k-1M; Freeman's Minitaur result and the off-policy goals sit at 500k). A run writes its actor
/// at each one it passes, and at its own last step, to `policies/step-<N>.safetensors`, so a
/// report evaluates every run at the same budget even when some went further.
pub(crate) const POLICY_BUDGETS: [u64; 4] = [100_000, 300_000, 500_000, 1_000_000];
pub(crate) const BUDGET_POLICY_DIR: &str = "policies";

/// Where a run keeps its actor at `step`.
pub(crate) fn budget_policy_path(run_dir: &Path, step: u64) -> PathBuf {
    run_dir.join(BUDGET_POLICY_DIR).join(format!("step-{step}.safetensors"))
}

/// The steps at which a run directory holds a policy file (`policies/step-<N>.safetensors`).
pub fn budget_policy_steps(run_dir: &Path) -> Vec<u64> {
    policy_file_steps(run_dir, "step-")
}

/// The steps N of the files `policies/<prefix><N>.safetensors` in `run_dir`, in order.
pub(crate) fn policy_file_steps(run_dir: &Path, prefix: &str) -> Vec<u64> {
    let mut steps: Vec<u64> = std::fs::read_dir(run_dir.join(BUDGET_POLICY_DIR))
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            name.strip_prefix(prefix)?.strip_suffix(".safetensors")?.parse().ok()
        })
        .collect();
    steps.sort_unstable();
    steps
}

/// The file of a checkpoint that lists the others' lengths and checksums.
pub(crate) const CHECKSUMS_FILE: &str = "checksums.toml";
/// The off-policy trainer's replay buffer in a checkpoint.
pub(crate) const BUFFER_FILE: &str = "buffer.safetensors";
/// How many of the newest checkpoints keep their replay buffer: the newest, and the one a resume
/// falls back to when the newest is damaged.
const CHECKPOINTS_WITH_BUFFER: usize = 2;

/// An exported policy: the actor's tensors only (`train::export_policy`).
pub(crate) const POLICY_FILE: &str = "policy.safetensors";

/// A parameter as a CPU tensor (a copy from the GPU when it lives there), for writing.
fn host(name: String, var: &candle_core::Var) -> Result<(String, Tensor)> {
    Ok((name, var.as_tensor().to_device(&Device::Cpu)?))
}

fn is_actor(name: &str) -> bool {
    name.starts_with("actor.")
}

/// Writes the actor's tensors (not its target) atomically.
pub(crate) fn save_actor(path: &Path, agent: &dyn Agent) -> Result<()> {
    let params: HashMap<String, Tensor> =
        agent.parameters().into_iter().filter(|(n, _)| is_actor(n)).map(|(n, v)| host(n, &v)).collect::<Result<_>>()?;
    anyhow::ensure!(!params.is_empty(), "this agent has no actor to export");
    let dir = path.parent().unwrap_or(Path::new("."));
    let tmp = tempfile::Builder::new().prefix(".policy-").suffix(".safetensors").tempfile_in(dir)?;
    candle_core::safetensors::save(&params, tmp.path())?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        tmp.as_file().set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    tmp.as_file().sync_all()?;
    fault::reach(Point::BudgetPolicyWrite);
    tmp.persist(path).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// Loads an exported actor into `agent`, checking every actor tensor's name and shape; the
/// agent's other networks keep their initial weights (acting does not use them).
pub(crate) fn load_actor(path: &Path, agent: &dyn Agent) -> Result<()> {
    load_actor_with_inputs(path, agent, None)
}

/// Loads an exported actor into an agent whose observation extends the actor's: `inputs` is
/// (the actor's observation length, the agent's), the agent's having the extra entries at its end
/// (a command task's over its base env's). Every tensor along the observation is extended so that
/// the new inputs change nothing at first: a layer's weights from them are zero, and normalisation
/// statistics see them as standard inputs (mean and shift 0, variance and scale 1). With `inputs`
/// None this is [`load_actor`].
pub(crate) fn load_actor_with_inputs(path: &Path, agent: &dyn Agent, inputs: Option<(usize, usize)>) -> Result<()> {
    let tensors = read_tensors(path)?;
    for (name, var) in agent.parameters().into_iter().filter(|(n, _)| is_actor(n)) {
        let t = tensors.get(&name).with_context(|| {
            format!("{} has no tensor '{name}': was it exported from another algorithm?", path.display())
        })?;
        let widened = inputs.filter(|&(from, to)| {
            from < to
                && t.rank() == var.rank()
                && t.dims().last() == Some(&from)
                && var.dims().last() == Some(&to)
                && t.dims()[..t.rank() - 1] == var.dims()[..var.rank() - 1]
        });
        let t = match widened {
            Some((from, to)) => widen_inputs(&name, t, to - from)?,
            None => t.clone(),
        };
        anyhow::ensure!(
            t.dims() == var.dims(),
            "{} tensor '{name}' has shape {:?} but this agent needs {:?}",
            path.display(),
            tensors[&name].dims(),
            var.dims()
        );
        var.set(&t.to_dtype(var.dtype())?.to_device(var.device())?)?;
    }
    Ok(())
}

/// `t` with `appended` entries added along its last axis (the observation's): ones for a
/// variance, an inverse standard deviation or a scale, zeros for anything else (a weight, a mean,
/// a shift).
fn widen_inputs(name: &str, t: &Tensor, appended: usize) -> Result<Tensor> {
    let leaf = name.rsplit('.').next().unwrap_or(name);
    let fill = match leaf {
        "running_var" | "obs_var" | "obs_inv_std" | "scale" => 1.0,
        "weight" | "running_mean" | "obs_mean" | "bias" => 0.0,
        _ => bail!("actor tensor '{name}' runs along the observation, and there is no rule to extend it"),
    };
    let mut shape = t.dims().to_vec();
    *shape.last_mut().expect("a widened tensor has an axis") = appended;
    let extra = (Tensor::ones(shape, t.dtype(), t.device())? * fill)?;
    Ok(Tensor::cat(&[t, &extra], t.rank() - 1)?)
}

pub(crate) fn checkpoints_dir(run_dir: &Path) -> PathBuf {
    run_dir.join("checkpoints")
}

/// Writes a checkpoint for `state.step` and makes it the newest; `metrics` are the run's rows so
/// far. Older checkpoints keep their weights; all but the newest two lose their replay buffer
/// (the only large file).
pub fn save(
    run_dir: &Path,
    agent: &mut dyn Agent,
    buffer: &ReplayBuffer,
    state: &TrainState,
    metrics: &[MetricsRow],
) -> Result<PathBuf> {
    save_with(run_dir, agent, state, metrics, |dir| super::buffer_file::write(buffer, &dir.join(BUFFER_FILE)))
}

/// Writes a checkpoint like [`save`], with `trainer_files` writing the trainer's own state into
/// the checkpoint directory before it becomes visible.
pub(crate) fn save_with(
    run_dir: &Path,
    agent: &mut dyn Agent,
    state: &TrainState,
    metrics: &[MetricsRow],
    trainer_files: impl FnOnce(&Path) -> Result<()>,
) -> Result<PathBuf> {
    let name = format!("step_{:09}", state.step);
    let root = checkpoints_dir(run_dir);
    let written = (|| {
        // The run's metrics first: a kill after this leaves it ahead of the newest checkpoint,
        // never behind it (a resume checks, see `metrics::restore`).
        metrics::write(&run_dir.join(metrics::FILE), metrics)?;
        std::fs::create_dir_all(&root)?;
        let tmp = tempfile::Builder::new().prefix(".incomplete-").tempdir_in(&root)?;
        write_files(tmp.path(), agent, state, metrics, trainer_files)?;
        let dest = root.join(&name);
        if dest.exists() {
            std::fs::remove_dir_all(&dest)?;
        }
        let tmp_path = tmp.keep();
        if let Err(e) = std::fs::rename(&tmp_path, &dest) {
            let _ = std::fs::remove_dir_all(&tmp_path);
            return Err(e.into());
        }
        sync_dir(&root)?;
        write_bytes_atomic(&root.join("latest"), name.as_bytes())?;
        anyhow::Ok(dest)
    })();
    let dest = written.with_context(|| {
        format!("writing checkpoint {} failed; the run's earlier checkpoints are untouched", root.join(&name).display())
    })?;
    prune_buffers(run_dir)?;
    fault::reach(Point::AfterCheckpoint);
    Ok(dest)
}

/// Writes a checkpoint's files into `dir`, each synced to disk, the checksums last.
fn write_files(
    dir: &Path,
    agent: &mut dyn Agent,
    state: &TrainState,
    metrics: &[MetricsRow],
    trainer_files: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    let params: HashMap<String, Tensor> =
        agent.parameters().into_iter().map(|(n, v)| host(n, &v)).collect::<Result<_>>()?;
    candle_core::safetensors::save(&params, dir.join("model.safetensors"))?;
    fault::reach(Point::CheckpointWrite);

    let mut optim = HashMap::new();
    let mut optimizer_steps = BTreeMap::new();
    for (name, opt) in agent.optimizers() {
        let (tensors, steps) = opt.state(name)?;
        optim.extend(tensors);
        optimizer_steps.insert(name.to_string(), steps);
    }
    candle_core::safetensors::save(&optim, dir.join("optim.safetensors"))?;
    trainer_files(dir)?;

    let state = TrainState {
        optimizer_steps,
        counters: agent.counters().into_iter().map(|(k, v)| (k.to_string(), v)).collect(),
        ..state.clone()
    };
    std::fs::write(dir.join("state.toml"), toml::to_string(&state)?)?;
    metrics::write(&dir.join(metrics::FILE), metrics)?;

    let mut sums = BTreeMap::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        std::fs::File::open(entry.path())?.sync_all()?;
        sums.insert(name, FileSum::of(&entry.path())?);
    }
    std::fs::write(dir.join(CHECKSUMS_FILE), toml::to_string(&Checksums { files: sums })?)?;
    std::fs::File::open(dir.join(CHECKSUMS_FILE))?.sync_all()?;
    sync_dir(dir)
}

/// Flushes a directory's entries (new names, renames) to disk.
fn sync_dir(dir: &Path) -> Result<()> {
    std::fs::File::open(dir)?.sync_all()?;
    Ok(())
}

/// The step directories under `checkpoints/`, newest first.
fn step_dirs(root: &Path) -> Vec<(u64, PathBuf)> {
    let mut dirs: Vec<(u64, PathBuf)> = std::fs::read_dir(root)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let step = e.file_name().to_str()?.strip_prefix("step_")?.parse().ok()?;
            e.path().is_dir().then(|| (step, e.path()))
        })
        .collect();
    dirs.sort_by_key(|d| std::cmp::Reverse(d.0));
    dirs
}

/// Removes the replay buffer from all but the newest [`CHECKPOINTS_WITH_BUFFER`] checkpoints.
pub(crate) fn prune_buffers(run_dir: &Path) -> Result<()> {
    for (_, dir) in step_dirs(&checkpoints_dir(run_dir)).into_iter().skip(CHECKPOINTS_WITH_BUFFER) {
        let buffer = dir.join(BUFFER_FILE);
        if buffer.exists() {
            // The checksums first: a kill between the two leaves a buffer nobody vouches for,
            // which the next pruning removes, never a checksum of a missing file.
            let sums = dir.join(CHECKSUMS_FILE);
            if let Ok(mut c) = read_checksums(&sums) {
                if c.files.remove(BUFFER_FILE).is_some() {
                    write_bytes_atomic(&sums, toml::to_string(&c)?.as_bytes())?;
                }
            }
            std::fs::remove_file(&buffer).with_context(|| format!("removing {}", buffer.display()))?;
        }
    }
    Ok(())
}

/// One file's length and CRC-32 (crc32fast, the IEEE polynomial of zlib and PNG).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct FileSum {
    bytes: u64,
    crc32: u32,
}

impl FileSum {
    fn of(path: &Path) -> Result<FileSum> {
        use std::io::Read;
        let mut file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
        let mut hasher = crc32fast::Hasher::new();
        let mut buf = vec![0u8; 1 << 20];
        let mut bytes = 0u64;
        loop {
            let n = file.read(&mut buf).with_context(|| format!("reading {}", path.display()))?;
            if n == 0 {
                break;
            }
            hasher.update(&buf[..n]);
            bytes += n as u64;
        }
        Ok(FileSum { bytes, crc32: hasher.finalize() })
    }
}

#[derive(Debug, Serialize, Deserialize)]
struct Checksums {
    files: BTreeMap<String, FileSum>,
}

fn read_checksums(path: &Path) -> Result<Checksums> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    toml::from_str(&text).with_context(|| format!("{} is corrupt", path.display()))
}

/// Why `checkpoint` cannot be resumed from, if it cannot: a file missing, cut short or changed
/// since it was written (against `checksums.toml`; checkpoints from before that file are read
/// instead), or no `trainer_file` (an off-policy checkpoint older than the newest two).
fn damage(checkpoint: &Path, trainer_file: &str) -> Option<String> {
    let check = || -> Result<()> {
        load_state(checkpoint)?;
        let sums = checkpoint.join(CHECKSUMS_FILE);
        if sums.exists() {
            for (name, expected) in read_checksums(&sums)?.files {
                let path = checkpoint.join(&name);
                let found = FileSum::of(&path)?;
                if found.bytes != expected.bytes {
                    bail!("{} has {} bytes where {} were written", path.display(), found.bytes, expected.bytes);
                }
                if found.crc32 != expected.crc32 {
                    bail!("{} does not match its checksum", path.display());
                }
            }
        } else {
            read_tensors(&checkpoint.join("model.safetensors"))?;
            read_tensors(&checkpoint.join("optim.safetensors"))?;
        }
        if !checkpoint.join(trainer_file).is_file() {
            bail!(
                "{} has no {trainer_file}{}",
                checkpoint.display(),
                if trainer_file == BUFFER_FILE {
                    " (only the newest two checkpoints keep their replay buffer)"
                } else {
                    ""
                }
            );
        }
        Ok(())
    };
    check().err().map(|e| format!("{e:#}"))
}

/// Whether a run directory holds any checkpoint directory, intact or not.
pub fn any(run_dir: &Path) -> bool {
    newest(run_dir).is_some()
}

/// A run's checkpoint directory of the highest step, intact or not.
pub(crate) fn newest(run_dir: &Path) -> Option<PathBuf> {
    step_dirs(&checkpoints_dir(run_dir)).into_iter().next().map(|(_, dir)| dir)
}

/// The newest checkpoint of a run that a resume can start from: its files match their checksums
/// and it holds `trainer_file` (the replay buffer, or PPO's rollout state). Passing over damaged
/// newer ones is said on stderr; none intact is an error that says why each is not.
pub(crate) fn newest_intact(run_dir: &Path, trainer_file: &str) -> Result<PathBuf> {
    let dirs = step_dirs(&checkpoints_dir(run_dir));
    if dirs.is_empty() {
        bail!("{} has no checkpoint (no checkpoints/step_*)", run_dir.display());
    }
    let mut passed_over = Vec::new();
    for (_, dir) in dirs {
        match damage(&dir, trainer_file) {
            None => {
                for why in &passed_over {
                    eprintln!("warning: passing over a damaged checkpoint: {why}");
                }
                if !passed_over.is_empty() {
                    eprintln!("warning: resuming from {} instead", dir.display());
                }
                return Ok(dir);
            }
            Some(why) => passed_over.push(why),
        }
    }
    bail!(
        "no checkpoint of {} can be resumed from:\n  {}\nstart the run afresh with --force",
        run_dir.display(),
        passed_over.join("\n  ")
    )
}

/// Removes what a killed process left under temporary names: half-built checkpoint directories,
/// and temporary files of the run directory, its `policies/` and its checkpoints. Call with the
/// run lock held.
pub(crate) fn remove_leftovers(run_dir: &Path) -> Result<()> {
    let mut dirs =
        vec![run_dir.to_path_buf(), checkpoints_dir(run_dir), run_dir.join(BUDGET_POLICY_DIR), run_dir.join("videos")];
    // A checkpoint's checksums are rewritten in place when its buffer is pruned.
    dirs.extend(step_dirs(&checkpoints_dir(run_dir)).into_iter().map(|(_, dir)| dir));
    for dir in dirs {
        for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let path = entry.path();
            if name.starts_with(".incomplete-") && path.is_dir() {
                std::fs::remove_dir_all(&path).with_context(|| format!("removing {}", path.display()))?;
            } else if (name.starts_with(".policy-") || name.starts_with(".video-")) && path.is_file() {
                std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
            }
        }
        crate::io::remove_temporaries(&dir)?;
    }
    Ok(())
}

/// Makes `checkpoint` the one `checkpoints/latest` names (a kill can come between a checkpoint's
/// rename into place and that file's update).
pub(crate) fn make_latest(run_dir: &Path, checkpoint: &Path) -> Result<()> {
    let name = checkpoint.file_name().context("a checkpoint directory has a name")?.to_string_lossy().into_owned();
    let file = checkpoints_dir(run_dir).join("latest");
    if std::fs::read_to_string(&file).map(|s| s.trim() == name).unwrap_or(false) {
        return Ok(());
    }
    write_bytes_atomic(&file, name.as_bytes())
}

/// The newest checkpoint of a run, as `checkpoints/latest` names it.
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
        var.set(&t.to_dtype(var.dtype())?.to_device(var.device())?)?;
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
    let buffer = super::buffer_file::read(&checkpoint.join(BUFFER_FILE))?;
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
