//! The evaluation protocol every final comparison goes through, whatever acts: a trained agent,
//! a controller or a replay. Each policy plays the same held-out episodes: reset seeds from their
//! own domain (disjoint from every run's training and in-training evaluation seeds, checked),
//! the same env options and reward, deterministic actions, each episode reset with its own seed
//! so no policy's episode depends on another's.
use anyhow::{bail, Result};

use super::push::{Push, Pushed};
use crate::agents::config::{EvalStarts, TrainConfig};
use crate::controller::command::SpeedProfile;
use crate::controller::measure::{measure_episode, GaitEpisode};
use crate::envs::Env;
use crate::policy::Policy;
use crate::train::seeds::{eval_episode_seed, fresh_eval_episode_seed, held_out_episode_seed, train_episode_seed};

/// Episodes per policy and seed unless asked otherwise.
pub const DEFAULT_EPISODES: usize = 50;

/// The held-out episodes every policy is evaluated on: how many, and the seed that picks their reset seeds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Protocol {
    /// Episodes per policy and seed.
    pub episodes: usize,
    /// Picks the held-out reset seeds (`train::seeds::held_out_episode_seed`).
    pub seed: u64,
}

impl Default for Protocol {
    fn default() -> Self {
        Protocol { episodes: DEFAULT_EPISODES, seed: 0 }
    }
}

impl Protocol {
    pub(crate) fn reset_seeds(&self) -> Vec<u64> {
        (0..self.episodes as u64).map(|i| held_out_episode_seed(self.seed, i)).collect()
    }

    /// Fails if a held-out reset seed is one a run trained or was evaluated on: run seed
    /// `run_seed`, at most `episodes_trained` training episodes (the step budget bounds it), and
    /// `eval_episodes` evaluation episodes.
    pub fn check_disjoint(&self, run_seed: u64, episodes_trained: u64, eval_episodes: usize) -> Result<()> {
        let held_out = self.reset_seeds();
        if let Some(e) = first_shared(&held_out, (0..episodes_trained).map(|e| train_episode_seed(run_seed, e))) {
            bail!(
                "held-out reset seeds (protocol seed {}) include training episode {e} of run seed {run_seed}",
                self.seed
            );
        }
        if let Some(i) = first_shared(&held_out, (0..eval_episodes as u64).map(|i| eval_episode_seed(run_seed, i))) {
            bail!(
                "held-out reset seeds (protocol seed {}) include evaluation episode {i} of run seed {run_seed}",
                self.seed
            );
        }
        Ok(())
    }

    /// Fails if a held-out reset seed is one run `run_seed` with settings `train` trained or was
    /// evaluated on. Under `eval_starts = "fresh"` that covers the starts of an evaluation at
    /// every step up to `total_steps`: `eval_episodes` hashes a step, cheap beside any episode.
    pub fn check_run(&self, run_seed: u64, train: &TrainConfig) -> Result<()> {
        self.check_disjoint(run_seed, train.total_steps, train.eval_episodes)?;
        if train.eval_starts == EvalStarts::Fresh {
            let k = train.eval_episodes as u64;
            let fresh = (1..=train.total_steps)
                .flat_map(|step| (0..k).map(move |i| fresh_eval_episode_seed(run_seed, step, i)));
            if let Some(n) = first_shared(&self.reset_seeds(), fresh) {
                let (step, i) = (n as u64 / k + 1, n as u64 % k);
                bail!(
                    "held-out reset seeds (protocol seed {}) include episode {i} of run seed {run_seed}'s evaluation at \
                     step {step}",
                    self.seed
                );
            }
        }
        Ok(())
    }

    /// Plays the protocol's episodes. `profile`: the set-point a controller follows (speed
    /// errors are measured against it; None for policies without one). `push`: a perturbation
    /// applied to every episode.
    pub fn run(
        &self,
        env: &mut dyn Env,
        policy: &mut dyn Policy,
        profile: Option<&SpeedProfile>,
        push: Option<Push>,
    ) -> Result<Vec<GaitEpisode>> {
        let seeds = self.reset_seeds();
        match push {
            None => seeds.iter().enumerate().map(|(i, &s)| measure_episode(env, policy, i, Some(s), profile)).collect(),
            Some(push) => {
                let mut pushed = Pushed::new(env, push)?;
                seeds
                    .iter()
                    .enumerate()
                    .map(|(i, &s)| measure_episode(&mut pushed, policy, i, Some(s), profile))
                    .collect()
            }
        }
    }
}

/// Index of the first of `used` that is also in `held_out`.
fn first_shared(held_out: &[u64], used: impl Iterator<Item = u64>) -> Option<usize> {
    let held_out: std::collections::HashSet<u64> = held_out.iter().copied().collect();
    used.enumerate().find(|(_, s)| held_out.contains(s)).map(|(i, _)| i)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::{make, EnvConfig};
    use crate::policy::ZeroPolicy;

    #[test]
    fn held_out_seeds_are_fixed_distinct_and_apart_from_training() {
        let p = Protocol::default();
        let seeds = p.reset_seeds();
        assert_eq!(seeds.len(), 50);
        assert_eq!(seeds, Protocol::default().reset_seeds());
        let unique: std::collections::HashSet<_> = seeds.iter().collect();
        assert_eq!(unique.len(), 50);
        assert_ne!(seeds, Protocol { seed: 1, ..p }.reset_seeds());
        for run_seed in 0..5 {
            p.check_disjoint(run_seed, 1_000_000, 10).unwrap();
        }
        let mut fresh = crate::agents::TrainConfig::td3_defaults();
        fresh.total_steps = 100_000;
        fresh.eval_starts = EvalStarts::Fresh;
        p.check_run(3, &fresh).unwrap();
    }

    #[test]
    fn a_shared_seed_is_found() {
        let training = (0..100).map(|e| train_episode_seed(7, e));
        let mut held_out = Protocol { episodes: 3, seed: 0 }.reset_seeds();
        assert_eq!(first_shared(&held_out, training.clone()), None);
        held_out[1] = train_episode_seed(7, 42);
        assert_eq!(first_shared(&held_out, training), Some(42));
    }

    #[test]
    fn every_policy_sees_the_same_starts_whatever_ran_before() {
        let mut env = make(&EnvConfig::new("ant")).unwrap();
        let p = Protocol { episodes: 3, seed: 5 };
        let a = p.run(env.as_mut(), &mut ZeroPolicy, None, None).unwrap();
        // Another policy in between leaves the environment's random stream elsewhere.
        let mut random = crate::policy::RandomPolicy::new(1);
        p.run(env.as_mut(), &mut random, None, None).unwrap();
        let b = p.run(env.as_mut(), &mut ZeroPolicy, None, None).unwrap();
        // (Debug text: NaN speed errors compare unequal as numbers.)
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        assert!(a[0].speed_error.is_nan(), "no set-point, no speed error");
        assert_ne!(a[0].episode_return, a[1].episode_return, "episodes start from different states");
    }
}
