//! Published returns kept as data in `baselines/published_returns.toml`, with their sources.
use std::path::Path;

use anyhow::{Context, Result};
use serde::Deserialize;

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    pub env: String,
    pub algo: String,
    #[serde(rename = "return")]
    pub value: f64,
    pub std: Option<f64>,
    pub steps: u64,
    pub source: String,
}

#[derive(Deserialize)]
struct File {
    anchor: Vec<Anchor>,
}

pub fn load_anchors(path: &Path) -> Result<Vec<Anchor>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(toml::from_str::<File>(&text).with_context(|| format!("parsing {}", path.display()))?.anchor)
}

/// The anchors bundled with the crate.
pub fn bundled_anchors() -> Vec<Anchor> {
    toml::from_str::<File>(include_str!("../../baselines/published_returns.toml"))
        .expect("baselines/published_returns.toml parses")
        .anchor
}

#[cfg(test)]
mod tests {
    #[test]
    fn bundled_anchors_parse_and_name_their_sources() {
        let a = super::bundled_anchors();
        assert!(a.len() >= 9);
        assert!(a.iter().all(|x| !x.source.is_empty() && x.steps > 0 && x.value.is_finite()));
        let td3 = a.iter().find(|x| x.env == "half-cheetah" && x.algo == "td3" && x.steps == 1_000_000).unwrap();
        assert_eq!(td3.value, 9636.95);
    }
}
