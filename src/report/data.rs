//! The report's numbers as CSV, for anything that quotes them (docs, the returns bench).
use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::anchors::{bundled_anchors, published_curve};
use super::controller::{return_interval, ControllerSection};
use super::heldout::BudgetRow;
use super::runs::{Group, Run};
use super::BOOTSTRAP_SEED;
use crate::controller::measure::mean_cost_of_transport;
use crate::evaluation::speed_grid::SpeedPoint;
use crate::evaluation::stats;

/// Budgets at which learning curves are tabulated: the marks published curves report.
pub(crate) const CURVE_MARKS: [u64; 5] = [100_000, 200_000, 300_000, 500_000, 1_000_000];

pub(crate) fn held_out_csv(rows: &BTreeMap<String, Vec<BudgetRow>>) -> String {
    let mut csv = String::from(
        "env,policy,budget,seeds,seeds_without_policy,episodes_per_seed,mean,mean_low,mean_high,iqm,iqm_low,iqm_high,\
         interval_over,falls,episodes,speed,cost_of_transport,machine\n",
    );
    for (env, rows) in rows {
        for r in rows {
            let (m, q) = (r.mean_return(BOOTSTRAP_SEED), r.iqm_return(BOOTSTRAP_SEED));
            let (falls, n) = r.falls();
            let _ = writeln!(
                csv,
                "{env},{},{},{},{},{},{},{},{},{},{},{},{},{falls},{n},{},{},\"{}\"",
                r.group.label().replace(',', ";"),
                r.budget,
                r.seeds(),
                r.missing.len(),
                r.episodes_per_seed(),
                m.interval.estimate,
                m.interval.low,
                m.interval.high,
                q.interval.estimate,
                q.interval.low,
                q.interval.high,
                m.over,
                r.speed(),
                r.cost_of_transport(),
                r.provenance.replace('"', "'"),
            );
        }
    }
    csv
}

/// `commanded,achieved,mean,low,high,falls,episodes` of one controller speed.
fn speed_point_fields(p: &SpeedPoint) -> String {
    let i = return_interval(p);
    format!("{},{},{},{},{},{},{}", p.commanded, p.achieved(), i.estimate, i.low, i.high, p.falls(), p.episodes.len())
}

pub(crate) fn controller_csv(sections: &BTreeMap<String, ControllerSection>) -> String {
    let mut csv =
        String::from("env,commanded,achieved,mean,mean_low,mean_high,falls,episodes,cost_of_transport,works\n");
    for (env, s) in sections {
        for p in &s.grid {
            let _ =
                writeln!(csv, "{env},{},{},{}", speed_point_fields(p), mean_cost_of_transport(&p.episodes), p.works());
        }
    }
    csv
}

/// Evaluation during training at each mark every seed of a group reached: mean over seeds, sample
/// std, 95% bootstrap interval over seeds, and the published curve at the same mark if any.
pub(crate) fn curves_csv(envs: &BTreeMap<String, Vec<(&Group, &Vec<&Run>)>>) -> String {
    let mut csv = String::from(
        "env,policy,algo,step,seeds,seed_values,evaluation_episodes,mean,sample_std,low,high,published_mean,\
         published_std,published_seeds,published_other_settings\n",
    );
    for (env, groups) in envs {
        for (g, runs) in groups {
            for mark in CURVE_MARKS {
                let values: Option<Vec<f64>> =
                    runs.iter().map(|r| r.evals().find(|(t, _)| *t == mark).map(|(_, v)| v)).collect();
                let Some(values) = values.filter(|v| !v.is_empty()) else { continue };
                let ci = stats::stratified_bootstrap(
                    std::slice::from_ref(&values),
                    |v| stats::mean(&v[0]),
                    20_000,
                    BOOTSTRAP_SEED ^ mark,
                );
                let sd = if values.len() > 1 { stats::sample_std(&values) } else { f64::NAN };
                let published = published_curve(env, &g.algo)
                    .filter(|_| g.is_default_setting())
                    .and_then(|c| c.at(mark).map(|(m, s)| (m, s, c.seeds.to_string())))
                    .or_else(|| evaluation_anchor(g, runs, mark));
                let (pm, ps, pn, other_settings) = match published {
                    Some((m, s, n)) => (m.to_string(), s.to_string(), n, !g.settings.is_empty()),
                    None => (String::new(), String::new(), String::new(), false),
                };
                let mut episodes: Vec<usize> = runs.iter().map(|r| r.config.train.eval_episodes).collect();
                episodes.dedup();
                let episodes = episodes.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("/");
                let mut seeds: Vec<u64> = runs.iter().map(|r| r.config.seed).collect();
                seeds.sort_unstable();
                let seeds = seeds.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(" ");
                let _ = writeln!(
                    csv,
                    "{env},{},{},{mark},{},{seeds},{episodes},{},{sd},{},{},{pm},{ps},{pn},{other_settings}",
                    g.label().replace(',', ";"),
                    g.algo,
                    values.len(),
                    stats::mean(&values),
                    ci.low,
                    ci.high,
                );
            }
        }
    }
    csv
}

/// A published deterministic evaluation at `mark` that these runs can stand beside where no
/// published curve covers them (CrossQ's 100k and 300k): same env, algorithm and environment
/// options (`Anchor::comparable`; an anchor naming no options holds for the default env only).
/// The agent's settings may differ, and the table then says so.
fn evaluation_anchor(g: &Group, runs: &[&Run], mark: u64) -> Option<(f64, f64, String)> {
    bundled_anchors()
        .into_iter()
        .filter(|a| a.steps == mark && a.evaluation_episodes.is_some() && a.env == g.env && a.algo == g.algo)
        .find(|a| runs.iter().all(|r| a.comparable(r)))
        .and_then(|a| Some((a.value, a.std?, a.seeds.map_or(String::new(), |n| n.to_string()))))
}

/// Each learned budget row beside the controller commanded to its speed, on the same episodes.
pub(crate) fn versus_controller_csv(
    rows: &BTreeMap<String, Vec<BudgetRow>>,
    sections: &BTreeMap<String, ControllerSection>,
) -> String {
    let mut csv = String::from(
        "env,policy,budget,seeds,speed,mean,mean_low,mean_high,falls,episodes,controller_commanded,\
         controller_achieved,controller_mean,controller_low,controller_high,controller_falls,controller_episodes,\
         p_beats_matched,p_matched_low,p_matched_high,p_beats_best,p_best_low,p_best_high,note\n",
    );
    for (env, section) in sections {
        let Some(env_rows) = rows.get(env) else { continue };
        for m in &section.matched {
            let r = &env_rows[m.row];
            let mean = r.mean_return(BOOTSTRAP_SEED).interval;
            let (falls, n) = r.falls();
            let (controller, note) = match &m.controller {
                Ok(p) => (speed_point_fields(p), String::new()),
                Err(why) => (",,,,,,".to_string(), why.replace([',', '"'], " ")),
            };
            let estimate = |e: &Option<super::heldout::Estimate>| match e {
                Some(e) => format!("{},{},{}", e.interval.estimate, e.interval.low, e.interval.high),
                None => ",,".to_string(),
            };
            let _ = writeln!(
                csv,
                "{env},{},{},{},{},{},{},{},{falls},{n},{controller},{},{},\"{note}\"",
                r.group.label().replace(',', ";"),
                r.budget,
                r.seeds(),
                m.rl_speed,
                mean.estimate,
                mean.low,
                mean.high,
                estimate(&m.beats_matched),
                estimate(&m.beats_best),
            );
        }
    }
    csv
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agents::Algo;
    use crate::report::runs::tests::run;

    fn eval_row(step: u64, mean: f64) -> crate::train::metrics::MetricsRow {
        crate::train::metrics::MetricsRow { kind: "eval", step, eval_mean: Some(mean), ..Default::default() }
    }

    #[test]
    fn curves_take_published_evaluations_where_no_curve_covers_the_runs_and_say_when_settings_differ() {
        let mut crossq = run("half-cheetah", Algo::Crossq, "critic_hidden=[256, 256]", &[]);
        crossq.metrics = vec![eval_row(100_000, 7000.0), eval_row(200_000, 8000.0)];
        let group = crossq.group();
        let runs = vec![&crossq];
        let envs = BTreeMap::from([("half-cheetah".to_string(), vec![(&group, &runs)])]);
        let csv = curves_csv(&envs);
        let rows: Vec<&str> = csv.lines().collect();
        assert!(rows[0].ends_with("published_mean,published_std,published_seeds,published_other_settings"));
        // 100k: CrossQ's published deterministic evaluation (2048-wide critics), ours narrower.
        assert!(rows[1].contains(",100000,") && rows[1].ends_with(",8112,896,10,true"), "{}", rows[1]);
        // 200k: no published value there.
        assert!(rows[2].contains(",200000,") && rows[2].ends_with(",,,,false"), "{}", rows[2]);
        // Another reward than the default: not beside the source's.
        let mut drift = run("half-cheetah", Algo::Crossq, "", &[("ctrl_cost_weight", "0.5")]);
        drift.metrics = vec![eval_row(100_000, 7000.0)];
        assert_eq!(evaluation_anchor(&drift.group(), &[&drift], 100_000), None);
        // The default settings: beside it, with nothing to flag.
        let mut plain = run("half-cheetah", Algo::Crossq, "", &[]);
        plain.metrics = vec![eval_row(100_000, 7000.0)];
        let (g, rs) = (plain.group(), vec![&plain]);
        let csv = curves_csv(&BTreeMap::from([("half-cheetah".to_string(), vec![(&g, &rs)])]));
        assert!(csv.lines().nth(1).unwrap().ends_with(",8112,896,10,false"));
        // TD3 keeps its published curve.
        let mut td3 = run("half-cheetah", Algo::Td3, "", &[]);
        td3.metrics = vec![eval_row(100_000, 5000.0)];
        let (g, rs) = (td3.group(), vec![&td3]);
        let csv = curves_csv(&BTreeMap::from([("half-cheetah".to_string(), vec![(&g, &rs)])]));
        assert!(csv.lines().nth(1).unwrap().ends_with(",5514,554,10,false"));
    }
}
