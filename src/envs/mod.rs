//! Environments with Gymnasium semantics: `reset(seed)` then `step(action)` until `terminated`
//! or `truncated`. Every reward term is reported by name in [`Info`].
//!
//! Action policy: entries outside the action space are clipped to its bounds before they reach
//! the physics or any cost term, and the number of clipped entries is counted in
//! [`Info::clipped_actions`]. Wrong length, NaN or infinite entries are errors.
//!
//! Physics blow-ups: MuJoCo silently resets a state whose accelerations become NaN. The
//! environments watch MuJoCo's instability counters and non-finite state; when either fires the
//! step returns the last good observation, zero reward, `truncated = true` and
//! [`Info::unstable`] set. Learners must not store that transition (it is not a real one).
mod ant;
pub mod command;
mod error;
mod half_cheetah;
mod hopper;
mod humanoid;
mod inverted_pendulum;
pub mod minitaur;
mod mujoco_env;
pub mod notch;
mod options;
mod planar_walker;
pub mod push;
mod registry;
mod simulation;
mod task;
mod vector;
mod walker2d;
pub mod world;

pub use ant::{Ant, AntOptions};
pub use error::EnvError;
pub use half_cheetah::{HalfCheetah, HalfCheetahOptions};
pub use hopper::{Hopper, HopperOptions};
pub use humanoid::{Humanoid, HumanoidOptions};
pub use inverted_pendulum::{InvertedPendulum, InvertedPendulumOptions};
pub use minitaur::{Minitaur, MinitaurOptions};
pub use mujoco_env::MujocoEnv;
pub use registry::{
    command_base, env_names, lookup, make, model_xml, parse_overrides, reward_weight_option, EnvConfig, EnvEntry,
    Registered, ENVS,
};
pub use simulation::{Simulation, VelocityNoise};
pub use task::{Task, TaskStep, Timing};
pub use vector::{episode_seed, EpisodeSeeds, VecEnv, VecEnvSnapshot, VecStep};
pub use walker2d::{Walker2d, Walker2dOptions};

use crate::mujoco::Data;

/// A box-shaped space: one `[low, high]` interval per dimension (bounds may be infinite).
#[derive(Debug, Clone, PartialEq)]
pub struct BoxSpace {
    /// Lower bound of each dimension.
    pub low: Vec<f64>,
    /// Upper bound of each dimension.
    pub high: Vec<f64>,
}

impl BoxSpace {
    /// A space from its bounds; panics when their lengths differ.
    pub fn new(low: Vec<f64>, high: Vec<f64>) -> BoxSpace {
        assert_eq!(low.len(), high.len());
        BoxSpace { low, high }
    }
    /// A space of `dim` dimensions, each `[low, high]`.
    pub fn uniform(dim: usize, low: f64, high: f64) -> BoxSpace {
        BoxSpace { low: vec![low; dim], high: vec![high; dim] }
    }
    pub(crate) fn unbounded(dim: usize) -> BoxSpace {
        Self::uniform(dim, f64::NEG_INFINITY, f64::INFINITY)
    }
    /// Number of dimensions.
    pub fn dim(&self) -> usize {
        self.low.len()
    }
    /// Whether `x` has the right length and lies within the bounds.
    pub fn contains(&self, x: &[f64]) -> bool {
        x.len() == self.dim() && x.iter().zip(&self.low).zip(&self.high).all(|((v, l), h)| v >= l && v <= h)
    }
}

/// What an environment is: its name, spaces, control period and episode length.
#[derive(Debug, Clone)]
pub struct EnvSpec {
    /// The registered name (`minitaur`, `ant`, ...).
    pub name: &'static str,
    /// Observation bounds (unbounded for the MuJoCo tasks).
    pub observation_space: BoxSpace,
    /// Action bounds; actions outside them are clipped.
    pub action_space: BoxSpace,
    /// Seconds of simulated time per `step`.
    pub dt: f64,
    /// Steps before an episode is truncated.
    pub max_episode_steps: usize,
    /// Names of the reward terms, in the order `Info::reward_terms` lists them.
    pub reward_terms: Vec<&'static str>,
}

/// Per-step details besides the reward.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Info {
    /// Each term's signed contribution to the reward (costs are negative); they sum to the reward.
    pub reward_terms: Vec<(&'static str, f64)>,
    /// Diagnostics such as positions and velocities (`x_position`, `x_velocity`, ...).
    pub metrics: Vec<(&'static str, f64)>,
    /// Action entries that were outside the action space and were clipped.
    pub clipped_actions: usize,
    /// The physics became unstable during this step (see the module docs).
    pub unstable: bool,
    /// MuJoCo warnings raised during this step.
    pub warnings: Vec<String>,
}

impl Info {
    /// The value of reward term `name` in this step, if the env has it.
    pub fn term(&self, name: &str) -> Option<f64> {
        self.reward_terms.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
    }
    /// The value of metric `name` in this step, if the env reports it.
    pub fn metric(&self, name: &str) -> Option<f64> {
        self.metrics.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
    }
}

/// The result of one `step`.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// The observation after the step.
    pub observation: Vec<f64>,
    /// The reward: the sum of `info.reward_terms`.
    pub reward: f64,
    /// The episode reached a terminal state (e.g. the robot fell); do not bootstrap from it.
    pub terminated: bool,
    /// The episode was cut short (time limit, instability); the state is not terminal.
    pub truncated: bool,
    /// Reward terms and diagnostics.
    pub info: Info,
}

impl Step {
    /// Whether the episode ended (terminated or truncated).
    pub fn done(&self) -> bool {
        self.terminated || self.truncated
    }
}

/// An environment with Gymnasium's reset/step semantics.
pub trait Env: Send {
    /// Its name, spaces, control period and episode length.
    fn spec(&self) -> &EnvSpec;
    /// Starts an episode. `Some(seed)` reseeds the environment's random stream; `None` continues
    /// it (an environment never seeded behaves as if seeded with 0).
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError>;
    /// Advances one control step; errors on a wrong length, a non-finite entry or a finished episode.
    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError>;
    /// The simulation state, for recorders and model-based controllers.
    fn data(&self) -> &Data;
    /// The simulation state, to perturb it between steps (applied forces, see `evaluation::push`).
    fn data_mut(&mut self) -> &mut Data;
    /// Overwrites positions and velocities mid-episode (Gymnasium's `set_state`), e.g. to start
    /// from a recorded state. Lengths are checked; the values are the caller's responsibility.
    fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), EnvError>;
    /// On a velocity-command task (`envs::command`): the command in force, (forward speed m/s,
    /// yaw rate rad/s). None on every other env.
    fn command(&self) -> Option<[f64; 2]> {
        None
    }
    /// On a velocity-command task: the direction it calls forward, in radians counter-clockwise
    /// from the commanded body's x axis (its `forward_angle` option). 0 on every other env.
    fn forward_angle(&self) -> f64 {
        0.0
    }
    /// On a velocity-command task: holds this command from the next step until the next reset
    /// (a joystick). Every other env refuses.
    fn set_command(&mut self, speed: f64, yaw_rate: f64) -> Result<(), EnvError> {
        let _ = (speed, yaw_rate);
        Err(EnvError::InvalidOption {
            env: self.spec().name.to_string(),
            message: "this env takes no velocity command; the command tasks are minitaur-command and ant-command"
                .into(),
        })
    }
}

/// Refuses an action of the wrong length or with a NaN or infinite entry.
pub(crate) fn check_action(space: &BoxSpace, action: &[f64]) -> Result<(), EnvError> {
    if action.len() != space.dim() {
        return Err(EnvError::ActionLength { expected: space.dim(), got: action.len() });
    }
    if let Some(index) = action.iter().position(|a| !a.is_finite()) {
        return Err(EnvError::NonFiniteAction { index, value: action[index] });
    }
    Ok(())
}

/// Checks an action against the space and returns a clipped copy and the number clipped.
pub(crate) fn clip_action(space: &BoxSpace, action: &[f64]) -> Result<(Vec<f64>, usize), EnvError> {
    check_action(space, action)?;
    let mut clipped = 0;
    let out = action
        .iter()
        .zip(space.low.iter().zip(&space.high))
        .map(|(&a, (&l, &h))| {
            if a < l || a > h {
                clipped += 1;
            }
            a.clamp(l, h)
        })
        .collect();
    Ok((out, clipped))
}

/// Counts steps and refuses to step a finished episode.
#[derive(Debug, Clone, Default)]
pub(crate) struct EpisodeClock {
    pub steps: usize,
    started: bool,
    finished: bool,
}

impl EpisodeClock {
    pub fn start(&mut self) {
        *self = EpisodeClock { steps: 0, started: true, finished: false };
    }
    pub(crate) fn check_can_step(&self) -> Result<(), EnvError> {
        if !self.started {
            Err(EnvError::NotReset)
        } else if self.finished {
            Err(EnvError::EpisodeOver)
        } else {
            Ok(())
        }
    }
    /// Advances one step and returns whether the time limit truncates the episode.
    pub fn tick(&mut self, max_steps: usize) -> bool {
        self.steps += 1;
        self.steps >= max_steps
    }
    pub(crate) fn finish_if(&mut self, done: bool) {
        self.finished |= done;
    }
}
