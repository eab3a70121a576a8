//! The velocity-command tasks' numbers: the tracking grids `locobench track --out` wrote into
//! `benches/results/command/` (how each was made: that folder's README.md), and the probes of the
//! off-policy learners on the Minitaur (`benches/minitaur_probe_summary.py`).
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{ensure, Result};

use super::csv_rows::{read, Row};

/// Folder of the committed tracking grids.
pub(crate) const GRIDS_DIR: &str = "benches/results/command";

fn interval(r: &Row, column: &str, digits: usize) -> String {
    let (v, lo, hi) = (r.num(column), r.num(&format!("{column}_low")), r.num(&format!("{column}_high")));
    if v.is_nan() {
        "-".into()
    } else {
        format!("{v:.digits$} [{lo:.digits$}, {hi:.digits$}]")
    }
}

/// Every grid of `env` (files `<env>-*-grid.csv`), one table row per contender and command.
pub(crate) fn tracking(root: &Path, env: &str) -> Result<String> {
    let dir = root.join(GRIDS_DIR);
    let mut files: Vec<_> = std::fs::read_dir(&dir)?
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            name.starts_with(&format!("{env}-")) && name.ends_with("-grid.csv")
        })
        .collect();
    files.sort();
    ensure!(!files.is_empty(), "no {env}-*-grid.csv in {}", dir.display());
    let mut out = String::new();
    let names: Vec<String> =
        files.iter().map(|f| format!("{GRIDS_DIR}/{}", f.file_name().unwrap().to_string_lossy())).collect();
    let _ = writeln!(
        out,
        "From {} ({GRIDS_DIR}/README.md says how each was made). Errors are RMS after the first second of each \
         held-out episode, means over episodes with 95% bootstrap intervals; falls with Wilson intervals; the settle \
         time over the episodes that settled (how many in brackets).\n",
        names.join(", ")
    );
    out.push_str("| contender | speed m/s | yaw rate rad/s | speed RMS m/s | yaw-rate RMS rad/s | achieved m/s | falls | cost of transport | settle s |\n");
    out.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for file in &files {
        for r in read(file)? {
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {:.3} | {}/{} [{:.2}, {:.2}] | {} | {} ({}) |",
                r.text("contender"),
                r.text("speed"),
                r.text("yaw_rate"),
                interval(&r, "speed_rms", 3),
                interval(&r, "yaw_rate_rms", 3),
                r.num("achieved_speed"),
                r.count("falls"),
                r.count("episodes"),
                r.num("fall_rate_low"),
                r.num("fall_rate_high"),
                interval(&r, "cost_of_transport", 2),
                interval(&r, "settle_time", 2),
                r.count("settled"),
            );
        }
    }
    Ok(out)
}

/// The probes' table from `probes.csv` (`benches/minitaur_probe_summary.py`).
pub(crate) fn probes(root: &Path, csv: &str) -> Result<String> {
    let rows = read(&root.join(csv))?;
    let mut out = format!(
        "From {csv} (`benches/minitaur_probes.sh`, then `benches/minitaur_probe_summary.py`; the folder's NOTES.md \
         names the machine and commit). SAC on `minitaur`, one change each from the preset (seed 0; the warm-up probe also seeds 1 and 2); held-out: 50 \
         episodes, protocol seed 0, 95% bootstrap intervals.\n\n"
    );
    out.push_str(
        "| probe | seed | change | steps | held-out return | falls | final temperature | truncated episode ends | wall s |\n",
    );
    out.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let _ = writeln!(
            out,
            "| {} | {} | `{}` | {} | {:.3} [{:.3}, {:.3}] | {}/{} | {:.2e} | {}/{} | {:.0} |",
            r.text("probe"),
            r.text("seed"),
            r.text("change"),
            r.text("steps"),
            r.num("return"),
            r.num("return_low"),
            r.num("return_high"),
            r.count("falls"),
            r.count("episodes"),
            r.num("final_alpha"),
            r.count("truncated"),
            r.count("training_episodes"),
            r.num("wall_s"),
        );
    }
    Ok(out)
}
