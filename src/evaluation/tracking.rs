//! How closely a policy follows a velocity command, over a grid of commands: the measure of the
//! command tasks (`envs::command`). Every contender, controller or learned policy, plays the same
//! held-out episodes at each grid point, each episode holding one command (a schedule of one
//! knot) from a standing start. Per grid point, with intervals:
//! - tracking error: per episode the RMS of (forward speed - command) and of (yaw rate - command)
//!   once the first [`SETTLE_WINDOW`] seconds are over, then the mean over episodes with a
//!   bootstrap interval;
//! - falls, with a Wilson interval;
//! - cost of transport, the motors' mechanical work over (total mass x g x path length);
//! - the time to settle: when the forward speed, averaged over half a second, enters and stays
//!   within [`SETTLE_BAND`] of the command, for at least [`SETTLE_HOLD`] seconds before the
//!   episode ends (of a standing start, so the time a command change takes).
use anyhow::{ensure, Result};

use super::protocol::Protocol;
use super::stats::{mean, stratified_bootstrap, wilson, Interval, BOOTSTRAP_SEED};
use crate::envs::{make, EnvConfig};
use crate::policy::Policy;
use crate::rollout::{run_episode, StepView};

/// Seconds at the start of an episode left out of the tracking error: the start from standing.
pub const SETTLE_WINDOW: f64 = 1.0;

/// The band around the command the speed settles in: 0.1 m/s, or 10% of the command if larger.
pub const SETTLE_BAND: (f64, f64) = (0.1, 0.1);

/// Seconds the speed is averaged over for the settling time.
const SMOOTHING: f64 = 0.5;

/// Seconds the smoothed speed must stay in the band before the episode ends to count as settled:
/// a speed that enters the band in the last moments of an episode has not shown that it stays.
pub const SETTLE_HOLD: f64 = 2.0;

/// One episode at one command.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingEpisode {
    /// RMS forward-speed error after the settle window (m/s); NaN if the episode ended before it.
    pub speed_rms: f64,
    /// RMS yaw-rate error after the settle window (rad/s).
    pub yaw_rate_rms: f64,
    /// The robot fell (the episode terminated).
    pub fell: bool,
    /// Mechanical work / (mass g path length); NaN when it did not move.
    pub cost_of_transport: f64,
    /// Seconds until the smoothed speed stayed within the band; None if it never did.
    pub settle_time: Option<f64>,
    /// Mean forward speed after the settle window (m/s).
    pub speed: f64,
}

/// A grid point's episodes and their summary.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingPoint {
    /// Commanded forward speed (m/s).
    pub speed: f64,
    /// Commanded yaw rate (rad/s).
    pub yaw_rate: f64,
    /// Every episode.
    pub episodes: Vec<TrackingEpisode>,
}

impl TrackingPoint {
    fn interval(&self, value: impl Fn(&TrackingEpisode) -> f64) -> Interval {
        let xs: Vec<f64> = self.episodes.iter().map(value).filter(|v| v.is_finite()).collect();
        if xs.is_empty() {
            return Interval::point(f64::NAN);
        }
        stratified_bootstrap(&[xs], |s| mean(&s[0]), 1000, BOOTSTRAP_SEED)
    }
    /// Mean RMS forward-speed error, with its bootstrap interval over episodes.
    pub fn speed_rms(&self) -> Interval {
        self.interval(|e| e.speed_rms)
    }
    /// Mean RMS yaw-rate error, with its interval.
    pub fn yaw_rate_rms(&self) -> Interval {
        self.interval(|e| e.yaw_rate_rms)
    }
    /// Mean achieved forward speed after the settle window, with its interval.
    pub fn achieved_speed(&self) -> Interval {
        self.interval(|e| e.speed)
    }
    /// Mean cost of transport, with its interval.
    pub fn cost_of_transport(&self) -> Interval {
        self.interval(|e| e.cost_of_transport)
    }
    /// Mean settling time over the episodes that settled, with its interval, and how many did.
    pub fn settle_time(&self) -> (Interval, usize) {
        (
            self.interval(|e| e.settle_time.unwrap_or(f64::NAN)),
            self.episodes.iter().filter(|e| e.settle_time.is_some()).count(),
        )
    }
    /// Falls among the episodes.
    pub fn falls(&self) -> usize {
        self.episodes.iter().filter(|e| e.fell).count()
    }
    /// The fall rate with its Wilson interval.
    pub fn fall_rate(&self) -> Interval {
        wilson(self.falls(), self.episodes.len())
    }
}

/// `env` holding the command (`speed`, `yaw_rate`) for the whole episode.
pub fn point_env(env: &EnvConfig, speed: f64, yaw_rate: f64) -> EnvConfig {
    let mut cfg = env.clone();
    cfg.options.insert("schedule".into(), toml::Value::String(format!("0:{speed}:{yaw_rate}")));
    cfg
}

/// Plays `policy` on `env` (a command task, holding one command: [`point_env`]) on the
/// protocol's held-out episodes.
pub fn tracking_episodes(env: &EnvConfig, policy: &mut dyn Policy, protocol: Protocol) -> Result<Vec<TrackingEpisode>> {
    ensure!(
        crate::envs::command::is_command_task(&env.name),
        "the tracking grid needs a command task (minitaur-command, ant-command), not {}",
        env.name
    );
    let command = match env.options.get("schedule").and_then(|s| s.as_str()) {
        Some(s) => crate::envs::command::Schedule::parse(s)
            .map_err(|e| anyhow::anyhow!("schedule: {e}"))?
            .map(|s| s.at(0.0))
            .ok_or_else(|| anyhow::anyhow!("the tracking grid needs one command (a schedule)"))?,
        None => anyhow::bail!("the tracking grid needs one command (a schedule)"),
    };
    let mut e = make(env)?;
    protocol
        .reset_seeds()
        .iter()
        .enumerate()
        .map(|(i, &seed)| track_episode(e.as_mut(), policy, i, seed, command))
        .collect()
}

/// Plays `policy` on `env` (a command task) at every (speed, yaw rate) of the grid, on the
/// protocol's held-out episodes.
pub fn tracking_grid(
    env: &EnvConfig,
    policy: &mut dyn Policy,
    speeds: &[f64],
    yaw_rates: &[f64],
    protocol: Protocol,
) -> Result<Vec<TrackingPoint>> {
    ensure!(!speeds.is_empty() && !yaw_rates.is_empty(), "the tracking grid needs at least one speed and one yaw rate");
    let mut points = Vec::new();
    for &yaw_rate in yaw_rates {
        for &speed in speeds {
            ensure!(speed.is_finite() && yaw_rate.is_finite(), "grid commands must be finite");
            let episodes = tracking_episodes(&point_env(env, speed, yaw_rate), policy, protocol)?;
            points.push(TrackingPoint { speed, yaw_rate, episodes });
        }
    }
    Ok(points)
}

fn track_episode(
    env: &mut dyn crate::envs::Env,
    policy: &mut dyn Policy,
    episode: usize,
    seed: u64,
    command: [f64; 2],
) -> Result<TrackingEpisode> {
    let dt = env.spec().dt;
    let mass: f64 = env.data().model().body_mass().iter().sum();
    let g = -env.data().model().gravity()[2];
    let mut speeds = Vec::new();
    let mut yaw_rates = Vec::new();
    let mut energy = 0.0;
    let mut path = 0.0;
    let mut last_xy: Option<(f64, f64)> = None;
    let mut observer = |v: &StepView| -> Result<()> {
        let m = |name: &str| v.step.info.metric(name).unwrap_or(f64::NAN);
        speeds.push(m("forward_velocity"));
        yaw_rates.push(m("yaw_rate"));
        energy += m("mechanical_energy").abs();
        let xy = (m("x_position"), m("y_position"));
        if let Some((x, y)) = last_xy {
            path += ((xy.0 - x).powi(2) + (xy.1 - y).powi(2)).sqrt();
        }
        last_xy = Some(xy);
        Ok(())
    };
    let summary = run_episode(env, policy, episode, Some(seed), &mut observer)?;
    let skip = (SETTLE_WINDOW / dt).round() as usize;
    let rms = |xs: &[f64], target: f64| -> f64 {
        if xs.len() <= skip {
            return f64::NAN;
        }
        (xs[skip..].iter().map(|x| (x - target).powi(2)).sum::<f64>() / (xs.len() - skip) as f64).sqrt()
    };
    let after = |xs: &[f64]| if xs.len() <= skip { f64::NAN } else { mean(&xs[skip..]) };
    Ok(TrackingEpisode {
        speed_rms: rms(&speeds, command[0]),
        yaw_rate_rms: rms(&yaw_rates, command[1]),
        fell: summary.terminated,
        cost_of_transport: if path > 1e-3 { energy / (mass * g * path) } else { f64::NAN },
        settle_time: if summary.terminated { None } else { settle_time(&speeds, command[0], dt) },
        speed: after(&speeds),
    })
}

/// The first time (s) after which the forward speed, averaged over [`SMOOTHING`] seconds, stays
/// within the band around `target` to the end of the episode, for at least [`SETTLE_HOLD`]
/// seconds; None if it never does.
pub fn settle_time(speeds: &[f64], target: f64, dt: f64) -> Option<f64> {
    let window = ((SMOOTHING / dt).round() as usize).max(1);
    if speeds.len() < window {
        return None;
    }
    let band = SETTLE_BAND.0.max(SETTLE_BAND.1 * target.abs());
    let smoothed: Vec<f64> = speeds.windows(window).map(mean).collect();
    // The first smoothed sample of the final stretch inside the band.
    let first_in = smoothed.iter().rposition(|v| (v - target).abs() > band).map_or(0, |i| i + 1);
    let held = (smoothed.len() - first_in) as f64 * dt;
    (held >= SETTLE_HOLD - 1e-9).then(|| (first_in + window - 1) as f64 * dt)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_settle_time_is_when_the_smoothed_speed_enters_the_band_for_good() {
        let dt = 0.1;
        // 0 for 1 s, then at the target: the 0.5 s average is in the band from t = 1.4 s on
        let mut speeds = vec![0.0; 10];
        speeds.extend(vec![1.0; 30]);
        let t = settle_time(&speeds, 1.0, dt).unwrap();
        assert!((t - 1.4).abs() < 1e-9, "{t}");
        // leaving the band at the end: never settled
        let mut late = speeds.clone();
        late.extend(vec![0.0; 10]);
        assert_eq!(settle_time(&late, 1.0, dt), None);
        // in the band from the start
        assert!((settle_time(&[1.0; 30], 1.0, dt).unwrap() - 0.4).abs() < 1e-9);
        // entering the band shortly before the end: not held for SETTLE_HOLD, so not settled
        let mut short = vec![0.0; 10];
        short.extend(vec![1.0; 23]);
        assert_eq!(settle_time(&short, 1.0, dt), None);
        short.push(1.0);
        assert!((settle_time(&short, 1.0, dt).unwrap() - 1.4).abs() < 1e-9);
    }
}
