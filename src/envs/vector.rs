//! N copies of one registered environment stepped together, with automatic reset: the batch
//! interface on-policy learners (PPO) collect rollouts through.
//!
//! Semantics follow Gymnasium's vector environments (`gymnasium.vector`, "same-step" autoreset):
//! when a copy's episode ends, `step` returns the new episode's first observation in its place and
//! keeps the last observation of the ended episode in [`VecStep::final_observations`], so a
//! learner can bootstrap through a truncation.
//!
//! Seeds: `reset(seed)` seeds copy `i` with [`copy_seed`]`(seed, i)`; later episodes of a copy
//! continue that copy's own random stream. Each copy is a function of its own seed and actions
//! alone, and the copies are split over threads in contiguous blocks, so the numbers are the
//! same bit for bit whatever the thread count (tested in `tests/vector_env.rs`).
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{make, Env, EnvConfig, EnvError, EnvSpec, Info};
use crate::numeric::denormals::{float_mode, set_float_mode};

/// The reset seed of copy `copy` for a vector reset with `seed`: distinct copies and distinct
/// seeds get unrelated streams (not `seed + copy`, which would make copy 1 of seed 0 replay
/// copy 0 of seed 1).
pub fn copy_seed(seed: u64, copy: usize) -> u64 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(copy as u64);
    rng.next_u64()
}

/// What one vector step returned, one entry per copy.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct VecStep {
    /// The observation to act on next: after the step, or the new episode's first one where
    /// the episode ended.
    pub observations: Vec<Vec<f64>>,
    /// Each copy's reward for the step.
    pub rewards: Vec<f64>,
    /// The copy's episode reached a terminal state.
    pub terminated: Vec<bool>,
    /// The copy's episode was cut short (time limit or instability).
    pub truncated: Vec<bool>,
    /// The last observation of an episode that ended this step, for the copies whose did.
    pub final_observations: Vec<Option<Vec<f64>>>,
    /// Each copy's step details (of the ended episode's last step where one ended).
    pub infos: Vec<Info>,
}

/// What stepping one copy gave.
struct CopyStep {
    observation: Vec<f64>,
    reward: f64,
    terminated: bool,
    truncated: bool,
    final_observation: Option<Vec<f64>>,
    info: Info,
}

/// N copies of one environment, stepped across threads.
pub struct VecEnv {
    envs: Vec<Box<dyn Env>>,
    spec: EnvSpec,
    threads: usize,
}

impl VecEnv {
    /// `copies` copies of the configured environment, stepped on up to `threads` threads.
    pub fn new(config: &EnvConfig, copies: usize, threads: usize) -> Result<VecEnv, EnvError> {
        if copies == 0 {
            return Err(EnvError::InvalidOption {
                env: config.name.clone(),
                message: "a vector environment needs at least one copy".into(),
            });
        }
        let envs = (0..copies).map(|_| make(config)).collect::<Result<Vec<_>, _>>()?;
        let spec = envs[0].spec().clone();
        Ok(VecEnv { envs, spec, threads: threads.max(1) })
    }

    /// Number of copies.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// Always false: a vector environment has at least one copy.
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// The spec every copy shares.
    pub fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    /// Changes how many threads step the copies; the results do not change.
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
    }

    /// Starts an episode in every copy, copy `i` seeded with `copy_seed(seed, i)`; returns the
    /// first observations.
    pub fn reset(&mut self, seed: u64) -> Result<Vec<Vec<f64>>, EnvError> {
        let results = self.run(|i, env| env.reset(Some(copy_seed(seed, i))).map(|(obs, _)| obs));
        results.into_iter().enumerate().map(|(i, r)| r.map_err(|e| in_copy(i, e))).collect()
    }

    /// Steps every copy with its action (`actions[i]` for copy `i`) and resets the copies whose
    /// episode ended. Every action's length and finiteness is checked before any copy steps, so a
    /// bad action leaves every copy where it was.
    pub fn step(&mut self, actions: &[Vec<f64>]) -> Result<VecStep, EnvError> {
        if actions.len() != self.envs.len() {
            return Err(EnvError::ActionCount { expected: self.envs.len(), got: actions.len() });
        }
        let dim = self.spec.action_space.dim();
        for (i, a) in actions.iter().enumerate() {
            if a.len() != dim {
                return Err(in_copy(i, EnvError::ActionLength { expected: dim, got: a.len() }));
            }
            if let Some(index) = a.iter().position(|x| !x.is_finite()) {
                return Err(in_copy(i, EnvError::NonFiniteAction { index, value: a[index] }));
            }
        }
        let results = self.run(|i, env| step_copy(env, &actions[i]));
        let mut out = VecStep::default();
        for (i, r) in results.into_iter().enumerate() {
            let s = r.map_err(|e| in_copy(i, e))?;
            out.observations.push(s.observation);
            out.rewards.push(s.reward);
            out.terminated.push(s.terminated);
            out.truncated.push(s.truncated);
            out.final_observations.push(s.final_observation);
            out.infos.push(s.info);
        }
        Ok(out)
    }

    /// The copies themselves (to read their simulation state).
    pub fn envs(&self) -> &[Box<dyn Env>] {
        &self.envs
    }

    /// `f` on every copy, results in copy order. Copies are split into `threads` contiguous
    /// blocks; worker threads take the caller's floating-point mode (flush-to-zero), so a copy
    /// computes the same bits on any thread.
    fn run<R: Send>(&mut self, f: impl Fn(usize, &mut dyn Env) -> R + Sync) -> Vec<R> {
        let n = self.envs.len();
        let threads = self.threads.min(n);
        if threads == 1 {
            return self.envs.iter_mut().enumerate().map(|(i, e)| f(i, e.as_mut())).collect();
        }
        let block = n.div_ceil(threads);
        let mode = float_mode();
        let f = &f;
        std::thread::scope(|scope| {
            let mut blocks = self.envs.chunks_mut(block).enumerate();
            // The caller steps the first block itself instead of waiting idle.
            let (_, first) = blocks.next().expect("at least one copy");
            let handles: Vec<_> = blocks
                .map(|(b, envs)| {
                    scope.spawn(move || {
                        set_float_mode(mode);
                        envs.iter_mut().enumerate().map(|(j, e)| f(b * block + j, e.as_mut())).collect::<Vec<R>>()
                    })
                })
                .collect();
            let mut out: Vec<R> = first.iter_mut().enumerate().map(|(j, e)| f(j, e.as_mut())).collect();
            for h in handles {
                out.extend(h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)));
            }
            out
        })
    }
}

fn step_copy(env: &mut dyn Env, action: &[f64]) -> Result<CopyStep, EnvError> {
    let step = env.step(action)?;
    let (observation, final_observation) = if step.done() {
        let (first, _) = env.reset(None)?;
        (first, Some(step.observation))
    } else {
        (step.observation, None)
    };
    Ok(CopyStep {
        observation,
        reward: step.reward,
        terminated: step.terminated,
        truncated: step.truncated,
        final_observation,
        info: step.info,
    })
}

fn in_copy(copy: usize, error: EnvError) -> EnvError {
    EnvError::InCopy { copy, source: Box::new(error) }
}
