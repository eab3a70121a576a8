//! Agents on candle-nn: the off-policy actor-critics TD3, DDPG, SAC and CrossQ, the on-policy PPO,
//! and the action-branching DQN over discretised joint actions.
//!
//! Agents work in the normalised action space [-1, 1]^n; the trainer maps actions to the
//! environment's bounds. All randomness (initialisation, exploration, target smoothing, SAC's
//! sampling) comes from RNGs the caller seeds, never from a library's global RNG.
pub mod common;
pub mod config;
pub mod crossq;
pub mod dpg;
pub mod dqn;
pub mod ppo;
pub mod registry;
pub mod sac;

/// What the algorithms share, at the paths it had before it moved to [`common`].
pub use common::{buffer, noise, normalize, objectives, squashed};

use candle_core::{Result, Var};
use rand_chacha::ChaCha8Rng;

pub use crate::numeric::allocator::keep_freed_memory;
pub use crate::numeric::denormals::{float_mode, flush_denormals_to_zero, set_float_mode};
/// The optimiser and the helper thread live in [`crate::numeric`]; these paths stay for callers.
pub use crate::numeric::{optim, second_core};
pub use common::buffer::{Batch, ReplayBuffer};
pub use common::normalize::NormalizedAgent;
pub use config::{
    Algo, CrossqConfig, DpgConfig, DqnConfig, OtherAlgorithmKeys, PpoConfig, SacConfig, SacVersion, TanhCorrection,
    TrainConfig, WeightInit,
};
pub use crossq::CrossqAgent;
pub use dpg::DeterministicAgent;
pub use dqn::BranchingDqnAgent;
pub use ppo::PpoAgent;
pub use sac::SacAgent;

use crate::numeric::optim::Optimizer;

/// Losses and temperature of one gradient update (None where the update did not touch them).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Losses {
    /// The critics' temporal-difference loss.
    pub critic: f64,
    /// The actor's loss, on the updates that trained the actor.
    pub actor: Option<f64>,
    /// SAC v1's value-network loss.
    pub value: Option<f64>,
    /// SAC's temperature after the update.
    pub alpha: Option<f64>,
    /// SAC's temperature loss, when the temperature is tuned.
    pub alpha_loss: Option<f64>,
}

/// A learner that acts, updates from minibatches and checkpoints its state.
pub trait Agent: Send {
    /// Which algorithm this is.
    fn algo(&self) -> Algo;
    /// The deterministic action for one observation (evaluation).
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>>;
    /// An exploratory action for one observation (training).
    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>>;
    /// Called at the start of every training episode (resets OU noise).
    fn begin_episode(&mut self) {}
    /// Every network parameter, targets included, by checkpoint name.
    fn parameters(&self) -> Vec<(String, Var)>;
    /// The Adam optimisers by checkpoint name, to save and restore their moments.
    fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn Optimizer)>;
    /// Counters that must survive a resume (updates done, noise steps).
    fn counters(&self) -> Vec<(&'static str, u64)>;
    /// Restores a counter saved by `counters`; unknown names are ignored.
    fn set_counter(&mut self, name: &str, value: u64);
}

/// The [`Agent`] methods a wrapper hands to its `inner` agent unchanged (`algo`, `begin_episode`,
/// `optimizers`, `counters`, `set_counter`): written once for every wrapper
/// ([`NormalizedAgent`], the device path's error explainer).
macro_rules! delegate_to_inner {
    () => {
        fn algo(&self) -> $crate::agents::Algo {
            self.inner.algo()
        }

        fn begin_episode(&mut self) {
            self.inner.begin_episode()
        }

        fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn $crate::numeric::optim::Optimizer)> {
            self.inner.optimizers()
        }

        fn counters(&self) -> Vec<(&'static str, u64)> {
            self.inner.counters()
        }

        fn set_counter(&mut self, name: &str, value: u64) {
            self.inner.set_counter(name, value)
        }
    };
}
pub(crate) use delegate_to_inner;

/// An off-policy learner: it updates from replay minibatches (TD3, DDPG, SAC, CrossQ, the
/// branching DQN). PPO learns from its own rollouts (`train::on_policy`) and is an [`Agent`] only.
pub trait OffPolicyAgent: Agent {
    /// One gradient update from a minibatch; `rng` drives any sampling it needs.
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses>;
    /// Called once, when learning starts, with the warm-up transitions (observation
    /// normalisation estimates its statistics here; other agents ignore it).
    fn fit_observations(&mut self, _buffer: &ReplayBuffer) -> Result<()> {
        Ok(())
    }
}

/// An on-policy learner (PPO): it samples a rollout with `policy_step` and learns from its
/// minibatches. Observations reach it raw; it keeps the statistics that normalise them.
pub trait OnPolicyAgent: Agent {
    /// Folds raw observations (in order) into the observation statistics.
    fn observe(&mut self, raw: &[Vec<f64>]) -> Result<()>;
    /// Raw observations as the networks see them (`n x obs_dim`, f32).
    fn normalize(&self, raw: &[Vec<f64>]) -> Result<Vec<f32>>;
    /// Samples an action for each normalised observation, with its log-probability and value.
    fn policy_step(&self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<ppo::PolicyStep>;
    /// The value of each normalised observation.
    fn values(&self, obs: &[f32]) -> Result<Vec<f32>>;
    /// Sets the learning rates to `fraction` of their configured values (annealing).
    fn anneal(&mut self, fraction: f64);
    /// One gradient step on a minibatch.
    fn learn(&mut self, batch: &ppo::PpoBatch) -> Result<ppo::PpoLosses>;
}

/// Builds the agent a config asks for, initialised from `rng`: any algorithm, to act with.
pub fn make_agent(cfg: &TrainConfig, obs_dim: usize, act_dim: usize, rng: &mut ChaCha8Rng) -> Result<Box<dyn Agent>> {
    match registry::entry(cfg.algo).build {
        registry::Build::OffPolicy(_) => Ok(make_learner(cfg, obs_dim, act_dim, rng)?),
        registry::Build::OnPolicy(build) => Ok(build(cfg, obs_dim, act_dim, rng)?),
    }
}

/// [`make_agent`] on `device`: the fused agent on the CPU, the device-generic one elsewhere.
pub fn make_agent_on(
    cfg: &TrainConfig,
    obs_dim: usize,
    act_dim: usize,
    rng: &mut ChaCha8Rng,
    device: crate::device::ComputeDevice,
) -> anyhow::Result<Box<dyn Agent>> {
    if device == crate::device::ComputeDevice::Cpu {
        return Ok(make_agent(cfg, obs_dim, act_dim, rng)?);
    }
    Ok(match registry::entry(cfg.algo).build {
        registry::Build::OffPolicy(_) => make_learner_on(cfg, obs_dim, act_dim, rng, device)?,
        registry::Build::OnPolicy(_) => make_on_policy_on(cfg, obs_dim, act_dim, rng, device)?,
    })
}

/// Builds the on-policy learner a config asks for on `device`: the fused agent on the CPU, the
/// device-generic one ([`common::device`]) elsewhere, from the same initial weights. An off-policy
/// algorithm is an error.
pub fn make_on_policy_on(
    cfg: &TrainConfig,
    obs_dim: usize,
    act_dim: usize,
    rng: &mut ChaCha8Rng,
    device: crate::device::ComputeDevice,
) -> anyhow::Result<Box<dyn OnPolicyAgent>> {
    let registry::Build::OnPolicy(build) = registry::entry(cfg.algo).build else {
        anyhow::bail!("{} learns from replay minibatches, not from its own rollouts", cfg.algo.name());
    };
    if device == crate::device::ComputeDevice::Cpu {
        return Ok(build(cfg, obs_dim, act_dim, rng)?);
    }
    let what = common::device::memory::describe(cfg, &device.to_string());
    let agent = common::device::make_generic_on_policy(cfg, obs_dim, act_dim, rng, &device.open()?)
        .map_err(|e| explained(e, &what))?;
    Ok(Box::new(common::device::memory::Explained { inner: agent, what }))
}

/// `e`, with a device's out-of-memory error explained (see [`common::device::memory::explain`]).
fn explained(e: anyhow::Error, what: &str) -> anyhow::Error {
    match e.downcast::<candle_core::Error>() {
        Ok(e) => anyhow::Error::new(common::device::memory::explain(e, what)),
        Err(e) => e,
    }
}

/// Builds the off-policy learner a config asks for, initialised from `rng` exactly as
/// [`make_agent`] would; an on-policy algorithm is an error.
pub fn make_learner(
    cfg: &TrainConfig,
    obs_dim: usize,
    act_dim: usize,
    rng: &mut ChaCha8Rng,
) -> Result<Box<dyn OffPolicyAgent>> {
    let registry::Build::OffPolicy(build) = registry::entry(cfg.algo).build else {
        candle_core::bail!(
            "{} learns from its own rollouts (train::on_policy), not from replay minibatches",
            cfg.algo.name()
        );
    };
    let agent = build(cfg, obs_dim, act_dim, rng)?;
    Ok(if cfg.normalize_observations { Box::new(NormalizedAgent::new(agent, obs_dim)?) } else { agent })
}

/// [`make_learner`] on `device`: the fused agent on the CPU, the device-generic one
/// ([`common::device`]) elsewhere, from the same initial weights.
pub fn make_learner_on(
    cfg: &TrainConfig,
    obs_dim: usize,
    act_dim: usize,
    rng: &mut ChaCha8Rng,
    device: crate::device::ComputeDevice,
) -> anyhow::Result<Box<dyn OffPolicyAgent>> {
    if device == crate::device::ComputeDevice::Cpu {
        return Ok(make_learner(cfg, obs_dim, act_dim, rng)?);
    }
    let what = common::device::memory::describe(cfg, &device.to_string());
    let agent = common::device::make_generic_agent(cfg, obs_dim, act_dim, rng, &device.open()?)
        .map_err(|e| explained(e, &what))?;
    let agent: Box<dyn OffPolicyAgent> = Box::new(common::device::memory::Explained { inner: agent, what });
    Ok(if cfg.normalize_observations { Box::new(NormalizedAgent::new(agent, obs_dim)?) } else { agent })
}

/// Layer sizes `input, hidden..., output`.
pub(crate) fn layer_sizes(input: usize, hidden: &[usize], output: usize) -> Vec<usize> {
    std::iter::once(input).chain(hidden.iter().copied()).chain(std::iter::once(output)).collect()
}
