//! Hopper as Gymnasium v5 defines it: observation qpos[1:] + clip(qvel, ±10) (11), reward
//! forward + healthy - 1e-3 |a|^2, terminates when the torso is below 0.7 m, tilts more than
//! 0.2 rad or any of qpos[2:], qvel leaves (-100, 100).
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::planar_walker::{inside, PlanarWalkerTask, WalkerRule};
use super::simulation::Simulation;

pub(crate) const MODEL_XML: &str = include_str!("../../models/hopper.xml");

/// Gymnasium Hopper-v5's options, with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HopperOptions {
    /// Weight of the forward-velocity reward.
    pub forward_reward_weight: f64,
    /// Weight of the squared-action cost.
    pub ctrl_cost_weight: f64,
    /// Reward per step while healthy.
    pub healthy_reward: f64,
    /// End the episode when the hopper becomes unhealthy.
    pub terminate_when_unhealthy: bool,
    /// Healthy while every entry of qpos[2:] and qvel lies strictly inside this interval.
    pub healthy_state_range: [f64; 2],
    /// Healthy while the torso height (qpos[1]) lies strictly inside this interval.
    pub healthy_z_range: [f64; 2],
    /// Healthy while the torso pitch (qpos[2]) lies strictly inside this interval.
    pub healthy_angle_range: [f64; 2],
    /// qpos and qvel += U(-s, s) at reset.
    pub reset_noise_scale: f64,
    /// Steps before the episode is truncated.
    pub max_episode_steps: usize,
    /// Physics steps per `step`.
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

/// Hopper's health rule; the rest of the task is every planar walker's.
pub struct HopperRule;

pub(crate) type HopperTask = PlanarWalkerTask<HopperRule>;
/// Gymnasium's Hopper-v5: a planar one-legged hopper rewarded for moving along x.
pub type Hopper = MujocoEnv<HopperTask>;

impl WalkerRule for HopperRule {
    type Options = HopperOptions;
    const NAME: &'static str = "hopper";
    const MODEL_XML: &'static str = MODEL_XML;

    fn is_healthy(o: &HopperOptions, sim: &Simulation) -> bool {
        let (q, v) = (sim.data.qpos(), sim.data.qvel());
        q[2..].iter().chain(v).all(|&x| inside(o.healthy_state_range, x))
            && inside(o.healthy_z_range, q[1])
            && inside(o.healthy_angle_range, q[2])
    }
}
