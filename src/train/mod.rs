//! Training runs: the collection loop (one place, top to bottom), the run directory, evaluation
//! and checkpoints.
//!
//! Run directory: `config.toml` (every hyperparameter, env options, seed, crate version, git
//! commit), `metrics.csv`, `provenance.csv` (the machine of every stretch), `checkpoints/`.
//! Everything is written atomically.
mod buffer_file;
pub mod checkpoint;
pub mod config;
pub mod evaluate;
pub(crate) mod fault;
pub mod metrics;
mod on_policy;
pub mod policy_ref;
pub mod provenance;
mod recording;
pub mod run_config;
pub mod run_dir;
pub(crate) mod run_lock;
mod scaffold;
pub mod seeds;
pub mod stop;
mod tensorboard;

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::agents::{make_learner_on, Agent, Batch, Losses, OffPolicyAgent, ReplayBuffer, TrainConfig};
use crate::device::ComputeDevice;
use crate::envs::{make, Env, EnvConfig};
use crate::io::write_bytes_atomic;
use crate::policy::to_env_action;
use crate::record::Recording;
use checkpoint::TrainState;
use evaluate::{evaluate, Evaluation};
use fault::Point;
use metrics::MetricsRow;
use recording::{TrainingClips, TrainingRecorder};
use scaffold::Scaffold;
use seeds::{init_rng, train_episode_seed, training_rng, RngState};

pub use policy_ref::{resolve_policy, PolicyRef};
pub use run_config::{read_run_config, RunConfig};
pub use run_dir::{
    budget_policy_steps, export_policy, has_policy, import_policy, load_budget_policy, load_policy, run_progress,
    RunProgress,
};

/// The step budgets results are reported at (Henderson et al. 2018 and the TD3/SAC papers report
/// 100k-1M). A run writes its actor at each one it passes, and at its own last step, to
/// `policies/step-<N>.safetensors`, so a report evaluates every run at the same budget even when
/// some went further.
pub(crate) const POLICY_BUDGETS: [u64; 3] = [100_000, 300_000, 1_000_000];
pub(crate) const BUDGET_POLICY_DIR: &str = "policies";

pub(crate) fn budget_policy_path(run_dir: &Path, step: u64) -> PathBuf {
    run_dir.join(BUDGET_POLICY_DIR).join(format!("step-{step}.safetensors"))
}

/// How a call to `train`/`resume` ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Reached its step budget.
    Finished,
    /// Stopped early (a signal, see `stop`, or `stop_after`); `resume` continues it.
    Stopped,
    /// `resume` found the run already finished and changed nothing.
    AlreadyFinished,
}

/// What a call to `train` or `resume` did.
#[derive(Debug)]
pub struct RunSummary {
    /// The run directory.
    pub run_dir: PathBuf,
    /// How it ended.
    pub outcome: Outcome,
    /// Environment steps done.
    pub steps: u64,
    /// The latest evaluation, if any ran.
    pub last_eval: Option<Evaluation>,
    /// The best evaluation mean so far.
    pub best_eval_mean: Option<f64>,
    /// The newest checkpoint.
    pub checkpoint: PathBuf,
}

/// Knobs that do not change what is computed, only when to stop and what to show.
#[derive(Debug, Clone, Default)]
pub struct RunControl {
    /// Show a progress bar.
    pub show_progress: bool,
    /// Stop (with a checkpoint) at the first episode boundary at or after this step.
    pub stop_after: Option<u64>,
    /// Finish early once an evaluation's mean return reaches this ("solved").
    pub target_return: Option<f64>,
    /// Write a rerun recording here: learning curves, and one evaluation episode (the first
    /// evaluation seed, acted deterministically) at every evaluation.
    pub record: Option<PathBuf>,
    /// Record a rollout at every this many evaluations (0 or 1: every one). A 1000-step Ant
    /// rollout takes about 3 MB.
    pub record_every: u64,
    /// Film the deterministic evaluation episode at every this many evaluations into
    /// `videos/eval-step-<N>.mp4` (320x240, on an environment of its own: the run's numbers are
    /// the same with or without). None: no clips.
    pub video_every: Option<u64>,
    /// Write TensorBoard event files here: every metrics row's values as scalars
    /// (`train::tensorboard`).
    pub tensorboard: Option<PathBuf>,
    /// 2: the training thread gets a helper thread, and the large dense layers of every update
    /// run in two halves on both cores (`numeric::second_core`); results are the same bit for
    /// bit. 0 or 1: the training thread alone (parallel runs, e.g. a sweep's jobs).
    pub threads: usize,
    /// Where the networks train: the CPU's exact fused path (the default), or a CUDA device
    /// through the device-generic path (`agents::generic`), whose numbers differ from the CPU's
    /// in the last bits.
    pub device: ComputeDevice,
    /// Called after every in-training evaluation (after its metrics row is written); returning
    /// `true` finishes the run there, as reaching `target_return` does. The time it takes counts
    /// in the run's wall time.
    pub on_evaluation: Option<EvaluationHook>,
}

/// What an [`EvaluationHook`] sees.
pub struct EvaluationEvent<'a> {
    /// Environment steps done.
    pub step: u64,
    /// The run's wall time (s) when the evaluation finished, as in `metrics.csv`.
    pub wall_time: f64,
    /// The evaluation just done.
    pub evaluation: &'a Evaluation,
    /// The agent, as trained so far.
    pub agent: &'a dyn Agent,
}

/// A caller's check after each evaluation, e.g. held-out episodes against a threshold
/// (`benches/time_to_walk.rs`). Returns whether to finish the run.
#[derive(Clone)]
#[allow(clippy::type_complexity)]
pub struct EvaluationHook(pub std::sync::Arc<dyn Fn(&EvaluationEvent<'_>) -> Result<bool> + Send + Sync>);

impl std::fmt::Debug for EvaluationHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("EvaluationHook")
    }
}

/// Every agent acts in [-1, 1]^n mapped onto the action space's bounds (the branching DQN's
/// levels are spread over them), so an unbounded action dimension is refused up front.
pub(crate) fn check_bounded_actions(env: &str, space: &crate::envs::BoxSpace, algo: crate::agents::Algo) -> Result<()> {
    if let Some(i) = (0..space.dim()).find(|&i| !(space.low[i].is_finite() && space.high[i].is_finite())) {
        bail!(
            "{env}'s action dimension {i} is unbounded ([{}, {}]): {} acts within finite bounds{}",
            space.low[i],
            space.high[i],
            algo.name(),
            if algo == crate::agents::Algo::Dqn { " (its levels are spread over each dimension's range)" } else { "" }
        );
    }
    Ok(())
}

/// The training progress bar (hidden unless `show`), at `position` of `total` steps.
fn progress_bar(show: bool, total: u64, position: u64) -> ProgressBar {
    let bar = if show { ProgressBar::new(total) } else { ProgressBar::hidden() };
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} steps, {per_sec} {msg}")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_position(position);
    bar
}

/// Writes the actor as the run's policy at `step` (`policies/step-<step>.safetensors`).
fn save_budget_policy(run_dir: &Path, step: u64, agent: &dyn Agent) -> Result<()> {
    let dir = run_dir.join(BUDGET_POLICY_DIR);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    checkpoint::save_actor(&budget_policy_path(run_dir, step), agent)
}

/// Appends an evaluation's row (`row` with `evaluation`'s figures), rewrites `metrics.csv`, logs
/// the row to the recording, with a rollout of the policy at every `control.record_every`-th
/// evaluation, and runs `control`'s evaluation hook. Returns whether the hook finishes the run.
#[allow(clippy::too_many_arguments)]
fn log_evaluation(
    run_dir: &Path,
    metrics: &mut Vec<MetricsRow>,
    row: MetricsRow,
    evaluation: &Evaluation,
    recorder: Option<&mut TrainingRecorder>,
    clips: Option<&mut TrainingClips>,
    mut events: Option<&mut tensorboard::EventWriter>,
    control: &RunControl,
    agent: &dyn Agent,
    run_seed: u64,
) -> Result<bool> {
    let (step, wall_time) = (row.step, row.wall_time);
    metrics.push(row.with_evaluation(evaluation));
    metrics::write(&run_dir.join(metrics::FILE), metrics)?;
    if let Some(e) = events.as_deref_mut() {
        e.row(metrics.last().expect("just pushed"))?;
    }
    if let Some(c) = clips {
        let evaluations = metrics.iter().filter(|m| m.kind == "eval").count() as u64;
        if let (Some(clip), Some(e)) = (c.evaluation(agent, step, run_seed, evaluations)?, events) {
            e.gif("eval/video", step, &clip.gif, clip.width, clip.height)?;
        }
    }
    if let Some(r) = recorder {
        r.curves(metrics.last().expect("just pushed"))?;
        let evaluations = metrics.iter().filter(|m| m.kind == "eval").count() as u64;
        if (evaluations - 1).is_multiple_of(control.record_every.max(1)) {
            r.evaluation_rollout(agent, step, run_seed)?;
        }
    }
    match &control.on_evaluation {
        Some(hook) => (hook.0)(&EvaluationEvent { step, wall_time, evaluation, agent }),
        None => Ok(false),
    }
}

/// What both training loops do once their last checkpoint is written: rewrite the run's
/// `metrics.csv` in full, move the recording (if any) to its name, and hand the summary back.
fn finish_run(metrics: &[MetricsRow], recording: Option<Recording>, summary: RunSummary) -> Result<RunSummary> {
    metrics::write(&summary.run_dir.join(metrics::FILE), metrics)?;
    if let Some(r) = recording {
        r.finish()?;
    }
    Ok(summary)
}

/// The commit this binary was built from (build.rs), not whatever the source tree holds now.
pub(crate) fn git_commit() -> Option<String> {
    option_env!("LOCOBENCH_GIT_COMMIT").map(str::to_string)
}

/// Starts a new run in `run_dir`. An existing non-empty directory is an error unless `force`.
pub fn train(
    env: EnvConfig,
    train: TrainConfig,
    seed: u64,
    run_dir: &Path,
    init_from: Option<&Path>,
    force: bool,
    control: &RunControl,
) -> Result<RunSummary> {
    train.validate()?;
    let mut env = env;
    env.options = env.resolved_options()?;
    // Before --force may remove the directory under a running trainer.
    run_lock::refuse_if_running(run_dir)?;
    // A lock that no process holds and a half-written temporary file (a trainer killed before
    // it wrote its config) are no run.
    let holds_something = |dir: &Path| -> Result<bool> {
        Ok(std::fs::read_dir(dir)?.flatten().any(|e| {
            let name = e.file_name();
            name != run_lock::LOCK_FILE && !crate::io::is_temporary_name(&name.to_string_lossy())
        }))
    };
    if run_dir.exists() && holds_something(run_dir)? {
        if !force {
            bail!(
                "run directory {} already exists; use --force to overwrite it or --resume to continue it",
                run_dir.display()
            );
        }
        std::fs::remove_dir_all(run_dir).with_context(|| format!("removing {}", run_dir.display()))?;
    }
    // Any policy reference: a checkpoint fine-tunes every network, an actor alone (a budget or
    // exported policy) starts the critics afresh.
    let init = init_from.map(|p| resolve_policy(p, None)).transpose()?;
    let run = RunConfig {
        format: run_config::FORMAT,
        seed,
        crate_version: env!("CARGO_PKG_VERSION").to_string(),
        git_commit: git_commit(),
        init_from: init.as_ref().map(|p| p.path().display().to_string()),
        env,
        train,
    };
    if run.train.algo.is_on_policy() {
        control.device.open()?;
        std::fs::create_dir_all(run_dir)?;
        let _lock = run_lock::RunLock::acquire(run_dir)?;
        write_bytes_atomic(&run_dir.join("config.toml"), run.to_toml()?.as_bytes())?;
        provenance::append(
            run_dir,
            provenance::Stretch::here(0, control.threads, run.git_commit.as_deref()).on(control.device),
        )?;
        return on_policy::train(run_dir, &run, init.as_ref(), control);
    }
    let mut trainer = Trainer::new(run_dir, &run, control.device)?;
    if let Some(policy) = &init {
        policy.load_into(trainer.agent.as_ref())?;
    }
    std::fs::create_dir_all(run_dir)?;
    let _lock = run_lock::RunLock::acquire(run_dir)?;
    write_bytes_atomic(&run_dir.join("config.toml"), run.to_toml()?.as_bytes())?;
    provenance::append(
        run_dir,
        provenance::Stretch::here(0, control.threads, run.git_commit.as_deref()).on(control.device),
    )?;
    trainer.run(control)
}

/// Raises a run's step budget so that `resume` trains it on, e.g. a finished 100k run to 300k.
/// Nothing in training depends on the budget, so the result equals a run started with the larger
/// budget when the newest checkpoint ends an episode (HalfCheetah's 1000-step episodes at any
/// multiple of 1000); otherwise the episode in progress at that checkpoint is cut short there.
/// Returns whether the continuation is exact.
pub fn extend(run_dir: &Path, total_steps: u64) -> Result<bool> {
    let _lock = run_lock::RunLock::acquire(run_dir)?;
    let mut run = read_run_config(run_dir)?;
    if total_steps < run.train.total_steps {
        bail!(
            "{} already has a budget of {} steps; --steps {total_steps} would shorten it",
            run_dir.display(),
            run.train.total_steps
        );
    }
    // No checkpoint yet: the resume starts the run afresh, with the larger budget from the start.
    let exact = if checkpoint::any(run_dir) {
        checkpoint::load_state(&checkpoint::newest_intact(run_dir, trainer_file(&run))?)?.at_episode_boundary
    } else {
        true
    };
    run.train.total_steps = total_steps;
    write_bytes_atomic(&run_dir.join("config.toml"), run.to_toml()?.as_bytes())?;
    Ok(exact)
}

/// The file a checkpoint of this run needs besides the networks to resume.
fn trainer_file(run: &RunConfig) -> &'static str {
    if run.train.algo.is_on_policy() {
        on_policy::ROLLOUT_FILE
    } else {
        checkpoint::BUFFER_FILE
    }
}

/// Continues a run from its newest intact checkpoint (`checkpoint::newest_intact`). A run with
/// no checkpoint yet (stopped before its first) starts afresh from its `config.toml`, which is
/// what an unbroken run computes too.
pub fn resume(run_dir: &Path, control: &RunControl) -> Result<RunSummary> {
    let run = read_run_config(run_dir)?;
    if !checkpoint::any(run_dir)
        && (run_dir.join(checkpoint::POLICY_FILE).is_file() || !budget_policy_steps(run_dir).is_empty())
    {
        bail!(
            "{} has no checkpoint to resume from: it holds a policy without its training state (an exported policy, \
             or a result kept without checkpoints); train anew into another --out (it can --init-from this one)",
            run_dir.display()
        );
    }
    let lock = run_lock::RunLock::acquire(run_dir)?;
    if !checkpoint::any(run_dir) {
        eprintln!(
            "{} has no checkpoint yet (it stopped before its first): starting it afresh from its config.toml",
            run_dir.display()
        );
        drop(lock);
        let init_from = run.init_from.as_deref().map(Path::new);
        return train(run.env, run.train, run.seed, run_dir, init_from, true, control);
    }
    // Everything is checked before anything is changed: a resume that stops on bad input leaves
    // the run directory as it found it.
    let ckpt = checkpoint::newest_intact(run_dir, trainer_file(&run))?;
    let saved = checkpoint::load_state(&ckpt)?;
    let metrics = metrics::restore(run_dir, &ckpt, saved.step)?;
    checkpoint::remove_leftovers(run_dir)?;
    checkpoint::prune_buffers(run_dir)?;
    checkpoint::make_latest(run_dir, &ckpt)?;
    if saved.step >= run.train.total_steps {
        return Ok(RunSummary {
            run_dir: run_dir.to_path_buf(),
            outcome: Outcome::AlreadyFinished,
            steps: saved.step,
            last_eval: None,
            best_eval_mean: saved.best_eval_mean,
            checkpoint: ckpt,
        });
    }
    if run.train.algo.is_on_policy() {
        control.device.open()?;
        provenance::append(
            run_dir,
            provenance::Stretch::here(saved.step, control.threads, git_commit().as_deref()).on(control.device),
        )?;
        return on_policy::resume(run_dir, &run, &ckpt, metrics, control);
    }
    let mut trainer = Trainer::new(run_dir, &run, control.device)?;
    let (state, buffer) = checkpoint::load_all(&ckpt, trainer.agent.as_mut())?;
    trainer.buffer = buffer;
    trainer.rng = state.rng.restore()?;
    trainer.step = state.step;
    trainer.episodes = state.episodes;
    trainer.wall_offset = state.wall_time;
    trainer.losses = state.losses;
    trainer.best_eval = state.best_eval_mean;
    trainer.metrics = metrics;
    provenance::append(
        run_dir,
        provenance::Stretch::here(state.step, control.threads, git_commit().as_deref()).on(control.device),
    )?;
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
                let learner_reward = (s.reward * cfg.reward_scale) as f32;
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

            // The actor at each reporting budget, for the report's per-budget rows.
            if POLICY_BUDGETS.contains(&self.step) || self.step == cfg.total_steps {
                save_budget_policy(&self.run_dir, self.step, self.agent.as_ref())?;
            }

            // Evaluate.
            if scaffold::crossed(self.step - 1, self.step, cfg.eval_every) || self.step == cfg.total_steps {
                let e = evaluate(self.agent.as_ref(), self.eval_env.as_mut(), cfg.eval_episodes, self.seed)?;
                self.best_eval = Some(self.best_eval.map_or(e.mean(), |b: f64| b.max(e.mean())));
                let row =
                    MetricsRow::progress("eval", self.step, self.losses, sc.rate(self.step), sc.wall(self.wall_offset));
                sc.evaluated(&self.run_dir, &mut self.metrics, row, e, control, self.agent.as_ref(), self.seed)?;
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
            save_budget_policy(&self.run_dir, self.step, self.agent.as_ref())?;
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
        };
        checkpoint::save(&self.run_dir, self.agent.as_mut(), &self.buffer, &state, &self.metrics)
    }
}

#[cfg(test)]
mod tests {
    use crate::agents::Algo;
    use crate::envs::BoxSpace;

    #[test]
    fn unbounded_action_spaces_are_refused_naming_the_dimension() {
        let space = BoxSpace::new(vec![-1.0, f64::NEG_INFINITY], vec![1.0, 2.0]);
        let err = super::check_bounded_actions("toy", &space, Algo::Dqn).unwrap_err().to_string();
        assert!(err.contains("toy's action dimension 1 is unbounded") && err.contains("levels"), "{err}");
        assert!(super::check_bounded_actions("toy", &BoxSpace::uniform(3, -0.4, 0.4), Algo::Td3).is_ok());
    }
}
