//! The controller as a family: one controller per commanded speed, evaluated over a grid of
//! speeds up to where it stops working, and evaluated again at any speed a learned policy runs
//! at, so a learned policy is compared with the controller at its own speed.
use std::collections::BTreeMap;

use anyhow::Result;

use super::protocol::Protocol;
use super::push::Push;
use crate::controller::baseline::{baseline_controller, baseline_env_like, RAMP_TIME};
use crate::controller::command::SpeedProfile;
use crate::controller::measure::GaitEpisode;
use crate::envs::{make, EnvConfig};

/// The grid every comparison uses: commanded multiples of `GRID_STEP` (m/s) up to the first that
/// fails, or `GRID_MAX`.
pub(crate) const GRID_STEP: f64 = 0.25;
pub(crate) const GRID_MAX: f64 = 4.0;

/// A speed works when no episode falls and the mean speed is within this share of the command.
pub(crate) const TRACKING_TOLERANCE: f64 = 0.10;

/// The controller commanded one speed, over the protocol's episodes.
#[derive(Debug, Clone)]
pub struct SpeedPoint {
    /// The commanded speed (m/s).
    pub commanded: f64,
    /// The protocol's episodes at that speed.
    pub episodes: Vec<GaitEpisode>,
}

impl SpeedPoint {
    pub(crate) fn achieved(&self) -> f64 {
        super::stats::mean(&self.episodes.iter().map(|e| e.mean_speed).collect::<Vec<_>>())
    }
    /// Episodes that ended in a fall.
    pub fn falls(&self) -> usize {
        self.episodes.iter().filter(|e| e.fell).count()
    }
    pub(crate) fn tracking_error(&self) -> f64 {
        (self.achieved() - self.commanded).abs() / self.commanded.abs().max(1e-9)
    }
    /// No fall, and the achieved speed within the tracking tolerance of the command.
    pub fn works(&self) -> bool {
        self.falls() == 0 && self.tracking_error() <= TRACKING_TOLERANCE
    }
    /// Each episode's return.
    pub fn returns(&self) -> Vec<f64> {
        self.episodes.iter().map(|e| e.episode_return).collect()
    }
}

/// Evaluates a controller of `env_config`'s env (Minitaur or Ant) under that config's reward and
/// options, caching each commanded speed.
#[derive(Clone)]
pub struct ControllerFamily {
    env_config: EnvConfig,
    protocol: Protocol,
    cache: BTreeMap<(i64, i64), SpeedPoint>,
    /// Speeds evaluated at once.
    pub threads: usize,
    /// Where evaluated speeds are kept across processes (off unless set).
    pub disk: super::cache::EvalCache,
}

fn round_speed(speed: f64) -> f64 {
    (speed * 1000.0).round() / 1000.0
}

fn key(speed: f64, push: Option<Push>) -> (i64, i64) {
    let push = push.map_or(-1, |p| {
        let size = (p.delta_v * 1000.0).round() as i64;
        match p.direction {
            super::push::PushDirection::Lateral => size,
            super::push::PushDirection::Frontal => -2 - size,
        }
    });
    ((round_speed(speed) * 1000.0).round() as i64, push)
}

impl ControllerFamily {
    /// `env_config`: the environment the learned policies ran in; the controller runs in it with
    /// its own action mode (`baseline_env_like`).
    pub fn new(env_config: &EnvConfig, protocol: Protocol) -> Result<ControllerFamily> {
        Ok(ControllerFamily {
            env_config: baseline_env_like(env_config)?,
            protocol,
            cache: BTreeMap::new(),
            threads: super::parallel::default_threads(),
            disk: super::cache::EvalCache::off(),
        })
    }

    /// The env's registered name.
    pub fn env(&self) -> &str {
        &self.env_config.name
    }

    /// The controller commanded `speed` (m/s, rounded to 1 mm/s), optionally under a push.
    pub fn at(&mut self, speed: f64, push: Option<Push>) -> Result<&SpeedPoint> {
        self.prefetch(&[(speed, push)])?;
        Ok(&self.cache[&key(speed, push)])
    }

    /// Evaluates the (speed, push) pairs not yet evaluated, several at once.
    pub(crate) fn prefetch(&mut self, jobs: &[(f64, Option<Push>)]) -> Result<()> {
        let mut missing: Vec<(f64, Option<Push>)> = jobs
            .iter()
            .filter(|(s, p)| !self.cache.contains_key(&key(*s, *p)))
            .map(|&(s, p)| (round_speed(s), p))
            .collect();
        missing.dedup_by_key(|(s, p)| key(*s, *p));
        let (cfg, protocol, disk) = (&self.env_config, &self.protocol, &self.disk);
        let points = super::parallel::map_in_order(&missing, self.threads, |&(speed, push)| -> Result<SpeedPoint> {
            let profile = SpeedProfile::ramp(speed, RAMP_TIME);
            let key =
                super::cache::Key::episodes(cfg, protocol, &format!("controller {speed:?}"), Some(&profile), push)?;
            let episodes = disk.episodes(&key, || {
                let mut env = make(cfg)?;
                let mut controller = baseline_controller(&cfg.name, speed, None)?;
                protocol.run(env.as_mut(), controller.as_mut(), Some(&profile), push)
            })?;
            Ok(SpeedPoint { commanded: speed, episodes })
        })?;
        for ((speed, push), point) in missing.into_iter().zip(points) {
            self.cache.insert(key(speed, push), point);
        }
        Ok(())
    }

    /// Commanded speeds `step, 2 step, ...` up to and including the first that does not work
    /// (or `max`), then two bisections between the last that works and the first that does not,
    /// so the top of the range is known to a quarter of a step. Sorted by command.
    pub fn sweep(&mut self, step: f64, max: f64) -> Result<Vec<SpeedPoint>> {
        let mut out = Vec::new();
        let mut k = 1;
        while step * k as f64 <= max + 1e-9 {
            // The next few speeds at once (one per thread); those past a failure go unused.
            let ahead: Vec<(f64, Option<Push>)> =
                (k..k + self.threads).map(|j| (step * j as f64, None)).filter(|(s, _)| *s <= max + 1e-9).collect();
            self.prefetch(&ahead)?;
            let point = self.at(step * k as f64, None)?.clone();
            let works = point.works();
            out.push(point);
            if !works {
                break;
            }
            k += 1;
        }
        if out.len() >= 2 && !out[out.len() - 1].works() && out[out.len() - 2].works() {
            let (mut good, mut bad) = (out[out.len() - 2].commanded, out[out.len() - 1].commanded);
            for _ in 0..2 {
                let mid = 0.5 * (good + bad);
                let point = self.at(mid, None)?.clone();
                if point.works() {
                    good = mid;
                } else {
                    bad = mid;
                }
                out.push(point);
            }
            out.sort_by(|a, b| a.commanded.total_cmp(&b.commanded));
        }
        Ok(out)
    }

    /// The controller at the speed a learned policy ran at: the command whose achieved speed on
    /// the grid interpolates to `speed` (over the working points below the first failing one),
    /// evaluated. None, with the reason, when the grid shows
    /// the controller cannot walk that fast, or the policy did not move forward.
    pub(crate) fn matched(&mut self, grid: &[SpeedPoint], speed: f64) -> Result<Result<SpeedPoint, String>> {
        match command_for(grid, speed) {
            Ok(c) => Ok(Ok(self.at(c, None)?.clone())),
            Err(why) => Ok(Err(why)),
        }
    }
}

/// The best working grid point by mean return.
pub(crate) fn best_point(grid: &[SpeedPoint]) -> Option<SpeedPoint> {
    grid.iter()
        .filter(|p| p.works())
        .max_by(|a, b| super::stats::mean(&a.returns()).total_cmp(&super::stats::mean(&b.returns())))
        .cloned()
}

/// The grid's working range: its points up to the first where the controller falls or loses
/// track.
pub(crate) fn working_points(grid: &[SpeedPoint]) -> impl Iterator<Item = &SpeedPoint> {
    grid.iter().take_while(|p| p.works())
}

/// Whether `speed` is faster than the controller achieves anywhere in its working range.
pub(crate) fn beyond_range(grid: &[SpeedPoint], speed: f64) -> bool {
    working_points(grid).last().is_some_and(|top| speed > top.achieved() * (1.0 + 1e-9))
}

/// The command that achieves `speed`, by linear interpolation of (achieved, commanded) over the
/// grid's working points (the ramp from standing makes the achieved speed trail the command);
/// an error below the slowest or above the fastest working point.
pub(crate) fn command_for(grid: &[SpeedPoint], speed: f64) -> Result<f64, String> {
    let working: Vec<(f64, f64)> = working_points(grid).map(|p| (p.achieved(), p.commanded)).collect();
    let Some(&(top, top_cmd)) = working.last() else {
        return Err("the controller works at no speed of the grid".into());
    };
    if speed.is_nan() || speed <= 0.0 {
        return Err(format!("the policy does not move forward ({speed:.3} m/s)"));
    }
    if beyond_range(grid, speed) {
        return Err(format!("beyond the controller's range ({top:.2} m/s achieved at {top_cmd:.2} commanded)"));
    }
    let (a0, c0) = working[0];
    // Below the grid the controller would be commanded towards standing still, where any policy
    // that stands without paying for energy "beats" it: no comparison there.
    if speed < a0 * (1.0 - 1e-9) {
        return Err(format!(
            "slower than the controller's slowest grid speed ({a0:.2} m/s achieved at {c0:.2} commanded)"
        ));
    }
    for w in working.windows(2) {
        let ((a0, c0), (a1, c1)) = (w[0], w[1]);
        if speed <= a1 {
            return Ok(c0 + (speed - a0) * (c1 - c0) / (a1 - a0).max(1e-12));
        }
    }
    Ok(top_cmd)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(commanded: f64, achieved: f64, fell: bool) -> SpeedPoint {
        SpeedPoint { commanded, episodes: vec![GaitEpisode { mean_speed: achieved, fell, ..Default::default() }] }
    }

    #[test]
    fn a_speed_works_without_falls_and_within_tolerance() {
        assert!(point(1.0, 0.93, false).works());
        assert!(!point(1.0, 0.85, false).works());
        assert!(!point(1.0, 1.0, true).works());
    }

    #[test]
    fn commands_interpolate_over_working_points_only() {
        let grid = vec![point(0.5, 0.45, false), point(1.0, 0.95, false), point(1.5, 1.0, true)];
        assert!((command_for(&grid, 0.7).unwrap() - 0.75).abs() < 1e-12);
        assert!((command_for(&grid, 0.45).unwrap() - 0.5).abs() < 1e-12);
        assert!(command_for(&grid, 0.225).unwrap_err().contains("slower"));
        assert!(command_for(&grid, 0.98).unwrap_err().contains("beyond"));
        assert!(command_for(&grid, -0.1).unwrap_err().contains("forward"));
        assert!(command_for(&[point(0.5, 0.1, false)], 0.1).unwrap_err().contains("no speed"));
    }

    #[test]
    fn minitaur_sweep_stops_at_the_first_speed_that_fails() {
        let mut family = ControllerFamily::new(&EnvConfig::new("minitaur"), Protocol { episodes: 2, seed: 0 }).unwrap();
        let grid = family.sweep(1.0, 3.0).unwrap();
        assert!(grid[0].works(), "1 m/s works");
        assert!(grid.windows(2).all(|w| w[0].commanded < w[1].commanded), "sorted by command");
        // 1 and 2 m/s, then two bisections when 2 fails (1.5, then 1.75 or 1.25); or 1, 2, 3.
        assert!(grid.len() == 4 || (grid.len() == 3 && grid.iter().all(|p| p.works())), "{}", grid.len());
        // Cached: asking again gives the same episodes.
        assert_eq!(family.at(1.0, None).unwrap().episodes, grid[0].episodes);
    }
}
