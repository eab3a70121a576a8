//! The report's numbers as CSV, for anything that quotes them (docs, the returns bench).
use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::anchors::published_curve;
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
         published_std,published_seeds\n",
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
                    .and_then(|c| c.at(mark).map(|(m, s)| (m, s, c.seeds)));
                let (pm, ps, pn) = match published {
                    Some((m, s, n)) => (m.to_string(), s.to_string(), n.to_string()),
                    None => (String::new(), String::new(), String::new()),
                };
                let mut episodes: Vec<usize> = runs.iter().map(|r| r.config.train.eval_episodes).collect();
                episodes.dedup();
                let episodes = episodes.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("/");
                let mut seeds: Vec<u64> = runs.iter().map(|r| r.config.seed).collect();
                seeds.sort_unstable();
                let seeds = seeds.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(" ");
                let _ = writeln!(
                    csv,
                    "{env},{},{},{mark},{},{seeds},{episodes},{},{sd},{},{},{pm},{ps},{pn}",
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
