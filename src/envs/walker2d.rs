//! Walker2d as Gymnasium v5 defines it: observation qpos[1:] + clip(qvel, ±10) (17), reward
//! forward + healthy - 1e-3 |a|^2, terminates when the torso leaves heights (0.8, 2) m or
//! pitches beyond 1 rad.
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::planar_walker::{inside, PlanarWalkerTask, WalkerRule};
use super::simulation::Simulation;

pub(crate) const MODEL_XML: &str = include_str!("../../models/walker2d.xml");

/// Gymnasium Walker2d-v5's options, with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Walker2dOptions {
    /// Weight of the forward-velocity reward.
    pub forward_reward_weight: f64,
    /// Weight of the squared-action cost.
    pub ctrl_cost_weight: f64,
    /// Reward per step while healthy.
    pub healthy_reward: f64,
    /// End the episode when the walker becomes unhealthy.
    pub terminate_when_unhealthy: bool,
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

/// Walker2d's health rule; the rest of the task is every planar walker's.
pub struct Walker2dRule;

pub(crate) type Walker2dTask = PlanarWalkerTask<Walker2dRule>;
/// Gymnasium's Walker2d-v5: a planar biped rewarded for walking along x.
pub type Walker2d = MujocoEnv<Walker2dTask>;

impl WalkerRule for Walker2dRule {
    type Options = Walker2dOptions;
    const NAME: &'static str = "walker2d";
    const MODEL_XML: &'static str = MODEL_XML;

    fn is_healthy(o: &Walker2dOptions, sim: &Simulation) -> bool {
        let q = sim.data.qpos();
        inside(o.healthy_z_range, q[1]) && inside(o.healthy_angle_range, q[2])
    }
}
