//! The in-training evaluation: K deterministic episodes on a separate environment instance, reset
//! with the run's evaluation seeds (the same starts every time, or fresh ones per evaluation under
//! `eval_starts = "fresh"`).
use anyhow::Result;

use crate::agents::{Agent, TrainConfig};
use crate::envs::{BoxSpace, Env};
use crate::policy::AgentPolicy;
use crate::rollout::{run_episode, StepView};

use super::seeds::{eval_episode_seed, evaluation_seed};

/// The results of evaluating a policy over some episodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    /// Each episode's return.
    pub returns: Vec<f64>,
    /// Each episode's length.
    pub lengths: Vec<usize>,
    /// Mean over episodes of each reward term's episode total.
    pub term_means: Vec<(&'static str, f64)>,
    /// Episodes ended by a physics blow-up.
    pub unstable_episodes: usize,
    /// Episodes ended before the time limit: in a terminal state (a fall, on the walkers) or by a
    /// physics blow-up.
    pub falls: usize,
    /// Share of action components with |a| >= SATURATED over all steps.
    pub saturation: f64,
}

/// An action component this close to its bound (normalised to [-1, 1]) counts as saturated.
pub(crate) const SATURATED: f64 = 0.99;

/// How many components of `action` (in the env's units) sit at their bounds: |a| >= SATURATED
/// once normalised to [-1, 1] (Humanoid's torques span ±0.4, Minitaur's angles their own range).
pub(crate) fn saturated_components(space: &BoxSpace, action: &[f64]) -> usize {
    action
        .iter()
        .zip(space.low.iter().zip(&space.high))
        .filter(|&(&a, (&l, &h))| (2.0 * (a - l) / (h - l) - 1.0).abs() >= SATURATED)
        .count()
}

impl Evaluation {
    /// Mean return.
    pub fn mean(&self) -> f64 {
        self.returns.iter().sum::<f64>() / self.returns.len() as f64
    }
    /// Population standard deviation (as numpy's default).
    pub fn std(&self) -> f64 {
        let m = self.mean();
        (self.returns.iter().map(|r| (r - m).powi(2)).sum::<f64>() / self.returns.len() as f64).sqrt()
    }
}

/// Runs the run's first `episodes` evaluation episodes (the fixed starts) through
/// `rollout::run_episode`, the path `eval`, recordings and reports take too.
pub fn evaluate(agent: &dyn Agent, env: &mut dyn Env, episodes: usize, run_seed: u64) -> Result<Evaluation> {
    evaluate_with(agent, env, episodes, |i| eval_episode_seed(run_seed, i))
}

/// The evaluation a run makes at `step` under its `eval_starts`.
pub fn evaluate_at(
    agent: &dyn Agent,
    env: &mut dyn Env,
    train: &TrainConfig,
    run_seed: u64,
    step: u64,
) -> Result<Evaluation> {
    evaluate_with(agent, env, train.eval_episodes, |i| evaluation_seed(train.eval_starts, run_seed, step, i))
}

/// `episodes` episodes, episode `i` reset with `seed_of(i)`.
pub fn evaluate_with(
    agent: &dyn Agent,
    env: &mut dyn Env,
    episodes: usize,
    seed_of: impl Fn(u64) -> u64,
) -> Result<Evaluation> {
    let terms = env.spec().reward_terms.clone();
    let mut eval = Evaluation {
        returns: Vec::with_capacity(episodes),
        lengths: Vec::with_capacity(episodes),
        term_means: terms.iter().map(|&t| (t, 0.0)).collect(),
        unstable_episodes: 0,
        falls: 0,
        saturation: 0.0,
    };
    let (mut components, mut saturated) = (0usize, 0usize);
    let mut policy = AgentPolicy { agent, label: agent.algo().name().to_string() };
    for i in 0..episodes {
        let seed = seed_of(i as u64);
        let mut count = |v: &StepView| {
            components += v.action.len();
            saturated += saturated_components(&v.env.spec().action_space, v.action);
            Ok(())
        };
        let s = run_episode(env, &mut policy, i, Some(seed), &mut count)?;
        for ((_, mean), (_, total)) in eval.term_means.iter_mut().zip(&s.term_totals) {
            *mean += total / episodes as f64;
        }
        eval.unstable_episodes += s.unstable as usize;
        eval.falls += s.fell() as usize;
        eval.returns.push(s.episode_return);
        eval.lengths.push(s.length);
        super::fault::reach(super::fault::Point::Evaluation);
    }
    eval.saturation = saturated as f64 / components.max(1) as f64;
    Ok(eval)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn saturation_is_measured_against_each_components_bounds() {
        let space = BoxSpace { low: vec![-0.4, -0.4, 0.0], high: vec![0.4, 0.4, 2.0] };
        // -0.4 and 1.99 are at their bounds; 0.39 is 0.975 of the way (not saturated); 0.0 of
        // [0, 2] is at its lower bound.
        assert_eq!(saturated_components(&space, &[-0.4, 0.39, 1.99]), 2);
        assert_eq!(saturated_components(&space, &[0.0, 0.0, 1.0]), 0);
        assert_eq!(saturated_components(&space, &[0.4, -0.3999, 0.0]), 3);
    }
}
