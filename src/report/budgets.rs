//! Which policy of which run answers a row at a given step budget. A run contributes the actor
//! it wrote when it passed the budget (`train::POLICY_BUDGETS`), never a later one; a shipped
//! policy (`models/policies/*`) counts at the step its `source.toml` names. A run that reached
//! the budget without a policy there is listed, never dropped.
use std::path::{Path, PathBuf};

use anyhow::Result;

use super::runs::Run;
use crate::agents::Agent;
use crate::train::{budget_policy_path, load_budget_policy, load_policy, RunConfig, POLICY_BUDGETS};

/// Where a run's policy at a budget comes from.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum PolicySource {
    /// `policies/step-<budget>.safetensors`, written by training.
    BudgetFile(PathBuf),
    /// An exported `policy.safetensors` whose `source.toml` says it is the actor at this step.
    Shipped(PathBuf),
}

impl PolicySource {
    pub fn load(&self, run_dir: &Path, budget: u64) -> Result<(RunConfig, Box<dyn Agent>)> {
        match self {
            PolicySource::BudgetFile(_) => load_budget_policy(run_dir, budget),
            PolicySource::Shipped(_) => load_policy(run_dir),
        }
    }

    /// SHA-256 over the policy file and the run's `config.toml` (the evaluation cache's key).
    pub fn digest(&self, run_dir: &Path) -> Result<String> {
        let file = match self {
            PolicySource::BudgetFile(f) | PolicySource::Shipped(f) => f.clone(),
        };
        crate::io::files_digest(&[file, run_dir.join("config.toml")])
    }
}

/// The step of an exported policy, from the `step = N` line of its `source.toml`.
pub fn shipped_step(run_dir: &Path) -> Option<u64> {
    if !run_dir.join(crate::train::checkpoint::POLICY_FILE).is_file() {
        return None;
    }
    crate::train::policy_ref::exported_step(run_dir)
}

/// An exported policy whose `source.toml` states no step (one imported from elsewhere without
/// its budget): its one row is at [`UNKNOWN_BUDGET`].
fn exported_without_step(run: &Run) -> bool {
    run.dir.join(crate::train::checkpoint::POLICY_FILE).is_file()
        && shipped_step(&run.dir).is_none()
        && run.metrics.is_empty()
}

/// The budget of a policy whose training steps are not known (`format::budget` writes it so).
pub const UNKNOWN_BUDGET: u64 = 0;

/// The furthest step a run reached (its metrics, or its exported policy's step).
pub fn reached(run: &Run) -> u64 {
    run.steps().max(shipped_step(&run.dir).unwrap_or(0))
}

/// The run's policy at `budget`, or why there is none (the run must have reached the budget).
pub(crate) fn policy_at(run: &Run, budget: u64) -> Result<PolicySource, String> {
    let file = budget_policy_path(&run.dir, budget);
    if file.is_file() {
        return Ok(PolicySource::BudgetFile(file));
    }
    if shipped_step(&run.dir) == Some(budget) || (budget == UNKNOWN_BUDGET && exported_without_step(run)) {
        return Ok(PolicySource::Shipped(run.dir.join(crate::train::checkpoint::POLICY_FILE)));
    }
    let held = crate::train::budget_policy_steps(&run.dir);
    Err(if held.is_empty() && shipped_step(&run.dir).is_none() {
        "no policy kept (config and metrics only)".to_string()
    } else {
        let mut steps: Vec<u64> = held;
        steps.extend(shipped_step(&run.dir));
        steps.sort_unstable();
        let list: Vec<String> = steps.iter().map(|s| super::plots::step_label(*s as f64)).collect();
        format!("no policy at this budget (policies at {})", list.join(", "))
    })
}

/// A standard budget that runs trained before it joined the list passed without keeping an
/// actor there: it is reported only where a run kept one (500k).
const KEPT_BUDGET: u64 = 500_000;

/// The budgets a set of runs is reported at: each standard budget but [`KEPT_BUDGET`] that some
/// run reached; the full budget of each run, and [`KEPT_BUDGET`], where the run reached it and
/// kept its actor there;
/// and the last step of each run that reached no standard budget (short runs), so that every run
/// appears in some row. An imported policy has one row, at the
/// step its `source.toml` states (or [`UNKNOWN_BUDGET`]).
pub fn budgets(runs: &[&Run]) -> Vec<u64> {
    // A policy imported from elsewhere is reported at the step its source states, and only there.
    let (imported, runs): (Vec<&Run>, Vec<&Run>) = runs.iter().copied().partition(|r| r.imported.is_some());
    let mut out: Vec<u64> = imported.iter().map(|r| shipped_step(&r.dir).unwrap_or(UNKNOWN_BUDGET)).collect();
    out.extend(POLICY_BUDGETS.iter().copied().filter(|&b| b != KEPT_BUDGET && runs.iter().any(|r| reached(r) >= b)));
    for r in runs {
        if exported_without_step(r) {
            out.push(UNKNOWN_BUDGET);
        }
        let last = reached(r);
        if last < POLICY_BUDGETS[0] && last > 0 {
            out.push(last);
        }
        for kept in [r.config.train.total_steps, KEPT_BUDGET] {
            if last >= kept && budget_policy_path(&r.dir, kept).is_file() {
                out.push(kept);
            }
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_policies_name_their_step() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/policies");
        assert_eq!(shipped_step(&root.join("minitaur-td3")), Some(300_000));
        assert_eq!(shipped_step(&root.join("minitaur-sac")), Some(300_000));
        assert_eq!(shipped_step(&root), None);
    }

    /// A SAC run trained to `total` steps in `dir`, whose metrics reach `reached`.
    fn run_in(dir: &Path, total: u64, reached: u64) -> Run {
        let mut run =
            crate::report::runs::tests::run("minitaur", crate::agents::Algo::Sac, &format!("total_steps={total}"), &[]);
        run.dir = dir.to_path_buf();
        run.metrics = vec![crate::train::metrics::MetricsRow { kind: "episode", step: reached, ..Default::default() }];
        run
    }

    #[test]
    fn a_run_trained_to_500k_gets_a_500k_row_only_when_its_policy_was_kept() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        let mut run = run_in(&dir, 500_000, 500_000);
        // Reached 500k but kept no actor there: only the standard budgets it passed.
        assert_eq!(budgets(&[&run]), vec![100_000, 300_000]);
        let file = budget_policy_path(&dir, 500_000);
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        std::fs::write(&file, b"").unwrap();
        assert_eq!(budgets(&[&run]), vec![100_000, 300_000, 500_000]);
        // A run stopped before its full budget gets no row there.
        run.metrics = vec![crate::train::metrics::MetricsRow { kind: "episode", step: 400_000, ..Default::default() }];
        assert_eq!(budgets(&[&run]), vec![100_000, 300_000]);
    }

    #[test]
    fn a_run_carried_on_past_500k_keeps_its_500k_row() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().to_path_buf();
        let run = run_in(&dir, 1_000_000, 1_000_000);
        for step in [100_000, 300_000, 1_000_000] {
            let file = budget_policy_path(&dir, step);
            std::fs::create_dir_all(file.parent().unwrap()).unwrap();
            std::fs::write(&file, b"").unwrap();
        }
        assert_eq!(budgets(&[&run]), vec![100_000, 300_000, 1_000_000]);
        std::fs::write(budget_policy_path(&dir, 500_000), b"").unwrap();
        assert_eq!(budgets(&[&run]), vec![100_000, 300_000, 500_000, 1_000_000]);
    }
}
