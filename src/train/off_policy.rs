//! The off-policy training loop (TD3, DDPG, SAC, CrossQ, the branching DQN), top to bottom:
//! act (uniformly at random during the warm-up), step, store the transition, update from a
//! replay minibatch, evaluate, checkpoint. Its checkpoints resume bit for bit: the networks and
//! their optimisers, the replay buffer, the RNG's position and the episode in progress.
use std::path::{Path, PathBuf};

use anyhow::Result;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::checkpoint::POLICY_BUDGETS;
use super::checkpoint::{self, TrainState};
use super::control::{Outcome, RunControl, RunSummary};
use super::evaluate::evaluate_at;
use super::fault::{self, Point};
use super::metrics::MetricsRow;
use super::policy_ref::PolicyRef;
use super::run_config::RunConfig;
use super::scaffold::{self, check_bounded_actions, finish_run, learner_reward, save_budget_policy, Scaffold};
use super::seeds::{init_rng, train_episode_seed, training_rng, RngState};
use super::selection::BestPolicy;
use crate::agents::{make_learner_on, Batch, Losses, OffPolicyAgent, ReplayBuffer, TrainConfig};
use crate::device::ComputeDevice;
use crate::envs::{make, Env, EnvConfig};
use crate::policy::to_env_action;

/// Starts a new off-policy run in `run_dir` (checked to be free), from `init_from`'s weights if
/// given.
pub(super) fn train(
    run_dir: &Path,
    run: &RunConfig,
    init_from: Option<&PolicyRef>,
    control: &RunControl,
) -> Result<RunSummary> {
    let mut trainer = Trainer::new(run_dir, run, control.device)?;
    if let Some(policy) = init_from {
        policy.load_into_env(trainer.agent.as_ref(), &run.env)?;
    }
    let _lock = scaffold::create_run_dir(run_dir, run, control)?;
    trainer.run(control)
}

/// Continues an off-policy run from `ckpt`, with the run's metrics rows up to it.
pub(super) fn resume(
    run_dir: &Path,
    run: &RunConfig,
    ckpt: &Path,
    metrics: Vec<MetricsRow>,
    control: &RunControl,
) -> Result<RunSummary> {
    let mut trainer = Trainer::new(run_dir, run, control.device)?;
    let (state, buffer) = checkpoint::load_all(ckpt, trainer.agent.as_mut())?;
    trainer.buffer = buffer;
    trainer.rng = state.rng.restore()?;
    trainer.step = state.step;
    trainer.episodes = state.episodes;
    trainer.wall_offset = state.wall_time;
    trainer.losses = state.losses;
    trainer.best_eval = state.best_eval_mean;
    trainer.best_policy = BestPolicy::resumed(trainer.cfg.budget_policy, state.best_policy);
    trainer.metrics = metrics;
    scaffold::record_stretch(run_dir, state.step, control)?;
    trainer.run(control)
}

struct Trainer {
    run_dir: PathBuf,
    env_config: EnvConfig,
    cfg: TrainConfig,
    seed: u64,
    env: Box<dyn Env>,
    eval_env: Box<dyn Env>,
    agent: Box<dyn OffPolicyAgent>,
    buffer: ReplayBuffer,
    batch: Batch,
    rng: ChaCha8Rng,
    step: u64,
    episodes: u64,
    wall_offset: f64,
    metrics: Vec<MetricsRow>,
    /// The latest update's losses, carried by the rows until the next update.
    losses: Option<Losses>,
    /// The best in-training evaluation mean so far.
    best_eval: Option<f64>,
    /// The actor `budget_policy = "best"` keeps.
    best_policy: BestPolicy,
    /// False when fine-tuning: the observation statistics come with the initial weights.
    fit_observations: bool,
}

impl Trainer {
    fn new(run_dir: &Path, run: &RunConfig, device: ComputeDevice) -> Result<Trainer> {
        let env = make(&run.env)?;
        check_bounded_actions(&run.env.name, &env.spec().action_space, run.train.algo)?;
        let eval_env = make(&run.env)?;
        let (obs_dim, act_dim) = (env.spec().observation_space.dim(), env.spec().action_space.dim());
        let agent = make_learner_on(&run.train, obs_dim, act_dim, &mut init_rng(run.seed), device)?;
        Ok(Trainer {
            run_dir: run_dir.to_path_buf(),
            env_config: run.env.clone(),
            cfg: run.train.clone(),
            seed: run.seed,
            buffer: ReplayBuffer::new(run.train.buffer_capacity, obs_dim, act_dim),
            batch: Batch::new(run.train.batch_size, obs_dim, act_dim),
            env,
            eval_env,
            agent,
            rng: training_rng(run.seed),
            step: 0,
            episodes: 0,
            wall_offset: 0.0,
            metrics: Vec::new(),
            losses: None,
            best_eval: None,
            best_policy: BestPolicy::new(run.train.budget_policy),
            fit_observations: run.init_from.is_none(),
        })
    }

    fn run(&mut self, control: &RunControl) -> Result<RunSummary> {
        let cfg = self.cfg.clone();
        let recording = scaffold::open_recording(control)?;
        let mut sc =
            Scaffold::start(control, &self.run_dir, &self.env_config, cfg.total_steps, self.step, recording.as_ref())?;
        let act_dim = self.env.spec().action_space.dim();
        let mut next_checkpoint = (self.step / cfg.checkpoint_every + 1) * cfg.checkpoint_every;
        let mut obs: Vec<f64> = Vec::new();
        let mut need_reset = true;
        let (mut ep_return, mut ep_len) = (0.0, 0u64);

        let outcome = loop {
            if self.step >= cfg.total_steps || sc.solved(control) {
                break Outcome::Finished;
            }
            let stop_at_boundary = sc.signals.at_episode_end() || control.stop_after.is_some_and(|s| self.step >= s);
            if sc.signals.now() || (need_reset && stop_at_boundary) {
                break Outcome::Stopped;
            }
            if need_reset {
                (obs, _) = self.env.reset(Some(train_episode_seed(self.seed, self.episodes)))?;
                self.episodes += 1;
                self.agent.begin_episode();
                (ep_return, ep_len, need_reset) = (0.0, 0, false);
            }

            // Act: random during warm-up, then the agent's exploratory action.
            let obs32: Vec<f32> = obs.iter().map(|&v| v as f32).collect();
            let action: Vec<f32> = if self.step < cfg.warmup_steps {
                (0..act_dim).map(|_| self.rng.random_range(-1.0f32..=1.0)).collect()
            } else {
                self.agent.explore(&obs32, &mut self.rng)?
            };
            let s = self.env.step(&to_env_action(self.env.as_ref(), &action))?;
            self.step += 1;
            fault::reach(Point::Step);

            if s.info.unstable {
                // Not a real transition: drop it and start over.
                sc.bar.println(format!(
                    "warning: physics unstable at step {}; episode dropped ({:?})",
                    self.step, s.info.warnings
                ));
                need_reset = true;
            } else {
                let next32: Vec<f32> = s.observation.iter().map(|&v| v as f32).collect();
                let learner_reward = (learner_reward(s.reward, s.terminated, &cfg) * cfg.reward_scale) as f32;
                self.buffer.add(&obs32, &action, learner_reward, &next32, s.terminated, s.truncated);
                ep_return += s.reward;
                ep_len += 1;
                if s.done() {
                    self.metrics.push(MetricsRow {
                        episode_return: Some(ep_return),
                        episode_length: Some(ep_len),
                        ..MetricsRow::progress(
                            "episode",
                            self.step,
                            self.losses,
                            sc.rate(self.step),
                            sc.wall(self.wall_offset),
                        )
                    });
                    if let Some(r) = &sc.recorder {
                        r.curves(self.metrics.last().unwrap())?;
                    }
                    if let Some(e) = sc.events.as_mut() {
                        e.row(self.metrics.last().unwrap())?;
                    }
                    need_reset = true;
                } else {
                    obs = s.observation;
                }
            }

            // Learn.
            if self.fit_observations && self.step == cfg.learning_starts.max(1) {
                self.agent.fit_observations(&self.buffer)?;
            }
            if self.step >= cfg.learning_starts && self.buffer.len() >= cfg.batch_size.min(self.buffer.capacity()) {
                for _ in 0..cfg.updates_per_step {
                    self.buffer.sample_into(&mut self.batch, &mut self.rng);
                    let l = self.agent.update(&self.batch, &mut self.rng)?;
                    // Delayed updates leave actor/alpha unset: keep their latest values.
                    let previous = self.losses.unwrap_or_default();
                    self.losses =
                        Some(Losses { actor: l.actor.or(previous.actor), alpha: l.alpha.or(previous.alpha), ..l });
                }
            }

            // The actor at each reporting budget, for the report's per-budget rows. Under
            // a `budget_policy` that selects it waits for this step's evaluation, which may win.
            let at_budget = POLICY_BUDGETS.contains(&self.step) || self.step == cfg.total_steps;
            if at_budget && !cfg.budget_policy.selects() {
                save_budget_policy(&self.run_dir, self.step, self.agent.as_ref())?;
            }

            // Evaluate.
            if scaffold::crossed(self.step - 1, self.step, cfg.eval_every) || self.step == cfg.total_steps {
                let e = evaluate_at(self.agent.as_ref(), self.eval_env.as_mut(), &cfg, self.seed, self.step)?;
                self.best_eval = Some(self.best_eval.map_or(e.mean(), |b: f64| b.max(e.mean())));
                if cfg.budget_policy.selects() {
                    self.best_policy.consider(&self.run_dir, self.step, &e, self.agent.as_ref())?;
                }
                let row =
                    MetricsRow::progress("eval", self.step, self.losses, sc.rate(self.step), sc.wall(self.wall_offset));
                sc.evaluated(&self.run_dir, &mut self.metrics, row, e, control, self.agent.as_ref(), self.seed)?;
            }
            if at_budget && cfg.budget_policy.selects() {
                self.best_policy.save_budget(&self.run_dir, self.step, self.agent.as_ref())?;
            }
            sc.bar.set_position(self.step);

            // Checkpoint at the first episode boundary past each multiple of checkpoint_every.
            if need_reset && self.step >= next_checkpoint {
                self.save(true, sc.wall(self.wall_offset))?;
                next_checkpoint = (self.step / cfg.checkpoint_every + 1) * cfg.checkpoint_every;
            }
        };
        sc.end()?;
        // A run finished early (target_return, an evaluation hook) keeps its actor at the step
        // it reached, as the on-policy loop does; budgets and the full budget are saved above.
        if outcome == Outcome::Finished && !POLICY_BUDGETS.contains(&self.step) && self.step != cfg.total_steps {
            if cfg.budget_policy.selects() {
                self.best_policy.save_budget(&self.run_dir, self.step, self.agent.as_ref())?
            } else {
                save_budget_policy(&self.run_dir, self.step, self.agent.as_ref())?
            }
        }
        let checkpoint = self.save(need_reset, sc.wall(self.wall_offset))?;
        let summary = sc.summary(&self.run_dir, outcome, self.step, self.best_eval, checkpoint);
        finish_run(&self.metrics, recording, summary)
    }

    fn save(&mut self, at_episode_boundary: bool, wall_time: f64) -> Result<PathBuf> {
        let state = TrainState {
            step: self.step,
            episodes: self.episodes,
            at_episode_boundary,
            wall_time,
            rng: RngState::of(&self.rng),
            optimizer_steps: Default::default(),
            counters: Default::default(),
            losses: self.losses,
            best_eval_mean: self.best_eval,
            best_policy: self.best_policy.best,
        };
        let saved = checkpoint::save(&self.run_dir, self.agent.as_mut(), &self.buffer, &state, &self.metrics)?;
        self.best_policy.mark_checkpointed(&self.run_dir)?;
        Ok(saved)
    }
}
