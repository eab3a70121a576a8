//! Which actor a run keeps at each reporting budget under `budget_policy = "best"`: of the actors
//! evaluated in training up to that budget, the one whose evaluation had the highest minimum
//! episode return, ties going to the higher mean.
//!
//! This is TD7's policy checkpointing (Fujimoto et al. 2023, "For SALE: State-Action Representation
//! Learning for Deep Reinforcement Learning", policy checkpoints; repository `sfujim/TD7`,
//! `TD7.py`, `maybe_train_and_checkpoint`): an off-policy actor's quality swings from one snapshot
//! to the next, and the worst episode is what a fall shows up in. TD7 judges on training episodes;
//! here the judge is the run's own evaluation episodes (`train::evaluate`), which are seeded apart
//! from the report's held-out ones, so the choice never sees a held-out episode.
//!
//! Files: each new best actor goes to `policies/best-step-<N>.safetensors`; at a budget it is
//! copied to `policies/step-<budget>.safetensors`, the file every reader of budget policies
//! takes, and `policies/selected.csv` says which step each budget's actor comes from. Only the
//! newest best and the one the latest checkpoint names are kept, so a resume always finds its own.
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use super::checkpoint::{budget_policy_path, policy_file_steps, save_actor, BUDGET_POLICY_DIR};
use super::evaluate::Evaluation;
use super::scaffold::save_budget_policy;
use crate::agents::Agent;
use crate::io::write_bytes_atomic;

/// The file that lists, per budget, the step of the actor kept for it.
pub const SELECTED_FILE: &str = "selected.csv";

/// An evaluated actor: its step and its evaluation's minimum and mean return.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// The step the actor was evaluated at.
    pub step: u64,
    /// Its evaluation's lowest episode return.
    pub min_return: f64,
    /// Its evaluation's mean return.
    pub mean_return: f64,
}

impl Snapshot {
    /// The actor at `step`, judged by `evaluation`.
    pub fn of(step: u64, evaluation: &Evaluation) -> Snapshot {
        let min_return = evaluation.returns.iter().copied().fold(f64::INFINITY, f64::min);
        Snapshot { step, min_return, mean_return: evaluation.mean() }
    }

    /// Strictly better: a higher minimum return, or the same minimum and a higher mean. An
    /// earlier actor keeps its place on a full tie.
    pub fn beats(&self, other: &Snapshot) -> bool {
        self.min_return > other.min_return
            || (self.min_return == other.min_return && self.mean_return > other.mean_return)
    }
}

/// The name of a best actor's file before its step (`policies/best-step-<N>.safetensors`).
const SNAPSHOT_PREFIX: &str = "best-step-";

/// Where the best actor evaluated at `step` is kept.
pub fn snapshot_path(run_dir: &Path, step: u64) -> PathBuf {
    run_dir.join(BUDGET_POLICY_DIR).join(format!("{SNAPSHOT_PREFIX}{step}.safetensors"))
}

/// The best actor so far, and the one the latest checkpoint names (whose file a resume needs).
#[derive(Debug, Clone, Default)]
pub struct BestPolicy {
    /// The best actor so far.
    pub best: Option<Snapshot>,
    /// The best actor the latest checkpoint names.
    pub checkpointed: Option<Snapshot>,
}

impl BestPolicy {
    /// The state a checkpoint saved.
    pub fn resumed(best: Option<Snapshot>) -> BestPolicy {
        BestPolicy { best, checkpointed: best }
    }

    /// Judges `agent`'s actor at `step` by `evaluation`; a new best is written to its file, and
    /// files no longer needed go.
    pub fn consider(&mut self, run_dir: &Path, step: u64, evaluation: &Evaluation, agent: &dyn Agent) -> Result<()> {
        let candidate = Snapshot::of(step, evaluation);
        if self.best.is_some_and(|b| !candidate.beats(&b)) {
            return Ok(());
        }
        let dir = run_dir.join(BUDGET_POLICY_DIR);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        save_actor(&snapshot_path(run_dir, step), agent)?;
        self.best = Some(candidate);
        self.prune(run_dir)
    }

    /// A checkpoint holding the current best was written: the files of earlier bests go.
    pub fn mark_checkpointed(&mut self, run_dir: &Path) -> Result<()> {
        self.checkpointed = self.best;
        self.prune(run_dir)
    }

    /// Removes every best-actor file but the newest best's and the latest checkpoint's.
    fn prune(&self, run_dir: &Path) -> Result<()> {
        let keep = [self.best.map(|b| b.step), self.checkpointed.map(|c| c.step)];
        for stale in policy_file_steps(run_dir, SNAPSHOT_PREFIX).into_iter().filter(|s| !keep.contains(&Some(*s))) {
            let path = snapshot_path(run_dir, stale);
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
        }
        Ok(())
    }

    /// Writes the actor kept for `budget`: the best so far, or `agent`'s if nothing was evaluated
    /// yet (the step is then the budget's own, with no figures).
    pub fn save_budget(&self, run_dir: &Path, budget: u64, agent: &dyn Agent) -> Result<()> {
        let Some(best) = self.best else {
            save_budget_policy(run_dir, budget, agent)?;
            return record_selection(run_dir, budget, None);
        };
        let from = snapshot_path(run_dir, best.step);
        let bytes = std::fs::read(&from).with_context(|| format!("reading {}", from.display()))?;
        write_bytes_atomic(&budget_policy_path(run_dir, budget), &bytes)?;
        record_selection(run_dir, budget, Some(best))
    }
}

/// One row of `policies/selected.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Selected {
    /// The reporting budget.
    pub budget: u64,
    /// The step of the actor kept for it.
    pub step: u64,
    /// The evaluation's minimum and mean return (absent when nothing had been evaluated).
    pub figures: Option<(f64, f64)>,
}

const HEADER: &str = "budget,step,min_return,mean_return";

/// The rows of `run_dir`'s `policies/selected.csv` (none when the run kept its last actors).
pub fn read_selected(run_dir: &Path) -> Result<Vec<Selected>> {
    let path = run_dir.join(BUDGET_POLICY_DIR).join(SELECTED_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let mut lines = text.lines();
    anyhow::ensure!(lines.next() == Some(HEADER), "{}: the first line must be `{HEADER}`", path.display());
    lines
        .enumerate()
        .map(|(i, line)| {
            let bad = || {
                format!("{} line {}: expected budget,step,min_return,mean_return, got `{line}`", path.display(), i + 2)
            };
            let f: Vec<&str> = line.split(',').collect();
            anyhow::ensure!(f.len() == 4, "{}", bad());
            let figures = match (f[2], f[3]) {
                ("", "") => None,
                (a, b) => Some((a.parse().with_context(bad)?, b.parse().with_context(bad)?)),
            };
            Ok(Selected { budget: f[0].parse().with_context(bad)?, step: f[1].parse().with_context(bad)?, figures })
        })
        .collect()
}

/// Records (or replaces) `budget`'s row in `policies/selected.csv`.
fn record_selection(run_dir: &Path, budget: u64, best: Option<Snapshot>) -> Result<()> {
    let mut rows: Vec<Selected> = read_selected(run_dir)?.into_iter().filter(|r| r.budget != budget).collect();
    rows.push(Selected {
        budget,
        step: best.map_or(budget, |b| b.step),
        figures: best.map(|b| (b.min_return, b.mean_return)),
    });
    rows.sort_by_key(|r| r.budget);
    let mut text = format!("{HEADER}\n");
    for r in &rows {
        let (min, mean) = r.figures.map_or((String::new(), String::new()), |(a, b)| (a.to_string(), b.to_string()));
        text.push_str(&format!("{},{},{min},{mean}\n", r.budget, r.step));
    }
    write_bytes_atomic(&run_dir.join(BUDGET_POLICY_DIR).join(SELECTED_FILE), text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn evaluation(returns: &[f64]) -> Evaluation {
        Evaluation {
            returns: returns.to_vec(),
            lengths: vec![1; returns.len()],
            term_means: Vec::new(),
            unstable_episodes: 0,
            saturation: 0.0,
        }
    }

    #[test]
    fn the_worst_episode_decides_then_the_mean() {
        let steady = Snapshot::of(10, &evaluation(&[18.0, 19.0, 20.0]));
        let fast_but_falls = Snapshot::of(20, &evaluation(&[2.0, 25.0, 25.0]));
        assert_eq!((steady.min_return, steady.mean_return), (18.0, 19.0));
        assert!(steady.beats(&fast_but_falls) && !fast_but_falls.beats(&steady));
        let same_floor_higher_mean = Snapshot::of(30, &evaluation(&[18.0, 21.0, 21.0]));
        assert!(same_floor_higher_mean.beats(&steady));
        let tie = Snapshot { step: 40, ..steady };
        assert!(!tie.beats(&steady), "the earlier actor keeps its place");
    }
}
