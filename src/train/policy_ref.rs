//! Policy references: what a path (and an optional step budget) names wherever a command takes
//! a trained policy (`eval`, `record`, `export`, `train --init-from`) and in Python's
//! `load_policy`. One resolver, so a path means the same thing everywhere:
//!
//! - a checkpoint directory (or its `model.safetensors`): that checkpoint;
//! - a run directory: with a budget, the actor it saved there (`policies/step-N.safetensors`);
//!   without one, its newest checkpoint, or, for a run kept without checkpoints (the committed
//!   results under `benches/results/`), its newest budget policy;
//! - a budget policy file (`RUN/policies/step-N.safetensors`): that actor;
//! - an exported policy directory (or its `policy.safetensors`): that actor.
use std::path::{Path, PathBuf};

use crate::device::ComputeDevice;
use anyhow::{bail, Context, Result};

use crate::agents::Agent;

use super::checkpoint::{self, budget_policy_path, budget_policy_steps, BUDGET_POLICY_DIR};
use super::run_config::{read_run_config, RunConfig};
use super::seeds::init_rng;
use crate::agents::make_agent_on;
use crate::envs::make;

/// A resolved policy reference.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum PolicyRef {
    /// A checkpoint directory: every network, so fine-tuning continues the critics too.
    Checkpoint(PathBuf),
    /// The actor a run saved when it passed `step`.
    Budget {
        /// The run directory.
        run_dir: PathBuf,
        /// The step budget.
        step: u64,
    },
    /// An exported policy directory (`locobench export`).
    Exported(PathBuf),
}

fn budget_file_step(path: &Path) -> Option<u64> {
    let name = path.file_name()?.to_str()?;
    let in_policies = path.parent()?.file_name()? == BUDGET_POLICY_DIR;
    in_policies.then_some(())?;
    name.strip_prefix("step-")?.strip_suffix(".safetensors")?.parse().ok()
}

fn no_budget_here(path: &Path, what: &str, budget: Option<u64>) -> Result<()> {
    if let Some(b) = budget {
        bail!("{} is {what}, which holds one policy; --budget {b} applies to a run directory", path.display());
    }
    Ok(())
}

/// Resolves `path` (and `budget`, a step) to the policy it names; an error says what was
/// expected, or which budgets the run holds.
pub fn resolve_policy(path: &Path, budget: Option<u64>) -> Result<PolicyRef> {
    if !path.exists() {
        bail!("no policy at {}: the path does not exist", path.display());
    }
    if path.is_file() {
        let parent = path.parent().unwrap_or(Path::new(".")).to_path_buf();
        if path.file_name().is_some_and(|n| n == "model.safetensors") {
            no_budget_here(path, "a checkpoint's weights", budget)?;
            return Ok(PolicyRef::Checkpoint(parent));
        }
        if path.file_name().is_some_and(|n| n == checkpoint::POLICY_FILE) {
            no_budget_here(path, "an exported policy", budget)?;
            return Ok(PolicyRef::Exported(parent));
        }
        if let Some(step) = budget_file_step(path) {
            if budget.is_some_and(|b| b != step) {
                bail!("{} is the policy at step {step}, not at --budget {}", path.display(), budget.unwrap());
            }
            let run_dir = parent.parent().unwrap_or(Path::new(".")).to_path_buf();
            return Ok(PolicyRef::Budget { run_dir, step });
        }
        bail!(
            "{} is not a policy file (model.safetensors of a checkpoint, policy.safetensors of an exported policy, or \
             policies/step-N.safetensors of a run)",
            path.display()
        );
    }
    if path.join("model.safetensors").is_file() {
        no_budget_here(path, "a checkpoint", budget)?;
        return Ok(PolicyRef::Checkpoint(path.to_path_buf()));
    }
    if path.join(checkpoint::POLICY_FILE).is_file() {
        if let Some(b) = budget {
            let step = exported_step(path);
            if step != Some(b) {
                bail!(
                    "{} is an exported policy {}; it holds no other budget than that",
                    path.display(),
                    step.map_or("of unknown step".to_string(), |s| format!("at step {s}"))
                );
            }
        }
        return Ok(PolicyRef::Exported(path.to_path_buf()));
    }
    if !path.join("config.toml").is_file() {
        bail!(
            "no policy at {} (expected a run directory, a checkpoint directory, an exported policy, or a policy file)",
            path.display()
        );
    }
    let steps = budget_policy_steps(path);
    let listed = || {
        if steps.is_empty() {
            "it holds no budget policies".to_string()
        } else {
            format!("it holds policies at {}", steps.iter().map(u64::to_string).collect::<Vec<_>>().join(", "))
        }
    };
    if let Some(b) = budget {
        if !budget_policy_path(path, b).is_file() {
            bail!("{} has no policy at step {b} ({})", path.display(), listed());
        }
        return Ok(PolicyRef::Budget { run_dir: path.to_path_buf(), step: b });
    }
    if let Some(newest) = checkpoint::newest(path) {
        return Ok(PolicyRef::Checkpoint(checkpoint::latest(path).unwrap_or(newest)));
    }
    match steps.last() {
        Some(&step) => Ok(PolicyRef::Budget { run_dir: path.to_path_buf(), step }),
        None => bail!("{} is a run directory with no checkpoint and no policies/ yet", path.display()),
    }
}

/// The step an exported policy was taken at (its `source.toml`).
pub(crate) fn exported_step(dir: &Path) -> Option<u64> {
    let text = std::fs::read_to_string(dir.join("source.toml")).ok()?;
    toml::from_str::<toml::Table>(&text).ok()?.get("step")?.as_integer().map(|s| s as u64)
}

impl PolicyRef {
    /// The directory whose `config.toml` describes the policy's run.
    pub fn run_dir(&self) -> Result<PathBuf> {
        match self {
            PolicyRef::Checkpoint(c) => c
                .parent()
                .and_then(Path::parent)
                .map(Path::to_path_buf)
                .with_context(|| format!("checkpoint {} is not inside a run directory", c.display())),
            PolicyRef::Budget { run_dir, .. } => Ok(run_dir.clone()),
            PolicyRef::Exported(dir) => Ok(dir.clone()),
        }
    }

    /// The training step the policy was taken at, where known.
    pub fn step(&self) -> Option<u64> {
        match self {
            PolicyRef::Checkpoint(c) => checkpoint::load_state(c).ok().map(|s| s.step),
            PolicyRef::Budget { step, .. } => Some(*step),
            PolicyRef::Exported(dir) => exported_step(dir),
        }
    }

    /// The file holding the actor's weights (a checkpoint's holds every network).
    pub fn weights_file(&self) -> PathBuf {
        match self {
            PolicyRef::Checkpoint(c) => c.join("model.safetensors"),
            PolicyRef::Budget { run_dir, step } => budget_policy_path(run_dir, *step),
            PolicyRef::Exported(dir) => dir.join(checkpoint::POLICY_FILE),
        }
    }

    /// SHA-256 over its weights file and its run's `config.toml`: everything its actions
    /// depend on, for the evaluation cache's keys.
    pub fn digest(&self) -> Result<String> {
        crate::io::files_digest(&[self.weights_file(), self.run_dir()?.join("config.toml")])
    }

    /// Whether it holds every network (a checkpoint) or the actor alone.
    pub fn has_critics(&self) -> bool {
        matches!(self, PolicyRef::Checkpoint(_))
    }

    /// A path that names this policy on its own, without a budget: what `config.toml` records as
    /// a fine-tuned run's `init_from`.
    pub fn path(&self) -> PathBuf {
        match self {
            PolicyRef::Checkpoint(c) => c.clone(),
            PolicyRef::Budget { .. } => self.weights_file(),
            PolicyRef::Exported(dir) => dir.clone(),
        }
    }

    /// The run's config and an agent of its shape with the policy's weights: every network from
    /// a checkpoint, the actor (with its observation statistics) otherwise.
    pub fn load(&self) -> Result<(RunConfig, Box<dyn Agent>)> {
        self.load_on(ComputeDevice::Cpu)
    }

    /// [`PolicyRef::load`] with the networks on `device` (the device-generic path off the CPU).
    pub fn load_on(&self, device: ComputeDevice) -> Result<(RunConfig, Box<dyn Agent>)> {
        let (run, agent) = run_agent(&self.run_dir()?, device)?;
        self.load_into(agent.as_ref())?;
        Ok((run, agent))
    }

    /// Loads the policy's weights into `agent` (of the same algorithm and sizes).
    pub fn load_into(&self, agent: &dyn Agent) -> Result<()> {
        match self {
            PolicyRef::Checkpoint(c) => checkpoint::load_weights(c, agent),
            _ => checkpoint::load_actor(&self.weights_file(), agent),
        }
    }

    /// Loads the weights into `agent`, which acts in `env`. Where `env` is the command task over
    /// the env this policy was trained in (`ant-command` over `ant`), an actor alone is taken, and
    /// its input grows by the command task's observations, which it ignores at first: training
    /// starts from the gait it had on the base env.
    pub fn load_into_env(&self, agent: &dyn Agent, env: &crate::envs::EnvConfig) -> Result<()> {
        use crate::envs::command::EXTRA_OBSERVATIONS;
        let source = read_run_config(&self.run_dir()?)?;
        if crate::envs::command_base(&env.name) != Some(source.env.name.as_str()) {
            return self.load_into(agent);
        }
        if self.has_critics() {
            bail!(
                "{} is a checkpoint of a {} run: the networks it holds beside the actor cannot take {}'s command inputs; start from the run's \
                 actor instead (a run directory with --init-budget, or a policies/step-N.safetensors file)",
                self.path().display(),
                source.env.name,
                env.name
            );
        }
        let base = make(&source.env)?.spec().observation_space.dim();
        checkpoint::load_actor_with_inputs(&self.weights_file(), agent, Some((base, base + EXTRA_OBSERVATIONS)))
    }
}

/// The config of the run in `dir` and a freshly initialised agent of its shape on `device`.
fn run_agent(dir: &Path, device: ComputeDevice) -> Result<(RunConfig, Box<dyn Agent>)> {
    let run = read_run_config(dir)?;
    let env = make(&run.env)?;
    let (obs_dim, act_dim) = (env.spec().observation_space.dim(), env.spec().action_space.dim());
    let agent = make_agent_on(&run.train, obs_dim, act_dim, &mut init_rng(run.seed), device)?;
    Ok((run, agent))
}
