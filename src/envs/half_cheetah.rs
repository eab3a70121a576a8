//! HalfCheetah as Gymnasium v5 defines it: observation qpos[1:] + qvel (17), reward
//! forward_weight * dx/dt - ctrl_weight * |a|^2, never terminates, 1000-step episodes.
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::simulation::{Simulation, VelocityNoise};
use super::task::{quadratic_cost, Task, TaskStep};
use super::EnvError;
use crate::mujoco::Model;

pub(crate) const MODEL_XML: &str = include_str!("../../models/half_cheetah.xml");

/// Gymnasium HalfCheetah-v5's options, with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HalfCheetahOptions {
    /// Weight of the forward-velocity reward.
    pub forward_reward_weight: f64,
    /// Weight of the squared-action cost.
    pub ctrl_cost_weight: f64,
    /// qpos += U(-s, s), qvel = s * N(0, 1) at reset.
    pub reset_noise_scale: f64,
    /// Steps before the episode is truncated.
    pub max_episode_steps: usize,
    /// Physics steps per `step`.
    pub frame_skip: usize,
}

impl Default for HalfCheetahOptions {
    fn default() -> Self {
        HalfCheetahOptions {
            forward_reward_weight: 1.0,
            ctrl_cost_weight: 0.1,
            reset_noise_scale: 0.1,
            max_episode_steps: 1000,
            frame_skip: 5,
        }
    }
}

pub struct HalfCheetahTask {
    opts: HalfCheetahOptions,
}

/// Gymnasium's HalfCheetah-v5: a planar cheetah rewarded for running along x; it never terminates.
pub type HalfCheetah = MujocoEnv<HalfCheetahTask>;

impl Task for HalfCheetahTask {
    type Options = HalfCheetahOptions;
    type Before = f64;
    const NAME: &'static str = "half-cheetah";
    const MODEL_XML: &'static str = MODEL_XML;
    const VELOCITY_NOISE: VelocityNoise = VelocityNoise::Normal;
    const REWARD_TERMS: &'static [&'static str] = &["forward", "ctrl_cost"];

    fn new(opts: HalfCheetahOptions, _model: &Model) -> Result<Self, EnvError> {
        Ok(HalfCheetahTask { opts })
    }

    fn options(&self) -> &Self::Options {
        &self.opts
    }

    fn observation_dim(&self, model: &Model) -> usize {
        model.nq() - 1 + model.nv()
    }

    fn observe(&self, sim: &Simulation, out: &mut Vec<f64>) {
        out.extend_from_slice(&sim.data.qpos()[1..]);
        out.extend_from_slice(sim.data.qvel());
    }

    fn reset_metrics(&self, sim: &Simulation) -> Vec<(&'static str, f64)> {
        vec![("x_position", sim.data.qpos()[0])]
    }

    fn before(&self, sim: &Simulation) -> f64 {
        sim.data.qpos()[0]
    }

    fn after(&self, sim: &mut Simulation, x_before: &f64, action: &[f64], dt: f64) -> Result<TaskStep, EnvError> {
        let x_after = sim.data.qpos()[0];
        let x_velocity = (x_after - x_before) / dt;
        Ok(TaskStep {
            reward_terms: vec![
                ("forward", self.opts.forward_reward_weight * x_velocity),
                ("ctrl_cost", -quadratic_cost(self.opts.ctrl_cost_weight, action)),
            ],
            metrics: vec![("x_position", x_after), ("x_velocity", x_velocity)],
            terminated: false,
        })
    }
}
