//! Which actor a run keeps at each reporting budget when it picks among the actors evaluated in
//! training up to that budget: under `budget_policy = "best"` the one whose evaluation had the
//! highest minimum episode return, under `"fewest_falls"` the one whose evaluation ended fewest
//! episodes in a fall; ties go to the higher mean.
//!
//! `"best"` is TD7's policy checkpointing (Fujimoto et al. 2023, "For SALE: State-Action Representation
//! Learning for Deep Reinforcement Learning", policy checkpoints; repository `sfujim/TD7`,
//! `TD7.py`, `maybe_train_and_checkpoint`): an off-policy actor's quality swings from one snapshot
//! to the next, and the worst episode is what a fall shows up in. TD7 judges on training episodes;
//! here the judge is the run's own evaluation episodes (`train::evaluate`), which are seeded apart
//! from the report's held-out ones, so the choice never sees a held-out episode. On the Minitaur a
//! fall late in an episode can still return more than a slow episode that stays up, so the lowest
//! return does not always show the falls; `"fewest_falls"` counts them.
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
use crate::agents::config::BudgetPolicy;
use crate::agents::Agent;
use crate::io::write_bytes_atomic;

/// The file that lists, per budget, the step of the actor kept for it.
pub const SELECTED_FILE: &str = "selected.csv";

/// An evaluated actor: its step, its evaluation's minimum and mean return and its falls.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Snapshot {
    /// The step the actor was evaluated at.
    pub step: u64,
    /// Its evaluation's lowest episode return.
    pub min_return: f64,
    /// Its evaluation's mean return.
    pub mean_return: f64,
    /// Its evaluation's episodes that ended before the time limit (unknown in checkpoints written
    /// before it was recorded, which only `"best"` runs wrote).
    #[serde(default)]
    pub falls: Option<u64>,
}

impl Snapshot {
    /// The actor at `step`, judged by `evaluation`.
    pub fn of(step: u64, evaluation: &Evaluation) -> Snapshot {
        let min_return = evaluation.returns.iter().copied().fold(f64::INFINITY, f64::min);
        Snapshot { step, min_return, mean_return: evaluation.mean(), falls: Some(evaluation.falls as u64) }
    }

    /// Strictly better by `policy`'s measure: under `Best` a higher minimum return, under
    /// `FewestFalls` fewer falls; then, on a tie, a higher mean. An earlier actor keeps its place
    /// on a full tie.
    pub fn beats(&self, other: &Snapshot, policy: BudgetPolicy) -> bool {
        let higher_mean = self.mean_return > other.mean_return;
        match policy {
            BudgetPolicy::FewestFalls => self.falls < other.falls || (self.falls == other.falls && higher_mean),
            _ => self.min_return > other.min_return || (self.min_return == other.min_return && higher_mean),
        }
    }
}

/// The name of a best actor's file before its step (`policies/best-step-<N>.safetensors`).
const SNAPSHOT_PREFIX: &str = "best-step-";

/// Where the best actor evaluated at `step` is kept.
pub fn snapshot_path(run_dir: &Path, step: u64) -> PathBuf {
    run_dir.join(BUDGET_POLICY_DIR).join(format!("{SNAPSHOT_PREFIX}{step}.safetensors"))
}

/// The best actor so far by the run's `budget_policy`, and the one the latest checkpoint names
/// (whose file a resume needs).
#[derive(Debug, Clone)]
pub struct BestPolicy {
    /// How actors are compared.
    pub policy: BudgetPolicy,
    /// The best actor so far.
    pub best: Option<Snapshot>,
    /// The best actor the latest checkpoint names.
    pub checkpointed: Option<Snapshot>,
}

impl BestPolicy {
    /// Nothing evaluated yet.
    pub fn new(policy: BudgetPolicy) -> BestPolicy {
        BestPolicy { policy, best: None, checkpointed: None }
    }

    /// The state a checkpoint saved.
    pub fn resumed(policy: BudgetPolicy, best: Option<Snapshot>) -> BestPolicy {
        BestPolicy { policy, best, checkpointed: best }
    }

    /// Judges `agent`'s actor at `step` by `evaluation`; a new best is written to its file, and
    /// files no longer needed go.
    pub fn consider(&mut self, run_dir: &Path, step: u64, evaluation: &Evaluation, agent: &dyn Agent) -> Result<()> {
        let candidate = Snapshot::of(step, evaluation);
        if self.best.is_some_and(|b| !candidate.beats(&b, self.policy)) {
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
    /// The evaluation's falls (absent when nothing had been evaluated, and in files written
    /// before the column existed).
    pub falls: Option<u64>,
}

const HEADER: &str = "budget,step,min_return,mean_return,falls";
/// The header of files written before the `falls` column.
const HEADER_WITHOUT_FALLS: &str = "budget,step,min_return,mean_return";

/// The rows of `run_dir`'s `policies/selected.csv` (none when the run kept its last actors).
pub fn read_selected(run_dir: &Path) -> Result<Vec<Selected>> {
    let path = run_dir.join(BUDGET_POLICY_DIR).join(SELECTED_FILE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let mut lines = text.lines();
    let header = lines.next();
    let columns = match header {
        Some(HEADER) => 5,
        Some(HEADER_WITHOUT_FALLS) => 4,
        _ => anyhow::bail!("{}: the first line must be `{HEADER}`", path.display()),
    };
    let header = header.unwrap_or_default();
    lines
        .enumerate()
        .map(|(i, line)| {
            let bad = || format!("{} line {}: expected {header}, got `{line}`", path.display(), i + 2);
            let f: Vec<&str> = line.split(',').collect();
            anyhow::ensure!(f.len() == columns, "{}", bad());
            let figures = match (f[2], f[3]) {
                ("", "") => None,
                (a, b) => Some((a.parse().with_context(bad)?, b.parse().with_context(bad)?)),
            };
            let falls = match f.get(4) {
                None | Some(&"") => None,
                Some(n) => Some(n.parse().with_context(bad)?),
            };
            Ok(Selected {
                budget: f[0].parse().with_context(bad)?,
                step: f[1].parse().with_context(bad)?,
                figures,
                falls,
            })
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
        falls: best.and_then(|b| b.falls),
    });
    rows.sort_by_key(|r| r.budget);
    let mut text = format!("{HEADER}\n");
    for r in &rows {
        let (min, mean) = r.figures.map_or((String::new(), String::new()), |(a, b)| (a.to_string(), b.to_string()));
        let falls = r.falls.map_or(String::new(), |n| n.to_string());
        text.push_str(&format!("{},{},{min},{mean},{falls}\n", r.budget, r.step));
    }
    write_bytes_atomic(&run_dir.join(BUDGET_POLICY_DIR).join(SELECTED_FILE), text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn evaluation(returns: &[f64], falls: usize) -> Evaluation {
        Evaluation {
            returns: returns.to_vec(),
            lengths: vec![1; returns.len()],
            term_means: Vec::new(),
            unstable_episodes: 0,
            falls,
            saturation: 0.0,
        }
    }

    #[test]
    fn the_worst_episode_decides_then_the_mean() {
        let best = BudgetPolicy::Best;
        let steady = Snapshot::of(10, &evaluation(&[18.0, 19.0, 20.0], 0));
        let fast_but_falls = Snapshot::of(20, &evaluation(&[2.0, 25.0, 25.0], 1));
        assert_eq!((steady.min_return, steady.mean_return, steady.falls), (18.0, 19.0, Some(0)));
        assert!(steady.beats(&fast_but_falls, best) && !fast_but_falls.beats(&steady, best));
        let same_floor_higher_mean = Snapshot::of(30, &evaluation(&[18.0, 21.0, 21.0], 0));
        assert!(same_floor_higher_mean.beats(&steady, best));
        let tie = Snapshot { step: 40, ..steady };
        assert!(!tie.beats(&steady, best), "the earlier actor keeps its place");
    }

    /// A fall late in an episode can return more than a slow episode that stays up: the lowest
    /// return prefers the actor that falls, the fall count does not.
    #[test]
    fn fewest_falls_counts_falls_then_the_mean() {
        let fewest = BudgetPolicy::FewestFalls;
        let slow_upright = Snapshot::of(10, &evaluation(&[8.0, 9.0, 10.0], 0));
        let fast_one_late_fall = Snapshot::of(20, &evaluation(&[12.0, 20.0, 22.0], 1));
        assert!(fast_one_late_fall.beats(&slow_upright, BudgetPolicy::Best));
        assert!(slow_upright.beats(&fast_one_late_fall, fewest) && !fast_one_late_fall.beats(&slow_upright, fewest));
        let faster_upright = Snapshot::of(30, &evaluation(&[7.0, 12.0, 14.0], 0));
        assert!(faster_upright.beats(&slow_upright, fewest) && !slow_upright.beats(&faster_upright, fewest));
        let tie = Snapshot { step: 40, ..faster_upright };
        assert!(!tie.beats(&faster_upright, fewest), "the earlier actor keeps its place");
    }

    #[test]
    fn selected_files_without_the_falls_column_still_read() {
        let dir = tempfile::tempdir().unwrap();
        let policies = dir.path().join(BUDGET_POLICY_DIR);
        std::fs::create_dir_all(&policies).unwrap();
        let file = policies.join(SELECTED_FILE);
        std::fs::write(&file, "budget,step,min_return,mean_return\n100000,95000,0.5,12.5\n").unwrap();
        let rows = read_selected(dir.path()).unwrap();
        assert_eq!(rows, vec![Selected { budget: 100000, step: 95000, figures: Some((0.5, 12.5)), falls: None }]);

        let snapshot = Snapshot::of(290000, &evaluation(&[9.0, 17.0], 1));
        record_selection(dir.path(), 300000, Some(snapshot)).unwrap();
        let text = std::fs::read_to_string(&file).unwrap();
        assert_eq!(text, "budget,step,min_return,mean_return,falls\n100000,95000,0.5,12.5,\n300000,290000,9,13,1\n");
        assert_eq!(read_selected(dir.path()).unwrap()[1].falls, Some(1));

        std::fs::write(&file, "budget,step\n").unwrap();
        let err = read_selected(dir.path()).unwrap_err().to_string();
        assert!(err.contains("selected.csv") && err.contains("falls"), "{err}");
        std::fs::write(&file, "budget,step,min_return,mean_return,falls\n300000,290000,9,13\n").unwrap();
        let err = read_selected(dir.path()).unwrap_err().to_string();
        assert!(err.contains("line 2"), "{err}");
    }
}
