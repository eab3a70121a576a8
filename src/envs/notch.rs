//! `walker2d-notch`: Walker2d driven by joint targets that move a notch at a time, S003's action
//! scheme for a walking biped learned by a DQN. Each step, each joint's target angle moves down
//! by `notch`, holds, or moves up by `notch` (the action's sign, with a dead band of a third of its
//! range, so a branching DQN with three levels acts exactly -1, 0, +1); a PD loop then drives the
//! joint towards its target: torque = kp (target - angle) - kd (joint velocity), in the motor's
//! control units, clipped to its range and held over the step's physics substeps. The targets start
//! at the joints' angles after reset (within their ranges), stay inside the joints' ranges, and extend the observation.
//!
//! Everything else is Walker2d-v5's: its observation first, its reward (the control cost on the
//! torques the PD loop applies), its falls and its time limit. Only an agent with discrete levels
//! (the branching DQN) can use this mode; training another algorithm on it is refused.
use serde::{Deserialize, Serialize};

use super::options::{join_wrapped, split_wrapped};
use super::registry::Registered;
use super::simulation::base_state_accessors;
use super::{BoxSpace, Env, EnvError, EnvSpec, Info, Step, Walker2d, Walker2dOptions};

/// The registered name.
pub const NAME: &str = "walker2d-notch";

/// The first joint a planar walker's motors drive: qpos[0..3] is the root (x, z, pitch).
const FIRST_JOINT: usize = 3;

/// The notch actions and their PD loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NotchSettings {
    /// How far one step moves a joint's target (rad).
    pub notch: f64,
    /// The PD loop's stiffness, control units per rad (Walker2d's motors have gear 100: 1 is
    /// 100 N m).
    pub target_kp: f64,
    /// The PD loop's damping, control units per rad/s.
    pub target_kd: f64,
}

impl Default for NotchSettings {
    /// A notch of 0.05 rad per 8 ms step (up to 6.25 rad/s of target motion), and a loop that
    /// holds the reset pose for a whole episode when every target holds (ours; S003's gains are
    /// not published: with target_kd = 0.2 the held-stepped loop shakes the walker over within a
    /// second).
    fn default() -> Self {
        NotchSettings { notch: 0.05, target_kp: 5.0, target_kd: 0.05 }
    }
}

impl NotchSettings {
    fn validate(&self) -> Result<(), EnvError> {
        let fail = |message: String| EnvError::InvalidOption { env: NAME.into(), message };
        if !(self.notch.is_finite() && self.notch > 0.0) {
            return Err(fail(format!("notch must be a finite angle above 0 rad, got {}", self.notch)));
        }
        for (name, v) in [("target_kp", self.target_kp), ("target_kd", self.target_kd)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(fail(format!("{name} must be a finite number >= 0, got {v}")));
            }
        }
        Ok(())
    }
}

/// Walker2d's options and the notch settings, in one flat table.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NotchOptions {
    /// Walker2d's options.
    pub base: Walker2dOptions,
    /// The notch actions.
    pub notch: NotchSettings,
}

impl Serialize for NotchOptions {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        join_wrapped(&self.base, &self.notch).map_err(serde::ser::Error::custom)?.serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for NotchOptions {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let table = toml::Table::deserialize(deserializer)?;
        let (base, notch) = split_wrapped(table, &NotchSettings::default()).map_err(serde::de::Error::custom)?;
        Ok(NotchOptions { base, notch })
    }
}

/// Walker2d with notch actions.
pub struct NotchWalker {
    base: Walker2d,
    settings: NotchSettings,
    spec: EnvSpec,
    targets: Vec<f64>,
    limits: Vec<[f64; 2]>,
    last_obs: Vec<f64>,
}

impl NotchWalker {
    /// Walker2d from `options.base`, driven by notches.
    pub fn new(options: NotchOptions) -> Result<Self, EnvError> {
        options.notch.validate()?;
        let base = Walker2d::new(options.base)?;
        let model = base.data().model();
        let joints = base.spec().action_space.dim();
        let range = model.jnt_range();
        // Walker2d's joints: the root's three, then one per motor, in motor order.
        let limits = (0..joints).map(|j| [range[2 * (FIRST_JOINT + j)], range[2 * (FIRST_JOINT + j) + 1]]).collect();
        let b = base.spec();
        let spec = EnvSpec {
            name: NAME,
            observation_space: BoxSpace::unbounded(b.observation_space.dim() + joints),
            action_space: BoxSpace::uniform(joints, -1.0, 1.0),
            dt: b.dt,
            max_episode_steps: b.max_episode_steps,
            reward_terms: b.reward_terms.clone(),
        };
        Ok(NotchWalker {
            base,
            settings: options.notch,
            spec,
            targets: vec![0.0; joints],
            limits,
            last_obs: Vec::new(),
        })
    }

    /// The joints' target angles now (rad).
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    fn observe(&self, base_obs: Vec<f64>) -> Vec<f64> {
        let mut obs = base_obs;
        obs.extend(&self.targets);
        obs
    }
}

/// A notch action's direction: -1, 0 or +1 (a dead band of a third on each side of 0).
pub fn direction(a: f64) -> f64 {
    if a > 1.0 / 3.0 {
        1.0
    } else if a < -1.0 / 3.0 {
        -1.0
    } else {
        0.0
    }
}

impl Registered for NotchWalker {
    type Options = NotchOptions;
    fn build(options: NotchOptions) -> Result<Self, EnvError> {
        NotchWalker::new(options)
    }
}

impl Env for NotchWalker {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        let (obs, info) = self.base.reset(seed)?;
        let q = self.base.data().qpos();
        // Reset noise may put a joint a hair outside its range; its target starts at the limit.
        self.targets =
            (0..self.targets.len()).map(|j| q[FIRST_JOINT + j].clamp(self.limits[j][0], self.limits[j][1])).collect();
        self.last_obs = self.observe(obs);
        Ok((self.last_obs.clone(), info))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        super::check_action(&self.spec.action_space, action)?;
        let s = &self.settings;
        let (q, v) = (self.base.data().qpos(), self.base.data().qvel());
        let mut torque = Vec::with_capacity(action.len());
        for (j, a) in action.iter().enumerate() {
            let [low, high] = self.limits[j];
            self.targets[j] = (self.targets[j] + s.notch * direction(*a)).clamp(low, high);
            let u = s.target_kp * (self.targets[j] - q[FIRST_JOINT + j]) - s.target_kd * v[FIRST_JOINT + j];
            torque.push(u.clamp(-1.0, 1.0));
        }
        let step = self.base.step(&torque)?;
        if step.info.unstable {
            return Ok(Step { observation: self.last_obs.clone(), ..step });
        }
        self.last_obs = self.observe(step.observation.clone());
        Ok(Step { observation: self.last_obs.clone(), ..step })
    }

    base_state_accessors!();
}
