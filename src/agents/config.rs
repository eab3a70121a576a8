//! Every hyperparameter of a training run: the settings all algorithms share, and the
//! `TrainConfig` that carries one algorithm's own section. Each algorithm's section, its
//! published defaults and their checks sit beside the algorithm (`dpg.rs`, `sac.rs`, ...).
use serde::{Deserialize, Serialize};

pub use super::crossq::CrossqConfig;
pub use super::dpg::DpgConfig;
pub use super::dqn::DqnConfig;
pub use super::ppo::PpoConfig;
pub use super::sac::SacConfig;
pub use crate::agents::common::squashed::TanhCorrection;

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

/// Which actor a run keeps at each reporting budget (`budget_policy` in `[train]`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BudgetPolicy {
    /// The actor at that step.
    #[default]
    Last,
    /// Of the actors evaluated in training up to that step, the one whose evaluation had the
    /// highest minimum episode return (ties: the higher mean): TD7's policy checkpoints
    /// (`train::selection`). Off-policy algorithms only.
    Best,
    /// Of the same actors, the one whose evaluation ended fewest episodes in a fall (ties: the
    /// higher mean return). Off-policy algorithms only.
    #[serde(rename = "fewest_falls")]
    FewestFalls,
}

impl BudgetPolicy {
    fn is_last(&self) -> bool {
        *self == BudgetPolicy::Last
    }

    /// Whether the run picks among its evaluated actors instead of keeping the one at the budget.
    pub fn selects(&self) -> bool {
        *self != BudgetPolicy::Last
    }

    /// The value as `config.toml` spells it.
    pub fn name(&self) -> &'static str {
        match self {
            BudgetPolicy::Last => "last",
            BudgetPolicy::Best => "best",
            BudgetPolicy::FewestFalls => "fewest_falls",
        }
    }
}

/// Which reset seeds a run's in-training evaluations play (`eval_starts` in `[train]`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum EvalStarts {
    /// Every evaluation replays the same `eval_episodes` starts.
    #[default]
    Fixed,
    /// Each evaluation plays starts of its own, drawn from its step, so that a `budget_policy`
    /// which picks among many evaluations cannot favour an actor that merely suits one set of
    /// starts.
    Fresh,
}

impl EvalStarts {
    fn is_fixed(&self) -> bool {
        *self == EvalStarts::Fixed
    }
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
    /// Subtracted from the reward the learner stores on a transition that ends its episode by
    /// termination (a fall; not a time limit), before `reward_scale`. Returns and evaluations stay
    /// the environment's. legged_gym's `termination` reward term is the same penalty
    /// (`leggedrobotics/legged_gym`, `legged_gym/envs/base/legged_robot.py`, `_reward_termination`).
    /// 0 unless asked for.
    pub termination_penalty: f64,
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
    /// Which actor the run keeps at each reporting budget: `last` (the default) or `best`.
    #[serde(default, skip_serializing_if = "BudgetPolicy::is_last")]
    pub budget_policy: BudgetPolicy,
    /// Which starts the in-training evaluations play: `fixed` (the default, the same ones every
    /// time) or `fresh` (new ones at every evaluation).
    #[serde(default, skip_serializing_if = "EvalStarts::is_fixed")]
    pub eval_starts: EvalStarts,
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

/// How [`TrainConfig::from_table`] treats a key of another algorithm's section.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OtherAlgorithmKeys {
    /// Config formats 1 and 2 listed every algorithm's settings flat in `[train]`: ignore them.
    Ignore,
    /// An error naming the key and the algorithms it belongs to.
    Refuse,
}

/// Settings an algorithm took after format 2 under names that format 1 and 2 files, which list
/// every algorithm's settings flat, used for another algorithm's (SAC's `policy_delay` was TD3's,
/// `adam_beta1` CrossQ's): read from such a file they belong to that other algorithm.
fn taken_after_format_2(algo: Algo) -> &'static [&'static str] {
    match algo {
        Algo::Sac => &["policy_delay", "adam_beta1"],
        _ => &[],
    }
}

/// Shared settings a config leaves out at their default, so that files written before them stay
/// byte for byte what they were.
const OMITTED_AT_DEFAULT: [&str; 2] = ["budget_policy", "eval_starts"];

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
                // An older file's flat listing: this name was another algorithm's setting then.
                _ if matches!(others, OtherAlgorithmKeys::Ignore)
                    && taken_after_format_2(algo).contains(&key.as_str()) => {}
                _ if flat.contains_key(key)
                    || own_keys.contains(&key.as_str())
                    || OMITTED_AT_DEFAULT.contains(&key.as_str()) =>
                {
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
    pub(crate) fn shared_defaults(algo: Algo) -> TrainConfig {
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
            termination_penalty: 0.0,
            normalize_observations: false,
            weight_init: WeightInit::Uniform,
            tau: 0.005,
            actor_lr: 1e-3,
            critic_lr: 1e-3,
            eval_every: 5000,
            eval_episodes: 10,
            checkpoint_every: 50_000,
            budget_policy: BudgetPolicy::Last,
            eval_starts: EvalStarts::Fixed,
            td3: None,
            ddpg: None,
            sac: None,
            ppo: None,
            dqn: None,
            crossq: None,
        }
    }

    /// Checks every setting's range and that exactly the algorithm's own section is present.
    pub fn validate(&self) -> anyhow::Result<()> {
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
            self.termination_penalty.is_finite() && self.termination_penalty >= 0.0,
            "termination_penalty must be a finite number >= 0, got {}",
            self.termination_penalty
        );
        anyhow::ensure!(
            self.algo.is_on_policy()
                || !self.normalize_observations
                || self.learning_starts >= self.batch_size.max(2) as u64,
            "normalize_observations estimates its statistics from the transitions before learning starts: \
             learning_starts ({}) must be at least the batch size ({})",
            self.learning_starts,
            self.batch_size
        );
        anyhow::ensure!(
            !(self.algo.is_on_policy() && self.budget_policy.selects()),
            "budget_policy = \"{}\" picks among the actors of the off-policy loop's evaluations; \
             {} keeps its last actor at each budget (budget_policy = \"last\")",
            self.budget_policy.name(),
            self.algo.name()
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
        // each algorithm's own section, checked where it is defined
        if let Some(d) = self.td3.as_ref().or(self.ddpg.as_ref()) {
            d.validate()?;
        }
        if let Some(s) = &self.sac {
            s.validate()?;
        }
        if let Some(c) = &self.crossq {
            c.validate(self)?;
        }
        if let Some(d) = &self.dqn {
            d.validate(self)?;
        }
        if let Some(p) = &self.ppo {
            p.validate()?;
        }
        Ok(())
    }
}

/// That a setting is a finite number above zero.
pub(crate) fn positive(name: &str, v: f64) -> anyhow::Result<()> {
    anyhow::ensure!(v.is_finite() && v > 0.0, "{name} must be a finite number > 0, got {v}");
    Ok(())
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
            // target_entropy (SAC, CrossQ) and target_kl (PPO) are absent while None, PPO's
            // activation and log_std_init while at their defaults (tanh, 0), and
            // critic_layer_norm (SAC, TD3, DDPG) while off, SAC's policy_delay and adam_beta1
            // at their defaults (1, 0.9), and CrossQ's td3_mode while off with its three noise
            // settings at TD3's values.
            let optional = match algo {
                Algo::Sac => 4,
                Algo::Crossq => 5,
                Algo::Td3 | Algo::Ddpg => 1,
                Algo::Ppo => 3,
                Algo::Dqn => 0,
            };
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
        // layer-normalised critics: an option of SAC, TD3 and DDPG, refused for the others
        for (algo, takes) in [("sac", true), ("td3", true), ("ddpg", true), ("crossq", false), ("ppo", false)] {
            let mut t = toml::Table::new();
            t.insert("algo".into(), algo.into());
            t.insert("critic_layer_norm".into(), true.into());
            match TrainConfig::from_table(&t, OtherAlgorithmKeys::Refuse) {
                Ok(c) => {
                    assert!(takes, "{algo}");
                    let on = if algo == "sac" { c.sac().critic_layer_norm } else { c.dpg().critic_layer_norm };
                    assert!(on, "{algo}");
                    assert!(toml::to_string(&c).unwrap().contains("critic_layer_norm = true"));
                }
                Err(e) => {
                    let e = e.to_string();
                    assert!(!takes && e.contains("'critic_layer_norm'") && e.contains("sac"), "{algo}: {e}");
                }
            }
        }
        assert!(!toml::to_string(&TrainConfig::sac_defaults()).unwrap().contains("critic_layer_norm"));
    }

    #[test]
    fn eval_starts_is_omitted_at_its_default_and_checked() {
        // omitted at the default, so older files stay as they were; read back when set
        let mut cfg = TrainConfig::td3_defaults();
        assert!(!toml::to_string(&cfg).unwrap().contains("eval_starts"));
        cfg.eval_starts = EvalStarts::Fresh;
        let text = toml::to_string(&cfg).unwrap();
        assert!(text.contains("eval_starts = \"fresh\""), "{text}");
        let table: toml::Table = toml::from_str(&text).unwrap();
        assert_eq!(TrainConfig::from_table(&table, OtherAlgorithmKeys::Refuse).unwrap(), cfg);
        let mut t = toml::Table::new();
        t.insert("algo".into(), "td3".into());
        t.insert("eval_starts".into(), "random".into());
        let err = format!("{:#}", TrainConfig::from_table(&t, OtherAlgorithmKeys::Refuse).unwrap_err());
        assert!(err.contains("random") && err.contains("fresh"), "{err}");
    }
}
