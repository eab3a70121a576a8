//! HalfCheetah as Gymnasium v5 defines it: observation qpos[1:] + qvel (17), reward
//! forward_weight * dx/dt - ctrl_weight * |a|^2, never terminates, 1000-step episodes.
use serde::{Deserialize, Serialize};

use super::options::Check;
use super::simulation::{unstable_step, EnvRng, Simulation};
use super::{clip_action, BoxSpace, Env, EnvError, EnvSpec, EpisodeClock, Info, Step};
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
        let c = Check {
            env: "half-cheetah",
        };
        c.non_negative("forward_reward_weight", self.forward_reward_weight)?;
        c.non_negative("ctrl_cost_weight", self.ctrl_cost_weight)?;
        c.non_negative("reset_noise_scale", self.reset_noise_scale)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("frame_skip", self.frame_skip)
    }
}

pub struct HalfCheetah {
    opts: HalfCheetahOptions,
    sim: Simulation,
    spec: EnvSpec,
    rng: EnvRng,
    clock: EpisodeClock,
    last_obs: Vec<f64>,
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
        Ok(HalfCheetah {
            opts,
            sim,
            spec,
            rng: EnvRng::new(),
            clock: EpisodeClock::default(),
            last_obs: vec![],
        })
    }

    fn observation(&self) -> Vec<f64> {
        let d = &self.sim.data;
        d.qpos()[1..].iter().chain(d.qvel()).copied().collect()
    }
}

impl Env for HalfCheetah {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        self.rng.reseed(seed);
        let s = self.opts.reset_noise_scale;
        let qpos_noise = self.rng.uniform(self.sim.model.nq(), s);
        let qvel_noise = self.rng.normal(self.sim.model.nv(), s);
        self.sim.reset_to(&qpos_noise, &qvel_noise)?;
        self.clock.start();
        self.last_obs = self.observation();
        let info = Info {
            metrics: vec![("x_position", self.sim.data.qpos()[0])],
            ..Info::default()
        };
        Ok((self.last_obs.clone(), info))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        self.clock.check_can_step()?;
        let (action, clipped) = clip_action(&self.spec.action_space, action)?;
        let x_before = self.sim.data.qpos()[0];
        let adv = self.sim.advance(&action, self.opts.frame_skip)?;
        if adv.unstable {
            self.clock.finish_if(true);
            return Ok(unstable_step(
                &self.last_obs,
                &self.spec,
                clipped,
                adv.warnings,
            ));
        }
        let x_after = self.sim.data.qpos()[0];
        let x_velocity = (x_after - x_before) / self.spec.dt;
        let forward = self.opts.forward_reward_weight * x_velocity;
        let ctrl_cost = self.opts.ctrl_cost_weight * action.iter().map(|a| a * a).sum::<f64>();
        let observation = self.observation();
        let truncated = self.clock.tick(self.opts.max_episode_steps);
        self.clock.finish_if(truncated);
        self.last_obs.clone_from(&observation);
        Ok(Step {
            observation,
            reward: forward - ctrl_cost,
            terminated: false,
            truncated,
            info: Info {
                reward_terms: vec![("forward", forward), ("ctrl_cost", -ctrl_cost)],
                metrics: vec![("x_position", x_after), ("x_velocity", x_velocity)],
                clipped_actions: clipped,
                unstable: false,
                warnings: adv.warnings,
            },
        })
    }

    fn data(&self) -> &Data {
        &self.sim.data
    }

    fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), EnvError> {
        Ok(self.sim.data.set_state(qpos, qvel)?)
    }
}
