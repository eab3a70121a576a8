//! The controller beside the learned policies on an env that has one (Minitaur, Ant): its grid
//! of commanded speeds, the controller at each learned row's own speed, the probability that the
//! learned policy beats it on the same episodes, and survival under pushes.
use anyhow::Result;

use super::heldout::{estimate, BudgetRow, Estimate};
use crate::envs::EnvConfig;
use crate::evaluation::stats;
use crate::evaluation::{ControllerFamily, Protocol, Push, SpeedPoint};

pub(crate) use crate::evaluation::speed_grid::{best_point, GRID_MAX, GRID_STEP};

/// Pushes of the robustness table (velocity change, m/s).
pub(crate) const PUSH_LEVELS: [f64; 4] = [0.25, 0.5, 1.0, 1.5];

/// An RL row next to the controller at that row's speed.
#[derive(Debug, Clone)]
pub struct MatchedRow {
    /// Index into the env's budget rows.
    pub row: usize,
    pub(crate) rl_speed: f64,
    /// The controller at the RL row's speed, or why there is none.
    pub controller: Result<SpeedPoint, String>,
    /// P(RL return > controller return) on the same episodes: at the matched speed, and against
    /// the controller's best speed.
    pub(crate) beats_matched: Option<Estimate>,
    pub(crate) beats_best: Option<Estimate>,
}

/// Survival (episodes without a fall) of one policy under each push level.
#[derive(Debug, Clone)]
pub struct PushRow {
    /// The policy's label.
    pub policy: String,
    /// Its mean speed, which the controller is commanded to match (m/s).
    pub speed: f64,
    pub(crate) survived: Vec<(usize, usize)>,
}

/// The controller in one env: its speed grid, best speed, matched rows and pushes.
#[derive(Debug, Clone)]
pub struct ControllerSection {
    /// Every speed tried.
    pub grid: Vec<SpeedPoint>,
    /// The working speed with the highest mean return.
    pub best: Option<SpeedPoint>,
    /// One per RL row.
    pub matched: Vec<MatchedRow>,
    /// Push survival of each policy and of the controller at its speed.
    pub pushes: Vec<PushRow>,
}

/// P(x > y) per seed, as per-seed vectors of 1 / 0.5 / 0 over the paired episodes.
fn improvement(row: &BudgetRow, controller: &SpeedPoint, seed: u64) -> Estimate {
    let per_seed: Vec<Vec<f64>> = row
        .evaluated
        .iter()
        .map(|s| {
            s.episodes
                .iter()
                .zip(&controller.episodes)
                .map(|(a, b)| stats::probability_of_improvement(&[(a.episode_return, b.episode_return)]))
                .collect()
        })
        .collect();
    estimate(&per_seed, stats::mean, seed)
}

/// A number that names a row (its group and budget), so that its bootstrap seed, and so its
/// intervals, do not change when rows are added to or removed from the report.
fn row_identity(row: &BudgetRow) -> u64 {
    let g = &row.group;
    let budget = row.budget.to_string();
    let parts = [g.env.as_str(), g.algo.as_str(), g.reward.as_str(), g.settings.as_str(), g.variant.as_str(), &budget];
    // 0xff (in no UTF-8 text) ends each field
    super::fnv1a(parts.iter().flat_map(|p| p.bytes().chain([0xff])))
}

/// A grid point's mean return with its 95% bootstrap interval over episodes (the controller has
/// no seeds to resample).
pub(crate) fn return_interval(point: &SpeedPoint) -> stats::Interval {
    stats::stratified_bootstrap(
        &[point.returns()],
        |v| stats::mean(&v[0]),
        stats::BOOTSTRAP_REPS,
        super::BOOTSTRAP_SEED,
    )
}

/// Everything about the controller on one env, run under `env_config`. `rows`: the env's
/// held-out rows; those with a policy for which `compared` holds (trained under `env_config`'s
/// options and reward) are matched, and `MatchedRow::row` indexes `rows`.
pub(crate) fn controller_section(
    env_config: &EnvConfig,
    rows: &[BudgetRow],
    compared: impl Fn(&BudgetRow) -> bool,
    protocol: &Protocol,
    seed: u64,
    threads: usize,
    cache: &crate::evaluation::EvalCache,
) -> Result<ControllerSection> {
    let mut family = ControllerFamily::new(env_config, *protocol)?;
    family.threads = threads;
    family.disk = cache.clone();
    let grid = family.sweep(GRID_STEP, GRID_MAX)?;
    let best = best_point(&grid);
    let matchable = || rows.iter().enumerate().filter(|(_, r)| r.seeds() > 0 && compared(r));
    let commands: Vec<(f64, Option<Push>)> = matchable()
        .filter_map(|(_, r)| crate::evaluation::speed_grid::command_for(&grid, r.speed()).ok())
        .map(|c| (c, None))
        .collect();
    family.prefetch(&commands)?;
    let mut matched = Vec::new();
    for (i, row) in matchable() {
        let rl_speed = row.speed();
        let controller = family.matched(&grid, rl_speed)?;
        let row_seed = seed ^ row_identity(row);
        let beats_matched = controller.as_ref().ok().map(|c| improvement(row, c, row_seed));
        let beats_best = best.as_ref().map(|b| improvement(row, b, row_seed ^ 0x100));
        matched.push(MatchedRow { row: i, rl_speed, controller, beats_matched, beats_best });
    }
    Ok(ControllerSection { grid, best, matched, pushes: Vec::new() })
}

/// Survival of the controller commanded `speed` under each push level.
pub(crate) fn controller_pushes(family: &mut ControllerFamily, speed: f64, label: String) -> Result<PushRow> {
    let mut survived = Vec::new();
    for &dv in &PUSH_LEVELS {
        let p = family.at(speed, Some(Push::lateral(dv)))?;
        survived.push((p.episodes.len() - p.falls(), p.episodes.len()));
    }
    Ok(PushRow { policy: label, speed, survived })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::runs::Group;

    fn row(env: &str, algo: &str, settings: &str, budget: u64) -> BudgetRow {
        let group = Group {
            env: env.into(),
            algo: algo.into(),
            reward: String::new(),
            settings: settings.into(),
            variant: String::new(),
        };
        BudgetRow::empty(group, budget)
    }

    #[test]
    fn a_rows_bootstrap_seed_follows_the_row_not_its_place_in_the_report() {
        let td3 = row("minitaur", "td3", "", 1_000_000);
        let mut same = row("minitaur", "td3", "", 1_000_000);
        same.provenance = "another machine".into();
        assert_eq!(row_identity(&td3), row_identity(&same));
        let others = [
            row("ant", "td3", "", 1_000_000),
            row("minitaur", "sac", "", 1_000_000),
            row("minitaur", "td3", "hidden=[64,64]", 1_000_000),
            row("minitaur", "td3", "", 300_000),
            // the fields are separated: "td" + "3..." is not "td3" + "..."
            row("minitaur", "td", "3", 1_000_000),
        ];
        for other in &others {
            assert_ne!(row_identity(&td3), row_identity(other), "{:?}", other.group);
        }
    }
}
