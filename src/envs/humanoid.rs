//! Humanoid as Gymnasium v5 defines it: observation qpos[2:], qvel, cinert[1:], cvel[1:],
//! qfrc_actuator[6:], cfrc_ext[1:] (348); reward 1.25 * centre-of-mass dx/dt + 5 while healthy
//! - 0.1 |ctrl|^2 - min(5e-7 |cfrc_ext|^2, 10); terminates when the torso leaves (1, 2) m.
use serde::{Deserialize, Serialize};

use super::options::Check;
use super::simulation::{locomotion_metrics, reset_info, EnvCore, Simulation, StepOutcome, VelocityNoise};
use super::{BoxSpace, Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Data;

pub const MODEL_XML: &str = include_str!("../../models/humanoid.xml");

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HumanoidOptions {
    pub forward_reward_weight: f64,
    pub ctrl_cost_weight: f64,
    pub contact_cost_weight: f64,
    /// The contact cost is clipped above at this value.
    pub contact_cost_max: f64,
    pub healthy_reward: f64,
    pub terminate_when_unhealthy: bool,
    /// Healthy while the torso height lies strictly inside this interval.
    pub healthy_z_range: [f64; 2],
    /// qpos and qvel += U(-s, s) at reset.
    pub reset_noise_scale: f64,
    pub max_episode_steps: usize,
    pub frame_skip: usize,
}

impl Default for HumanoidOptions {
    fn default() -> Self {
        HumanoidOptions {
            forward_reward_weight: 1.25,
            ctrl_cost_weight: 0.1,
            contact_cost_weight: 5e-7,
            contact_cost_max: 10.0,
            healthy_reward: 5.0,
            terminate_when_unhealthy: true,
            healthy_z_range: [1.0, 2.0],
            reset_noise_scale: 1e-2,
            max_episode_steps: 1000,
            frame_skip: 5,
        }
    }
}

impl HumanoidOptions {
    pub fn validate(&self) -> Result<(), EnvError> {
        let c = Check { env: "humanoid" };
        c.non_negative("forward_reward_weight", self.forward_reward_weight)?;
        c.non_negative("ctrl_cost_weight", self.ctrl_cost_weight)?;
        c.non_negative("contact_cost_weight", self.contact_cost_weight)?;
        c.non_negative("contact_cost_max", self.contact_cost_max)?;
        c.non_negative("healthy_reward", self.healthy_reward)?;
        c.range("healthy_z_range", self.healthy_z_range)?;
        c.non_negative("reset_noise_scale", self.reset_noise_scale)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("frame_skip", self.frame_skip)
    }
}

pub struct Humanoid {
    opts: HumanoidOptions,
    core: EnvCore,
}

impl Humanoid {
    pub fn new(opts: HumanoidOptions) -> Result<Self, EnvError> {
        opts.validate()?;
        let sim = Simulation::from_xml(MODEL_XML)?;
        let m = &sim.model;
        let nb = m.nbody() - 1;
        let obs_dim = (m.nq() - 2) + m.nv() + 10 * nb + 6 * nb + (m.nv() - 6) + 6 * nb;
        let ctrl = m.actuator_ctrlrange();
        let spec = EnvSpec {
            name: "humanoid",
            observation_space: BoxSpace::unbounded(obs_dim),
            action_space: BoxSpace::new(
                (0..m.nu()).map(|i| ctrl[2 * i]).collect(),
                (0..m.nu()).map(|i| ctrl[2 * i + 1]).collect(),
            ),
            dt: m.timestep() * opts.frame_skip as f64,
            max_episode_steps: opts.max_episode_steps,
            reward_terms: vec!["forward", "healthy", "ctrl_cost", "contact_cost"],
        };
        Ok(Humanoid { opts, core: EnvCore::new(sim, spec) })
    }

    fn observation(&self) -> Vec<f64> {
        let d = &self.core.sim.data;
        let mut obs = Vec::with_capacity(self.core.spec.observation_space.dim());
        obs.extend_from_slice(&d.qpos()[2..]);
        obs.extend_from_slice(d.qvel());
        obs.extend_from_slice(&d.cinert()[10..]);
        obs.extend_from_slice(&d.cvel()[6..]);
        obs.extend_from_slice(&d.qfrc_actuator()[6..]);
        obs.extend_from_slice(&d.cfrc_ext()[6..]);
        obs
    }

    /// Mass-weighted centre of mass, x and y.
    fn mass_center(&self) -> [f64; 2] {
        let mass = self.core.sim.model.body_mass();
        let xipos = self.core.sim.data.xipos();
        let total: f64 = mass.iter().sum();
        let mut c = [0.0; 2];
        for (b, m) in mass.iter().enumerate() {
            c[0] += m * xipos[3 * b];
            c[1] += m * xipos[3 * b + 1];
        }
        [c[0] / total, c[1] / total]
    }

    fn is_healthy(&self) -> bool {
        let z = self.core.sim.data.qpos()[2];
        let [lo, hi] = self.opts.healthy_z_range;
        lo < z && z < hi
    }
}

impl Env for Humanoid {
    fn spec(&self) -> &EnvSpec {
        &self.core.spec
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        self.core.reset_with_noise(seed, self.opts.reset_noise_scale, VelocityNoise::Uniform)?;
        self.core.last_obs = self.observation();
        Ok((self.core.last_obs.clone(), reset_info(&self.core)))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let start = self.core.begin_step(action)?;
        let before = self.mass_center();
        let warnings = match self.core.advance(&start, self.opts.frame_skip)? {
            StepOutcome::Stepped(warnings) => warnings,
            StepOutcome::BlewUp(step) => return Ok(step),
        };
        self.core.sim.data.rne_post_constraint()?;
        let after = self.mass_center();
        let velocity = [(after[0] - before[0]) / self.core.spec.dt, (after[1] - before[1]) / self.core.spec.dt];

        let d = &self.core.sim.data;
        let healthy = self.is_healthy();
        let forward = self.opts.forward_reward_weight * velocity[0];
        let healthy_reward = if healthy { self.opts.healthy_reward } else { 0.0 };
        let ctrl_cost = self.opts.ctrl_cost_weight * d.ctrl().iter().map(|a| a * a).sum::<f64>();
        let contact_cost = (self.opts.contact_cost_weight * d.cfrc_ext().iter().map(|f| f * f).sum::<f64>())
            .min(self.opts.contact_cost_max);
        let info = Info {
            reward_terms: vec![
                ("forward", forward),
                ("healthy", healthy_reward),
                ("ctrl_cost", -ctrl_cost),
                ("contact_cost", -contact_cost),
            ],
            metrics: locomotion_metrics(&self.core, velocity),
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
