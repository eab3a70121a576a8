//! The Minitaur motor model of PyBullet's `pybullet_envs/bullet/motor.py` (bulletphysics/bullet3): a PD loop produces a PWM
//! duty cycle; the battery voltage, back-EMF and winding resistance give a current; a measured
//! current-torque curve gives the torque.

/// Electrical and control parameters of one motor.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MotorParams {
    /// PWM per radian of angle error.
    pub kp: f64,
    /// PWM per rad/s of velocity.
    pub(crate) kd: f64,
    pub(crate) voltage: f64,
    pub(crate) resistance: f64,
    pub(crate) torque_constant: f64,
    pub(crate) viscous_damping: f64,
    /// Share of the current-torque curve the motor delivers (a weakened motor).
    pub(crate) strength: f64,
}

impl Default for MotorParams {
    fn default() -> Self {
        MotorParams {
            kp: 1.0,
            kd: 0.02,
            voltage: 16.0,
            resistance: 0.186,
            torque_constant: 0.0954,
            viscous_damping: 0.0,
            strength: 1.0,
        }
    }
}

pub(crate) const VOLTAGE_CLIP: f64 = 50.0;
pub(crate) const OBSERVED_TORQUE_LIMIT: f64 = 5.7;
/// Motor current (A) to output torque (N m), measured on the real motor.
const CURRENT_TABLE: [f64; 7] = [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0];
const TORQUE_TABLE: [f64; 7] = [0.0, 1.0, 1.9, 2.45, 3.0, 3.25, 3.5];
/// The largest torque the curve allows.
pub(crate) const MAX_TORQUE: f64 = 3.5;
/// A motor above this torque for `OVERHEAT_SECONDS` is switched off.
pub(crate) const OVERHEAT_TORQUE: f64 = 2.45;
pub(crate) const OVERHEAT_SECONDS: f64 = 1.0;

impl MotorParams {
    /// Fastest the motor can turn (rad/s): where back-EMF cancels the full battery voltage.
    pub(crate) fn speed_limit(&self) -> f64 {
        self.voltage / (self.torque_constant + self.viscous_damping)
    }

    /// Duty cycle that tracks a desired angle.
    pub(crate) fn pwm_for_angle(&self, desired: f64, angle: f64, velocity: f64) -> f64 {
        (self.kp * (desired - angle) - self.kd * velocity).clamp(-1.0, 1.0)
    }

    /// Duty cycle that would give `torque` at standstill (the torque-command mode).
    pub(crate) fn pwm_for_torque(&self, torque: f64) -> f64 {
        (torque * self.resistance / (self.torque_constant * self.voltage)).clamp(-1.0, 1.0)
    }

    /// (torque applied to the joint, torque the robot reports) for a duty cycle and velocity.
    pub fn torque(&self, pwm: f64, velocity: f64) -> (f64, f64) {
        let observed = (self.torque_constant * pwm * self.voltage / self.resistance)
            .clamp(-OBSERVED_TORQUE_LIMIT, OBSERVED_TORQUE_LIMIT);
        let net_voltage = (pwm * self.voltage - (self.torque_constant + self.viscous_damping) * velocity)
            .clamp(-VOLTAGE_CLIP, VOLTAGE_CLIP);
        let current = net_voltage / self.resistance;
        let applied = current.signum() * interpolate(current.abs(), &CURRENT_TABLE, &TORQUE_TABLE);
        let applied = if self.strength == 1.0 { applied } else { self.strength * applied };
        (if current == 0.0 { 0.0 } else { applied }, observed)
    }
}

/// Piecewise-linear interpolation, clamped at both ends (numpy's `interp`).
fn interpolate(x: f64, xs: &[f64], ys: &[f64]) -> f64 {
    if x <= xs[0] {
        return ys[0];
    }
    for i in 1..xs.len() {
        if x <= xs[i] {
            let t = (x - xs[i - 1]) / (xs[i] - xs[i - 1]);
            return ys[i - 1] + t * (ys[i] - ys[i - 1]);
        }
    }
    ys[ys.len() - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn torque_curve_and_limits() {
        let p = MotorParams::default();
        // Full PWM at standstill: 16 V / 0.186 ohm = 86 A, past the table's end: 3.5 N m.
        let (applied, observed) = p.torque(1.0, 0.0);
        assert!((applied - MAX_TORQUE).abs() < 1e-12);
        assert!((observed - OBSERVED_TORQUE_LIMIT).abs() < 1e-12);
        // 15 A sits halfway between 1.0 and 1.9 N m.
        let pwm = 15.0 * p.resistance / p.voltage;
        let (applied, _) = p.torque(pwm, 0.0);
        assert!((applied - 1.45).abs() < 1e-9, "{applied}");
        // Symmetric in sign.
        assert_eq!(p.torque(-pwm, 0.0).0, -applied);
        // Back-EMF: at the speed limit a full PWM gives no current.
        let (applied, _) = p.torque(1.0, p.speed_limit());
        assert!(applied.abs() < 1e-9);
        // A weakened motor gives its share of the curve; a lower battery less current.
        let full = p.torque(pwm, 0.0).0;
        let weak = MotorParams { strength: 0.4, ..p };
        assert_eq!(weak.torque(pwm, 0.0).0, 0.4 * full);
        let low = MotorParams { voltage: 8.0, ..p };
        assert!(low.torque(pwm, 0.0).0 < full);
        // PD saturates at +-1.
        assert_eq!(p.pwm_for_angle(10.0, 0.0, 0.0), 1.0);
        assert!((p.pwm_for_angle(0.1, 0.0, 1.0) - (0.1 - 0.02)).abs() < 1e-12);
    }
}
