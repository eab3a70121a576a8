//! CrossQ (Bhatt et al., ICLR 2024) on any device: `agents::crossq`'s update from candle's
//! operations, with the batch renormalisation's running statistics kept on the device.
use candle_core::{DType, Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;

use super::{crossq_glue, renorm_net_vars};
use crate::agents::common::buffer::Batch;
use crate::agents::common::device::adam::DeviceAdam;
use crate::agents::common::device::layers::{squashed_sample, DeviceRenorm, DeviceStack, RenormConstants};
use crate::agents::common::device::{read_scalars, row, standard_normal, DeviceBatch};
use crate::agents::config::{Algo, TanhCorrection, TrainConfig};
use crate::agents::crossq::{Passes, Td3Mode, D_MAX, EPSILON, R_MAX};
use crate::agents::{Agent, CrossqAgent, Losses, OffPolicyAgent};
use crate::numeric::optim::Optimizer;

/// Dense layers with batch renormalisation before each and ReLU between them.
struct RenormNet {
    norms: Vec<DeviceRenorm>,
    layers: DeviceStack,
}

impl RenormNet {
    fn from_named(params: &[(String, Var)], prefix: &str, device: &Device) -> Result<RenormNet> {
        let layers = DeviceStack::from_named(params, prefix, device)?;
        let norms = (0..layers.layers().len())
            .map(|i| DeviceRenorm::from_named(params, &format!("{prefix}.norm{i}"), device))
            .collect::<Result<_>>()?;
        Ok(RenormNet { norms, layers })
    }

    fn forward(&self, x: &Tensor, train: bool, steps: u64, frozen: bool, c: RenormConstants) -> Result<Tensor> {
        let mut h = x.clone();
        for (i, norm) in self.norms.iter().enumerate() {
            h = norm.forward(&h, train, steps, frozen, c)?;
            h = self.layers.layer(i, &h, frozen)?;
        }
        Ok(h)
    }

    renorm_net_vars!();
}

/// CrossQ: SAC's policy and temperature with batch-renormalised twin critics and no targets.
pub struct GenericCrossq {
    device: Device,
    obs_dim: usize,
    act_dim: usize,
    gamma: f64,
    renorm: RenormConstants,
    actor: RenormNet,
    critics: [RenormNet; 2],
    log_alpha: Var,
    target_entropy: f64,
    actor_opt: DeviceAdam,
    critic_opt: DeviceAdam,
    alpha_opt: DeviceAdam,
    policy_delay: u64,
    td3: Option<Td3Mode>,
    passes: Passes,
}

impl GenericCrossq {
    /// The fused agent's initial networks (same RNG draws), on `device`.
    pub fn new(
        cfg: &TrainConfig,
        obs_dim: usize,
        act_dim: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> anyhow::Result<Self> {
        let s = cfg.crossq();
        let params = CrossqAgent::new(cfg, obs_dim, act_dim, rng)?.parameters();
        let actor = RenormNet::from_named(&params, "actor", device)?;
        let critics =
            [RenormNet::from_named(&params, "critic0", device)?, RenormNet::from_named(&params, "critic1", device)?];
        let log_alpha = Var::from_tensor(&Tensor::new(&[s.initial_alpha.ln() as f32], device)?)?;
        let adam = |vars: Vec<Var>, lr: f64| -> Result<DeviceAdam> {
            let mut opt = DeviceAdam::new(vars, lr)?;
            opt.beta1 = s.adam_beta1;
            Ok(opt)
        };
        Ok(GenericCrossq {
            device: device.clone(),
            obs_dim,
            act_dim,
            gamma: cfg.gamma,
            renorm: RenormConstants {
                eps: EPSILON,
                r_max: R_MAX,
                d_max: D_MAX,
                momentum: s.batch_norm_momentum,
                warmup: s.renorm_warmup_steps,
            },
            actor_opt: adam(actor.trained_vars(), cfg.actor_lr)?,
            critic_opt: adam(critics.iter().flat_map(|c| c.trained_vars()).collect(), cfg.critic_lr)?,
            alpha_opt: adam(vec![log_alpha.clone()], s.alpha_lr)?,
            actor,
            critics,
            log_alpha,
            target_entropy: s.target_entropy.unwrap_or(-(act_dim as f64)),
            policy_delay: s.policy_delay as u64,
            td3: s.td3(),
            passes: Passes::default(),
        })
    }

    fn policy(&self, obs: &Tensor, train: bool) -> Result<Tensor> {
        self.actor.forward(obs, train, self.passes.actor, false, self.renorm)
    }

    /// The deterministic policy of `td3_mode`: tanh of the actor's mean.
    fn deterministic(&self, obs: &Tensor, train: bool) -> Result<Tensor> {
        self.policy(obs, train)?.narrow(1, 0, self.act_dim)?.tanh()
    }

    /// One pass of both critics over [(s, a); (s', a')], whose halves share batch statistics, and
    /// their step towards r + γ (min Q(s', a') − `entropy`); returns the loss. `entropy` is SAC
    /// mode's α·log π(a'|s'), absent in `td3_mode`.
    fn critic_step(&mut self, b: &DeviceBatch, next_a: &Tensor, entropy: Option<Tensor>) -> Result<Tensor> {
        let n = b.obs.dim(0)?;
        let joint = Tensor::cat(&[Tensor::cat(&[&b.obs, &b.actions], 1)?, Tensor::cat(&[&b.next_obs, next_a], 1)?], 0)?;
        let q = self
            .critics
            .iter()
            .map(|c| c.forward(&joint, true, self.passes.critic, false, self.renorm))
            .collect::<Result<Vec<_>>>()?;
        self.passes.critic += 1;
        let q_next = q[0].narrow(0, n, n)?.minimum(&q[1].narrow(0, n, n)?)?.detach();
        let next_value = match entropy {
            Some(entropy) => (q_next - entropy)?,
            None => q_next,
        };
        let y = (&b.rewards + (&b.not_done * next_value)?.affine(self.gamma, 0.0)?)?.detach();
        let mut critic_loss = Tensor::zeros((), DType::F32, &self.device)?;
        for qk in &q {
            critic_loss =
                (critic_loss + qk.narrow(0, 0, n)?.broadcast_sub(&y)?.sqr()?.mean_all()?.affine(0.5, 0.0)?)?;
        }
        self.critic_opt.step(&critic_loss.backward()?)?;
        self.passes.updates += 1;
        Ok(critic_loss)
    }

    /// The smaller critic's value of `(obs, action)` with the critics frozen, so the actor's loss
    /// trains only the actor.
    fn frozen_min_q(&self, obs: &Tensor, action: &Tensor) -> Result<Tensor> {
        let x = Tensor::cat(&[obs, action], 1)?;
        let frozen = |c: &RenormNet| c.forward(&x, false, self.passes.critic, true, self.renorm);
        frozen(&self.critics[0])?.minimum(&frozen(&self.critics[1])?)
    }

    /// The update in `td3_mode`, with the fused one's draws (the smoothing noise) in its order.
    fn update_td3(&mut self, batch: &Batch, td3: Td3Mode, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let trains_actor = (self.passes.updates + 1).is_multiple_of(self.policy_delay);
        let noise = [td3.smoothing_noise(n * self.act_dim, rng)];
        let b = DeviceBatch::upload(batch, self.obs_dim, self.act_dim, &noise, &self.device)?;
        let next_a = (self.deterministic(&b.next_obs, false)? + &b.noise[0])?.clamp(-1f32, 1f32)?.detach();
        let mut scalars = vec![self.critic_step(&b, &next_a, None)?];
        if trains_actor {
            let pi = self.deterministic(&b.obs, true)?;
            self.passes.actor += 1;
            let actor_loss = self.frozen_min_q(&b.obs, &pi)?.mean_all()?.neg()?;
            self.actor_opt.step(&actor_loss.backward()?)?;
            scalars.push(actor_loss);
        }
        let values = read_scalars(&scalars.iter().collect::<Vec<_>>())?;
        Ok(Losses { critic: values[0], actor: trains_actor.then(|| values[1]), ..Default::default() })
    }
}

impl Agent for GenericCrossq {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let out = self.policy(&row(obs, &self.device)?, false)?;
        out.narrow(1, 0, self.act_dim)?.tanh()?.flatten_all()?.to_vec1::<f32>()
    }

    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        if let Some(td3) = self.td3 {
            return Ok(td3.explore(&self.act(obs)?, rng));
        }
        let eps = Tensor::from_vec(standard_normal(self.act_dim, rng), (1, self.act_dim), &self.device)?;
        let (a, _) = squashed_sample(&self.policy(&row(obs, &self.device)?, false)?, &eps, TanhCorrection::Exact)?;
        a.flatten_all()?.to_vec1::<f32>()
    }

    crossq_glue!();
}

impl OffPolicyAgent for GenericCrossq {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        if let Some(td3) = self.td3 {
            return self.update_td3(batch, td3, rng);
        }
        let n = batch.size;
        let trains_actor = (self.passes.updates + 1).is_multiple_of(self.policy_delay);
        // the fused update's draws, in its order: the next state's sample, then the policy's
        let mut noise = vec![standard_normal(n * self.act_dim, rng)];
        if trains_actor {
            noise.push(standard_normal(n * self.act_dim, rng));
        }
        let b = DeviceBatch::upload(batch, self.obs_dim, self.act_dim, &noise, &self.device)?;
        let alpha = self.log_alpha.as_tensor().detach().exp()?;

        // detached: the critics' loss reaches the next action through the shared batch statistics,
        // but the critics' step does not train the actor
        let (next_a, next_logp) =
            squashed_sample(&self.policy(&b.next_obs, false)?, &b.noise[0], TanhCorrection::Exact)?;
        let (next_a, next_logp) = (next_a.detach(), next_logp.detach());
        let entropy = next_logp.broadcast_mul(&alpha)?;
        let mut scalars = vec![self.critic_step(&b, &next_a, Some(entropy))?];
        if trains_actor {
            let (pi, logp) = squashed_sample(&self.policy(&b.obs, true)?, &b.noise[1], TanhCorrection::Exact)?;
            self.passes.actor += 1;
            let q_pi = self.frozen_min_q(&b.obs, &pi)?;
            let actor_loss = (logp.broadcast_mul(&alpha)? - q_pi)?.mean_all()?;
            self.actor_opt.step(&actor_loss.backward()?)?;

            let gap = logp.detach().affine(1.0, self.target_entropy)?;
            let alpha_loss = self.log_alpha.as_tensor().broadcast_mul(&gap)?.mean_all()?.neg()?;
            self.alpha_opt.step(&alpha_loss.backward()?)?;
            scalars.extend([actor_loss, alpha_loss]);
        }
        scalars.push(self.log_alpha.as_tensor().exp()?);
        let values = read_scalars(&scalars.iter().collect::<Vec<_>>())?;
        Ok(Losses {
            critic: values[0],
            actor: trains_actor.then(|| values[1]),
            alpha_loss: trains_actor.then(|| values[2]),
            alpha: values.last().copied(),
            value: None,
        })
    }
}
