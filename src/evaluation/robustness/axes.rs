//! The robustness suite's axes: what each perturbs, its unit, and its levels from nominal to
//! where the policies we measured mostly fail. An axis is applied the same way to every policy: a
//! push scenario, or env options set on the env every policy (and the controller) runs in.
use anyhow::{bail, Result};

use crate::envs::EnvConfig;
use crate::evaluation::Push;

/// How an axis's level reaches the episode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Apply {
    /// A push of `level` m/s, sideways or along the heading.
    Push(crate::evaluation::PushDirection),
    /// Env options set to `level` times each factor (one option, or a group such as sensor noise).
    Options(&'static [(&'static str, f64)]),
}

/// One axis of the suite.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Axis {
    /// Its name (`--axes`, the CSV's `axis` column).
    pub name: &'static str,
    /// What a reader sees on the chart's x axis.
    pub label: &'static str,
    /// The level's unit.
    pub unit: &'static str,
    /// The unperturbed level.
    pub nominal: f64,
    /// Levels beyond nominal, from mild to severe.
    pub levels: &'static [f64],
    /// How a level is applied.
    pub apply: Apply,
}

use crate::evaluation::PushDirection::{Frontal, Lateral};

const fn axis(
    name: &'static str,
    label: &'static str,
    unit: &'static str,
    nominal: f64,
    levels: &'static [f64],
    apply: Apply,
) -> Axis {
    Axis { name, label, unit, nominal, levels, apply }
}

/// Sensor noise at level 1: the standard deviations on motor angles (rad), motor velocities
/// (rad/s) and orientation (rad about each axis).
const NOISE: &[(&str, f64)] = &[("noise_angle", 0.05), ("noise_velocity", 1.0), ("noise_orientation", 0.05)];

/// The axes both robots have, each with the robot's own levels (and, for the body, its name).
const fn push_lateral(levels: &'static [f64]) -> Axis {
    axis("push_lateral", "sideways push", "m/s", 0.0, levels, Apply::Push(Lateral))
}
const fn push_frontal(levels: &'static [f64]) -> Axis {
    axis("push_frontal", "push along the heading", "m/s", 0.0, levels, Apply::Push(Frontal))
}
const fn friction_low(levels: &'static [f64]) -> Axis {
    axis("friction_low", "ground friction (scale, low)", "x", 1.0, levels, Apply::Options(&[("friction_scale", 1.0)]))
}
const fn payload(label: &'static str, levels: &'static [f64]) -> Axis {
    axis("payload", label, "kg", 0.0, levels, Apply::Options(&[("payload_mass", 1.0)]))
}
const fn com_shift(label: &'static str, levels: &'static [f64]) -> Axis {
    axis("com_shift", label, "m", 0.0, levels, Apply::Options(&[("com_shift", 1.0)]))
}
const fn motor_strength(levels: &'static [f64]) -> Axis {
    axis(
        "motor_strength",
        "motor strength (share of torque)",
        "x",
        1.0,
        levels,
        Apply::Options(&[("motor_strength", 1.0)]),
    )
}
const fn latency(levels: &'static [f64]) -> Axis {
    axis("latency", "control latency", "s", 0.0, levels, Apply::Options(&[("latency", 1.0)]))
}
const fn slope_up(levels: &'static [f64]) -> Axis {
    axis("slope_up", "slope up", "deg", 0.0, levels, Apply::Options(&[("slope", 1.0)]))
}
const fn slope_down(levels: &'static [f64]) -> Axis {
    axis("slope_down", "slope down", "deg", 0.0, levels, Apply::Options(&[("slope", -1.0)]))
}

/// Minitaur's axes, levels from mild to where the policies measured mostly fail (a contender that
/// survives an axis's last level is marked so in the suite's tables).
pub const MINITAUR_AXES: &[Axis] = &[
    push_lateral(&[0.25, 0.5, 1.0, 1.5]),
    push_frontal(&[0.5, 1.5, 2.5, 4.0, 6.0, 8.0]),
    friction_low(&[0.3, 0.1, 0.03, 0.01, 0.003, 0.001]),
    axis(
        "friction_high",
        "ground friction (scale, high)",
        "x",
        1.0,
        &[1.5, 2.0, 4.0, 8.0],
        Apply::Options(&[("friction_scale", 1.0)]),
    ),
    payload("payload on the base", &[1.0, 2.0, 4.0, 6.0]),
    com_shift("base centre of mass moved forward", &[0.03, 0.06, 0.12, 0.2]),
    motor_strength(&[0.8, 0.6, 0.45, 0.3]),
    axis("battery", "battery voltage", "V", 16.0, &[12.0, 9.0, 6.0, 3.0], Apply::Options(&[("battery_voltage", 1.0)])),
    latency(&[0.002, 0.004, 0.01, 0.02, 0.04]),
    axis(
        "sensor_noise",
        "sensor noise (x 0.05 rad, 1 rad/s, 0.05 rad)",
        "x",
        0.0,
        &[0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0],
        Apply::Options(NOISE),
    ),
    axis(
        "terrain",
        "rough terrain: step height",
        "m",
        0.0,
        &[0.005, 0.01, 0.02, 0.04, 0.07],
        Apply::Options(&[("terrain_step_height", 1.0)]),
    ),
    slope_up(&[5.0, 10.0, 15.0, 22.0, 30.0]),
    slope_down(&[2.5, 5.0, 10.0, 15.0, 22.0, 30.0]),
];

/// Ant's axes: the pushes, up to 16 m/s (the controller survived more than 90% of the pushes
/// at 8 m/s), and the world options of `envs::world` (friction, payload, centre of mass, motor
/// strength, latency, slopes). Minitaur's battery, sensor noise and terrain have no counterpart
/// in Gymnasium's Ant: it has no motor model, and its controller reads the simulator's state, so
/// sensor noise would reach only the policies.
pub const ANT_AXES: &[Axis] = &[
    push_lateral(&[0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 16.0]),
    push_frontal(&[0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 12.0, 16.0]),
    friction_low(&[0.3, 0.1, 0.03, 0.01]),
    payload("payload on the torso", &[2.0, 4.0, 8.0, 16.0, 32.0, 60.0]),
    com_shift("torso centre of mass moved forward", &[0.05, 0.1, 0.2, 0.3]),
    motor_strength(&[0.8, 0.6, 0.4, 0.2]),
    latency(&[0.01, 0.02, 0.05, 0.1]),
    slope_up(&[5.0, 10.0, 20.0, 30.0]),
    slope_down(&[5.0, 10.0, 20.0, 30.0]),
];

/// The axes of `env`'s suite; an error for an env without one.
pub fn axes_of(env: &str) -> Result<&'static [Axis]> {
    match env {
        "minitaur" | "minitaur-command" => Ok(MINITAUR_AXES),
        "ant" | "ant-command" => Ok(ANT_AXES),
        other => bail!("the robustness suite covers minitaur and ant, not '{other}'"),
    }
}

/// The axes named (all of them for `all`); an unknown name is an error listing the known ones.
pub fn select(env: &str, names: &[String]) -> Result<Vec<Axis>> {
    let all = axes_of(env)?;
    if names.is_empty() || names.iter().any(|n| n == "all") {
        return Ok(all.to_vec());
    }
    names
        .iter()
        .map(|n| {
            all.iter().find(|a| a.name == n).copied().ok_or_else(|| {
                anyhow::anyhow!(
                    "unknown robustness axis '{n}' for {env} (its axes: {})",
                    all.iter().map(|a| a.name).collect::<Vec<_>>().join(", ")
                )
            })
        })
        .collect()
}

impl Axis {
    /// The env and push of one level: `base` with the axis's options set, or a push. The level
    /// must be finite; whether the env can represent it is checked when the env is built, and
    /// the error names the option.
    pub fn at(&self, base: &EnvConfig, level: f64) -> Result<(EnvConfig, Option<Push>)> {
        if !level.is_finite() {
            bail!("level {level} of axis {} is not a finite number", self.name);
        }
        if level == self.nominal {
            return Ok((base.clone(), None));
        }
        match self.apply {
            Apply::Push(direction) => {
                if level < 0.0 {
                    bail!("axis {}: a push of {level} m/s is negative", self.name);
                }
                Ok((base.clone(), Some(Push { delta_v: level, direction })))
            }
            Apply::Options(options) => {
                let mut cfg = base.clone();
                for (key, factor) in options {
                    cfg.options.insert(key.to_string(), toml::Value::Float(level * factor));
                }
                crate::envs::make(&cfg).map_err(|e| anyhow::anyhow!("axis {} at level {level}: {e}", self.name))?;
                Ok((cfg, None))
            }
        }
    }

    /// Every level, nominal first.
    pub fn all_levels(&self) -> Vec<f64> {
        std::iter::once(self.nominal).chain(self.levels.iter().copied()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_level_builds_and_levels_grow_in_severity() {
        for (env, axes) in [("minitaur", MINITAUR_AXES), ("ant", ANT_AXES)] {
            check_levels(&EnvConfig::new(env), axes);
        }
    }

    fn check_levels(base: &EnvConfig, axes: &[Axis]) {
        for axis in axes {
            let levels = axis.all_levels();
            let distance: Vec<f64> = levels.iter().map(|l| (l - axis.nominal).abs()).collect();
            assert!(distance.windows(2).all(|w| w[0] < w[1]), "{}: {levels:?}", axis.name);
            for level in levels {
                axis.at(base, level).unwrap();
            }
        }
    }

    #[test]
    fn bad_axes_and_levels_are_named() {
        let e = select("minitaur", &["wind".into()]).unwrap_err().to_string();
        assert!(e.contains("'wind'") && e.contains("push_lateral"), "{e}");
        assert!(select("hopper", &[]).unwrap_err().to_string().contains("hopper"));
        let base = EnvConfig::new("minitaur");
        let payload = select("minitaur", &["payload".into()]).unwrap()[0];
        let e = payload.at(&base, -1.0).unwrap_err().to_string();
        assert!(e.contains("payload_mass"), "{e}");
        let friction = select("minitaur", &["friction_low".into()]).unwrap()[0];
        assert!(friction.at(&base, -0.1).unwrap_err().to_string().contains("friction_scale"));
        let terrain = select("minitaur", &["terrain".into()]).unwrap()[0];
        assert!(terrain.at(&base, 0.5).unwrap_err().to_string().contains("terrain_step_height"));
        assert!(payload.at(&base, f64::NAN).is_err());
        let push = select("minitaur", &["push_lateral".into()]).unwrap()[0];
        assert!(push.at(&base, -1.0).is_err());
        assert_eq!(select("ant", &["all".into()]).unwrap().len(), ANT_AXES.len());
        let ant = EnvConfig::new("ant");
        let motors = select("ant", &["motor_strength".into()]).unwrap()[0];
        assert!(motors.at(&ant, -0.5).unwrap_err().to_string().contains("motor_strength"));
    }
}
