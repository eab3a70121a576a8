//! What Gymnasium's planar walkers (Hopper, Walker2d) share, once: observation qpos[1:] +
//! clip(qvel, ±10), reward forward * dx/dt + healthy (while healthy) - ctrl * |a|^2, reset noise
//! U(-s, s) on qpos and qvel. Each walker adds its model, its options and its health rule.
use serde::de::DeserializeOwned;
use serde::Serialize;

use super::options::read_by_name;
use super::simulation::{Simulation, VelocityNoise};
use super::task::{quadratic_cost, Task, TaskStep};
use super::EnvError;
use crate::mujoco::Model;

/// The reward weights and settings every planar walker's options carry, read from them by name.
#[derive(Debug, Clone, serde::Deserialize)]
pub(crate) struct WalkerSettings {
    pub(crate) forward_reward_weight: f64,
    pub(crate) healthy_reward: f64,
    pub ctrl_cost_weight: f64,
    pub terminate_when_unhealthy: bool,
}

/// What one planar walker adds: its name, model, options and health rule.
pub trait WalkerRule: Send + 'static {
    type Options: DeserializeOwned + Serialize + Send;
    const NAME: &'static str;
    const MODEL_XML: &'static str;
    fn is_healthy(options: &Self::Options, sim: &Simulation) -> bool;
}

/// A planar walker as a task: `HopperTask = PlanarWalkerTask<HopperRule>`.
pub struct PlanarWalkerTask<R: WalkerRule> {
    opts: R::Options,
    /// Read from `opts` once, as the step needs them.
    settings: WalkerSettings,
}

impl<R: WalkerRule> Task for PlanarWalkerTask<R> {
    type Options = R::Options;
    type Before = f64;
    const NAME: &'static str = R::NAME;
    const MODEL_XML: &'static str = R::MODEL_XML;
    const REWARD_TERMS: &'static [&'static str] = &["forward", "healthy", "ctrl_cost"];
    const VELOCITY_NOISE: VelocityNoise = VelocityNoise::Uniform;

    fn new(opts: R::Options, _model: &Model) -> Result<Self, EnvError> {
        Ok(PlanarWalkerTask { settings: read_by_name(&opts), opts })
    }

    fn options(&self) -> &R::Options {
        &self.opts
    }

    fn observation_dim(&self, model: &Model) -> usize {
        model.nq() - 1 + model.nv()
    }

    fn observe(&self, sim: &Simulation, out: &mut Vec<f64>) {
        out.extend_from_slice(&sim.data.qpos()[1..]);
        out.extend(sim.data.qvel().iter().map(|v| v.clamp(-10.0, 10.0)));
    }

    fn reset_metrics(&self, sim: &Simulation) -> Vec<(&'static str, f64)> {
        vec![("x_position", sim.data.qpos()[0])]
    }

    fn before(&self, sim: &Simulation) -> f64 {
        sim.data.qpos()[0]
    }

    fn after(&self, sim: &mut Simulation, x_before: &f64, action: &[f64], dt: f64) -> Result<TaskStep, EnvError> {
        let s = &self.settings;
        let healthy = R::is_healthy(&self.opts, sim);
        let q = sim.data.qpos();
        let x_velocity = (q[0] - x_before) / dt;
        Ok(TaskStep {
            reward_terms: vec![
                ("forward", s.forward_reward_weight * x_velocity),
                ("healthy", if healthy { s.healthy_reward } else { 0.0 }),
                ("ctrl_cost", -quadratic_cost(s.ctrl_cost_weight, action)),
            ],
            metrics: vec![
                ("x_position", q[0]),
                ("x_velocity", x_velocity),
                ("torso_height", q[1]),
                ("torso_angle", q[2]),
            ],
            terminated: !healthy && s.terminate_when_unhealthy,
        })
    }
}

/// `lo < x < hi`, Gymnasium's open health intervals.
pub(crate) fn inside([lo, hi]: [f64; 2], x: f64) -> bool {
    lo < x && x < hi
}
