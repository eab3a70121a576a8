//! Which matrix-multiply kernels the networks run on, and the switch that forces one.
//!
//! The three exact paths ([`KernelPath::Avx512`], [`KernelPath::Avx2`], [`KernelPath::Portable`])
//! compute every output element with the same sequence of fused multiply-adds, so they give the
//! same bits; they differ only in how many elements they compute at once. [`KernelPath::Library`]
//! is the `gemm` crate candle uses: often faster, but it picks its kernels and its blocking from
//! the CPU it finds, so its results differ between AVX2 and AVX-512 machines.
//!
//! The default (`auto`) is the widest exact path the CPU has. `LOCOBENCH_KERNELS=avx512|avx2|
//! portable|library|auto` forces one for the whole process; [`force_on_this_thread`] does it for
//! one thread (tests, benchmarks).
use std::cell::Cell;
use std::fmt;
use std::sync::OnceLock;

/// The environment variable that forces a path.
pub(crate) const ENV_VAR: &str = "LOCOBENCH_KERNELS";

/// A family of matrix-multiply kernels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum KernelPath {
    /// 16 lanes with AVX-512F and FMA.
    Avx512,
    /// 8 lanes with AVX2 and FMA.
    Avx2,
    /// One element at a time with `f32::mul_add` (a correctly rounded fused multiply-add on
    /// every CPU; in software, and slow, on CPUs without FMA).
    Portable,
    /// The `gemm` crate; not the same bits on every CPU.
    Library,
}

impl KernelPath {
    /// Every path, exact ones first.
    pub const ALL: [KernelPath; 4] = [KernelPath::Avx512, KernelPath::Avx2, KernelPath::Portable, KernelPath::Library];

    /// The name the switch takes.
    pub fn name(self) -> &'static str {
        match self {
            KernelPath::Avx512 => "avx512",
            KernelPath::Avx2 => "avx2",
            KernelPath::Portable => "portable",
            KernelPath::Library => "library",
        }
    }

    /// Whether this path gives the same bits on every CPU that can run it.
    pub fn is_exact(self) -> bool {
        self != KernelPath::Library
    }

    /// Whether this CPU can run the path.
    pub fn is_supported(self) -> bool {
        match self {
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx512 => is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("fma"),
            #[cfg(target_arch = "x86_64")]
            KernelPath::Avx2 => is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"),
            #[cfg(not(target_arch = "x86_64"))]
            KernelPath::Avx512 | KernelPath::Avx2 => false,
            KernelPath::Portable | KernelPath::Library => true,
        }
    }

    /// The widest exact path this CPU supports.
    pub fn best_exact() -> KernelPath {
        [KernelPath::Avx512, KernelPath::Avx2].into_iter().find(|p| p.is_supported()).unwrap_or(KernelPath::Portable)
    }

    /// Parses a value of the switch: a path name, or `auto` for [`KernelPath::best_exact`].
    /// A path this CPU cannot run is an error, not a silent fallback.
    pub fn parse(value: &str) -> Result<KernelPath, KernelPathError> {
        let path = match value.trim().to_ascii_lowercase().as_str() {
            "" | "auto" => return Ok(KernelPath::best_exact()),
            "avx512" => KernelPath::Avx512,
            "avx2" => KernelPath::Avx2,
            "portable" => KernelPath::Portable,
            "library" => KernelPath::Library,
            _ => return Err(KernelPathError::Unknown(value.to_string())),
        };
        if path.is_supported() {
            Ok(path)
        } else {
            Err(KernelPathError::Unsupported(path))
        }
    }
}

impl fmt::Display for KernelPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A bad value of the switch.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KernelPathError {
    /// Not one of the path names.
    #[error("{ENV_VAR}={0:?} is not a kernel path (auto, avx512, avx2, portable or library)")]
    Unknown(String),
    /// A path the CPU cannot run.
    #[error("{ENV_VAR}={0} needs CPU features this machine lacks (it has: {best})", best = KernelPath::best_exact())]
    Unsupported(KernelPath),
}

static PROCESS: OnceLock<Result<KernelPath, KernelPathError>> = OnceLock::new();

thread_local! {
    static FORCED: Cell<Option<KernelPath>> = const { Cell::new(None) };
}

/// The process's path, from `LOCOBENCH_KERNELS` (read once). The CLI calls this at start so that
/// a bad value is an error before any work.
pub fn process_path() -> Result<KernelPath, KernelPathError> {
    PROCESS.get_or_init(|| KernelPath::parse(&std::env::var(ENV_VAR).unwrap_or_default())).clone()
}

/// The path the calling thread computes on: its forced path, or the process's.
///
/// # Panics
/// When `LOCOBENCH_KERNELS` holds a bad value; [`process_path`] reports it as an error first.
pub fn active() -> KernelPath {
    FORCED.with(|f| f.get()).unwrap_or_else(|| process_path().unwrap_or_else(|e| panic!("{e}")))
}

/// Forces `path` on the calling thread until the guard drops (the previous setting returns).
pub fn force_on_this_thread(path: KernelPath) -> Result<ForcedPath, KernelPathError> {
    if !path.is_supported() {
        return Err(KernelPathError::Unsupported(path));
    }
    let previous = FORCED.with(|f| f.replace(Some(path)));
    Ok(ForcedPath { previous })
}

/// Restores the thread's previous path when dropped.
pub struct ForcedPath {
    previous: Option<KernelPath>,
}

impl Drop for ForcedPath {
    fn drop(&mut self) {
        FORCED.with(|f| f.set(self.previous));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_bad_values_are_clear_errors() {
        for p in KernelPath::ALL.into_iter().filter(|p| p.is_supported()) {
            assert_eq!(KernelPath::parse(p.name()).unwrap(), p);
        }
        assert_eq!(KernelPath::parse("auto").unwrap(), KernelPath::best_exact());
        assert_eq!(
            KernelPath::parse(" AVX2 ").map(|p| p.name()).ok(),
            KernelPath::Avx2.is_supported().then_some("avx2")
        );
        let err = KernelPath::parse("sse9").unwrap_err().to_string();
        assert!(err.contains("LOCOBENCH_KERNELS") && err.contains("sse9") && err.contains("avx2"), "{err}");
        assert!(KernelPath::best_exact().is_exact() && !KernelPath::Library.is_exact());
    }

    #[test]
    fn forcing_is_per_thread_and_undone_by_the_guard() {
        let before = active();
        {
            let _g = force_on_this_thread(KernelPath::Portable).unwrap();
            assert_eq!(active(), KernelPath::Portable);
            std::thread::spawn(move || assert_eq!(active(), before)).join().unwrap();
            {
                let _inner = force_on_this_thread(KernelPath::Library).unwrap();
                assert_eq!(active(), KernelPath::Library);
            }
            assert_eq!(active(), KernelPath::Portable);
        }
        assert_eq!(active(), before);
    }
}
