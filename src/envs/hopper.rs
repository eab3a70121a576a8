//! Hopper as Gymnasium v5 defines it: observation qpos[1:] + clip(qvel, ±10) (11), reward
//! forward + healthy - 1e-3 |a|^2, terminates when the torso is below 0.7 m, tilts more than
//! 0.2 rad or any of qpos[2:], qvel leaves (-100, 100).
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::options::Check;
use super::simulation::{Simulation, VelocityNoise};
use super::task::{planar_walker_observation, planar_walker_step, Task, TaskStep, Timing};
use super::{BoxSpace, EnvError};
use crate::mujoco::Model;

pub const MODEL_XML: &str = include_str!("../../models/hopper.xml");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HopperOptions {
    pub forward_reward_weight: f64,
    pub ctrl_cost_weight: f64,
    pub healthy_reward: f64,
    pub terminate_when_unhealthy: bool,
    /// Healthy while every entry of qpos[2:] and qvel lies strictly inside this interval.
    pub healthy_state_range: [f64; 2],
    /// Healthy while the torso height (qpos[1]) lies strictly inside this interval.
    pub healthy_z_range: [f64; 2],
    /// Healthy while the torso pitch (qpos[2]) lies strictly inside this interval.
    pub healthy_angle_range: [f64; 2],
    /// qpos and qvel += U(-s, s) at reset.
    pub reset_noise_scale: f64,
    pub max_episode_steps: usize,
    pub frame_skip: usize,
}

impl Default for HopperOptions {
    fn default() -> Self {
        HopperOptions {
            forward_reward_weight: 1.0,
            ctrl_cost_weight: 1e-3,
            healthy_reward: 1.0,
            terminate_when_unhealthy: true,
            healthy_state_range: [-100.0, 100.0],
            healthy_z_range: [0.7, f64::INFINITY],
            healthy_angle_range: [-0.2, 0.2],
            reset_noise_scale: 5e-3,
            max_episode_steps: 1000,
            frame_skip: 4,
        }
    }
}

impl HopperOptions {
    pub fn validate(&self) -> Result<(), EnvError> {
        let c = Check { env: "hopper" };
        c.non_negative("forward_reward_weight", self.forward_reward_weight)?;
        c.non_negative("ctrl_cost_weight", self.ctrl_cost_weight)?;
        c.non_negative("healthy_reward", self.healthy_reward)?;
        c.range("healthy_state_range", self.healthy_state_range)?;
        c.range("healthy_z_range", self.healthy_z_range)?;
        c.range("healthy_angle_range", self.healthy_angle_range)?;
        c.non_negative("reset_noise_scale", self.reset_noise_scale)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("frame_skip", self.frame_skip)
    }
}

pub struct HopperTask {
    opts: HopperOptions,
}

pub type Hopper = MujocoEnv<HopperTask>;

impl HopperTask {
    fn is_healthy(&self, sim: &Simulation) -> bool {
        let (q, v) = (sim.data.qpos(), sim.data.qvel());
        let inside = |[lo, hi]: [f64; 2], x: f64| lo < x && x < hi;
        q[2..].iter().chain(v).all(|&x| inside(self.opts.healthy_state_range, x))
            && inside(self.opts.healthy_z_range, q[1])
            && inside(self.opts.healthy_angle_range, q[2])
    }
}

impl Task for HopperTask {
    type Options = HopperOptions;
    type Before = f64;
    const NAME: &'static str = "hopper";
    const MODEL_XML: &'static str = MODEL_XML;
    const REWARD_TERMS: &'static [&'static str] = &["forward", "healthy", "ctrl_cost"];

    fn new(opts: HopperOptions, _model: &Model) -> Result<Self, EnvError> {
        opts.validate()?;
        Ok(HopperTask { opts })
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
