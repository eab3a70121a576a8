//! Walker2d as Gymnasium v5 defines it: observation qpos[1:] + clip(qvel, ±10) (17), reward
//! forward + healthy - 1e-3 |a|^2, terminates when the torso leaves heights (0.8, 2) m or
//! pitches beyond 1 rad.
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::options::Check;
use super::simulation::{Simulation, VelocityNoise};
use super::task::{planar_walker_observation, planar_walker_step, Task, TaskStep, Timing};
use super::{BoxSpace, EnvError};
use crate::mujoco::Model;

pub const MODEL_XML: &str = include_str!("../../models/walker2d.xml");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Walker2dOptions {
    pub forward_reward_weight: f64,
    pub ctrl_cost_weight: f64,
    pub healthy_reward: f64,
    pub terminate_when_unhealthy: bool,
    /// Healthy while the torso height (qpos[1]) lies strictly inside this interval.
    pub healthy_z_range: [f64; 2],
    /// Healthy while the torso pitch (qpos[2]) lies strictly inside this interval.
    pub healthy_angle_range: [f64; 2],
    /// qpos and qvel += U(-s, s) at reset.
    pub reset_noise_scale: f64,
    pub max_episode_steps: usize,
    pub frame_skip: usize,
}

impl Default for Walker2dOptions {
    fn default() -> Self {
        Walker2dOptions {
            forward_reward_weight: 1.0,
            ctrl_cost_weight: 1e-3,
            healthy_reward: 1.0,
            terminate_when_unhealthy: true,
            healthy_z_range: [0.8, 2.0],
            healthy_angle_range: [-1.0, 1.0],
            reset_noise_scale: 5e-3,
            max_episode_steps: 1000,
            frame_skip: 4,
        }
    }
}

impl Walker2dOptions {
    pub fn validate(&self) -> Result<(), EnvError> {
        let c = Check { env: "walker2d" };
        c.non_negative("forward_reward_weight", self.forward_reward_weight)?;
        c.non_negative("ctrl_cost_weight", self.ctrl_cost_weight)?;
        c.non_negative("healthy_reward", self.healthy_reward)?;
        c.range("healthy_z_range", self.healthy_z_range)?;
        c.range("healthy_angle_range", self.healthy_angle_range)?;
        c.non_negative("reset_noise_scale", self.reset_noise_scale)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("frame_skip", self.frame_skip)
    }
}

pub struct Walker2dTask {
    opts: Walker2dOptions,
}

pub type Walker2d = MujocoEnv<Walker2dTask>;

impl Walker2dTask {
    fn is_healthy(&self, sim: &Simulation) -> bool {
        let q = sim.data.qpos();
        let inside = |[lo, hi]: [f64; 2], x: f64| lo < x && x < hi;
        inside(self.opts.healthy_z_range, q[1]) && inside(self.opts.healthy_angle_range, q[2])
    }
}

impl Task for Walker2dTask {
    type Options = Walker2dOptions;
    type Before = f64;
    const NAME: &'static str = "walker2d";
    const MODEL_XML: &'static str = MODEL_XML;
    const REWARD_TERMS: &'static [&'static str] = &["forward", "healthy", "ctrl_cost"];

    fn new(opts: Walker2dOptions, _model: &Model) -> Result<Self, EnvError> {
        opts.validate()?;
        Ok(Walker2dTask { opts })
    }

    fn timing(&self) -> Timing {
        Timing {
            frame_skip: self.opts.frame_skip,
            max_episode_steps: self.opts.max_episode_steps,
            reset_noise_scale: self.opts.reset_noise_scale,
            velocity_noise: VelocityNoise::Uniform,
        }
    }

    fn observation_dim(&self, model: &Model) -> usize {
        model.nq() - 1 + model.nv()
    }

    fn action_space(&self, model: &Model) -> BoxSpace {
        BoxSpace::uniform(model.nu(), -1.0, 1.0)
    }

    fn observe(&self, sim: &Simulation, out: &mut Vec<f64>) {
        planar_walker_observation(sim, out)
    }

    fn reset_metrics(&self, sim: &Simulation) -> Vec<(&'static str, f64)> {
        vec![("x_position", sim.data.qpos()[0])]
    }

    fn before(&self, sim: &Simulation) -> f64 {
        sim.data.qpos()[0]
    }

    fn after(&self, sim: &mut Simulation, x_before: &f64, action: &[f64], dt: f64) -> Result<TaskStep, EnvError> {
        let healthy = self.is_healthy(sim);
        let o = &self.opts;
        let weights = [o.forward_reward_weight, o.healthy_reward, o.ctrl_cost_weight];
        Ok(planar_walker_step(sim, *x_before, action, dt, healthy, weights, o.terminate_when_unhealthy))
    }
}
