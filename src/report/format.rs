//! How numbers read in the report's tables.
use crate::evaluation::stats::wilson;

/// Returns span from about 0.01 (short Minitaur episodes) to 10,000 (HalfCheetah): more
/// decimals below 1.
pub fn fmt_return(v: f64) -> String {
    match v.abs() {
        a if !a.is_finite() => "–".into(),
        a if a < 1.0 => format!("{v:.3}"),
        a if a < 1000.0 => format!("{v:.2}"),
        _ => format!("{v:.0}"),
    }
}

/// `v` with `digits` decimals, or `–` when not finite.
pub fn fixed(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "–".into()
    }
}

pub use crate::evaluation::stats::interval;

/// `k/n (low-high)`: a count with the Wilson interval of its rate.
pub fn rate(k: usize, n: usize) -> String {
    let w = wilson(k, n);
    format!("{k}/{n} ({:.2}-{:.2})", w.low, w.high)
}

/// `300k`, `1M`.
pub fn budget(steps: u64) -> String {
    if steps == super::budgets::UNKNOWN_BUDGET {
        return "steps unknown".into();
    }
    // exact, unlike a tick label: an on-policy run ends past its budget (2,015,232 steps is
    // 2.015232M, not a second "2M")
    for (unit, suffix) in [(1_000_000u64, "M"), (1_000, "k")] {
        if steps >= unit {
            let (whole, rest) = (steps / unit, steps % unit);
            if rest == 0 {
                return format!("{whole}{suffix}");
            }
            let digits = format!("{rest:0width$}", width = unit.ilog10() as usize);
            return format!("{whole}.{}{suffix}", digits.trim_end_matches('0'));
        }
    }
    steps.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluation::stats::Interval;

    #[test]
    fn numbers_read_at_their_scale() {
        assert_eq!(fmt_return(0.1234), "0.123");
        assert_eq!(fmt_return(9.916), "9.92");
        assert_eq!(fmt_return(8651.4), "8651");
        assert_eq!(fmt_return(f64::NAN), "–");
        assert_eq!(interval(Interval { estimate: 1.0, low: 0.5, high: 2.0 }, fmt_return), "1.00 [0.500, 2.00]");
        assert_eq!(interval(Interval::point(3.0), fmt_return), "3.00");
        assert_eq!(rate(0, 10), "0/10 (0.00-0.28)");
        assert_eq!(budget(300_000), "300k");
        assert_eq!(budget(2_000_000), "2M");
        assert_eq!(budget(2_015_232), "2.015232M");
        assert_eq!(budget(1_500_000), "1.5M");
        assert_eq!(budget(25_600), "25.6k");
        assert_eq!(budget(999), "999");
    }
}
