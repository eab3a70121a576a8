//! InvertedPendulum as Gymnasium v5 defines it: observation qpos + qvel (4), reward 1 per step
//! while the pole stays within 0.2 rad and the state is finite, terminates otherwise.
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::options::Check;
use super::simulation::{Simulation, VelocityNoise};
use super::task::{Task, TaskStep};
use super::EnvError;
use crate::mujoco::Model;

pub(crate) const MODEL_XML: &str = include_str!("../../models/inverted_pendulum.xml");

/// Gymnasium InvertedPendulum-v5's options, with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InvertedPendulumOptions {
    /// The episode terminates once |pole angle| exceeds this (radians).
    pub max_pole_angle: f64,
    /// qpos and qvel += U(-s, s) at reset.
    pub reset_noise_scale: f64,
    /// Steps before the episode is truncated.
    pub max_episode_steps: usize,
    /// Physics steps per `step`.
    pub frame_skip: usize,
}

impl Default for InvertedPendulumOptions {
    fn default() -> Self {
        InvertedPendulumOptions { max_pole_angle: 0.2, reset_noise_scale: 0.01, max_episode_steps: 1000, frame_skip: 2 }
    }
}

impl InvertedPendulumOptions {
    /// Its own check; the ones every task shares run by name (`options::check_by_name`).
    pub fn validate(&self) -> Result<(), EnvError> {
        Check { env: "inverted-pendulum" }.within(
            "max_pole_angle",
            self.max_pole_angle,
            0.0,
            std::f64::consts::FRAC_PI_2,
        )
    }
}

pub struct InvertedPendulumTask {
    opts: InvertedPendulumOptions,
}

/// Gymnasium's InvertedPendulum-v5: keep a pole upright on a cart; +1 per step while it stands.
pub type InvertedPendulum = MujocoEnv<InvertedPendulumTask>;

impl Task for InvertedPendulumTask {
    type Options = InvertedPendulumOptions;
    type Before = ();
    const NAME: &'static str = "inverted-pendulum";
    const MODEL_XML: &'static str = MODEL_XML;
    const VELOCITY_NOISE: VelocityNoise = VelocityNoise::Uniform;
    const REWARD_TERMS: &'static [&'static str] = &["healthy"];

    fn new(opts: InvertedPendulumOptions, _model: &Model) -> Result<Self, EnvError> {
        opts.validate()?;
        Ok(InvertedPendulumTask { opts })
    }

    fn options(&self) -> &Self::Options {
        &self.opts
    }

    fn observation_dim(&self, model: &Model) -> usize {
        model.nq() + model.nv()
    }

    fn observe(&self, sim: &Simulation, out: &mut Vec<f64>) {
        out.extend_from_slice(sim.data.qpos());
        out.extend_from_slice(sim.data.qvel());
    }

    fn before(&self, _sim: &Simulation) {}

    fn after(&self, sim: &mut Simulation, _: &(), _action: &[f64], _dt: f64) -> Result<TaskStep, EnvError> {
        let (q, v) = (sim.data.qpos(), sim.data.qvel());
        let finite = q.iter().chain(v).all(|x| x.is_finite());
        let terminated = !finite || q[1].abs() > self.opts.max_pole_angle;
        Ok(TaskStep {
            reward_terms: vec![("healthy", if terminated { 0.0 } else { 1.0 })],
            metrics: vec![("cart_position", q[0]), ("pole_angle", q[1])],
            terminated,
        })
    }
}
