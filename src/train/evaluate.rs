//! The evaluation protocol: K deterministic episodes on a separate environment instance, with
//! fixed episode seeds so that every evaluation of a run sees the same starts.
use anyhow::Result;

use crate::agents::Agent;
use crate::envs::Env;
use crate::policy::AgentPolicy;
use crate::rollout::{run_episode, StepView};

use super::seeds::eval_episode_seed;

#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    pub returns: Vec<f64>,
    pub lengths: Vec<usize>,
    /// Mean over episodes of each reward term's episode total.
    pub term_means: Vec<(&'static str, f64)>,
    /// Episodes ended by a physics blow-up.
    pub unstable_episodes: usize,
    /// Share of action components with |a| >= SATURATED over all steps.
    pub saturation: f64,
}

/// An action component this close to the bound of [-1, 1] counts as saturated.
pub const SATURATED: f64 = 0.99;

impl Evaluation {
    pub fn mean(&self) -> f64 {
        self.returns.iter().sum::<f64>() / self.returns.len() as f64
    }
    /// Population standard deviation (as numpy's default).
    pub fn std(&self) -> f64 {
        let m = self.mean();
        (self.returns.iter().map(|r| (r - m).powi(2)).sum::<f64>() / self.returns.len() as f64).sqrt()
    }
}

/// Runs the protocol's episodes through `rollout::run_episode`, the path `eval`, recordings and
/// reports take too.
pub fn evaluate(agent: &dyn Agent, env: &mut dyn Env, episodes: usize, run_seed: u64) -> Result<Evaluation> {
    let terms = env.spec().reward_terms.clone();
    let mut eval = Evaluation {
        returns: Vec::with_capacity(episodes),
        lengths: Vec::with_capacity(episodes),
        term_means: terms.iter().map(|&t| (t, 0.0)).collect(),
        unstable_episodes: 0,
        saturation: 0.0,
    };
    let (mut components, mut saturated) = (0usize, 0usize);
    let mut policy = AgentPolicy { agent, label: agent.algo().name().to_string() };
    for i in 0..episodes {
        let seed = eval_episode_seed(run_seed, i as u64);
        let mut count = |v: &StepView| {
            components += v.action.len();
            saturated += v.action.iter().filter(|a| a.abs() >= SATURATED).count();
            Ok(())
        };
        let s = run_episode(env, &mut policy, i, Some(seed), &mut count)?;
        for ((_, mean), (_, total)) in eval.term_means.iter_mut().zip(&s.term_totals) {
            *mean += total / episodes as f64;
        }
        eval.unstable_episodes += s.unstable as usize;
        eval.returns.push(s.episode_return);
        eval.lengths.push(s.length);
    }
    eval.saturation = saturated as f64 / components.max(1) as f64;
    Ok(eval)
}
