//! The settings every computation with the networks runs under, in one place. Training, `eval`,
//! `record`, the report's rollouts and library callers get the same bits only if they compute
//! under the same settings, so each of them enters a [`Runtime`]:
//!
//! | setting | scope | why |
//! |---|---|---|
//! | `RAYON_NUM_THREADS`, `CANDLE_NUM_THREADS` = 1 unless set | process, before candle starts ([`configure_process`]) | candle's pools busy-wait; one thread is fastest at these sizes (`cargo bench --bench throughput`) |
//! | glibc keeps freed memory (`numeric::allocator`) | process | each update would page-fault its buffers again (~8% of a TD3 update) |
//! | flush-to-zero and denormals-are-zero (`numeric::denormals`) | calling thread | subnormal Adam moments take x86's slow path; results depend on the bit, so it must be on wherever the networks run |
//! | one helper thread (`numeric::second_core`), when `threads >= 2` | calling thread | splits large layers over two cores, same bits |
//! | the matrix-multiply kernel path (`numeric::kernel_path`, `LOCOBENCH_KERNELS`) | process, or one thread when forced | the exact paths give the same bits on every AVX2+FMA CPU; `library` does not |
//!
//! `train::train`, `train::resume`, `train::evaluate::evaluate` and `rollout::run_episode` enter
//! it themselves; a library caller running an agent some other way enters it around its work.
use crate::numeric::second_core::HelperGuard;

/// Process-wide settings; the CLI calls this first thing. Environment variables are only read
/// when candle starts its pools, and setting them is only sound while no other thread runs.
pub fn configure_process() {
    for var in ["RAYON_NUM_THREADS", "CANDLE_NUM_THREADS"] {
        if std::env::var_os(var).is_none() {
            std::env::set_var(var, "1");
        }
    }
    crate::numeric::allocator::keep_freed_memory();
}

/// The per-thread settings, held while the guard lives; dropping it restores the thread's float
/// mode and stops a helper it started. Entering inside an entered runtime changes nothing.
pub struct Runtime {
    float_mode: u32,
    _helper: Option<HelperGuard>,
}

impl Runtime {
    /// `threads`: 2 gives the calling thread a helper on the second core, 0 or 1 none.
    pub fn enter(threads: usize) -> Runtime {
        crate::numeric::allocator::keep_freed_memory();
        let float_mode = crate::numeric::denormals::float_mode();
        crate::numeric::denormals::flush_denormals_to_zero();
        Runtime { float_mode, _helper: (threads >= 2).then(HelperGuard::start) }
    }
}

impl Drop for Runtime {
    fn drop(&mut self) {
        crate::numeric::denormals::set_float_mode(self.float_mode);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fresh_thread_computes_like_the_cli_inside_the_runtime_and_is_restored_after() {
        std::thread::spawn(|| {
            let tiny = || std::hint::black_box(f32::MIN_POSITIVE) / 4.0;
            assert!(tiny() > 0.0, "a fresh thread keeps subnormals");
            {
                let _rt = Runtime::enter(1);
                #[cfg(target_arch = "x86_64")]
                assert_eq!(tiny(), 0.0);
                let _nested = Runtime::enter(1);
            }
            assert!(tiny() > 0.0, "leaving the runtime restores the thread's mode");
        })
        .join()
        .unwrap();
    }
}
