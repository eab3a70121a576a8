//! A device agent whose errors say what ran out when the GPU runs out of memory: the algorithm,
//! its networks' widths and the batch size, which is what a user changes.
use crate::agents::delegate_to_inner;
use candle_core::{Result, Var};
use rand_chacha::ChaCha8Rng;

use crate::agents::common::buffer::{Batch, ReplayBuffer};
use crate::agents::config::TrainConfig;
use crate::agents::ppo::{PolicyStep, PpoBatch, PpoLosses};
use crate::agents::{Agent, Losses, OffPolicyAgent, OnPolicyAgent};

/// What an out-of-memory error names: `crossq with actor 256-256, critics 2048-2048, batch 256 on cuda:0`.
pub(crate) fn describe(cfg: &TrainConfig, device: &str) -> String {
    let join = |w: &[usize]| w.iter().map(|v| v.to_string()).collect::<Vec<_>>().join("-");
    let critics = cfg.crossq.as_ref().map_or_else(|| join(&cfg.hidden), |c| join(&c.critic_hidden));
    format!(
        "{} with actor {}, critics {critics}, batch {} on {device}",
        cfg.algo.name(),
        join(&cfg.hidden),
        cfg.batch_size
    )
}

/// `e`, or, when it is the device running out of memory, an error that names `what` and the
/// settings that size it.
pub(crate) fn explain(e: candle_core::Error, what: &str) -> candle_core::Error {
    let text = e.to_string();
    if text.contains("OUT_OF_MEMORY") || text.to_lowercase().contains("out of memory") {
        candle_core::Error::Msg(format!(
            "the GPU ran out of memory training {what}: lower hidden, critic_hidden or batch_size (--set), \
             or free the GPU ({text})"
        ))
    } else {
        e
    }
}

/// A device-generic agent (off- or on-policy) whose errors go through [`explain`].
pub(crate) struct Explained<A: ?Sized> {
    pub inner: Box<A>,
    pub what: String,
}

impl<A: Agent + ?Sized> Agent for Explained<A> {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.inner.act(obs).map_err(|e| explain(e, &self.what))
    }

    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        self.inner.explore(obs, rng).map_err(|e| explain(e, &self.what))
    }

    fn parameters(&self) -> Vec<(String, Var)> {
        self.inner.parameters()
    }

    delegate_to_inner!();
}

impl OffPolicyAgent for Explained<dyn OffPolicyAgent> {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        self.inner.update(batch, rng).map_err(|e| explain(e, &self.what))
    }

    fn fit_observations(&mut self, buffer: &ReplayBuffer) -> Result<()> {
        self.inner.fit_observations(buffer).map_err(|e| explain(e, &self.what))
    }
}

impl OnPolicyAgent for Explained<dyn OnPolicyAgent> {
    fn observe(&mut self, raw: &[Vec<f64>]) -> Result<()> {
        self.inner.observe(raw)
    }

    fn normalize(&self, raw: &[Vec<f64>]) -> Result<Vec<f32>> {
        self.inner.normalize(raw)
    }

    fn policy_step(&self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<PolicyStep> {
        self.inner.policy_step(obs, rng).map_err(|e| explain(e, &self.what))
    }

    fn values(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.inner.values(obs).map_err(|e| explain(e, &self.what))
    }

    fn anneal(&mut self, fraction: f64) {
        self.inner.anneal(fraction)
    }

    fn learn(&mut self, batch: &PpoBatch) -> Result<PpoLosses> {
        self.inner.learn(batch).map_err(|e| explain(e, &self.what))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agents::common::device::make_generic_agent;
    use crate::agents::Algo;
    use candle_core::Device;
    use rand::SeedableRng;

    #[test]
    fn out_of_memory_names_the_networks_and_the_batch_and_other_errors_pass_through() {
        let cfg = TrainConfig::defaults(Algo::Crossq);
        let what = describe(&cfg, "cuda:0");
        assert_eq!(what, "crossq with actor 256-256, critics 2048-2048, batch 256 on cuda:0");
        let oom = candle_core::Error::Msg("DriverError(CUDA_ERROR_OUT_OF_MEMORY, \"out of memory\")".into());
        let text = explain(oom, &what).to_string();
        assert!(text.contains("ran out of memory training crossq with actor 256-256, critics 2048-2048"), "{text}");
        assert!(text.contains("batch_size") && text.contains("CUDA_ERROR_OUT_OF_MEMORY"), "{text}");
        let other = explain(candle_core::Error::Msg("shape mismatch".into()), &what).to_string();
        assert_eq!(other, "shape mismatch");
    }

    #[test]
    fn the_wrapper_acts_and_updates_as_the_agent_it_wraps() {
        let mut cfg = TrainConfig::defaults(Algo::Sac);
        (cfg.hidden, cfg.batch_size) = (vec![16, 16], 8);
        let make = || make_generic_agent(&cfg, 5, 2, &mut ChaCha8Rng::seed_from_u64(1), &Device::Cpu).unwrap();
        let mut plain = make();
        let mut wrapped: Explained<dyn OffPolicyAgent> = Explained { inner: make(), what: describe(&cfg, "cpu") };
        let batch = Batch::new(8, 5, 2);
        let (mut r1, mut r2) = (ChaCha8Rng::seed_from_u64(2), ChaCha8Rng::seed_from_u64(2));
        assert_eq!(plain.update(&batch, &mut r1).unwrap(), wrapped.update(&batch, &mut r2).unwrap());
        assert_eq!(plain.act(&[0.1; 5]).unwrap(), wrapped.act(&[0.1; 5]).unwrap());
        assert_eq!(plain.counters(), wrapped.counters());
        assert_eq!(plain.optimizers().len(), wrapped.optimizers().len());
    }
}
