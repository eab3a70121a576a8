//! The evaluation protocol: K deterministic episodes on a separate environment instance, with
//! fixed episode seeds so that every evaluation of a run sees the same starts.
use anyhow::Result;

use crate::agents::Agent;
use crate::envs::Env;

use super::seeds::eval_episode_seed;

#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    pub returns: Vec<f64>,
    pub lengths: Vec<usize>,
    /// Mean over episodes of each reward term's episode total.
    pub term_means: Vec<(&'static str, f64)>,
    /// Episodes ended by a physics blow-up.
    pub unstable_episodes: usize,
}

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

/// Maps a normalised action in [-1, 1] to the environment's bounds.
pub fn to_env_action(env: &dyn Env, normalised: &[f32]) -> Vec<f64> {
    let s = &env.spec().action_space;
    normalised
        .iter()
        .zip(s.low.iter().zip(&s.high))
        .map(|(&a, (&l, &h))| l + (a as f64 + 1.0) * 0.5 * (h - l))
        .collect()
}

pub fn evaluate(agent: &dyn Agent, env: &mut dyn Env, episodes: usize, run_seed: u64) -> Result<Evaluation> {
    let _runtime = crate::runtime::Runtime::enter(1);
    let terms = env.spec().reward_terms.clone();
    let mut eval = Evaluation {
        returns: Vec::with_capacity(episodes),
        lengths: Vec::with_capacity(episodes),
        term_means: terms.iter().map(|&t| (t, 0.0)).collect(),
        unstable_episodes: 0,
    };
    for i in 0..episodes {
        let (mut obs, _) = env.reset(Some(eval_episode_seed(run_seed, i as u64)))?;
        let (mut ret, mut len) = (0.0, 0);
        loop {
            let obs32: Vec<f32> = obs.iter().map(|&v| v as f32).collect();
            let action = to_env_action(env, &agent.act(&obs32)?);
            let s = env.step(&action)?;
            ret += s.reward;
            len += 1;
            for ((_, total), (_, v)) in eval.term_means.iter_mut().zip(&s.info.reward_terms) {
                *total += v / episodes as f64;
            }
            if s.done() {
                eval.unstable_episodes += s.info.unstable as usize;
                break;
            }
            obs = s.observation;
        }
        eval.returns.push(ret);
        eval.lengths.push(len);
    }
    Ok(eval)
}
