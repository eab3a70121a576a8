//! Flush-to-zero and denormals-are-zero for the calling thread. Adam's second moments and the
//! gradients of nearly dead units drift into the subnormal range, where x86 arithmetic takes a
//! slow microcode path. PyTorch sets the same two bits (`torch.set_flush_denormal`). The
//! setting is deterministic, so a seed still reproduces a run; it must be on for the whole
//! run (training, and again after a resume) for results to match bit for bit.

/// Sets MXCSR's FTZ (bit 15) and DAZ (bit 6) on this thread. A no-op off x86-64.
pub fn flush_denormals_to_zero() {
    set_float_mode(float_mode() | (1 << 15) | (1 << 6));
}

/// This thread's SSE control register (MXCSR), 0 off x86-64.
pub fn float_mode() -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        let mut csr: u32 = 0;
        // SAFETY: reads this thread's SSE control register.
        unsafe { std::arch::asm!("stmxcsr [{}]", in(reg) &mut csr, options(nostack)) };
        csr
    }
    #[cfg(not(target_arch = "x86_64"))]
    0
}

/// Sets this thread's MXCSR to a value `float_mode` returned (on this or another thread). The
/// bits change how subnormal floats and rounding are treated, nothing else.
pub fn set_float_mode(_csr: u32) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: writes this thread's SSE control register with a value read from a control
    // register, so no reserved bit is set.
    unsafe {
        std::arch::asm!("ldmxcsr [{}]", in(reg) &_csr, options(nostack, readonly))
    };
}

#[cfg(test)]
mod tests {
    #[test]
    fn subnormals_become_zero_on_this_thread() {
        std::thread::spawn(|| {
            let tiny = std::hint::black_box(f32::MIN_POSITIVE);
            assert!(tiny / 4.0 > 0.0);
            super::flush_denormals_to_zero();
            let tiny = std::hint::black_box(f32::MIN_POSITIVE);
            #[cfg(target_arch = "x86_64")]
            assert_eq!(tiny / 4.0, 0.0);
        })
        .join()
        .unwrap();
    }
}
