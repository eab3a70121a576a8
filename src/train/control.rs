//! What a caller of `train`/`resume` sets and gets back: the knobs that change when a run stops
//! and what it shows (never what it computes), the hook called after each evaluation, and the
//! summary of how the call ended.
use std::path::PathBuf;

use anyhow::Result;

use super::evaluate::Evaluation;
use crate::agents::Agent;
use crate::device::ComputeDevice;

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
    /// through the device-generic path (`agents::common::device`), whose numbers differ from the CPU's
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
