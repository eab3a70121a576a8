//! Published returns kept as data in `baselines/published_returns.toml`, with their sources.
use serde::Deserialize;

use super::runs::Run;
use crate::envs::EnvConfig;

#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
/// One published return: what was trained where, for how long, with what result, and the source.
pub struct Anchor {
    /// Our environment name.
    pub env: String,
    /// Our algorithm name.
    pub algo: String,
    /// The published return.
    #[serde(rename = "return")]
    pub value: f64,
    /// Its spread (`spread` says over what), when published.
    pub std: Option<f64>,
    /// Environment steps of training behind it.
    pub steps: u64,
    /// Training seeds behind the value, when the source says.
    pub seeds: Option<usize>,
    /// What the ± is taken over, when it is not seeds.
    pub(crate) spread: Option<String>,
    /// Where the figure comes from (paper, repository and file).
    pub source: String,
    /// The value is a mean of training-episode returns: the last this many episodes at `steps`
    /// (Freeman's 50-episode rolling mean) ...
    pub(crate) window_episodes: Option<usize>,
    /// ... or the episodes of the last this many steps before `steps` (CleanRL's curves).
    pub(crate) window_steps: Option<u64>,
    /// The value is a deterministic evaluation over this many episodes at `steps`; ours is the
    /// run's own in-training evaluation there (the first at or after `steps`, within one
    /// evaluation interval).
    pub(crate) evaluation_episodes: Option<usize>,
    /// Environment options the source trained with (e.g. `energy_weight = 0.0`); only our runs
    /// with the same values are set beside it.
    #[serde(default)]
    pub(crate) options: toml::Table,
    /// Options the source varied and reports its value for every setting of (Freeman's drift
    /// weight): ours may have any value of these.
    #[serde(default)]
    pub(crate) any_value: Vec<String>,
}

impl Anchor {
    /// Whether the source says how its value was measured (a window of training episodes, or a
    /// deterministic evaluation), so that ours can be measured the same way.
    pub(crate) fn is_measurable(&self) -> bool {
        self.window_episodes.is_some() || self.window_steps.is_some() || self.evaluation_episodes.is_some()
    }

    /// Same env, algorithm and environment options as the source: the options the anchor names
    /// at its values, those it lists in `any_value` at any, every other option at the env's
    /// default (an anchor naming none was trained on the default env). The agent's settings may
    /// differ (CrossQ with narrower critics than the paper's), and then say so where shown.
    pub(crate) fn comparable(&self, run: &Run) -> bool {
        if run.env() != self.env || run.algo() != self.algo {
            return false;
        }
        let (Ok(ours), Ok(defaults)) =
            (run.config.env.resolved_options(), EnvConfig::new(&self.env).resolved_options())
        else {
            return false;
        };
        let same = |a: Option<&toml::Value>, b: Option<&toml::Value>| match (a, b) {
            (Some(a), Some(b)) => number(a).zip(number(b)).map_or(a == b, |(x, y)| x == y),
            _ => false,
        };
        let theirs = |k: &str| self.options.get(k).or_else(|| defaults.get(k));
        let free = |k: &str| self.any_value.iter().any(|v| v == k);
        self.options.keys().chain(ours.keys()).filter(|k| !free(k)).all(|k| same(ours.get(k), theirs(k)))
    }

    /// The run's value measured as the source's: its mean training-episode return in the
    /// anchor's window at `steps`, or its in-training evaluation at `steps`; None when the run did
    /// not reach `steps` or the source does not say how it measured.
    pub(crate) fn measure(&self, run: &Run) -> Option<f64> {
        if run.steps() < self.steps {
            return None;
        }
        if self.evaluation_episodes.is_some() {
            let interval = run.config.train.eval_every.max(1);
            return run
                .metrics
                .iter()
                .filter(|r| r.kind == "eval" && r.step >= self.steps && r.step < self.steps + interval)
                .find_map(|r| r.eval_mean);
        }
        let before: Vec<(u64, f64)> = run.episodes().filter(|&(step, _)| step <= self.steps).collect();
        let window: Vec<f64> = if let Some(n) = self.window_episodes {
            before[before.len().saturating_sub(n)..].iter().map(|e| e.1).collect()
        } else {
            let w = self.window_steps?;
            before.iter().filter(|e| e.0 + w > self.steps).map(|e| e.1).collect()
        };
        (!window.is_empty()).then(|| window.iter().sum::<f64>() / window.len() as f64)
    }
}

/// An option value as a number (TOML integers and floats compare alike).
fn number(v: &toml::Value) -> Option<f64> {
    v.as_float().or_else(|| v.as_integer().map(|i| i as f64))
}

#[derive(Deserialize)]
struct File {
    anchor: Vec<Anchor>,
}

/// The anchors bundled with the crate.
pub fn bundled_anchors() -> Vec<Anchor> {
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
    /// Where the figure comes from (paper, repository and file).
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
    use crate::agents::Algo;
    use crate::report::runs::tests::run;
    use crate::train::metrics::MetricsRow;

    fn episode(step: u64, ret: f64) -> MetricsRow {
        MetricsRow { episode_return: Some(ret), ..MetricsRow::progress("episode", step, None, 0.0, 0.0) }
    }

    #[test]
    fn training_measures_average_the_window_before_the_budget_of_matching_runs() {
        let freeman = super::bundled_anchors().into_iter().find(|a| a.env == "minitaur" && a.algo == "sac").unwrap();
        assert_eq!(freeman.window_episodes, Some(50));
        let mut ours = run("minitaur", Algo::Sac, "", &[("energy_weight", "0")]);
        // 100 episodes of 10k steps: returns 0, 1, ..., 99; the budget, 500k, ends episode 49.
        ours.metrics = (0..100).map(|i| episode((i + 1) * 10_000, i as f64)).collect();
        assert!(freeman.comparable(&ours));
        // The last 50 episodes at or before 500k: returns 0..=49.
        assert_eq!(freeman.measure(&ours), Some(24.5));
        // Another energy weight or another algorithm: not comparable. Other agent settings are
        // (the report names them).
        assert!(!freeman.comparable(&run("minitaur", Algo::Sac, "", &[])));
        // He reports every drift weight he tried: any of ours is his env; another shake weight is not.
        assert!(freeman.comparable(&run("minitaur", Algo::Sac, "", &[("energy_weight", "0"), ("drift_weight", "3")])));
        assert!(!freeman.comparable(&run("minitaur", Algo::Sac, "", &[("energy_weight", "0"), ("shake_weight", "3")])));
        assert!(!freeman.comparable(&run("minitaur", Algo::Td3, "", &[("energy_weight", "0")])));
        assert!(freeman.comparable(&run("minitaur", Algo::Sac, "batch_size=64", &[("energy_weight", "0")])));
        // A run that stopped before the budget has no value.
        ours.metrics.truncate(40);
        assert_eq!(freeman.measure(&ours), None);

        let cleanrl = super::bundled_anchors().into_iter().find(|a| a.env == "hopper" && a.algo == "ppo").unwrap();
        let mut ppo = run("hopper", Algo::Ppo, "", &[]);
        ppo.metrics =
            vec![episode(850_000, 100.0), episode(950_000, 10.0), episode(1_000_000, 20.0), episode(1_050_000, 1e6)];
        // The episodes of the last 100k steps before 1M.
        assert_eq!(cleanrl.measure(&ppo), Some(15.0));
        // An anchor naming no options holds for the default env only: a run with another
        // reward weight is not set beside it; one naming a default value explicitly is.
        assert!(cleanrl.options.is_empty() && cleanrl.comparable(&ppo));
        assert!(!cleanrl.comparable(&run("hopper", Algo::Ppo, "", &[("ctrl_cost_weight", "0.5")])));
        assert!(cleanrl.comparable(&run("hopper", Algo::Ppo, "", &[("forward_reward_weight", "1")])));
        assert!(!super::bundled_anchors().into_iter().find(|a| a.algo == "td3").unwrap().is_measurable());
    }

    fn evaluation(step: u64, mean: f64) -> MetricsRow {
        MetricsRow { eval_mean: Some(mean), ..MetricsRow::progress("eval", step, None, 0.0, 0.0) }
    }

    #[test]
    fn evaluation_measures_take_the_runs_own_evaluation_at_the_budget_whatever_its_settings() {
        let crossq = super::bundled_anchors()
            .into_iter()
            .find(|a| a.env == "half-cheetah" && a.algo == "crossq" && a.steps == 100_000)
            .unwrap();
        assert_eq!(crossq.evaluation_episodes, Some(10));
        let mut ours = run("half-cheetah", Algo::Crossq, "critic_hidden=[256, 256]", &[]);
        ours.config.train.eval_every = 5000;
        ours.metrics =
            vec![evaluation(95_000, 1.0), episode(99_000, 7.0), evaluation(100_000, 2.0), evaluation(105_000, 3.0)];
        // Narrower critics than the source's: comparable (the report names the setting).
        assert!(crossq.comparable(&ours) && !ours.settings_label().is_empty());
        assert_eq!(crossq.measure(&ours), Some(2.0));
        // A run evaluated off the mark (PPO evaluates at rollout boundaries) gives the first
        // evaluation past it, within one interval.
        ours.metrics = vec![evaluation(98_304, 1.0), evaluation(102_400, 4.0)];
        assert_eq!(crossq.measure(&ours), Some(4.0));
        ours.metrics = vec![evaluation(98_304, 1.0), evaluation(110_000, 4.0)];
        assert_eq!(crossq.measure(&ours), None);
        assert!(!crossq.comparable(&run("ant", Algo::Crossq, "", &[])));
    }

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
