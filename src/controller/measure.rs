//! Running a controller (or any policy) for whole episodes and measuring how it walks against a
//! speed profile: speeds in the heading frame, so turning runs are measured like straight ones.
use anyhow::Result;

use super::command::{wrap_angle, SpeedProfile};
use crate::envs::Env;
use crate::policy::Policy;
use crate::rollout::{run_episode, Observer, StepView};

/// Locomotion measures of one episode.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaitEpisode {
    /// Sum of rewards.
    pub episode_return: f64,
    /// Steps taken.
    pub length: usize,
    /// The episode terminated because the robot fell, or the physics blew up.
    pub fell: bool,
    /// The physics blew up (MuJoCo's instability), which ended the episode.
    pub unstable: bool,
    /// Mean forward speed (m/s): distance travelled along the robot's heading over episode time.
    pub mean_speed: f64,
    /// Mean |forward velocity - set-point| over steps (m/s).
    pub speed_error: f64,
    /// Mean yaw rate (rad/s): heading change over episode time.
    pub yaw_rate: f64,
    /// Net displacement across the heading (m): how far the robot ended up to the side of
    /// where it was going.
    pub sideways: f64,
    /// Mechanical energy delivered by the motors (J), integrated every physics step.
    pub energy: f64,
    /// energy / (m g distance); infinite when the robot did not advance.
    pub cost_of_transport: f64,
    /// m g distance (J): the denominator of the cost of transport, 0 when it did not advance.
    pub weight_times_distance: f64,
    /// Sum of |sideways step| (m), PyBullet's drift term: sway counts as well as drift.
    pub drift: f64,
    /// Sum of |vertical step| (m), PyBullet's shake term.
    pub shake: f64,
    /// Control ticks whose force QP failed and fell back to sharing the weight.
    pub qp_failures: f64,
    /// The rest of the policy's end-of-episode diagnostics (a controller's limits).
    pub diagnostics: Vec<(&'static str, f64)>,
    /// Each reward term summed over the episode.
    pub reward_terms: Vec<(&'static str, f64)>,
}

/// Cost of transport of a set of episodes: their energy over their weight times distance, both
/// summed over the episodes that moved forward (a ratio of totals, so an episode that barely
/// moved does not dominate as a mean of ratios would); infinite if none did.
pub(crate) fn mean_cost_of_transport(episodes: &[GaitEpisode]) -> f64 {
    let forward = episodes.iter().filter(|e| e.weight_times_distance > 0.0);
    let (energy, work): (f64, f64) = forward.fold((0.0, 0.0), |(a, b), e| (a + e.energy, b + e.weight_times_distance));
    if work > 0.0 {
        energy / work
    } else {
        f64::INFINITY
    }
}

/// Position (x, y) and yaw of the base (the model's first body). A planar model (HalfCheetah,
/// Hopper, Walker2d) cannot turn: its heading is +x whatever its pitch. Reading yaw from its
/// orientation would give pi once the torso pitches past vertical, and a cheetah running on its
/// back would be measured as running backwards.
pub fn base_pose(env: &dyn Env) -> ([f64; 2], f64) {
    let d = env.data();
    let (p, r) = (&d.xpos()[3..6], &d.xmat()[9..18]);
    let yaw = if d.model().body_is_free(1) { r[3].atan2(r[0]) } else { 0.0 };
    ([p[0], p[1]], yaw)
}

struct GaitObserver<'a> {
    profile: Option<&'a SpeedProfile>,
    dt: f64,
    episode: GaitEpisode,
    pose: ([f64; 2], f64),
    forward_distance: f64,
    turned: f64,
}

impl Observer for GaitObserver<'_> {
    fn reset(&mut self, _episode: usize, env: &dyn Env) -> Result<()> {
        self.pose = base_pose(env);
        Ok(())
    }

    fn step(&mut self, v: &StepView) -> Result<()> {
        let (p, body_yaw) = base_pose(v.env);
        let yaw = wrap_angle(body_yaw + v.policy.heading_offset());
        let (p0, yaw0) = self.pose;
        let step = [p[0] - p0[0], p[1] - p0[1]];
        let mid = yaw0 + 0.5 * wrap_angle(yaw - yaw0);
        let (along, across) = (step[0] * mid.cos() + step[1] * mid.sin(), -step[0] * mid.sin() + step[1] * mid.cos());
        let e = &mut self.episode;
        self.forward_distance += along;
        e.sideways += across;
        self.turned += wrap_angle(yaw - yaw0);
        // Without a set-point (a trained agent) there is no speed error: it stays NaN.
        e.speed_error += self.profile.map_or(f64::NAN, |p| (along / self.dt - p.at(v.t as f64 * self.dt)).abs());
        let info = &v.step.info;
        e.energy += info.metric("mechanical_energy").unwrap_or(0.0);
        e.drift += info.metric("dy").map(f64::abs).unwrap_or(0.0);
        e.shake += info.metric("dz").map(f64::abs).unwrap_or(0.0);
        self.pose = (p, yaw);
        Ok(())
    }
}

/// Runs `episodes` episodes (the first reset seeded with `seed`, later ones continuing the
/// environment's random stream) and measures each against the speed profile (time from each
/// episode's start).
pub fn measure(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    episodes: usize,
    seed: u64,
    profile: &SpeedProfile,
) -> Result<Vec<GaitEpisode>> {
    (0..episodes)
        .map(|episode| {
            let reset_seed = if episode == 0 { Some(seed) } else { None };
            measure_episode(env, policy, episode, reset_seed, Some(profile))
        })
        .collect()
}

/// Runs and measures one episode, reset with `reset_seed` (None continues the environment's
/// random stream); `profile` is the set-point speed errors are measured against, if the policy
/// has one.
pub(crate) fn measure_episode(
    env: &mut dyn Env,
    policy: &mut dyn Policy,
    episode: usize,
    reset_seed: Option<u64>,
    profile: Option<&SpeedProfile>,
) -> Result<GaitEpisode> {
    let dt = env.spec().dt;
    let mass: f64 = env.data().model().body_mass().iter().sum();
    // |g|: on a slope (tilted gravity) the work against gravity is still m |g| distance per unit.
    let gravity = env.data().model().gravity().iter().map(|g| g * g).sum::<f64>().sqrt();
    let mut obs = GaitObserver {
        profile,
        dt,
        episode: GaitEpisode::default(),
        pose: ([0.0; 2], 0.0),
        forward_distance: 0.0,
        turned: 0.0,
    };
    let summary = run_episode(env, policy, episode, reset_seed, &mut obs)?;
    let mut e = obs.episode;
    e.episode_return = summary.episode_return;
    e.length = summary.length;
    e.fell = summary.fell();
    e.unstable = summary.unstable;
    e.reward_terms = summary.term_totals.clone();
    let time = summary.length as f64 * dt;
    let distance = obs.forward_distance;
    e.mean_speed = if time > 0.0 { distance / time } else { 0.0 };
    e.yaw_rate = if time > 0.0 { obs.turned / time } else { 0.0 };
    e.sideways = e.sideways.abs();
    e.speed_error /= summary.length.max(1) as f64;
    e.weight_times_distance = if distance > 0.0 { mass * gravity * distance } else { 0.0 };
    e.cost_of_transport = if distance > 0.0 { e.energy / e.weight_times_distance } else { f64::INFINITY };
    let diagnostics = policy.diagnostics();
    e.qp_failures = diagnostics.iter().find(|(n, _)| *n == "qp_failures").map_or(0.0, |(_, v)| *v);
    e.diagnostics = diagnostics.into_iter().filter(|(n, _)| !matches!(*n, "qp_failures" | "ticks")).collect();
    Ok(e)
}

/// The columns both `locobench baseline` and the report's baseline-vs-RL tables show for a set of
/// measured episodes (means over the episodes), so the two cannot drift apart.
pub const SUMMARY_COLUMNS: [&str; 11] = [
    "return",
    "speed m/s",
    "speed error m/s",
    "yaw rate rad/s",
    "side m",
    "energy J",
    "CoT",
    "drift m",
    "shake m",
    "falls",
    "length",
];

/// `SUMMARY_COLUMNS` for `episodes`, as text: the return as mean ± std, `fmt_return` formats
/// returns (their scale spans 0.01 to 10,000).
pub fn summary_cells(episodes: &[GaitEpisode], fmt_return: impl Fn(f64) -> String) -> Vec<String> {
    let n = episodes.len().max(1) as f64;
    let mean = |f: fn(&GaitEpisode) -> f64| episodes.iter().map(f).sum::<f64>() / n;
    let ret = mean(|e| e.episode_return);
    let ret_std = (episodes.iter().map(|e| (e.episode_return - ret).powi(2)).sum::<f64>() / n).sqrt();
    let fixed = |v: f64, digits: usize| if v.is_finite() { format!("{v:.digits$}") } else { "–".to_string() };
    vec![
        format!("{} ± {}", fmt_return(ret), fmt_return(ret_std)),
        fixed(mean(|e| e.mean_speed), 3),
        fixed(mean(|e| e.speed_error), 3),
        fixed(mean(|e| e.yaw_rate), 3),
        fixed(mean(|e| e.sideways), 3),
        fixed(mean(|e| e.energy), 1),
        fixed(mean_cost_of_transport(episodes), 2),
        fixed(mean(|e| e.drift), 3),
        fixed(mean(|e| e.shake), 3),
        format!("{}/{}", episodes.iter().filter(|e| e.fell).count(), episodes.len()),
        fixed(mean(|e| e.length as f64), 0),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cost_of_transport_is_a_ratio_of_totals() {
        let ep = |energy: f64, wd: f64| GaitEpisode { energy, weight_times_distance: wd, ..Default::default() };
        // CoT 1 and CoT 100 (barely moved): 11 J over 10.01 J, not the mean of ratios 50.5.
        let c = mean_cost_of_transport(&[ep(10.0, 10.0), ep(1.0, 0.01), ep(5.0, 0.0)]);
        assert!((c - 11.0 / 10.01).abs() < 1e-12, "{c}");
        assert_eq!(mean_cost_of_transport(&[ep(5.0, 0.0)]), f64::INFINITY);
    }
}
