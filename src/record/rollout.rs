//! Per-step logging of a rollout: body poses, contacts, and the time series a researcher
//! plots (reward and its terms, speed, height, actions, torques, controller signals).
use anyhow::Result;
use rerun::RecordingStream;

use super::scene::{body_entity, log_scene, rerun_quat};
use crate::envs::Env;
use crate::mujoco::{Model, ObjKind};
use crate::rollout::{EpisodeSummary, Observer, StepView};

/// Metres of arrow per newton of contact force.
const FORCE_ARROW_SCALE: f64 = 0.002;

/// Writes rollouts into a recording, one frame per reset and per step. Frames are numbered on
/// the `step` timeline and placed on `sim_time` (seconds, continuing across episodes). With
/// `train_step` set, frames also carry that timeline (evaluation rollouts during training).
pub struct RolloutRecorder<'a> {
    rec: &'a RecordingStream,
    bodies: Vec<String>,
    actuators: Vec<String>,
    /// The entity paths of the static scene.
    pub scene: Vec<String>,
    frame: i64,
    /// `sim_time` of the current episode's first frame.
    time_offset: f64,
    episode_start_time: f64,
    last_time: f64,
    train_step: Option<u64>,
}

impl<'a> RolloutRecorder<'a> {
    /// Logs the static scene of `model` and prepares per-step logging.
    pub fn new(rec: &'a RecordingStream, model: &Model) -> Result<RolloutRecorder<'a>> {
        let scene = log_scene(rec, model)?;
        let bodies = (0..model.nbody()).map(|b| body_entity(model, b)).collect();
        let actuators = (0..model.nu())
            .map(|a| model.name(ObjKind::Actuator, a).ok().flatten().unwrap_or_else(|| format!("actuator_{a}")))
            .collect();
        Ok(RolloutRecorder {
            rec,
            bodies,
            actuators,
            scene,
            frame: 0,
            time_offset: 0.0,
            episode_start_time: 0.0,
            last_time: 0.0,
            train_step: None,
        })
    }

    /// Frames logged so far.
    pub fn frames(&self) -> i64 {
        self.frame
    }

    /// Tags the following frames with a training step (None to stop).
    pub(crate) fn set_train_step(&mut self, step: Option<u64>) {
        self.train_step = step;
    }

    fn set_frame_time(&mut self, env: &dyn Env) {
        self.rec.reset_time();
        if let Some(s) = self.train_step {
            self.rec.set_time_sequence("train_step", s as i64);
        }
        self.rec.set_time_sequence("step", self.frame);
        let t = self.time_offset + env.data().time() - self.episode_start_time;
        self.rec.set_duration_secs("sim_time", t);
        self.last_time = t;
        self.frame += 1;
    }

    fn scalar(&self, path: &str, value: f64) -> Result<()> {
        self.rec.log(path, &rerun::Scalars::single(value))?;
        Ok(())
    }

    /// Body poses and contacts of the current state.
    fn log_state(&self, env: &dyn Env) -> Result<()> {
        let d = env.data();
        let (xpos, xquat) = (d.xpos(), d.xquat());
        for (b, path) in self.bodies.iter().enumerate().skip(1) {
            let p = &xpos[3 * b..3 * b + 3];
            self.rec.log(
                path.as_str(),
                &rerun::Transform3D::from_translation_rotation(
                    [p[0] as f32, p[1] as f32, p[2] as f32],
                    rerun_quat(&xquat[4 * b..4 * b + 4]),
                ),
            )?;
        }
        let contacts = d.contacts();
        let points: Vec<[f32; 3]> = contacts.iter().map(|c| c.pos.map(|v| v as f32)).collect();
        // Contact-frame force (normal, tangent 1, tangent 2) to world: rows of `frame` are those axes.
        let forces: Vec<[f32; 3]> = contacts
            .iter()
            .map(|c| {
                let f = c.force;
                std::array::from_fn(|k| {
                    ((f[0] * c.frame[k] + f[1] * c.frame[3 + k] + f[2] * c.frame[6 + k]) * FORCE_ARROW_SCALE) as f32
                })
            })
            .collect();
        self.rec.log("world/contacts/points", &rerun::Points3D::new(points.clone()).with_radii([0.01f32]))?;
        self.rec.log(
            "world/contacts/forces",
            &rerun::Arrows3D::from_vectors(forces)
                .with_origins(points)
                .with_colors([rerun::Color::from_rgb(230, 60, 40)]),
        )?;
        let root = self.bodies.len().min(2) - 1;
        self.scalar("plots/base_height", xpos[3 * root + 2])?;
        Ok(())
    }

    /// Frame of a freshly reset environment.
    pub(crate) fn log_reset(&mut self, episode: usize, env: &dyn Env) -> Result<()> {
        self.episode_start_time = env.data().time();
        if self.frame > 0 {
            // Episodes follow each other on `sim_time`, one control period apart.
            self.time_offset = self.last_time + env.spec().dt;
        }
        self.set_frame_time(env);
        self.rec.log("events", &rerun::TextLog::new(format!("episode {episode} starts")))?;
        self.scalar("plots/episode", episode as f64)?;
        self.log_state(env)
    }

    /// Frame after one step.
    pub(crate) fn log_step(&mut self, view: &StepView) -> Result<()> {
        let env = view.env;
        self.set_frame_time(env);
        self.log_state(env)?;
        let step = view.step;
        if step.info.unstable {
            self.rec.log(
                "events",
                &rerun::TextLog::new(format!(
                    "episode {}: physics unstable at step {} ({})",
                    view.episode,
                    view.t,
                    step.info.warnings.join("; ")
                ))
                .with_level(rerun::TextLogLevel::WARN),
            )?;
        }
        self.scalar("plots/reward", step.reward)?;
        for (term, v) in &step.info.reward_terms {
            self.scalar(&format!("plots/reward_terms/{term}"), *v)?;
        }
        for (name, v) in &step.info.metrics {
            match *name {
                "x_velocity" => self.scalar("plots/forward_speed", *v)?,
                "base_height" => {} // already logged from the root body
                other => self.scalar(&format!("plots/metrics/{other}"), *v)?,
            }
        }
        for (name, a) in self.actuators.iter().zip(view.action) {
            self.scalar(&format!("plots/action/{name}"), *a)?;
        }
        for (name, f) in self.actuators.iter().zip(env.data().actuator_force()) {
            self.scalar(&format!("plots/torque/{name}"), *f)?;
        }
        let telemetry = view.policy.telemetry();
        for (name, v) in &telemetry.scalars {
            self.scalar(&format!("plots/controller/{name}"), *v)?;
        }
        // A controller with gait telemetry logs its targets every step, even none (all legs in
        // stance), so stale targets do not linger in the viewer.
        if !telemetry.points.is_empty() || !telemetry.scalars.is_empty() {
            let targets: Vec<[f32; 3]> = telemetry.points.iter().map(|(_, p)| p.map(|v| v as f32)).collect();
            let labels: Vec<String> = telemetry.points.iter().map(|(n, _)| n.clone()).collect();
            self.rec.log(
                "world/foot_targets",
                &rerun::Points3D::new(targets)
                    .with_labels(labels)
                    .with_radii([0.015f32])
                    .with_colors([rerun::Color::from_rgb(40, 200, 80)]),
            )?;
        }
        Ok(())
    }

    pub(crate) fn log_end(&mut self, summary: &EpisodeSummary) -> Result<()> {
        let end = summary.end_reason();
        self.rec.log(
            "events",
            &rerun::TextLog::new(format!(
                "episode {} ends ({end}) after {} steps, return {:.3}",
                summary.episode, summary.length, summary.episode_return
            )),
        )?;
        self.scalar("plots/episode_return", summary.episode_return)
    }
}

impl Observer for RolloutRecorder<'_> {
    fn reset(&mut self, episode: usize, env: &dyn Env) -> Result<()> {
        self.log_reset(episode, env)
    }
    fn step(&mut self, view: &StepView) -> Result<()> {
        self.log_step(view)
    }
    fn end(&mut self, summary: &EpisodeSummary) -> Result<()> {
        self.log_end(summary)
    }
}
