//! What both training loops (the off-policy one in `mod.rs`, PPO's rollouts in `on_policy.rs`)
//! set up, run and tear down the same way: the numeric runtime, the stop signals, the progress
//! bar, the clock (wall time and steps per second), the recording, the clips and the TensorBoard
//! events, each evaluation's logging and cadence, and the finish.
use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use indicatif::ProgressBar;

use super::evaluate::Evaluation;
use super::metrics::MetricsRow;
use super::recording::{TrainingClips, TrainingRecorder};
use super::stop::{stop_signals, StopSignals};
use super::tensorboard::EventWriter;
use super::{log_evaluation, progress_bar, Outcome, RunControl, RunSummary};
use crate::agents::Agent;
use crate::envs::EnvConfig;
use crate::record::Recording;
use crate::runtime::Runtime;

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
    /// recording, which [`super::finish_run`] then closes.
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
}
