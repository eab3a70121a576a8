//! The same command for everyone: on a command task (`envs::command`), the controller and each
//! group's policies hold the same commands on the same held-out episodes
//! (`evaluation::tracking`), and the report shows commanded against achieved speed with bands and
//! the grid table. Every grid point's episodes go through the evaluation cache, keyed by the
//! env's resolved options, so the command settings are part of the key.
use std::path::Path;

use anyhow::Result;

use super::budgets::{policy_at, reached, shipped_step};
use super::document::Document;
use super::format::interval;
use super::plots::{bands_svg, Band};
use super::runs::{Group, Run};
use super::ReportOptions;
use crate::controller::baseline::{baseline_controller_for, baseline_env_like};
use crate::controller::command::Command;
use crate::envs::EnvConfig;
use crate::evaluation::cache::Key;
use crate::evaluation::tracking::{point_env, tracking_episodes, TrackingEpisode, TrackingPoint};
use crate::io::write_bytes_atomic;
use crate::policy::AgentPolicy;

/// The commanded speeds of the report's grid (m/s), those within a run's `speed_range`.
pub const GRID_SPEEDS: [f64; 6] = [0.25, 0.5, 1.0, 1.5, 2.0, 2.5];

/// One contender's grid.
struct Contender {
    label: String,
    points: Vec<TrackingPoint>,
}

/// The tracking section of a command task; nothing when the env is not one.
pub(crate) fn section(
    doc: &mut Document,
    out: &Path,
    env: &str,
    groups: &[(&Group, &Vec<&Run>)],
    opts: &ReportOptions,
) -> Result<()> {
    if !env.ends_with("-command") {
        return Ok(());
    }
    let Some(first) = groups.iter().flat_map(|(_, rs)| rs.iter()).next() else { return Ok(()) };
    let base_env = first.config.env.for_evaluation();
    let speeds = grid_speeds(&base_env)?;
    let protocol = opts.protocol;
    let mut contenders = Vec::new();
    // The controller, where the task has one, on the same episodes.
    if let Ok(cfg) = baseline_env_like(&base_env) {
        let mut points = Vec::new();
        for &speed in &speeds {
            let at = point_env(&cfg, speed, 0.0);
            let key = opts.cache.timed(|| Key::tracking(&at, &protocol, "controller command"))?;
            let episodes = opts.cache.tracking(&key, || {
                let mut c = baseline_controller_for(&cfg.name, Command::straight(0.0, 0.0), None)?;
                tracking_episodes(&at, c.as_mut(), protocol)
            })?;
            points.push(TrackingPoint { speed, yaw_rate: 0.0, episodes });
        }
        contenders.push(Contender { label: "controller".into(), points });
    }
    for (group, runs) in groups {
        let mut points: Vec<TrackingPoint> =
            speeds.iter().map(|&speed| TrackingPoint { speed, yaw_rate: 0.0, episodes: Vec::new() }).collect();
        let mut budgets = Vec::new();
        for run in runs.iter() {
            // The newest policy the run kept at a whole 100k (a run's last step is seldom round), or
            // its newest; a run still training has metrics beyond it.
            let held: Vec<u64> =
                crate::train::budget_policy_steps(&run.dir).into_iter().filter(|s| *s <= reached(run)).collect();
            let newest = held.iter().copied().filter(|s| s % 100_000 == 0).max().or_else(|| held.iter().copied().max());
            let Some(budget) = newest.or_else(|| shipped_step(&run.dir)) else { continue };
            let Ok(source) = policy_at(run, budget) else { continue };
            let (cfg, agent) = source.load(&run.dir, budget)?;
            protocol.check_disjoint(cfg.seed, cfg.train.total_steps, cfg.train.eval_episodes)?;
            let env_config = cfg.env.for_evaluation();
            let digest = source.digest(&run.dir)?;
            for p in points.iter_mut() {
                let at = point_env(&env_config, p.speed, 0.0);
                let key = opts.cache.timed(|| Key::tracking(&at, &protocol, &format!("agent {digest}")))?;
                let episodes: Vec<TrackingEpisode> = opts.cache.tracking(&key, || {
                    let mut policy = AgentPolicy { agent: agent.as_ref(), label: run.algo().to_string() };
                    tracking_episodes(&at, &mut policy, protocol)
                })?;
                p.episodes.extend(episodes);
            }
            budgets.push(budget);
        }
        if budgets.is_empty() {
            continue;
        }
        let seeds = if budgets.len() == 1 { "1 seed".to_string() } else { format!("{} seeds", budgets.len()) };
        let label = format!("{} at {} ({seeds})", group.label(), super::format::budget(budgets[0]));
        contenders.push(Contender { label, points });
    }
    if contenders.is_empty() {
        return Ok(());
    }
    doc.heading(2, "Same command: speed tracking");
    doc.lines(vec![format!(
        "Every contender holds the same commands (straight ahead, yaw rate 0) on the same {} held-out episodes per \
         command and seed, from a standing start: RMS errors after the first second, falls with Wilson intervals, \
         cost of transport, 95% intervals. `locobench track` gives the same measures for any grid, turns included.",
        protocol.episodes
    )]);
    let bands: Vec<Band> = contenders
        .iter()
        .map(|c| {
            let achieved: Vec<_> = c.points.iter().map(|p| p.achieved_speed()).collect();
            Band {
                label: c.label.clone(),
                x: c.points.iter().map(|p| p.speed).collect(),
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
                interval(p.speed_rms(), |v| format!("{v:.3}")),
                interval(p.achieved_speed(), |v| format!("{v:.2}")),
                format!("{}/{} [{:.2}, {:.2}]", p.falls(), p.episodes.len(), f.low, f.high),
                interval(p.cost_of_transport(), |v| format!("{v:.2}")),
            ]);
        }
    }
    doc.table(&["contender", "command m/s", "speed RMS m/s", "achieved m/s", "falls", "cost of transport"], rows);
    Ok(())
}

/// [`GRID_SPEEDS`] within the env's `speed_range`.
fn grid_speeds(env: &EnvConfig) -> Result<Vec<f64>> {
    let resolved = env.resolved_options()?;
    let high = resolved
        .get("speed_range")
        .and_then(|r| r.as_array())
        .and_then(|a| a.get(1))
        .and_then(|v| v.as_float())
        .unwrap_or(f64::INFINITY);
    Ok(GRID_SPEEDS.iter().copied().filter(|s| *s <= high + 1e-9).collect())
}
