//! The action-branching DQN on any device: `agents::dqn`'s update from candle's operations. The
//! taken levels travel to the device in the batch's one upload (as f32, cast there).
use candle_core::{DType, Device, Result, Tensor, Var, D};
use rand_chacha::ChaCha8Rng;

use super::dqn_glue;
use crate::agents::common::buffer::Batch;
use crate::agents::common::device::adam::DeviceAdam;
use crate::agents::common::device::layers::DeviceStack;
use crate::agents::common::device::{read_scalars, row, DeviceBatch};
use crate::agents::config::{Algo, TrainConfig};
use crate::agents::dqn::{epsilon_greedy, greedy_levels, named_networks, value_level, DqnCounters, EpsilonSchedule};
use crate::agents::{Agent, BranchingDqnAgent, Losses, OffPolicyAgent};
use crate::numeric::optim::Optimizer;

/// Branching DQN: one dueling network with an advantage head per action dimension, and its target.
pub struct GenericDqn {
    device: Device,
    obs_dim: usize,
    branches: usize,
    levels: usize,
    gamma: f64,
    tau: f64,
    schedule: EpsilonSchedule,
    q: DeviceStack,
    target: DeviceStack,
    opt: DeviceAdam,
    steps: DqnCounters,
}

impl GenericDqn {
    /// The fused agent's initial network (same RNG draws), on `device`.
    pub fn new(
        cfg: &TrainConfig,
        obs_dim: usize,
        branches: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let s = cfg.dqn();
        let params = BranchingDqnAgent::new(cfg, obs_dim, branches, rng)?.parameters();
        let q = DeviceStack::from_named(&params, "actor.q", device)?;
        let target = DeviceStack::from_named(&params, "q_target", device)?;
        Ok(GenericDqn {
            device: device.clone(),
            obs_dim,
            branches,
            levels: s.levels,
            gamma: cfg.gamma,
            tau: cfg.tau,
            schedule: EpsilonSchedule::new(s),
            opt: DeviceAdam::new(q.vars(), cfg.critic_lr)?,
            q,
            target,
            steps: DqnCounters::default(),
        })
    }

    /// Q-values `[n, branches, levels]`: V plus each branch's centred advantages.
    fn q_values(&self, out: &Tensor) -> Result<Tensor> {
        let n = out.dim(0)?;
        let value = out.narrow(1, 0, 1)?.reshape((n, 1, 1))?;
        let adv = out.narrow(1, 1, self.branches * self.levels)?.reshape((n, self.branches, self.levels))?;
        adv.broadcast_sub(&adv.mean_keepdim(D::Minus1)?)?.broadcast_add(&value)
    }

    fn greedy(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let q = self.q_values(&self.q.forward_frozen(&row(obs, &self.device)?)?)?;
        Ok(greedy_levels(&q.flatten_all()?.to_vec1::<f32>()?, self.levels))
    }
}

impl Agent for GenericDqn {
    dqn_glue!();
}

impl OffPolicyAgent for GenericDqn {
    fn update(&mut self, batch: &Batch, _rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let taken: Vec<f32> = batch.actions.iter().map(|&a| value_level(a, self.levels) as f32).collect();
        let b = DeviceBatch::upload(batch, self.obs_dim, self.branches, &[taken], &self.device)?;
        let taken = b.noise[0].to_dtype(DType::U32)?.reshape((n, self.branches, 1))?;

        // Double DQN per branch: the online network picks, the target network values.
        let best = self.q_values(&self.q.forward_frozen(&b.next_obs)?)?.argmax_keepdim(D::Minus1)?;
        let q_next = self.q_values(&self.target.forward_frozen(&b.next_obs)?)?;
        let q_next = q_next.gather(&best, D::Minus1)?.squeeze(D::Minus1)?.mean_keepdim(D::Minus1)?;
        let y = (&b.rewards + (&b.not_done * q_next)?.affine(self.gamma, 0.0)?)?.detach();
        let q = self.q_values(&self.q.forward(&b.obs)?)?.gather(&taken, D::Minus1)?.squeeze(D::Minus1)?;
        let loss = q.broadcast_sub(&y)?.sqr()?.mean_all()?;
        self.opt.step(&loss.backward()?)?;
        self.q.polyak_into(&self.target, self.tau)?;
        self.steps.updates += 1;
        Ok(Losses { critic: read_scalars(&[&loss])?[0], ..Default::default() })
    }
}
