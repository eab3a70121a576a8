//! Every hyperparameter of a training run, with each algorithm's published defaults.
use serde::{Deserialize, Serialize};

use super::noise::NoiseKind;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Algo {
    Td3,
    Sac,
    Ddpg,
}

impl Algo {
    pub fn parse(name: &str) -> anyhow::Result<Algo> {
        super::registry::ALGOS.iter().find(|e| e.name == name).map(|e| e.algo).ok_or_else(|| {
            let known: Vec<&str> = super::registry::ALGOS.iter().map(|e| e.name).collect();
            anyhow::anyhow!("unknown algorithm '{name}'; known algorithms: {}", known.join(", "))
        })
    }
    pub fn name(self) -> &'static str {
        super::registry::entry(self).name
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SacVersion {
    /// Haarnoja et al. 2018b: twin critics, automatic temperature, no value network.
    V2,
    /// Haarnoja et al. 2018a: separate value network and target value network, fixed temperature.
    V1,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    pub algo: Algo,
    /// Environment steps in the whole run.
    pub total_steps: u64,
    /// Steps with uniformly random actions at the start.
    pub warmup_steps: u64,
    /// No gradient update before the buffer holds this many transitions.
    pub learning_starts: u64,
    pub updates_per_step: u32,
    pub batch_size: usize,
    pub buffer_capacity: usize,
    /// Hidden layer sizes of every network.
    pub hidden: Vec<usize>,
    pub gamma: f64,
    /// Multiplies every reward the learner stores; returns and evaluations stay the environment's.
    /// 1 unless a preset says otherwise (Haarnoja et al. 2018a tune a reward scale per task; it
    /// sets how large rewards are against the critic's approximation error).
    pub reward_scale: f64,
    /// Feed the networks observations standardised by the warm-up transitions' mean and std,
    /// frozen from then on (`agents::normalize`). Off unless a preset says otherwise.
    pub normalize_observations: bool,
    /// Polyak coefficient of the target networks.
    pub tau: f64,
    pub actor_lr: f64,
    pub critic_lr: f64,
    pub eval_every: u64,
    pub eval_episodes: usize,
    pub checkpoint_every: u64,

    // TD3 and DDPG
    /// Exploration noise std in units of the action half-range (OU: its starting std).
    pub exploration_noise: f64,
    pub noise: NoiseKind,
    pub ou_theta: f64,
    pub ou_sigma_min: f64,
    pub ou_decay_steps: u64,
    pub ou_dt: f64,
    /// Target policy smoothing noise std and clip (TD3), in units of the action half-range.
    pub policy_noise: f64,
    pub noise_clip: f64,
    /// Actor and target updates happen every this many critic updates.
    pub policy_delay: u32,
    pub twin_critics: bool,

    // SAC
    pub sac_version: SacVersion,
    pub autotune_alpha: bool,
    pub initial_alpha: f64,
    pub alpha_lr: f64,
    /// Target entropy for the temperature; `None` means -dim(A).
    pub target_entropy: Option<f64>,
    pub value_lr: f64,
}

impl TrainConfig {
    /// Reads a `[train]` table: keys it does not give take the algorithm's defaults (so a run
    /// written before a hyperparameter existed still loads), an unknown key is an error naming it.
    pub fn from_table(table: &toml::Table) -> anyhow::Result<TrainConfig> {
        let algo = match table.get("algo") {
            Some(toml::Value::String(name)) => Algo::parse(name)?,
            Some(other) => anyhow::bail!("algo must be a name like \"td3\", got {other}"),
            None => anyhow::bail!("no algo given"),
        };
        let mut merged = toml::Table::try_from(TrainConfig::defaults(algo))?;
        merged.extend(table.clone());
        toml::Value::Table(merged).try_into().map_err(|e: toml::de::Error| anyhow::anyhow!("{}", e.message()))
    }

    /// The defaults each algorithm was published with (REFERENCE §5), from its registry entry.
    pub fn defaults(algo: Algo) -> TrainConfig {
        (super::registry::entry(algo).defaults)()
    }

    /// TD3's published settings (Fujimoto et al. 2018).
    pub fn td3_defaults() -> TrainConfig {
        TrainConfig {
            algo: Algo::Td3,
            total_steps: 1_000_000,
            warmup_steps: 10_000,
            learning_starts: 10_000,
            updates_per_step: 1,
            batch_size: 100,
            buffer_capacity: 1_000_000,
            hidden: vec![400, 300],
            gamma: 0.99,
            reward_scale: 1.0,
            normalize_observations: false,
            tau: 0.005,
            actor_lr: 1e-3,
            critic_lr: 1e-3,
            eval_every: 5000,
            eval_episodes: 10,
            checkpoint_every: 50_000,
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
            sac_version: SacVersion::V2,
            autotune_alpha: true,
            initial_alpha: 1.0,
            alpha_lr: 3e-4,
            target_entropy: None,
            value_lr: 3e-4,
        }
    }

    /// "Our DDPG" of the TD3 paper: TD3's settings without its three changes.
    pub fn ddpg_defaults() -> TrainConfig {
        TrainConfig {
            algo: Algo::Ddpg,
            policy_noise: 0.0,
            noise_clip: 0.0,
            policy_delay: 1,
            twin_critics: false,
            ..TrainConfig::td3_defaults()
        }
    }

    /// SAC v2's (Haarnoja et al. 2018b): 256-256, Adam 3e-4, batch 256.
    pub fn sac_defaults() -> TrainConfig {
        TrainConfig {
            algo: Algo::Sac,
            batch_size: 256,
            hidden: vec![256, 256],
            actor_lr: 3e-4,
            critic_lr: 3e-4,
            policy_delay: 1,
            ..TrainConfig::td3_defaults()
        }
    }

    pub fn validate(&self) -> anyhow::Result<()> {
        let positive = |name: &str, v: f64| -> anyhow::Result<()> {
            anyhow::ensure!(v.is_finite() && v > 0.0, "{name} must be a finite number > 0, got {v}");
            Ok(())
        };
        positive("actor_lr", self.actor_lr)?;
        positive("critic_lr", self.critic_lr)?;
        positive("alpha_lr", self.alpha_lr)?;
        positive("value_lr", self.value_lr)?;
        positive("initial_alpha", self.initial_alpha)?;
        positive("reward_scale", self.reward_scale)?;
        anyhow::ensure!(
            !self.normalize_observations || self.learning_starts >= self.batch_size.max(2) as u64,
            "normalize_observations estimates its statistics from the transitions before learning starts: \
             learning_starts ({}) must be at least the batch size ({})",
            self.learning_starts,
            self.batch_size
        );
        anyhow::ensure!((0.0..=1.0).contains(&self.gamma), "gamma must lie in [0, 1]");
        anyhow::ensure!(self.tau > 0.0 && self.tau <= 1.0, "tau must lie in (0, 1]");
        anyhow::ensure!(self.batch_size > 0, "batch_size must be at least 1");
        anyhow::ensure!(self.buffer_capacity > 0, "buffer_capacity must be at least 1");
        anyhow::ensure!(
            !self.hidden.is_empty() && self.hidden.iter().all(|&h| h > 0),
            "hidden needs at least one layer size > 0"
        );
        anyhow::ensure!(self.policy_delay >= 1, "policy_delay must be at least 1");
        anyhow::ensure!(self.updates_per_step >= 1, "updates_per_step must be at least 1");
        anyhow::ensure!(
            self.eval_every > 0 && self.eval_episodes > 0,
            "eval_every and eval_episodes must be at least 1"
        );
        anyhow::ensure!(self.checkpoint_every > 0, "checkpoint_every must be at least 1");
        anyhow::ensure!(
            self.exploration_noise >= 0.0 && self.policy_noise >= 0.0 && self.noise_clip >= 0.0,
            "noise scales must be >= 0"
        );
        Ok(())
    }
}
