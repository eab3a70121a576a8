//! Clips of whole episodes: one policy's episode filmed on its own env (optionally pushed, as the
//! evaluation pushes), and several panels tiled into one video, for `record --side-by-side` and
//! the report's videos.
use std::path::{Path, PathBuf};

use anyhow::{ensure, Result};

use super::video::{Quality, VideoWriter};
use super::{Film, Frame, RenderSettings, Renderer};
use crate::envs::push::{Push, Pushed};
use crate::envs::{make, Env, EnvConfig};
use crate::policy::Policy;

/// One filmed episode.
#[derive(Debug, Clone)]
pub struct Panel {
    /// The frames: the reset's, then one every `stride` steps.
    pub frames: Vec<Frame>,
    /// Frames per simulated second.
    pub fps: f64,
    /// Environment steps the episode lasted.
    pub length: usize,
    /// Simulated seconds it lasted.
    pub seconds: f64,
    /// Its return.
    pub episode_return: f64,
    /// The base's mean forward speed (displacement along x over the episode's simulated time).
    pub speed: f64,
    /// Whether it ended in a fall (terminated before its time limit).
    pub fell: bool,
    /// Whether the physics blew up.
    pub unstable: bool,
    /// When a push on the base began (simulated seconds from the reset), if one did.
    pub push_time: Option<f64>,
}

/// Plays `policy` for one episode of `cfg` from reset seed `seed` (pushed by `push` if given,
/// at the time the evaluation's push would come) and films it at about `fps`, with `caption`
/// as the panel's label when given.
pub fn film_episode(
    cfg: &EnvConfig,
    policy: &mut dyn Policy,
    settings: &RenderSettings,
    fps: f64,
    seed: u64,
    caption: Option<&str>,
    push: Option<Push>,
) -> Result<Panel> {
    let mut env = make(cfg)?;
    let dt = env.spec().dt;
    let renderer = Renderer::new(env.data().model(), settings.clone())?;
    let mut film = Film::frames(renderer, dt, super::frame_stride(dt, fps));
    if let Some(label) = caption {
        film = film.with_caption(label);
    }
    let fps = film.fps();
    let mut pushed;
    let env: &mut dyn Env = match push {
        Some(p) => {
            pushed = Pushed::new(env.as_mut(), p)?;
            &mut pushed
        }
        None => env.as_mut(),
    };
    let summary = crate::rollout::run_episode(env, policy, 0, Some(seed), &mut film)?;
    // The film kept the base's position at the reset.
    let speed = (env.data().xpos()[3] - film.start_x()) / (summary.length.max(1) as f64 * dt);
    let push_time = film.push_time();
    Ok(Panel {
        push_time,
        frames: film.into_frames(),
        fps,
        length: summary.length,
        seconds: summary.length as f64 * dt,
        episode_return: summary.episode_return,
        speed,
        fell: summary.terminated,
        unstable: summary.unstable,
    })
}

/// Panels side by side, left to right, frame by frame; a panel whose episode ended earlier holds
/// its last frame. Every panel must have the same height.
pub fn tile<P: AsRef<[Frame]>>(panels: &[P]) -> Result<Vec<Frame>> {
    let panels: Vec<&[Frame]> = panels.iter().map(AsRef::as_ref).collect();
    let Some(first) = panels.first().and_then(|p| p.first()) else { anyhow::bail!("no frames to tile") };
    let height = first.height;
    if let Some(p) = panels.iter().find(|p| p.is_empty() || p[0].height != height) {
        anyhow::bail!("panels must have frames of one height ({} and {})", height, p.first().map_or(0, |f| f.height));
    }
    let width: usize = panels.iter().map(|p| p[0].width).sum();
    let length = panels.iter().map(|p| p.len()).max().unwrap_or(0);
    Ok((0..length)
        .map(|i| {
            let mut rgb = Vec::with_capacity(width * height * 3);
            for y in 0..height {
                for panel in &panels {
                    let f = &panel[i.min(panel.len() - 1)];
                    rgb.extend_from_slice(&f.rgb[y * f.width * 3..(y + 1) * f.width * 3]);
                }
            }
            Frame { width, height, rgb }
        })
        .collect())
}

/// Panels that were filmed at one rate, tiled into one clip; an error names a panel filmed at
/// another rate (its frames would not line up in time).
pub fn tile_panels(panels: &[Panel]) -> Result<(Vec<Frame>, f64)> {
    let fps = panels.first().map_or(0.0, |p| p.fps);
    for (i, p) in panels.iter().enumerate() {
        ensure!((p.fps - fps).abs() < 1e-9, "panel {} is filmed at {} frames/s, the first at {fps}", i + 1, p.fps);
    }
    let frames: Vec<&[Frame]> = panels.iter().map(|p| p.frames.as_slice()).collect();
    Ok((tile(&frames)?, fps))
}

/// Writes `frames` as the video `path` (its extension picks the format) at `fps`.
pub fn write_video(path: &Path, frames: &[Frame], fps: f64) -> Result<PathBuf> {
    write_video_at(path, frames, fps, Quality::Standard)
}

/// [`write_video`] at `quality`.
pub fn write_video_at(path: &Path, frames: &[Frame], fps: f64, quality: Quality) -> Result<PathBuf> {
    let first = frames.first().ok_or_else(|| anyhow::anyhow!("{}: no frames to write", path.display()))?;
    let mut writer = VideoWriter::create_at(path, first.width, first.height, fps, quality)?;
    for f in frames {
        writer.push(f)?;
    }
    writer.finish()
}
