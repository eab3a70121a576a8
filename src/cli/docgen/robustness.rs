//! docs/robustness.md's numbers, from the newest dated directory holding a robustness suite
//! (`cargo bench --bench robustness`): how it was run, who survives the largest perturbation of
//! each axis at 90%, and the goal check of each policy.
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;

use super::benchmarks::{newest, source, undated};
use locobench::report::robustness::{goal_lines, provenance, summary_table, SuiteData};

/// The newest suite of `env` as Markdown: Minitaur's sits in the dated directory itself, another
/// env's in a folder named after it (`cargo bench --bench robustness` writes them so).
pub(crate) fn summary(results: &Path, env: &str) -> Result<String> {
    let file = locobench::evaluation::robustness::output::CSV_FILE;
    let csv = if env == "minitaur" { newest(results, file)? } else { newest(results, &format!("{env}/{file}"))? };
    let suite = SuiteData::read(csv.parent().expect("a file in a directory"))?;
    let from = if env == "minitaur" {
        source(&csv)
    } else {
        format!("the newest benches/results/<date>-<machine>/{env}/{file}")
    };
    let mut out = format!("From {from}. {}\n\n", undated(&provenance(&suite)));
    let (header, rows) = summary_table(&suite);
    let _ = writeln!(out, "| {} |\n|{}", header.join(" | "), "---|".repeat(header.len()));
    for row in rows {
        let _ = writeln!(out, "| {} |", row.join(" | "));
    }
    let goal = goal_lines(&suite);
    if !goal.is_empty() {
        out.push_str("\nThe goal (more return than the controller at its best speed, no more falls, at least its 90% level on every axis):\n\n");
        for line in goal {
            let _ = writeln!(out, "- {line}");
        }
    }
    Ok(out)
}
