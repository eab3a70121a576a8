//! What both training loops (`off_policy.rs`, `on_policy.rs`) set up, run and tear down the same
//! way: the run directory, the numeric runtime, the stop signals, the progress bar, the clock
//! (wall time and steps per second), the recording, the clips and the TensorBoard events, each
//! evaluation's logging and cadence, the budget policies, and the finish.
use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use super::checkpoint;
use super::checkpoint::{budget_policy_path, BUDGET_POLICY_DIR};
use super::control::{EvaluationEvent, Outcome, RunControl, RunSummary};
use super::evaluate::Evaluation;
use super::metrics;
use super::metrics::MetricsRow;
use super::provenance;
use super::recording::{TrainingClips, TrainingRecorder};
use super::run_config::RunConfig;
use super::run_lock::RunLock;
use super::stop::{stop_signals, StopSignals};
use super::tensorboard::EventWriter;
use crate::agents::{Agent, TrainConfig};
use crate::envs::EnvConfig;
use crate::io::write_bytes_atomic;
use crate::record::Recording;
use crate::runtime::Runtime;

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
pub(super) fn progress_bar(show: bool, total: u64, position: u64) -> ProgressBar {
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
pub(super) fn save_budget_policy(run_dir: &Path, step: u64, agent: &dyn Agent) -> Result<()> {
    let dir = run_dir.join(BUDGET_POLICY_DIR);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    checkpoint::save_actor(&budget_policy_path(run_dir, step), agent)
}

/// Appends an evaluation's row (`row` with `evaluation`'s figures), rewrites `metrics.csv`, logs
/// the row to the recording, with a rollout of the policy at every `control.record_every`-th
/// evaluation, and runs `control`'s evaluation hook. Returns whether the hook finishes the run.
#[allow(clippy::too_many_arguments)]
pub(super) fn log_evaluation(
    run_dir: &Path,
    metrics: &mut Vec<MetricsRow>,
    row: MetricsRow,
    evaluation: &Evaluation,
    recorder: Option<&mut TrainingRecorder>,
    clips: Option<&mut TrainingClips>,
    mut events: Option<&mut EventWriter>,
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
pub(super) fn finish_run(
    metrics: &[MetricsRow],
    recording: Option<Recording>,
    summary: RunSummary,
) -> Result<RunSummary> {
    metrics::write(&summary.run_dir.join(metrics::FILE), metrics)?;
    if let Some(r) = recording {
        r.finish()?;
    }
    Ok(summary)
}

/// Creates the run directory of a new run, locks it for the process's lifetime (the returned
/// lock), and writes its `config.toml` and the first line of `provenance.csv`.
pub(super) fn create_run_dir(run_dir: &Path, run: &RunConfig, control: &RunControl) -> Result<RunLock> {
    std::fs::create_dir_all(run_dir).with_context(|| format!("creating {}", run_dir.display()))?;
    let lock = RunLock::acquire(run_dir)?;
    write_bytes_atomic(&run_dir.join("config.toml"), run.to_toml()?.as_bytes())?;
    record_stretch(run_dir, 0, control)?;
    Ok(lock)
}

/// Appends the stretch that starts at `step` (this machine, thread count, device, commit) to the
/// run's `provenance.csv`.
pub(super) fn record_stretch(run_dir: &Path, step: u64, control: &RunControl) -> Result<()> {
    provenance::append(
        run_dir,
        provenance::Stretch::here(step, control.threads, provenance::git_commit().as_deref()).on(control.device),
    )
}

/// One stretch of a training run, from its (re)start to its last checkpoint. The recording it
/// writes to (`control.record`) is the caller's, opened by [`open_recording`], because the
/// recorder borrows it.
pub(super) struct Scaffold<'a> {
    _runtime: Runtime,
    pub signals: &'static StopSignals,
    pub bar: ProgressBar,
    started: Instant,
    start_step: u64,
    pub recorder: Option<TrainingRecorder<'a>>,
    clips: Option<TrainingClips>,
    pub events: Option<EventWriter>,
    pub last_eval: Option<Evaluation>,
    /// The evaluation hook asked to finish.
    hook_done: bool,
}

/// The rerun recording `control.record` asks for, if any.
pub(super) fn open_recording(control: &RunControl) -> Result<Option<Recording>> {
    control.record.as_deref().map(Recording::create).transpose()
}

impl<'a> Scaffold<'a> {
    /// Starts a stretch at `step` of `total` steps of the run in `run_dir` on `env`, recording into
    /// `recording`.
    pub fn start(
        control: &RunControl,
        run_dir: &Path,
        env: &EnvConfig,
        total: u64,
        step: u64,
        recording: Option<&'a Recording>,
    ) -> Result<Scaffold<'a>> {
        let runtime = Runtime::enter(control.threads);
        let recorder = match recording {
            Some(r) => Some(TrainingRecorder::new(r.stream(), env)?),
            None => None,
        };
        Ok(Scaffold {
            _runtime: runtime,
            signals: stop_signals(),
            bar: progress_bar(control.show_progress, total, step),
            started: Instant::now(),
            start_step: step,
            recorder,
            clips: control.video_every.map(|n| TrainingClips::new(run_dir, env, n)).transpose()?,
            events: control.tensorboard.as_deref().map(|d| EventWriter::create(d, step)).transpose()?,
            last_eval: None,
            hook_done: false,
        })
    }

    /// The run's wall time: `offset` (its earlier stretches) plus this stretch's so far.
    pub fn wall(&self, offset: f64) -> f64 {
        offset + self.started.elapsed().as_secs_f64()
    }

    /// Steps per second of this stretch, at `step`.
    pub fn rate(&self, step: u64) -> f64 {
        (step - self.start_step) as f64 / self.started.elapsed().as_secs_f64().max(1e-9)
    }

    /// Whether the run is done before its budget: the evaluation hook said so, or the last
    /// evaluation reached `control.target_return`.
    pub fn solved(&self, control: &RunControl) -> bool {
        self.hook_done || control.target_return.is_some_and(|t| self.last_eval.as_ref().is_some_and(|e| e.mean() >= t))
    }

    /// Logs an evaluation as `row` (metrics, recording, clips, events, the hook) and keeps it.
    #[allow(clippy::too_many_arguments)]
    pub fn evaluated(
        &mut self,
        run_dir: &Path,
        metrics: &mut Vec<MetricsRow>,
        row: MetricsRow,
        evaluation: Evaluation,
        control: &RunControl,
        agent: &dyn Agent,
        run_seed: u64,
    ) -> Result<()> {
        self.bar.set_message(format!("eval {:.1} ± {:.1}", evaluation.mean(), evaluation.std()));
        self.hook_done = log_evaluation(
            run_dir,
            metrics,
            row,
            &evaluation,
            self.recorder.as_mut(),
            self.clips.as_mut(),
            self.events.as_mut(),
            control,
            agent,
            run_seed,
        )?;
        self.last_eval = Some(evaluation);
        Ok(())
    }

    /// The loop is over: the bar goes and the event files are flushed (before the last
    /// checkpoint, which follows).
    pub fn end(&mut self) -> Result<()> {
        self.bar.finish_and_clear();
        if let Some(e) = self.events.as_mut() {
            e.flush()?;
        }
        Ok(())
    }

    /// The stretch's summary, once its last checkpoint is written; the recorder lets go of the
    /// recording, which [`finish_run`] then closes.
    pub fn summary(
        self,
        run_dir: &Path,
        outcome: Outcome,
        steps: u64,
        best_eval_mean: Option<f64>,
        checkpoint: std::path::PathBuf,
    ) -> RunSummary {
        RunSummary {
            run_dir: run_dir.to_path_buf(),
            outcome,
            steps,
            last_eval: self.last_eval,
            best_eval_mean,
            checkpoint,
        }
    }
}

/// Whether a multiple of `every` lies in (`before`, `now`]: an evaluation or other periodic
/// event is due after steps that took the run from `before` to `now`.
pub(super) fn crossed(before: u64, now: u64, every: u64) -> bool {
    before / every != now / every
}

/// The reward a learner stores for one transition, before `reward_scale`: the environment's, less
/// `termination_penalty` when the transition ends its episode by termination (time limits are not
/// terminations).
pub(super) fn learner_reward(reward: f64, terminated: bool, cfg: &TrainConfig) -> f64 {
    if terminated {
        reward - cfg.termination_penalty
    } else {
        reward
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cadence_is_due_once_per_multiple_crossed() {
        // one step at a time: due exactly at multiples
        let due: Vec<u64> = (1..=25).filter(|&s| crossed(s - 1, s, 10)).collect();
        assert_eq!(due, vec![10, 20]);
        // rollouts of 8 steps: due at the rollout that passes a multiple
        let due: Vec<u64> = (1..=5).map(|i| i * 8).filter(|&s| crossed(s - 8, s, 10)).collect();
        assert_eq!(due, vec![16, 24, 32, 40]);
    }

    use crate::agents::Algo;
    use crate::envs::BoxSpace;

    #[test]
    fn unbounded_action_spaces_are_refused_naming_the_dimension() {
        let space = BoxSpace::new(vec![-1.0, f64::NEG_INFINITY], vec![1.0, 2.0]);
        let err = super::check_bounded_actions("toy", &space, Algo::Dqn).unwrap_err().to_string();
        assert!(err.contains("toy's action dimension 1 is unbounded") && err.contains("levels"), "{err}");
        assert!(super::check_bounded_actions("toy", &BoxSpace::uniform(3, -0.4, 0.4), Algo::Td3).is_ok());
    }

    #[test]
    fn the_termination_penalty_falls_on_terminations_only() {
        let mut cfg = TrainConfig::defaults(Algo::Sac);
        assert_eq!(learner_reward(0.25, true, &cfg), 0.25, "0 by default");
        cfg.termination_penalty = 5.0;
        assert_eq!(learner_reward(0.25, true, &cfg), 0.25 - 5.0);
        assert_eq!(learner_reward(0.25, false, &cfg), 0.25, "a step that goes on, or a time limit");
    }
}
