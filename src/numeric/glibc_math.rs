//! `expf`, `logf` and `tanhf` as the GNU C library computes them (glibc 2.36, Debian 12, on CPUs
//! with FMA), bit for bit, in branch-free code that vectorises.
//!
//! Rust's `f32::exp`, `ln` and `tanh` call the system's libm one element at a time; in SAC's
//! policy head those calls took about a twentieth of a two-thread update. These functions follow the
//! same operations in the same order as glibc's code, so they return the same bits, and because
//! every lane does the same IEEE 754 operations they do so at any vector width:
//! - [`exp`]: glibc's `sysdeps/ieee754/flt-32/e_expf.c` (from Arm's optimized-routines), in
//!   double precision with a 32-entry table of 2^(i/32), as built for FMA CPUs
//!   (`sysdeps/x86_64/fpu/multiarch/e_expf-fma.c`): the compiler fused the reduction and the
//!   polynomial's multiply-adds, and so do we.
//! - [`ln`]: `e_logf.c` with its 16-entry table (`e_logf_data.c`), FMA build (`e_logf-fma.c`).
//! - [`tanh`]: `s_tanhf.c` and the `s_expm1f.c` it calls (Sun's fdlibm), single precision and no
//!   fused operations; glibc 2.36 has one build of it for every CPU.
//!
//! On a CPU without FMA glibc runs the plain builds of `expf` and `logf`, which can differ in the
//! last bit; these functions do not change with the CPU (`f64::mul_add` is exact everywhere, in
//! software where there is no FMA). A different glibc (2.41 replaced `tanhf`) or another libm may
//! differ from them: the tests compare against the system's libm and say so when they fail.
//! The exceptions glibc raises (errno, inexact) are not reproduced; the values are.
use super::kernel_path::KernelPath;

// ---- expf ----

/// 2^(i/32) minus i << 47, as glibc stores it (`__exp2f_data.tab`), so that adding k << 47 for
/// k = 32 e + i gives 2^(e + i/32).
const EXP_TABLE: [u64; 32] = [
    0x3ff0000000000000,
    0x3fefd9b0d3158574,
    0x3fefb5586cf9890f,
    0x3fef9301d0125b51,
    0x3fef72b83c7d517b,
    0x3fef54873168b9aa,
    0x3fef387a6e756238,
    0x3fef1e9df51fdee1,
    0x3fef06fe0a31b715,
    0x3feef1a7373aa9cb,
    0x3feedea64c123422,
    0x3feece086061892d,
    0x3feebfdad5362a27,
    0x3feeb42b569d4f82,
    0x3feeab07dd485429,
    0x3feea47eb03a5585,
    0x3feea09e667f3bcd,
    0x3fee9f75e8ec5f74,
    0x3feea11473eb0187,
    0x3feea589994cce13,
    0x3feeace5422aa0db,
    0x3feeb737b0cdc5e5,
    0x3feec49182a3f090,
    0x3feed503b23e255d,
    0x3feee89f995ad3ad,
    0x3feeff76f2fb5e47,
    0x3fef199bdd85529c,
    0x3fef3720dcef9069,
    0x3fef5818dcfba487,
    0x3fef7c97337b9b5f,
    0x3fefa4afa2a490da,
    0x3fefd0765b6e4540,
];
/// 32 / ln 2.
const EXP_INV_LN2_N: f64 = f64::from_bits(0x40471547652b82fe);
/// 1.5 * 2^52: adding it rounds to an integer held in the low bits.
const EXP_SHIFT: f64 = f64::from_bits(0x4338000000000000);
/// The polynomial for 2^(r/32), highest power first (`poly_scaled`).
const EXP_POLY: [f64; 3] =
    [f64::from_bits(0x3ebc6af84b912394), f64::from_bits(0x3f2ebfce50fac4f3), f64::from_bits(0x3f962e42ff0c52d6)];

/// glibc's `expf` (FMA build).
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    let xd = x as f64;
    let kd_shifted = EXP_INV_LN2_N.mul_add(xd, EXP_SHIFT);
    let ki = kd_shifted.to_bits();
    let kd = kd_shifted - EXP_SHIFT;
    let r = EXP_INV_LN2_N.mul_add(xd, -kd);
    let t = EXP_TABLE[(ki & 31) as usize].wrapping_add(ki << 47);
    let s = f64::from_bits(t);
    let z = EXP_POLY[0].mul_add(r, EXP_POLY[1]);
    let r2 = r * r;
    let y = r.mul_add(EXP_POLY[2], 1.0);
    let y = z.mul_add(r2, y);
    let main = (y * s) as f32;

    // |x| >= 88 or not a number
    let bits = x.to_bits();
    if (bits >> 20) & 0x7ff <= 0x42a {
        return main;
    }
    if bits == 0xff80_0000 {
        0.0
    } else if (bits >> 20) & 0x7ff > 0x7f7 {
        x + x
    } else if x > f32::from_bits(0x42b1_7217) {
        f32::INFINITY
    } else if x < f32::from_bits(0xc2cf_f1b4) {
        // below log(2^-150): glibc returns 2^-95 * 2^-95. Between log(2^-150) and log(2^-149)
        // it returns 1.25 * 2^-75 squared, the smallest subnormal (zero when subnormals
        // flush), which is what the main path rounds to there.
        f32::from_bits(0x1000_0000) * f32::from_bits(0x1000_0000)
    } else {
        main
    }
}

// ---- logf ----

/// 1/c and log(c) for the 16 subintervals of [0x3f330000, 2 * 0x3f330000) (`__logf_data.tab`).
const LOG_TABLE: [(u64, u64); 16] = [
    (0x3ff661ec79f8f3be, 0xbfd57bf7808caade),
    (0x3ff571ed4aaf883d, 0xbfd2bef0a7c06ddb),
    (0x3ff49539f0f010b0, 0xbfd01eae7f513a67),
    (0x3ff3c995b0b80385, 0xbfcb31d8a68224e9),
    (0x3ff30d190c8864a5, 0xbfc6574f0ac07758),
    (0x3ff25e227b0b8ea0, 0xbfc1aa2bc79c8100),
    (0x3ff1bb4a4a1a343f, 0xbfba4e76ce8c0e5e),
    (0x3ff12358f08ae5ba, 0xbfb1973c5a611ccc),
    (0x3ff0953f419900a7, 0xbfa252f438e10c1e),
    (0x3ff0000000000000, 0x0000000000000000),
    (0x3fee608cfd9a47ac, 0x3faaa5aa5df25984),
    (0x3feca4b31f026aa0, 0x3fbc5e53aa362eb4),
    (0x3feb2036576afce6, 0x3fc526e57720db08),
    (0x3fe9c2d163a1aa2d, 0x3fcbc2860d224770),
    (0x3fe886e6037841ed, 0x3fd1058bc8a07ee1),
    (0x3fe767dcf5534862, 0x3fd4043057b6ee09),
];
const LN2: f64 = f64::from_bits(0x3fe62e42fefa39ef);
/// The polynomial for log1p(r): A0 r^2 (A1 r + A2) + ... (`__logf_data.poly`).
const LOG_POLY: [f64; 3] =
    [f64::from_bits(0xbfd00ea348b88334), f64::from_bits(0x3fd5575b0be00b6a), f64::from_bits(0xbfdffffef20a4123)];

/// glibc's `logf` (FMA build).
#[inline(always)]
pub fn ln(x: f32) -> f32 {
    let bits = x.to_bits();
    // subnormal: scaled into the normal range, its exponent taken back below
    let normal = bits.wrapping_sub(0x0080_0000) <= 0x7eff_ffff;
    let scaled = (x * f32::from_bits(0x4b00_0000)).to_bits().wrapping_sub(23 << 23);
    let ix = if normal { bits } else { scaled };

    let tmp = ix.wrapping_sub(0x3f33_0000);
    let (invc, logc) = LOG_TABLE[((tmp >> 19) & 15) as usize];
    let (invc, logc) = (f64::from_bits(invc), f64::from_bits(logc));
    let k = (tmp as i32) >> 23;
    let iz = ix.wrapping_sub(tmp & 0xff80_0000);
    let z = f32::from_bits(iz) as f64;
    let r = z.mul_add(invc, -1.0);
    let y0 = (k as f64).mul_add(LN2, logc);
    let y = r.mul_add(LOG_POLY[1], LOG_POLY[2]);
    let r2 = r * r;
    let y = r2.mul_add(LOG_POLY[0], y);
    let main = r2.mul_add(y, r + y0) as f32;

    let subnormal = bits != 0 && bits < 0x0080_0000;
    // Written without a test for zero: the compiler may turn an integer test for +-0 into a
    // float compare, which is also true for a subnormal when subnormals are treated as zero.
    if bits == 0x3f80_0000 {
        0.0
    } else if normal || subnormal {
        main
    } else if bits == 0x7f80_0000 {
        x
    } else if bits > 0x7f80_0000 && bits != 0x8000_0000 {
        // negative or not a number: glibc returns (x - x) / (x - x)
        #[allow(clippy::eq_op)]
        let nan = (x - x) / (x - x);
        nan
    } else {
        f32::NEG_INFINITY
    }
}

// ---- tanhf ----

const EXPM1_LN2_HI: f32 = f32::from_bits(0x3f31_7180);
const EXPM1_LN2_LO: f32 = f32::from_bits(0x3717_f7d1);
const EXPM1_INV_LN2: f32 = f32::from_bits(0x3fb8_aa3b);
/// Q1..Q5 of fdlibm's expm1f.
const EXPM1_Q: [f32; 5] = [
    f32::from_bits(0xbd08_8889),
    f32::from_bits(0x3ad0_0d01),
    f32::from_bits(0xb8a6_70cd),
    f32::from_bits(0x3686_7e54),
    f32::from_bits(0xb457_edbb),
];

/// fdlibm's `expm1f` for the arguments `tanhf` passes: 2|x| in [2, 44) and -2|x| in (-2, 0).
#[inline(always)]
fn expm1_for_tanh(x: f32) -> f32 {
    let hx = x.to_bits() & 0x7fff_ffff;
    let negative = x.to_bits() >> 31 != 0;
    let half = if negative { -0.5f32 } else { 0.5 };

    // argument reduction: x = k ln2 + hi - lo, and c the rounding error of hi - lo
    // |x| < 1.5 ln 2: k = +-1
    let near = hx < 0x3f85_1592;
    // k = (int) (x / ln 2 +- 1/2), truncated, as C converts. `as i32` would saturate, which the
    // compiler does one lane at a time; the arguments tanhf passes are far inside the range, and
    // any other (infinite or NaN, whose result is not used) is replaced first.
    let q = EXPM1_INV_LN2 * x + half;
    let q = if q.abs() < 1e9 { q } else { 0.0 };
    // SAFETY: q is finite and |q| < 1e9, so its truncation fits in an i32.
    let ki: i32 = unsafe { q.to_int_unchecked() };
    let kf = ki as f32;
    let (hi, lo, k) = if near {
        if negative {
            (x + EXPM1_LN2_HI, -EXPM1_LN2_LO, -1)
        } else {
            (x - EXPM1_LN2_HI, EXPM1_LN2_LO, 1)
        }
    } else {
        (x - kf * EXPM1_LN2_HI, kf * EXPM1_LN2_LO, ki)
    };
    let reduced = hx > 0x3eb1_7218; // |x| > ln2 / 2
    let (xr, c, k) = if reduced {
        let xr = hi - lo;
        (xr, (hi - xr) - lo, k)
    } else {
        (x, 0.0, 0)
    };

    let hfx = 0.5 * xr;
    let hxs = xr * hfx;
    let q = EXPM1_Q;
    let r1 = 1.0 + hxs * (q[0] + hxs * (q[1] + hxs * (q[2] + hxs * (q[3] + hxs * q[4]))));
    let t = 3.0 - r1 * hfx;
    let e = hxs * ((r1 - t) / (6.0 - xr * t));
    let unreduced = xr - (xr * e - hxs);

    let e = (xr * (e - c) - c) - hxs;
    let k_minus_one = 0.5 * (xr - e) - 0.5;
    let k_one = if xr < -0.25 { -2.0 * (e - (xr + 0.5)) } else { 1.0 + 2.0 * (xr - e) };
    let exponent = (k as u32) << 23;
    let with_k = |y: f32| f32::from_bits(y.to_bits().wrapping_add(exponent));
    // k <= -2 or k > 56
    let far = with_k(1.0 - (e - xr)) - 1.0;
    // 2 <= k <= 22: 1 - 2^-k + x - e
    let small_k = k.clamp(0, 31) as u32;
    let one_minus = f32::from_bits(0x3f80_0000 - (0x0100_0000 >> small_k));
    let mid = with_k(one_minus - (e - xr));
    // 23 <= k <= 56: x - (e + 2^-k) + 1
    let two_minus_k = f32::from_bits((0x7f_u32.wrapping_sub(k as u32)) << 23);
    let high = with_k((xr - (e + two_minus_k)) + 1.0);

    if hx < 0x3300_0000 {
        x // |x| < 2^-25
    } else if k == 0 {
        unreduced
    } else if k == -1 {
        k_minus_one
    } else if k == 1 {
        k_one
    } else if k <= -2 || k > 56 {
        far
    } else if k <= 22 {
        mid
    } else {
        high
    }
}

/// glibc's `tanhf` (fdlibm's, the same on every CPU).
#[inline(always)]
pub fn tanh(x: f32) -> f32 {
    let bits = x.to_bits();
    let ix = bits & 0x7fff_ffff;
    let a = f32::from_bits(ix);
    let big = ix >= 0x3f80_0000; // |x| >= 1
    let t = expm1_for_tanh(if big { a + a } else { a * -2.0 });
    // 1 - 2 / (t + 2) or -t / (t + 2), with one division
    let quotient = if big { 2.0 } else { -t } / (t + 2.0);
    let z = if big { 1.0 - quotient } else { quotient };
    let z = if ix > 0x41af_ffff { 1.0 - f32::from_bits(0x0da2_4260) } else { z }; // |x| >= 22
    let signed = f32::from_bits(z.to_bits() ^ (bits & 0x8000_0000));
    if ix > 0x7f7f_ffff {
        // infinite or not a number
        if bits >> 31 == 0 {
            1.0 / x + 1.0
        } else {
            1.0 / x - 1.0
        }
    } else if ix <= 0x23ff_ffff {
        // |x| < 2^-55, zero included: glibc returns a zero as it is, (1 + x) x does the same
        // (and a test for zero could become a float compare, true for subnormals under DAZ)
        (1.0 + x) * x
    } else {
        signed
    }
}

// ---- whole slices, at the path's vector width ----

/// `$name(path, xs)` sets `x = $f(x)` for every element, in a loop compiled for the path's
/// vector width. (Through `numeric::wide` the loop stayed in the baseline target: the compiler
/// did not inline a closure this large into the wide function.)
macro_rules! in_place {
    ($(#[$doc:meta])* $name:ident, $f:ident) => {
        $(#[$doc])*
        pub fn $name(path: KernelPath, xs: &mut [f32]) {
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx512f,fma")]
            fn avx512(xs: &mut [f32]) {
                for x in xs.iter_mut() {
                    *x = $f(*x);
                }
            }
            #[cfg(target_arch = "x86_64")]
            #[target_feature(enable = "avx2,fma")]
            fn avx2(xs: &mut [f32]) {
                for x in xs.iter_mut() {
                    *x = $f(*x);
                }
            }
            match path {
                // SAFETY: the CPU has the features (checked).
                #[cfg(target_arch = "x86_64")]
                KernelPath::Avx512 if path.is_supported() => unsafe { avx512(xs) },
                // SAFETY: as above.
                #[cfg(target_arch = "x86_64")]
                KernelPath::Avx2 if path.is_supported() => unsafe { avx2(xs) },
                _ => {
                    for x in xs.iter_mut() {
                        *x = $f(*x);
                    }
                }
            }
        }
    };
}

in_place!(
    /// `x = exp(x)` for every element.
    exp_in_place,
    exp
);
in_place!(
    /// `x = ln(x)` for every element.
    ln_in_place,
    ln
);
in_place!(
    /// `x = tanh(x)` for every element.
    tanh_in_place,
    tanh
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numeric::denormals;

    type Pair = (fn(f32) -> f32, fn(f32) -> f32, &'static str);

    const PAIRS: [Pair; 3] = [(exp, f32::exp, "expf"), (ln, f32::ln, "logf"), (tanh, f32::tanh, "tanhf")];

    /// Same bits as the system libm (NaNs: both NaN with the same bits).
    fn check(ours: fn(f32) -> f32, libm: fn(f32) -> f32, name: &str, bits: impl Iterator<Item = u32>) {
        for b in bits {
            let x = f32::from_bits(b);
            let (o, l) = (ours(x), libm(x));
            assert_eq!(
                o.to_bits(),
                l.to_bits(),
                "{name}({x:e}, bits {b:#010x}): ours {o:e} ({:#010x}), libm {l:e} ({:#010x}); the reference is \
                 glibc 2.36's FMA build (Debian 12)",
                o.to_bits(),
                l.to_bits()
            );
        }
    }

    /// Every float with a stride that visits every exponent and sign, and the edges of each
    /// branch the functions take.
    fn sample() -> impl Iterator<Item = u32> + Clone {
        let edges = [
            0x3f80_0000u32,
            0x3f85_1591,
            0x3f85_1592,
            0x3eb1_7218,
            0x3eb1_7219,
            0x3300_0000,
            0x32ff_ffff,
            0x41af_ffff,
            0x41b0_0000,
            0x23ff_ffff,
            0x2400_0000,
            0x42b1_7217,
            0x42b1_7218,
            0x42cf_f1b4,
            0x42ce_8ecf,
            0x42b0_0000,
            0x0080_0000,
            0x007f_ffff,
            0x0000_0001,
            0x7f80_0000,
            0x7fc0_0000,
            0x7f7f_ffff,
            0,
        ];
        let around =
            edges.into_iter().flat_map(|e| (0..16u32).flat_map(move |d| [e.wrapping_add(d), e.wrapping_sub(d)]));
        let signed = around.flat_map(|b| [b, b | 0x8000_0000]);
        signed.chain((0..u32::MAX / 251).map(|i| i * 251))
    }

    #[test]
    fn the_same_bits_as_the_system_libm() {
        for (ours, libm, name) in PAIRS {
            check(ours, libm, name, sample());
        }
    }

    #[test]
    fn the_same_bits_as_the_system_libm_when_subnormals_flush_to_zero() {
        std::thread::spawn(|| {
            denormals::flush_denormals_to_zero();
            for (ours, libm, name) in PAIRS {
                check(ours, libm, name, sample());
            }
        })
        .join()
        .unwrap();
    }

    #[test]
    fn every_vector_width_gives_the_same_bits() {
        let xs: Vec<f32> = sample().map(f32::from_bits).collect();
        let apply = |path, f: fn(KernelPath, &mut [f32])| {
            let mut v = xs.clone();
            f(path, &mut v);
            v.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
        };
        for f in [exp_in_place as fn(KernelPath, &mut [f32]), ln_in_place, tanh_in_place] {
            let portable = apply(KernelPath::Portable, f);
            for path in [KernelPath::Avx2, KernelPath::Avx512].into_iter().filter(|p| p.is_supported()) {
                assert_eq!(apply(path, f), portable, "{path:?}");
            }
        }
    }

    /// Every one of the 2^32 floats against the system libm, with subnormals kept and flushed:
    /// a few minutes on one core. `cargo test --release --lib glibc_math::tests::every_float
    /// -- --ignored`.
    #[test]
    #[ignore]
    fn every_float() {
        for flush in [false, true] {
            std::thread::spawn(move || {
                if flush {
                    denormals::flush_denormals_to_zero();
                }
                for (ours, libm, name) in PAIRS {
                    check(ours, libm, name, 0..=u32::MAX);
                }
            })
            .join()
            .unwrap();
        }
    }
}
