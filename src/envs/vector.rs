//! N copies of one registered environment stepped together, with automatic reset: the batch
//! interface on-policy learners (PPO) collect rollouts through.
//!
//! Semantics follow Gymnasium's vector environments (`gymnasium.vector`, "same-step" autoreset):
//! when a copy's episode ends, `step` returns the new episode's first observation in its place and
//! keeps the last observation of the ended episode in [`VecStep::final_observations`], so a
//! learner can bootstrap through a truncation.
//!
//! Seeds: episode `k` of copy `i` after `reset(seed)` is reset with [`episode_seed`]`(seed, i, k)`
//! (or the trainer's own scheme, [`VecEnv::with_episode_seeds`]).
//! Each copy is a function of its own seeds and actions alone, whichever thread steps it, so the
//! numbers are the same bit for bit whatever the thread count (tested in `tests/vector_env.rs`).
//!
//! Snapshots: every copy keeps the actions of its episode in progress, so [`VecEnv::snapshot`] is
//! a few numbers per copy plus those actions, and [`VecEnv::restore`] rebuilds every copy's exact
//! state by resetting it with the same seed and replaying them. A training checkpoint taken in the
//! middle of episodes thus resumes bit for bit, for every environment, without reading MuJoCo's
//! state or an environment's internals.
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{check_action, make, Env, EnvConfig, EnvError, EnvSpec, Info};
use crate::numeric::second_core::{self, OwnedHelper};

/// The reset seed of episode `episode` of copy `copy` after a vector reset with `seed`: one ChaCha8
/// stream per copy, one word pair per episode, so distinct copies and seeds get unrelated seeds
/// (not `seed + copy`, which would make copy 1 of seed 0 replay copy 0 of seed 1).
pub fn episode_seed(seed: u64, copy: usize, episode: u64) -> u64 {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(copy as u64);
    rng.set_word_pos(2 * episode as u128);
    rng.next_u64()
}

/// How a vector environment picks reset seeds: `(seed, copy, copies, episode)` to the reset seed of
/// that copy's episode. [`episode_seed`] by default; a trainer may use its own seed domain.
pub type EpisodeSeeds = fn(u64, usize, usize, u64) -> u64;

fn default_seeds(seed: u64, copy: usize, _copies: usize, episode: u64) -> u64 {
    episode_seed(seed, copy, episode)
}

/// Where a vector environment stands: enough to rebuild every copy's state exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct VecEnvSnapshot {
    /// The seed of the last `reset`.
    pub seed: u64,
    /// Per copy: episodes started since that reset.
    pub episodes: Vec<u64>,
    /// Per copy: the actions of its episode in progress, one after another.
    pub actions: Vec<Vec<f64>>,
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

/// One copy and its bookkeeping.
struct Copy {
    env: Box<dyn Env>,
    /// Episodes started since the last vector reset.
    episodes: u64,
    /// The actions of the episode in progress, one after another.
    actions: Vec<f64>,
}

impl Copy {
    fn start_episode(&mut self, seeds: (EpisodeSeeds, u64, usize), index: usize) -> Result<Vec<f64>, EnvError> {
        let (f, seed, copies) = seeds;
        let (obs, _) = self.env.reset(Some(f(seed, index, copies, self.episodes)))?;
        self.episodes += 1;
        self.actions.clear();
        Ok(obs)
    }
}

/// N copies of one environment, stepped across threads.
pub struct VecEnv {
    copies: Vec<Copy>,
    spec: EnvSpec,
    threads: usize,
    seed: u64,
    seeds: EpisodeSeeds,
    /// The helper threads of steps on more than one thread made without a training thread's
    /// helper (one per thread after the caller's), started on the first such step and kept: a
    /// thread spawned per step cost about as much as the half of a small environment's step it
    /// took over (a scoped spawn and join took 98 us on a 2-core KVM guest).
    helpers: Vec<OwnedHelper>,
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
        let copies = (0..copies)
            .map(|_| make(config).map(|env| Copy { env, episodes: 0, actions: Vec::new() }))
            .collect::<Result<Vec<_>, _>>()?;
        let spec = copies[0].env.spec().clone();
        Ok(VecEnv { copies, spec, threads: threads.max(1), seed: 0, seeds: default_seeds, helpers: Vec::new() })
    }

    /// Number of copies.
    pub fn len(&self) -> usize {
        self.copies.len()
    }

    /// Always false: a vector environment has at least one copy.
    pub fn is_empty(&self) -> bool {
        self.copies.is_empty()
    }

    /// The spec every copy shares.
    pub fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    /// Uses `seeds` for every later reset instead of [`episode_seed`].
    pub fn with_episode_seeds(mut self, seeds: EpisodeSeeds) -> VecEnv {
        self.seeds = seeds;
        self
    }

    fn seeding(&self) -> (EpisodeSeeds, u64, usize) {
        (self.seeds, self.seed, self.copies.len())
    }

    /// Changes how many threads step the copies; the results do not change.
    pub fn set_threads(&mut self, threads: usize) {
        self.threads = threads.max(1);
    }

    /// Starts an episode in every copy, copy `i` seeded with `episode_seed(seed, i, 0)`; returns
    /// the first observations.
    pub fn reset(&mut self, seed: u64) -> Result<Vec<Vec<f64>>, EnvError> {
        self.seed = seed;
        let seeding = self.seeding();
        let results = self.run(|i, copy| {
            copy.episodes = 0;
            copy.start_episode(seeding, i)
        });
        results.into_iter().enumerate().map(|(i, r)| r.map_err(|e| in_copy(i, e))).collect()
    }

    /// Where every copy stands (see the module docs).
    pub fn snapshot(&self) -> VecEnvSnapshot {
        VecEnvSnapshot {
            seed: self.seed,
            episodes: self.copies.iter().map(|c| c.episodes).collect(),
            actions: self.copies.iter().map(|c| c.actions.clone()).collect(),
        }
    }

    /// Puts every copy back where `snapshot` found it, by resetting it with the same seed and
    /// replaying its episode's actions; returns the observations to act on next. Fails when the
    /// snapshot does not fit these copies (count, action length) or its replay ends an episode.
    pub fn restore(&mut self, snapshot: &VecEnvSnapshot) -> Result<Vec<Vec<f64>>, EnvError> {
        let dim = self.spec.action_space.dim();
        let n = self.copies.len();
        if snapshot.episodes.len() != n || snapshot.actions.len() != n {
            return Err(EnvError::ActionCount { expected: n, got: snapshot.episodes.len() });
        }
        if let Some(i) = (0..n).find(|&i| snapshot.episodes[i] == 0 || !snapshot.actions[i].len().is_multiple_of(dim)) {
            return Err(in_copy(
                i,
                EnvError::InvalidOption {
                    env: self.spec.name.to_string(),
                    message: "the snapshot has no episode in progress or a partial action".into(),
                },
            ));
        }
        self.seed = snapshot.seed;
        let seeding = self.seeding();
        let results = self.run(|i, copy| {
            copy.episodes = snapshot.episodes[i] - 1;
            let mut obs = copy.start_episode(seeding, i)?;
            for action in snapshot.actions[i].chunks(dim) {
                let s = copy.env.step(action)?;
                if s.done() {
                    return Err(EnvError::InvalidOption {
                        env: copy.env.spec().name.to_string(),
                        message: "replaying the snapshot ended the episode: it was taken with another \
                                  environment or build"
                            .into(),
                    });
                }
                obs = s.observation;
            }
            copy.actions.extend_from_slice(&snapshot.actions[i]);
            Ok(obs)
        });
        results.into_iter().enumerate().map(|(i, r)| r.map_err(|e| in_copy(i, e))).collect()
    }

    /// Steps every copy with its action (`actions[i]` for copy `i`) and resets the copies whose
    /// episode ended. Every action's length and finiteness is checked before any copy steps, so a
    /// bad action leaves every copy where it was.
    pub fn step(&mut self, actions: &[Vec<f64>]) -> Result<VecStep, EnvError> {
        if actions.len() != self.copies.len() {
            return Err(EnvError::ActionCount { expected: self.copies.len(), got: actions.len() });
        }
        for (i, a) in actions.iter().enumerate() {
            check_action(&self.spec.action_space, a).map_err(|e| in_copy(i, e))?;
        }
        let seeding = self.seeding();
        let results = self.run(|i, copy| step_copy(copy, &actions[i], seeding, i));
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

    /// Copy `i` itself (to read its simulation state).
    pub fn env(&self, i: usize) -> &dyn Env {
        self.copies[i].env.as_ref()
    }

    /// `f` on every copy, results in copy order. With two threads (the calling thread's helper,
    /// `numeric::second_core`, or this environment's own helper when `threads` is 2) both take
    /// copies as they come, from opposite ends; with more, copies are split into `threads`
    /// contiguous blocks, the caller stepping the first and this environment's kept helpers the
    /// others. Every thread computes with the caller's floating-point mode (flush-to-zero), so a
    /// copy computes the same bits on any thread.
    fn run<R: Send>(&mut self, f: impl Fn(usize, &mut Copy) -> R + Sync) -> Vec<R> {
        let n = self.copies.len();
        let threads = self.threads.min(n);
        if threads == 1 {
            return self.copies.iter_mut().enumerate().map(|(i, c)| f(i, c)).collect();
        }
        let training_helper = second_core::has_helper();
        if training_helper || threads == 2 {
            // A thread that already runs takes part, instead of one spawned per step: the training
            // thread's helper (`runtime::Runtime` with two threads), or ours. Each takes copies
            // one at a time, while any are left: the caller from the first copy up, the helper from
            // the last one down. So a thread held up (a copy's reset, another process on its core)
            // steps fewer of them instead of keeping the other waiting, and a copy is stepped by
            // the same thread from step to step, its simulation's data still in that core's cache.
            let slots: Vec<Mutex<(&mut Copy, Option<R>)>> =
                self.copies.iter_mut().map(|c| Mutex::new((c, None))).collect();
            let taken = AtomicUsize::new(0);
            let step_slot = |i: usize| {
                let mut slot = slots[i].lock().unwrap_or_else(|p| p.into_inner());
                let result = f(i, slot.0);
                slot.1 = Some(result);
            };
            // Every copy is granted once (`taken` counts grants), so the two ends never meet.
            let granted = |_: &usize| taken.fetch_add(1, Ordering::Relaxed) < n;
            let from_first = || (0..n).take_while(granted).for_each(step_slot);
            let from_last = || (0..n).rev().take_while(granted).for_each(step_slot);
            if training_helper {
                second_core::join(from_first, from_last);
            } else {
                kept(&mut self.helpers, 1)[0].join(from_first, from_last);
            }
            return slots
                .into_iter()
                .map(|m| m.into_inner().unwrap_or_else(|p| p.into_inner()).1.expect("every copy was stepped"))
                .collect();
        }
        let size = n.div_ceil(threads);
        let mut blocks: Vec<(usize, &mut [Copy])> =
            self.copies.chunks_mut(size).enumerate().map(|(b, copies)| (b * size, copies)).collect();
        let mut results: Vec<Vec<R>> = blocks.iter().map(|_| Vec::new()).collect();
        let helpers = kept(&mut self.helpers, blocks.len() - 1);
        run_blocks(helpers, &mut blocks, &mut results, &f);
        results.into_iter().flatten().collect()
    }
}

/// The first `count` of `helpers`, started as needed.
fn kept(helpers: &mut Vec<OwnedHelper>, count: usize) -> &mut [OwnedHelper] {
    while helpers.len() < count {
        helpers.push(OwnedHelper::start());
    }
    &mut helpers[..count]
}

/// Block 0 (first copy's index, copies) on this thread and block `k` on `helpers[k - 1]`, all at
/// once, each block's results into its slot of `out`. Returns when every block is done.
fn run_blocks<R: Send>(
    helpers: &mut [OwnedHelper],
    blocks: &mut [(usize, &mut [Copy])],
    out: &mut [Vec<R>],
    f: &(impl Fn(usize, &mut Copy) -> R + Sync),
) {
    let step_block = |(first, copies): &mut (usize, &mut [Copy]), out: &mut Vec<R>| {
        *out = copies.iter_mut().enumerate().map(|(j, c)| f(*first + j, c)).collect();
    };
    let Some((helper, others)) = helpers.split_last_mut() else {
        return step_block(&mut blocks[0], &mut out[0]);
    };
    // the last block on the last helper, the rest (nested, one helper fewer) meanwhile here
    let (last_block, rest) = blocks.split_last_mut().expect("a block per helper and one more");
    let (last_out, rest_out) = out.split_last_mut().expect("a slot per block");
    helper.join(|| run_blocks(others, rest, rest_out, f), || step_block(last_block, last_out));
}

fn step_copy(
    copy: &mut Copy,
    action: &[f64],
    seeding: (EpisodeSeeds, u64, usize),
    index: usize,
) -> Result<CopyStep, EnvError> {
    let step = copy.env.step(action)?;
    copy.actions.extend_from_slice(action);
    let (observation, final_observation) = if step.done() {
        (copy.start_episode(seeding, index)?, Some(step.observation))
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::thread::{current, sleep, ThreadId};
    use std::time::Duration;

    /// The thread that ran `run`'s closure for each copy, each copy taking long enough that the
    /// helpers pick their blocks up (a block not picked up in time is run by the caller).
    fn threads_of_copies(env: &mut VecEnv) -> Vec<ThreadId> {
        env.run(|_, _| {
            sleep(Duration::from_millis(20));
            current().id()
        })
    }

    #[test]
    fn more_than_two_threads_step_their_blocks_on_kept_helpers() {
        std::thread::spawn(|| {
            let mut env = VecEnv::new(&EnvConfig::new("inverted-pendulum"), 5, 3).unwrap();
            let first = threads_of_copies(&mut env);
            // blocks of 2, 2 and 1 copies: the caller's first, then a helper each
            let me = current().id();
            assert_eq!(&first[..2], &[me, me]);
            assert!(first[2] == first[3] && first[2] != me && first[4] != me && first[4] != first[2], "{first:?}");
            // the same threads on the next step: kept, not spawned anew
            assert_eq!(threads_of_copies(&mut env), first);
        })
        .join()
        .unwrap();
    }
}
