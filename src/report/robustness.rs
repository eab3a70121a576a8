//! The report's robustness section, from a committed suite (`locobench robustness`, `cargo bench
//! --bench robustness`): who survives the largest perturbation of each axis at 90%, how often a
//! policy survives where the controller at its best speed falls, the goal a robust policy is
//! measured against, and one chart of survival against level per axis.
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;

use super::document::Document;
use super::plots::{bands_svg, Band};
use crate::evaluation::robustness::output::{read_dir, SuiteMeta};
use crate::evaluation::robustness::summary::{
    along, survives_where_controller_falls, threshold, walking_note, SURVIVAL_BAR, WALK_SHARE,
};
use crate::evaluation::robustness::{axes_of, Axis, Cell};
use crate::evaluation::stats::Interval;

/// A committed suite, restricted to one env.
pub struct SuiteData {
    /// Its cells.
    pub cells: Vec<Cell>,
    /// How it was run.
    pub meta: SuiteMeta,
    /// The axes it covers, in the suite's order.
    pub axes: Vec<Axis>,
}

impl SuiteData {
    /// Reads `dir` (robustness.csv and robustness.toml).
    pub fn read(dir: &Path) -> Result<SuiteData> {
        let (cells, meta) = read_dir(dir)?;
        let axes =
            axes_of(&meta.env.name)?.iter().filter(|a| cells.iter().any(|c| c.axis == a.name)).copied().collect();
        Ok(SuiteData { cells, meta, axes })
    }

    /// Contenders in the order they were played.
    pub fn contenders(&self) -> Vec<&str> {
        let mut out: Vec<&str> = Vec::new();
        for c in &self.cells {
            if !out.contains(&c.policy.as_str()) {
                out.push(&c.policy);
            }
        }
        out
    }

    /// The controller at its best speed, if the suite has it.
    pub fn best_controller(&self) -> Option<&str> {
        self.contenders().into_iter().find(|p| p.ends_with("(best)"))
    }

    fn policies(&self) -> Vec<&str> {
        self.contenders()
            .into_iter()
            .filter(|p| self.cells.iter().any(|c| c.policy == *p && c.kind == "policy"))
            .collect()
    }
}

fn level(l: f64, axis: &Axis) -> String {
    format!("{} {}", trim(l), axis.unit)
}

fn trim(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

fn rate(i: Interval) -> String {
    format!("{:.2} [{:.2}, {:.2}]", i.estimate, i.low, i.high)
}

/// The 90% level of one contender on one axis, as a table cell.
fn threshold_cell(s: &SuiteData, policy: &str, axis: &Axis) -> String {
    let t = threshold(&s.cells, policy, axis);
    let below = t.first_below.map_or(String::new(), |(l, i)| format!("; {} at {}", rate(i), level(l, axis)));
    let below = match walking_note(&s.cells, policy, axis, |l| level(l, axis)) {
        Some(note) => format!("{below}; {note}"),
        None => below,
    };
    match (t.level, t.survival) {
        (Some(l), Some(i)) => {
            let beyond = if t.beyond_last { ", every level" } else { "" };
            if l == axis.nominal {
                format!("nominal only ({}{beyond}){below}", rate(i))
            } else {
                format!("{} ({}{beyond}){below}", level(l, axis), rate(i))
            }
        }
        _ => format!("below 90% even nominal{below}"),
    }
}

/// How far along an axis a contender's 90% level is: the index of that level (nominal 0), -1
/// when even nominal is below the bar.
fn reach(s: &SuiteData, policy: &str, axis: &Axis) -> i64 {
    let t = threshold(&s.cells, policy, axis);
    t.level.map_or(-1, |l| axis.all_levels().iter().position(|x| *x == l).map_or(-1, |i| i as i64))
}

/// The summary table: per axis, each contender's 90% level, who reaches furthest, and each
/// policy's P(survives | the controller at its best speed falls).
pub fn summary_table(s: &SuiteData) -> (Vec<String>, Vec<Vec<String>>) {
    let contenders = s.contenders();
    let policies = s.policies();
    let best = s.best_controller();
    let mut header = vec!["axis".to_string()];
    header.extend(contenders.iter().map(|c| format!("{c}: 90% up to (survival there; at the next level)")));
    header.push("furthest at 90%".into());
    if let Some(b) = best {
        header.extend(policies.iter().map(|p| format!("P({p} survives | {b} falls)")));
    }
    let rows = s
        .axes
        .iter()
        .map(|axis| {
            let mut row = vec![format!("{} ({})", axis.name, axis.unit)];
            row.extend(contenders.iter().map(|c| threshold_cell(s, c, axis)));
            let top = contenders.iter().map(|c| reach(s, c, axis)).max().unwrap_or(-1);
            let winners: Vec<&str> = contenders.iter().copied().filter(|c| reach(s, c, axis) == top).collect();
            row.push(if top < 0 { "none".into() } else { winners.join(", ") });
            if let Some(b) = best {
                row.extend(policies.iter().map(|p| match survives_where_controller_falls(&s.cells, p, b, axis) {
                    Some((n, i)) => format!("{} of {n}", rate(i)),
                    None => "the controller never fell".into(),
                }));
            }
            row
        })
        .collect();
    (header, rows)
}

/// The goal each policy is held to: nominal return above the controller's best, no more falls,
/// and at least the controller's 90% level on every axis; how far each misses.
pub fn goal_lines(s: &SuiteData) -> Vec<String> {
    let Some(best) = s.best_controller() else { return Vec::new() };
    let nominal = |p: &str| s.cells.iter().find(|c| c.policy == p && c.axis == "nominal");
    let Some(ctrl) = nominal(best) else { return Vec::new() };
    let mut out = Vec::new();
    for p in s.policies() {
        let Some(n) = nominal(p) else { continue };
        let mut misses = Vec::new();
        if n.ret.estimate <= ctrl.ret.estimate {
            misses.push(format!("return {:.2} is not above the controller's {:.2}", n.ret.estimate, ctrl.ret.estimate));
        }
        let falls_rate = |c: &Cell| c.fell() as f64 / c.outcomes.len().max(1) as f64;
        if falls_rate(n) > falls_rate(ctrl) {
            misses.push(format!(
                "falls in {}/{} nominal episodes against the controller's {}/{}",
                n.fell(),
                n.outcomes.len(),
                ctrl.fell(),
                ctrl.outcomes.len()
            ));
        }
        let below_nominal = s.axes.first().is_some_and(|a| reach(s, p, a) < 0);
        if below_nominal {
            misses.push(
                "it survives less than 90% of the nominal episodes, so it is short of the controller on every axis"
                    .into(),
            );
        }
        for axis in s.axes.iter().filter(|_| !below_nominal) {
            let (mine, theirs) = (reach(s, p, axis), reach(s, best, axis));
            if mine < theirs {
                let levels = axis.all_levels();
                let name = |r: i64| if r < 0 { "below nominal".to_string() } else { level(levels[r as usize], axis) };
                misses.push(format!("{}: {} against the controller's {}", axis.name, name(mine), name(theirs)));
            }
        }
        let head = format!(
            "{p}: nominal return {:.2} [{:.2}, {:.2}], {}/{} falls, {:.2} m/s (the controller at its best speed: {:.2}, {}/{} falls, {:.2} m/s)",
            n.ret.estimate,
            n.ret.low,
            n.ret.high,
            n.fell(),
            n.outcomes.len(),
            n.speed,
            ctrl.ret.estimate,
            ctrl.fell(),
            ctrl.outcomes.len(),
            ctrl.speed
        );
        if misses.is_empty() {
            out.push(format!("{head}: meets the goal on every count."));
        } else {
            out.push(format!("{head}: misses it by: {}.", misses.join("; ")));
        }
    }
    out
}

/// Survival against level on one axis: a line per contender with its Wilson band.
fn chart(s: &SuiteData, axis: &Axis) -> Result<String> {
    let bands: Vec<Band> = s
        .contenders()
        .iter()
        .map(|p| {
            let line = along(&s.cells, p, axis);
            let levels = axis.all_levels();
            let pts: Vec<(f64, Interval)> = line.iter().zip(&levels).map(|(c, l)| (*l, c.survival())).collect();
            Band {
                label: p.to_string(),
                x: pts.iter().map(|p| p.0).collect(),
                mean: pts.iter().map(|p| p.1.estimate).collect(),
                low: pts.iter().map(|p| p.1.low).collect(),
                high: pts.iter().map(|p| p.1.high).collect(),
            }
        })
        .collect();
    bands_svg(&format!("{}: survival", axis.label), &format!("{} ({})", axis.label, axis.unit), "survival", &bands, &[])
}

/// One axis's cells as a table: per contender and level, survival, return, speed, cost of
/// transport.
fn axis_table(s: &SuiteData, axis: &Axis) -> (Vec<String>, Vec<Vec<String>>) {
    let levels = axis.all_levels();
    let mut header = vec!["contender".to_string()];
    header.extend(levels.iter().map(|l| level(*l, axis)));
    let rows = s
        .contenders()
        .iter()
        .map(|p| {
            let mut row = vec![p.to_string()];
            for c in along(&s.cells, p, axis) {
                let unstable = if c.unstable() > 0 { format!(", {} blew up", c.unstable()) } else { String::new() };
                row.push(format!(
                    "{}/{} survived{unstable}; return {:.2}; {:.2} m/s; CoT {}",
                    c.survived(),
                    c.survived() + c.fell(),
                    c.ret.estimate,
                    c.speed,
                    if c.cost_of_transport.is_finite() { format!("{:.2}", c.cost_of_transport) } else { "–".into() }
                ));
            }
            row
        })
        .collect();
    (header, rows)
}

/// What the suite ran, for a reader.
pub fn provenance(s: &SuiteData) -> String {
    let m = &s.meta;
    let mut text = format!(
        "Every contender plays the same {} held-out episodes (protocol seed {}) at every level of every axis, \
         in the env's default options plus the axis's own, each policy acting at its own run's control rate \
         (`action_repeat`) over the same episode length; a row of several trained seeds plays every episode \
         once per seed. Survival is the share of episodes that walked to the time limit, with its 95% Wilson \
         interval; episodes where the physics blew up are counted apart, not as falls. Surviving is not walking \
         (a policy can stand still on ice): where a contender's 90% level differs from the last level at which it \
         also keeps at least {:.0}% of its nominal mean speed, the summary table names both, and for a contender \
         below the bar even nominally it gives the level up to which that speed is kept. The controller reads the \
         simulator's state (base pose and velocity, masses, gravity) where the policies read their {} observed \
         values{}. Measured on {} at commit {}, {:.0} s of wall time with {} threads: `{}`.",
        m.episodes,
        m.protocol_seed,
        WALK_SHARE * 100.0,
        crate::envs::make(&m.env).map_or(0, |e| e.spec().observation_space.dim()),
        if s.axes.iter().any(|a| matches!(a.apply, crate::evaluation::robustness::axes::Apply::Options(_))) {
            ", so sensor noise reaches the controller only through the motor angles and velocities, and it knows a \
             payload or a slope that the policies must feel"
        } else {
            ""
        },
        m.machine,
        crate::train::provenance::short_commit(&m.git_commit, 12),
        m.wall_seconds,
        m.threads,
        m.command
    );
    for c in &m.contenders {
        let _ = write!(text, "\n- {c}");
    }
    for n in &m.notes {
        let _ = write!(text, "\n- {n}");
    }
    let _ = write!(text, "\n- {}", commits_line(&s.cells));
    text
}

/// Which commits played the cells (the CSV's `commit` column), most cells first.
fn commits_line(cells: &[Cell]) -> String {
    let mut counts: Vec<(&str, usize)> = Vec::new();
    for c in cells {
        match counts.iter_mut().find(|(k, _)| *k == c.commit) {
            Some((_, n)) => *n += 1,
            None => counts.push((&c.commit, 1)),
        }
    }
    counts.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(b.0)));
    let parts: Vec<String> = counts
        .iter()
        .map(|(commit, n)| {
            let (hash, earlier) = commit.strip_prefix("<=").map_or((*commit, ""), |c| (c, " or an earlier commit"));
            format!("{n} at {}{earlier}", crate::train::provenance::short_commit(hash, 12))
        })
        .collect();
    format!("cells played (the CSV's commit column): {}", parts.join(", "))
}

/// The section: provenance, summary table, goal, then per axis its chart and cells.
/// With `videos` (the threads to film with), each axis also gets its side-by-side clip
/// ([`super::robustness_clips`]).
pub(crate) fn section(
    doc: &mut Document,
    out: &Path,
    s: &SuiteData,
    videos: Option<usize>,
    cache: &crate::evaluation::EvalCache,
) -> Result<Vec<super::videos::Clip>> {
    let env = &s.meta.env.name;
    let clips = match videos {
        Some(threads) => super::robustness_clips::film_axes(s, out, threads, cache)?,
        None => Vec::new(),
    };
    doc.heading(2, "Robustness suite");
    doc.paragraph(provenance(s));
    doc.heading(3, format!("Who survives the largest perturbation at {:.0}%", SURVIVAL_BAR * 100.0));
    let (header, rows) = summary_table(s);
    doc.table(&header.iter().map(String::as_str).collect::<Vec<_>>(), rows);
    let goal = goal_lines(s);
    if !goal.is_empty() {
        doc.heading(3, "The goal: more return than the controller, no more falls, at least its reach on every axis");
        doc.lines(goal);
    }
    for axis in &s.axes {
        doc.heading(3, format!("{} ({})", axis.label, axis.name));
        let file = format!("{env}_robustness_{}.svg", axis.name);
        let svg = chart(s, axis)?;
        crate::io::write_bytes_atomic(&out.join(&file), svg.as_bytes())?;
        doc.image(file, format!("Survival against {} with 95% Wilson bands.", axis.label));
        if let Some((_, clip)) = clips.iter().find(|(a, _)| a.name == axis.name) {
            doc.video(clip);
        }
        let (header, rows) = axis_table(s, axis);
        doc.table(&header.iter().map(String::as_str).collect::<Vec<_>>(), rows);
    }
    Ok(clips.into_iter().map(|(_, clip)| clip).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::robustness::suite::test_cell;

    #[test]
    fn the_commits_line_counts_cells_per_commit_and_marks_carried_ones() {
        let at = |commit: &str| Cell { commit: commit.into(), ..test_cell("p", "policy", "payload", 1.0, "S") };
        let cells = [at("<=0123456789abcdef"), at("fedcba9876543210-dirty"), at("<=0123456789abcdef")];
        assert_eq!(
            commits_line(&cells),
            "cells played (the CSV's commit column): 2 at 0123456789ab or an earlier commit, 1 at fedcba987654-dirty"
        );
    }
}
