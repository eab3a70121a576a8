//! Has a learned policy walked past the controller? One held-out check, made as the report makes
//! its comparison: the policy plays the protocol's held-out episodes; its mean return is set
//! against the controller's at the policy's own mean speed (commanded whatever achieves that
//! speed on the grid), or, when the policy runs faster than the controller can, against the
//! controller's best working speed. `benches/time_to_walk.rs` makes this check during training.
use anyhow::Result;

use super::protocol::Protocol;
use super::speed_grid::{
    best_point, beyond_range, command_for, working_points, ControllerFamily, SpeedPoint, GRID_MAX, GRID_STEP,
};
use super::stats;
use crate::envs::{make, EnvConfig};
use crate::policy::Policy;

/// The controller a policy is compared with.
#[derive(Debug, Clone, PartialEq)]
pub struct ControllerComparison {
    /// The controller's commanded speed (m/s).
    pub command: f64,
    /// True: commanded to run at the policy's speed; false: the policy runs faster than the
    /// controller can, and this is the controller's best working speed.
    pub matched: bool,
    /// The controller's mean return over the same held-out episodes.
    pub mean_return: f64,
}

/// One held-out check of a policy.
#[derive(Debug, Clone)]
pub struct HeldOutCheck {
    /// Mean return over the held-out episodes.
    pub mean_return: f64,
    /// Its 95% bootstrap interval over episodes.
    pub return_interval: stats::Interval,
    /// Mean forward speed over the episodes (m/s).
    pub speed: f64,
    /// Episodes that ended in a fall.
    pub falls: usize,
    /// Episodes played.
    pub episodes: usize,
    /// The controller it is compared with, or why there is none (the policy does not move
    /// forward; the controller works at no speed).
    pub controller: Result<ControllerComparison, String>,
}

impl HeldOutCheck {
    /// The policy's mean return is above the controller's it is compared with.
    pub fn beats_controller(&self) -> bool {
        self.controller.as_ref().is_ok_and(|c| self.mean_return > c.mean_return)
    }
}

/// The controller's grid on one env, evaluated once, and the held-out episodes policies play.
#[derive(Clone)]
pub struct WalkingCheck {
    env_config: EnvConfig,
    protocol: Protocol,
    family: ControllerFamily,
    grid: Vec<SpeedPoint>,
}

impl WalkingCheck {
    /// Sweeps the controller's grid on `env_config`'s env (Minitaur or Ant) with `threads`
    /// speeds at once; policies are then checked in that same env.
    pub fn new(env_config: &EnvConfig, protocol: Protocol, threads: usize) -> Result<WalkingCheck> {
        let mut family = ControllerFamily::new(env_config, protocol)?;
        family.threads = threads;
        let grid = family.sweep(GRID_STEP, GRID_MAX)?;
        Ok(WalkingCheck { env_config: env_config.clone(), protocol, family, grid })
    }

    /// The controller's best working speed: (command, mean return).
    pub fn controller_best(&self) -> Option<(f64, f64)> {
        best_point(&self.grid).map(|p| (p.commanded, stats::mean(&p.returns())))
    }

    /// The fastest speed the controller achieves without falling or losing track (m/s).
    pub fn controller_top_speed(&self) -> Option<f64> {
        working_points(&self.grid).map(|p| p.achieved()).last()
    }

    /// Plays the held-out episodes with `policy` and compares it with the controller.
    pub fn check(&mut self, policy: &mut dyn Policy) -> Result<HeldOutCheck> {
        let mut env = make(&self.env_config)?;
        let episodes = self.protocol.run(env.as_mut(), policy, None, None)?;
        let returns: Vec<f64> = episodes.iter().map(|e| e.episode_return).collect();
        let speed = stats::mean(&episodes.iter().map(|e| e.mean_speed).collect::<Vec<_>>());
        let return_interval = stats::stratified_bootstrap(
            std::slice::from_ref(&returns),
            |v| stats::mean(&v[0]),
            stats::BOOTSTRAP_REPS,
            0,
        );
        let beyond = beyond_range(&self.grid, speed);
        let controller = if beyond {
            best_point(&self.grid)
                .map(|p| ControllerComparison {
                    command: p.commanded,
                    matched: false,
                    mean_return: stats::mean(&p.returns()),
                })
                .ok_or_else(|| "the controller works at no speed of the grid".to_string())
        } else {
            match command_for(&self.grid, speed) {
                Ok(command) => {
                    let point = self.family.at(command, None)?;
                    Ok(ControllerComparison { command, matched: true, mean_return: stats::mean(&point.returns()) })
                }
                Err(why) => Err(why),
            }
        };
        Ok(HeldOutCheck {
            mean_return: stats::mean(&returns),
            return_interval,
            speed,
            falls: episodes.iter().filter(|e| e.fell).count(),
            episodes: episodes.len(),
            controller,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::baseline::{baseline_controller, baseline_env_like};
    use crate::policy::ZeroPolicy;

    #[test]
    fn the_controller_is_matched_with_itself_and_a_standing_robot_beats_nothing() {
        // The controller's own action mode, so that the controller can play the policy's part.
        let env = baseline_env_like(&EnvConfig::new("minitaur")).unwrap();
        let mut check = WalkingCheck::new(&env, Protocol { episodes: 2, seed: 0 }, 2).unwrap();
        let (best_command, best_return) = check.controller_best().unwrap();
        assert!(best_command >= 1.0 && best_return > 8.0, "{best_command} {best_return}");

        let standing = check.check(&mut ZeroPolicy).unwrap();
        assert_eq!(standing.episodes, 2);
        assert!(!standing.beats_controller(), "{standing:?}");

        let mut itself = baseline_controller("minitaur", 1.0, None).unwrap();
        let c = check.check(itself.as_mut()).unwrap();
        let against = c.controller.as_ref().unwrap();
        assert!(against.matched, "{c:?}");
        assert!((against.command - 1.0).abs() < 0.05, "{}", against.command);
        assert!((c.mean_return - against.mean_return).abs() < 0.5, "{} {}", c.mean_return, against.mean_return);
        assert_eq!(c.falls, 0);
    }
}
