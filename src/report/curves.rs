//! Learning-curve statistics: evaluation mean ± std across seeds, rolling means of episode
//! returns, area under the curve.

/// Evaluation returns of a group of seeds at the steps all of them evaluated.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EvalCurve {
    /// Steps at which every seed evaluated.
    pub steps: Vec<u64>,
    /// Mean over seeds of each seed's evaluation mean.
    pub mean: Vec<f64>,
    /// Standard deviation over seeds (population, as numpy's default).
    pub std: Vec<f64>,
    /// Seeds in the curve.
    pub seeds: usize,
}

pub(crate) fn mean_std(xs: &[f64]) -> (f64, f64) {
    if xs.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = xs.iter().sum::<f64>() / xs.len() as f64;
    (m, (xs.iter().map(|x| (x - m).powi(2)).sum::<f64>() / xs.len() as f64).sqrt())
}

/// Combines per-seed evaluation series `(step, mean return)`; steps missing from any seed are
/// left out so every point averages the same seeds.
pub(crate) fn eval_curve(per_seed: &[Vec<(u64, f64)>]) -> EvalCurve {
    let Some(first) = per_seed.first() else { return EvalCurve::default() };
    let mut curve = EvalCurve { seeds: per_seed.len(), ..Default::default() };
    for &(step, _) in first {
        let values: Option<Vec<f64>> =
            per_seed.iter().map(|s| s.iter().find(|(t, _)| *t == step).map(|(_, v)| *v)).collect();
        if let Some(values) = values {
            let (m, sd) = mean_std(&values);
            curve.steps.push(step);
            curve.mean.push(m);
            curve.std.push(sd);
        }
    }
    curve
}

impl EvalCurve {
    /// Mean and std over seeds of the last common evaluation.
    pub fn last(&self) -> Option<(u64, f64, f64)> {
        let i = self.steps.len().checked_sub(1)?;
        Some((self.steps[i], self.mean[i], self.std[i]))
    }

    /// The mean return at the last evaluation at or before `step`.
    #[cfg(test)]
    pub(crate) fn at(&self, step: u64) -> Option<f64> {
        self.steps.iter().rposition(|&s| s <= step).map(|i| self.mean[i])
    }

    /// Area under the mean curve divided by its step span (trapezoids): the average return over
    /// training, which rewards learning early as well as learning well.
    pub(crate) fn normalised_auc(&self) -> Option<f64> {
        if self.steps.len() < 2 {
            return self.mean.first().copied();
        }
        let area: f64 = self
            .steps
            .windows(2)
            .zip(self.mean.windows(2))
            .map(|(s, m)| (s[1] - s[0]) as f64 * 0.5 * (m[0] + m[1]))
            .sum();
        Some(area / (self.steps[self.steps.len() - 1] - self.steps[0]) as f64)
    }
}

/// Trailing rolling mean and standard deviation over up to `window` values (fewer at the start).
pub(crate) fn rolling(values: &[f64], window: usize) -> (Vec<f64>, Vec<f64>) {
    let window = window.max(1);
    (0..values.len()).map(|i| mean_std(&values[(i + 1).saturating_sub(window)..=i])).unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_statistics_match_hand_computation() {
        let a = vec![(100, 1.0), (200, 3.0), (300, 5.0)];
        let b = vec![(100, 3.0), (200, 5.0)];
        let c = eval_curve(&[a, b]);
        assert_eq!(c.steps, vec![100, 200]);
        assert_eq!(c.mean, vec![2.0, 4.0]);
        assert_eq!(c.std, vec![1.0, 1.0]);
        // Trapezoid from 100 to 200 of a line from 2 to 4: mean 3.
        assert_eq!(c.normalised_auc(), Some(3.0));
        assert_eq!(c.at(250), Some(4.0));
        assert_eq!(c.at(50), None);
        let (m, s) = rolling(&[1.0, 3.0, 5.0, 7.0], 2);
        assert_eq!(m, vec![1.0, 2.0, 4.0, 6.0]);
        assert_eq!(s, vec![0.0, 1.0, 1.0, 1.0]);
    }
}
