//! SAC v2 (Haarnoja et al. 2018b) on any device: `agents::sac`'s update from candle's operations.
use candle_core::{Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;

use super::sac_glue;
use crate::agents::common::buffer::Batch;
use crate::agents::common::device::adam::DeviceAdam;
use crate::agents::common::device::layers::{squashed_sample, DeviceStack};
use crate::agents::common::device::{read_scalars, row, standard_normal, DeviceBatch};
use crate::agents::config::{Algo, SacVersion, TanhCorrection, TrainConfig};
use crate::agents::{Agent, Losses, OffPolicyAgent, SacAgent};
use crate::numeric::optim::Optimizer;

/// Soft Actor-Critic v2 with twin critics, target critics and a tuned (or fixed) temperature.
pub struct GenericSac {
    device: Device,
    obs_dim: usize,
    act_dim: usize,
    gamma: f64,
    tau: f64,
    actor: DeviceStack,
    critics: DeviceStack,
    critic_targets: DeviceStack,
    log_alpha: Var,
    target_entropy: f64,
    correction: TanhCorrection,
    actor_opt: DeviceAdam,
    critic_opt: DeviceAdam,
    alpha_opt: Option<DeviceAdam>,
    updates: u64,
}

impl GenericSac {
    /// The fused agent's initial networks (same RNG draws), on `device`.
    pub fn new(
        cfg: &TrainConfig,
        obs_dim: usize,
        act_dim: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let s = cfg.sac();
        anyhow::ensure!(
            s.sac_version == SacVersion::V2,
            "SAC v1 has no device-generic path: train it with --device cpu"
        );
        let cpu_only = s.cpu_only_settings();
        anyhow::ensure!(
            cpu_only.is_empty(),
            "{} has no device-generic path for SAC: train it with --device cpu",
            cpu_only.join(", ")
        );
        let params = SacAgent::new(cfg, obs_dim, act_dim, rng)?.parameters();
        let actor = DeviceStack::from_named(&params, "actor", device)?;
        let critics = DeviceStack::from_named(&params, "critics", device)?;
        let critic_targets = DeviceStack::from_named(&params, "critics_target", device)?;
        let log_alpha = Var::from_tensor(&Tensor::new(&[s.initial_alpha.ln() as f32], device)?)?;
        Ok(GenericSac {
            device: device.clone(),
            obs_dim,
            act_dim,
            gamma: cfg.gamma,
            tau: cfg.tau,
            actor_opt: DeviceAdam::new(actor.vars(), cfg.actor_lr)?,
            critic_opt: DeviceAdam::new(critics.vars(), cfg.critic_lr)?,
            alpha_opt: s.autotune_alpha.then(|| DeviceAdam::new(vec![log_alpha.clone()], s.alpha_lr)).transpose()?,
            actor,
            critics,
            critic_targets,
            log_alpha,
            target_entropy: s.target_entropy.unwrap_or(-(act_dim as f64)),
            correction: s.tanh_correction,
            updates: 0,
        })
    }
}

impl Agent for GenericSac {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let out = self.actor.forward(&row(obs, &self.device)?)?;
        out.narrow(1, 0, self.act_dim)?.tanh()?.flatten_all()?.to_vec1::<f32>()
    }

    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        let eps = Tensor::from_vec(standard_normal(self.act_dim, rng), (1, self.act_dim), &self.device)?;
        let (a, _) = squashed_sample(&self.actor.forward(&row(obs, &self.device)?)?, &eps, self.correction)?;
        a.flatten_all()?.to_vec1::<f32>()
    }

    fn parameters(&self) -> Vec<(String, Var)> {
        let mut out = self.actor.named_vars("actor");
        out.extend(self.critics.named_vars("critics"));
        out.extend(self.critic_targets.named_vars("critics_target"));
        out.push(("log_alpha".into(), self.log_alpha.clone()));
        out
    }

    fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn Optimizer)> {
        let mut out: Vec<(&'static str, &mut dyn Optimizer)> =
            vec![("actor_opt", &mut self.actor_opt), ("critic_opt", &mut self.critic_opt)];
        if let Some(o) = &mut self.alpha_opt {
            out.push(("alpha_opt", o));
        }
        out
    }

    sac_glue!();
}

impl OffPolicyAgent for GenericSac {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        // the fused update's draws, in its order: the next state's sample, then the policy's
        let noise = [standard_normal(n * self.act_dim, rng), standard_normal(n * self.act_dim, rng)];
        let b = DeviceBatch::upload(batch, self.obs_dim, self.act_dim, &noise, &self.device)?;
        let alpha = self.log_alpha.as_tensor().detach().exp()?;

        let (next_a, next_logp) = squashed_sample(&self.actor.forward(&b.next_obs)?, &b.noise[0], self.correction)?;
        let q_next = self.critic_targets.forward(&Tensor::cat(&[&b.next_obs, &next_a], 1)?)?.min(0)?;
        let soft_next = (q_next - next_logp.broadcast_mul(&alpha)?)?;
        let y = (&b.rewards + (&b.not_done * soft_next)?.affine(self.gamma, 0.0)?)?.detach();
        let q = self.critics.forward(&Tensor::cat(&[&b.obs, &b.actions], 1)?)?;
        let k = q.dim(0)? as f64;
        let critic_loss = (q.broadcast_sub(&y)?.sqr()?.mean_all()? * k)?;
        self.critic_opt.step(&critic_loss.backward()?)?;

        let (pi, logp) = squashed_sample(&self.actor.forward(&b.obs)?, &b.noise[1], self.correction)?;
        let q_pi = self.critics.forward_frozen(&Tensor::cat(&[&b.obs, &pi], 1)?)?.min(0)?;
        let actor_loss = (logp.broadcast_mul(&alpha)? - q_pi)?.mean_all()?;
        self.actor_opt.step(&actor_loss.backward()?)?;

        let mut scalars = vec![critic_loss, actor_loss];
        if let Some(opt) = &mut self.alpha_opt {
            let gap = logp.detach().affine(1.0, self.target_entropy)?;
            let alpha_loss = self.log_alpha.as_tensor().broadcast_mul(&gap)?.mean_all()?.neg()?;
            opt.step(&alpha_loss.backward()?)?;
            scalars.push(alpha_loss);
        }
        self.critics.polyak_into(&self.critic_targets, self.tau)?;
        self.updates += 1;

        scalars.push(self.log_alpha.as_tensor().exp()?);
        let values = read_scalars(&scalars.iter().collect::<Vec<_>>())?;
        Ok(Losses {
            critic: values[0],
            actor: Some(values[1]),
            alpha_loss: self.alpha_opt.as_ref().map(|_| values[2]),
            alpha: values.last().copied(),
            value: None,
        })
    }
}
