//! The baseline controllers behind one entry point: build the env they need and the matching
//! controller for a speed set-point.
use anyhow::{bail, Result};

use super::ant::{AntController, AntGaitParams};
use super::ant_row::{AntRowController, AntRowParams};
use super::command::Command;
use super::gait::GaitKind;
use super::minitaur::{MinitaurController, MinitaurGaitParams};
use crate::envs::EnvConfig;
use crate::policy::Policy;

/// The env config the baseline runs in (Minitaur switches to its torque action mode).
pub fn baseline_env(env: &str) -> Result<EnvConfig> {
    Ok(match env {
        "minitaur" | "minitaur-command" => {
            EnvConfig::new(env).with_overrides(&[("action_mode".into(), "\"torque\"".into())])?
        }
        "ant" | "ant-command" => EnvConfig::new(env),
        other => bail!("the Raibert baseline exists for minitaur and ant, not '{other}'"),
    })
}

/// The env a trained policy ran in, switched to what the baseline needs (Minitaur's torque
/// action mode), keeping its reward, episode length and randomisation.
pub fn baseline_env_like(cfg: &EnvConfig) -> Result<EnvConfig> {
    let mut out = cfg.clone();
    for (k, v) in baseline_env(&cfg.name)?.options {
        out.options.insert(k, v);
    }
    Ok(out)
}

/// Seconds over which a straight-line set-point is ramped up from standing.
pub const RAMP_TIME: f64 = 1.0;

/// A controller for `env` walking straight at `speed` (reached over `RAMP_TIME`); `gait`
/// overrides the default (Minitaur bounds, Ant rows).
pub fn baseline_controller(env: &str, speed: f64, gait: Option<GaitKind>) -> Result<Box<dyn Policy>> {
    anyhow::ensure!(speed.is_finite(), "speed must be a finite number");
    baseline_controller_for(env, Command::straight(speed, RAMP_TIME), gait)
}

/// A controller for `env` following a speed profile and a yaw-rate command.
pub fn baseline_controller_for(env: &str, command: Command, gait: Option<GaitKind>) -> Result<Box<dyn Policy>> {
    command.validate()?;
    Ok(match env {
        "minitaur" | "minitaur-command" => {
            let defaults = MinitaurGaitParams::default();
            Box::new(MinitaurController::new(MinitaurGaitParams {
                command,
                on_command_task: env == "minitaur-command",
                gait: gait.unwrap_or(defaults.gait),
                ..defaults
            })?)
        }
        "ant-command" if gait.unwrap_or(GaitKind::Row) == GaitKind::Row => {
            Box::new(AntRowController::new(AntRowParams { on_command_task: true, ..AntRowParams::default() })?)
        }
        "ant-command" => {
            let name = format!("raibert-{}@command", if gait == Some(GaitKind::Trot) { "trot" } else { "row" });
            Box::new(super::follow::CommandFollower::new(name, |c, g| baseline_controller_for("ant", c, g), gait))
        }
        "ant" => match gait.unwrap_or(GaitKind::Row) {
            GaitKind::Row => Box::new(AntRowController::new(AntRowParams::for_command(command))?),
            GaitKind::Trot => Box::new(AntController::new(AntGaitParams { command, ..Default::default() })?),
            other => bail!("the Ant controller rows (default) or trots, it does not {other:?}"),
        },
        other => bail!("the Raibert baseline exists for minitaur and ant, not '{other}'"),
    })
}

/// The gait named `trot`, `bound`, `pace` or `row`; the error lists them.
pub fn parse_gait(name: &str) -> Result<GaitKind> {
    match name {
        "trot" => Ok(GaitKind::Trot),
        "bound" => Ok(GaitKind::Bound),
        "pace" => Ok(GaitKind::Pace),
        "row" => Ok(GaitKind::Row),
        other => bail!("unknown gait '{other}': use trot, bound, pace or row (Ant)"),
    }
}
