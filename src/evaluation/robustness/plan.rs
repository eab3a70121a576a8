//! Who plays the suite: the trained policies asked for, and the controller at its best speed
//! and at each policy's own speed (found on the controller's speed grid, as the report's
//! matched comparisons are). A policy faster than the controller can walk meets the
//! controller's fastest working speed instead, and the plan says so.
use anyhow::{bail, Result};

use super::suite::{Cell, Contender, Suite};
use crate::evaluation::speed_grid::{best_point, command_for, working_points, GRID_MAX, GRID_STEP};
use crate::evaluation::ControllerFamily;

/// Which controllers to add.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControllerChoice {
    /// The grid speed with the best mean return.
    Best,
    /// The speed of each policy (its nominal cell's mean speed).
    Matched,
    /// A commanded speed (m/s).
    Speed(f64),
}

impl std::str::FromStr for ControllerChoice {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "best" => Ok(ControllerChoice::Best),
            "matched" => Ok(ControllerChoice::Matched),
            other => match other.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 && v <= GRID_MAX => Ok(ControllerChoice::Speed(v)),
                _ => bail!("--controller takes best, matched or a speed in (0, {GRID_MAX}] m/s, not '{other}'"),
            },
        }
    }
}

/// The contenders, the policies' nominal cells already played (so the suite does not play them
/// twice), and one line per choice made for the reader.
pub struct Plan {
    /// Policies first, then controllers (no two at the same commanded speed).
    pub contenders: Vec<Contender>,
    /// Cells played while planning.
    pub known: Vec<Cell>,
    /// How each controller speed was chosen.
    pub notes: Vec<String>,
}

fn controller(speed: f64, why: &str) -> Contender {
    Contender::Controller { label: format!("controller {speed:.3} m/s ({why})"), speed }
}

/// On a command task the controller reads the command from the observation, as every policy
/// does, so one controller contender stands for every choice: there is no speed to pick.
fn command_task_plan(agents: Vec<Contender>, choices: &[ControllerChoice]) -> Plan {
    let mut contenders = agents;
    let mut notes = Vec::new();
    if !choices.is_empty() {
        contenders.push(Contender::Controller { label: COMMAND_CONTROLLER.into(), speed: 0.0 });
        notes.push("a command task: the controller follows the task's command, as every policy does".into());
    }
    Plan { contenders, known: Vec::new(), notes }
}

/// The controller's label on a command task.
pub const COMMAND_CONTROLLER: &str = "controller (follows the command)";

/// Plans the suite for `agents` and the controller `choices`; a policy's nominal cell found in
/// `reuse` is not played again.
pub fn plan(suite: &Suite, agents: Vec<Contender>, choices: &[ControllerChoice], reuse: &[Cell]) -> Result<Plan> {
    if crate::envs::command::is_command_task(&suite.env.name) {
        return Ok(command_task_plan(agents, choices));
    }
    let mut notes = Vec::new();
    let mut known = Vec::new();
    let mut controllers: Vec<Contender> = Vec::new();
    let add = |c: Contender, controllers: &mut Vec<Contender>| {
        if !controllers.iter().any(|o| o.commanded() == c.commanded()) {
            controllers.push(c);
        }
    };
    let needs_grid = choices.iter().any(|c| matches!(c, ControllerChoice::Best | ControllerChoice::Matched));
    let grid = if needs_grid {
        let mut family = ControllerFamily::new(&suite.env, suite.protocol)?;
        family.threads = suite.threads;
        family.disk = suite.cache.clone();
        family.sweep(GRID_STEP, GRID_MAX)?
    } else {
        Vec::new()
    };
    for choice in choices {
        match *choice {
            ControllerChoice::Speed(v) => add(controller(v, "asked for"), &mut controllers),
            ControllerChoice::Best => {
                let Some(best) = best_point(&grid) else { bail!("the controller works at no speed of its grid") };
                notes.push(format!(
                    "controller's best speed: {:.3} m/s commanded, {:.3} achieved",
                    best.commanded,
                    best.achieved()
                ));
                add(controller(best.commanded, "best"), &mut controllers);
            }
            ControllerChoice::Matched => {
                let nominal: Vec<Cell> = crate::evaluation::parallel::map_in_order(&agents, suite.threads, |a| {
                    match reuse.iter().find(|c| c.policy == a.label() && c.axis == super::suite::NOMINAL) {
                        Some(c) => Ok(c.clone()),
                        None => suite.cell(a, None, 0.0),
                    }
                })?;
                for (agent, cell) in agents.iter().zip(nominal) {
                    match command_for(&grid, cell.speed) {
                        Ok(c) => {
                            let c = (c * 1000.0).round() / 1000.0;
                            notes.push(format!(
                                "{}: {:.3} m/s; the controller commanded {c:.3} matches it",
                                agent.label(),
                                cell.speed
                            ));
                            add(controller(c, &format!("at {}'s speed", agent.label())), &mut controllers);
                        }
                        Err(why) => {
                            let top = working_points(&grid).last().map(|p| p.commanded);
                            notes.push(format!(
                                "{}: {:.3} m/s, {why}; the controller's fastest working speed stands in",
                                agent.label(),
                                cell.speed
                            ));
                            if let Some(top) = top {
                                add(controller(top, "fastest"), &mut controllers);
                            }
                        }
                    }
                    known.push(cell);
                }
            }
        }
    }
    let mut contenders = agents;
    contenders.extend(controllers);
    Ok(Plan { contenders, known, notes })
}
