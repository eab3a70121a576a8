//! Deterministic policy gradients: TD3 (Fujimoto, van Hoof and Meger, "Addressing Function
//! Approximation Error in Actor-Critic Methods", ICML 2018) and DDPG (Lillicrap et al.,
//! "Continuous control with deep reinforcement learning", ICLR 2016) as the TD3 paper's "our DDPG".
//!
//! One update from a replay minibatch (TD3):
//! 1. critics: y = r + gamma (1 - terminated) min_i Q'_i(s', clip(mu'(s') + clip(eps, -c, c))),
//!    eps ~ N(0, policy_noise^2) (target policy smoothing); both critics regress on y;
//! 2. every `policy_delay`-th update: the actor ascends Q_1(s, mu(s)), and the actor and critic
//!    targets follow by Polyak averaging.
//!
//! DDPG is the same machinery with one critic, no smoothing and no delay. Exploration adds
//! Gaussian noise (or Ornstein-Uhlenbeck, `noise = "ou"`) to the actor's action.
//!
//! Defaults are the TD3 paper's: 400 x 300, Adam 1e-3, batch 100, tau 0.005, gamma 0.99,
//! exploration noise 0.1, policy noise 0.2 clipped at 0.5, delay 2, 10k random warm-up steps (the
//! authors' repository, sfujim/TD3, uses 25k).
//!
//! To read it end to end: this file (settings, the fused CPU agent and its update), then
//! `../common/critics.rs`, `../common/objectives.rs` (the TD target) and `../common/noise.rs`;
//! `device.rs` is the same agent on any candle device.
pub mod device;

use serde::{Deserialize, Serialize};

use candle_core::{Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use crate::agents::common::buffer::Batch;
use crate::agents::common::critics::{polyak_update_critics, Critics};
use crate::agents::common::nets::{batch_tensor, polyak_update, Mlp, Output};
use crate::agents::common::noise::{Noise, NoiseKind};
use crate::agents::common::objectives::{critic_minimum, td_target};
use crate::agents::config::{Algo, TrainConfig};
use crate::agents::{layer_sizes, Agent, Losses, OffPolicyAgent};
use crate::numeric::optim::{Adam, Optimizer};

/// TD3 and DDPG: a deterministic actor, one or two critics, and target networks.
pub struct DeterministicAgent {
    algo: Algo,
    act_dim: usize,
    obs_dim: usize,
    gamma: f64,
    tau: f64,
    policy_noise: f64,
    noise_clip: f64,
    policy_delay: u64,
    actor: Mlp,
    actor_target: Mlp,
    critics: Critics,
    critic_targets: Critics,
    actor_opt: Adam,
    critic_opt: Adam,
    noise: Noise,
    updates: u64,
}

impl DeterministicAgent {
    /// Builds the networks for `obs_dim`/`act_dim`, initialised from `rng`; `cfg.algo` picks TD3 or DDPG.
    pub fn new(cfg: &TrainConfig, obs_dim: usize, act_dim: usize, rng: &mut ChaCha8Rng) -> Result<Self> {
        let actor = Mlp::new(&layer_sizes(obs_dim, &cfg.hidden, act_dim), Output::Tanh, cfg.weight_init, rng)?;
        let dpg = cfg.dpg();
        let n_critics = if dpg.twin_critics { 2 } else { 1 };
        let critics = Critics::new(n_critics, &layer_sizes(obs_dim + act_dim, &cfg.hidden, 1), cfg.weight_init, rng)?
            .layer_normalised_if(dpg.critic_layer_norm)?;
        let actor_target = actor.deep_copy()?;
        let critic_targets = critics.deep_copy()?;
        let actor_opt = Adam::new(actor.params(), cfg.actor_lr);
        let critic_opt = Adam::new(critics.params(), cfg.critic_lr);
        let noise = Noise::for_config(dpg, act_dim);
        Ok(DeterministicAgent {
            algo: cfg.algo,
            act_dim,
            obs_dim,
            gamma: cfg.gamma,
            tau: cfg.tau,
            policy_noise: dpg.policy_noise,
            noise_clip: dpg.noise_clip,
            policy_delay: dpg.policy_delay as u64,
            actor,
            actor_target,
            critics,
            critic_targets,
            actor_opt,
            critic_opt,
            noise,
            updates: 0,
        })
    }

    fn critic_input(obs: &Tensor, action: &Tensor) -> Result<Tensor> {
        Tensor::cat(&[obs, action], 1)
    }

    /// min_i Q'_i(s, a) over the target critics, one value per row (diagnostics and tests).
    pub fn target_q_min(&self, obs: &[f32], actions: &[f32]) -> Result<Vec<f32>> {
        let n = obs.len() / self.obs_dim;
        let (o, a) = (batch_tensor(obs, n, self.obs_dim)?, batch_tensor(actions, n, self.act_dim)?);
        self.critic_targets.min(&Self::critic_input(&o, &a)?)?.flatten_all()?.to_vec1::<f32>()
    }

    /// The target actor's action for each row.
    pub fn target_actions(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let n = obs.len() / self.obs_dim;
        self.actor_target.forward(&batch_tensor(obs, n, self.obs_dim)?)?.flatten_all()?.to_vec1::<f32>()
    }

    /// y = r + gamma * (1 - terminated) * min_i Q'_i(s', clip(pi'(s') + smoothing noise)).
    /// Truncated rows bootstrap like any non-terminal row.
    pub fn td_targets(&self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Tensor> {
        let n = batch.size;
        let next_obs = batch_tensor(&batch.next_obs, n, self.obs_dim)?;
        let mut next_action = self.actor_target.forward(&next_obs)?;
        if self.policy_noise > 0.0 {
            let normal = Normal::new(0.0, self.policy_noise).expect("policy_noise >= 0");
            let c = self.noise_clip;
            let eps: Vec<f32> = (0..n * self.act_dim).map(|_| normal.sample(rng).clamp(-c, c) as f32).collect();
            next_action =
                (next_action + Tensor::from_vec(eps, (n, self.act_dim), &Device::Cpu)?)?.clamp(-1f32, 1f32)?;
        }
        let q = self.critic_targets.forward(&Self::critic_input(&next_obs, &next_action)?)?;
        let q_next = critic_minimum(&q.flatten_all()?.to_vec1::<f32>()?, n);
        td_target(&batch.rewards, &batch.terminated, &q_next, self.gamma)
    }
}

/// The [`Agent`] methods both versions of TD3 and DDPG share (this file's fused one and `device.rs`'s),
/// written once: both keep their networks, optimisers and counters under the same field names, so
/// a checkpoint names the same things on either path.
macro_rules! dpg_glue {
    () => {
        fn algo(&self) -> Algo {
            self.algo
        }

        fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
            let a = self.act(obs)?;
            let noise = self.noise.sample(self.act_dim, rng);
            Ok(a.iter().zip(noise).map(|(a, n)| (*a as f64 + n).clamp(-1.0, 1.0) as f32).collect())
        }

        fn begin_episode(&mut self) {
            self.noise.reset();
        }

        fn parameters(&self) -> Vec<(String, Var)> {
            let mut out = self.actor.named_vars("actor");
            out.extend(self.actor_target.named_vars("actor_target"));
            out.extend(self.critics.named_vars("critics"));
            out.extend(self.critic_targets.named_vars("critics_target"));
            out
        }

        fn optimizers(&mut self) -> Vec<(&'static str, &mut dyn Optimizer)> {
            vec![("actor_opt", &mut self.actor_opt as &mut dyn Optimizer), ("critic_opt", &mut self.critic_opt)]
        }

        fn counters(&self) -> Vec<(&'static str, u64)> {
            vec![("updates", self.updates), ("noise_steps", self.noise.steps())]
        }

        fn set_counter(&mut self, name: &str, value: u64) {
            match name {
                "updates" => self.updates = value,
                "noise_steps" => self.noise.set_steps(value),
                _ => {}
            }
        }
    };
}
pub(crate) use dpg_glue;

impl Agent for DeterministicAgent {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let x = batch_tensor(obs, 1, self.obs_dim)?;
        self.actor.forward(&x)?.flatten_all()?.to_vec1::<f32>()
    }

    dpg_glue!();
}

impl OffPolicyAgent for DeterministicAgent {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let n = batch.size;
        let obs = batch_tensor(&batch.obs, n, self.obs_dim)?;
        let actions = batch_tensor(&batch.actions, n, self.act_dim)?;
        let y = self.td_targets(batch, rng)?;

        let critic_loss = self.critics.mse_sum(&Self::critic_input(&obs, &actions)?, &y)?;
        let grads = critic_loss.backward()?;
        self.critic_opt.step(&grads)?;
        self.updates += 1;

        let mut losses = Losses { critic: critic_loss.to_scalar::<f32>()? as f64, ..Default::default() };
        if self.updates.is_multiple_of(self.policy_delay) {
            let pi = self.actor.forward(&obs)?;
            let actor_loss = self.critics.first_frozen(&Self::critic_input(&obs, &pi)?)?.mean_all()?.neg()?;
            let grads = actor_loss.backward()?;
            self.actor_opt.step(&grads)?;
            polyak_update(&self.actor, &self.actor_target, self.tau)?;
            polyak_update_critics(&self.critics, &self.critic_targets, self.tau)?;
            losses.actor = Some(actor_loss.to_scalar::<f32>()? as f64);
        }
        Ok(losses)
    }
}

/// TD3's and DDPG's own settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DpgConfig {
    /// Exploration noise std in units of the action half-range (OU: its starting std).
    pub exploration_noise: f64,
    /// Gaussian or Ornstein-Uhlenbeck exploration noise.
    pub noise: NoiseKind,
    /// OU mean-reversion rate.
    pub ou_theta: f64,
    /// OU's final std, reached after `ou_decay_steps`.
    pub ou_sigma_min: f64,
    /// Steps over which the OU std decays linearly to `ou_sigma_min`.
    pub ou_decay_steps: u64,
    /// OU time step.
    pub ou_dt: f64,
    /// Target policy smoothing noise std and clip (TD3), in units of the action half-range.
    pub policy_noise: f64,
    /// Clip of the target policy smoothing noise (TD3).
    pub noise_clip: f64,
    /// Actor and target updates happen every this many critic updates.
    pub policy_delay: u32,
    /// Two critics and the smaller of their targets (TD3), or one (DDPG).
    pub twin_critics: bool,
    /// Layer-normalise the critics' hidden layers (`agents::common::critics`). Off unless asked for.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub critic_layer_norm: bool,
}

impl DpgConfig {
    pub(crate) const KEYS: &'static [&'static str] = &[
        "exploration_noise",
        "noise",
        "ou_theta",
        "ou_sigma_min",
        "ou_decay_steps",
        "ou_dt",
        "policy_noise",
        "noise_clip",
        "policy_delay",
        "twin_critics",
        "critic_layer_norm",
    ];

    /// Checks this section's settings.
    pub(crate) fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.policy_delay >= 1, "policy_delay must be at least 1");
        anyhow::ensure!(
            self.exploration_noise >= 0.0 && self.policy_noise >= 0.0 && self.noise_clip >= 0.0,
            "noise scales must be >= 0"
        );
        Ok(())
    }
}

impl TrainConfig {
    /// TD3's published settings (Fujimoto et al. 2018).
    pub(crate) fn td3_defaults() -> TrainConfig {
        TrainConfig {
            td3: Some(DpgConfig {
                exploration_noise: 0.1,
                noise: NoiseKind::Gaussian,
                ou_theta: 0.15,
                ou_sigma_min: 0.05,
                ou_decay_steps: 500_000,
                ou_dt: 1e-2,
                policy_noise: 0.2,
                noise_clip: 0.5,
                policy_delay: 2,
                twin_critics: true,
                critic_layer_norm: false,
            }),
            ..TrainConfig::shared_defaults(Algo::Td3)
        }
    }

    /// "Our DDPG" of the TD3 paper: TD3's settings without its three changes.
    pub(crate) fn ddpg_defaults() -> TrainConfig {
        let td3 = TrainConfig::td3_defaults().td3.expect("TD3's section");
        TrainConfig {
            ddpg: Some(DpgConfig { policy_noise: 0.0, noise_clip: 0.0, policy_delay: 1, twin_critics: false, ..td3 }),
            ..TrainConfig::shared_defaults(Algo::Ddpg)
        }
    }
}
