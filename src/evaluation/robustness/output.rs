//! The suite's committed form: `robustness.csv` (one row per cell, each episode's outcome
//! included so survival can be paired across policies) and `robustness.toml` (how it was run:
//! command, machine, commit, protocol, wall time, and how the controller's speeds were chosen).
//! Both are written atomically.
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use super::axes::Axis;
use super::plan::{plan, ControllerChoice};
use super::suite::{to_csv, Cell, Contender, Suite};
use super::summary::{survives_where_controller_falls, threshold, walking_note};
use crate::io::write_atomic;

/// The cells' file.
pub const CSV_FILE: &str = "robustness.csv";
/// How they were made.
pub const META_FILE: &str = "robustness.toml";

/// `robustness.toml`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SuiteMeta {
    /// The command that wrote the files.
    pub command: String,
    /// CPU model and SIMD level of the machine.
    pub machine: String,
    /// The commit the binary was built from.
    pub git_commit: String,
    /// The env and its options.
    pub env: crate::envs::EnvConfig,
    /// Held-out episodes per cell and the protocol seed that picks them.
    pub episodes: usize,
    /// The protocol seed.
    pub protocol_seed: u64,
    /// Cells evaluated at once.
    pub threads: usize,
    /// Wall time of this run of the suite, planning included (s).
    pub wall_seconds: f64,
    /// With cells reused from earlier suites: the wall time of every run that played them, this
    /// one included (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub total_wall_seconds: Option<f64>,
    /// Every contender: label and what it is.
    pub contenders: Vec<String>,
    /// How the controller's speeds were chosen.
    pub notes: Vec<String>,
}

/// Plans and plays the suite and writes both files into `dir`; returns the cells. Cells of
/// `reuse` (an earlier suite's, read with [`reusable`]) with the same contender label, axis and
/// level are taken instead of played again.
pub fn run_to_dir(
    suite: &Suite,
    agents: Vec<Contender>,
    choices: &[ControllerChoice],
    dir: &Path,
    command: &str,
    reuse: &[Cell],
    reused_from: Option<(String, f64)>,
) -> Result<(Vec<Cell>, SuiteMeta)> {
    let start = Instant::now();
    let p = plan(suite, agents, choices, reuse)?;
    let mut known = p.known.clone();
    known.extend(reuse.iter().cloned());
    let cells = suite.run(&p.contenders, &known)?;
    let mut notes = p.notes;
    let mut earlier = None;
    if let Some((dir, wall)) = reused_from {
        earlier = Some(wall);
        let n = cells
            .iter()
            .filter(|c| reuse.iter().any(|r| r.policy == c.policy && r.axis == c.axis && r.level == c.level))
            .count();
        notes.push(format!(
            "{n} of the {} cells were taken from the earlier suite in {dir}, which took {wall:.0} s in all; this run's wall time is the rest",
            cells.len()
        ));
    }
    let meta = SuiteMeta {
        command: command.to_string(),
        machine: format!("{} ({})", crate::train::provenance::cpu_model(), crate::train::provenance::simd_level()),
        git_commit: crate::train::git_commit().unwrap_or_else(|| "unknown".into()),
        env: suite.env.clone(),
        episodes: suite.protocol.episodes,
        protocol_seed: suite.protocol.seed,
        threads: suite.threads,
        wall_seconds: start.elapsed().as_secs_f64(),
        total_wall_seconds: earlier.map(|w| w + start.elapsed().as_secs_f64()),
        contenders: p.contenders.iter().map(describe).collect(),
        notes,
    };
    write_atomic(&dir.join(CSV_FILE), |w| Ok(w.write_all(to_csv(&cells).as_bytes())?))?;
    let text = toml::to_string_pretty(&meta).context("writing the suite's metadata")?;
    write_atomic(&dir.join(META_FILE), |w| Ok(w.write_all(text.as_bytes())?))?;
    Ok((cells, meta))
}

/// What the metadata says of the controller on a command task.
const FOLLOWS_THE_COMMAND: &str = "the controller following the task's command";

/// A contender as the metadata lists it: `LABEL: the controller commanded SPEED m/s`, or
/// `LABEL: REFERENCE[ at budget B], ...` (one per seed).
pub fn describe(c: &Contender) -> String {
    match c {
        // On a command task it takes no speed: it follows the task's command.
        Contender::Controller { label, .. } if label == super::plan::COMMAND_CONTROLLER => {
            format!("{label}: {FOLLOWS_THE_COMMAND}")
        }
        Contender::Controller { label, speed } => format!("{label}: the controller commanded {speed} m/s"),
        Contender::Agent { label, seeds } => format!(
            "{label}: {}",
            seeds
                .iter()
                .map(|s| format!(
                    "{}{}",
                    s.reference.display(),
                    s.budget.map_or(String::new(), |b| format!(" at budget {b}"))
                ))
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// The contender a [`describe`] line stands for; an error naming the line when it is not one.
pub fn parse_description(line: &str) -> Result<Contender> {
    let Some((label, what)) = line.split_once(": ") else {
        anyhow::bail!("'{line}' is not a suite contender (LABEL: WHAT)");
    };
    if what == FOLLOWS_THE_COMMAND {
        return Ok(Contender::Controller { label: label.to_string(), speed: 0.0 });
    }
    if let Some(speed) = what.strip_prefix("the controller commanded ").and_then(|r| r.strip_suffix(" m/s")) {
        let speed = speed.parse().with_context(|| format!("'{line}': '{speed}' is not a speed"))?;
        return Ok(Contender::Controller { label: label.to_string(), speed });
    }
    let seeds = what
        .split(", ")
        .map(|s| match s.rsplit_once(" at budget ") {
            Some((r, b)) => Ok(super::suite::PolicySource {
                reference: r.into(),
                budget: Some(b.parse().with_context(|| format!("'{line}': '{b}' is not a step budget"))?),
            }),
            None => Ok(super::suite::PolicySource { reference: s.into(), budget: None }),
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Contender::Agent { label: label.to_string(), seeds })
}

impl SuiteMeta {
    /// The contenders, as [`parse_description`] reads them back from `contenders`.
    pub fn parsed_contenders(&self) -> Result<Vec<Contender>> {
        self.contenders.iter().map(|l| parse_description(l)).collect()
    }

    /// The wall time of every run that played this suite's cells (s).
    pub fn total_wall(&self) -> f64 {
        self.total_wall_seconds.unwrap_or(self.wall_seconds)
    }
}

/// Reads a committed suite: its cells and metadata from `dir`. A cell from a CSV without the
/// commit column gets `<=COMMIT` (the suite's commit, or an earlier one, played it).
pub fn read_dir(dir: &Path) -> Result<(Vec<Cell>, SuiteMeta)> {
    let csv = dir.join(CSV_FILE);
    let text = std::fs::read_to_string(&csv).with_context(|| format!("reading {}", csv.display()))?;
    let mut cells = super::suite::from_csv(&text, &csv.display().to_string())?;
    let meta_path = dir.join(META_FILE);
    let meta_text = std::fs::read_to_string(&meta_path).with_context(|| format!("reading {}", meta_path.display()))?;
    let meta: SuiteMeta =
        toml::from_str(&meta_text).with_context(|| format!("{}: not a suite's metadata", meta_path.display()))?;
    for c in cells.iter_mut().filter(|c| c.commit.is_empty()) {
        c.commit = format!("<={}", meta.git_commit);
    }
    Ok((cells, meta))
}

/// The cells of the suite in `dir`, to reuse in a suite with the same env, episodes and protocol
/// seed (anything else is an error naming what differs). The cells are a function of those and
/// of the contender, so a reused cell is the cell the new suite would play. A trained contender's
/// cells are kept only where the earlier suite's label stood for the same policies as `agents`'
/// (a label moved to another policy plays again); a controller's label carries its speed.
pub fn reusable(dir: &Path, suite: &Suite, agents: &[Contender]) -> Result<(Vec<Cell>, SuiteMeta)> {
    let (cells, meta) = read_dir(dir)?;
    if meta.env != suite.env || meta.episodes != suite.protocol.episodes || meta.protocol_seed != suite.protocol.seed {
        anyhow::bail!(
            "{}: its suite ran {} with {} episodes at protocol seed {}, not {} with {} at seed {}: nothing to reuse",
            dir.display(),
            meta.env.name,
            meta.episodes,
            meta.protocol_seed,
            suite.env.name,
            suite.protocol.episodes,
            suite.protocol.seed
        );
    }
    let same_policies =
        |label: &str| agents.iter().any(|a| a.label() == label && meta.contenders.iter().any(|d| *d == describe(a)));
    let cells = cells.into_iter().filter(|c| c.kind == "controller" || same_policies(&c.policy)).collect();
    Ok((cells, meta))
}

fn fmt_level(level: Option<f64>, axis: &Axis) -> String {
    match level {
        Some(l) if l == axis.nominal => format!("nominal only ({l} {})", axis.unit),
        Some(l) => format!("{l} {}", axis.unit),
        None => "below 90% even nominal".into(),
    }
}

/// Per axis and contender: the largest level survived at 90% (with the survival interval there),
/// and, for each policy, how often it survived where `controller` fell. As text lines.
pub fn summary_lines(cells: &[Cell], axes: &[Axis], controller: Option<&str>) -> Vec<String> {
    let mut policies: Vec<&str> = Vec::new();
    for c in cells {
        if !policies.contains(&c.policy.as_str()) {
            policies.push(&c.policy);
        }
    }
    let mut out = Vec::new();
    for axis in axes {
        out.push(format!("{} ({}):", axis.name, axis.unit));
        for p in &policies {
            let t = threshold(cells, p, axis);
            let survival = t
                .survival
                .map_or(String::new(), |s| format!(", survival {:.2} [{:.2}, {:.2}]", s.estimate, s.low, s.high));
            let beyond = if t.beyond_last { ", and beyond the last level" } else { "" };
            let below = t.first_below.map_or(String::new(), |(l, s)| {
                format!("; {:.2} [{:.2}, {:.2}] at {l} {}", s.estimate, s.low, s.high, axis.unit)
            });
            let walking = walking_note(cells, p, axis, |l| format!("{l} {}", axis.unit))
                .map_or(String::new(), |n| format!("; {n}"));
            let mut line =
                format!("  {p:<44} 90% up to {}{survival}{beyond}{below}{walking}", fmt_level(t.level, axis));
            if let Some(ctrl) = controller.filter(|c| c != p) {
                if let Some((n, s)) = survives_where_controller_falls(cells, p, ctrl, axis) {
                    line.push_str(&format!(
                        "; survives {:.2} [{:.2}, {:.2}] of {n} episodes the controller fell in",
                        s.estimate, s.low, s.high
                    ));
                }
            }
            out.push(line);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::robustness::suite::PolicySource;

    #[test]
    fn contenders_read_back_from_their_description() {
        let contenders = [
            Contender::Controller { label: "controller 1.563 m/s (best)".into(), speed: 1.5625 },
            Contender::Agent {
                label: "ppo 1M".into(),
                seeds: vec![PolicySource { reference: "models/policies/minitaur-ppo".into(), budget: None }],
            },
            Contender::Controller { label: super::super::plan::COMMAND_CONTROLLER.into(), speed: 0.0 },
            Contender::Agent {
                label: "crossq".into(),
                seeds: (0..3)
                    .map(|s| PolicySource {
                        reference: format!("benches/results/ant/crossq-256-seed{s}").into(),
                        budget: Some(300_000),
                    })
                    .collect(),
            },
        ];
        for c in contenders {
            assert_eq!(parse_description(&describe(&c)).unwrap(), c);
        }
        let err = parse_description("no colon here").unwrap_err().to_string();
        assert!(err.contains("no colon here"), "{err}");
        let err = parse_description("x: a at budget many").unwrap_err().to_string();
        assert!(err.contains("'many' is not a step budget"), "{err}");
    }
}
