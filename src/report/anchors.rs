//! Published returns kept as data in `baselines/published_returns.toml`, with their sources.
use serde::Deserialize;

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct Anchor {
    pub env: String,
    pub algo: String,
    #[serde(rename = "return")]
    pub value: f64,
    pub std: Option<f64>,
    pub steps: u64,
    /// Training seeds behind the value, when the source says.
    pub seeds: Option<usize>,
    /// What the ± is taken over, when it is not seeds.
    pub(crate) spread: Option<String>,
    pub source: String,
}

#[derive(Deserialize)]
struct File {
    anchor: Vec<Anchor>,
}

/// The anchors bundled with the crate.
pub(crate) fn bundled_anchors() -> Vec<Anchor> {
    toml::from_str::<File>(include_str!("../../baselines/published_returns.toml"))
        .expect("baselines/published_returns.toml parses")
        .anchor
}

/// A published learning curve: mean ± std over seeds at a few step marks.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PublishedCurve {
    pub env: String,
    pub algo: String,
    pub source: String,
    pub seeds: usize,
    pub steps: Vec<u64>,
    pub mean: Vec<f64>,
    pub std: Vec<f64>,
}

impl PublishedCurve {
    /// (mean, std) at exactly `step`, if the curve has that mark.
    pub fn at(&self, step: u64) -> Option<(f64, f64)> {
        self.steps.iter().position(|&s| s == step).map(|i| (self.mean[i], self.std[i]))
    }
}

#[derive(Deserialize)]
struct CurveFile {
    curve: Vec<PublishedCurve>,
}

/// The published learning curves bundled with the crate (`baselines/published_curves.toml`).
pub(crate) fn bundled_curves() -> Vec<PublishedCurve> {
    let curves = toml::from_str::<CurveFile>(include_str!("../../baselines/published_curves.toml"))
        .expect("baselines/published_curves.toml parses")
        .curve;
    for c in &curves {
        assert!(c.steps.len() == c.mean.len() && c.steps.len() == c.std.len(), "{} {}: ragged curve", c.env, c.algo);
    }
    curves
}

/// The published curve for an env and algorithm, if there is one.
pub(crate) fn published_curve(env: &str, algo: &str) -> Option<PublishedCurve> {
    bundled_curves().into_iter().find(|c| c.env == env && c.algo == algo)
}

#[cfg(test)]
mod tests {
    #[test]
    fn bundled_anchors_parse_and_name_their_sources() {
        let a = super::bundled_anchors();
        assert!(a.len() >= 9);
        assert!(a.iter().all(|x| !x.source.is_empty() && x.steps > 0 && x.value.is_finite()));
        assert!(a.iter().all(|x| crate::envs::lookup(&x.env).is_ok()), "every anchor names a registered env");
        let td3 = a.iter().find(|x| x.env == "half-cheetah" && x.algo == "td3" && x.steps == 1_000_000).unwrap();
        assert_eq!(td3.value, 9636.95);
    }

    #[test]
    fn bundled_curves_have_the_five_marks_and_a_source() {
        let curves = super::bundled_curves();
        assert_eq!(curves.len(), 9);
        for c in &curves {
            assert!(crate::envs::lookup(&c.env).is_ok() && crate::agents::Algo::parse(&c.algo).is_ok(), "{}", c.env);
            assert_eq!(c.steps, vec![100_000, 200_000, 300_000, 500_000, 1_000_000]);
            assert!(!c.source.is_empty());
        }
        let sac = super::published_curve("half-cheetah", "sac").unwrap();
        assert_eq!(sac.at(100_000), Some((5794.0, 437.0)));
        assert_eq!(sac.at(150_000), None);
        assert_eq!(super::published_curve("hopper", "td3").unwrap().at(300_000), Some((2410.0, 900.0)));
        assert!(super::published_curve("minitaur", "sac").is_none());
    }
}
