//! Running a controller for whole episodes and measuring how it walks.
use anyhow::Result;

use crate::envs::Env;
use crate::policy::Policy;
use crate::rollout::{run_episode, StepView};

/// Locomotion measures of one episode.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaitEpisode {
    pub episode_return: f64,
    pub length: usize,
    pub fell: bool,
    /// Mean forward speed (m/s): forward distance over episode time.
    pub mean_speed: f64,
    /// Mean |forward velocity - set-point| over steps (m/s).
    pub speed_error: f64,
    /// Mechanical energy delivered by the motors (J), where the env reports it.
    pub energy: f64,
    /// energy / (m g distance); infinite when the robot did not advance.
    pub cost_of_transport: f64,
    pub drift: f64,
    pub shake: f64,
    /// Control ticks whose force QP failed and fell back to sharing the weight.
    pub qp_failures: f64,
}

/// Mean cost of transport over the episodes that moved forward (infinite if none did).
pub fn mean_cost_of_transport(episodes: &[GaitEpisode]) -> f64 {
    let finite: Vec<f64> = episodes.iter().map(|e| e.cost_of_transport).filter(|c| c.is_finite()).collect();
    if finite.is_empty() {
        f64::INFINITY
    } else {
        finite.iter().sum::<f64>() / finite.len() as f64
    }
}

/// Runs `episodes` episodes (the first reset seeded with `seed`) and measures each against
/// the speed set-point.
pub fn measure(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    episodes: usize,
    seed: u64,
    set_point: f64,
) -> Result<Vec<GaitEpisode>> {
    let dt = env.spec().dt;
    let mass: f64 = env.data().model().body_mass().iter().sum();
    let gravity = -env.data().model().gravity()[2];
    let mut out = Vec::with_capacity(episodes);
    for episode in 0..episodes {
        let mut e = GaitEpisode::default();
        let (mut start_x, mut end_x) = (0.0, 0.0);
        let reset_seed = if episode == 0 { Some(seed) } else { None };
        let summary = run_episode(env, policy, episode, reset_seed, &mut |v: &StepView| {
            let (t, step) = (v.t, v.step);
            let x = step.info.metric("x_position").unwrap_or(0.0);
            let vx = step.info.metric("x_velocity").unwrap_or(0.0);
            if t == 0 {
                start_x = x - vx * dt;
            }
            end_x = x;
            e.speed_error += (vx - set_point).abs();
            e.energy += step.info.metric("mechanical_energy").unwrap_or(0.0);
            e.drift += step.info.metric("dy").map(f64::abs).unwrap_or(0.0);
            e.shake += step.info.metric("dz").map(f64::abs).unwrap_or(0.0);
            Ok(())
        })?;
        e.episode_return = summary.episode_return;
        e.length = summary.length;
        e.fell = summary.terminated || summary.unstable;
        let distance = end_x - start_x;
        let time = summary.length as f64 * dt;
        e.mean_speed = if time > 0.0 { distance / time } else { 0.0 };
        e.speed_error /= summary.length.max(1) as f64;
        e.cost_of_transport = if distance > 0.0 { e.energy / (mass * gravity * distance) } else { f64::INFINITY };
        e.qp_failures = policy.diagnostics().iter().find(|(n, _)| *n == "qp_failures").map_or(0.0, |(_, v)| *v);
        out.push(e);
    }
    Ok(out)
}
