//! One policy's held-out episodes summed up as `locobench eval` prints them and
//! `locobench.evaluate` returns them: mean and IQM return with bootstrap intervals over the
//! episodes, sample spread, falls with their Wilson interval, length, speed, cost of transport and
//! each reward term's mean; and the optional comparisons, the controller at the policy's speed on
//! the same episodes and survival under pushes.
use anyhow::Result;

use super::stats::{self, wilson, Interval};
use super::{ControllerFamily, Protocol, Push};
use crate::controller::measure::{mean_cost_of_transport, GaitEpisode};
use crate::envs::{make, EnvConfig};
use crate::evaluation::stats::{estimate, BOOTSTRAP_SEED};
use crate::policy::Policy;

/// The held-out statistics of one policy.
#[derive(Debug, Clone)]
pub struct HeldOutSummary {
    /// Episodes played.
    pub episodes: usize,
    /// Mean return, with its 95% percentile bootstrap interval over episodes.
    pub mean: Interval,
    /// Interquartile mean return, with its interval.
    pub iqm: Interval,
    /// Sample standard deviation of the returns.
    pub std: f64,
    /// Episodes that ended in a fall or a blow-up.
    pub falls: usize,
    /// The fall rate's 95% Wilson interval.
    pub fall_rate: Interval,
    /// Mean episode length (steps).
    pub length: f64,
    /// Mean forward speed (m/s).
    pub speed: f64,
    /// Mean cost of transport.
    pub cost_of_transport: f64,
    /// Each reward term's mean over episodes, in the env's order.
    pub reward_terms: Vec<(String, f64)>,
}

impl HeldOutSummary {
    /// The statistics of `episodes` (at least one).
    pub fn of(episodes: &[GaitEpisode]) -> HeldOutSummary {
        let returns: Vec<f64> = episodes.iter().map(|e| e.episode_return).collect();
        let falls = episodes.iter().filter(|e| e.fell).count();
        let mean_of = |f: &dyn Fn(&GaitEpisode) -> f64| stats::mean(&episodes.iter().map(f).collect::<Vec<_>>());
        let reward_terms = episodes.first().map_or_else(Vec::new, |first| {
            first
                .reward_terms
                .iter()
                .enumerate()
                .map(|(i, (term, _))| (term.to_string(), mean_of(&|e| e.reward_terms[i].1)))
                .collect()
        });
        HeldOutSummary {
            episodes: episodes.len(),
            mean: estimate(std::slice::from_ref(&returns), stats::mean, BOOTSTRAP_SEED).interval,
            iqm: estimate(std::slice::from_ref(&returns), stats::iqm, BOOTSTRAP_SEED ^ 1).interval,
            std: stats::sample_std(&returns),
            falls,
            fall_rate: wilson(falls, episodes.len()),
            length: mean_of(&|e| e.length as f64),
            speed: mean_of(&|e| e.mean_speed),
            cost_of_transport: mean_cost_of_transport(episodes),
            reward_terms,
        }
    }

    /// The lines `locobench eval` prints under its heading.
    pub fn lines(&self) -> Vec<String> {
        let i = |v: Interval| crate::evaluation::stats::interval(v, |x| format!("{x:.3}"));
        let mut out = vec![
            format!("  return  mean {} (95% CI over episodes)", i(self.mean)),
            format!("  return  IQM  {}", i(self.iqm)),
            format!("  return  sample std {:.3}", self.std),
            format!(
                "  falls   {}/{} ({:.2}-{:.2})",
                self.falls, self.episodes, self.fall_rate.low, self.fall_rate.high
            ),
            format!("  length  {:.1}", self.length),
            format!("  speed   {:.3} m/s", self.speed),
        ];
        out.extend(self.reward_terms.iter().map(|(term, m)| format!("  {term:<14} {m:>12.3}")));
        out
    }
}

/// The controller commanded to a policy's mean speed, on the same episodes.
#[derive(Debug, Clone)]
pub struct MatchedController {
    /// Commanded speed (m/s, the policy's rounded to 1 mm/s).
    pub commanded: f64,
    /// Its own statistics.
    pub summary: HeldOutSummary,
    /// P(policy's return > controller's) over the paired episodes (ties count half), with a
    /// bootstrap interval over episodes.
    pub policy_better: Interval,
}

/// Plays the controller of `cfg`'s env (Minitaur, Ant) commanded to `speed` on `protocol`'s
/// episodes, in `cfg`'s env switched to the controller's action mode, and pairs it with the
/// policy's `episodes`. None when the speed is outside the controller's grid (0 to its top).
pub fn controller_at_speed(
    cfg: &EnvConfig,
    protocol: Protocol,
    speed: f64,
    episodes: &[GaitEpisode],
) -> Result<Option<MatchedController>> {
    if !(speed > 0.0 && speed <= super::speed_grid::GRID_MAX) {
        return Ok(None);
    }
    let mut family = ControllerFamily::new(cfg, protocol)?;
    let point = family.at(speed, None)?.clone();
    let wins: Vec<f64> = episodes
        .iter()
        .zip(&point.episodes)
        .map(|(p, c)| stats::probability_of_improvement(&[(p.episode_return, c.episode_return)]))
        .collect();
    Ok(Some(MatchedController {
        commanded: point.commanded,
        summary: HeldOutSummary::of(&point.episodes),
        policy_better: estimate(&[wins], stats::mean, BOOTSTRAP_SEED ^ 2).interval,
    }))
}

/// Episodes survived (no fall) out of those played under a push of `delta_v` m/s.
pub fn push_survival(
    cfg: &EnvConfig,
    protocol: Protocol,
    policy: &mut dyn Policy,
    delta_v: f64,
) -> Result<(usize, usize)> {
    let mut env = make(cfg)?;
    let eps = protocol.run(env.as_mut(), policy, None, Some(Push::lateral(delta_v)))?;
    Ok((eps.iter().filter(|e| !e.fell).count(), eps.len()))
}
