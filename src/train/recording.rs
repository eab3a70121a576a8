//! The training run's rerun recording: learning curves, and an evaluation rollout at chosen
//! evaluations.
use anyhow::Result;
use rerun::RecordingStream;

use crate::agents::Agent;
use crate::envs::{make, Env, EnvConfig};
use crate::policy::AgentPolicy;
use crate::record::RolloutRecorder;

use super::metrics::MetricsRow;
use super::seeds;

/// Logs every value a metrics row carries under `training/`.
pub(crate) fn log_training_row(rec: &RecordingStream, row: &MetricsRow) -> Result<()> {
    rec.reset_time();
    rec.set_time_sequence("train_step", row.step as i64);
    // The wall time is the recording's own timeline, not a curve.
    for (column, value) in row.values().into_iter().filter(|(c, _)| *c != "wall_time") {
        if let Some(v) = value {
            rec.log(format!("training/{column}"), &rerun::Scalars::single(v))?;
        }
    }
    Ok(())
}

/// The training run's recording: curves, and the first evaluation episode at every evaluation
/// (on an environment of its own, so the run's numbers do not depend on recording).
pub(super) struct TrainingRecorder<'a> {
    rollouts: RolloutRecorder<'a>,
    env: Box<dyn Env>,
    stream: &'a RecordingStream,
}

impl<'a> TrainingRecorder<'a> {
    pub(super) fn new(stream: &'a RecordingStream, env: &EnvConfig) -> Result<TrainingRecorder<'a>> {
        let env = make(env)?;
        Ok(TrainingRecorder { rollouts: RolloutRecorder::new(stream, env.data().model())?, env, stream })
    }

    pub(super) fn curves(&self, row: &MetricsRow) -> Result<()> {
        log_training_row(self.stream, row)
    }

    pub(super) fn evaluation_rollout(&mut self, agent: &dyn Agent, step: u64, run_seed: u64) -> Result<()> {
        self.rollouts.set_train_step(Some(step));
        let seed = seeds::eval_episode_seed(run_seed, 0);
        let mut policy = AgentPolicy { agent, label: agent.algo().name().to_string() };
        crate::rollout::run_episode(self.env.as_mut(), &mut policy, 0, Some(seed), &mut self.rollouts)?;
        self.rollouts.set_train_step(None);
        Ok(())
    }
}

/// Clips of the deterministic evaluation episode (the first evaluation seed) at chosen
/// evaluations, rendered on an environment of its own so that the run's numbers do not depend on
/// filming: `videos/eval-step-<N>.mp4` in the run directory (25 frames/s) and
/// `videos/eval-step-<N>.gif` (every other frame: for Markdown pages and TensorBoard), each
/// captioned with the algorithm, the step, the return and the speed.
pub(super) struct TrainingClips {
    env: Box<dyn Env>,
    dir: std::path::PathBuf,
    every: u64,
}

/// The clips' size: small enough to keep one per evaluation beside a run.
const CLIP_SETTINGS: (usize, usize) = (320, 240);

/// A clip just written.
pub(super) struct Clip {
    /// The GIF copy.
    pub gif: std::path::PathBuf,
    /// Its frame size.
    pub width: usize,
    pub height: usize,
}

impl TrainingClips {
    /// Checks up front that rendering and encoding work here (a missing GL library or ffmpeg is
    /// an error before training starts, not at the first evaluation).
    pub(super) fn new(run_dir: &std::path::Path, env: &EnvConfig, every: u64) -> Result<TrainingClips> {
        let env = make(env)?;
        crate::render::check_available(env.data().model())?;
        crate::render::video::check_encoder(crate::render::video::Format::Mp4)?;
        let dir = run_dir.join("videos");
        Ok(TrainingClips { env, dir, every: every.max(1) })
    }

    /// Called at every evaluation, after `evaluations` evaluations so far (this one included):
    /// films the evaluation episode at every `every`-th one.
    pub(super) fn evaluation(
        &mut self,
        agent: &dyn Agent,
        step: u64,
        run_seed: u64,
        evaluations: u64,
    ) -> Result<Option<Clip>> {
        if !(evaluations - 1).is_multiple_of(self.every) {
            return Ok(None);
        }
        std::fs::create_dir_all(&self.dir)?;
        let (width, height) = CLIP_SETTINGS;
        let settings = crate::render::RenderSettings { width, height, camera: crate::render::Camera::Follow };
        let dt = self.env.spec().dt;
        let renderer = crate::render::Renderer::new(self.env.data().model(), settings)?;
        let mut film = crate::render::Film::frames(renderer, dt, crate::render::frame_stride(dt, 25.0))
            .with_caption(format!("{} at step {step}", agent.algo().name()));
        let seed = seeds::eval_episode_seed(run_seed, 0);
        let mut policy = AgentPolicy { agent, label: agent.algo().name().to_string() };
        crate::rollout::run_episode(self.env.as_mut(), &mut policy, 0, Some(seed), &mut film)?;
        let fps = film.fps();
        let frames = film.into_frames();
        crate::render::clip::write_video(&self.dir.join(format!("eval-step-{step}.mp4")), &frames, fps)?;
        let half: Vec<_> = frames.into_iter().step_by(2).collect();
        let gif = crate::render::clip::write_video(&self.dir.join(format!("eval-step-{step}.gif")), &half, fps / 2.0)?;
        Ok(Some(Clip { gif, width, height }))
    }
}
