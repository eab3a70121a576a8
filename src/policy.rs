//! Policies that drive an environment: the interface every controller and agent implements,
//! and the simple ones (zero, uniform random, replay of recorded actions).
use anyhow::{bail, Context, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::envs::{BoxSpace, Env};

/// Chooses an action from the environment's current observation (and, for model-based
/// controllers, its physics state).
pub trait Policy {
    /// A label for tables and recordings.
    fn name(&self) -> String;
    /// Called after every reset, with the episode index.
    fn begin_episode(&mut self, _episode: usize) {}
    /// The action for the current state.
    fn act(&mut self, env: &dyn Env, observation: &[f64]) -> Result<Vec<f64>>;
    /// True when the policy has nothing more to say this episode (a replay ran out of actions).
    fn exhausted(&self) -> bool {
        false
    }
    /// Counters a policy keeps about itself (e.g. failed QP solves), since the last episode start.
    fn diagnostics(&self) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// The angle (rad, positive left) from the body's heading to the direction the policy walks
    /// in, for a gait that walks crabwise on purpose (Ant's rowing): speeds are measured along
    /// the body's heading turned by it.
    fn heading_offset(&self) -> f64 {
        0.0
    }
    /// What the policy decided on its latest `act`, for recorders (gait phases, foot targets).
    fn telemetry(&self) -> Telemetry {
        Telemetry::default()
    }
}

/// Internal signals of a controller, named: scalar series and world-frame points.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Telemetry {
    /// Named scalar signals.
    pub scalars: Vec<(String, f64)>,
    /// Named points, world coordinates.
    pub points: Vec<(String, [f64; 3])>,
}

/// Always the zero action.
pub struct ZeroPolicy;

impl Policy for ZeroPolicy {
    fn name(&self) -> String {
        "zero".into()
    }
    fn act(&mut self, env: &dyn Env, _: &[f64]) -> Result<Vec<f64>> {
        Ok(vec![0.0; env.spec().action_space.dim()])
    }
}

/// Uniform samples from the action space, from its own seeded stream.
pub struct RandomPolicy {
    rng: ChaCha8Rng,
}

impl RandomPolicy {
    /// Uniform random actions from their own seeded stream.
    pub fn new(seed: u64) -> RandomPolicy {
        RandomPolicy { rng: ChaCha8Rng::seed_from_u64(seed) }
    }
    /// One action drawn uniformly within `space` (its bounds must be finite).
    pub fn sample(&mut self, space: &BoxSpace) -> Vec<f64> {
        space.low.iter().zip(&space.high).map(|(&l, &h)| self.rng.random_range(l..=h)).collect()
    }
}

impl Policy for RandomPolicy {
    fn name(&self) -> String {
        "random".into()
    }
    fn act(&mut self, env: &dyn Env, _: &[f64]) -> Result<Vec<f64>> {
        Ok(self.sample(&env.spec().action_space))
    }
}

/// Replays actions read from a CSV file: either a `locobench rollout` output (columns
/// `episode` and `action_0..`) or plain rows of numbers, one action per row, reused for every
/// episode.
pub struct ReplayPolicy {
    episodes: Vec<Vec<Vec<f64>>>,
    current: usize,
    cursor: usize,
    path: String,
}

impl ReplayPolicy {
    /// Replays the actions of a CSV written by `locobench rollout` (`a0`, `a1`, ... columns).
    pub fn from_csv(path: &str) -> Result<ReplayPolicy> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading action file {path}"))?;
        let mut lines = text.lines().filter(|l| !l.trim().is_empty()).peekable();
        let first = lines.peek().copied().unwrap_or("");
        let header: Vec<&str> = first.split(',').map(str::trim).collect();
        let is_header = header.iter().any(|c| c.parse::<f64>().is_err());
        let mut episodes: Vec<Vec<Vec<f64>>> = Vec::new();
        if is_header {
            lines.next();
            let action_cols: Vec<usize> =
                header.iter().enumerate().filter(|(_, c)| c.starts_with("action_")).map(|(i, _)| i).collect();
            if action_cols.is_empty() {
                bail!("{path}: header has no action_0, action_1, ... columns");
            }
            let episode_col = header.iter().position(|c| *c == "episode");
            for (n, line) in lines.enumerate() {
                let fields: Vec<&str> = line.split(',').map(str::trim).collect();
                let episode = match episode_col {
                    Some(c) => fields
                        .get(c)
                        .and_then(|v| v.parse::<usize>().ok())
                        .with_context(|| format!("{path}: line {}: bad episode number", n + 2))?,
                    None => 0,
                };
                let action = action_cols
                    .iter()
                    .map(|&c| parse_number(fields.get(c).copied(), path, n + 2))
                    .collect::<Result<Vec<f64>>>()?;
                if episodes.len() <= episode {
                    episodes.resize(episode + 1, Vec::new());
                }
                episodes[episode].push(action);
            }
        } else {
            let rows = lines
                .enumerate()
                .map(|(n, line)| line.split(',').map(|v| parse_number(Some(v.trim()), path, n + 1)).collect())
                .collect::<Result<Vec<Vec<f64>>>>()?;
            episodes.push(rows);
        }
        if episodes.iter().all(|e| e.is_empty()) {
            bail!("{path}: no actions found");
        }
        Ok(ReplayPolicy { episodes, current: 0, cursor: 0, path: path.to_string() })
    }

    fn episode_actions(&self) -> &Vec<Vec<f64>> {
        // A plain file (one episode) is reused for every episode.
        &self.episodes[self.current.min(self.episodes.len() - 1)]
    }
}

fn parse_number(field: Option<&str>, path: &str, line: usize) -> Result<f64> {
    let text = field.with_context(|| format!("{path}: line {line}: missing value"))?;
    text.parse::<f64>().with_context(|| format!("{path}: line {line}: '{text}' is not a number"))
}

impl Policy for ReplayPolicy {
    fn name(&self) -> String {
        format!("actions:{}", self.path)
    }
    fn begin_episode(&mut self, episode: usize) {
        self.current = episode;
        self.cursor = 0;
    }
    fn exhausted(&self) -> bool {
        self.cursor >= self.episode_actions().len()
    }
    fn act(&mut self, env: &dyn Env, _: &[f64]) -> Result<Vec<f64>> {
        let actions = self.episode_actions();
        let Some(a) = actions.get(self.cursor) else {
            bail!("{}: no recorded action for step {} of episode {}", self.path, self.cursor, self.current);
        };
        let expected = env.spec().action_space.dim();
        if a.len() != expected {
            bail!("{}: actions have {} entries, {} expects {expected}", self.path, a.len(), env.spec().name);
        }
        let a = a.clone();
        self.cursor += 1;
        Ok(a)
    }
}

/// A trained agent acting deterministically (its evaluation action), as a [`Policy`].
pub struct AgentPolicy<'a> {
    /// The agent.
    pub agent: &'a dyn crate::agents::Agent,
    /// Its label in tables.
    pub label: String,
}

impl Policy for AgentPolicy<'_> {
    fn name(&self) -> String {
        self.label.clone()
    }
    fn act(&mut self, env: &dyn Env, observation: &[f64]) -> Result<Vec<f64>> {
        let obs: Vec<f32> = observation.iter().map(|&v| v as f32).collect();
        let normalised = self.agent.act(&obs)?;
        Ok(to_env_action(env, &normalised))
    }
}

/// Maps a normalised action in [-1, 1] to the environment's bounds.
pub(crate) fn to_env_action(env: &dyn Env, normalised: &[f32]) -> Vec<f64> {
    to_space(&env.spec().action_space, normalised)
}

/// Maps a normalised action in [-1, 1] to a space's bounds.
pub(crate) fn to_space(s: &BoxSpace, normalised: &[f32]) -> Vec<f64> {
    normalised
        .iter()
        .zip(s.low.iter().zip(&s.high))
        .map(|(&a, (&l, &h))| l + (a as f64 + 1.0) * 0.5 * (h - l))
        .collect()
}
