//! The algorithm registry: each algorithm is declared once, in [`ALGOS`] (name, published
//! defaults, its config section's keys, constructor); parsing names, defaults, config sections
//! and `make_agent` all go through it.
use candle_core::Result;
use rand_chacha::ChaCha8Rng;

use super::{
    Algo, BranchingDqnAgent, CrossqAgent, CrossqConfig, DeterministicAgent, DpgConfig, DqnConfig, OffPolicyAgent,
    OnPolicyAgent, PpoAgent, PpoConfig, SacAgent, SacConfig, TrainConfig,
};

/// A registered algorithm: its name, published defaults, settings and constructor.
pub struct AlgoEntry {
    /// The algorithm this entry builds.
    pub algo: Algo,
    /// The name `--algo` and config files use.
    pub name: &'static str,
    /// The settings it was published with.
    pub defaults: fn() -> TrainConfig,
    /// The keys of its own `config.toml` section (`[train.<name>]`).
    pub settings: &'static [&'static str],
    /// Builds the agent for observation and action sizes, initialised from the RNG.
    pub build: Build,
}

/// How an algorithm's agent is built from its config, the observation and action sizes and the
/// initialisation RNG: an off-policy learner, or an on-policy one.
#[derive(Clone, Copy)]
pub enum Build {
    /// Learns from replay minibatches.
    OffPolicy(BuildFn<dyn OffPolicyAgent>),
    /// Learns from its own rollouts.
    OnPolicy(BuildFn<dyn OnPolicyAgent>),
}

/// A constructor: config, observation and action sizes, initialisation RNG.
pub type BuildFn<A> = fn(&TrainConfig, usize, usize, &mut ChaCha8Rng) -> Result<Box<A>>;

pub(crate) const ALGOS: &[AlgoEntry] = &[
    AlgoEntry {
        algo: Algo::Td3,
        name: "td3",
        defaults: TrainConfig::td3_defaults,
        settings: DpgConfig::KEYS,
        build: Build::OffPolicy(deterministic),
    },
    AlgoEntry {
        algo: Algo::Sac,
        name: "sac",
        defaults: TrainConfig::sac_defaults,
        settings: SacConfig::KEYS,
        build: Build::OffPolicy(sac),
    },
    AlgoEntry {
        algo: Algo::Ddpg,
        name: "ddpg",
        defaults: TrainConfig::ddpg_defaults,
        settings: DpgConfig::KEYS,
        build: Build::OffPolicy(deterministic),
    },
    AlgoEntry {
        algo: Algo::Ppo,
        name: "ppo",
        defaults: TrainConfig::ppo_defaults,
        settings: PpoConfig::KEYS,
        build: Build::OnPolicy(ppo),
    },
    AlgoEntry {
        algo: Algo::Dqn,
        name: "dqn",
        defaults: TrainConfig::dqn_defaults,
        settings: DqnConfig::KEYS,
        build: Build::OffPolicy(dqn),
    },
    AlgoEntry {
        algo: Algo::Crossq,
        name: "crossq",
        defaults: TrainConfig::crossq_defaults,
        settings: CrossqConfig::KEYS,
        build: Build::OffPolicy(crossq),
    },
];

/// The entry of an algorithm (every `Algo` has one; tested).
pub fn entry(algo: Algo) -> &'static AlgoEntry {
    ALGOS.iter().find(|e| e.algo == algo).expect("every Algo is registered")
}

fn deterministic(cfg: &TrainConfig, obs: usize, act: usize, rng: &mut ChaCha8Rng) -> Result<Box<dyn OffPolicyAgent>> {
    Ok(Box::new(DeterministicAgent::new(cfg, obs, act, rng)?))
}

fn sac(cfg: &TrainConfig, obs: usize, act: usize, rng: &mut ChaCha8Rng) -> Result<Box<dyn OffPolicyAgent>> {
    Ok(Box::new(SacAgent::new(cfg, obs, act, rng)?))
}

fn ppo(cfg: &TrainConfig, obs: usize, act: usize, rng: &mut ChaCha8Rng) -> Result<Box<dyn OnPolicyAgent>> {
    Ok(Box::new(PpoAgent::new(cfg, obs, act, rng)?))
}

fn dqn(cfg: &TrainConfig, obs: usize, act: usize, rng: &mut ChaCha8Rng) -> Result<Box<dyn OffPolicyAgent>> {
    Ok(Box::new(BranchingDqnAgent::new(cfg, obs, act, rng)?))
}

fn crossq(cfg: &TrainConfig, obs: usize, act: usize, rng: &mut ChaCha8Rng) -> Result<Box<dyn OffPolicyAgent>> {
    Ok(Box::new(CrossqAgent::new(cfg, obs, act, rng)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_algorithm_is_declared_once_and_round_trips() {
        for (i, e) in ALGOS.iter().enumerate() {
            assert!(ALGOS[..i].iter().all(|o| o.name != e.name && o.algo != e.algo), "{} twice", e.name);
            assert_eq!(Algo::parse(e.name).unwrap(), e.algo);
            assert_eq!(e.algo.name(), e.name);
            assert_eq!((e.defaults)().algo, e.algo);
            // The serialised name is the registry's.
            let table = toml::Table::try_from((e.defaults)()).unwrap();
            assert_eq!(table["algo"].as_str(), Some(e.name));
        }
        for algo in [Algo::Td3, Algo::Sac, Algo::Ddpg, Algo::Ppo, Algo::Dqn, Algo::Crossq] {
            entry(algo);
        }
        let err = Algo::parse("a2c").unwrap_err().to_string();
        assert!(err.contains("a2c") && err.contains("td3, sac, ddpg, ppo, dqn, crossq"), "{err}");
    }
}
