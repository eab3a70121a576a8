//! The numeric engine under the agents: the dense layer, the fused stack of dense layers the
//! off-policy agents train through, the matrix-multiply kernels they run on, glibc's
//! `expf`, `logf` and `tanhf` in vectorised form ([`glibc_math`]), the in-place optimiser and
//! target-network steps, and the settings every network computation runs under (flush-to-zero,
//! the helper thread, the allocator).
//!
//! Results are the same bits on every x86-64 CPU with AVX2 and FMA, with or without AVX-512, for
//! a fixed seed and thread count: the matrix products follow one order of operations on every
//! [`kernel_path::KernelPath`] (see [`matmul`]); the elementwise loops ([`wide`], and
//! [`glibc_math`]'s) use only operations IEEE 754 rounds one at a time, so their vector width
//! does not change a bit; and everything else here is plain Rust compiled for the baseline x86-64
//! target.
pub(crate) mod allocator;
pub mod batch_renorm;
pub(crate) mod denormals;
pub mod dense;
pub mod glibc_math;
pub(crate) mod inplace;
pub mod kernel_path;
pub mod layer_norm;
pub mod matmul;
pub mod optim;
pub mod second_core;
pub mod stack;
pub(crate) mod wide;

pub use kernel_path::KernelPath;
