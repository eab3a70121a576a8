//! What a MuJoCo task adds to the physics, in the spirit of dm_control's physics / task /
//! environment split: its spaces, its observation, its signed reward terms and when it ends.
//! [`super::mujoco_env::MujocoEnv`] carries everything else (reset noise, action checks,
//! frame skip, instability detection, the time limit) once for every task.
use super::simulation::{Simulation, VelocityNoise};
use super::world::World;
use super::{BoxSpace, EnvError};
use crate::mujoco::Model;

/// The settings every MuJoCo task's options carry, read from them by name once.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
pub struct Timing {
    /// Physics steps per `step`.
    pub frame_skip: usize,
    /// Steps before an episode is truncated.
    pub max_episode_steps: usize,
    /// qpos += U(-s, s) at reset; qvel gets the task's `VELOCITY_NOISE` of the same scale.
    pub reset_noise_scale: f64,
}

/// What a task reports after the physics of a step ran.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TaskStep {
    /// Signed contributions (costs negative), in the order of [`Task::REWARD_TERMS`].
    pub reward_terms: Vec<(&'static str, f64)>,
    /// Diagnostics (positions, velocities) reported in `Info::metrics`.
    pub metrics: Vec<(&'static str, f64)>,
    /// The episode reached a terminal state.
    pub terminated: bool,
}

/// What one MuJoCo environment adds to [`MujocoEnv`]: model, observation, action space and reward.
pub trait Task: Send + Sized + 'static {
    /// Its options (every field defaulted, `#[serde(default, deny_unknown_fields)]`).
    type Options: serde::de::DeserializeOwned + serde::Serialize;
    /// What the task measures before the physics runs (e.g. the x position), to compare after.
    type Before;
    /// The registered name.
    const NAME: &'static str;
    /// The MJCF model, as text.
    const MODEL_XML: &'static str;
    /// The reward terms' names, in the order `TaskStep::reward_terms` lists them.
    const REWARD_TERMS: &'static [&'static str];
    /// How reset noise is drawn for velocities.
    const VELOCITY_NOISE: VelocityNoise;

    /// Looks up what the task needs in the model (body ids, ...) and checks what is its own in
    /// the options (the checks every task shares ran by name before: `options::check_by_name`).
    fn new(options: Self::Options, model: &Model) -> Result<Self, EnvError>;
    /// The options it was built with.
    fn options(&self) -> &Self::Options;
    /// Length of the observation.
    fn observation_dim(&self, model: &Model) -> usize;
    /// The action bounds: by default each actuator's `ctrlrange` in the model, as Gymnasium's
    /// MuJoCo envs take them (`MujocoEnv._set_action_space`, gymnasium/envs/mujoco/mujoco_env.py).
    fn action_space(&self, model: &Model) -> BoxSpace {
        let ctrl = model.actuator_ctrlrange();
        let nu = model.nu();
        BoxSpace::new((0..nu).map(|i| ctrl[2 * i]).collect(), (0..nu).map(|i| ctrl[2 * i + 1]).collect())
    }
    /// Appends the current observation to `out`.
    fn observe(&self, sim: &Simulation, out: &mut Vec<f64>);
    /// Diagnostics at reset (positions).
    fn reset_metrics(&self, _sim: &Simulation) -> Vec<(&'static str, f64)> {
        Vec::new()
    }
    /// The world perturbations the task takes (`world::World`, read from its options) and the
    /// body that carries a payload; None (the default) for a task without them.
    fn world(&self) -> Option<(&World, usize)> {
        None
    }
    /// What the reward needs from the state before the physics runs (e.g. the x position).
    fn before(&self, sim: &Simulation) -> Self::Before;
    /// Reward terms, metrics and termination once the physics ran with `action` (clipped to the
    /// action space). May compute derived quantities first (e.g. contact forces).
    fn after(&self, sim: &mut Simulation, before: &Self::Before, action: &[f64], dt: f64)
        -> Result<TaskStep, EnvError>;
}

/// `weight * sum(a^2)`, the control cost every task uses.
pub(crate) fn quadratic_cost(weight: f64, values: &[f64]) -> f64 {
    weight * values.iter().map(|a| a * a).sum::<f64>()
}

/// Positions of a free-floating robot at reset (x, y of qpos).
pub(crate) fn planar_position(sim: &Simulation) -> Vec<(&'static str, f64)> {
    let q = sim.data.qpos();
    vec![("x_position", q[0]), ("y_position", q[1])]
}

/// Positions, planar velocity and torso height of a free-floating robot after a step.
pub(crate) fn locomotion_metrics(sim: &Simulation, velocity: [f64; 2]) -> Vec<(&'static str, f64)> {
    let q = sim.data.qpos();
    vec![
        ("x_position", q[0]),
        ("y_position", q[1]),
        ("x_velocity", velocity[0]),
        ("y_velocity", velocity[1]),
        ("torso_height", q[2]),
    ]
}

/// The weights of Gymnasium's legged rewards (Ant, Humanoid), read from the options by name.
#[derive(Debug, Clone, serde::Deserialize)]
pub(crate) struct LeggedWeights {
    #[serde(rename = "forward_reward_weight")]
    pub forward: f64,
    #[serde(rename = "healthy_reward")]
    pub healthy: f64,
    #[serde(rename = "ctrl_cost_weight")]
    pub ctrl: f64,
    pub terminate_when_unhealthy: bool,
}

/// Ant's and Humanoid's step: forward * vx + healthy (while healthy) - ctrl * |a|^2 - contact
/// cost, terminated when unhealthy if asked.
pub(crate) fn legged_step(
    w: &LeggedWeights,
    x_velocity: f64,
    healthy: bool,
    action: &[f64],
    contact_cost: f64,
    metrics: Vec<(&'static str, f64)>,
) -> TaskStep {
    TaskStep {
        reward_terms: vec![
            ("forward", w.forward * x_velocity),
            ("healthy", if healthy { w.healthy } else { 0.0 }),
            ("ctrl_cost", -quadratic_cost(w.ctrl, action)),
            ("contact_cost", -contact_cost),
        ],
        metrics,
        terminated: !healthy && w.terminate_when_unhealthy,
    }
}
