//! What the world does to a Gymnasium MuJoCo task beyond its own reset noise (Ant's options):
//! ground friction, a payload and a shifted centre of mass on the torso, weaker motors, control
//! latency and slopes. The robustness suite's axes set them, and training can too. All are off by
//! default, and off they leave the model and the step exactly as Gymnasium's.
//!
//! The model edits and the delay line are the ones Minitaur's own perturbations use
//! (`minitaur::perturb`), so an axis means the same physics on both robots.
use std::collections::VecDeque;

use serde::Deserialize;

use super::options::Check;
use super::EnvError;
use crate::mujoco::Model;

/// The world options of a task that takes them, read from its options by name.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct World {
    /// Every geom's sliding friction times this.
    pub friction_scale: f64,
    /// Mass added to the torso (kg), its inertia scaled with it.
    pub payload_mass: f64,
    /// The torso's centre of mass moved forward along its x axis (m).
    pub com_shift: f64,
    /// Every actuator's gear times this (the share of torque the motors still give).
    pub motor_strength: f64,
    /// Delay from an action to the actuators acting on it (s), in whole physics steps.
    pub latency: f64,
    /// Ground slope along +x (degrees, up positive), as gravity tilted under flat ground.
    pub slope: f64,
}

/// The world options' names: what the held-out protocol returns to nominal.
pub const OPTIONS: [&str; 6] = ["friction_scale", "payload_mass", "com_shift", "motor_strength", "latency", "slope"];

impl Default for World {
    fn default() -> World {
        World { friction_scale: 1.0, payload_mass: 0.0, com_shift: 0.0, motor_strength: 1.0, latency: 0.0, slope: 0.0 }
    }
}

impl World {
    /// Checks each option against what the model can represent; the error names the option.
    pub(crate) fn validate(&self, env: &str) -> Result<(), EnvError> {
        let c = Check { env };
        c.within("friction_scale", self.friction_scale, 0.0, 10.0)?;
        c.within("payload_mass", self.payload_mass, 0.0, 60.0)?;
        c.within("com_shift", self.com_shift, -0.3, 0.3)?;
        c.within("motor_strength", self.motor_strength, 0.0, 2.0)?;
        c.within("latency", self.latency, 0.0, 0.5)?;
        c.within("slope", self.slope, -30.0, 30.0)
    }

    /// Applies the options to a freshly compiled model; `body` carries the payload.
    pub(crate) fn edit_model(&self, model: &mut Model, body: usize) {
        edit_body_and_ground(model, body, self.friction_scale, self.payload_mass, self.com_shift, self.slope);
        if self.motor_strength != 1.0 {
            // gear is nu x 6; a motor's torque is gear[0] * ctrl.
            for g in model.actuator_gear_mut().chunks_exact_mut(6) {
                g[0] *= self.motor_strength;
            }
        }
    }

    /// The latency in whole physics steps of `sim_dt`.
    pub(crate) fn latency_steps(&self, sim_dt: f64) -> usize {
        delay_steps(self.latency, sim_dt)
    }
}

/// A delay of `seconds` rounded to whole physics steps of `sim_dt`.
pub(crate) fn delay_steps(seconds: f64, sim_dt: f64) -> usize {
    (seconds / sim_dt).round() as usize
}

/// The edits both robots take: sliding friction of every geom times `friction_scale`, `payload`
/// kg on `body` (its inertia grown in proportion, as if spread like the body itself), its centre
/// of mass moved `com_shift` m along its x axis, and a uniform slope of `slope` degrees up along
/// +x, which is flat ground under gravity tilted back by that angle. Nominal values leave the
/// model untouched.
pub(crate) fn edit_body_and_ground(
    model: &mut Model,
    body: usize,
    friction_scale: f64,
    payload: f64,
    com_shift: f64,
    slope: f64,
) {
    if friction_scale != 1.0 {
        for f in model.geom_friction_mut().chunks_exact_mut(3) {
            f[0] *= friction_scale;
        }
    }
    if payload != 0.0 {
        let mass = model.body_mass()[body];
        let ratio = (mass + payload) / mass;
        model.body_mass_mut()[body] += payload;
        for i in &mut model.body_inertia_mut()[3 * body..3 * body + 3] {
            *i *= ratio;
        }
    }
    if com_shift != 0.0 {
        model.shift_body_com(body, [com_shift, 0.0, 0.0]);
    }
    if slope != 0.0 {
        let (g, theta) = (-model.gravity()[2], slope.to_radians());
        model.set_gravity([-g * theta.sin(), 0.0, -g * theta.cos()]);
    }
}

/// The commands sent at each control step, so that a physics step `d` steps later applies the
/// one that had reached the actuators by then.
#[derive(Debug, Clone)]
pub(crate) struct Delay<C> {
    delay: usize,
    repeat: usize,
    first: usize,
    sent: VecDeque<C>,
}

impl<C> Delay<C> {
    /// A delay of `delay` physics steps, with `repeat` physics steps per control step.
    pub fn new(delay: usize, repeat: usize) -> Delay<C> {
        Delay { delay, repeat, first: 0, sent: VecDeque::new() }
    }

    /// Records the command of control step `step` (0, 1, 2, ... in order).
    pub fn send(&mut self, step: usize, command: C) {
        self.sent.push_back(command);
        // Keep the commands a physics step of this control step or later can still need.
        let oldest_needed = (step * self.repeat).saturating_sub(self.delay) / self.repeat;
        while self.first < oldest_needed {
            self.sent.pop_front();
            self.first += 1;
        }
    }

    /// The command acting at physics step `t` of the episode (counted from its first action);
    /// None before the first command has arrived.
    pub fn acting(&self, t: usize) -> Option<&C> {
        let t = t.checked_sub(self.delay)?;
        self.sent.get((t / self.repeat).checked_sub(self.first)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_delay_applies_each_command_the_given_physics_steps_late() {
        // 5 physics steps per control step, 7 steps of delay: control step c's command acts
        // from physics step 5c + 7 on.
        let mut d = Delay::new(7, 5);
        let mut acting = Vec::new();
        for step in 0..4 {
            d.send(step, step);
            for j in 0..5 {
                acting.push(d.acting(step * 5 + j).copied());
            }
        }
        let expect: Vec<Option<usize>> = (0..20).map(|t: usize| t.checked_sub(7).map(|u| u / 5)).collect();
        assert_eq!(acting, expect);
        let mut none = Delay::new(0, 5);
        none.send(0, 'a');
        assert_eq!(none.acting(0), Some(&'a'));
    }

    #[test]
    fn nominal_world_leaves_the_model_as_compiled() {
        let xml = super::super::ant::MODEL_XML;
        let mut edited = Model::from_xml_str(xml).unwrap();
        World::default().edit_model(&mut edited, 1);
        let plain = Model::from_xml_str(xml).unwrap();
        assert_eq!(edited.body_mass(), plain.body_mass());
        assert_eq!(edited.gravity(), plain.gravity());
        assert_eq!(edited.actuator_gear(), plain.actuator_gear());
    }
}
