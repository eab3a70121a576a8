//! How numbers read in the report's tables.
use crate::evaluation::stats::{wilson, Interval};

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

/// `estimate [low, high]`.
pub fn interval(i: Interval, f: impl Fn(f64) -> String) -> String {
    if i.low == i.high {
        f(i.estimate)
    } else {
        format!("{} [{}, {}]", f(i.estimate), f(i.low), f(i.high))
    }
}

/// `k/n (low-high)`: a count with the Wilson interval of its rate.
pub fn rate(k: usize, n: usize) -> String {
    let w = wilson(k, n);
    format!("{k}/{n} ({:.2}-{:.2})", w.low, w.high)
}

/// `300k`, `1M`.
pub fn budget(steps: u64) -> String {
    super::plots::step_label(steps as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

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
    }
}
