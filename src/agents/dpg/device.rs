//! TD3 (Fujimoto et al. 2018) and DDPG on any device: `agents::dpg`'s update from candle's
//! operations.
use candle_core::{Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::dpg_glue;
use crate::agents::common::buffer::Batch;
use crate::agents::common::device::adam::DeviceAdam;
use crate::agents::common::device::layers::DeviceStack;
use crate::agents::common::device::{read_scalars, row, DeviceBatch};
use crate::agents::common::noise::Noise;
use crate::agents::config::{Algo, TrainConfig};
use crate::agents::{Agent, DeterministicAgent, Losses, OffPolicyAgent};
use crate::numeric::optim::Optimizer;

/// TD3 and DDPG: a deterministic actor, one or two critics, and target networks.
pub struct GenericDeterministic {
    device: Device,
    algo: Algo,
    obs_dim: usize,
    act_dim: usize,
    gamma: f64,
    tau: f64,
    policy_noise: f64,
    noise_clip: f64,
    policy_delay: u64,
    actor: DeviceStack,
    actor_target: DeviceStack,
    critics: DeviceStack,
    critic_targets: DeviceStack,
    actor_opt: DeviceAdam,
    critic_opt: DeviceAdam,
    noise: Noise,
    updates: u64,
}

impl GenericDeterministic {
    /// The fused agent's initial networks (same RNG draws), on `device`.
    pub fn new(
        cfg: &TrainConfig,
        obs_dim: usize,
        act_dim: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> anyhow::Result<Self> {
        anyhow::ensure!(
            !cfg.dpg().critic_layer_norm,
            "critic_layer_norm has no device-generic path: train it with --device cpu"
        );
        let params = DeterministicAgent::new(cfg, obs_dim, act_dim, rng)?.parameters();
        let stack = |prefix: &str| DeviceStack::from_named(&params, prefix, device);
        let (actor, critics) = (stack("actor")?, stack("critics")?);
        let dpg = cfg.dpg();
        let noise = Noise::for_config(dpg, act_dim);
        Ok(GenericDeterministic {
            device: device.clone(),
            algo: cfg.algo,
            obs_dim,
            act_dim,
            gamma: cfg.gamma,
            tau: cfg.tau,
            policy_noise: dpg.policy_noise,
            noise_clip: dpg.noise_clip,
            policy_delay: dpg.policy_delay as u64,
            actor_opt: DeviceAdam::new(actor.vars(), cfg.actor_lr)?,
            critic_opt: DeviceAdam::new(critics.vars(), cfg.critic_lr)?,
            actor_target: stack("actor_target")?,
            critic_targets: stack("critics_target")?,
            actor,
            critics,
            noise,
            updates: 0,
        })
    }
}

impl Agent for GenericDeterministic {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.actor.forward(&row(obs, &self.device)?)?.tanh()?.flatten_all()?.to_vec1::<f32>()
    }

    dpg_glue!();
}

impl OffPolicyAgent for GenericDeterministic {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let mut noise = Vec::new();
        if self.policy_noise > 0.0 {
            // target policy smoothing, drawn as the fused path draws it
            let normal = Normal::new(0.0, self.policy_noise).expect("policy_noise >= 0");
            let c = self.noise_clip;
            noise.push((0..n * self.act_dim).map(|_| normal.sample(rng).clamp(-c, c) as f32).collect());
        }
        let b = DeviceBatch::upload(batch, self.obs_dim, self.act_dim, &noise, &self.device)?;

        let mut next_action = self.actor_target.forward(&b.next_obs)?.tanh()?;
        if let Some(eps) = b.noise.first() {
            next_action = crate::agents::common::device::layers::clamp(&(next_action + eps)?, -1.0, 1.0)?;
        }
        let q_next = self.critic_targets.forward(&Tensor::cat(&[&b.next_obs, &next_action], 1)?)?.min(0)?;
        let y = (&b.rewards + (&b.not_done * q_next)?.affine(self.gamma, 0.0)?)?.detach();
        let q = self.critics.forward(&Tensor::cat(&[&b.obs, &b.actions], 1)?)?;
        let k = q.dim(0)? as f64;
        let critic_loss = (q.broadcast_sub(&y)?.sqr()?.mean_all()? * k)?;
        self.critic_opt.step(&critic_loss.backward()?)?;
        self.updates += 1;

        let mut scalars = vec![critic_loss];
        if self.updates.is_multiple_of(self.policy_delay) {
            let pi = self.actor.forward(&b.obs)?.tanh()?;
            let q_pi = self.critics.forward_frozen(&Tensor::cat(&[&b.obs, &pi], 1)?)?.get(0)?;
            let actor_loss = q_pi.mean_all()?.neg()?;
            self.actor_opt.step(&actor_loss.backward()?)?;
            self.actor.polyak_into(&self.actor_target, self.tau)?;
            self.critics.polyak_into(&self.critic_targets, self.tau)?;
            scalars.push(actor_loss);
        }
        let values = read_scalars(&scalars.iter().collect::<Vec<_>>())?;
        Ok(Losses { critic: values[0], actor: values.get(1).copied(), ..Default::default() })
    }
}
