//! Pushes: at a time drawn from each episode's reset seed, between 2 and 6 s in, the floating
//! base gets a shove that would change a free body's velocity by `delta_v` (impulse = total mass
//! x delta_v, spread over 0.1 s), sideways (left or right) or along the heading (forward or
//! backward) by the same draw. Every policy meets the same pushes on the same episodes.
use anyhow::{ensure, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Data;

/// Seconds the force acts for.
pub const PUSH_DURATION: f64 = 0.1;

/// Which way a push acts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PushDirection {
    /// Along world y: sideways to a robot walking along x.
    Lateral,
    /// Along world x: with or against the walking direction.
    Frontal,
}

/// One push per episode, at a time drawn from the episode's own stream.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Push {
    /// Velocity change (m/s) the impulse would give the whole robot as one free body.
    pub delta_v: f64,
    /// Which way it acts.
    pub direction: PushDirection,
}

impl Push {
    /// A sideways push of `delta_v` m/s.
    pub fn lateral(delta_v: f64) -> Push {
        Push { delta_v, direction: PushDirection::Lateral }
    }
    /// A push along the walking direction of `delta_v` m/s, forward or backward.
    pub fn frontal(delta_v: f64) -> Push {
        Push { delta_v, direction: PushDirection::Frontal }
    }
}

/// An environment whose base is pushed once per episode.
pub struct Pushed<'a> {
    inner: &'a mut dyn Env,
    /// Control steps the force acts for, and the force (N, along world y) while it does.
    steps: usize,
    force: f64,
    dof: usize,
    start: usize,
    t: usize,
}

impl<'a> Pushed<'a> {
    /// `inner`, pushed at each episode's drawn time (an error for a push that is not finite and >= 0).
    pub fn new(inner: &'a mut dyn Env, push: Push) -> Result<Pushed<'a>> {
        ensure!(
            push.delta_v.is_finite() && push.delta_v >= 0.0,
            "push size must be a finite number >= 0, got {}",
            push.delta_v
        );
        let m = inner.data().model();
        ensure!(m.has_floating_base(), "{} has no floating base to push", inner.spec().name);
        let mass: f64 = m.body_mass().iter().sum();
        let dt = inner.spec().dt;
        let steps = ((PUSH_DURATION / dt).round() as usize).max(1);
        let force = mass * push.delta_v / (steps as f64 * dt);
        let dof = match push.direction {
            PushDirection::Lateral => 1,
            PushDirection::Frontal => 0,
        };
        Ok(Pushed { inner, steps, force, dof, start: usize::MAX, t: 0 })
    }

    /// The control step the push starts at and its sign, drawn from the reset seed.
    fn draw(seed: u64, dt: f64) -> (usize, f64) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x9054_0000_0000_0000);
        let time = rng.random_range(2.0..6.0);
        let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
        ((time / dt).round() as usize, sign)
    }
}

impl Env for Pushed<'_> {
    fn spec(&self) -> &EnvSpec {
        self.inner.spec()
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        let out = self.inner.reset(seed)?;
        let (start, sign) = Self::draw(seed.unwrap_or(0), self.inner.spec().dt);
        self.start = start;
        self.force = sign * self.force.abs();
        self.t = 0;
        Ok(out)
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let pushing = self.t >= self.start && self.t < self.start + self.steps;
        // The base's translational dofs are world-frame: qfrc_applied[0] pushes along world x, [1]
        // along world y.
        self.inner.data_mut().qfrc_applied_mut()[self.dof] = if pushing { self.force } else { 0.0 };
        let out = self.inner.step(action);
        self.t += 1;
        out
    }

    fn data(&self) -> &Data {
        self.inner.data()
    }

    fn data_mut(&mut self) -> &mut Data {
        self.inner.data_mut()
    }

    fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), EnvError> {
        self.inner.set_state(qpos, qvel)
    }

    fn command(&self) -> Option<[f64; 2]> {
        self.inner.command()
    }

    fn set_command(&mut self, speed: f64, yaw_rate: f64) -> Result<(), EnvError> {
        self.inner.set_command(speed, yaw_rate)
    }

    fn forward_angle(&self) -> f64 {
        self.inner.forward_angle()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::envs::{make, EnvConfig};
    use crate::policy::ZeroPolicy;
    use crate::rollout::run_episode;

    #[test]
    fn a_push_moves_the_base_sideways_by_about_its_velocity_change() {
        // Ant settled under zero torques: just before the push it does not move sideways; the
        // push gives it a lateral velocity of the order of delta_v (less, as feet drag).
        let mut env = make(&EnvConfig::new("ant")).unwrap();
        let mut pushed = Pushed::new(env.as_mut(), Push::lateral(1.0)).unwrap();
        assert_eq!(pushed.steps, 2, "Ant acts every 0.05 s: two steps of force");
        let (start, _) = Pushed::draw(3, 0.05);
        assert!((40..=120).contains(&start));
        let mut peak = 0.0f64;
        let mut before = 0.0f64;
        let mut observer = |v: &crate::rollout::StepView| {
            let vy = v.env.data().qvel()[1].abs();
            if v.t + 10 >= start && v.t + 1 < start {
                before = before.max(vy);
            } else {
                peak = peak.max(vy);
            }
            Ok(())
        };
        let s = run_episode(&mut pushed, &mut ZeroPolicy, 0, Some(3), &mut observer).unwrap();
        assert!(s.length > start);
        assert!(before < 0.05, "no sideways motion before the push: {before}");
        assert!(peak > 0.3 && peak < 1.5, "lateral speed after the push: {peak}");
    }

    #[test]
    fn no_push_changes_nothing_and_bad_sizes_are_refused() {
        let mut env = make(&EnvConfig::new("ant")).unwrap();
        let plain =
            run_episode(env.as_mut(), &mut ZeroPolicy, 0, Some(2), &mut |_: &crate::rollout::StepView| Ok(())).unwrap();
        let mut pushed = Pushed::new(env.as_mut(), Push::lateral(0.0)).unwrap();
        let zero =
            run_episode(&mut pushed, &mut ZeroPolicy, 0, Some(2), &mut |_: &crate::rollout::StepView| Ok(())).unwrap();
        assert_eq!(plain, zero);
        assert!(Pushed::new(env.as_mut(), Push::lateral(f64::NAN)).is_err());
        let mut cheetah = make(&EnvConfig::new("half-cheetah")).unwrap();
        let e = Pushed::new(cheetah.as_mut(), Push::lateral(1.0)).err().unwrap().to_string();
        assert!(e.contains("no floating base"), "{e}");
    }
}
