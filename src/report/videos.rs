//! The report's videos (`report --videos`): per env and algorithm, the best row's policy on the
//! first held-out episode, beside the controller commanded to that row's speed on the same
//! episode where the env has a controller; and on those envs the same pair under a push (the
//! evaluation's push, marked in the frame). Each clip is an MP4 for `index.html` (the whole
//! episode, with a poster frame) and, for the clips the Markdown page plays, a short GIF, under
//! `videos/`. The robustness suite's clips get no GIF: the Markdown page shows their poster,
//! linked to the MP4, so that the committed report stays light.
use std::path::Path;

use anyhow::{Context, Result};

use super::budgets::policy_at;
use super::format::budget;
use super::heldout::BudgetRow;
use super::runs::{Group, Run};
use crate::controller::baseline::baseline_controller;
use crate::envs::EnvConfig;
use crate::evaluation::cache::{EvalCache, Key};
use crate::evaluation::parallel::map_in_order;
use crate::evaluation::{Protocol, Push};
use crate::policy::AgentPolicy;
use crate::render::clip::{film_episode, tile_panels, write_video_at, Panel};
use crate::render::video::Quality;
use crate::render::{Camera, RenderSettings};

/// The folder of the clips, in the report's directory.
pub const VIDEO_DIR: &str = "videos";

/// Each panel's size: two side by side make a 640x240 clip.
const PANEL: (usize, usize) = (320, 240);

/// A robustness clip's panel: four side by side make a 960x180 clip.
const SMALL_PANEL: (usize, usize) = (240, 180);

/// At most this many frames per simulated second, and about this many frames per panel at most
/// (a 50-second Ant episode is filmed at fewer frames per second than a 10-second Minitaur one).
const MAX_FPS: f64 = 25.0;
const MAX_FRAMES: f64 = 300.0;

/// The GIF copy: at most this many frames per second and seconds (a push clip's seconds start a
/// second before the push; a clip where a panel falls ends them just after its first fall). GIFs
/// compress far worse than H.264, so they are kept short: the MP4 shows the whole episode.
pub(crate) const GIF_FPS: f64 = 6.0;
pub(crate) const GIF_SECONDS: f64 = 3.0;

/// The push filmed (velocity change, m/s): the second level of the push table.
pub const FILMED_PUSH: f64 = super::controller::PUSH_LEVELS[1];

/// One panel of a clip: a learned row's representative run, a policy by reference (a robustness
/// suite's contender, in the suite's env), or the controller at a speed.
#[derive(Debug, Clone)]
enum Actor {
    Learned { run_dir: std::path::PathBuf, budget: u64, label: String },
    Policy { source: crate::evaluation::robustness::suite::PolicySource, label: String },
    Controller { speed: f64 },
}

/// One clip to film.
#[derive(Debug, Clone)]
pub struct ClipPlan {
    /// File name without extension, e.g. `minitaur_ppo` or `minitaur_ppo_push`.
    pub stem: String,
    /// What the clip shows, for its caption.
    pub caption: String,
    panels: Vec<Actor>,
    push: Option<Push>,
    env: EnvConfig,
    /// The episode's reset seed; the protocol's first held-out episode when absent.
    episode_seed: Option<u64>,
    /// Each panel's size in pixels.
    panel: (usize, usize),
    /// End the clip a second after the last panel that falls has fallen (the whole episode when
    /// none falls): what a robustness clip is about is decided by then.
    until_decided: bool,
    /// Write a GIF for the Markdown page (else it shows the poster, linked to the MP4).
    gif: bool,
}

impl ClipPlan {
    /// A clip of a command task's schedule (`cfg` holds it): `policy`, left, beside the
    /// controller following the same commands, right, on the first held-out episode.
    pub fn command_schedule(
        stem: String,
        caption: String,
        policy: crate::evaluation::robustness::suite::PolicySource,
        label: String,
        cfg: EnvConfig,
    ) -> ClipPlan {
        let mut panels = vec![Actor::Policy { source: policy, label }];
        if crate::controller::baseline::baseline_env_like(&cfg).is_ok() {
            panels.push(Actor::Controller { speed: 0.0 });
        }
        ClipPlan {
            stem,
            caption,
            panels,
            push: None,
            env: cfg,
            episode_seed: None,
            panel: PANEL,
            until_decided: false,
            gif: true,
        }
    }

    /// A clip of a robustness suite's contenders side by side, left to right, on one episode of
    /// `env` (an axis's level) with `push`: each policy row by its first seed, each controller at
    /// its commanded speed.
    pub fn of_contenders(
        stem: String,
        caption: String,
        contenders: &[crate::evaluation::robustness::Contender],
        env: EnvConfig,
        push: Option<Push>,
        episode_seed: u64,
    ) -> Result<ClipPlan> {
        use crate::evaluation::robustness::Contender;
        let panels = contenders
            .iter()
            .map(|c| match c {
                Contender::Controller { speed, .. } => Ok(Actor::Controller { speed: *speed }),
                Contender::Agent { label, seeds } => Ok(Actor::Policy {
                    source: seeds.first().with_context(|| format!("{label} has no policy"))?.clone(),
                    label: label.clone(),
                }),
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(ClipPlan {
            stem,
            caption,
            panels,
            push,
            env,
            episode_seed: Some(episode_seed),
            panel: SMALL_PANEL,
            until_decided: true,
            gif: false,
        })
    }
}

/// A clip written.
#[derive(Debug, Clone)]
pub struct Clip {
    /// The plan's file name without extension.
    pub stem: String,
    /// What it shows.
    pub caption: String,
    /// The MP4, relative to the report.
    pub video: String,
    /// The GIF, relative to the report, if the plan asked for one.
    pub gif: Option<String>,
    /// The poster frame (JPEG), relative to the report.
    pub poster: String,
    /// The longest panel's episode, in simulated seconds: what the MP4 lasts (it plays in real
    /// time), give or take a frame.
    pub duration: f64,
    /// The MP4's frames per second.
    pub fps: f64,
    /// Bytes of the MP4 and the GIF (0 without one).
    pub bytes: (u64, u64),
    /// How each panel's episode ended, left to right: whether it fell (a blow-up counts as one).
    pub fell: Vec<bool>,
}

impl Clip {
    /// Its MP4, GIF (if any) and poster, relative to the report.
    pub fn files(&self) -> Vec<String> {
        [Some(self.video.clone()), self.gif.clone(), Some(self.poster.clone())].into_iter().flatten().collect()
    }
}

/// How rows are ranked: by the lower end of the 95% interval of their mean held-out return, then
/// by the mean. A row whose return is high but uncertain (few seeds that disagree, or frequent
/// falls) ranks below one that is almost as high and sure.
pub(crate) fn rank_key(r: &BudgetRow) -> (f64, f64) {
    let i = r.mean_return(super::BOOTSTRAP_SEED).interval;
    (i.low, i.estimate)
}

/// Per algorithm, the index of its best row ([`rank_key`]) among the rows with a policy whose
/// index `keep` admits; in algorithm order.
pub fn best_rows(rows: &[BudgetRow], keep: impl Fn(usize) -> bool) -> Vec<usize> {
    let mut best: std::collections::BTreeMap<&str, (usize, (f64, f64))> = std::collections::BTreeMap::new();
    for (i, r) in rows.iter().enumerate().filter(|(i, r)| r.seeds() > 0 && keep(*i)) {
        let k = rank_key(r);
        let e = best.entry(r.group.algo.as_str()).or_insert((i, k));
        if k.0 > e.1 .0 || (k.0 == e.1 .0 && k.1 > e.1 .1) {
            *e = (i, k);
        }
    }
    best.into_values().map(|(i, _)| i).collect()
}

/// The run whose mean held-out return is the row's median (the lower one of an even count): the
/// seed a clip shows, so it is neither the luckiest nor the unluckiest.
fn representative(row: &BudgetRow) -> Option<&super::heldout::SeedResult> {
    let mut seeds: Vec<(f64, &super::heldout::SeedResult)> = row
        .evaluated
        .iter()
        .map(|s| (crate::evaluation::stats::mean(&s.episodes.iter().map(|e| e.episode_return).collect::<Vec<_>>()), s))
        .collect();
    seeds.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.seed.cmp(&b.1.seed)));
    seeds.get((seeds.len().max(1) - 1) / 2).map(|(_, s)| *s)
}

/// Where the controller stands beside a learned row: commanded to the row's speed, or, when it
/// cannot reach that speed, at its own best speed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControllerSpeed {
    /// The row's speed, which the controller reaches.
    Matched(f64),
    /// The controller's best speed; the row is faster or slower than the controller goes.
    Best(f64),
    /// The controller's best speed; the row trained under other env options than the
    /// controller's env, so it was not matched at its own speed.
    Unmatched(f64),
}

/// The clips of one env: per algorithm's best row, the policy (beside the controller when
/// `controller_speed` places one), and the same panels pushed when `push` is on.
pub fn plan(
    env: &str,
    rows: &[BudgetRow],
    best: &[usize],
    controller_speed: &dyn Fn(usize) -> Option<ControllerSpeed>,
    push: bool,
) -> Vec<ClipPlan> {
    let mut plans = Vec::new();
    for &i in best {
        let row = &rows[i];
        let (Some(seed), Some(cfg)) = (representative(row), row.env_config.clone()) else { continue };
        let label = format!("{} {}", row.group.algo, budget(row.budget));
        let learned = Actor::Learned {
            run_dir: seed.run_dir.clone(),
            budget: row.budget,
            label: format!("{label} seed {}", seed.seed),
        };
        let stem = format!("{env}_{}", row.group.algo);
        let who = format!(
            "{} at {} (seed {}, the median of the row's {} seeds)",
            row.group.label(),
            budget(row.budget),
            seed.seed,
            row.seeds()
        );
        let (panels, caption) = match controller_speed(i) {
            Some(ControllerSpeed::Matched(speed)) => (
                vec![learned, Actor::Controller { speed }],
                format!(
                    "{who}, left, beside the controller commanded to its speed ({speed:.2} m/s), right; the first held-out episode"
                ),
            ),
            Some(ControllerSpeed::Best(speed)) => (
                vec![learned, Actor::Controller { speed }],
                format!(
                    "{who}, left, beside the controller at its best speed ({speed:.2} m/s commanded; it does not reach the \
                     policy's {:.2} m/s), right; the first held-out episode",
                    row.speed()
                ),
            ),
            Some(ControllerSpeed::Unmatched(speed)) => (
                vec![learned, Actor::Controller { speed }],
                format!(
                    "{who}, left, beside the controller at its best speed ({speed:.2} m/s commanded; the policy trained \
                     under other env options, so it is not matched at its own speed), right; the first held-out episode"
                ),
            ),
            None => (vec![learned], format!("{who}; the first held-out episode")),
        };
        plans.push(ClipPlan {
            stem: stem.clone(),
            caption,
            panels: panels.clone(),
            push: None,
            env: cfg.clone(),
            episode_seed: None,
            panel: PANEL,
            until_decided: false,
            gif: true,
        });
        if push {
            plans.push(ClipPlan {
                stem: format!("{stem}_push"),
                caption: format!(
                    "The same episode pushed sideways (Δv {FILMED_PUSH} m/s, marked by the red arrow and the caption)"
                ),
                panels,
                push: Some(Push::lateral(FILMED_PUSH)),
                env: cfg,
                episode_seed: None,
                panel: PANEL,
                until_decided: false,
                gif: true,
            });
        }
    }
    plans
}

/// Films and writes every planned clip into `out/videos/`, panels filmed `threads` at a time. A
/// clip `cache` holds whose files are already in `out/videos/`, byte for byte, is kept as it is.
pub fn film(
    plans: &[ClipPlan],
    runs: &[(&Group, &Vec<&Run>)],
    out: &Path,
    protocol: &Protocol,
    threads: usize,
    cache: &EvalCache,
) -> Result<Vec<Clip>> {
    let dir = out.join(VIDEO_DIR);
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let first_seed = protocol.reset_seeds().first().copied().context("the protocol has no episodes")?;
    let keys =
        plans.iter().map(|p| clip_key(p, runs, p.episode_seed.unwrap_or(first_seed))).collect::<Result<Vec<Key>>>()?;
    let kept: Vec<Option<Clip>> =
        plans.iter().zip(&keys).map(|(p, k)| cache.lookup(k).and_then(|body| kept_clip(p, &body, &dir))).collect();
    let jobs: Vec<(usize, usize)> = plans
        .iter()
        .enumerate()
        .filter(|(c, _)| kept[*c].is_none())
        .flat_map(|(c, p)| (0..p.panels.len()).map(move |k| (c, k)))
        .collect();
    let panels = map_in_order(&jobs, threads, |&(c, k)| {
        let plan = &plans[c];
        film_panel(&plan.panels[k], &plan.env, plan.push, runs, plan.episode_seed.unwrap_or(first_seed), plan.panel)
            .with_context(|| format!("filming {} (panel {})", plan.stem, k + 1))
    })?;
    let mut clips = Vec::new();
    let mut at = 0;
    for ((plan, key), kept) in plans.iter().zip(&keys).zip(kept) {
        if let Some(clip) = kept {
            cache.count_read();
            clips.push(clip);
            continue;
        }
        let mine = &panels[at..at + plan.panels.len()];
        at += plan.panels.len();
        let clip = write_clip(plan, mine, &dir)?;
        cache.store(key, &clip_entry(&clip, out)?)?;
        clips.push(clip);
    }
    Ok(clips)
}

/// Everything a clip's files depend on besides the code: its env and episode, each panel's
/// policy (the digest of its weights and run config), label and command, push, size and cut.
fn clip_key(plan: &ClipPlan, runs: &[(&Group, &Vec<&Run>)], episode_seed: u64) -> Result<Key> {
    let mut what = vec![
        format!("stem = {}", plan.stem),
        crate::evaluation::cache::env_line(&plan.env)?,
        format!("episode seed = {episode_seed}"),
        format!("push = {:?}", plan.push),
        format!("panel = {:?}", plan.panel),
        format!("until decided = {}", plan.until_decided),
        format!("gif = {}", plan.gif),
        // The OpenGL the frames are drawn with (Mesa's OSMesa, or EGL on a GPU's driver).
        format!("gl = {:?}", crate::render::gl::Backend::from_env()?),
    ];
    for actor in &plan.panels {
        what.push(match actor {
            Actor::Learned { run_dir, budget, label } => {
                let run = find_run(runs, run_dir)?;
                let source = policy_at(run, *budget).map_err(|why| anyhow::anyhow!("{}: {why}", run_dir.display()))?;
                format!("learned {} at {budget}, {label:?}", source.digest(run_dir)?)
            }
            Actor::Policy { source, label } => {
                let digest = crate::train::resolve_policy(&source.reference, source.budget)?.digest()?;
                format!("policy {digest}, {label:?}")
            }
            Actor::Controller { speed } => format!("controller {speed:?}"),
        });
    }
    Ok(Key::clip(&what.join("\n")))
}

fn find_run<'a>(runs: &[(&Group, &Vec<&'a Run>)], run_dir: &Path) -> Result<&'a Run> {
    runs.iter()
        .flat_map(|(_, rs)| rs.iter().copied())
        .find(|r| r.dir == run_dir)
        .with_context(|| format!("{} is not among the report's runs", run_dir.display()))
}

/// A clip's cache entry: its measures and each file's SHA-256.
fn clip_entry(clip: &Clip, out: &Path) -> Result<String> {
    let digest = |rel: &str| crate::io::files_digest(&[out.join(rel)]);
    let fell: Vec<String> = clip.fell.iter().map(bool::to_string).collect();
    Ok(format!(
        "duration = {:?}\nfps = {:?}\nfell = {}\nmp4 = {}\ngif = {}\njpg = {}\n",
        clip.duration,
        clip.fps,
        fell.join(","),
        digest(&clip.video)?,
        clip.gif.as_deref().map_or(Ok(NO_GIF.to_string()), digest)?,
        digest(&clip.poster)?
    ))
}

/// A cache entry's `gif` for a clip without one.
const NO_GIF: &str = "none";

/// The clip of `plan` from its cache entry, when its files in `dir` are the ones the entry names;
/// None (film it) otherwise.
fn kept_clip(plan: &ClipPlan, body: &str, dir: &Path) -> Option<Clip> {
    let field = |name: &str| body.lines().find_map(|l| l.strip_prefix(name)?.strip_prefix(" = "));
    let file = |ext: &str| format!("{}.{ext}", plan.stem);
    let exts: &[&str] = if plan.gif { &["mp4", "gif", "jpg"] } else { &["mp4", "jpg"] };
    for ext in exts {
        if crate::io::files_digest(&[dir.join(file(ext))]).ok()? != field(ext)? {
            return None;
        }
    }
    if !plan.gif && field("gif")? != NO_GIF {
        return None;
    }
    let size = |ext: &str| std::fs::metadata(dir.join(file(ext))).map(|m| m.len()).ok();
    Some(Clip {
        stem: plan.stem.clone(),
        caption: plan.caption.clone(),
        video: format!("{VIDEO_DIR}/{}", file("mp4")),
        gif: plan.gif.then(|| format!("{VIDEO_DIR}/{}", file("gif"))),
        poster: format!("{VIDEO_DIR}/{}", file("jpg")),
        duration: field("duration")?.parse().ok()?,
        fps: field("fps")?.parse().ok()?,
        bytes: (size("mp4")?, if plan.gif { size("gif")? } else { 0 }),
        fell: field("fell")?.split(',').map(|f| f.parse().ok()).collect::<Option<Vec<bool>>>()?,
    })
}

fn film_panel(
    actor: &Actor,
    env: &EnvConfig,
    push: Option<Push>,
    runs: &[(&Group, &Vec<&Run>)],
    episode_seed: u64,
    size: (usize, usize),
) -> Result<Panel> {
    let settings = RenderSettings { width: size.0, height: size.1, camera: Camera::Follow };
    let spec = crate::envs::make(env)?.spec().clone();
    let episode_time = spec.max_episode_steps as f64 * spec.dt;
    let fps = MAX_FPS.min(MAX_FRAMES / episode_time);
    match actor {
        Actor::Learned { run_dir, budget, label, .. } => {
            let run = find_run(runs, run_dir)?;
            let source = policy_at(run, *budget).map_err(|why| anyhow::anyhow!("{}: {why}", run_dir.display()))?;
            let (cfg, agent) = source.load(run_dir, *budget)?;
            let mut policy = AgentPolicy { agent: agent.as_ref(), label: label.clone() };
            film_episode(
                &super::heldout::evaluation_env(&cfg.env),
                &mut policy,
                &settings,
                fps,
                episode_seed,
                Some(label),
                push,
            )
        }
        Actor::Policy { source, label } => {
            // In the given env, as the robustness suite plays it: the policy's own training
            // options are not used.
            let (run, agent) = crate::train::resolve_policy(&source.reference, source.budget)?
                .load()
                .with_context(|| format!("loading {label} from {}", source.reference.display()))?;
            anyhow::ensure!(run.env.name == env.name, "{label} was trained on {}, not on {}", run.env.name, env.name);
            let mut policy = AgentPolicy { agent: agent.as_ref(), label: label.clone() };
            film_episode(env, &mut policy, &settings, fps, episode_seed, Some(label), push)
        }
        Actor::Controller { speed } => {
            // In the learned policy's env, switched to the controller's action mode, as the
            // report's controller rows are.
            let env = crate::controller::baseline::baseline_env_like(env)?;
            let mut controller = baseline_controller(&env.name, *speed, None)?;
            // On a command task it follows the task's command, whatever the speed.
            let label = if crate::envs::command::is_command_task(&env.name) {
                "controller".to_string()
            } else {
                format!("controller {speed:.2} m/s")
            };
            film_episode(&env, controller.as_mut(), &settings, fps, episode_seed, Some(&label), push)
        }
    }
}

/// The frames of a `len`-frame clip at `fps` that its GIF shows: at most [`GIF_SECONDS`], from a
/// second before the push (the first frame a panel's caption marks it in), or else up to half a
/// second after the first fall, or else from the start.
fn gif_window(push: Option<f64>, first_fall: Option<f64>, fps: f64, len: usize) -> std::ops::Range<usize> {
    let start = match (push, first_fall) {
        (Some(push), _) => push - 1.0,
        (None, Some(fall)) => fall + 0.5 - GIF_SECONDS,
        (None, None) => 0.0,
    };
    let first = ((start.max(0.0) * fps) as usize).min(len.saturating_sub(1));
    first..(first + (GIF_SECONDS * fps) as usize).min(len)
}

fn write_clip(plan: &ClipPlan, panels: &[Panel], dir: &Path) -> Result<Clip> {
    let (mut frames, fps) = tile_panels(panels)?;
    let mut duration = panels.iter().map(|p| p.seconds).fold(0.0, f64::max);
    // When each panel that ended early fell (or blew up).
    let falls: Vec<f64> = panels.iter().filter(|p| p.fell || p.unstable).map(|p| p.seconds).collect();
    let last_fall = falls.iter().copied().fold(f64::NAN, f64::max);
    if plan.until_decided && last_fall + 1.0 < duration {
        // Whole frames only, and the duration the kept frames show: a browser plays n frames
        // for n / fps seconds, so the clip must not claim a fraction of a frame more or less.
        let kept = (((last_fall + 1.0) * fps).floor() as usize + 1).min(frames.len());
        frames.truncate(kept);
        duration = (kept - 1) as f64 / fps;
    }
    let name = |ext: &str| format!("{}.{ext}", plan.stem);
    // Compact: the report's clips are committed with its results.
    let video = write_video_at(&dir.join(name("mp4")), &frames, fps, Quality::Compact)?;
    crate::render::video::write_poster(&dir.join(name("jpg")), &frames[frames.len() / 2], Quality::Compact)?;
    let size = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    let gif = if plan.gif {
        let every = (fps / GIF_FPS).ceil().max(1.0) as usize;
        let push = panels.iter().filter_map(|p| p.push_time).reduce(f64::min);
        let first_fall = falls.iter().copied().reduce(f64::min);
        // At half the size: a GIF's frames compress far worse than a video's.
        let gif_frames: Vec<_> =
            frames[gif_window(push, first_fall, fps, frames.len())].iter().step_by(every).map(|f| f.half()).collect();
        Some(write_video_at(&dir.join(name("gif")), &gif_frames, fps / every as f64, Quality::Compact)?)
    } else {
        None
    };
    Ok(Clip {
        stem: plan.stem.clone(),
        caption: plan.caption.clone(),
        video: format!("{VIDEO_DIR}/{}", name("mp4")),
        gif: plan.gif.then(|| format!("{VIDEO_DIR}/{}", name("gif"))),
        poster: format!("{VIDEO_DIR}/{}", name("jpg")),
        duration,
        fps,
        bytes: (size(&video), gif.as_deref().map_or(0, size)),
        fell: panels.iter().map(|p| p.fell || p.unstable).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gif_window_starts_before_a_push_ends_after_a_fall_or_starts_at_the_start() {
        // 25 frames/s, 250 frames (10 s): a GIF is 3 s, 75 frames.
        assert_eq!(gif_window(None, None, 25.0, 250), 0..75);
        assert_eq!(gif_window(Some(4.0), Some(6.0), 25.0, 250), 75..150, "a second before the push at 4 s");
        assert_eq!(gif_window(None, Some(6.0), 25.0, 250), 87..162, "from 3.5 s to half a second after the fall");
        assert_eq!(gif_window(None, Some(1.0), 25.0, 250), 0..75, "a fall within the first seconds");
        assert_eq!(gif_window(Some(0.5), None, 25.0, 250), 0..75);
        assert_eq!(gif_window(None, Some(9.9), 25.0, 40), 39..40, "never past the last frame");
        assert_eq!(gif_window(None, None, 25.0, 10), 0..10, "a clip shorter than a GIF");
    }
}
