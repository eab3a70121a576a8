//! The statistics every result table uses, written once: mean, sample standard deviation,
//! interquartile mean, percentile intervals from a stratified bootstrap, the Wilson interval of
//! a rate, and the probability of improvement. They follow Agarwal et al., "Deep Reinforcement
//! Learning at the Edge of the Statistical Precipice" (NeurIPS 2021), as implemented in
//! google-research/rliable (`rliable/metrics.py`, `rliable/library.py`).
//!
//! One convention for spread: the sample standard deviation (divisor n - 1).
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Confidence level of every interval in the report.
pub(crate) const LEVEL: f64 = 0.95;
/// Bootstrap resamples (rliable's default is 50,000; the statistics here are cheap).
pub(crate) const BOOTSTRAP_REPS: usize = 20_000;

/// Seed of every bootstrap in the report and the evaluation summaries.
pub const BOOTSTRAP_SEED: u64 = 2021;

/// The arithmetic mean; NaN for no values.
pub fn mean(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return f64::NAN;
    }
    xs.iter().sum::<f64>() / xs.len() as f64
}

/// Sample standard deviation (n - 1); NaN below two values.
pub fn sample_std(xs: &[f64]) -> f64 {
    if xs.len() < 2 {
        return f64::NAN;
    }
    let m = mean(xs);
    (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (xs.len() - 1) as f64).sqrt()
}

/// Interquartile mean: the mean of what is left after cutting floor(n/4) values from each end
/// of the sorted values (`scipy.stats.trim_mean(x, 0.25)`, what rliable calls IQM).
pub fn iqm(xs: &[f64]) -> f64 {
    if xs.is_empty() {
        return f64::NAN;
    }
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    let cut = v.len() / 4;
    mean(&v[cut..v.len() - cut])
}

/// The q-quantile (0..=1) of sorted values with linear interpolation between order statistics
/// (numpy's default).
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (lo, frac) = (h.floor() as usize, h - h.floor());
    if lo + 1 < sorted.len() {
        sorted[lo] + frac * (sorted[lo + 1] - sorted[lo])
    } else {
        sorted[lo]
    }
}

/// An estimate with its interval.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    /// The point estimate.
    pub estimate: f64,
    /// Lower end of the interval.
    pub low: f64,
    /// Upper end of the interval.
    pub high: f64,
}

impl Interval {
    /// An interval of zero width at `v`.
    pub fn point(v: f64) -> Interval {
        Interval { estimate: v, low: v, high: v }
    }
}

/// Percentile bootstrap interval of `statistic`, resampling each stratum (e.g. the seeds of one
/// task) with replacement on its own, as rliable's `StratifiedBootstrap` does. Seeded: the same
/// inputs give the same interval.
pub(crate) fn stratified_bootstrap(
    strata: &[Vec<f64>],
    statistic: impl Fn(&[Vec<f64>]) -> f64,
    reps: usize,
    seed: u64,
) -> Interval {
    let estimate = statistic(strata);
    if strata.iter().all(|s| s.len() < 2) || reps == 0 {
        return Interval::point(estimate);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut resampled: Vec<Vec<f64>> = strata.iter().map(|s| vec![0.0; s.len()]).collect();
    let mut values: Vec<f64> = (0..reps)
        .map(|_| {
            for (out, s) in resampled.iter_mut().zip(strata) {
                for v in out.iter_mut() {
                    *v = s[rng.random_range(0..s.len())];
                }
            }
            statistic(&resampled)
        })
        .collect();
    values.sort_by(f64::total_cmp);
    let tail = (1.0 - LEVEL) / 2.0;
    Interval { estimate, low: quantile(&values, tail), high: quantile(&values, 1.0 - tail) }
}

/// Wilson score interval of a rate of `k` in `n` (Wilson 1927): unlike the normal
/// approximation it stays inside [0, 1] and is not zero-width at 0 or n.
pub fn wilson(k: usize, n: usize) -> Interval {
    if n == 0 {
        return Interval { estimate: f64::NAN, low: 0.0, high: 1.0 };
    }
    let z = 1.959_963_984_540_054; // the 97.5% normal quantile
    let (n, p) = (n as f64, k as f64 / n as f64);
    let centre = (p + z * z / (2.0 * n)) / (1.0 + z * z / n);
    let half = z / (1.0 + z * z / n) * (p * (1.0 - p) / n + z * z / (4.0 * n * n)).sqrt();
    Interval { estimate: p, low: (centre - half).max(0.0), high: (centre + half).min(1.0) }
}

/// P(X > Y) + P(X = Y) / 2 over paired outcomes (the Mann-Whitney form rliable's probability of
/// improvement uses), here for pairs that share a reset seed.
pub(crate) fn probability_of_improvement(pairs: &[(f64, f64)]) -> f64 {
    if pairs.is_empty() {
        return f64::NAN;
    }
    pairs
        .iter()
        .map(|&(x, y)| {
            if x > y {
                1.0
            } else if x == y {
                0.5
            } else {
                0.0
            }
        })
        .sum::<f64>()
        / pairs.len() as f64
}

/// Where an estimate sits against a published interval.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Verdict {
    Below,
    Inside,
    Above,
}

impl Verdict {
    /// Ours against theirs: below when our whole interval lies under theirs, above when over it,
    /// inside when the two overlap.
    pub fn of(ours: Interval, theirs_low: f64, theirs_high: f64) -> Verdict {
        if ours.high < theirs_low {
            Verdict::Below
        } else if ours.low > theirs_high {
            Verdict::Above
        } else {
            Verdict::Inside
        }
    }
    pub(crate) fn word(self) -> &'static str {
        match self {
            Verdict::Below => "below",
            Verdict::Inside => "inside",
            Verdict::Above => "above",
        }
    }
}

/// An interval and what it was resampled over.
#[derive(Debug, Clone, Copy)]
pub struct Estimate {
    /// The statistic and its 95% interval.
    pub interval: Interval,
    /// "seeds", or "episodes" for a single seed.
    pub over: &'static str,
}

/// `statistic` of per-seed values with its 95% bootstrap interval: resampling seeds (each seed
/// summarised by the mean of its values) when there are two or more, else the one seed's values.
pub fn estimate(per_seed: &[Vec<f64>], statistic: fn(&[f64]) -> f64, seed: u64) -> Estimate {
    if per_seed.len() >= 2 {
        let scores: Vec<f64> = per_seed.iter().map(|v| mean(v)).collect();
        let i = stratified_bootstrap(&[scores], |s| statistic(&s[0]), BOOTSTRAP_REPS, seed);
        Estimate { interval: i, over: "seeds" }
    } else {
        let values = per_seed.first().cloned().unwrap_or_default();
        let i = stratified_bootstrap(&[values], |s| statistic(&s[0]), BOOTSTRAP_REPS, seed);
        Estimate { interval: i, over: "episodes" }
    }
}

/// `estimate [low, high]`, each number written by `f`; the estimate alone for a zero-width interval.
pub fn interval(i: Interval, f: impl Fn(f64) -> String) -> String {
    if i.low == i.high {
        f(i.estimate)
    } else {
        format!("{} [{}, {}]", f(i.estimate), f(i.low), f(i.high))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_resample_seeds_or_the_single_seeds_episodes() {
        let two = estimate(&[vec![1.0, 3.0], vec![5.0, 7.0]], mean, 1);
        assert_eq!(two.over, "seeds");
        assert_eq!(two.interval.estimate, 4.0);
        // Two seed means, 2 and 6: every resample's mean is 2, 4 or 6.
        assert!(two.interval.low >= 2.0 && two.interval.high <= 6.0);
        let one = estimate(&[vec![1.0, 2.0, 3.0, 10.0]], iqm, 1);
        assert_eq!(one.over, "episodes");
        assert_eq!(one.interval.estimate, 2.5);
    }

    #[test]
    fn spread_and_iqm_match_hand_computation() {
        let xs = [2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0];
        assert_eq!(mean(&xs), 5.0);
        // Squared deviations sum to 32; 32 / 7.
        assert!((sample_std(&xs) - (32.0f64 / 7.0).sqrt()).abs() < 1e-12);
        assert!(sample_std(&[3.0]).is_nan());
        // n = 8: cut 2 from each end of the sorted values -> mean of 4, 4, 5, 5.
        assert_eq!(iqm(&xs), 4.5);
        // n = 3: nothing is cut (floor(3/4) = 0), as scipy's trim_mean does.
        assert_eq!(iqm(&[1.0, 2.0, 30.0]), 11.0);
        // n = 5: one cut from each end, order of input does not matter.
        assert_eq!(iqm(&[100.0, 1.0, 3.0, 2.0, -50.0]), 2.0);
    }

    #[test]
    fn quantiles_interpolate_like_numpy() {
        let s = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(quantile(&s, 0.0), 1.0);
        assert_eq!(quantile(&s, 1.0), 4.0);
        assert_eq!(quantile(&s, 0.5), 2.5);
        // numpy.percentile([1,2,3,4], 2.5) = 1.075
        assert!((quantile(&s, 0.025) - 1.075).abs() < 1e-12);
    }

    #[test]
    fn wilson_interval_matches_hand_computation() {
        // 0 of 10: [0, z^2/(n+z^2)] = [0, 3.8415/13.8415] = [0, 0.2775].
        let w = wilson(0, 10);
        assert_eq!(w.low, 0.0);
        assert!((w.high - 0.27754).abs() < 1e-4, "{w:?}");
        // 5 of 10: 0.5 ± 0.3010 -> [0.2366, 0.7634].
        let w = wilson(5, 10);
        assert!((w.low - 0.23659).abs() < 1e-4 && (w.high - 0.76341).abs() < 1e-4, "{w:?}");
        assert!(wilson(10, 10).high > 1.0 - 1e-12 && wilson(10, 10).low < 1.0);
    }

    #[test]
    fn bootstrap_is_seeded_and_brackets_the_estimate() {
        let scores = [1.0, 2.0, 3.0, 4.0, 10.0];
        let a = stratified_bootstrap(&[scores.to_vec()], |s| mean(&s.concat()), 5000, 7);
        let b = stratified_bootstrap(&[scores.to_vec()], |s| mean(&s.concat()), 5000, 7);
        assert_eq!(a, b);
        assert_eq!(a.estimate, 4.0);
        assert!(a.low < 4.0 && a.high > 4.0 && a.low >= 1.0 && a.high <= 10.0);
        // Every resample of a constant is that constant.
        let c = stratified_bootstrap(&[vec![3.0; 4]], |s| mean(&s.concat()), 100, 1);
        assert_eq!((c.low, c.high), (3.0, 3.0));
        // A single value has no spread to resample.
        assert_eq!(stratified_bootstrap(&[vec![2.0]], |s| mean(&s.concat()), 100, 1), Interval::point(2.0));
    }

    #[test]
    fn bootstrap_resamples_each_stratum_on_its_own() {
        // Two strata of constants: a resample can never mix them, so the mean of stratum means
        // is always exactly 5.5, whereas a pooled resample of the 6 values would vary.
        let strata = vec![vec![1.0, 1.0, 1.0], vec![10.0, 10.0, 10.0]];
        let stat = |s: &[Vec<f64>]| s.iter().map(|x| mean(x)).sum::<f64>() / s.len() as f64;
        let i = stratified_bootstrap(&strata, stat, 1000, 3);
        assert_eq!((i.estimate, i.low, i.high), (5.5, 5.5, 5.5));
    }

    #[test]
    fn bootstrap_interval_of_a_mean_is_near_the_normal_one() {
        // 40 values 0..39: mean 19.5, standard error sqrt(var/n) = 11.69/sqrt(40) = 1.826.
        let xs: Vec<f64> = (0..40).map(f64::from).collect();
        let i = stratified_bootstrap(&[xs], |s| mean(&s.concat()), 20_000, 11);
        let normal_half = 1.96 * 1.826;
        assert!(((i.high - i.low) / 2.0 - normal_half).abs() < 0.25, "{i:?}");
    }

    #[test]
    fn improvement_and_verdicts() {
        assert_eq!(probability_of_improvement(&[(2.0, 1.0), (1.0, 2.0), (3.0, 3.0), (5.0, 0.0)]), 0.625);
        let ours = Interval { estimate: 5.0, low: 4.0, high: 6.0 };
        assert_eq!(Verdict::of(ours, 6.5, 8.0), Verdict::Below);
        assert_eq!(Verdict::of(ours, 5.5, 8.0), Verdict::Inside);
        assert_eq!(Verdict::of(ours, 1.0, 3.0), Verdict::Above);
    }
}
