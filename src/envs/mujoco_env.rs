//! The one step skeleton of the MuJoCo environments: a [`Task`] over a [`Simulation`].
use std::sync::Arc;

use super::options::{check_by_name, read_by_name};
use super::simulation::{env_core_accessors, EnvCore, Simulation, StepOutcome};
use super::task::{Task, Timing};
use super::world::Delay;
use super::{Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Model;

/// An environment made of a [`Task`] on a MuJoCo [`Simulation`]: clipping, reset noise, time limit and
/// instability handling are shared here.
pub struct MujocoEnv<T: Task> {
    task: T,
    timing: Timing,
    core: EnvCore,
    /// The task's control latency in physics steps, and its delay line (latency > 0 only).
    latency: usize,
    delay: Option<Delay<Vec<f64>>>,
}

impl<T: Task> MujocoEnv<T> {
    /// Builds the task's model and checks its options.
    pub fn new(options: T::Options) -> Result<Self, EnvError> {
        check_by_name(T::NAME, &options)?;
        let mut model = Model::from_xml_str(T::MODEL_XML)?;
        let task = T::new(options, &model)?;
        let mut latency = 0;
        if let Some((world, body)) = task.world() {
            world.validate(T::NAME)?;
            world.edit_model(&mut model, body);
            latency = world.latency_steps(model.timestep());
        }
        let sim = Simulation::from_model(Arc::new(model))?;
        let timing: Timing = read_by_name(task.options());
        let spec = EnvSpec {
            name: T::NAME,
            observation_space: super::BoxSpace::unbounded(task.observation_dim(&sim.model)),
            action_space: task.action_space(&sim.model),
            dt: sim.model.timestep() * timing.frame_skip as f64,
            max_episode_steps: timing.max_episode_steps,
            reward_terms: T::REWARD_TERMS.to_vec(),
        };
        Ok(MujocoEnv { task, timing, core: EnvCore::new(sim, spec), latency, delay: None })
    }

    fn observe(&self) -> Vec<f64> {
        let mut observation = Vec::with_capacity(self.core.spec.observation_space.dim());
        self.task.observe(&self.core.sim, &mut observation);
        debug_assert_eq!(observation.len(), self.core.spec.observation_space.dim());
        observation
    }
}

impl<T: Task> Env for MujocoEnv<T> {
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        self.core.reset_with_noise(seed, self.timing.reset_noise_scale, T::VELOCITY_NOISE)?;
        self.delay = (self.latency > 0).then(|| Delay::new(self.latency, self.timing.frame_skip));
        self.core.last_obs = self.observe();
        let info = Info { metrics: self.task.reset_metrics(&self.core.sim), ..Info::default() };
        Ok((self.core.last_obs.clone(), info))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let start = self.core.begin_step(action)?;
        let before = self.task.before(&self.core.sim);
        let warnings = match self.core.advance(&start, self.timing.frame_skip, self.delay.as_mut())? {
            StepOutcome::Stepped(warnings) => warnings,
            StepOutcome::BlewUp(step) => return Ok(step),
        };
        let outcome = self.task.after(&mut self.core.sim, &before, &start.action, self.core.spec.dt)?;
        let mut metrics = outcome.metrics;
        // Every task reports the motors' work, integrated over the physics steps, so a cost of
        // transport is measured the same way on every env.
        metrics.push(("mechanical_energy", self.core.sim.last_mechanical_energy));
        let info = Info {
            reward_terms: outcome.reward_terms,
            metrics,
            clipped_actions: start.clipped,
            unstable: false,
            warnings,
        };
        let observation = self.observe();
        Ok(self.core.finish_step(observation, outcome.terminated, info))
    }

    env_core_accessors!();
}
