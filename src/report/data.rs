//! The report's numbers as CSV, for anything that quotes them (docs, the returns bench).
use std::collections::BTreeMap;
use std::fmt::Write as _;

use super::controller::{return_interval, ControllerSection};
use super::heldout::BudgetRow;
use super::BOOTSTRAP_SEED;
use crate::controller::measure::mean_cost_of_transport;

pub fn held_out_csv(rows: &BTreeMap<String, Vec<BudgetRow>>) -> String {
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

pub fn controller_csv(sections: &BTreeMap<String, ControllerSection>) -> String {
    let mut csv =
        String::from("env,commanded,achieved,mean,mean_low,mean_high,falls,episodes,cost_of_transport,works\n");
    for (env, s) in sections {
        for p in &s.grid {
            let i = return_interval(p);
            let _ = writeln!(
                csv,
                "{env},{},{},{},{},{},{},{},{},{}",
                p.commanded,
                p.achieved(),
                i.estimate,
                i.low,
                i.high,
                p.falls(),
                p.episodes.len(),
                mean_cost_of_transport(&p.episodes),
                p.works()
            );
        }
    }
    csv
}
