//! InvertedPendulum as Gymnasium v5 defines it: observation qpos + qvel (4), reward 1 per step
//! while the pole stays within 0.2 rad and the state is finite, terminates otherwise.
use serde::{Deserialize, Serialize};

use super::options::Check;
use super::simulation::{EnvCore, Simulation, StepOutcome, VelocityNoise};
use super::{BoxSpace, Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Data;

pub const MODEL_XML: &str = include_str!("../../models/inverted_pendulum.xml");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InvertedPendulumOptions {
    /// The episode terminates once |pole angle| exceeds this (radians).
    pub max_pole_angle: f64,
    /// qpos and qvel += U(-s, s) at reset.
    pub reset_noise_scale: f64,
    pub max_episode_steps: usize,
    pub frame_skip: usize,
}

impl Default for InvertedPendulumOptions {
    fn default() -> Self {
        InvertedPendulumOptions { max_pole_angle: 0.2, reset_noise_scale: 0.01, max_episode_steps: 1000, frame_skip: 2 }
    }
}

impl InvertedPendulumOptions {
    pub fn validate(&self) -> Result<(), EnvError> {
        let c = Check { env: "inverted-pendulum" };
        c.within("max_pole_angle", self.max_pole_angle, 0.0, std::f64::consts::FRAC_PI_2)?;
        c.non_negative("reset_noise_scale", self.reset_noise_scale)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("frame_skip", self.frame_skip)
    }
}

pub struct InvertedPendulum {
    opts: InvertedPendulumOptions,
    core: EnvCore,
}

impl InvertedPendulum {
    pub fn new(opts: InvertedPendulumOptions) -> Result<Self, EnvError> {
        opts.validate()?;
        let sim = Simulation::from_xml(MODEL_XML)?;
        let m = &sim.model;
        let spec = EnvSpec {
            name: "inverted-pendulum",
            observation_space: BoxSpace::unbounded(m.nq() + m.nv()),
            action_space: BoxSpace::uniform(m.nu(), -3.0, 3.0),
            dt: m.timestep() * opts.frame_skip as f64,
            max_episode_steps: opts.max_episode_steps,
            reward_terms: vec!["healthy"],
        };
        Ok(InvertedPendulum { opts, core: EnvCore::new(sim, spec) })
    }

    fn observation(&self) -> Vec<f64> {
        let d = &self.core.sim.data;
        d.qpos().iter().chain(d.qvel()).copied().collect()
    }
}

impl Env for InvertedPendulum {
    fn spec(&self) -> &EnvSpec {
        &self.core.spec
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        self.core.reset_with_noise(seed, self.opts.reset_noise_scale, VelocityNoise::Uniform)?;
        self.core.last_obs = self.observation();
        Ok((self.core.last_obs.clone(), Info::default()))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let start = self.core.begin_step(action)?;
        let warnings = match self.core.advance(&start, self.opts.frame_skip)? {
            StepOutcome::Stepped(warnings) => warnings,
            StepOutcome::BlewUp(step) => return Ok(step),
        };
        let observation = self.observation();
        let terminated = !observation.iter().all(|v| v.is_finite()) || observation[1].abs() > self.opts.max_pole_angle;
        let q = self.core.sim.data.qpos();
        let info = Info {
            reward_terms: vec![("healthy", if terminated { 0.0 } else { 1.0 })],
            metrics: vec![("cart_position", q[0]), ("pole_angle", q[1])],
            clipped_actions: start.clipped,
            unstable: false,
            warnings,
        };
        Ok(self.core.finish_step(observation, terminated, info))
    }

    fn data(&self) -> &Data {
        &self.core.sim.data
    }

    fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), EnvError> {
        Ok(self.core.sim.data.set_state(qpos, qvel)?)
    }
}
