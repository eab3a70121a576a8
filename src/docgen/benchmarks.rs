//! Sections quoting the newest speed and memory measurements (`bash benches/speed.sh`).
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::csv_rows::{comments, read};
use crate::report::format::fixed;

/// The newest `benches/results/<date>-<machine>/<file>`: directories sort by their date prefix.
fn newest(results: &Path, file: &str) -> Result<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(results)
        .with_context(|| format!("reading {}", results.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.join(file).is_file())
        .collect();
    dirs.sort();
    match dirs.pop() {
        Some(d) => Ok(d.join(file)),
        None => bail!("no {file} under {}: run bash benches/speed.sh", results.display()),
    }
}

fn duration(ns: f64) -> String {
    match ns {
        n if n >= 1e6 => format!("{:.2} ms", n / 1e6),
        n if n >= 1e3 => format!("{:.2} µs", n / 1e3),
        n => format!("{n:.0} ns"),
    }
}

/// How a generated section names its source: the newest file of that name in the dated result
/// directories (the file's own comment line names machine and commit).
fn source(path: &Path) -> String {
    let file = path.file_name().map_or(String::new(), |f| f.to_string_lossy().to_string());
    format!("the newest benches/results/<date>-<machine>/{file}")
}

/// Every criterion measurement of the newest `speed.csv`, one table per group.
pub fn speed(results: &Path) -> Result<String> {
    let path = newest(results, "speed.csv")?;
    let rows = read(&path)?;
    let mut out = format!("From {} ({}).\n", source(&path), comments(&path)?.join("; "));
    let mut group = String::new();
    for r in &rows {
        if r.text("group") != group {
            group = r.text("group").to_string();
            let _ = write!(out, "\n`{group}`:\n\n| benchmark | mean time | 95% CI |\n|---|---|---|\n");
        }
        let _ = writeln!(
            out,
            "| {} | {} | {} – {} |",
            r.text("benchmark"),
            duration(r.num("mean_ns")),
            duration(r.num("low_ns")),
            duration(r.num("high_ns"))
        );
    }
    Ok(out)
}

/// The newest `memory-bench.md`, as the memory bench printed it.
pub fn memory(results: &Path) -> Result<String> {
    let path = newest(results, "memory-bench.md")?;
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    Ok(format!("From {}: {}", source(&path), text.trim()))
}

/// The newest `python-speed.csv` (`python python/bench_speed.py`).
pub(crate) fn python_speed(results: &Path) -> Result<String> {
    let path = newest(results, "python-speed.csv")?;
    let rows = read(&path)?;
    let mut out = format!(
        "From {} ({}).\n\n| env | locobench through Gymnasium (steps/s) | raw binding (steps/s) | looped in Rust (steps/s) | binding overhead per step | Gymnasium's own env (steps/s) |\n|---|---|---|---|---|---|\n",
        source(&path),
        comments(&path)?.join("; ")
    );
    for r in &rows {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {:.1} µs | {} |",
            r.text("env"),
            fixed(r.num("locobench_gym_steps_per_s"), 0),
            fixed(r.num("locobench_raw_steps_per_s"), 0),
            fixed(r.num("locobench_rust_steps_per_s"), 0),
            r.num("binding_overhead_us"),
            fixed(r.num("gymnasium_steps_per_s"), 0),
        );
    }
    Ok(out)
}
