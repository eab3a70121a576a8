//! The list of committed runs, from the run directories themselves.
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;

use locobench::report::budgets::{reached, shipped_step};
use locobench::report::format::budget;
use locobench::report::runs::find_runs;
use locobench::train::{budget_policy_steps, provenance};

/// Every run directory under `dirs` (relative to `root`): where, what, how far, which policies.
pub fn list(root: &Path, dirs: &[&str]) -> Result<String> {
    let paths: Vec<PathBuf> = dirs.iter().map(|d| root.join(d)).collect();
    let mut runs = find_runs(&paths)?;
    runs.sort_by(|a, b| a.dir.cmp(&b.dir));
    let mut out = String::from(
        "| run | env | algo | seed | steps | settings | policies kept | machine |\n|---|---|---|---|---|---|---|---|\n",
    );
    for run in &runs {
        let mut policies: Vec<u64> = budget_policy_steps(&run.dir);
        policies.extend(shipped_step(&run.dir));
        let policies = if policies.is_empty() {
            "–".to_string()
        } else {
            policies.iter().map(|&s| budget(s)).collect::<Vec<_>>().join(", ")
        };
        let machines: BTreeSet<String> = provenance::read(&run.dir)
            .unwrap_or_default()
            .iter()
            .map(|s| format!("{} ({})", s.cpu_model, s.simd))
            .collect();
        let machines = if machines.is_empty() {
            "not recorded".to_string()
        } else {
            machines.into_iter().collect::<Vec<_>>().join("; ")
        };
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} | {policies} | {machines} |",
            run.dir.strip_prefix(root).unwrap_or(&run.dir).display(),
            run.env(),
            run.algo(),
            run.config.seed,
            budget(reached(run)),
            run.group().description(),
        );
    }
    Ok(out)
}
