use std::path::PathBuf;

use anyhow::{Context, Result};
use locobench::controller::baseline::{baseline_controller_for, baseline_env, baseline_env_like, parse_gait};
use locobench::controller::command::Command;
use locobench::envs::make;
use locobench::policy::{AgentPolicy, Policy};
use locobench::record::{spawn_viewer, Recording, RolloutRecorder};
use locobench::render::clip::{film_episode, tile_panels, write_video};
use locobench::render::{Camera, Film, RenderSettings};
use locobench::rollout::{run_episodes, Observer};
use locobench::train::resolve_policy;

use super::rollout::simple_policy;

#[derive(clap::Args, Debug)]
pub struct RecordArgs {
    /// Environment name (see `locobench envs`); optional with a checkpoint (its run's env).
    #[arg(long)]
    pub env: Option<String>,
    /// A trained policy (a run directory, a committed result run, a checkpoint, a budget
    /// policy file or an exported policy), `raibert` (the controller), `random`, `zero`, or
    /// `actions:FILE.csv`.
    #[arg(long)]
    pub policy: String,
    /// With a run directory as --policy: the actor the run saved at this step budget.
    #[arg(long)]
    pub budget: Option<u64>,
    /// Episodes to record, one after another (reset seeds from --seed on).
    #[arg(long, default_value_t = 1)]
    pub episodes: usize,
    #[command(flatten)]
    pub seed: super::SeedArg,
    /// The controller's commanded forward speed (m/s), reached over the first second (as in
    /// `baseline`).
    #[arg(long, default_value_t = 0.35)]
    pub speed: f64,
    #[command(flatten)]
    pub command: super::baseline::CommandArgs,
    /// Gait of the Raibert controller (Minitaur: bound, trot, pace; Ant: row, trot).
    #[arg(long)]
    pub gait: Option<String>,
    /// Options over the policy's environment, e.g. `--option max_episode_steps=200`.
    #[command(flatten)]
    pub env_options: super::EnvOptionArgs,
    /// The rerun recording to write (default rollout.rrd, unless --video is given alone).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Also render the episodes into a video: .mp4 (H.264, plays in browsers), .webm (VP9) or
    /// .gif (for Markdown). Offscreen, no display needed (MUJOCO_GL=osmesa, the default, or egl).
    #[arg(long, value_name = "FILE")]
    pub video: Option<PathBuf>,
    /// The video's camera: follow (the robot's base, the default), fixed:NAME (one of the
    /// model's cameras) or free:DISTANCE,AZIMUTH,ELEVATION.
    #[arg(long, default_value = "follow")]
    pub camera: String,
    /// The video's width and height in pixels.
    #[arg(long, default_value_t = 640)]
    pub width: usize,
    #[arg(long, default_value_t = 480)]
    pub height: usize,
    /// At most this many frames per simulated second (the video plays in real time).
    #[arg(long, default_value_t = 25.0)]
    pub fps: f64,
    /// With --video: more panels beside the policy's, left to right, each playing the same
    /// episode (reset seed --seed) with the same camera: `controller` (the Raibert controller,
    /// Minitaur and Ant, commanded to the policy's mean speed over the episode, capped at 1.5
    /// m/s) or another trained policy. Repeatable; one episode.
    #[arg(long = "side-by-side", value_name = "controller|POLICY")]
    pub side_by_side: Vec<String>,
    /// With --video: a caption on every frame: the policy, the step, the return so far and the
    /// mean forward speed so far (and a push's size while one is marked).
    #[arg(long)]
    pub caption: bool,
    /// Open the recording in the rerun viewer (needs `rerun` on the PATH).
    #[arg(long)]
    pub spawn: bool,
}

pub fn run(args: RecordArgs) -> Result<()> {
    let agent_holder;
    let simple = ["raibert", "random", "zero"].contains(&args.policy.as_str()) || args.policy.starts_with("actions:");
    anyhow::ensure!(
        !(simple && args.budget.is_some()),
        "--budget applies to a trained policy, not to --policy {}",
        args.policy
    );
    let (cfg, mut policy): (_, Box<dyn Policy>) = match args.policy.as_str() {
        "raibert" => {
            let env = args.env.as_deref().context("--policy raibert needs --env minitaur or --env ant")?;
            let gait = args.gait.as_deref().map(parse_gait).transpose()?;
            let command = args.command.commands(&[args.speed])?.remove(0);
            (baseline_env(env)?, baseline_controller_for(env, command, gait)?)
        }
        p if p == "random" || p == "zero" || p.starts_with("actions:") => {
            let env = args.env.as_deref().with_context(|| format!("--policy {p} needs --env"))?;
            (locobench::envs::EnvConfig::new(env), simple_policy(p, args.seed.seed)?)
        }
        checkpoint => {
            let path = std::path::Path::new(checkpoint);
            let (run, agent) = resolve_policy(path, args.budget).and_then(|p| p.load()).with_context(|| {
                format!("--policy '{checkpoint}' is not raibert, random, zero, actions:FILE.csv or a trained policy")
            })?;
            if let Some(env) = &args.env {
                anyhow::ensure!(*env == run.env.name, "the checkpoint was trained on {}, not {env}", run.env.name);
            }
            agent_holder = agent;
            let label =
                format!("{} {}", run.train.algo.name(), path.file_name().unwrap_or(path.as_os_str()).to_string_lossy());
            (run.env.for_evaluation(), Box::new(AgentPolicy { agent: agent_holder.as_ref(), label }) as Box<dyn Policy>)
        }
    };
    let cfg = args.env_options.apply(cfg)?;
    if !args.side_by_side.is_empty() {
        return side_by_side(&args, &cfg, policy.as_mut());
    }
    let mut env = make(&cfg)?;
    let rrd = match (&args.out, &args.video) {
        (Some(out), _) => Some(out.clone()),
        (None, None) => Some(PathBuf::from("rollout.rrd")),
        (None, Some(_)) => None,
    };
    let recording = rrd.as_deref().map(Recording::create).transpose()?;
    let mut recorder = match &recording {
        Some(r) => Some(RolloutRecorder::new(r.stream(), env.data().model())?),
        None => None,
    };
    let mut video = match &args.video {
        Some(path) => {
            let settings =
                RenderSettings { width: args.width, height: args.height, camera: Camera::parse(&args.camera)? };
            let film = Film::video(env.data().model(), env.spec().dt, settings, path, args.fps)?;
            Some(if args.caption { film.with_caption(policy.name()) } else { film })
        }
        None => None,
    };
    let mut observers: Vec<&mut dyn Observer> = Vec::new();
    if let Some(r) = recorder.as_mut() {
        observers.push(r);
    }
    if let Some(v) = video.as_mut() {
        observers.push(v);
    }
    let summaries =
        run_episodes(env.as_mut(), policy.as_mut(), args.episodes, args.seed.seed, &mut Observers(observers))?;
    let frames = recorder.as_ref().map(|r| r.frames());
    drop(recorder);
    for s in &summaries {
        println!(
            "{} with {}: episode {} return {:.3} over {} steps",
            cfg.name,
            policy.name(),
            s.episode,
            s.episode_return,
            s.length
        );
    }
    if let Some(v) = video {
        let (frames, every) = (v.frame_count(), v.stride());
        let path = v.finish()?;
        println!("wrote {} ({frames} frames, one every {every} steps, real time)", path.display());
    }
    if let Some(recording) = recording {
        let path = recording.finish()?;
        println!("wrote {} ({} frames); view it with `rerun {}`", path.display(), frames.unwrap_or(0), path.display());
        if args.spawn {
            spawn_viewer(&path)?;
        }
    }
    Ok(())
}

/// Several observers watching one rollout, in order.
struct Observers<'a>(Vec<&'a mut dyn Observer>);

impl Observer for Observers<'_> {
    fn reset(&mut self, episode: usize, env: &dyn locobench::envs::Env) -> Result<()> {
        self.0.iter_mut().try_for_each(|o| o.reset(episode, env))
    }
    fn step(&mut self, view: &locobench::rollout::StepView) -> Result<()> {
        self.0.iter_mut().try_for_each(|o| o.step(view))
    }
    fn end(&mut self, summary: &locobench::rollout::EpisodeSummary) -> Result<()> {
        self.0.iter_mut().try_for_each(|o| o.end(summary))
    }
}

/// The controller's top command here (the grid the report sweeps ends there).
const CONTROLLER_TOP_SPEED: f64 = 1.5;

/// `record --video FILE --side-by-side ...`: the policy's episode and each other panel's, tiled.
fn side_by_side(args: &RecordArgs, cfg: &locobench::envs::EnvConfig, policy: &mut dyn Policy) -> Result<()> {
    let path = args.video.as_ref().context("--side-by-side makes a video: give --video FILE")?;
    anyhow::ensure!(args.episodes == 1, "--side-by-side films one episode (the same one in every panel): --episodes 1");
    anyhow::ensure!(args.out.is_none(), "--side-by-side writes a video only: leave out --out");
    locobench::render::video::check_encoder(locobench::render::video::Format::of(path)?)?;
    let settings = RenderSettings { width: args.width, height: args.height, camera: Camera::parse(&args.camera)? };
    let seed = args.seed.seed;
    let caption = |label: String| args.caption.then_some(label);
    let name = policy.name();
    let first = film_episode(cfg, policy, &settings, args.fps, seed, caption(name.clone()).as_deref(), None)?;
    println!("left: {name} on {}: return {:.3}, {:.2} m/s", cfg.name, first.episode_return, first.speed);
    let speed = first.speed;
    let mut panels = vec![first];
    for spec in &args.side_by_side {
        let (panel, label) = if spec == "controller" {
            let (env, command, label) = if locobench::envs::command::is_command_task(&cfg.name) {
                // On a command task the controller follows the task's command, as the policy does.
                (baseline_env_like(cfg)?, Command::straight(0.0, 0.0), "controller".to_string())
            } else {
                let speed = speed.clamp(0.0, CONTROLLER_TOP_SPEED);
                let base = baseline_env(&cfg.name).with_context(|| {
                    format!("--side-by-side controller: {} has no controller (minitaur, ant)", cfg.name)
                })?;
                // The same --option and --reward settings as the policy's panel.
                let base = args.env_options.apply(base)?;
                let command = args.command.commands(&[speed])?.into_iter().next().unwrap();
                (base, command, format!("controller at {speed:.2} m/s"))
            };
            let mut controller = baseline_controller_for(&cfg.name, command, None)?;
            let panel = film_episode(
                &env,
                controller.as_mut(),
                &settings,
                args.fps,
                seed,
                caption(label.clone()).as_deref(),
                None,
            )?;
            (panel, label)
        } else {
            let (run, agent) = resolve_policy(std::path::Path::new(spec), None)?.load()?;
            anyhow::ensure!(
                run.env.name == cfg.name,
                "--side-by-side {spec} was trained on {}, not {}",
                run.env.name,
                cfg.name
            );
            let mut other = AgentPolicy { agent: agent.as_ref(), label: spec.clone() };
            let env = args.env_options.apply(run.env.for_evaluation())?;
            let label = format!(
                "{} {}",
                run.train.algo.name(),
                std::path::Path::new(spec).file_name().map_or(spec.clone(), |f| f.to_string_lossy().into_owned())
            );
            (film_episode(&env, &mut other, &settings, args.fps, seed, caption(label.clone()).as_deref(), None)?, label)
        };
        anyhow::ensure!(
            (panel.fps - panels[0].fps).abs() < 1e-9,
            "{spec} acts at another rate than the policy: its frames would not line up"
        );
        println!("next: {label}: return {:.3}, {:.2} m/s", panel.episode_return, panel.speed);
        panels.push(panel);
    }
    let (tiled, fps) = tile_panels(&panels)?;
    let path = write_video(path, &tiled, fps)?;
    println!("wrote {} ({} frames of {} panels, episode seed {seed})", path.display(), tiled.len(), panels.len());
    Ok(())
}
