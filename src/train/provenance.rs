//! `provenance.csv` of a run directory: what computed each stretch of the run. One row per start
//! (`train`) and per `resume`, written before the stretch trains, so a run that was moved between
//! machines says which machine computed which steps. Run directories written before this file
//! existed simply lack it.
//!
//! Which of these change a run's numbers is documented in `docs/` (reproducibility): the kernel
//! path only as `library`, the CPU only without FMA, the commit and MuJoCo version always may.
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::io::write_bytes_atomic;
use crate::numeric::kernel_path;

/// The file's name in a run directory.
pub const FILE: &str = "provenance.csv";

/// One stretch of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stretch {
    /// The step the stretch starts from (0 for a new run).
    pub from_step: u64,
    pub git_commit: String,
    pub crate_version: String,
    /// `model name` from /proc/cpuinfo.
    pub cpu_model: String,
    /// The widest vector instructions the CPU has: avx512, avx2 (with FMA), or baseline.
    pub simd: String,
    /// The matrix-multiply kernels the networks ran on (`numeric::kernel_path`).
    pub kernel_path: String,
    /// 1 or 2 (a helper thread).
    pub threads: usize,
    /// MuJoCo's library version, as `mj_version` reports it (222 for 2.2.2).
    pub mujoco_version: i32,
}

impl Stretch {
    /// This process, now, starting at `from_step`.
    pub fn here(from_step: u64, threads: usize, git_commit: Option<&str>) -> Stretch {
        Stretch {
            from_step,
            git_commit: git_commit.unwrap_or("unknown").to_string(),
            crate_version: env!("CARGO_PKG_VERSION").to_string(),
            cpu_model: cpu_model(),
            simd: simd_level().to_string(),
            kernel_path: kernel_path::active().to_string(),
            threads: threads.max(1),
            mujoco_version: crate::mujoco::version(),
        }
    }
}

/// The CPU's model name, or "unknown".
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|text| {
            text.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, name)| name.trim().to_string())
        })
        .unwrap_or_else(|| "unknown".into())
}

/// avx512, avx2 or baseline: which of the exact kernel paths the CPU can run at its widest.
pub fn simd_level() -> &'static str {
    match kernel_path::KernelPath::best_exact() {
        kernel_path::KernelPath::Avx512 => "avx512",
        kernel_path::KernelPath::Avx2 => "avx2",
        _ => "baseline",
    }
}

/// The stretches recorded in `run_dir` (none for older run directories).
pub fn read(run_dir: &Path) -> Result<Vec<Stretch>> {
    let path = run_dir.join(FILE);
    if !path.exists() {
        return Ok(Vec::new());
    }
    let mut reader = csv::Reader::from_path(&path).with_context(|| format!("reading {}", path.display()))?;
    reader
        .deserialize()
        .enumerate()
        .map(|(i, row)| row.with_context(|| format!("{}: row {} is not a provenance row", path.display(), i + 1)))
        .collect()
}

/// Adds `stretch` to `run_dir`'s file, dropping rows that start at or after it (a resume from an
/// earlier checkpoint recomputes those steps). Written atomically.
pub fn append(run_dir: &Path, stretch: Stretch) -> Result<()> {
    let mut rows: Vec<Stretch> = read(run_dir)?.into_iter().filter(|r| r.from_step < stretch.from_step).collect();
    rows.push(stretch);
    let mut writer = csv::Writer::from_writer(Vec::new());
    for row in &rows {
        writer.serialize(row)?;
    }
    write_bytes_atomic(&run_dir.join(FILE), &writer.into_inner()?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretches_append_replace_later_ones_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        assert!(read(dir.path()).unwrap().is_empty(), "older run directories have no file");
        let first = Stretch::here(0, 2, Some("abc"));
        assert!(["avx512", "avx2", "baseline"].contains(&first.simd.as_str()));
        assert_eq!((first.threads, first.mujoco_version), (2, crate::mujoco::version()));
        append(dir.path(), first.clone()).unwrap();
        append(dir.path(), Stretch { from_step: 5000, ..Stretch::here(5000, 1, None) }).unwrap();
        append(dir.path(), Stretch::here(3000, 1, None)).unwrap();
        let rows = read(dir.path()).unwrap();
        assert_eq!(rows.iter().map(|r| r.from_step).collect::<Vec<_>>(), [0, 3000]);
        assert_eq!(rows[0], first);
        assert_eq!(rows[1].git_commit, "unknown");
        std::fs::write(dir.path().join(FILE), "from_step,git_commit\nnot-a-number,x\n").unwrap();
        let err = format!("{:#}", read(dir.path()).unwrap_err());
        assert!(err.contains(FILE) && err.contains("row 1"), "{err}");
    }
}
