//! Ant as Gymnasium v5 defines it: observation qpos[2:] + qvel + clipped cfrc_ext of bodies 1..
//! (105), reward forward + healthy - ctrl_cost - contact_cost, terminates when unhealthy.
use serde::{Deserialize, Serialize};

use super::options::Check;
use super::simulation::{locomotion_metrics, reset_info, EnvCore, Simulation, StepOutcome, VelocityNoise};
use super::{BoxSpace, Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Data;

pub const MODEL_XML: &str = include_str!("../../models/ant.xml");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AntOptions {
    pub forward_reward_weight: f64,
    pub ctrl_cost_weight: f64,
    pub contact_cost_weight: f64,
    pub healthy_reward: f64,
    pub terminate_when_unhealthy: bool,
    /// Healthy while the torso height lies in this closed interval (and the state is finite).
    pub healthy_z_range: [f64; 2],
    /// cfrc_ext entries are clipped to this range for the observation and the contact cost.
    pub contact_force_range: [f64; 2],
    /// qpos += U(-s, s), qvel = s * N(0, 1) at reset.
    pub reset_noise_scale: f64,
    pub max_episode_steps: usize,
    pub frame_skip: usize,
}

impl Default for AntOptions {
    fn default() -> Self {
        AntOptions {
            forward_reward_weight: 1.0,
            ctrl_cost_weight: 0.5,
            contact_cost_weight: 5e-4,
            healthy_reward: 1.0,
            terminate_when_unhealthy: true,
            healthy_z_range: [0.2, 1.0],
            contact_force_range: [-1.0, 1.0],
            reset_noise_scale: 0.1,
            max_episode_steps: 1000,
            frame_skip: 5,
        }
    }
}

impl AntOptions {
    pub fn validate(&self) -> Result<(), EnvError> {
        let c = Check { env: "ant" };
        c.non_negative("forward_reward_weight", self.forward_reward_weight)?;
        c.non_negative("ctrl_cost_weight", self.ctrl_cost_weight)?;
        c.non_negative("contact_cost_weight", self.contact_cost_weight)?;
        c.non_negative("healthy_reward", self.healthy_reward)?;
        c.range("healthy_z_range", self.healthy_z_range)?;
        c.range("contact_force_range", self.contact_force_range)?;
        c.non_negative("reset_noise_scale", self.reset_noise_scale)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("frame_skip", self.frame_skip)
    }
}

pub struct Ant {
    opts: AntOptions,
    core: EnvCore,
    torso: usize,
}

impl Ant {
    pub fn new(opts: AntOptions) -> Result<Self, EnvError> {
        opts.validate()?;
        let sim = Simulation::from_xml(MODEL_XML)?;
        let m = &sim.model;
        let spec = EnvSpec {
            name: "ant",
            observation_space: BoxSpace::unbounded(m.nq() - 2 + m.nv() + 6 * (m.nbody() - 1)),
            action_space: BoxSpace::uniform(m.nu(), -1.0, 1.0),
            dt: m.timestep() * opts.frame_skip as f64,
            max_episode_steps: opts.max_episode_steps,
            reward_terms: vec!["forward", "healthy", "ctrl_cost", "contact_cost"],
        };
        let torso = m.body_id("torso")?;
        Ok(Ant { opts, core: EnvCore::new(sim, spec), torso })
    }

    fn clipped_contact_forces(&self) -> impl Iterator<Item = f64> + '_ {
        let [lo, hi] = self.opts.contact_force_range;
        self.core.sim.data.cfrc_ext().iter().map(move |f| f.clamp(lo, hi))
    }

    fn observation(&self) -> Vec<f64> {
        let d = &self.core.sim.data;
        let mut obs: Vec<f64> = d.qpos()[2..].iter().chain(d.qvel()).copied().collect();
        obs.extend(self.clipped_contact_forces().skip(6));
        obs
    }

    fn is_healthy(&self) -> bool {
        let d = &self.core.sim.data;
        let [lo, hi] = self.opts.healthy_z_range;
        let finite = d.qpos().iter().chain(d.qvel()).all(|v| v.is_finite());
        finite && d.qpos()[2] >= lo && d.qpos()[2] <= hi
    }

    fn torso_xy(&self) -> [f64; 2] {
        let p = &self.core.sim.data.xpos()[3 * self.torso..];
        [p[0], p[1]]
    }
}

impl Env for Ant {
    fn spec(&self) -> &EnvSpec {
        &self.core.spec
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        self.core.reset_with_noise(seed, self.opts.reset_noise_scale, VelocityNoise::Normal)?;
        self.core.last_obs = self.observation();
        Ok((self.core.last_obs.clone(), reset_info(&self.core)))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let start = self.core.begin_step(action)?;
        let before = self.torso_xy();
        let z_before = self.core.sim.data.qpos()[2];
        let warnings = match self.core.advance(&start, self.opts.frame_skip)? {
            StepOutcome::Stepped(warnings) => warnings,
            StepOutcome::BlewUp(step) => return Ok(step),
        };
        self.core.sim.data.rne_post_constraint()?;
        let after = self.torso_xy();
        let velocity = [(after[0] - before[0]) / self.core.spec.dt, (after[1] - before[1]) / self.core.spec.dt];

        let healthy = self.is_healthy();
        let forward = self.opts.forward_reward_weight * velocity[0];
        let healthy_reward = if healthy { self.opts.healthy_reward } else { 0.0 };
        let ctrl_cost = self.opts.ctrl_cost_weight * start.action.iter().map(|a| a * a).sum::<f64>();
        let contact_cost = self.opts.contact_cost_weight * self.clipped_contact_forces().map(|f| f * f).sum::<f64>();
        let info = Info {
            reward_terms: vec![
                ("forward", forward),
                ("healthy", healthy_reward),
                ("ctrl_cost", -ctrl_cost),
                ("contact_cost", -contact_cost),
            ],
            metrics: {
                let d = &self.core.sim.data;
                let mut m = locomotion_metrics(&self.core, velocity);
                m.extend([
                    ("dy", after[1] - before[1]),
                    ("dz", d.qpos()[2] - z_before),
                    ("mechanical_energy", self.core.sim.last_mechanical_energy),
                ]);
                m
            },
            clipped_actions: start.clipped,
            unstable: false,
            warnings,
        };
        let terminated = !healthy && self.opts.terminate_when_unhealthy;
        Ok(self.core.finish_step(self.observation(), terminated, info))
    }

    fn data(&self) -> &Data {
        &self.core.sim.data
    }

    fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), EnvError> {
        Ok(self.core.sim.data.set_state(qpos, qvel)?)
    }
}
