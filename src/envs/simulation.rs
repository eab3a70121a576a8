//! What the MuJoCo environments share: a model and its data, stepping with instability checks,
//! the seeded random stream and reset noise.
use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal, Uniform};

use super::world::Delay;
use super::{clip_action, EnvError, EnvSpec, EpisodeClock, Info, Step};
use crate::mujoco::{take_warnings, Data, Model};

/// The random stream of an environment: reseeded by `reset(Some(seed))`, continued otherwise.
pub(crate) struct EnvRng(ChaCha8Rng);

impl EnvRng {
    pub fn new() -> EnvRng {
        EnvRng(ChaCha8Rng::seed_from_u64(0))
    }
    pub(crate) fn reseed(&mut self, seed: Option<u64>) {
        if let Some(s) = seed {
            self.0 = ChaCha8Rng::seed_from_u64(s);
        }
    }
    pub fn rng(&mut self) -> &mut ChaCha8Rng {
        &mut self.0
    }
    /// `n` samples of U[-scale, scale).
    pub fn uniform(&mut self, n: usize, scale: f64) -> Vec<f64> {
        if scale <= 0.0 {
            return vec![0.0; n];
        }
        let dist = Uniform::new(-scale, scale).expect("scale > 0");
        (0..n).map(|_| dist.sample(&mut self.0)).collect()
    }
    /// `n` samples of scale * N(0, 1).
    pub(crate) fn normal(&mut self, n: usize, scale: f64) -> Vec<f64> {
        (0..n)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut self.0);
                scale * z
            })
            .collect()
    }
}

/// Outcome of advancing the physics.
#[derive(Debug, Default)]
pub(crate) struct Advance {
    pub unstable: bool,
    pub warnings: Vec<String>,
}

/// A model and its state, stepped by `advance` with energy accounting and instability checks.
pub struct Simulation {
    /// The compiled model.
    pub model: Arc<Model>,
    /// The simulation state.
    pub data: Data,
    /// Mechanical energy the actuators delivered during the latest `advance` (J): sum over
    /// physics steps of |actuator force . joint velocity| * timestep, the force and velocity
    /// both at the start of each step (the same rule as Minitaur's motor model).
    pub last_mechanical_energy: f64,
    velocity_before: Vec<f64>,
}

impl Simulation {
    pub(crate) fn from_model(model: Arc<Model>) -> Result<Simulation, EnvError> {
        let data = Data::new(&model)?;
        Ok(Simulation { model, data, last_mechanical_energy: 0.0, velocity_before: Vec::new() })
    }

    /// Resets to `qpos0 + qpos_noise`, `qvel_noise`, then computes derived quantities (as
    /// Gymnasium's `set_state` does; `cfrc_ext` stays zero until the first step).
    pub(crate) fn reset_to(&mut self, qpos_noise: &[f64], qvel_noise: &[f64]) -> Result<(), EnvError> {
        self.data.reset()?;
        let qpos: Vec<f64> = self.model.qpos0().iter().zip(qpos_noise).map(|(a, b)| a + b).collect();
        self.data.set_state(&qpos, qvel_noise)?;
        take_warnings();
        Ok(())
    }

    /// Sets `ctrl` and runs `frames` MuJoCo steps, stopping at the first sign of instability.
    pub(crate) fn advance(&mut self, ctrl: &[f64], frames: usize) -> Result<Advance, EnvError> {
        self.data.set_ctrl(ctrl)?;
        self.advance_with(frames, |_, _| Ok(()))
    }

    /// Runs `frames` MuJoCo steps, calling `before(j, data)` ahead of step `j` (to change the
    /// controls mid-step, as a delayed command does), stopping at the first sign of instability.
    pub(crate) fn advance_with(
        &mut self,
        frames: usize,
        mut before: impl FnMut(usize, &mut Data) -> Result<(), EnvError>,
    ) -> Result<Advance, EnvError> {
        let mut out = Advance::default();
        let timestep = self.model.timestep();
        self.last_mechanical_energy = 0.0;
        for j in 0..frames {
            before(j, &mut self.data)?;
            self.velocity_before.clear();
            self.velocity_before.extend_from_slice(self.data.qvel());
            if self.step_once()? {
                out.unstable = true;
                break;
            }
            // mj_step computed qfrc_actuator from the state it started from.
            let power: f64 =
                self.data.qfrc_actuator().iter().zip(&self.velocity_before).map(|(f, v)| (f * v).abs()).sum();
            self.last_mechanical_energy += power * timestep;
        }
        out.warnings = take_warnings();
        Ok(out)
    }

    /// One `mj_step`; returns true when MuJoCo reported or hid an instability.
    pub(crate) fn step_once(&mut self) -> Result<bool, EnvError> {
        let (before, time_before) = (self.data.instability_counts(), self.data.time());
        self.data.step()?;
        let after = self.data.instability_counts();
        // MuJoCo's automatic reset also rewinds time, which catches a repeat of the same warning.
        let rewound = self.data.time() <= time_before;
        let finite = self.data.qpos().iter().chain(self.data.qvel()).all(|v| v.is_finite());
        Ok(after != before || rewound || !finite)
    }
}

/// The step reported when the physics blew up: last good observation, zero reward, truncated.
pub(crate) fn unstable_step(last_obs: &[f64], spec: &EnvSpec, clipped: usize, warnings: Vec<String>) -> Step {
    Step {
        observation: last_obs.to_vec(),
        reward: 0.0,
        terminated: false,
        truncated: true,
        info: Info {
            reward_terms: spec.reward_terms.iter().map(|&n| (n, 0.0)).collect(),
            metrics: vec![],
            clipped_actions: clipped,
            unstable: true,
            warnings,
        },
    }
}

/// How reset noise is drawn for velocities (positions always get U(-s, s)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VelocityNoise {
    /// s * N(0, 1) (HalfCheetah, Ant).
    Normal,
    /// U(-s, s) (Humanoid, InvertedPendulum).
    Uniform,
}

/// The [`Env`](super::Env) methods that read or write an environment's [`EnvCore`] (its `core`
/// field) and nothing else: written once for [`MujocoEnv`](super::MujocoEnv) and the Minitaur.
macro_rules! env_core_accessors {
    () => {
        fn spec(&self) -> &$crate::envs::EnvSpec {
            &self.core.spec
        }

        fn data(&self) -> &$crate::mujoco::Data {
            &self.core.sim.data
        }

        fn data_mut(&mut self) -> &mut $crate::mujoco::Data {
            &mut self.core.sim.data
        }

        fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), $crate::envs::EnvError> {
            Ok(self.core.sim.data.set_state(qpos, qvel)?)
        }
    };
}
pub(crate) use env_core_accessors;

/// The [`Env`](super::Env) methods a wrapper env (a command task, notch actions) hands to the env
/// it wraps (its `base` field): the simulation state is the base's.
macro_rules! base_state_accessors {
    () => {
        fn data(&self) -> &$crate::mujoco::Data {
            self.base.data()
        }

        fn data_mut(&mut self) -> &mut $crate::mujoco::Data {
            self.base.data_mut()
        }

        fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), $crate::envs::EnvError> {
            self.base.set_state(qpos, qvel)
        }
    };
}
pub(crate) use base_state_accessors;

/// The state every MuJoCo environment keeps, and the parts of reset/step they all share.
pub(crate) struct EnvCore {
    pub(crate) sim: Simulation,
    pub spec: EnvSpec,
    pub rng: EnvRng,
    pub(crate) clock: EpisodeClock,
    pub(crate) last_obs: Vec<f64>,
}

/// How a control step's physics went.
pub(crate) enum StepOutcome {
    /// It ran; MuJoCo's warnings, if any.
    Stepped(Vec<String>),
    /// It blew up: the step to return as it is (the episode is over).
    BlewUp(Step),
}

/// What `EnvCore::begin_step` hands back: the clipped action and how many entries were clipped.
pub(crate) struct StepStart {
    pub action: Vec<f64>,
    pub clipped: usize,
}

impl EnvCore {
    pub fn new(sim: Simulation, spec: EnvSpec) -> EnvCore {
        EnvCore { sim, spec, rng: EnvRng::new(), clock: EpisodeClock::default(), last_obs: vec![] }
    }

    /// Reseeds (if asked), resets to qpos0 plus noise of scale `scale`, starts the clock.
    pub(crate) fn reset_with_noise(
        &mut self,
        seed: Option<u64>,
        scale: f64,
        velocity: VelocityNoise,
    ) -> Result<(), EnvError> {
        self.rng.reseed(seed);
        let qpos_noise = self.rng.uniform(self.sim.model.nq(), scale);
        let nv = self.sim.model.nv();
        let qvel_noise = match velocity {
            VelocityNoise::Normal => self.rng.normal(nv, scale),
            VelocityNoise::Uniform => self.rng.uniform(nv, scale),
        };
        self.sim.reset_to(&qpos_noise, &qvel_noise)?;
        self.clock.start();
        Ok(())
    }

    /// Refuses a step outside an episode and validates/clips the action.
    pub(crate) fn begin_step(&self, action: &[f64]) -> Result<StepStart, EnvError> {
        self.clock.check_can_step()?;
        let (action, clipped) = clip_action(&self.spec.action_space, action)?;
        Ok(StepStart { action, clipped })
    }

    /// Runs the physics for one control step; with a delay line, the actuators act on the
    /// command that has reached them at each physics step (none yet: the controls stay as reset).
    pub(crate) fn advance(
        &mut self,
        start: &StepStart,
        frames: usize,
        delay: Option<&mut Delay<Vec<f64>>>,
    ) -> Result<StepOutcome, EnvError> {
        let adv = match delay {
            None => self.sim.advance(&start.action, frames)?,
            Some(delay) => {
                let step = self.clock.steps;
                delay.send(step, start.action.clone());
                self.sim.advance_with(frames, |j, data| match delay.acting(step * frames + j) {
                    Some(command) => Ok(data.set_ctrl(command)?),
                    None => Ok(()),
                })?
            }
        };
        if adv.unstable {
            self.clock.finish_if(true);
            return Ok(StepOutcome::BlewUp(unstable_step(&self.last_obs, &self.spec, start.clipped, adv.warnings)));
        }
        Ok(StepOutcome::Stepped(adv.warnings))
    }

    /// Counts the step, applies the time limit and assembles the result.
    pub(crate) fn finish_step(&mut self, observation: Vec<f64>, terminated: bool, info: Info) -> Step {
        let truncated = self.clock.tick(self.spec.max_episode_steps);
        self.clock.finish_if(terminated || truncated);
        self.last_obs.clone_from(&observation);
        let reward = info.reward_terms.iter().map(|(_, v)| v).sum();
        Step { observation, reward, terminated, truncated, info }
    }
}
