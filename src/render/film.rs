//! Filming a rollout: an [`Observer`] that renders every k-th step (and each reset) into a video
//! file or into frames kept in memory, optionally with a caption (the panel's label, the step,
//! the return so far and the mean forward speed so far) and with pushes marked: while a force
//! pushes the floating base, and for a second after, a red arrow points at the base along the
//! push and the caption gives its size as a velocity change. On a velocity-command task the
//! caption also gives the command and the achieved forward speed and yaw rate (averaged over the
//! last half second, so that a stride's swing does not hide the mean).
//!
//! [`Observer`]: crate::rollout::Observer
use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Result;

use super::video::VideoWriter;
use super::{Frame, Marks, RenderSettings, Renderer};
use crate::envs::Env;
use crate::mujoco::{Data, Model};
use crate::rollout::{Observer, StepView};

/// Seconds a push stays marked after it starts: long enough to be seen at video speed.
const PUSH_MARK_TIME: f64 = 1.0;

/// Seconds the caption's achieved speed and yaw rate are averaged over.
const ACHIEVED_WINDOW: f64 = 0.5;

enum Sink {
    Frames(Vec<Frame>),
    Video(VideoWriter),
}

/// A push seen on the base: when it started (simulated seconds since the reset), its direction
/// (unit, world frame) and the impulse so far (N s).
#[derive(Debug, Clone, Copy)]
struct PushSeen {
    start: f64,
    direction: [f64; 3],
    impulse: f64,
}

/// Renders an episode as it is played.
pub struct Film {
    renderer: Renderer,
    every: usize,
    sink: Sink,
    label: Option<String>,
    dt: f64,
    mass: f64,
    floating: bool,
    // The episode so far.
    steps: usize,
    episode_return: f64,
    x0: f64,
    push: Option<PushSeen>,
    /// On a command task: the command in force and the recent (forward speed, yaw rate).
    command: Option<[f64; 2]>,
    recent: std::collections::VecDeque<[f64; 2]>,
}

/// Steps per frame so that frames come at most `fps` times per simulated second.
pub fn frame_stride(dt: f64, fps: f64) -> usize {
    ((1.0 / (dt * fps)).round() as usize).max(1)
}

impl Film {
    /// Keeps the frames in memory (for panels tiled later), one every `every` steps of a control
    /// period of `dt` seconds.
    pub fn frames(renderer: Renderer, dt: f64, every: usize) -> Film {
        Film::with_sink(renderer, dt, every, Sink::Frames(Vec::new()))
    }

    /// Writes `model`'s states (control period `dt` seconds) into the video `path` at about
    /// `fps` frames per simulated second, so that it plays in real time.
    pub fn video(
        model: &Arc<Model>,
        dt: f64,
        settings: RenderSettings,
        path: &std::path::Path,
        fps: f64,
    ) -> Result<Film> {
        let every = frame_stride(dt, fps);
        let writer = VideoWriter::create(path, settings.width, settings.height, 1.0 / (every as f64 * dt))?;
        let renderer = Renderer::new(model, settings)?;
        Ok(Film::with_sink(renderer, dt, every, Sink::Video(writer)))
    }

    fn with_sink(renderer: Renderer, dt: f64, every: usize, sink: Sink) -> Film {
        let model = renderer.model();
        let mass = model.body_mass().iter().sum();
        let floating = model.has_floating_base();
        Film {
            renderer,
            every: every.max(1),
            sink,
            label: None,
            dt,
            mass,
            floating,
            steps: 0,
            episode_return: 0.0,
            x0: 0.0,
            push: None,
            command: None,
            recent: std::collections::VecDeque::new(),
        }
    }

    /// Draws a caption on every frame: `label` (e.g. the policy), then step, return and speed.
    pub fn with_caption(mut self, label: impl Into<String>) -> Film {
        self.label = Some(label.into());
        self
    }

    /// Frames made so far.
    pub fn frame_count(&self) -> usize {
        match &self.sink {
            Sink::Frames(f) => f.len(),
            Sink::Video(w) => w.frames(),
        }
    }

    /// Environment steps per frame.
    pub fn stride(&self) -> usize {
        self.every
    }

    /// Frames per simulated second.
    pub fn fps(&self) -> f64 {
        1.0 / (self.every as f64 * self.dt)
    }

    /// The base's x position at the last reset.
    pub fn start_x(&self) -> f64 {
        self.x0
    }

    /// When the last push on the base began (simulated seconds from the reset), if one did.
    pub fn push_time(&self) -> Option<f64> {
        self.push.map(|p| p.start)
    }

    /// The frames kept (empty for a film written to a file).
    pub fn into_frames(self) -> Vec<Frame> {
        match self.sink {
            Sink::Frames(f) => f,
            Sink::Video(_) => Vec::new(),
        }
    }

    /// Finishes the video file; returns its path. An error for a film kept in memory.
    pub fn finish(self) -> Result<PathBuf> {
        match self.sink {
            Sink::Video(w) => w.finish(),
            Sink::Frames(_) => anyhow::bail!("this film keeps its frames in memory; it has no file to finish"),
        }
    }

    fn base_x(data: &Data) -> f64 {
        data.xpos()[3]
    }

    fn shoot(&mut self, data: &Data) -> Result<()> {
        let t = self.steps as f64 * self.dt;
        let mut marks = Marks::default();
        let push = self.push.filter(|p| t - p.start <= PUSH_MARK_TIME);
        if let Some(p) = push {
            let base = &data.xpos()[3..6];
            // From the side the push comes from and a little above, so that the camera sees its length.
            let tail: [f64; 3] =
                std::array::from_fn(|k| base[k] - 0.6 * p.direction[k] + if k == 2 { 0.3 } else { 0.0 });
            marks.arrow = Some((tail, [base[0], base[1], base[2]]));
        }
        if let Some(label) = &self.label {
            let speed = if self.steps == 0 { 0.0 } else { (Self::base_x(data) - self.x0) / t };
            let mut text = format!("{label}\nstep {}  return {:.2}  {speed:.2} m/s", self.steps, self.episode_return);
            if let Some(c) = self.command {
                let n = self.recent.len().max(1) as f64;
                let (v, w) = self.recent.iter().fold((0.0, 0.0), |(v, w), r| (v + r[0] / n, w + r[1] / n));
                text.push_str(&format!(
                    "\ncommand  {:.2} m/s  {:+.2} rad/s\nachieved {v:.2} m/s  {w:+.2} rad/s",
                    c[0], c[1]
                ));
            }
            if let Some(p) = push {
                text.push_str(&format!("\npush {:.2} m/s", p.impulse / self.mass));
            }
            marks.caption = Some((text, String::new()));
        }
        let frame = self.renderer.render_marked(data, &marks)?;
        match &mut self.sink {
            Sink::Frames(f) => f.push(frame),
            Sink::Video(w) => w.push(&frame)?,
        }
        Ok(())
    }

    /// A force on the base's translational coordinates (what `evaluation::push` applies).
    fn watch_push(&mut self, data: &Data) {
        if !self.floating {
            return;
        }
        let f = &data.qfrc_applied()[0..3];
        let norm = f.iter().map(|v| v * v).sum::<f64>().sqrt();
        if norm == 0.0 {
            return;
        }
        let t = (self.steps - 1) as f64 * self.dt;
        let direction = [f[0] / norm, f[1] / norm, f[2] / norm];
        match &mut self.push {
            // The same push, still acting.
            Some(p) if t - p.start <= PUSH_MARK_TIME => p.impulse += norm * self.dt,
            _ => self.push = Some(PushSeen { start: t, direction, impulse: norm * self.dt }),
        }
    }
}

impl Observer for Film {
    fn reset(&mut self, _episode: usize, env: &dyn Env) -> Result<()> {
        self.steps = 0;
        self.episode_return = 0.0;
        self.push = None;
        self.x0 = Self::base_x(env.data());
        self.command = env.command();
        self.recent.clear();
        self.shoot(env.data())
    }

    fn step(&mut self, view: &StepView) -> Result<()> {
        self.steps = view.t + 1;
        self.episode_return += view.step.reward;
        self.watch_push(view.env.data());
        if let Some(c) = view.env.command() {
            self.command = Some(c);
            let m = |name: &str| view.step.info.metric(name).unwrap_or(f64::NAN);
            self.recent.push_back([m("forward_velocity"), m("yaw_rate")]);
            if self.recent.len() as f64 * self.dt > ACHIEVED_WINDOW {
                self.recent.pop_front();
            }
        }
        if self.steps.is_multiple_of(self.every) {
            self.shoot(view.env.data())?;
        }
        Ok(())
    }
}
