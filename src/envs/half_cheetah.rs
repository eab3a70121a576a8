//! HalfCheetah as Gymnasium v5 defines it: observation qpos[1:] + qvel (17), reward
//! forward_weight * dx/dt - ctrl_weight * |a|^2, never terminates, 1000-step episodes.
use serde::{Deserialize, Serialize};

use super::options::Check;
use super::simulation::{EnvCore, Simulation, StepOutcome, VelocityNoise};
use super::{BoxSpace, Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Data;

pub const MODEL_XML: &str = include_str!("../../models/half_cheetah.xml");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HalfCheetahOptions {
    pub forward_reward_weight: f64,
    pub ctrl_cost_weight: f64,
    /// qpos += U(-s, s), qvel = s * N(0, 1) at reset.
    pub reset_noise_scale: f64,
    pub max_episode_steps: usize,
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

impl HalfCheetahOptions {
    pub fn validate(&self) -> Result<(), EnvError> {
        let c = Check { env: "half-cheetah" };
        c.non_negative("forward_reward_weight", self.forward_reward_weight)?;
        c.non_negative("ctrl_cost_weight", self.ctrl_cost_weight)?;
        c.non_negative("reset_noise_scale", self.reset_noise_scale)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("frame_skip", self.frame_skip)
    }
}

pub struct HalfCheetah {
    opts: HalfCheetahOptions,
    core: EnvCore,
}

impl HalfCheetah {
    pub fn new(opts: HalfCheetahOptions) -> Result<Self, EnvError> {
        opts.validate()?;
        let sim = Simulation::from_xml(MODEL_XML)?;
        let spec = EnvSpec {
            name: "half-cheetah",
            observation_space: BoxSpace::unbounded(sim.model.nq() - 1 + sim.model.nv()),
            action_space: BoxSpace::uniform(sim.model.nu(), -1.0, 1.0),
            dt: sim.model.timestep() * opts.frame_skip as f64,
            max_episode_steps: opts.max_episode_steps,
            reward_terms: vec!["forward", "ctrl_cost"],
        };
        Ok(HalfCheetah { opts, core: EnvCore::new(sim, spec) })
    }

    fn observation(&self) -> Vec<f64> {
        let d = &self.core.sim.data;
        d.qpos()[1..].iter().chain(d.qvel()).copied().collect()
    }
}

impl Env for HalfCheetah {
    fn spec(&self) -> &EnvSpec {
        &self.core.spec
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        self.core.reset_with_noise(seed, self.opts.reset_noise_scale, VelocityNoise::Normal)?;
        self.core.last_obs = self.observation();
        let info = Info { metrics: vec![("x_position", self.core.sim.data.qpos()[0])], ..Info::default() };
        Ok((self.core.last_obs.clone(), info))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let start = self.core.begin_step(action)?;
        let x_before = self.core.sim.data.qpos()[0];
        let warnings = match self.core.advance(&start, self.opts.frame_skip)? {
            StepOutcome::Stepped(warnings) => warnings,
            StepOutcome::BlewUp(step) => return Ok(step),
        };
        let x_after = self.core.sim.data.qpos()[0];
        let x_velocity = (x_after - x_before) / self.core.spec.dt;
        let forward = self.opts.forward_reward_weight * x_velocity;
        let ctrl_cost = self.opts.ctrl_cost_weight * start.action.iter().map(|a| a * a).sum::<f64>();
        let info = Info {
            reward_terms: vec![("forward", forward), ("ctrl_cost", -ctrl_cost)],
            metrics: vec![("x_position", x_after), ("x_velocity", x_velocity)],
            clipped_actions: start.clipped,
            unstable: false,
            warnings,
        };
        Ok(self.core.finish_step(self.observation(), false, info))
    }

    fn data(&self) -> &Data {
        &self.core.sim.data
    }

    fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), EnvError> {
        Ok(self.core.sim.data.set_state(qpos, qvel)?)
    }
}
