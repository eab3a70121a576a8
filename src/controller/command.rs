//! What a controller is asked to do over an episode: a forward-speed profile (m/s along the
//! body's heading, piecewise linear in time) and a yaw rate (rad/s, positive turning left).
use anyhow::{bail, ensure, Context, Result};

/// Forward speed as a function of time: linear between knots (time s, speed m/s), held before
/// the first knot and after the last.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedProfile {
    knots: Vec<(f64, f64)>,
}

impl SpeedProfile {
    /// From zero to `speed` in `ramp_time` seconds, then constant.
    pub fn ramp(speed: f64, ramp_time: f64) -> SpeedProfile {
        if ramp_time > 0.0 {
            SpeedProfile { knots: vec![(0.0, 0.0), (ramp_time, speed)] }
        } else {
            SpeedProfile { knots: vec![(0.0, speed)] }
        }
    }

    /// Knots from `t:v` pairs, e.g. `0:0,3:0.35,6:-0.35` (PyBullet's Raibert example: up to
    /// 0.35 m/s over 3 s, then reverse). Times must increase.
    pub fn parse(text: &str) -> Result<SpeedProfile> {
        let mut knots = Vec::new();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (t, v) = item.split_once(':').with_context(|| format!("speed profile: '{item}' is not time:speed"))?;
            let t: f64 = t.trim().parse().with_context(|| format!("speed profile: bad time in '{item}'"))?;
            let v: f64 = v.trim().parse().with_context(|| format!("speed profile: bad speed in '{item}'"))?;
            ensure!(t.is_finite() && t >= 0.0 && v.is_finite(), "speed profile: '{item}' must be finite, time >= 0");
            if let Some(&(last, _)) = knots.last() {
                ensure!(t > last, "speed profile: times must increase ({t} after {last})");
            }
            knots.push((t, v));
        }
        if knots.is_empty() {
            bail!("speed profile is empty; write it as time:speed pairs, e.g. 0:0,3:0.35,6:-0.35");
        }
        Ok(SpeedProfile { knots })
    }

    /// The commanded speed at time `t` (s): linear between knots, constant outside them.
    pub fn at(&self, t: f64) -> f64 {
        let k = &self.knots;
        if t <= k[0].0 {
            return k[0].1;
        }
        for w in k.windows(2) {
            let ((t0, v0), (t1, v1)) = (w[0], w[1]);
            if t <= t1 {
                return v0 + (v1 - v0) * (t - t0) / (t1 - t0);
            }
        }
        k[k.len() - 1].1
    }

    /// The largest |speed| the profile asks for (its extremes are at knots).
    pub(crate) fn peak_speed(&self) -> f64 {
        self.knots.iter().map(|&(_, v)| v.abs()).fold(0.0, f64::max)
    }

    /// The speed the profile settles at.
    pub fn final_speed(&self) -> f64 {
        self.knots[self.knots.len() - 1].1
    }
}

/// A speed profile plus a yaw-rate command.
#[derive(Debug, Clone, PartialEq)]
pub struct Command {
    /// Forward speed over time (m/s).
    pub speed: SpeedProfile,
    /// rad/s about the vertical, positive turning left (counter-clockwise seen from above).
    pub yaw_rate: f64,
}

impl Command {
    /// A controller's name for this command: `raibert-GAIT@Vm/s`, plus `,Wrad/s` when turning.
    pub(crate) fn controller_name(&self, gait: &str) -> String {
        let mut name = format!("raibert-{gait}@{}m/s", self.speed.final_speed());
        if self.yaw_rate != 0.0 {
            name += &format!(",{}rad/s", self.yaw_rate);
        }
        name
    }

    /// Straight ahead at `speed`, reached over `ramp_time` seconds.
    pub fn straight(speed: f64, ramp_time: f64) -> Command {
        Command { speed: SpeedProfile::ramp(speed, ramp_time), yaw_rate: 0.0 }
    }

    /// Checks that the yaw rate is finite.
    pub fn validate(&self) -> Result<()> {
        ensure!(self.yaw_rate.is_finite(), "yaw rate must be finite");
        Ok(())
    }
}

/// The integral of the forward-speed error after one more tick, bounded so that the integral
/// force (ki x integral) never exceeds half the damping gain's worth (0.5 kd): a stumble cannot
/// wind it up. Unchanged when ki is 0.
pub(crate) fn integrate_speed_error(integral: f64, error: f64, dt: f64, kd: f64, ki: f64) -> f64 {
    if ki <= 0.0 {
        return integral;
    }
    let bound = 0.5 / ki * kd;
    (integral + error * dt).clamp(-bound, bound)
}

/// An angle wrapped to (-pi, pi].
pub(crate) fn wrap_angle(a: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let w = a.rem_euclid(two_pi);
    if w > std::f64::consts::PI {
        w - two_pi
    } else {
        w
    }
}

/// A floating base seen in its heading frame (yaw removed): what both controllers set their
/// speeds, wrenches and footholds in, so the same laws hold whichever way the robot faces.
pub(crate) struct HeadingFrame {
    /// Yaw of the base (rad).
    pub yaw: f64,
    /// Rotation from the heading frame to the world.
    pub heading: nalgebra::Rotation3<f64>,
    /// The base's attitude with yaw removed (pitch and roll only).
    pub body: nalgebra::Matrix3<f64>,
    /// Linear and angular velocity in the heading frame.
    pub velocity: nalgebra::Vector3<f64>,
    pub(crate) angular_velocity: nalgebra::Vector3<f64>,
}

impl HeadingFrame {
    /// From the base's rotation matrix and its world-frame velocities.
    pub fn new(
        rotation: &nalgebra::Matrix3<f64>,
        velocity: nalgebra::Vector3<f64>,
        angular_velocity: nalgebra::Vector3<f64>,
    ) -> HeadingFrame {
        let yaw = rotation[(1, 0)].atan2(rotation[(0, 0)]);
        let heading = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), yaw);
        let to_heading = heading.inverse();
        HeadingFrame {
            yaw,
            heading,
            body: to_heading * rotation,
            velocity: to_heading * velocity,
            angular_velocity: to_heading * angular_velocity,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_interpolates_and_holds() {
        let p = SpeedProfile::parse("0:0, 3:0.35, 6:-0.35").unwrap();
        assert_eq!(p.at(0.0), 0.0);
        assert!((p.at(1.5) - 0.175).abs() < 1e-12);
        assert!((p.at(4.5) - 0.0).abs() < 1e-12);
        assert_eq!(p.at(10.0), -0.35);
        let r = SpeedProfile::ramp(1.0, 2.0);
        assert_eq!((r.at(1.0), r.at(5.0)), (0.5, 1.0));
        assert_eq!(SpeedProfile::ramp(0.4, 0.0).at(0.0), 0.4);
        assert_eq!(p.peak_speed(), 0.35);
        assert_eq!(SpeedProfile::parse("0:0.2,2:-0.9,4:0.5").unwrap().peak_speed(), 0.9);
    }

    #[test]
    fn bad_profiles_are_errors() {
        for bad in ["", "1", "0:0,0:1", "2:0,1:1", "0:x", "0:nan", "-1:0"] {
            assert!(SpeedProfile::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn wrapping() {
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(0.3) - 0.3).abs() < 1e-12);
    }
}
