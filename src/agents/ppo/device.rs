//! PPO on any device: `agents::ppo`'s minibatch update from candle's operations. The rollout's
//! sampling stays on the host (the same draws from the same RNG as the fused path); per minibatch
//! the host sends one buffer and reads back one (the diagnostics), and the global gradient-norm
//! clip is computed on the device, so no value travels to the host in between.
use candle_core::{DType, Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;

use super::{gaussian_log_prob_and_entropy, ppo_glue, ppo_on_policy_glue};
use crate::agents::common::device::adam::DeviceAdam;
use crate::agents::common::device::layers::{clamp, constant, DeviceStack};
use crate::agents::common::device::read_scalars;
use crate::agents::config::{Algo, PpoConfig, TrainConfig};
use crate::agents::ppo::{
    named_networks, normalized_advantages, sample_actions, Activation, ObsStats, PolicyStep, PpoBatch, PpoLosses,
};
use crate::agents::{Agent, OnPolicyAgent, PpoAgent};
use crate::numeric::optim::Optimizer;

/// PPO's Gaussian policy (MLP mean, state-independent log-std) and MLP critic, tanh or ReLU
/// between their hidden layers.
pub struct GenericPpo {
    device: Device,
    obs_dim: usize,
    act_dim: usize,
    settings: PpoConfig,
    actor: DeviceStack,
    log_std: Var,
    critic: DeviceStack,
    obs_stats: ObsStats,
    actor_opt: DeviceAdam,
    critic_opt: DeviceAdam,
    base_actor_lr: f64,
    base_critic_lr: f64,
}

impl GenericPpo {
    /// The fused agent's initial networks (same RNG draws), on `device`.
    pub fn new(
        cfg: &TrainConfig,
        obs_dim: usize,
        act_dim: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let settings = cfg.ppo().clone();
        let params = PpoAgent::new(cfg, obs_dim, act_dim, rng)?.parameters();
        let stack = |prefix: &str| -> Result<DeviceStack> {
            let s = DeviceStack::from_named(&params, prefix, device)?;
            Ok(match settings.activation {
                Activation::Tanh => s.with_tanh(),
                Activation::Relu => s,
            })
        };
        let (actor, critic) = (stack("actor.mean")?, stack("critic")?);
        let (_, log_std) = params.iter().find(|(n, _)| n == "actor.log_std").expect("PPO has a log-std");
        let log_std = Var::from_tensor(&log_std.as_tensor().to_device(device)?)?;
        let adam = |vars: Vec<Var>, lr: f64| -> Result<DeviceAdam> {
            let mut opt = DeviceAdam::new(vars, lr)?;
            opt.eps = settings.adam_eps;
            Ok(opt)
        };
        let mut actor_vars = actor.vars();
        actor_vars.push(log_std.clone());
        Ok(GenericPpo {
            device: device.clone(),
            obs_dim,
            act_dim,
            obs_stats: ObsStats::from_named(&params, cfg.normalize_observations, settings.clip_observations)?,
            actor_opt: adam(actor_vars, cfg.actor_lr)?,
            critic_opt: adam(critic.vars(), cfg.critic_lr)?,
            settings,
            actor,
            log_std,
            critic,
            base_actor_lr: cfg.actor_lr,
            base_critic_lr: cfg.critic_lr,
        })
    }

    fn rows(&self, obs: &[f32]) -> Result<Tensor> {
        Tensor::from_slice(obs, (obs.len() / self.obs_dim, self.obs_dim), &self.device)
    }

    /// Every trained parameter, in the fused path's clipping order.
    fn trained_vars(&self) -> Vec<Var> {
        let mut vars = self.actor.vars();
        vars.push(self.log_std.clone());
        vars.extend(self.critic.vars());
        vars
    }
}

/// The smallest f32 above `x`, so that `v >= above(x)` is `v as f64 > x` for any f32 `v`.
fn above(x: f64) -> f32 {
    let y = x as f32;
    if y as f64 > x {
        y
    } else {
        y.next_up()
    }
}

impl OnPolicyAgent for GenericPpo {
    ppo_on_policy_glue!();

    fn policy_step(&self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<PolicyStep> {
        let x = self.rows(obs)?;
        // one read-back: each row is the policy's mean, then the value
        let both = Tensor::cat(&[self.actor.forward(&x)?, self.critic.forward(&x)?], 1)?.to_vec2::<f32>()?;
        let mean: Vec<f32> = both.iter().flat_map(|r| r[..self.act_dim].to_vec()).collect();
        let values: Vec<f32> = both.iter().map(|r| r[self.act_dim]).collect();
        let log_std = self.log_std.as_tensor().flatten_all()?.to_vec1::<f32>()?;
        let (actions, log_probs) = sample_actions(&mean, &log_std, rng);
        Ok(PolicyStep { actions, log_probs, values })
    }

    fn values(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.critic.forward(&self.rows(obs)?)?.flatten_all()?.to_vec1::<f32>()
    }

    fn learn(&mut self, b: &PpoBatch) -> Result<PpoLosses> {
        let n = b.log_probs.len();
        let s = &self.settings;
        let advantages = if s.norm_adv { normalized_advantages(&b.advantages) } else { b.advantages.clone() };
        // one upload: observations, actions, then the four per-sample columns
        let mut flat = Vec::with_capacity(n * (self.obs_dim + self.act_dim + 4));
        for column in [&b.obs, &b.actions, &b.log_probs, &advantages, &b.returns, &b.values] {
            flat.extend_from_slice(column);
        }
        let all = Tensor::from_vec(flat, n * (self.obs_dim + self.act_dim + 4), &self.device)?;
        let mut offset = 0;
        let mut take = |cols: usize| -> Result<Tensor> {
            let t = all.narrow(0, offset, n * cols)?;
            offset += n * cols;
            if cols == 1 {
                Ok(t)
            } else {
                t.reshape((n, cols))
            }
        };
        let (obs, actions) = (take(self.obs_dim)?, take(self.act_dim)?);
        let (old_log_probs, advantages, returns, old_values) = (take(1)?, take(1)?, take(1)?, take(1)?);

        let mean = self.actor.forward(&obs)?;
        let (new_log_probs, entropy) = gaussian_log_prob_and_entropy(&mean, &self.log_std, &actions)?;
        let log_ratio = (&new_log_probs - &old_log_probs)?;
        let ratio = log_ratio.exp()?;
        let clipped = clamp(&ratio, 1.0 - s.clip_coef as f32, 1.0 + s.clip_coef as f32)?;
        let pg1 = (advantages.neg()? * &ratio)?;
        let pg2 = (advantages.neg()? * &clipped)?;
        let policy_loss = pg1.maximum(&pg2)?.mean_all()?;

        let new_values = self.critic.forward(&obs)?.flatten_all()?;
        let unclipped = (&new_values - &returns)?.sqr()?;
        let value_loss = if s.clip_vloss {
            let delta = clamp(&(&new_values - &old_values)?, -s.clip_coef as f32, s.clip_coef as f32)?;
            let v_clipped = ((old_values + delta)? - &returns)?.sqr()?;
            unclipped.maximum(&v_clipped)?.mean_all()?.affine(0.5, 0.0)?
        } else {
            unclipped.mean_all()?.affine(0.5, 0.0)?
        };
        let loss = ((&policy_loss - entropy.affine(s.ent_coef, 0.0)?)? + value_loss.affine(s.vf_coef, 0.0)?)?;
        let mut grads = loss.backward()?;

        // Global gradient-norm clipping (torch's clip_grad_norm_) on the device: the gradients are
        // scaled by min(1, max_norm / (norm + 1e-6)); a factor of exactly 1 changes nothing.
        let vars = self.trained_vars();
        let squares = vars
            .iter()
            .filter_map(|v| grads.get(v.as_tensor()))
            .map(|g| g.sqr()?.sum_all()?.reshape(1))
            .collect::<Result<Vec<_>>>()?;
        let norm = Tensor::cat(&squares, 0)?.sum_all()?.sqrt()?;
        let coef = norm.affine(1.0, 1e-6)?.recip()?.affine(s.max_grad_norm, 0.0)?;
        let coef = coef.broadcast_minimum(&constant(1.0, &self.device)?)?;
        for v in &vars {
            if let Some(g) = grads.remove(v.as_tensor()) {
                grads.insert(v.as_tensor(), g.broadcast_mul(&coef)?);
            }
        }
        self.actor_opt.step(&grads)?;
        self.critic_opt.step(&grads)?;

        let approx_kl = (ratio.affine(1.0, -1.0)? - &log_ratio)?.mean_all()?;
        let clip_fraction = ratio
            .affine(1.0, -1.0)?
            .abs()?
            .broadcast_ge(&constant(above(s.clip_coef), &self.device)?)?
            .to_dtype(DType::F32)?
            .mean_all()?;
        let v = read_scalars(&[&policy_loss, &value_loss, &entropy, &approx_kl, &clip_fraction])?;
        Ok(PpoLosses { policy: v[0], value: v[1], entropy: v[2], approx_kl: v[3], clip_fraction: v[4] })
    }
}

impl Agent for GenericPpo {
    /// The policy's mean, clipped to [-1, 1].
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let x = self.normalize(&[obs.iter().map(|&v| v as f64).collect()])?;
        let mean = self.actor.forward(&self.rows(&x)?)?;
        Ok(mean.flatten_all()?.to_vec1::<f32>()?.into_iter().map(|a| a.clamp(-1.0, 1.0)).collect())
    }

    fn parameters(&self) -> Vec<(String, Var)> {
        named_networks(
            self.actor.named_vars("actor.mean"),
            &self.log_std,
            &self.obs_stats,
            self.critic.named_vars("critic"),
        )
    }

    ppo_glue!();
}
