//! Rendering and encoding speed, measured separately: a 10-second Minitaur episode of the
//! shipped PPO policy is played once, its states kept, then rendered offscreen (OSMesa unless
//! `MUJOCO_GL=egl`) at each size, and the frames encoded as MP4 (ffmpeg, H.264), WebM (ffmpeg,
//! VP9) and GIF (the gif crate). Frames are taken as `record --video` takes them: 25 per simulated
//! second, 251 for the episode. The goal is the episode's video in under 10 s of wall time at
//! 640 x 480.
//!
//! Run: `cargo bench --bench render [-- OUT.csv]`; prints a table and, given a path, writes it
//! as CSV (with the machine, the commit and the backend). Under `cargo test` (no `--bench`) it
//! makes a smoke run: 25 frames at 160 x 120.
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use locobench::envs::make;
use locobench::policy::AgentPolicy;
use locobench::render::video::VideoWriter;
use locobench::render::{frame_stride, Backend, Camera, Frame, RenderSettings, Renderer};
use locobench::train::load_policy;

const SIZES: [(usize, usize); 3] = [(320, 240), (640, 480), (1280, 720)];
const SMOKE_SIZES: [(usize, usize); 1] = [(160, 120)];

fn main() -> Result<()> {
    let out = std::env::args().skip(1).find(|a| a.ends_with(".csv")).map(PathBuf::from);
    let smoke = !std::env::args().any(|a| a == "--bench");
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let (run, agent) = load_policy(&root.join("models/policies/minitaur-ppo"))?;
    let mut env = make(&run.env)?;
    let every = frame_stride(env.spec().dt, 25.0);
    // The episode's states at the frames a video takes.
    let mut states: Vec<(Vec<f64>, Vec<f64>)> = Vec::new();
    let mut policy = AgentPolicy { agent: agent.as_ref(), label: "ppo".into() };
    let mut keep = |v: &locobench::rollout::StepView| {
        if (v.t + 1).is_multiple_of(every) {
            states.push((v.env.data().qpos().to_vec(), v.env.data().qvel().to_vec()));
        }
        Ok(())
    };
    env.reset(Some(0))?;
    let first = (env.data().qpos().to_vec(), env.data().qvel().to_vec());
    locobench::rollout::run_episode(env.as_mut(), &mut policy, 0, Some(0), &mut keep)?;
    states.insert(0, first);
    if smoke {
        states.truncate(25);
    }
    let seconds = env.spec().max_episode_steps as f64 * env.spec().dt;
    let backend = Backend::from_env()?;
    let dir = tempfile::tempdir()?;
    let mut rows = Vec::new();
    println!(
        "{} frames of a {seconds:.0} s episode, backend {}; seconds of wall time and frames per second",
        states.len(),
        backend.name()
    );
    println!(
        "{:<10} {:>14} {:>14} {:>14} {:>14} {:>12}",
        "size", "render", "encode mp4", "encode webm", "encode gif", "mp4 total"
    );
    for &(w, h) in if smoke { &SMOKE_SIZES[..] } else { &SIZES[..] } {
        let settings = RenderSettings { width: w, height: h, camera: Camera::Follow };
        let mut renderer = Renderer::with_backend(env.data().model(), settings, backend)?;
        let started = Instant::now();
        let mut frames: Vec<Frame> = Vec::with_capacity(states.len());
        for (qpos, qvel) in &states {
            env.set_state(qpos, qvel)?;
            frames.push(renderer.render(env.data())?);
        }
        let render = started.elapsed().as_secs_f64();
        let encode = |ext: &str| -> Result<f64> {
            let started = Instant::now();
            let mut writer = VideoWriter::create(&dir.path().join(format!("v.{ext}")), w, h, 25.0)?;
            for f in &frames {
                writer.push(f)?;
            }
            writer.finish()?;
            Ok(started.elapsed().as_secs_f64())
        };
        let (mp4, webm, gif) = (encode("mp4")?, encode("webm")?, encode("gif")?);
        let n = frames.len() as f64;
        let cell = |s: f64| format!("{s:.2} ({:.0} fps)", n / s);
        println!(
            "{:<10} {:>14} {:>14} {:>14} {:>14} {:>12}",
            format!("{w}x{h}"),
            cell(render),
            cell(mp4),
            cell(webm),
            cell(gif),
            format!("{:.2}", render + mp4)
        );
        rows.push(format!("{w},{h},{},{render:.3},{mp4:.3},{webm:.3},{gif:.3}", frames.len()));
    }
    if let Some(path) = out.filter(|_| !smoke) {
        let cpu = locobench::train::provenance::Stretch::here(0, 1, None).cpu_model;
        let commit = option_env!("LOCOBENCH_GIT_COMMIT").unwrap_or("unknown");
        let mut text = format!(
            "# cargo bench --bench render; backend {}; cpu {cpu}; {} cores; commit {commit}\n\
             width,height,frames,render_s,encode_mp4_s,encode_webm_s,encode_gif_s\n",
            backend.name(),
            std::thread::available_parallelism().map_or(1, |n| n.get())
        );
        for r in rows {
            text.push_str(&r);
            text.push('\n');
        }
        locobench::io::write_bytes_atomic(&path, text.as_bytes())?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
