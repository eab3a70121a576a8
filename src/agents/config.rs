//! Every hyperparameter of a training run, with each algorithm's published defaults.
use serde::{Deserialize, Serialize};

use super::noise::NoiseKind;
pub use crate::numeric::squashed::TanhCorrection;

/// A learning algorithm, as named in `--algo` and `config.toml`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Algo {
    /// Twin Delayed DDPG (Fujimoto et al., 2018).
    Td3,
    /// Soft Actor-Critic (Haarnoja et al., 2018).
    Sac,
    /// Deep Deterministic Policy Gradient (Lillicrap et al., 2016).
    Ddpg,
    /// Proximal Policy Optimization (Schulman et al., 2017), on vector environments.
    Ppo,
    /// Action-branching DQN over discretised joint actions (Tavakoli et al., 2018).
    Dqn,
    /// CrossQ (Bhatt et al., 2024): SAC with batch-renormalised critics and no target networks.
    Crossq,
}

impl Algo {
    /// The algorithm registered under `name`; the error lists the known names.
    pub fn parse(name: &str) -> anyhow::Result<Algo> {
        super::registry::ALGOS.iter().find(|e| e.name == name).map(|e| e.algo).ok_or_else(|| {
            let known: Vec<&str> = super::registry::ALGOS.iter().map(|e| e.name).collect();
            anyhow::anyhow!("unknown algorithm '{name}'; known algorithms: {}", known.join(", "))
        })
    }
    /// The registered name (`td3`, `sac`, `ddpg`, `ppo`, `dqn`, `crossq`).
    pub fn name(self) -> &'static str {
        super::registry::entry(self).name
    }
    /// Whether it learns from its own fresh rollouts (PPO) rather than from a replay buffer.
    pub fn is_on_policy(self) -> bool {
        self == Algo::Ppo
    }
}

/// Which of the two published SAC variants to train.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SacVersion {
    /// Haarnoja et al. 2018b: twin critics, automatic temperature, no value network.
    V2,
    /// Haarnoja et al. 2018a: separate value network and target value network, fixed temperature.
    V1,
}

/// How every network's weights are drawn (biases: see each variant).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WeightInit {
    /// PyTorch's `nn.Linear` default, U(-1/sqrt(fan_in), 1/sqrt(fan_in)) for weights and biases:
    /// what Stable-Baselines3, CleanRL and the TD3 authors' code start from.
    Uniform,
    /// Orthogonal weights with gain sqrt(2) and zero biases, as jaxrl's `default_init` (the code
    /// behind the published SAC curves: repository ikostrikov/jaxrl, `learning_curves`); SAC's log-std rows
    /// get gain 1, as
    /// jaxrl's `log_std_scale`.
    Orthogonal,
}

/// Every hyperparameter of a training run: the settings all algorithms share, then the run's
/// algorithm's own section (`[train.td3]`, `[train.ddpg]` or `[train.sac]` in `config.toml`).
/// Exactly the section of `algo` is present (`validate` checks it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// The algorithm whose section (`td3`, `ddpg` or `sac`) must be present.
    pub algo: Algo,
    /// Environment steps in the whole run.
    pub total_steps: u64,
    /// Steps with uniformly random actions at the start.
    pub warmup_steps: u64,
    /// No gradient update before the buffer holds this many transitions.
    pub learning_starts: u64,
    /// Gradient updates per environment step once learning has started.
    pub updates_per_step: u32,
    /// Transitions per minibatch.
    pub batch_size: usize,
    /// Transitions the replay buffer keeps.
    pub buffer_capacity: usize,
    /// Hidden layer sizes of every network.
    pub hidden: Vec<usize>,
    /// Discount factor.
    pub gamma: f64,
    /// Multiplies every reward the learner stores; returns and evaluations stay the environment's.
    /// 1 unless a preset says otherwise (Haarnoja et al. 2018a tune a reward scale per task; it
    /// sets how large rewards are against the critic's approximation error).
    pub reward_scale: f64,
    /// Feed the networks observations standardised by the warm-up transitions' mean and std,
    /// frozen from then on (`agents::normalize`). Off unless a preset says otherwise.
    pub normalize_observations: bool,
    /// How the networks' initial weights are drawn.
    pub weight_init: WeightInit,
    /// Polyak coefficient of the target networks.
    pub tau: f64,
    /// Adam learning rate of the actor.
    pub actor_lr: f64,
    /// Adam learning rate of the critics.
    pub critic_lr: f64,
    /// Environment steps between in-training evaluations.
    pub eval_every: u64,
    /// Episodes per in-training evaluation.
    pub eval_episodes: usize,
    /// Environment steps between checkpoints.
    pub checkpoint_every: u64,
    /// TD3's own settings (present exactly when `algo` is TD3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub td3: Option<DpgConfig>,
    /// DDPG's own settings (present exactly when `algo` is DDPG).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ddpg: Option<DpgConfig>,
    /// SAC's own settings (present exactly when `algo` is SAC).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sac: Option<SacConfig>,
    /// PPO's own settings (present exactly when `algo` is PPO).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ppo: Option<PpoConfig>,
    /// The branching DQN's own settings (present exactly when `algo` is DQN).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dqn: Option<DqnConfig>,
    /// CrossQ's own settings (present exactly when `algo` is CrossQ).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crossq: Option<CrossqConfig>,
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
    ];
}

/// SAC's own settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SacConfig {
    /// Which SAC variant to train.
    pub sac_version: SacVersion,
    /// Learn the temperature against `target_entropy`; otherwise keep `initial_alpha`.
    pub autotune_alpha: bool,
    /// Temperature at the start (and throughout when not tuned).
    pub initial_alpha: f64,
    /// Adam learning rate of the log-temperature.
    pub alpha_lr: f64,
    /// Target entropy for the temperature; absent means -dim(A).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_entropy: Option<f64>,
    /// SAC v1's value network.
    pub value_lr: f64,
    /// How the log-probability is corrected for the tanh squashing.
    pub tanh_correction: TanhCorrection,
}

impl SacConfig {
    pub(crate) const KEYS: &'static [&'static str] = &[
        "sac_version",
        "autotune_alpha",
        "initial_alpha",
        "alpha_lr",
        "target_entropy",
        "value_lr",
        "tanh_correction",
    ];
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
    ];

    /// Transitions per rollout.
    pub fn rollout_size(&self) -> usize {
        self.num_envs * self.num_steps
    }
}

/// The action-branching DQN's own settings. It reads the shared `critic_lr` (its one network's
/// learning rate), `tau` (the target network's Polyak coefficient), `batch_size`, the buffer and
/// `learning_starts`; `warmup_steps` must be 0 (epsilon-greedy exploration starts at random).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DqnConfig {
    /// Evenly spaced values each action dimension is discretised into, bounds included.
    pub levels: usize,
    /// Exploration rate at the start.
    pub epsilon_start: f64,
    /// Exploration rate after `exploration_steps`, and from then on.
    pub epsilon_end: f64,
    /// Exploratory steps over which epsilon decays linearly.
    pub exploration_steps: u64,
}

impl DqnConfig {
    pub(crate) const KEYS: &'static [&'static str] = &["levels", "epsilon_start", "epsilon_end", "exploration_steps"];
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
    ];
}

/// How [`TrainConfig::from_table`] treats a key of another algorithm's section.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OtherAlgorithmKeys {
    /// Config formats 1 and 2 listed every algorithm's settings flat in `[train]`: ignore them.
    Ignore,
    /// An error naming the key and the algorithms it belongs to.
    Refuse,
}

impl TrainConfig {
    /// Reads a `[train]` table: keys it does not give take the algorithm's defaults (so a run
    /// written before a hyperparameter existed still loads); the algorithm's settings may sit in
    /// its section (`[train.td3]`) or, as in formats 1 and 2 and in `--set`, among the shared
    /// keys. An unknown key is an error naming it.
    pub(crate) fn from_table(table: &toml::Table, others: OtherAlgorithmKeys) -> anyhow::Result<TrainConfig> {
        let algo = match table.get("algo") {
            Some(toml::Value::String(name)) => Algo::parse(name)?,
            Some(other) => anyhow::bail!("algo must be a name like \"td3\", got {other}"),
            None => anyhow::bail!("no algo given"),
        };
        let section_name = algo.name();
        let own_keys = section_keys(algo);
        // Work on the flat view (every setting by name), then put the algorithm's own back in
        // its section.
        let mut flat = TrainConfig::defaults(algo).to_flat_table();
        for (key, value) in table {
            match (Algo::parse(key), value) {
                (Ok(a), toml::Value::Table(entries)) if a == algo => {
                    for (k, v) in entries {
                        anyhow::ensure!(
                            own_keys.contains(&k.as_str()),
                            "unknown hyperparameter '{k}' in the [{section_name}] section"
                        );
                        flat.insert(k.clone(), v.clone());
                    }
                }
                (Ok(_), _) => anyhow::bail!("a {section_name} run has no [{key}] section"),
                _ if flat.contains_key(key) || own_keys.contains(&key.as_str()) => {
                    flat.insert(key.clone(), value.clone());
                }
                _ => {
                    let owners: Vec<&str> = super::registry::ALGOS
                        .iter()
                        .filter(|e| section_keys(e.algo).contains(&key.as_str()))
                        .map(|e| e.name)
                        .collect();
                    match (owners.is_empty(), others) {
                        (true, _) => anyhow::bail!("unknown hyperparameter '{key}'"),
                        (false, OtherAlgorithmKeys::Ignore) => {}
                        (false, OtherAlgorithmKeys::Refuse) => {
                            anyhow::bail!("'{key}' is a setting of {}, not of {section_name}", owners.join(" and "))
                        }
                    }
                }
            }
        }
        let section: toml::Table =
            own_keys.iter().filter_map(|&k| flat.remove(k).map(|v| (k.to_string(), v))).collect();
        flat.insert(section_name.to_string(), toml::Value::Table(section));
        toml::Value::Table(flat).try_into().map_err(|e: toml::de::Error| anyhow::anyhow!("{}", e.message()))
    }

    /// Every setting by name in one table, the algorithm's section lifted among the shared ones
    /// (what `--set` takes and what reports compare).
    pub(crate) fn to_flat_table(&self) -> toml::Table {
        let mut table = toml::Table::try_from(self).expect("config serialises");
        if let Some(toml::Value::Table(section)) = table.remove(self.algo.name()) {
            table.extend(section);
        }
        table
    }

    /// TD3's or DDPG's section. Panics for another algorithm (agents only read their own).
    pub fn dpg(&self) -> &DpgConfig {
        self.td3.as_ref().or(self.ddpg.as_ref()).expect("a TD3 or DDPG config")
    }

    /// The TD3 or DDPG section, mutably; panics for SAC.
    pub fn dpg_mut(&mut self) -> &mut DpgConfig {
        self.td3.as_mut().or(self.ddpg.as_mut()).expect("a TD3 or DDPG config")
    }

    /// SAC's section. Panics for another algorithm.
    pub fn sac(&self) -> &SacConfig {
        self.sac.as_ref().expect("a SAC config")
    }

    /// PPO's section. Panics for another algorithm.
    pub fn ppo(&self) -> &PpoConfig {
        self.ppo.as_ref().expect("a PPO config")
    }

    /// The branching DQN's section. Panics for another algorithm.
    pub fn dqn(&self) -> &DqnConfig {
        self.dqn.as_ref().expect("a DQN config")
    }

    /// CrossQ's section. Panics for another algorithm.
    pub fn crossq(&self) -> &CrossqConfig {
        self.crossq.as_ref().expect("a CrossQ config")
    }

    /// The defaults each algorithm was published with (sources in docs/references.md), from its
    /// registry entry.
    pub fn defaults(algo: Algo) -> TrainConfig {
        (super::registry::entry(algo).defaults)()
    }

    /// The settings all three algorithms share, at TD3's published values (Fujimoto et al. 2018).
    fn shared_defaults(algo: Algo) -> TrainConfig {
        TrainConfig {
            algo,
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
            weight_init: WeightInit::Uniform,
            tau: 0.005,
            actor_lr: 1e-3,
            critic_lr: 1e-3,
            eval_every: 5000,
            eval_episodes: 10,
            checkpoint_every: 50_000,
            td3: None,
            ddpg: None,
            sac: None,
            ppo: None,
            dqn: None,
            crossq: None,
        }
    }

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

    /// SAC v2's (Haarnoja et al. 2018b): 256-256, Adam 3e-4, batch 256.
    pub(crate) fn sac_defaults() -> TrainConfig {
        TrainConfig {
            batch_size: 256,
            hidden: vec![256, 256],
            actor_lr: 3e-4,
            critic_lr: 3e-4,
            sac: Some(SacConfig {
                sac_version: SacVersion::V2,
                autotune_alpha: true,
                initial_alpha: 1.0,
                alpha_lr: 3e-4,
                target_entropy: None,
                value_lr: 3e-4,
                tanh_correction: TanhCorrection::Exact,
            }),
            ..TrainConfig::shared_defaults(Algo::Sac)
        }
    }

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
            }),
            ..TrainConfig::shared_defaults(Algo::Ppo)
        }
    }

    /// Tavakoli et al. (2018)'s branching DQN: Adam 1e-4, batch 64, 512-256 shared torso, three
    /// levels per joint (the Minitaur study this project grew from used three), epsilon-greedy
    /// from 1 to 0.05 over 50k steps.
    pub(crate) fn dqn_defaults() -> TrainConfig {
        TrainConfig {
            warmup_steps: 0,
            batch_size: 64,
            hidden: vec![512, 256],
            actor_lr: 1e-4,
            critic_lr: 1e-4,
            dqn: Some(DqnConfig { levels: 3, epsilon_start: 1.0, epsilon_end: 0.05, exploration_steps: 50_000 }),
            ..TrainConfig::shared_defaults(Algo::Dqn)
        }
    }

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
            }),
            ..TrainConfig::shared_defaults(Algo::Crossq)
        }
    }

    /// Checks every setting's range and that exactly the algorithm's own section is present.
    pub fn validate(&self) -> anyhow::Result<()> {
        let positive = |name: &str, v: f64| -> anyhow::Result<()> {
            anyhow::ensure!(v.is_finite() && v > 0.0, "{name} must be a finite number > 0, got {v}");
            Ok(())
        };
        let sections = [
            ("td3", self.td3.is_some()),
            ("ddpg", self.ddpg.is_some()),
            ("sac", self.sac.is_some()),
            ("ppo", self.ppo.is_some()),
            ("dqn", self.dqn.is_some()),
            ("crossq", self.crossq.is_some()),
        ];
        for (name, present) in sections {
            anyhow::ensure!(
                present == (name == self.algo.name()),
                "a {} config must carry exactly its own [{}] section",
                self.algo.name(),
                self.algo.name()
            );
        }
        positive("actor_lr", self.actor_lr)?;
        positive("critic_lr", self.critic_lr)?;
        positive("reward_scale", self.reward_scale)?;
        anyhow::ensure!(
            self.algo.is_on_policy()
                || !self.normalize_observations
                || self.learning_starts >= self.batch_size.max(2) as u64,
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
        anyhow::ensure!(self.updates_per_step >= 1, "updates_per_step must be at least 1");
        anyhow::ensure!(
            self.eval_every > 0 && self.eval_episodes > 0,
            "eval_every and eval_episodes must be at least 1"
        );
        anyhow::ensure!(self.checkpoint_every > 0, "checkpoint_every must be at least 1");
        if let Some(d) = self.td3.as_ref().or(self.ddpg.as_ref()) {
            anyhow::ensure!(d.policy_delay >= 1, "policy_delay must be at least 1");
            anyhow::ensure!(
                d.exploration_noise >= 0.0 && d.policy_noise >= 0.0 && d.noise_clip >= 0.0,
                "noise scales must be >= 0"
            );
        }
        if let Some(s) = &self.sac {
            positive("alpha_lr", s.alpha_lr)?;
            positive("value_lr", s.value_lr)?;
            positive("initial_alpha", s.initial_alpha)?;
        }
        if let Some(c) = &self.crossq {
            anyhow::ensure!(
                !c.critic_hidden.is_empty() && c.critic_hidden.iter().all(|&h| h > 0),
                "critic_hidden needs at least one layer size > 0"
            );
            anyhow::ensure!(c.policy_delay >= 1, "policy_delay must be at least 1");
            anyhow::ensure!((0.0..1.0).contains(&c.adam_beta1), "adam_beta1 must lie in [0, 1)");
            anyhow::ensure!((0.0..1.0).contains(&c.batch_norm_momentum), "batch_norm_momentum must lie in [0, 1)");
            positive("initial_alpha", c.initial_alpha)?;
            positive("alpha_lr", c.alpha_lr)?;
            anyhow::ensure!(
                self.batch_size >= 2,
                "batch normalisation needs at least 2 transitions per batch, got batch_size {}",
                self.batch_size
            );
        }
        if let Some(d) = &self.dqn {
            anyhow::ensure!(d.levels >= 2, "levels must be at least 2 (the two bounds), got {}", d.levels);
            anyhow::ensure!(
                (0.0..=1.0).contains(&d.epsilon_start) && (0.0..=1.0).contains(&d.epsilon_end),
                "epsilon_start and epsilon_end must lie in [0, 1]"
            );
            anyhow::ensure!(
                self.warmup_steps == 0,
                "dqn explores with epsilon-greedy levels from the start: warmup_steps must be 0 (the warm-up's \
                 uniform continuous actions are not levels), got {}",
                self.warmup_steps
            );
        }
        if let Some(p) = &self.ppo {
            anyhow::ensure!(
                p.num_envs >= 1 && p.num_steps >= 1 && p.update_epochs >= 1 && p.num_minibatches >= 1,
                "num_envs, num_steps, num_minibatches and update_epochs must be at least 1"
            );
            anyhow::ensure!(
                p.num_minibatches <= p.rollout_size(),
                "num_minibatches ({}) is more than a rollout holds (num_envs x num_steps = {}): a minibatch would \
                 be empty",
                p.num_minibatches,
                p.rollout_size()
            );
            anyhow::ensure!((0.0..=1.0).contains(&p.gae_lambda), "gae_lambda must lie in [0, 1]");
            positive("clip_coef", p.clip_coef)?;
            positive("max_grad_norm", p.max_grad_norm)?;
            positive("clip_observations", p.clip_observations)?;
            positive("clip_rewards", p.clip_rewards)?;
            positive("adam_eps", p.adam_eps)?;
            anyhow::ensure!(p.ent_coef >= 0.0 && p.vf_coef >= 0.0, "ent_coef and vf_coef must be >= 0");
            if let Some(kl) = p.target_kl {
                positive("target_kl", kl)?;
            }
        }
        Ok(())
    }
}

/// The keys of an algorithm's own section, from its registry entry.
pub(crate) fn section_keys(algo: Algo) -> &'static [&'static str] {
    super::registry::entry(algo).settings
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_hold_exactly_their_algorithms_settings() {
        for algo in [Algo::Td3, Algo::Ddpg, Algo::Sac, Algo::Ppo, Algo::Dqn, Algo::Crossq] {
            let d = TrainConfig::defaults(algo);
            d.validate().unwrap();
            let table = toml::Table::try_from(&d).unwrap();
            let section = table[algo.name()].as_table().unwrap();
            // Every serialised key is declared (target_entropy is absent while None).
            assert!(section.keys().all(|k| section_keys(algo).contains(&k.as_str())), "{algo:?}");
            // target_entropy (SAC) and target_kl (PPO) are absent while None.
            let optional = usize::from(matches!(algo, Algo::Sac | Algo::Ppo | Algo::Crossq));
            assert_eq!(section.len() + optional, section_keys(algo).len());
            for other in ["td3", "ddpg", "sac", "ppo", "dqn", "crossq"].into_iter().filter(|o| *o != algo.name()) {
                assert!(!table.contains_key(other));
            }
            // Flat and sectioned spellings read the same.
            let flat = d.to_flat_table();
            assert_eq!(TrainConfig::from_table(&flat, OtherAlgorithmKeys::Refuse).unwrap(), d);
            assert_eq!(TrainConfig::from_table(&table, OtherAlgorithmKeys::Refuse).unwrap(), d);
        }
        let mut t = toml::Table::new();
        t.insert("algo".into(), "td3".into());
        t.insert("alpha_lr".into(), 0.1.into());
        let err = TrainConfig::from_table(&t, OtherAlgorithmKeys::Refuse).unwrap_err().to_string();
        assert!(err.contains("alpha_lr") && err.contains("sac"), "{err}");
        assert_eq!(TrainConfig::from_table(&t, OtherAlgorithmKeys::Ignore).unwrap(), TrainConfig::td3_defaults());
        let mut t = toml::Table::new();
        t.insert("algo".into(), "td3".into());
        t.insert("sac".into(), toml::Value::Table(toml::Table::new()));
        assert!(TrainConfig::from_table(&t, OtherAlgorithmKeys::Ignore).is_err());
        let mut t = toml::Table::new();
        t.insert("algo".into(), "sac".into());
        t.insert("target_entropy".into(), (-3.0).into());
        assert_eq!(TrainConfig::from_table(&t, OtherAlgorithmKeys::Refuse).unwrap().sac().target_entropy, Some(-3.0));
    }
}
