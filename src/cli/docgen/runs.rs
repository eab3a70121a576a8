//! The list of committed runs, from the run directories themselves.
use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;

use locobench::report::budgets::{reached, shipped_step};
use locobench::report::format::budget;
use locobench::report::runs::{find_runs, Run};
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
            settings(run),
        );
    }
    Ok(out)
}

/// The run's group description, and for a run that started from another's weights
/// (`train --init-from`), which run and step it started from.
fn settings(run: &Run) -> String {
    let description = run.group().description();
    match &run.config.init_from {
        None => description,
        Some(from) => format!("{description}; started from {}", started_from(from)),
    }
}

/// `benches/results/ant/crossq-256-seed0/policies/step-300000.safetensors` reads
/// `` `ant/crossq-256-seed0` at 300k ``; a path of another shape is quoted as it is.
fn started_from(path: &str) -> String {
    let shortened = path.strip_prefix("benches/results/").unwrap_or(path);
    let step = shortened
        .rsplit_once("/policies/step-")
        .and_then(|(run, file)| Some((run, file.strip_suffix(".safetensors")?.parse::<u64>().ok()?)));
    match step {
        Some((run, step)) => format!("`{run}` at {}", budget(step)),
        None => format!("`{shortened}`"),
    }
}

#[cfg(test)]
mod tests {
    use super::started_from;

    #[test]
    fn a_fine_tune_names_the_run_and_step_it_started_from() {
        assert_eq!(
            started_from("benches/results/ant/crossq-256-seed0/policies/step-300000.safetensors"),
            "`ant/crossq-256-seed0` at 300k"
        );
        assert_eq!(started_from("/tmp/runs/x/checkpoints/step_000001000"), "`/tmp/runs/x/checkpoints/step_000001000`");
    }
}
