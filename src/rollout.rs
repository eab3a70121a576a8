//! Running a policy in an environment for whole episodes.
use anyhow::Result;

use crate::envs::{Env, Step};
use crate::policy::Policy;

/// Totals of one episode.
#[derive(Debug, Clone, PartialEq)]
pub struct EpisodeSummary {
    /// Index of the episode, from 0.
    pub episode: usize,
    /// Sum of rewards.
    pub episode_return: f64,
    /// Steps taken.
    pub length: usize,
    /// Ended in a terminal state.
    pub terminated: bool,
    /// Cut short by the time limit or instability.
    pub truncated: bool,
    /// Ended because the physics became unstable.
    pub unstable: bool,
    /// Each reward term summed over the episode.
    pub term_totals: Vec<(&'static str, f64)>,
}

impl EpisodeSummary {
    /// Ended before its time limit: a fall (a terminal state) or unstable physics.
    pub fn fell(&self) -> bool {
        self.terminated || self.unstable
    }

    /// Why the episode ended, in words.
    pub fn end_reason(&self) -> &'static str {
        if self.unstable {
            "physics unstable"
        } else if self.terminated {
            "terminated"
        } else if self.truncated {
            "truncated"
        } else {
            "actions ran out"
        }
    }
}

/// Everything an observer may look at after one step.
pub struct StepView<'a> {
    /// Index of the episode, from 0.
    pub episode: usize,
    /// Index of the step within the episode, from 0.
    pub t: usize,
    /// The action the policy chose.
    pub action: &'a [f64],
    /// What the environment returned.
    pub step: &'a Step,
    /// The environment after the step.
    pub env: &'a dyn Env,
    /// The policy that acted.
    pub policy: &'a dyn Policy,
}

/// Watches a rollout: recorders, CSV writers, metric accumulators. A closure taking a
/// [`StepView`] is an observer of steps only.
pub trait Observer {
    /// After every reset, with the environment in its initial state.
    fn reset(&mut self, _episode: usize, _env: &dyn Env) -> Result<()> {
        Ok(())
    }
    /// After every step.
    fn step(&mut self, view: &StepView) -> Result<()>;
    /// After every episode, with its totals.
    fn end(&mut self, _summary: &EpisodeSummary) -> Result<()> {
        Ok(())
    }
}

impl<F: FnMut(&StepView) -> Result<()>> Observer for F {
    fn step(&mut self, view: &StepView) -> Result<()> {
        self(view)
    }
}

/// Runs `episodes` episodes. The first reset uses `seed`; later ones continue the environment's
/// random stream, so the whole run is a function of the seed.
pub fn run_episodes(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    episodes: usize,
    seed: u64,
    observer: &mut dyn Observer,
) -> Result<Vec<EpisodeSummary>> {
    (0..episodes)
        .map(|episode| {
            let reset_seed = if episode == 0 { Some(seed) } else { None };
            run_episode(env, policy, episode, reset_seed, observer)
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
    observer: &mut dyn Observer,
) -> Result<EpisodeSummary> {
    let _runtime = crate::runtime::Runtime::enter(1);
    let (mut obs, _) = env.reset(reset_seed)?;
    policy.begin_episode(episode);
    observer.reset(episode, &*env)?;
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
        observer.step(&StepView {
            episode,
            t: summary.length,
            action: &action,
            step: &step,
            env: &*env,
            policy: &*policy,
        })?;
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
    observer.end(&summary)?;
    Ok(summary)
}
