//! CrossQ (Bhatt et al., "CrossQ: Batch Normalization in Deep Reinforcement Learning for Greater
//! Sample Efficiency and Simplicity", ICLR 2024), after Stable-Baselines Jax's `sbx/crossq`
//! (repository `araffin/sbx`): SAC without target networks. Both critics and the actor put batch
//! renormalisation (Ioffe, "Batch Renormalization", NeurIPS 2017) before every dense layer; the
//! critics see the (s, a) and (s', a') batches concatenated in one forward pass, so both halves
//! are normalised with the same statistics, and the target is computed from that same pass
//! (held constant). Adam with beta1 = 0.5, learning rate 1e-3, the actor and temperature updated
//! every third critic update.
//!
//! The critics' width is a setting of its own (`critic_hidden`, the paper's 2048 by default), apart
//! from the actor's (`hidden`). To read it end to end: this file (settings, networks,
//! the fused CPU agent and its update), then `../common/squashed.rs` (the policy head) and
//! `../common/objectives.rs` (the temperature); `device.rs` is the same agent on any candle device.
pub mod device;

use serde::{Deserialize, Serialize};

use candle_core::{DType, Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::agents::common::buffer::Batch;
use crate::agents::common::nets::{batch_tensor, scalar_var, DenseStack, Mlp, Output};
use crate::agents::common::objectives::{temperature, temperature_loss};
use crate::agents::common::squashed::{sample_squashed, squashed_mean};
use crate::agents::config::{positive, Algo, TanhCorrection, TrainConfig};
use crate::agents::{layer_sizes, Agent, Losses, OffPolicyAgent};
use crate::numeric::batch_renorm::{batch_renorm, RenormLimits, RenormMode};
use crate::numeric::dense::dense;
use crate::numeric::inplace::Activation;
use crate::numeric::optim::{Adam, Optimizer};

/// Batch renormalisation's limits on r and d (Ioffe 2017; sbx's `BatchRenorm`).
pub(crate) const R_MAX: f64 = 3.0;
pub(crate) const D_MAX: f64 = 5.0;
/// Added to every variance (sbx, flax).
pub(crate) const EPSILON: f64 = 1e-3;

/// Batch renormalisation over the batch dimension of `[n, features]` inputs, with a learned
/// scale and bias. In training mode it normalises with the batch's statistics, corrected towards
/// the running ones by r and d (held constant) once `warmup` training passes have run (before,
/// plain batch normalisation), and moves the running statistics towards the batch's; in
/// evaluation mode it uses the running statistics alone.
pub struct BatchRenorm {
    scale: Var,
    bias: Var,
    running_mean: Var,
    running_var: Var,
    momentum: f64,
    warmup: u64,
}

impl BatchRenorm {
    /// A layer for `features` inputs: scale 1, bias 0, running mean 0 and variance 1.
    pub fn new(features: usize, momentum: f64, warmup: u64) -> Result<BatchRenorm> {
        let cpu = &Device::Cpu;
        let var = |v: f32| Var::from_tensor(&Tensor::full(v, features, cpu)?);
        Ok(BatchRenorm {
            scale: var(1.0)?,
            bias: var(0.0)?,
            running_mean: var(0.0)?,
            running_var: var(1.0)?,
            momentum,
            warmup,
        })
    }

    /// Normalises `x`. `train`: batch statistics (and the running ones move); `steps`: training
    /// passes before this one; `frozen`: scale and bias held constant (gradients reach `x` only).
    pub fn forward(&self, x: &Tensor, train: bool, steps: u64, frozen: bool) -> Result<Tensor> {
        let (scale, bias) = if frozen {
            (self.scale.as_tensor().detach(), self.bias.as_tensor().detach())
        } else {
            (self.scale.as_tensor().clone(), self.bias.as_tensor().clone())
        };
        let mode = match (train, steps >= self.warmup) {
            (false, _) => RenormMode::Running,
            (true, false) => RenormMode::Batch,
            (true, true) => RenormMode::Renorm,
        };
        let running_mean = self.running_mean.as_tensor().to_vec1::<f32>()?;
        let running_var = self.running_var.as_tensor().to_vec1::<f32>()?;
        let limits = RenormLimits { eps: EPSILON, r_max: R_MAX, d_max: D_MAX };
        let (y, batch) = batch_renorm(x, &scale, &bias, &running_mean, &running_var, mode, limits)?;
        if let Some((batch_mean, batch_var)) = batch {
            let m = self.momentum as f32;
            let moved = |running: &[f32], batch: &[f32]| -> Vec<f32> {
                running.iter().zip(batch).map(|(r, b)| r * m + b * (1.0 - m)).collect()
            };
            let f = running_mean.len();
            self.running_mean.set(&Tensor::from_vec(moved(&running_mean, &batch_mean), f, &Device::Cpu)?)?;
            self.running_var.set(&Tensor::from_vec(moved(&running_var, &batch_var), f, &Device::Cpu)?)?;
        }
        Ok(y)
    }

    fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        vec![
            (format!("{prefix}.scale"), self.scale.clone()),
            (format!("{prefix}.bias"), self.bias.clone()),
            (format!("{prefix}.running_mean"), self.running_mean.clone()),
            (format!("{prefix}.running_var"), self.running_var.clone()),
        ]
    }
}

/// Dense layers with batch renormalisation before each and ReLU between them.
struct RenormMlp {
    norms: Vec<BatchRenorm>,
    layers: DenseStack,
}

impl RenormMlp {
    fn new(sizes: &[usize], cfg: &TrainConfig, rng: &mut ChaCha8Rng) -> Result<RenormMlp> {
        let s = cfg.crossq();
        let mlp = Mlp::new(sizes, Output::Linear, cfg.weight_init, rng)?;
        let layers = DenseStack::new((0..sizes.len() - 1).map(|i| mlp.layer(i).clone()).collect());
        let norms = sizes[..sizes.len() - 1]
            .iter()
            .map(|&f| BatchRenorm::new(f, s.batch_norm_momentum, s.renorm_warmup_steps))
            .collect::<Result<_>>()?;
        Ok(RenormMlp { norms, layers })
    }

    fn forward(&self, x: &Tensor, train: bool, steps: u64, frozen: bool) -> Result<Tensor> {
        let mut h = x.clone();
        let last = self.layers.layers().len() - 1;
        for (i, (norm, (w, b))) in self.norms.iter().zip(self.layers.layers()).enumerate() {
            h = norm.forward(&h, train, steps, frozen)?;
            let (w, b) = if frozen {
                (w.as_tensor().detach(), b.as_tensor().detach())
            } else {
                (w.as_tensor().clone(), b.as_tensor().clone())
            };
            h = dense(&h, &w, &b, if i < last { Activation::Relu } else { Activation::Identity })?;
        }
        Ok(h)
    }

    renorm_net_vars!();
}

/// CrossQ's counters, which checkpoints keep by name (the fused and the generic agent alike).
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct Passes {
    /// Critic updates done.
    pub updates: u64,
    /// Training passes through the actor's and the critics' normalisation layers.
    pub actor: u64,
    pub critic: u64,
}

impl Passes {
    pub fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![("updates", self.updates), ("actor_passes", self.actor), ("critic_passes", self.critic)]
    }

    pub fn set(&mut self, name: &str, value: u64) {
        match name {
            "updates" => self.updates = value,
            "actor_passes" => self.actor = value,
            "critic_passes" => self.critic = value,
            _ => {}
        }
    }
}

/// CrossQ: SAC's policy and temperature with batch-renormalised twin critics and no targets.
pub struct CrossqAgent {
    obs_dim: usize,
    act_dim: usize,
    gamma: f64,
    actor: RenormMlp,
    critics: [RenormMlp; 2],
    log_alpha: Var,
    target_entropy: f64,
    actor_opt: Adam,
    critic_opt: Adam,
    alpha_opt: Adam,
    policy_delay: u64,
    td3: Option<Td3Mode>,
    passes: Passes,
}

impl CrossqAgent {
    /// Builds the networks for `obs_dim`/`act_dim`, initialised from `rng`.
    pub fn new(cfg: &TrainConfig, obs_dim: usize, act_dim: usize, rng: &mut ChaCha8Rng) -> Result<Self> {
        let s = cfg.crossq();
        let actor = RenormMlp::new(&layer_sizes(obs_dim, &cfg.hidden, 2 * act_dim), cfg, rng)?;
        let critic_sizes = layer_sizes(obs_dim + act_dim, &s.critic_hidden, 1);
        let critics = [RenormMlp::new(&critic_sizes, cfg, rng)?, RenormMlp::new(&critic_sizes, cfg, rng)?];
        let log_alpha = scalar_var(s.initial_alpha.ln() as f32)?;
        let adam = |vars: Vec<Var>, lr: f64| Adam::with_beta1(vars, lr, s.adam_beta1);
        Ok(CrossqAgent {
            obs_dim,
            act_dim,
            gamma: cfg.gamma,
            actor_opt: adam(actor.trained_vars(), cfg.actor_lr),
            critic_opt: adam(critics.iter().flat_map(|c| c.trained_vars()).collect(), cfg.critic_lr),
            alpha_opt: adam(vec![log_alpha.clone()], s.alpha_lr),
            actor,
            critics,
            log_alpha,
            target_entropy: s.target_entropy.unwrap_or(-(act_dim as f64)),
            policy_delay: s.policy_delay as u64,
            td3: s.td3(),
            passes: Passes::default(),
        })
    }

    /// The current temperature.
    pub fn alpha(&self) -> Result<f64> {
        temperature(&self.log_alpha)
    }

    fn sample(&self, obs: &Tensor, train: bool, rng: &mut ChaCha8Rng) -> Result<(Tensor, Tensor)> {
        sample_squashed(&self.actor.forward(obs, train, self.passes.actor, false)?, TanhCorrection::Exact, rng)
    }

    /// The deterministic policy of `td3_mode`: tanh of the actor's mean, `[n, act_dim]`.
    fn deterministic(&self, obs: &Tensor, train: bool) -> Result<Tensor> {
        self.actor.forward(obs, train, self.passes.actor, false)?.narrow(1, 0, self.act_dim)?.tanh()
    }

    /// The smaller critic's value of `(obs, action)` with the critics frozen (in evaluation mode,
    /// scale and bias held), so the actor's loss trains only the actor.
    fn frozen_min_q(&self, obs: &Tensor, action: &Tensor) -> Result<Tensor> {
        let x = Tensor::cat(&[obs, action], 1)?;
        let frozen = |c: &RenormMlp| c.forward(&x, false, self.passes.critic, true);
        frozen(&self.critics[0])?.minimum(&frozen(&self.critics[1])?)
    }
}

/// A batch-renormalised network's parameters, for both versions: `trained_vars` are the
/// weights and biases, then each norm's scale and bias (the optimiser's order), never the running
/// statistics; `named_vars` adds each norm's statistics under `<prefix>.norm<i>`.
macro_rules! renorm_net_vars {
    () => {
        fn trained_vars(&self) -> Vec<Var> {
            let mut out = self.layers.vars();
            out.extend(self.norms.iter().flat_map(|n| [n.scale.clone(), n.bias.clone()]));
            out
        }

        fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
            let mut out = self.layers.named_vars(prefix);
            for (i, n) in self.norms.iter().enumerate() {
                out.extend(n.named_vars(&format!("{prefix}.norm{i}")));
            }
            out
        }
    };
}
pub(crate) use renorm_net_vars;

/// The [`Agent`] methods both versions of CrossQ share (this file's fused one and `device.rs`'s),
/// written once: both keep their networks, optimisers and counters under the same field names, so
/// a checkpoint names the same things on either path.
macro_rules! crossq_glue {
    () => {
        fn algo(&self) -> Algo {
            Algo::Crossq
        }

        fn parameters(&self) -> Vec<(String, Var)> {
            let mut out = self.actor.named_vars("actor");
            out.extend(self.critics[0].named_vars("critic0"));
            out.extend(self.critics[1].named_vars("critic1"));
            out.push(("log_alpha".into(), self.log_alpha.clone()));
            out
        }

        fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn Optimizer)> {
            vec![
                ("actor_opt", &mut self.actor_opt as &mut dyn Optimizer),
                ("critic_opt", &mut self.critic_opt),
                ("alpha_opt", &mut self.alpha_opt),
            ]
        }

        fn counters(&self) -> Vec<(&'static str, u64)> {
            self.passes.counters()
        }

        fn set_counter(&mut self, name: &str, value: u64) {
            self.passes.set(name, value)
        }
    };
}
pub(crate) use crossq_glue;

impl Agent for CrossqAgent {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        squashed_mean(&self.actor.forward(&batch_tensor(obs, 1, self.obs_dim)?, false, self.passes.actor, false)?)
    }

    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        if let Some(td3) = self.td3 {
            return Ok(td3.explore(&self.act(obs)?, rng));
        }
        let (a, _) = self.sample(&batch_tensor(obs, 1, self.obs_dim)?, false, rng)?;
        a.flatten_all()?.to_vec1::<f32>()
    }

    crossq_glue!();
}

impl OffPolicyAgent for CrossqAgent {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let obs = batch_tensor(&batch.obs, n, self.obs_dim)?;
        let actions = batch_tensor(&batch.actions, n, self.act_dim)?;
        let next_obs = batch_tensor(&batch.next_obs, n, self.obs_dim)?;
        let rewards = batch_tensor(&batch.rewards, n, 1)?;
        let not_done = batch_tensor(&batch.terminated, n, 1)?.affine(-1.0, 1.0)?;
        let alpha = self.alpha()?;
        let mut losses = Losses::default();

        // One pass of both critics over [(s, a); (s', a')]: the halves share batch statistics.
        let (next_a, next_logp) = match self.td3 {
            Some(td3) => {
                let eps =
                    Tensor::from_vec(td3.smoothing_noise(n * self.act_dim, rng), (n, self.act_dim), &Device::Cpu)?;
                let a = (self.deterministic(&next_obs, false)? + eps)?.clamp(-1f32, 1f32)?;
                (a, Tensor::zeros((n, 1), DType::F32, &Device::Cpu)?)
            }
            None => self.sample(&next_obs, false, rng)?,
        };
        let joint = Tensor::cat(&[Tensor::cat(&[&obs, &actions], 1)?, Tensor::cat(&[&next_obs, &next_a], 1)?], 0)?;
        let q: Vec<Tensor> =
            self.critics.iter().map(|c| c.forward(&joint, true, self.passes.critic, false)).collect::<Result<_>>()?;
        self.passes.critic += 1;
        let q_next = q[0].narrow(0, n, n)?.minimum(&q[1].narrow(0, n, n)?)?.detach();
        let soft_next = (q_next - next_logp.detach().affine(alpha, 0.0)?)?;
        let y = (rewards + (not_done * soft_next)?.affine(self.gamma, 0.0)?)?.detach();
        let mut critic_loss = Tensor::zeros((), DType::F32, &Device::Cpu)?;
        for qk in &q {
            critic_loss =
                (critic_loss + qk.narrow(0, 0, n)?.broadcast_sub(&y)?.sqr()?.mean_all()?.affine(0.5, 0.0)?)?;
        }
        self.critic_opt.step(&critic_loss.backward()?)?;
        losses.critic = critic_loss.to_scalar::<f32>()? as f64;
        self.passes.updates += 1;

        if self.td3.is_some() {
            if self.passes.updates.is_multiple_of(self.policy_delay) {
                let pi_a = self.deterministic(&obs, true)?;
                self.passes.actor += 1;
                let actor_loss = self.frozen_min_q(&obs, &pi_a)?.mean_all()?.neg()?;
                self.actor_opt.step(&actor_loss.backward()?)?;
                losses.actor = Some(actor_loss.to_scalar::<f32>()? as f64);
            }
            return Ok(losses);
        }
        if self.passes.updates.is_multiple_of(self.policy_delay) {
            let (pi_a, logp) = self.sample(&obs, true, rng)?;
            self.passes.actor += 1;
            let q_pi = self.frozen_min_q(&obs, &pi_a)?;
            let actor_loss = (logp.affine(alpha, 0.0)? - q_pi)?.mean_all()?;
            self.actor_opt.step(&actor_loss.backward()?)?;
            losses.actor = Some(actor_loss.to_scalar::<f32>()? as f64);

            let alpha_loss = temperature_loss(&self.log_alpha, &logp, self.target_entropy)?;
            self.alpha_opt.step(&alpha_loss.backward()?)?;
            losses.alpha_loss = Some(alpha_loss.to_scalar::<f32>()? as f64);
        }
        losses.alpha = Some(self.alpha()?);
        Ok(losses)
    }
}

/// CrossQ's own settings; the defaults are the paper's and sbx's. It reads the shared `hidden`
/// (the actor's layers), `actor_lr` and `critic_lr`, `batch_size`, `gamma`, the buffer,
/// `warmup_steps` and `learning_starts`; it has no target networks, so `tau` does not apply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CrossqConfig {
    /// The critics' hidden layers (the paper's 2048-2048; 256-512 wide is what 2 cores afford).
    pub critic_hidden: Vec<usize>,
    /// Actor and temperature updates happen every this many critic updates.
    pub policy_delay: u32,
    /// Adam's beta1 for every optimiser.
    pub adam_beta1: f64,
    /// Temperature at the start.
    pub initial_alpha: f64,
    /// Adam learning rate of the log-temperature.
    pub alpha_lr: f64,
    /// Target entropy for the temperature; absent means -dim(A).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_entropy: Option<f64>,
    /// Weight of the old value in the running statistics' moving average.
    pub batch_norm_momentum: f64,
    /// Training passes of plain batch normalisation before the renormalisation's corrections start.
    pub renorm_warmup_steps: u64,
    /// Train a deterministic actor as TD3 does, on CrossQ's critics: the CrossQ authors' `td3_mode`
    /// (repository `adityab/CrossQ`, `sbx/sac/sac.py` and `train.py -algo td3 -bn 1`). The tanh of
    /// the actor's mean is the policy; exploration adds N(0, `exploration_noise`); the next action
    /// of the critics' target adds TD3's smoothing noise, N(0, `policy_noise`) clipped at
    /// `noise_clip`; the actor ascends the smaller critic; no entropy term, no temperature. Off
    /// unless asked for.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub td3_mode: bool,
    /// With `td3_mode`: the exploration noise's std, in units of the action half-range (TD3's 0.1).
    #[serde(default = "Td3Mode::exploration_noise", skip_serializing_if = "Td3Mode::is_exploration_noise")]
    pub exploration_noise: f64,
    /// With `td3_mode`: the target smoothing noise's std (TD3's 0.2).
    #[serde(default = "Td3Mode::policy_noise", skip_serializing_if = "Td3Mode::is_policy_noise")]
    pub policy_noise: f64,
    /// With `td3_mode`: the smoothing noise's clip (TD3's 0.5).
    #[serde(default = "Td3Mode::noise_clip", skip_serializing_if = "Td3Mode::is_noise_clip")]
    pub noise_clip: f64,
}

/// TD3's noise settings (Fujimoto et al. 2018), which the CrossQ authors' `td3_mode` keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Td3Mode {
    pub exploration_noise: f64,
    pub policy_noise: f64,
    pub noise_clip: f64,
}

impl Td3Mode {
    const DEFAULT: Td3Mode = Td3Mode { exploration_noise: 0.1, policy_noise: 0.2, noise_clip: 0.5 };

    fn exploration_noise() -> f64 {
        Self::DEFAULT.exploration_noise
    }

    fn is_exploration_noise(v: &f64) -> bool {
        *v == Self::DEFAULT.exploration_noise
    }

    fn policy_noise() -> f64 {
        Self::DEFAULT.policy_noise
    }

    fn is_policy_noise(v: &f64) -> bool {
        *v == Self::DEFAULT.policy_noise
    }

    fn noise_clip() -> f64 {
        Self::DEFAULT.noise_clip
    }

    fn is_noise_clip(v: &f64) -> bool {
        *v == Self::DEFAULT.noise_clip
    }

    /// Exploration: `action` plus N(0, exploration_noise) per element, within [-1, 1].
    pub(crate) fn explore(&self, action: &[f32], rng: &mut ChaCha8Rng) -> Vec<f32> {
        action
            .iter()
            .map(|&a| {
                let z: f64 = StandardNormal.sample(rng);
                (a as f64 + self.exploration_noise * z).clamp(-1.0, 1.0) as f32
            })
            .collect()
    }

    /// `count` draws of the target smoothing noise, N(0, policy_noise) clipped at `noise_clip`.
    pub(crate) fn smoothing_noise(&self, count: usize, rng: &mut ChaCha8Rng) -> Vec<f32> {
        let c = self.noise_clip;
        (0..count)
            .map(|_| {
                let z: f64 = StandardNormal.sample(rng);
                (self.policy_noise * z).clamp(-c, c) as f32
            })
            .collect()
    }
}

impl CrossqConfig {
    pub(crate) const KEYS: &'static [&'static str] = &[
        "critic_hidden",
        "policy_delay",
        "adam_beta1",
        "initial_alpha",
        "alpha_lr",
        "target_entropy",
        "batch_norm_momentum",
        "renorm_warmup_steps",
        "td3_mode",
        "exploration_noise",
        "policy_noise",
        "noise_clip",
    ];

    /// TD3's noise settings when `td3_mode` is on.
    pub(crate) fn td3(&self) -> Option<Td3Mode> {
        self.td3_mode.then_some(Td3Mode {
            exploration_noise: self.exploration_noise,
            policy_noise: self.policy_noise,
            noise_clip: self.noise_clip,
        })
    }

    /// Checks this section's settings (with the shared ones they depend on).
    pub(crate) fn validate(&self, train: &TrainConfig) -> anyhow::Result<()> {
        anyhow::ensure!(
            !self.critic_hidden.is_empty() && self.critic_hidden.iter().all(|&h| h > 0),
            "critic_hidden needs at least one layer size > 0"
        );
        anyhow::ensure!(self.policy_delay >= 1, "policy_delay must be at least 1");
        anyhow::ensure!((0.0..1.0).contains(&self.adam_beta1), "adam_beta1 must lie in [0, 1)");
        anyhow::ensure!((0.0..1.0).contains(&self.batch_norm_momentum), "batch_norm_momentum must lie in [0, 1)");
        positive("initial_alpha", self.initial_alpha)?;
        positive("alpha_lr", self.alpha_lr)?;
        for (name, value, default) in [
            ("exploration_noise", self.exploration_noise, Td3Mode::DEFAULT.exploration_noise),
            ("policy_noise", self.policy_noise, Td3Mode::DEFAULT.policy_noise),
            ("noise_clip", self.noise_clip, Td3Mode::DEFAULT.noise_clip),
        ] {
            anyhow::ensure!(value >= 0.0 && value.is_finite(), "{name} must be a finite number >= 0, got {value}");
            anyhow::ensure!(
                self.td3_mode || value == default,
                "{name} = {value} applies only with td3_mode = true (CrossQ's own actor explores by sampling)"
            );
        }
        anyhow::ensure!(
            train.batch_size >= 2,
            "batch normalisation needs at least 2 transitions per batch, got batch_size {}",
            train.batch_size
        );
        Ok(())
    }
}

impl TrainConfig {
    /// CrossQ's (Bhatt et al. 2024; sbx's `CrossQ`): actor 256-256, critics 2048-2048, Adam 1e-3
    /// with beta1 0.5, batch 256, 5000 random steps, policy delay 3, batch-norm momentum 0.99 and
    /// 100k renormalisation warm-up passes.
    pub(crate) fn crossq_defaults() -> TrainConfig {
        TrainConfig {
            warmup_steps: 5000,
            learning_starts: 5000,
            batch_size: 256,
            hidden: vec![256, 256],
            actor_lr: 1e-3,
            critic_lr: 1e-3,
            crossq: Some(CrossqConfig {
                critic_hidden: vec![2048, 2048],
                policy_delay: 3,
                adam_beta1: 0.5,
                initial_alpha: 1.0,
                alpha_lr: 1e-3,
                target_entropy: None,
                batch_norm_momentum: 0.99,
                renorm_warmup_steps: 100_000,
                td3_mode: false,
                exploration_noise: Td3Mode::DEFAULT.exploration_noise,
                policy_noise: Td3Mode::DEFAULT.policy_noise,
                noise_clip: Td3Mode::DEFAULT.noise_clip,
            }),
            ..TrainConfig::shared_defaults(Algo::Crossq)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn column_stats(x: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
        let n = x.len() as f64;
        let mut mean = [0.0; 2];
        let mut var = [0.0; 2];
        for j in 0..2 {
            mean[j] = x.iter().map(|r| r[j]).sum::<f64>() / n;
            var[j] = x.iter().map(|r| (r[j] - mean[j]).powi(2)).sum::<f64>() / n;
        }
        (mean, var)
    }

    fn run(layer: &BatchRenorm, x: &[[f64; 2]], train: bool, steps: u64) -> Vec<Vec<f32>> {
        let flat: Vec<f32> = x.iter().flatten().map(|&v| v as f32).collect();
        let t = Tensor::from_vec(flat, (x.len(), 2), &Device::Cpu).unwrap();
        layer.forward(&t, train, steps, false).unwrap().to_vec2::<f32>().unwrap()
    }

    #[test]
    fn batch_renorm_matches_a_hand_computation() {
        let x = [[1.0, -2.0], [3.0, 0.5], [-1.0, 4.0], [2.0, 1.5]];
        let (mean, var) = column_stats(&x);
        let m = 0.9;

        // During warm-up: plain batch normalisation, and the running statistics move.
        let layer = BatchRenorm::new(2, m, 10).unwrap();
        let y = run(&layer, &x, true, 0);
        for (i, row) in x.iter().enumerate() {
            for j in 0..2 {
                let expect = (row[j] - mean[j]) / (var[j] + EPSILON).sqrt();
                assert!((y[i][j] as f64 - expect).abs() < 1e-5, "warm-up ({i}, {j}): {} vs {expect}", y[i][j]);
            }
        }
        let rm = layer.running_mean.as_tensor().to_vec1::<f32>().unwrap();
        let rv = layer.running_var.as_tensor().to_vec1::<f32>().unwrap();
        for j in 0..2 {
            assert!((rm[j] as f64 - (1.0 - m) * mean[j]).abs() < 1e-6);
            assert!((rv[j] as f64 - (m + (1.0 - m) * var[j])).abs() < 1e-6);
        }

        // After warm-up: r and d correct the batch statistics towards the running ones (here the
        // running statistics after the pass above), with r and d clipped.
        let x2 = [[10.0, 0.0], [12.0, 0.1], [8.0, -0.1], [14.0, 0.2]];
        let (mean2, var2) = column_stats(&x2);
        let y2 = run(&layer, &x2, true, 10);
        for j in 0..2 {
            let running_std = (rv[j] as f64 + EPSILON).sqrt();
            let r = ((var2[j] + EPSILON).sqrt() / running_std).clamp(1.0 / R_MAX, R_MAX);
            let d = ((mean2[j] - rm[j] as f64) / running_std).clamp(-D_MAX, D_MAX);
            let (cm, cv) = (mean2[j] - d * var2[j].sqrt() / r, var2[j] / (r * r));
            for (i, row) in x2.iter().enumerate() {
                let expect = (row[j] - cm) / (cv + EPSILON).sqrt();
                assert!((y2[i][j] as f64 - expect).abs() < 1e-4, "renorm ({i}, {j}): {} vs {expect}", y2[i][j]);
            }
        }
        // Column 0's mean is far from the running one: d is clipped at D_MAX.
        assert!((mean2[0] - rm[0] as f64) / (rv[0] as f64 + EPSILON).sqrt() > D_MAX);

        // Evaluation: the running statistics alone, and they stay where they are.
        let before = layer.running_mean.as_tensor().to_vec1::<f32>().unwrap();
        let rv = layer.running_var.as_tensor().to_vec1::<f32>().unwrap();
        let y3 = run(&layer, &x, false, 10);
        for (i, row) in x.iter().enumerate() {
            for j in 0..2 {
                let expect = (row[j] - before[j] as f64) / (rv[j] as f64 + EPSILON).sqrt();
                assert!((y3[i][j] as f64 - expect).abs() < 1e-5);
            }
        }
        assert_eq!(layer.running_mean.as_tensor().to_vec1::<f32>().unwrap(), before);
    }

    fn td3_config() -> TrainConfig {
        let mut cfg = TrainConfig::crossq_defaults();
        cfg.hidden = vec![16, 16];
        cfg.batch_size = 8;
        let s = cfg.crossq.as_mut().unwrap();
        s.critic_hidden = vec![16, 16];
        s.td3_mode = true;
        cfg
    }

    #[test]
    fn td3_mode_explores_around_the_deterministic_action_with_tds_noise() {
        use rand::SeedableRng;
        let cfg = td3_config();
        let mut agent = CrossqAgent::new(&cfg, 3, 2, &mut ChaCha8Rng::seed_from_u64(0)).unwrap();
        let obs = [0.5f32, -1.0, 2.0];
        let mean = agent.act(&obs).unwrap();
        let (mut a, mut b) = (ChaCha8Rng::seed_from_u64(7), ChaCha8Rng::seed_from_u64(7));
        let explored = agent.explore(&obs, &mut a).unwrap();
        for (i, e) in explored.iter().enumerate() {
            let z: f64 = StandardNormal.sample(&mut b);
            assert_eq!(*e, (mean[i] as f64 + 0.1 * z).clamp(-1.0, 1.0) as f32);
        }
        // many draws: the exploration noise has TD3's std; the smoothing noise its std and clip
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let td3 = cfg.crossq().td3().unwrap();
        let d: Vec<f64> = (0..20000).map(|_| (td3.explore(&[0.0], &mut rng)[0]) as f64).collect();
        let std = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
        assert!((std - 0.1).abs() < 0.003, "{std}");
        let s = td3.smoothing_noise(20000, &mut rng);
        assert!(s.iter().all(|x| x.abs() <= 0.5) && s.contains(&0.5) && s.contains(&-0.5));
        // N(0, 0.2) clipped at 0.5 (2.5 std) keeps nearly all its variance
        let std = (s.iter().map(|x| (*x as f64).powi(2)).sum::<f64>() / s.len() as f64).sqrt();
        assert!((std - 0.2).abs() < 0.005, "{std}");
    }

    #[test]
    fn td3_mode_trains_the_actor_on_the_policy_delay_without_a_temperature() {
        use rand::SeedableRng;
        let cfg = td3_config();
        let mut agent = CrossqAgent::new(&cfg, 3, 2, &mut ChaCha8Rng::seed_from_u64(0)).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let batch = Batch {
            size: 8,
            obs: (0..24).map(|i| (i as f32 * 0.37).sin()).collect(),
            actions: (0..16).map(|i| (i as f32 * 0.61).cos() * 0.9).collect(),
            rewards: (0..8).map(|i| i as f32 * 0.1).collect(),
            next_obs: (0..24).map(|i| (i as f32 * 0.29).cos()).collect(),
            terminated: vec![0.0; 8],
        };
        let alpha = agent.alpha().unwrap();
        for u in 1..=6u64 {
            let l = agent.update(&batch, &mut rng).unwrap();
            assert!(l.critic.is_finite());
            assert_eq!(l.actor.is_some(), u % 3 == 0, "update {u}");
            assert!(l.alpha.is_none() && l.alpha_loss.is_none());
        }
        assert_eq!(agent.alpha().unwrap(), alpha, "td3_mode has no temperature to learn");
        assert_eq!((agent.passes.updates, agent.passes.actor, agent.passes.critic), (6, 2, 6));
    }

    #[test]
    fn td3_mode_settings_are_checked_and_omitted_when_off() {
        let mut cfg = TrainConfig::crossq_defaults();
        assert!(!toml::to_string(&cfg).unwrap().contains("td3_mode"));
        assert!(!toml::to_string(&cfg).unwrap().contains("noise"));
        cfg.crossq.as_mut().unwrap().exploration_noise = 0.2;
        let err = cfg.crossq().validate(&cfg).unwrap_err().to_string();
        assert!(err.contains("exploration_noise") && err.contains("td3_mode"), "{err}");
        let s = cfg.crossq.as_mut().unwrap();
        s.td3_mode = true;
        s.noise_clip = -0.1;
        let err = cfg.crossq().validate(&cfg).unwrap_err().to_string();
        assert!(err.contains("noise_clip"), "{err}");
        cfg.crossq.as_mut().unwrap().noise_clip = 0.5;
        cfg.crossq().validate(&cfg).unwrap();
        let text = toml::to_string(&cfg).unwrap();
        assert!(text.contains("td3_mode = true") && text.contains("exploration_noise = 0.2"), "{text}");
    }

    #[test]
    fn gradients_flow_through_the_batch_statistics() {
        // Batch normalisation's output sums to zero per column whatever the input, so the
        // gradient of the column sum with respect to every input is zero; a layer that treated
        // the statistics as constants would give 1 / std instead.
        let layer = BatchRenorm::new(1, 0.99, 100).unwrap();
        let x = Var::from_tensor(&Tensor::new(&[[1.0f32], [2.0], [4.0]], &Device::Cpu).unwrap()).unwrap();
        let y = layer.forward(x.as_tensor(), true, 0, false).unwrap();
        let grads = y.sum_all().unwrap().backward().unwrap();
        let g = grads.get(x.as_tensor()).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        assert!(g.iter().all(|v| v.abs() < 1e-5), "{g:?}");
    }
}
