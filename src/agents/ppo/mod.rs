//! Proximal Policy Optimization (Schulman et al. 2017) for continuous actions, after CleanRL's
//! `ppo_continuous_action.py` (vwxyzjn/cleanrl): a Gaussian policy whose mean is a tanh MLP and
//! whose log-std is a state-independent parameter, a separate tanh MLP critic, orthogonal
//! initialisation (gain sqrt 2, 0.01 on the mean's output, 1 on the value's), the clipped
//! surrogate objective, a clipped value loss, advantage normalisation per minibatch and global
//! gradient-norm clipping. Observations are normalised by running statistics that belong to the
//! policy (they are saved with it and used when it acts). ReLU networks, PyTorch's default
//! initialisation and a starting log-std are settings, for rl-baselines3-zoo's tuned MuJoCo
//! entries (DLR-RM/rl-baselines3-zoo, `hyperparams/ppo.yml`).
//!
//! This file holds the settings, the networks and one minibatch update; `update.rs` holds GAE,
//! the epochs, the minibatches and the KL stop, and `device.rs` the same agent on any candle
//! device. The collection loop and reward normalisation live in `train::on_policy`. Actions live in [-1, 1]^n like every agent's: a sample
//! is clipped to it before it reaches the environment, and its log-probability is that of the
//! unclipped sample, as in CleanRL.
pub mod device;
pub mod update;

use serde::{Deserialize, Serialize};

use candle_core::{Device, Result, Tensor, Var, D};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::agents::common::nets::{batch_tensor, orthogonal, torch_default_layer, DenseStack};
use crate::agents::config::{positive, Algo, TrainConfig, WeightInit};
use crate::agents::{layer_sizes, Agent, OnPolicyAgent};
use crate::numeric::dense::dense;
use crate::numeric::inplace::Activation as DenseActivation;
use crate::numeric::optim::{Adam, Optimizer};

/// gymnasium's `NormalizeObservation` epsilon and the clip CleanRL applies after it.
const OBS_EPSILON: f64 = 1e-8;

/// The nonlinearity between PPO's hidden layers: tanh (CleanRL's, the default) or ReLU
/// (rl-baselines3-zoo's tuned MuJoCo settings, `activation_fn=nn.ReLU`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Activation {
    /// tanh.
    #[default]
    Tanh,
    /// max(x, 0).
    Relu,
}

impl Activation {
    fn is_tanh(&self) -> bool {
        *self == Activation::Tanh
    }
}

/// Dense layers with the activation between them and nothing after the last; the parameters,
/// their checkpoint names and updates are `DenseStack`'s.
struct PpoMlp {
    stack: DenseStack,
    activation: Activation,
}

impl PpoMlp {
    /// Orthogonal weights (gain sqrt 2, `output_gain` on the last layer) and zero biases, as
    /// CleanRL; with `WeightInit::Uniform`, PyTorch's `nn.Linear` default (SB3's `ortho_init=False`).
    fn new(
        sizes: &[usize],
        output_gain: f64,
        init: WeightInit,
        activation: Activation,
        rng: &mut ChaCha8Rng,
    ) -> Result<PpoMlp> {
        let n = sizes.len() - 1;
        let mut layers = Vec::with_capacity(n);
        for (i, w) in sizes.windows(2).enumerate() {
            let (fan_in, fan_out) = (w[0], w[1]);
            let (weight, bias) = match init {
                WeightInit::Orthogonal => {
                    let gain = if i + 1 == n { output_gain } else { std::f64::consts::SQRT_2 };
                    (orthogonal(fan_out, fan_in, gain, rng), vec![0.0f32; fan_out])
                }
                WeightInit::Uniform => torch_default_layer(fan_in, fan_out, rng),
            };
            let weight = Tensor::from_vec(weight, (fan_out, fan_in), &Device::Cpu)?;
            let bias = Tensor::from_vec(bias, fan_out, &Device::Cpu)?;
            layers.push((Var::from_tensor(&weight)?, Var::from_tensor(&bias)?));
        }
        Ok(PpoMlp { stack: DenseStack::new(layers), activation })
    }

    fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let layers = self.stack.layers();
        let mut h = x.clone();
        for (i, (w, b)) in layers.iter().enumerate() {
            h = dense(&h, w.as_tensor(), b.as_tensor(), DenseActivation::Identity)?;
            if i + 1 < layers.len() {
                h = match self.activation {
                    Activation::Tanh => h.tanh()?,
                    Activation::Relu => h.relu()?,
                };
            }
        }
        Ok(h)
    }
}

/// What the policy and value function say about a batch of observations while collecting.
pub struct PolicyStep {
    /// Sampled actions, unclipped, `n x act_dim`.
    pub actions: Vec<f32>,
    /// Log-probability of each sampled action.
    pub log_probs: Vec<f32>,
    /// The value of each observation.
    pub values: Vec<f32>,
}

/// A minibatch of a rollout, row-major.
pub struct PpoBatch {
    /// Normalised observations, `n x obs_dim`.
    pub obs: Vec<f32>,
    /// The actions taken (unclipped samples), `n x act_dim`.
    pub actions: Vec<f32>,
    /// Their log-probabilities when sampled.
    pub log_probs: Vec<f32>,
    /// GAE advantages.
    pub advantages: Vec<f32>,
    /// Value targets (advantage + value).
    pub returns: Vec<f32>,
    /// The values when collected.
    pub values: Vec<f32>,
}

/// The diagnostics CleanRL logs per update.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PpoLosses {
    /// Clipped surrogate loss.
    pub policy: f64,
    /// Value loss (half the mean squared error, clipped if so set).
    pub value: f64,
    /// Mean entropy of the policy.
    pub entropy: f64,
    /// Approximate KL divergence from the collecting policy, `((r - 1) - log r).mean()`.
    pub approx_kl: f64,
    /// Share of samples whose ratio was clipped.
    pub clip_fraction: f64,
}

/// A running mean and variance per feature, merged batch by batch with the parallel update
/// numpy's and gymnasium's `RunningMeanStd` use; it starts as 1e-4 of a sample with mean 0 and
/// variance 1.
#[derive(Debug, Clone, PartialEq)]
pub struct RunningMeanStd {
    /// Mean per feature.
    pub mean: Vec<f64>,
    /// Population variance per feature.
    pub var: Vec<f64>,
    /// Samples seen (plus the prior's 1e-4).
    pub count: f64,
}

impl RunningMeanStd {
    /// Statistics of `features` features, before any sample.
    pub fn new(features: usize) -> RunningMeanStd {
        RunningMeanStd { mean: vec![0.0; features], var: vec![1.0; features], count: 1e-4 }
    }

    /// Folds in a batch of samples, one row of `mean.len()` features each, in order.
    pub fn update(&mut self, rows: &[&[f64]]) {
        let n = rows.len() as f64;
        let total = self.count + n;
        for j in 0..self.mean.len() {
            let batch_mean = rows.iter().map(|o| o[j]).sum::<f64>() / n;
            let batch_var = rows.iter().map(|o| (o[j] - batch_mean).powi(2)).sum::<f64>() / n;
            let delta = batch_mean - self.mean[j];
            let m2 = self.var[j] * self.count + batch_var * n + delta * delta * self.count * n / total;
            self.mean[j] += delta * n / total;
            self.var[j] = m2 / total;
        }
        self.count = total;
    }
}

/// PPO's policy and value networks, their optimisers and the observation statistics.
pub struct PpoAgent {
    obs_dim: usize,
    act_dim: usize,
    settings: PpoConfig,
    actor: PpoMlp,
    log_std: Var,
    critic: PpoMlp,
    obs_stats: ObsStats,
    actor_opt: Adam,
    critic_opt: Adam,
    base_actor_lr: f64,
    base_critic_lr: f64,
}

/// The policy's observation statistics: the running mean, variance and count of the raw
/// observations (f64 on the CPU, as gymnasium keeps them), saved with the policy and used when it
/// acts. Both PPO paths keep them on the host.
pub(crate) struct ObsStats {
    pub mean: Var,
    pub var: Var,
    pub count: Var,
    enabled: bool,
    clip: f64,
}

impl ObsStats {
    /// gymnasium's `RunningMeanStd` prior: mean 0, variance 1, count 1e-4.
    fn new(obs_dim: usize, enabled: bool, clip: f64) -> Result<ObsStats> {
        let f64_var =
            |values: Vec<f64>| Var::from_tensor(&Tensor::from_vec(values.clone(), values.len(), &Device::Cpu)?);
        let prior = RunningMeanStd::new(obs_dim);
        Ok(ObsStats {
            mean: f64_var(prior.mean)?,
            var: f64_var(prior.var)?,
            count: f64_var(vec![prior.count])?,
            enabled,
            clip,
        })
    }

    /// The statistics named `actor.obs_mean`, `actor.obs_var`, `actor.obs_count` in `params`
    /// (copies, on the CPU).
    pub fn from_named(params: &[(String, Var)], enabled: bool, clip: f64) -> Result<ObsStats> {
        let get = |name: &str| -> Result<Var> {
            let (_, v) = params
                .iter()
                .find(|(n, _)| n == name)
                .ok_or_else(|| candle_core::Error::Msg(format!("no parameter {name}")))?;
            Var::from_tensor(&v.as_tensor().copy()?)
        };
        Ok(ObsStats {
            mean: get("actor.obs_mean")?,
            var: get("actor.obs_var")?,
            count: get("actor.obs_count")?,
            enabled,
            clip,
        })
    }

    pub fn named_vars(&self) -> Vec<(String, Var)> {
        vec![
            ("actor.obs_mean".into(), self.mean.clone()),
            ("actor.obs_var".into(), self.var.clone()),
            ("actor.obs_count".into(), self.count.clone()),
        ]
    }

    /// Folds a batch of raw observations (in order) into the statistics.
    pub fn observe(&mut self, raw: &[Vec<f64>]) -> Result<()> {
        if !self.enabled || raw.is_empty() {
            return Ok(());
        }
        let mut stats = RunningMeanStd {
            mean: self.mean.as_tensor().to_vec1::<f64>()?,
            var: self.var.as_tensor().to_vec1::<f64>()?,
            count: self.count.as_tensor().to_vec1::<f64>()?[0],
        };
        stats.update(&raw.iter().map(|o| o.as_slice()).collect::<Vec<_>>());
        let features = stats.mean.len();
        self.mean.set(&Tensor::from_vec(stats.mean, features, &Device::Cpu)?)?;
        self.var.set(&Tensor::from_vec(stats.var, features, &Device::Cpu)?)?;
        self.count.set(&Tensor::from_vec(vec![stats.count], 1, &Device::Cpu)?)
    }

    /// Raw observations normalised and clipped, as the networks see them (`n x obs_dim`, f32).
    pub fn normalize(&self, raw: &[Vec<f64>]) -> Result<Vec<f32>> {
        if !self.enabled {
            return Ok(raw.iter().flatten().map(|&v| v as f32).collect());
        }
        let mean = self.mean.as_tensor().to_vec1::<f64>()?;
        let var = self.var.as_tensor().to_vec1::<f64>()?;
        let clip = self.clip;
        Ok(raw
            .iter()
            .flat_map(|o| {
                o.iter()
                    .zip(mean.iter().zip(&var))
                    .map(move |(&x, (&m, &v))| ((x - m) / (v + OBS_EPSILON).sqrt()).clamp(-clip, clip) as f32)
            })
            .collect())
    }
}

/// The checkpoint names of PPO's networks, in the order both paths list them: the policy's mean
/// network, its log-std and observation statistics (together, what an exported policy keeps),
/// then the value network.
pub(crate) fn named_networks(
    mean: Vec<(String, Var)>,
    log_std: &Var,
    obs_stats: &ObsStats,
    critic: Vec<(String, Var)>,
) -> Vec<(String, Var)> {
    let mut out = mean;
    out.push(("actor.log_std".into(), log_std.clone()));
    out.extend(obs_stats.named_vars());
    out.extend(critic);
    out
}

/// Gaussian samples around each row of `mean` (`n x act_dim`) with the state-independent
/// `log_std`, drawn from `rng` row by row, and their log-probabilities (f32, as accumulated here).
pub(crate) fn sample_actions(mean: &[f32], log_std: &[f32], rng: &mut ChaCha8Rng) -> (Vec<f32>, Vec<f32>) {
    let mut actions = Vec::with_capacity(mean.len());
    let mut log_probs = Vec::with_capacity(mean.len() / log_std.len().max(1));
    for row in mean.chunks(log_std.len()) {
        let mut lp = 0.0f32;
        for (m, &s) in row.iter().zip(log_std) {
            let eps: f32 = rng.sample(StandardNormal);
            actions.push(m + s.exp() * eps);
            lp += -0.5 * eps * eps - s - HALF_LOG_2PI;
        }
        log_probs.push(lp);
    }
    (actions, log_probs)
}

/// Per-minibatch advantage normalisation as CleanRL does it (torch's sample std, plus 1e-8), in f64.
pub(crate) fn normalized_advantages(advantages: &[f32]) -> Vec<f32> {
    let n = advantages.len();
    if n < 2 {
        return advantages.to_vec();
    }
    let mean = advantages.iter().map(|&a| a as f64).sum::<f64>() / n as f64;
    let var = advantages.iter().map(|&a| (a as f64 - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    let std = var.sqrt();
    advantages.iter().map(|&a| ((a as f64 - mean) / (std + 1e-8)) as f32).collect()
}

impl PpoAgent {
    /// Builds the networks for `obs_dim`/`act_dim`, initialised from `rng`.
    pub fn new(cfg: &TrainConfig, obs_dim: usize, act_dim: usize, rng: &mut ChaCha8Rng) -> Result<Self> {
        let settings = cfg.ppo().clone();
        let (init, activation) = (cfg.weight_init, settings.activation);
        let critic = PpoMlp::new(&layer_sizes(obs_dim, &cfg.hidden, 1), 1.0, init, activation, rng)?;
        let actor = PpoMlp::new(&layer_sizes(obs_dim, &cfg.hidden, act_dim), 0.01, init, activation, rng)?;
        let log_std = Var::from_tensor(&Tensor::full(settings.log_std_init as f32, (1, act_dim), &Device::Cpu)?)?;
        let mut actor_vars = actor.stack.vars();
        actor_vars.push(log_std.clone());
        let mut actor_opt = Adam::new(actor_vars, cfg.actor_lr);
        let mut critic_opt = Adam::new(critic.stack.vars(), cfg.critic_lr);
        actor_opt.eps = settings.adam_eps;
        critic_opt.eps = settings.adam_eps;
        Ok(PpoAgent {
            obs_dim,
            act_dim,
            obs_stats: ObsStats::new(obs_dim, cfg.normalize_observations, settings.clip_observations)?,
            settings,
            actor,
            log_std,
            critic,
            actor_opt,
            critic_opt,
            base_actor_lr: cfg.actor_lr,
            base_critic_lr: cfg.critic_lr,
        })
    }
}

/// The [`OnPolicyAgent`] methods both versions of PPO share: the running observation statistics
/// and the learning-rate annealing.
macro_rules! ppo_on_policy_glue {
    () => {
        fn anneal(&mut self, fraction: f64) {
            self.actor_opt.lr = fraction * self.base_actor_lr;
            self.critic_opt.lr = fraction * self.base_critic_lr;
        }

        fn observe(&mut self, raw: &[Vec<f64>]) -> Result<()> {
            self.obs_stats.observe(raw)
        }

        fn normalize(&self, raw: &[Vec<f64>]) -> Result<Vec<f32>> {
            self.obs_stats.normalize(raw)
        }
    };
}
pub(crate) use ppo_on_policy_glue;

impl OnPolicyAgent for PpoAgent {
    ppo_on_policy_glue!();

    fn policy_step(&self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<PolicyStep> {
        let n = obs.len() / self.obs_dim;
        let x = batch_tensor(obs, n, self.obs_dim)?;
        let mean = self.actor.forward(&x)?.flatten_all()?.to_vec1::<f32>()?;
        let log_std = self.log_std.as_tensor().flatten_all()?.to_vec1::<f32>()?;
        let values = self.values(obs)?;
        let (actions, log_probs) = sample_actions(&mean, &log_std, rng);
        Ok(PolicyStep { actions, log_probs, values })
    }

    fn values(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let n = obs.len() / self.obs_dim;
        self.critic.forward(&batch_tensor(obs, n, self.obs_dim)?)?.flatten_all()?.to_vec1::<f32>()
    }

    fn learn(&mut self, b: &PpoBatch) -> Result<PpoLosses> {
        let n = b.log_probs.len();
        let s = &self.settings;
        let obs = batch_tensor(&b.obs, n, self.obs_dim)?;
        let actions = batch_tensor(&b.actions, n, self.act_dim)?;
        let column = |v: &[f32]| Tensor::from_slice(v, n, &Device::Cpu);
        let old_log_probs = column(&b.log_probs)?;
        let advantages = if s.norm_adv { normalized_advantages(&b.advantages) } else { b.advantages.clone() };
        let advantages = column(&advantages)?;

        let mean = self.actor.forward(&obs)?;
        let (new_log_probs, entropy) = gaussian_log_prob_and_entropy(&mean, &self.log_std, &actions)?;
        let log_ratio = (&new_log_probs - &old_log_probs)?;
        let ratio = log_ratio.exp()?;
        let clipped = ratio.clamp(1.0 - s.clip_coef as f32, 1.0 + s.clip_coef as f32)?;
        let pg1 = (advantages.neg()? * &ratio)?;
        let pg2 = (advantages.neg()? * &clipped)?;
        let policy_loss = pg1.maximum(&pg2)?.mean_all()?;

        let new_values = self.critic.forward(&obs)?.flatten_all()?;
        let returns = column(&b.returns)?;
        let unclipped = (&new_values - &returns)?.sqr()?;
        let value_loss = if s.clip_vloss {
            let old = column(&b.values)?;
            let delta = (&new_values - &old)?.clamp(-s.clip_coef as f32, s.clip_coef as f32)?;
            let v_clipped = ((old + delta)? - &returns)?.sqr()?;
            unclipped.maximum(&v_clipped)?.mean_all()?.affine(0.5, 0.0)?
        } else {
            unclipped.mean_all()?.affine(0.5, 0.0)?
        };
        let loss = ((&policy_loss - entropy.affine(s.ent_coef, 0.0)?)? + value_loss.affine(s.vf_coef, 0.0)?)?;
        let mut grads = loss.backward()?;

        // Global gradient-norm clipping over every trained parameter, as torch's
        // clip_grad_norm_ (the norm accumulates in f64 in a fixed order).
        let vars: Vec<Var> =
            self.actor.stack.vars().into_iter().chain([self.log_std.clone()]).chain(self.critic.stack.vars()).collect();
        let mut sum_sq = 0.0f64;
        for v in &vars {
            if let Some(g) = grads.get(v.as_tensor()) {
                sum_sq += g.sqr()?.sum_all()?.to_scalar::<f32>()? as f64;
            }
        }
        let coef = s.max_grad_norm / (sum_sq.sqrt() + 1e-6);
        if coef < 1.0 {
            for v in &vars {
                if let Some(g) = grads.remove(v.as_tensor()) {
                    grads.insert(v.as_tensor(), g.affine(coef, 0.0)?);
                }
            }
        }
        self.actor_opt.step(&grads)?;
        self.critic_opt.step(&grads)?;

        let ratio_values = ratio.to_vec1::<f32>()?;
        let log_ratio_values = log_ratio.to_vec1::<f32>()?;
        let approx_kl =
            ratio_values.iter().zip(&log_ratio_values).map(|(&r, &l)| (r - 1.0 - l) as f64).sum::<f64>() / n as f64;
        let clip_fraction =
            ratio_values.iter().filter(|&&r| ((r - 1.0).abs() as f64) > s.clip_coef).count() as f64 / n as f64;
        Ok(PpoLosses {
            policy: policy_loss.to_scalar::<f32>()? as f64,
            value: value_loss.to_scalar::<f32>()? as f64,
            entropy: entropy.to_scalar::<f32>()? as f64,
            approx_kl,
            clip_fraction,
        })
    }
}

/// ln(2 pi) / 2.
pub(crate) const HALF_LOG_2PI: f32 = 0.918_938_5;

/// log pi(a|s) of each row under the diagonal Gaussian (`mean`, exp(`log_std`)), and the
/// policy's entropy averaged over the batch, as CleanRL's `get_action_and_value` computes them;
/// both versions of PPO's update build their loss on it.
pub(crate) fn gaussian_log_prob_and_entropy(
    mean: &Tensor,
    log_std: &Var,
    actions: &Tensor,
) -> Result<(Tensor, Tensor)> {
    let log_std = log_std.as_tensor().broadcast_as(mean.shape())?;
    let z = ((actions - mean)? / log_std.exp()?)?;
    let new_log_probs = ((z.sqr()?.affine(-0.5, -HALF_LOG_2PI as f64))? - &log_std)?.sum(D::Minus1)?;
    let entropy = log_std.affine(1.0, 0.5 + HALF_LOG_2PI as f64)?.sum(D::Minus1)?.mean_all()?;
    Ok((new_log_probs, entropy))
}

/// The [`Agent`] methods both versions of PPO share (this file's fused one and `device.rs`'s),
/// written once: both keep their networks, optimisers and counters under the same field names, so
/// a checkpoint names the same things on either path.
macro_rules! ppo_glue {
    () => {
        fn algo(&self) -> Algo {
            Algo::Ppo
        }

        fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
            let x = self.normalize(&[obs.iter().map(|&v| v as f64).collect()])?;
            Ok(self.policy_step(&x, rng)?.actions.into_iter().map(|a| a.clamp(-1.0, 1.0)).collect())
        }

        fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn Optimizer)> {
            vec![("actor_opt", &mut self.actor_opt as &mut dyn Optimizer), ("critic_opt", &mut self.critic_opt)]
        }

        fn counters(&self) -> Vec<(&'static str, u64)> {
            Vec::new()
        }

        fn set_counter(&mut self, _name: &str, _value: u64) {}
    };
}
pub(crate) use ppo_glue;

impl Agent for PpoAgent {
    /// The policy's mean, clipped to [-1, 1].
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let raw: Vec<f64> = obs.iter().map(|&v| v as f64).collect();
        let x = self.normalize(&[raw])?;
        let mean = self.actor.forward(&batch_tensor(&x, 1, self.obs_dim)?)?;
        Ok(mean.flatten_all()?.to_vec1::<f32>()?.into_iter().map(|a| a.clamp(-1.0, 1.0)).collect())
    }

    fn parameters(&self) -> Vec<(String, Var)> {
        named_networks(
            self.actor.stack.named_vars("actor.mean"),
            &self.log_std,
            &self.obs_stats,
            self.critic.stack.named_vars("critic"),
        )
    }

    ppo_glue!();
}

/// PPO's own settings; the defaults are CleanRL's `ppo_continuous_action.py`. PPO reads these
/// shared settings too: `total_steps`, `hidden`, `gamma`, `actor_lr` and `critic_lr` (its one
/// learning rate, for the policy and the value network), `normalize_observations` (running
/// statistics, updated at every step), `reward_scale`, `eval_every`, `eval_episodes` and
/// `checkpoint_every`; the replay and target-network settings do not apply.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PpoConfig {
    /// Environment copies stepped together.
    pub num_envs: usize,
    /// Steps per copy in each rollout.
    pub num_steps: usize,
    /// Minibatches each rollout is split into.
    pub num_minibatches: usize,
    /// Passes over each rollout.
    pub update_epochs: usize,
    /// GAE's lambda.
    pub gae_lambda: f64,
    /// The surrogate objective's clip range (and the value clip's).
    pub clip_coef: f64,
    /// Clip the value loss around the collected values.
    pub clip_vloss: bool,
    /// Normalise advantages per minibatch.
    pub norm_adv: bool,
    /// Weight of the entropy bonus.
    pub ent_coef: f64,
    /// Weight of the value loss.
    pub vf_coef: f64,
    /// Global gradient-norm limit.
    pub max_grad_norm: f64,
    /// Decay the learning rates linearly to 0 over the run.
    pub anneal_lr: bool,
    /// Divide rewards by the running std of the discounted return (gymnasium's `NormalizeReward`).
    pub normalize_rewards: bool,
    /// Normalised observations are clipped to this magnitude.
    pub clip_observations: f64,
    /// Normalised rewards are clipped to this magnitude.
    pub clip_rewards: f64,
    /// Stop a rollout's epochs once the approximate KL exceeds this; absent means never.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_kl: Option<f64>,
    /// Adam's epsilon.
    pub adam_eps: f64,
    /// The hidden layers' nonlinearity, in the policy and the value network.
    #[serde(default, skip_serializing_if = "Activation::is_tanh")]
    pub activation: Activation,
    /// The policy's log-std before training (SB3's `log_std_init`; CleanRL starts at 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub log_std_init: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl PpoConfig {
    pub(crate) const KEYS: &'static [&'static str] = &[
        "num_envs",
        "num_steps",
        "num_minibatches",
        "update_epochs",
        "gae_lambda",
        "clip_coef",
        "clip_vloss",
        "norm_adv",
        "ent_coef",
        "vf_coef",
        "max_grad_norm",
        "anneal_lr",
        "normalize_rewards",
        "clip_observations",
        "clip_rewards",
        "target_kl",
        "adam_eps",
        "activation",
        "log_std_init",
    ];

    /// Transitions per rollout.
    pub fn rollout_size(&self) -> usize {
        self.num_envs * self.num_steps
    }

    /// Checks this section's settings.
    pub(crate) fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(
            self.num_envs >= 1 && self.num_steps >= 1 && self.update_epochs >= 1 && self.num_minibatches >= 1,
            "num_envs, num_steps, num_minibatches and update_epochs must be at least 1"
        );
        anyhow::ensure!(
            self.num_minibatches <= self.rollout_size(),
            "num_minibatches ({}) is more than a rollout holds (num_envs x num_steps = {}): a minibatch would \
             be empty",
            self.num_minibatches,
            self.rollout_size()
        );
        anyhow::ensure!((0.0..=1.0).contains(&self.gae_lambda), "gae_lambda must lie in [0, 1]");
        positive("clip_coef", self.clip_coef)?;
        positive("max_grad_norm", self.max_grad_norm)?;
        positive("clip_observations", self.clip_observations)?;
        positive("clip_rewards", self.clip_rewards)?;
        positive("adam_eps", self.adam_eps)?;
        anyhow::ensure!(self.ent_coef >= 0.0 && self.vf_coef >= 0.0, "ent_coef and vf_coef must be >= 0");
        if let Some(kl) = self.target_kl {
            positive("target_kl", kl)?;
        }
        anyhow::ensure!(
            self.log_std_init.is_finite() && self.log_std_init.abs() <= 20.0,
            "log_std_init must be a number in [-20, 20], got {}",
            self.log_std_init
        );
        Ok(())
    }
}

impl TrainConfig {
    /// CleanRL's `ppo_continuous_action.py` (vwxyzjn/cleanrl): 64-64 tanh networks, Adam 3e-4
    /// (eps 1e-5) annealed, one copy, 2048-step rollouts in 32 minibatches for 10 epochs.
    pub(crate) fn ppo_defaults() -> TrainConfig {
        TrainConfig {
            warmup_steps: 0,
            learning_starts: 0,
            batch_size: 64,
            buffer_capacity: 1,
            hidden: vec![64, 64],
            normalize_observations: true,
            weight_init: WeightInit::Orthogonal,
            actor_lr: 3e-4,
            critic_lr: 3e-4,
            eval_every: 10_000,
            ppo: Some(PpoConfig {
                num_envs: 1,
                num_steps: 2048,
                num_minibatches: 32,
                update_epochs: 10,
                gae_lambda: 0.95,
                clip_coef: 0.2,
                clip_vloss: true,
                norm_adv: true,
                ent_coef: 0.0,
                vf_coef: 0.5,
                max_grad_norm: 0.5,
                anneal_lr: true,
                normalize_rewards: true,
                clip_observations: 10.0,
                clip_rewards: 10.0,
                target_kl: None,
                adam_eps: 1e-5,
                activation: Activation::Tanh,
                log_std_init: 0.0,
            }),
            ..TrainConfig::shared_defaults(Algo::Ppo)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn agent() -> PpoAgent {
        let mut cfg = TrainConfig::defaults(Algo::Ppo);
        cfg.hidden = vec![8, 8];
        PpoAgent::new(&cfg, 3, 2, &mut ChaCha8Rng::seed_from_u64(0)).unwrap()
    }

    #[test]
    fn relu_networks_and_the_initial_log_std_are_as_configured() {
        let mut cfg = TrainConfig::defaults(Algo::Ppo);
        cfg.hidden = vec![8, 8];
        cfg.weight_init = WeightInit::Uniform;
        let ppo = cfg.ppo.as_mut().unwrap();
        (ppo.activation, ppo.log_std_init) = (Activation::Relu, -2.0);
        let a = PpoAgent::new(&cfg, 3, 2, &mut ChaCha8Rng::seed_from_u64(0)).unwrap();
        assert_eq!(a.log_std.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap(), vec![-2.0, -2.0]);
        // PyTorch's nn.Linear default: every weight and bias within 1/sqrt(fan_in).
        for (w, b) in a.actor.stack.layers() {
            let fan_in = w.as_tensor().dims()[1] as f32;
            let bound = 1.0 / fan_in.sqrt();
            let values = [w.as_tensor().flatten_all().unwrap(), b.as_tensor().clone()];
            assert!(values.iter().all(|t| t.to_vec1::<f32>().unwrap().iter().all(|v| v.abs() <= bound)));
        }
        // The mean by hand: ReLU between the layers, nothing after the last.
        let x = [0.3f32, -1.2, 2.0];
        let mut h: Vec<f32> = x.to_vec();
        let layers = a.actor.stack.layers();
        for (i, (w, b)) in layers.iter().enumerate() {
            let (w, b) = (w.as_tensor().to_vec2::<f32>().unwrap(), b.as_tensor().to_vec1::<f32>().unwrap());
            h = w
                .iter()
                .zip(&b)
                .map(|(row, bj)| row.iter().zip(&h).map(|(wi, hi)| wi * hi).sum::<f32>() + bj)
                .collect();
            if i + 1 < layers.len() {
                h.iter_mut().for_each(|v| *v = v.max(0.0));
            }
        }
        let got = a.actor.forward(&batch_tensor(&x, 1, 3).unwrap()).unwrap().flatten_all().unwrap().to_vec1::<f32>();
        for (g, e) in got.unwrap().iter().zip(&h) {
            assert!((g - e).abs() < 1e-6, "{g} vs {e}");
        }
        // Written to config.toml only when set, so a CleanRL-style run's file is as before.
        let flat = TrainConfig::defaults(Algo::Ppo).to_flat_table();
        assert!(!flat.contains_key("activation") && !flat.contains_key("log_std_init"));
        let text = toml::to_string(&cfg).unwrap();
        assert!(text.contains("activation = \"relu\"") && text.contains("log_std_init = -2.0"), "{text}");
        let table: toml::Table = toml::from_str(&text).unwrap();
        let back = TrainConfig::from_table(&table, crate::agents::config::OtherAlgorithmKeys::Refuse).unwrap();
        assert_eq!(back, cfg);
        cfg.ppo.as_mut().unwrap().log_std_init = f64::NAN;
        assert!(cfg.ppo().validate().unwrap_err().to_string().contains("log_std_init"));
    }

    #[test]
    fn running_statistics_match_numpy_s_parallel_update() {
        let mut a = agent();
        let batches = [vec![vec![1.0, 2.0, -1.0], vec![3.0, 2.0, 0.0]], vec![vec![-2.0, 5.0, 4.0]]];
        for b in &batches {
            a.observe(b).unwrap();
        }
        // By hand: the prior (mean 0, var 1, count 1e-4) plus the three samples.
        let samples = [[1.0, 2.0, -1.0], [3.0, 2.0, 0.0], [-2.0, 5.0, 4.0]];
        let count = 3.0 + 1e-4;
        for j in 0..3 {
            let mean = samples.iter().map(|s| s[j]).sum::<f64>() / count;
            let m2 = 1e-4 * (1.0 + mean * mean) + samples.iter().map(|s| (s[j] - mean).powi(2)).sum::<f64>();
            let got_mean = a.obs_stats.mean.as_tensor().to_vec1::<f64>().unwrap()[j];
            let got_var = a.obs_stats.var.as_tensor().to_vec1::<f64>().unwrap()[j];
            assert!((got_mean - mean).abs() < 1e-12, "mean {j}: {got_mean} vs {mean}");
            assert!((got_var - m2 / count).abs() < 1e-9, "var {j}: {got_var} vs {}", m2 / count);
        }
        assert!((a.obs_stats.count.as_tensor().to_vec1::<f64>().unwrap()[0] - count).abs() < 1e-12);
    }

    #[test]
    fn sampled_log_probabilities_are_the_gaussian_density() {
        let a = agent();
        let obs = vec![0.1, -0.2, 0.3, 0.5, 0.0, -1.0];
        let step = a.policy_step(&obs, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let mean = a.actor.forward(&batch_tensor(&obs, 2, 3).unwrap()).unwrap().to_vec2::<f32>().unwrap();
        // log-std starts at 0: log N(a; m, 1) = -(a - m)^2 / 2 - ln(2 pi) / 2 per dimension.
        for (r, row) in mean.iter().enumerate() {
            let lp: f64 = (0..2)
                .map(|j| {
                    let d = (step.actions[2 * r + j] - row[j]) as f64;
                    -0.5 * d * d - 0.5 * (2.0 * std::f64::consts::PI).ln()
                })
                .sum();
            assert!((step.log_probs[r] as f64 - lp).abs() < 1e-5, "{} vs {lp}", step.log_probs[r]);
        }
        assert_eq!(step.values.len(), 2);
    }

    #[test]
    fn a_first_update_leaves_the_ratio_at_one_and_moves_towards_the_advantage() {
        let mut a = agent();
        let obs = vec![0.1, -0.2, 0.3, 0.5, 0.0, -1.0];
        let step = a.policy_step(&obs, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let batch = PpoBatch {
            obs: obs.clone(),
            actions: step.actions.clone(),
            log_probs: step.log_probs.clone(),
            advantages: vec![1.0, -1.0],
            returns: vec![1.0, 1.0],
            values: step.values.clone(),
        };
        let l = a.learn(&batch).unwrap();
        // Nothing changed between sampling and the loss: ratio 1, nothing clipped, KL 0.
        assert!(l.approx_kl.abs() < 1e-6 && l.clip_fraction == 0.0, "{l:?}");
        // The entropy of a unit Gaussian per dimension: 1/2 + ln(2 pi)/2.
        assert!((l.entropy - 2.0 * (0.5 + 0.5 * (2.0 * std::f64::consts::PI).ln())).abs() < 1e-5);
        // The action with the positive advantage became more likely, the other less.
        let after = PpoBatch { ..batch };
        let mean = a.actor.forward(&batch_tensor(&after.obs, 2, 3).unwrap()).unwrap().to_vec2::<f32>().unwrap();
        let log_std = a.log_std.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let lp = |r: usize| -> f32 {
            (0..2)
                .map(|j| {
                    let z = (after.actions[2 * r + j] - mean[r][j]) / log_std[j].exp();
                    -0.5 * z * z - log_std[j] - HALF_LOG_2PI
                })
                .sum()
        };
        assert!(lp(0) > after.log_probs[0], "{} <= {}", lp(0), after.log_probs[0]);
        assert!(lp(1) < after.log_probs[1], "{} >= {}", lp(1), after.log_probs[1]);
    }
}
