//! The same command for everyone: on a command task (`envs::command`), the controller and each
//! group's policies hold the same commands on the same held-out episodes
//! (`evaluation::tracking`), and the report shows commanded against achieved speed with bands and
//! the grid table. Every grid point's episodes go through the evaluation cache, keyed by the
//! env's resolved options, so the command settings are part of the key. With videos on, the
//! policy that tracks best and the controller follow one schedule side by side (walk, speed up,
//! turn, stop), the command and the achieved speed in each panel's caption.
use std::path::Path;

use anyhow::Result;

use super::budgets::{policy_at, reached, shipped_step};
use super::document::{Block, Document};
use super::format::interval;
use super::plots::{bands_svg, Band};
use super::runs::{Group, Run};
use super::videos::{Clip, ClipPlan};
use super::ReportOptions;
use crate::controller::baseline::{baseline_controller_for, baseline_env_like};
use crate::controller::command::Command;
use crate::envs::EnvConfig;
use crate::evaluation::cache::Key;
use crate::evaluation::robustness::suite::PolicySource;
use crate::evaluation::tracking::{point_env, tracking_episodes, TrackingEpisode, TrackingPoint};
use crate::io::write_bytes_atomic;
use crate::policy::AgentPolicy;

/// The commanded speeds of the report's grid (m/s), those within a run's `speed_range`.
pub const GRID_SPEEDS: [f64; 6] = [0.25, 0.5, 1.0, 1.5, 2.0, 2.5];
/// The commanded yaw rates of the report's grid (rad/s), those within a run's `yaw_rate_range`:
/// straight, and turning either way at the rate the controller follows.
pub const GRID_YAW_RATES: [f64; 3] = [0.0, -0.3, 0.3];

/// One contender's grid (every speed straight, then every speed at each turn rate), and for a
/// learned one the policy its clip plays (its first seed's).
struct Contender {
    label: String,
    points: Vec<TrackingPoint>,
    clip_policy: Option<PolicySource>,
}

impl Contender {
    /// Its straight-ahead points, in the order of the speeds.
    fn straight(&self) -> Vec<&TrackingPoint> {
        self.points.iter().filter(|p| p.yaw_rate == 0.0).collect()
    }

    /// The mean of its straight grid points' mean RMS speed errors.
    fn mean_speed_rms(&self) -> f64 {
        let xs: Vec<f64> = self.straight().iter().map(|p| p.speed_rms().estimate).collect();
        xs.iter().sum::<f64>() / xs.len().max(1) as f64
    }
}

/// The filmed schedule, as (fraction of the episode, forward speed m/s, yaw rate rad/s) knots:
/// walk, speed up, turn, stop.
const FILMED_SCHEDULE: [(f64, f64, f64); 4] = [(0.0, 0.5, 0.0), (0.3, 1.0, 0.0), (0.6, 1.0, 0.3), (0.8, 0.0, 0.0)];

/// What the tracking section gives the rest of the report: its clips, and the blocks the
/// summary opens the env with.
#[derive(Default)]
pub(crate) struct Tracking {
    pub clips: Vec<Clip>,
    pub summary: Vec<Block>,
}

/// The tracking section of a command task, and its clip when videos are on; nothing when the env
/// is not one.
pub(crate) fn section(
    doc: &mut Document,
    out: &Path,
    env: &str,
    groups: &[(&Group, &Vec<&Run>)],
    opts: &ReportOptions,
) -> Result<Tracking> {
    if !crate::envs::command::is_command_task(env) {
        return Ok(Tracking::default());
    }
    let Some(first) = groups.iter().flat_map(|(_, rs)| rs.iter()).next() else { return Ok(Tracking::default()) };
    let base_env = first.config.env.for_evaluation();
    let speeds = grid_speeds(&base_env)?;
    let commands: Vec<(f64, f64)> =
        grid_yaw_rates(&base_env)?.into_iter().flat_map(|w| speeds.iter().map(move |&v| (v, w))).collect();
    let protocol = opts.protocol;
    let mut contenders = Vec::new();
    // The controller, where the task has one, on the same episodes.
    if let Ok(cfg) = baseline_env_like(&base_env) {
        let mut points = Vec::new();
        for &(speed, yaw_rate) in &commands {
            let at = point_env(&cfg, speed, yaw_rate);
            let key = opts.cache.timed(|| Key::tracking(&at, &protocol, "controller command"))?;
            let episodes = opts.cache.tracking(&key, || {
                let mut c = baseline_controller_for(&cfg.name, Command::straight(0.0, 0.0), None)?;
                tracking_episodes(&at, c.as_mut(), protocol)
            })?;
            points.push(TrackingPoint { speed, yaw_rate, episodes });
        }
        contenders.push(Contender { label: "controller".into(), points, clip_policy: None });
    }
    for (group, runs) in groups {
        let mut points: Vec<TrackingPoint> =
            commands.iter().map(|&(speed, yaw_rate)| TrackingPoint { speed, yaw_rate, episodes: Vec::new() }).collect();
        let mut budgets = Vec::new();
        let mut clip_policy = None;
        for run in runs.iter() {
            // The newest policy the run kept at a whole 100k (a run's last step is seldom round), or
            // its newest; a run still training has metrics beyond it.
            let held: Vec<u64> =
                crate::train::budget_policy_steps(&run.dir).into_iter().filter(|s| *s <= reached(run)).collect();
            let newest = held.iter().copied().filter(|s| s % 100_000 == 0).max().or_else(|| held.iter().copied().max());
            let Some(budget) = newest.or_else(|| shipped_step(&run.dir)) else { continue };
            let Ok(source) = policy_at(run, budget) else { continue };
            let (cfg, agent) = source.load(&run.dir, budget)?;
            protocol.check_run(cfg.seed, &cfg.train)?;
            let env_config = cfg.env.for_evaluation();
            let digest = source.digest(&run.dir)?;
            for p in points.iter_mut() {
                let at = point_env(&env_config, p.speed, p.yaw_rate);
                let key = opts.cache.timed(|| Key::tracking(&at, &protocol, &format!("agent {digest}")))?;
                let episodes: Vec<TrackingEpisode> = opts.cache.tracking(&key, || {
                    let mut policy = AgentPolicy { agent: agent.as_ref(), label: run.algo().to_string() };
                    tracking_episodes(&at, &mut policy, protocol)
                })?;
                p.episodes.extend(episodes);
            }
            budgets.push(budget);
            clip_policy.get_or_insert(PolicySource { reference: run.dir.clone(), budget: Some(budget) });
        }
        if budgets.is_empty() {
            continue;
        }
        let seeds = if budgets.len() == 1 { "1 seed".to_string() } else { format!("{} seeds", budgets.len()) };
        // Each seed plays its newest whole-100k policy; seeds that stopped at different budgets
        // are named by the range.
        let (low, high) = (budgets.iter().min().copied().unwrap_or(0), budgets.iter().max().copied().unwrap_or(0));
        let at = if low == high {
            super::format::budget(low)
        } else {
            format!("{}-{}", super::format::budget(low), super::format::budget(high))
        };
        let label = format!("{} at {at} ({seeds})", group.label());
        contenders.push(Contender { label, points, clip_policy });
    }
    if contenders.is_empty() {
        return Ok(Tracking::default());
    }
    doc.heading(2, "Same command: speed tracking");
    doc.lines(vec![format!(
        "Every contender holds the same commands, straight ahead and turning either way, on the same {} held-out \
         episodes per command and seed, from a standing start: RMS errors of speed and yaw rate after the first \
         second, falls with Wilson intervals, cost of transport, 95% intervals. The chart shows the straight \
         commands. `locobench track` gives the same measures for any grid.",
        protocol.episodes
    )]);
    let bands: Vec<Band> = contenders
        .iter()
        .map(|c| {
            let achieved: Vec<_> = c.straight().iter().map(|p| p.achieved_speed()).collect();
            Band {
                label: c.label.clone(),
                x: c.straight().iter().map(|p| p.speed).collect(),
                mean: achieved.iter().map(|i| i.estimate).collect(),
                low: achieved.iter().map(|i| i.low).collect(),
                high: achieved.iter().map(|i| i.high).collect(),
            }
        })
        .collect();
    let mut all = bands.clone();
    all.push(Band {
        label: "command".into(),
        x: speeds.clone(),
        mean: speeds.clone(),
        low: speeds.clone(),
        high: speeds.clone(),
    });
    let file = format!("{env}_tracking.svg");
    let svg = bands_svg(
        &format!("{env}: achieved against commanded speed"),
        "commanded speed m/s",
        "achieved speed m/s",
        &all,
        &[],
    )?;
    write_bytes_atomic(&out.join(&file), svg.as_bytes())?;
    doc.image(file, "achieved speed against the command (mean after the first second, 95% intervals)".to_string());
    let mut rows = Vec::new();
    for c in &contenders {
        for p in &c.points {
            let f = p.fall_rate();
            rows.push(vec![
                c.label.clone(),
                format!("{:.2}", p.speed),
                format!("{:.1}", p.yaw_rate),
                interval(p.speed_rms(), |v| format!("{v:.3}")),
                interval(p.yaw_rate_rms(), |v| format!("{v:.3}")),
                interval(p.achieved_speed(), |v| format!("{v:.2}")),
                format!("{}/{} [{:.2}, {:.2}]", p.falls(), p.episodes.len(), f.low, f.high),
                interval(p.cost_of_transport(), |v| format!("{v:.2}")),
            ]);
        }
    }
    doc.table(
        &[
            "contender",
            "command m/s",
            "yaw rate rad/s",
            "speed RMS m/s",
            "yaw-rate RMS rad/s",
            "achieved m/s",
            "falls",
            "cost of transport",
        ],
        rows,
    );
    let clips =
        if opts.videos { schedule_clip(doc, out, env, &base_env, &contenders, groups, opts)? } else { Vec::new() };
    let mut summary = summary(env, &speeds, &contenders, protocol.episodes);
    summary.extend(clips.iter().map(Block::clip));
    Ok(Tracking { clips, summary })
}

/// The summary's opening for a command task: per command, each contender's RMS speed error and
/// falls.
fn summary(env: &str, speeds: &[f64], contenders: &[Contender], episodes: usize) -> Vec<Block> {
    let mut header = vec!["command m/s".to_string()];
    header.extend(contenders.iter().map(|c| c.label.clone()));
    let rows = speeds
        .iter()
        .enumerate()
        .map(|(k, speed)| {
            let mut row = vec![format!("{speed:.2}")];
            row.extend(contenders.iter().map(|c| {
                let p = c.straight()[k];
                format!("{:.3} m/s, falls {}/{}", p.speed_rms().estimate, p.falls(), p.episodes.len())
            }));
            row
        })
        .collect();
    vec![
        Block::Paragraph(format!(
            "{env}, the same straight commands for every contender ({episodes} held-out episodes per command and seed): \
             the mean RMS speed error after the first second, and the falls. The tracking section below gives the \
             intervals and the cost of transport; the line after this table, the return on the task's own random \
             commands."
        )),
        Block::Table { header, rows },
    ]
}

/// Films the learned contender with the lowest mean RMS speed error beside the controller on
/// [`FILMED_SCHEDULE`].
fn schedule_clip(
    doc: &mut Document,
    out: &Path,
    env: &str,
    base_env: &EnvConfig,
    contenders: &[Contender],
    groups: &[(&Group, &Vec<&Run>)],
    opts: &ReportOptions,
) -> Result<Vec<Clip>> {
    let best = contenders
        .iter()
        .filter(|c| c.clip_policy.is_some())
        .min_by(|a, b| a.mean_speed_rms().total_cmp(&b.mean_speed_rms()));
    let Some(best) = best else { return Ok(Vec::new()) };
    let spec = crate::envs::make(base_env)?.spec().clone();
    let seconds = spec.max_episode_steps as f64 * spec.dt;
    let schedule = filmed_schedule(seconds);
    let mut cfg = base_env.clone();
    cfg.options.insert("schedule".into(), toml::Value::String(schedule.clone()));
    let source = best.clip_policy.clone().expect("filtered above");
    let caption = format!(
        "{}, left, and the controller, right, following the same schedule (`{schedule}`: time s, forward speed m/s, \
         yaw rate rad/s) on the first held-out episode; the captions give the command and the speed and yaw rate \
         achieved over the last half second",
        best.label
    );
    let plan = ClipPlan::command_schedule(format!("{env}_schedule"), caption, source, best.label.clone(), cfg);
    let clips = super::videos::film(&[plan], groups, out, &opts.protocol, opts.threads, &opts.cache)?;
    for clip in &clips {
        doc.video(clip);
    }
    Ok(clips)
}

/// [`FILMED_SCHEDULE`] over an episode of `seconds`, as the `schedule` option spells it.
fn filmed_schedule(seconds: f64) -> String {
    FILMED_SCHEDULE
        .iter()
        .map(|(at, v, w)| format!("{}:{v}:{w}", (at * seconds * 100.0).round() / 100.0))
        .collect::<Vec<_>>()
        .join(" ")
}

/// [`GRID_YAW_RATES`] within the env's `yaw_rate_range`.
fn grid_yaw_rates(env: &EnvConfig) -> Result<Vec<f64>> {
    let range = crate::envs::command::command_ranges(env)?.map_or([f64::NEG_INFINITY, f64::INFINITY], |(_, w)| w);
    Ok(GRID_YAW_RATES.iter().copied().filter(|w| (range[0] - 1e-9..=range[1] + 1e-9).contains(w)).collect())
}

/// [`GRID_SPEEDS`] within the env's `speed_range`.
fn grid_speeds(env: &EnvConfig) -> Result<Vec<f64>> {
    let high = crate::envs::command::command_ranges(env)?.map_or(f64::INFINITY, |(speeds, _)| speeds[1]);
    Ok(GRID_SPEEDS.iter().copied().filter(|s| *s <= high + 1e-9).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_filmed_schedule_spans_the_episode_and_parses() {
        let s = filmed_schedule(10.0);
        assert_eq!(s, "0:0.5:0 3:1:0 6:1:0.3 8:0:0");
        let parsed = crate::envs::command::Schedule::parse(&s).unwrap().unwrap();
        assert_eq!(parsed.at(7.0), [1.0, 0.3]);
        assert_eq!(filmed_schedule(50.0), "0:0.5:0 15:1:0 30:1:0.3 40:0:0");
    }
}
