//! Elementwise loops compiled for the kernel path's vector width.
//!
//! The crate is built for the baseline x86-64 target, so a plain loop vectorises to four SSE
//! lanes, and Adam's square root and division alone took about 3% of a SAC update. [`wide`] runs
//! a closure inside a function compiled with the path's CPU features, into which the closure is
//! inlined, so its loops vectorise to 16 (AVX-512) or 8 (AVX2) lanes.
//!
//! Only for elementwise arithmetic that IEEE 754 rounds operation by operation: add, multiply,
//! divide, square root, compare and select. Rust never fuses a multiply and an add unasked and
//! never reorders a sum, so every width computes each element with the same operations in the
//! same order: the same bits (the kernel-path training tests compare whole runs).
use super::kernel_path::KernelPath;

/// Runs `f` compiled for `path`'s vector width (the baseline target for the other paths).
#[inline(always)]
pub(crate) fn wide<R>(path: KernelPath, f: impl FnOnce() -> R) -> R {
    match path {
        // SAFETY: the CPU has the features (checked; a cached flag test).
        #[cfg(target_arch = "x86_64")]
        KernelPath::Avx512 if path.is_supported() => unsafe { avx512(f) },
        // SAFETY: as above.
        #[cfg(target_arch = "x86_64")]
        KernelPath::Avx2 if path.is_supported() => unsafe { avx2(f) },
        _ => f(),
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn avx512<R>(f: impl FnOnce() -> R) -> R {
    f()
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}
