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
    /// The commit the binary was built from.
    pub git_commit: String,
    /// The crate's version.
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
    /// Where the networks trained: `cpu` (the fused path) or `cuda:N` (the device-generic path).
    /// Files written before this column existed read as `cpu`.
    #[serde(default = "cpu_device")]
    pub device: String,
}

fn cpu_device() -> String {
    "cpu".into()
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
            device: cpu_device(),
        }
    }

    /// The same stretch, trained on `device`.
    pub fn on(self, device: crate::device::ComputeDevice) -> Stretch {
        Stretch { device: device.to_string(), ..self }
    }
}

/// The CPU's model name, or "unknown".
pub(crate) fn cpu_model() -> String {
    cpuinfo_field("model name").unwrap_or_else(|| "unknown".into())
}

/// A field of /proc/cpuinfo's first processor, trimmed.
fn cpuinfo_field(field: &str) -> Option<String> {
    let text = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let (_, value) = text.lines().filter_map(|l| l.split_once(':')).find(|(key, _)| key.trim() == field)?;
    Some(value.trim().to_string())
}

/// The machine as a directory name for dated results: its CPU model's words in lower case, an
/// AMD core's generation when the model name hides it (a VM's "AMD EPYC"), and its SIMD level,
/// e.g. `amd-epyc-7b13-avx2` or `amd-epyc-zen3-avx2`.
pub fn machine_slug() -> String {
    let model = cpu_model().to_lowercase();
    let mut words: Vec<&str> = model
        .split(|c: char| !c.is_ascii_alphanumeric())
        .filter(|w| !w.is_empty() && !matches!(*w, "processor" | "core" | "cpu" | "with" | "radeon" | "graphics"))
        .collect();
    let number = |field| cpuinfo_field(field).and_then(|v| v.parse().ok());
    let generation = number("cpu family").zip(number("model")).and_then(|(f, m)| amd_generation(f, m));
    if let Some(g) = generation.filter(|_| model.contains("amd") && !words.iter().any(|w| w.contains("zen"))) {
        words.push(g);
    }
    format!("{}-{}", words.join("-"), simd_level())
}

/// The Zen generation of an AMD CPU family and model, by the ranges Linux assigns them
/// (torvalds/linux, `arch/x86/kernel/cpu/amd.c`, `bsp_init_amd`).
fn amd_generation(family: u32, model: u32) -> Option<&'static str> {
    match (family, model) {
        (0x17, 0x30..=0x4f | 0x60..=0x7f | 0x84..=0x87 | 0x90..=0x91 | 0xa0..=0xaf) => Some("zen2"),
        (0x17, _) => Some("zen"),
        (0x19, 0x00..=0x0f | 0x20..=0x5f) => Some("zen3"),
        (0x19, 0x10..=0x1f | 0x60..=0xaf) => Some("zen4"),
        (0x1a, _) => Some("zen5"),
        _ => None,
    }
}

/// avx512, avx2 or baseline: which of the exact kernel paths the CPU can run at its widest.
pub(crate) fn simd_level() -> &'static str {
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
/// earlier checkpoint recomputes those steps). A stretch computed as the one before it was (same
/// commit, CPU, kernels, threads and MuJoCo) continues that row instead of adding one, so a run
/// resumed where it ran writes the file an unbroken run writes. Written atomically.
pub(crate) fn append(run_dir: &Path, stretch: Stretch) -> Result<()> {
    let mut rows: Vec<Stretch> = read(run_dir)?.into_iter().filter(|r| r.from_step < stretch.from_step).collect();
    let continues = |last: &Stretch| Stretch { from_step: stretch.from_step, ..last.clone() } == stretch;
    if rows.last().is_some_and(continues) {
        // Rewritten all the same: rows from a stretch that a resume recomputes are gone.
    } else {
        rows.push(stretch);
    }
    let mut writer = csv::Writer::from_writer(Vec::new());
    for row in &rows {
        writer.serialize(row)?;
    }
    write_bytes_atomic(&run_dir.join(FILE), &writer.into_inner()?)
}

/// Why resuming a run whose last stretch is `last` here (`here`) will not continue it bit for bit,
/// if it will not. `last` is None for a run directory written before this file existed.
pub(crate) fn resume_caveat(last: Option<&Stretch>, here: &Stretch) -> Option<String> {
    let Some(last) = last else {
        return Some(
            "this run predates provenance.csv: it ran on the gemm crate's kernels, so continuing it on the exact ones \
             (the default) will not match an uninterrupted run bit for bit; LOCOBENCH_KERNELS=library on the kind of \
             CPU that wrote it would"
                .into(),
        );
    };
    let exact = |s: &Stretch| s.kernel_path != "library";
    let why = if last.device != here.device {
        format!(
            "its last stretch trained on {}, this one on {}, and the fused CPU path and the device-generic path \
             round differently (the run continues from the same weights, optimiser state and counters)",
            last.device, here.device
        )
    } else if exact(last) != exact(here) {
        format!("its last stretch ran on the {} kernels, this one on {}", last.kernel_path, here.kernel_path)
    } else if !exact(here) && (last.cpu_model != here.cpu_model || last.simd != here.simd) {
        format!(
            "the gemm crate's kernels depend on the CPU, and its last stretch ran on {} ({}), this one on {} ({})",
            last.cpu_model, last.simd, here.cpu_model, here.simd
        )
    } else if (last.simd == "baseline") != (here.simd == "baseline") {
        format!("one of the CPUs lacks FMA ({} then {}), and glibc rounds differently without it", last.simd, here.simd)
    } else if last.git_commit != here.git_commit {
        format!("its last stretch ran at commit {}, this one at {}", last.git_commit, here.git_commit)
    } else if last.mujoco_version != here.mujoco_version {
        format!("its last stretch ran on MuJoCo {}, this one on {}", last.mujoco_version, here.mujoco_version)
    } else {
        return None;
    };
    Some(format!("resuming will not match an uninterrupted run bit for bit: {why}"))
}

/// [`resume_caveat`] for `run_dir` resumed by this process with `threads`.
pub fn resume_caveat_for(
    run_dir: &Path,
    threads: usize,
    device: crate::device::ComputeDevice,
) -> Result<Option<String>> {
    let rows = read(run_dir)?;
    Ok(resume_caveat(rows.last(), &Stretch::here(0, threads, git_commit().as_deref()).on(device)))
}

/// A commit shortened to `n` hex digits for display, keeping a `-dirty` mark (built with
/// uncommitted changes to the source).
pub fn short_commit(commit: &str, n: usize) -> String {
    let (hash, dirty) = commit.strip_suffix("-dirty").map_or((commit, ""), |h| (h, "-dirty"));
    format!("{}{dirty}", &hash[..hash.len().min(n)])
}

/// The commit this binary was built from (build.rs), not whatever the source tree holds now.
pub(crate) fn git_commit() -> Option<String> {
    option_env!("LOCOBENCH_GIT_COMMIT").map(str::to_string)
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_short_commit_keeps_the_dirty_mark() {
        assert_eq!(super::short_commit("0123456789abcdef", 8), "01234567");
        assert_eq!(super::short_commit("0123456789abcdef-dirty", 12), "0123456789ab-dirty");
        assert_eq!(super::short_commit("unknown", 12), "unknown");
    }

    use super::*;

    #[test]
    fn amd_generations_follow_linuxs_family_and_model_ranges() {
        assert_eq!(amd_generation(25, 1), Some("zen3"), "EPYC 7003 (Milan)");
        assert_eq!(amd_generation(25, 0x11), Some("zen4"), "EPYC 9004 (Genoa)");
        assert_eq!(amd_generation(23, 0x31), Some("zen2"), "EPYC 7002 (Rome)");
        assert_eq!(amd_generation(26, 2), Some("zen5"));
        assert_eq!(amd_generation(6, 85), None, "an Intel family");
    }

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
        // Resumed where it ran, as it ran: the row continues, as if the run had never stopped.
        append(dir.path(), Stretch::here(4000, 1, None)).unwrap();
        assert_eq!(read(dir.path()).unwrap(), rows);
        std::fs::write(dir.path().join(FILE), "from_step,git_commit\nnot-a-number,x\n").unwrap();
        let err = format!("{:#}", read(dir.path()).unwrap_err());
        assert!(err.contains(FILE) && err.contains("row 1"), "{err}");
    }

    #[test]
    fn resuming_names_what_breaks_exactness_and_nothing_else() {
        let base = Stretch {
            from_step: 0,
            git_commit: "abc".into(),
            crate_version: "0.1.0".into(),
            cpu_model: "Intel Xeon".into(),
            simd: "avx512".into(),
            kernel_path: "avx512".into(),
            threads: 2,
            mujoco_version: 222,
            device: "cpu".into(),
        };
        let with = |f: &dyn Fn(&mut Stretch)| {
            let mut s = base.clone();
            f(&mut s);
            s
        };
        // Another CPU with AVX2, another exact path, another thread count: exact.
        let amd = with(&|s| {
            s.cpu_model = "AMD EPYC".into();
            s.simd = "avx2".into();
            s.kernel_path = "avx2".into();
            s.threads = 1;
        });
        assert_eq!(resume_caveat(Some(&base), &amd), None);
        let lib = with(&|s| s.kernel_path = "library".into());
        assert!(resume_caveat(Some(&base), &lib).unwrap().contains("avx512 kernels, this one on library"));
        let lib_amd = with(&|s| {
            s.kernel_path = "library".into();
            s.cpu_model = "AMD EPYC".into();
        });
        assert!(resume_caveat(Some(&lib), &lib_amd).unwrap().contains("depend on the CPU"));
        assert_eq!(resume_caveat(Some(&lib), &lib), None);
        let old_cpu = with(&|s| {
            s.simd = "baseline".into();
            s.kernel_path = "portable".into();
        });
        assert!(resume_caveat(Some(&base), &old_cpu).unwrap().contains("FMA"));
        assert!(resume_caveat(Some(&base), &with(&|s| s.git_commit = "def".into()))
            .unwrap()
            .contains("commit abc, this one at def"));
        assert!(resume_caveat(Some(&base), &with(&|s| s.mujoco_version = 300))
            .unwrap()
            .contains("MuJoCo 222, this one on 300"));
        assert!(resume_caveat(None, &base).unwrap().contains("predates"));
        let gpu = with(&|s| s.device = "cuda:0".into());
        assert!(resume_caveat(Some(&base), &gpu).unwrap().contains("trained on cpu, this one on cuda:0"));
        assert_eq!(resume_caveat(Some(&gpu), &gpu), None);
    }

    #[test]
    fn files_without_the_device_column_read_as_cpu() {
        let dir = tempfile::tempdir().unwrap();
        let header = "from_step,git_commit,crate_version,cpu_model,simd,kernel_path,threads,mujoco_version";
        std::fs::write(dir.path().join(FILE), format!("{header}\n0,abc,0.1.0,AMD,avx2,avx2,2,222\n")).unwrap();
        assert_eq!(read(dir.path()).unwrap()[0].device, "cpu");
    }
}
