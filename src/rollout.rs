//! Running a policy in an environment for whole episodes.
use anyhow::Result;

use crate::envs::{Env, Step};
use crate::policy::Policy;

/// Totals of one episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeSummary {
    pub episode: usize,
    pub episode_return: f64,
    pub length: usize,
    pub terminated: bool,
    pub truncated: bool,
    pub unstable: bool,
    /// Each reward term summed over the episode.
    pub term_totals: Vec<(&'static str, f64)>,
}

/// Runs `episodes` episodes. The first reset uses `seed`; later ones continue the environment's
/// random stream, so the whole run is a function of the seed. `on_step` sees every step.
pub fn run_episodes(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    episodes: usize,
    seed: u64,
    mut on_step: impl FnMut(usize, usize, &[f64], &Step) -> Result<()>,
) -> Result<Vec<EpisodeSummary>> {
    (0..episodes)
        .map(|episode| {
            let reset_seed = if episode == 0 { Some(seed) } else { None };
            run_episode(env, policy, episode, reset_seed, |t, action, step| on_step(episode, t, action, step))
        })
        .collect()
}

/// Runs one episode, numbered `episode`, resetting with `reset_seed` (None continues the
/// environment's random stream).
pub fn run_episode(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    episode: usize,
    reset_seed: Option<u64>,
    mut on_step: impl FnMut(usize, &[f64], &Step) -> Result<()>,
) -> Result<EpisodeSummary> {
    let (mut obs, _) = env.reset(reset_seed)?;
    policy.begin_episode(episode);
    let mut summary = EpisodeSummary {
        episode,
        episode_return: 0.0,
        length: 0,
        terminated: false,
        truncated: false,
        unstable: false,
        term_totals: env.spec().reward_terms.iter().map(|&n| (n, 0.0)).collect(),
    };
    while !policy.exhausted() {
        let action = policy.act(&*env, &obs)?;
        let step = env.step(&action)?;
        on_step(summary.length, &action, &step)?;
        summary.length += 1;
        summary.episode_return += step.reward;
        for ((_, total), (_, v)) in summary.term_totals.iter_mut().zip(&step.info.reward_terms) {
            *total += v;
        }
        summary.terminated = step.terminated;
        summary.truncated = step.truncated;
        summary.unstable = step.info.unstable;
        if step.done() {
            break;
        }
        obs = step.observation;
    }
    Ok(summary)
}
