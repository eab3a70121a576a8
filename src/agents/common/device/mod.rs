//! What the device versions of the algorithms share. Each algorithm's folder holds a `device.rs`:
//! TD3, DDPG, SAC (v2), CrossQ, the branching DQN and PPO written with candle's own operations
//! alone, so they run on any candle device: the CPU, or a CUDA GPU in a build with the `cuda`
//! feature (`--device cuda`). On the CPU the fused path ([`crate::numeric`]) stays the default; the
//! device path is its reference implementation, tested against it from the same weights and
//! batches (`locobench device check`, and the same comparison in the binary's unit tests).
//!
//! Each agent starts from the fused agent's initial weights (built on the CPU from the same RNG,
//! then copied), uses the same parameter and optimiser names, and draws its noise from the same RNG
//! in the same order, so a seed means the same run on either path, and a checkpoint written by one
//! resumes on the other (bit-exact only on the path that wrote it).
//!
//! Per update the host sends the device one buffer (the batch's columns and the update's noise)
//! and reads back one (the losses the metrics rows carry); everything else stays on the device.
pub mod adam;
pub(crate) mod layers;
pub(crate) mod memory;

use candle_core::{Device, Result, Tensor};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::agents::common::buffer::Batch;
use crate::agents::config::{Algo, TrainConfig};
use crate::agents::{OffPolicyAgent, OnPolicyAgent};

pub use crate::agents::crossq::device::GenericCrossq;
pub use crate::agents::dpg::device::GenericDeterministic;
pub use crate::agents::dqn::device::GenericDqn;
pub use crate::agents::ppo::device::GenericPpo;
pub use crate::agents::sac::device::GenericSac;

/// The device-generic off-policy learner for `cfg`, initialised from `rng` exactly as the fused
/// one is.
pub fn make_generic_agent(
    cfg: &TrainConfig,
    obs_dim: usize,
    act_dim: usize,
    rng: &mut ChaCha8Rng,
    device: &Device,
) -> anyhow::Result<Box<dyn OffPolicyAgent>> {
    Ok(match cfg.algo {
        Algo::Td3 | Algo::Ddpg => Box::new(GenericDeterministic::new(cfg, obs_dim, act_dim, rng, device)?),
        Algo::Sac => Box::new(GenericSac::new(cfg, obs_dim, act_dim, rng, device)?),
        Algo::Crossq => Box::new(GenericCrossq::new(cfg, obs_dim, act_dim, rng, device)?),
        Algo::Dqn => Box::new(GenericDqn::new(cfg, obs_dim, act_dim, rng, device)?),
        Algo::Ppo => anyhow::bail!("ppo learns from its own rollouts: build it with make_generic_on_policy"),
    })
}

/// The device-generic on-policy learner (PPO) for `cfg`, initialised from `rng` exactly as the
/// fused one is.
pub fn make_generic_on_policy(
    cfg: &TrainConfig,
    obs_dim: usize,
    act_dim: usize,
    rng: &mut ChaCha8Rng,
    device: &Device,
) -> anyhow::Result<Box<dyn OnPolicyAgent>> {
    match cfg.algo {
        Algo::Ppo => Ok(Box::new(GenericPpo::new(cfg, obs_dim, act_dim, rng, device)?)),
        other => anyhow::bail!("{} learns from replay minibatches: build it with make_generic_agent", other.name()),
    }
}

/// A batch on the device: one host-to-device copy of every column and of the update's noise.
pub struct DeviceBatch {
    /// Observations, `[n, obs_dim]`.
    pub obs: Tensor,
    /// Actions taken, `[n, act_dim]`.
    pub actions: Tensor,
    /// Next observations, `[n, obs_dim]`.
    pub next_obs: Tensor,
    /// Rewards as the learner stores them, `[n, 1]`.
    pub rewards: Tensor,
    /// 1 - terminated, `[n, 1]`.
    pub not_done: Tensor,
    /// The noise blocks, each `[n, act_dim]`, in the order given.
    pub noise: Vec<Tensor>,
}

impl DeviceBatch {
    /// Copies `batch` and the update's `noise` blocks to `device` in one transfer.
    pub fn upload(batch: &Batch, obs_dim: usize, act_dim: usize, noise: &[Vec<f32>], device: &Device) -> Result<Self> {
        let n = batch.size;
        let mut flat = Vec::with_capacity(n * (2 * obs_dim + act_dim + 2 + noise.len() * act_dim));
        flat.extend_from_slice(&batch.obs);
        flat.extend_from_slice(&batch.actions);
        flat.extend_from_slice(&batch.next_obs);
        flat.extend_from_slice(&batch.rewards);
        flat.extend(batch.terminated.iter().map(|t| t * -1.0 + 1.0));
        for block in noise {
            flat.extend_from_slice(block);
        }
        let all = Tensor::from_vec(flat, n * (2 * obs_dim + act_dim + 2 + noise.len() * act_dim), device)?;
        let mut offset = 0;
        let mut take = |cols: usize| -> Result<Tensor> {
            let t = all.narrow(0, offset, n * cols)?.reshape((n, cols))?;
            offset += n * cols;
            Ok(t)
        };
        Ok(DeviceBatch {
            obs: take(obs_dim)?,
            actions: take(act_dim)?,
            next_obs: take(obs_dim)?,
            rewards: take(1)?,
            not_done: take(1)?,
            noise: (0..noise.len()).map(|_| take(act_dim)).collect::<Result<_>>()?,
        })
    }
}

/// `count` standard normal draws from `rng` (SAC's and CrossQ's sampling noise, in the fused
/// path's order).
pub(crate) fn standard_normal(count: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
    (0..count).map(|_| StandardNormal.sample(rng)).collect()
}

/// Scalars on the device read back in one copy.
pub(crate) fn read_scalars(values: &[&Tensor]) -> Result<Vec<f64>> {
    let flat = values.iter().map(|t| t.flatten_all()).collect::<Result<Vec<_>>>()?;
    Ok(Tensor::cat(&flat, 0)?.to_vec1::<f32>()?.into_iter().map(f64::from).collect())
}

/// One observation as a `[1, obs_dim]` tensor on the device.
pub(crate) fn row(obs: &[f32], device: &Device) -> Result<Tensor> {
    Tensor::from_slice(obs, (1, obs.len()), device)
}
