//! Sections quoting the evaluation report's CSV files (`bash benches/report.sh` writes them).
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;

use super::csv_rows::{read, Row};
use locobench::evaluation::stats::Interval;
use locobench::report::format::{budget, fixed, fmt_return, interval, rate};
use locobench::report::{CONTROLLER_CSV, CURVES_CSV, HELD_OUT_CSV, VERSUS_CONTROLLER_CSV};

fn ci(r: &Row, estimate: &str, low: &str, high: &str) -> String {
    interval(Interval { estimate: r.num(estimate), low: r.num(low), high: r.num(high) }, fmt_return)
}

fn probability(r: &Row, prefix: &str) -> String {
    let i = Interval {
        estimate: r.num(&format!("p_beats_{prefix}")),
        low: r.num(&format!("p_{prefix}_low")),
        high: r.num(&format!("p_{prefix}_high")),
    };
    if i.estimate.is_nan() {
        "–".into()
    } else {
        interval(i, |v| fixed(v, 2))
    }
}

/// A held-out row's cells: seeds × episodes, return [95% CI], falls, speed.
fn held_out_cells(r: &Row) -> String {
    format!(
        "{} × {} | {} | {} | {}",
        r.count("seeds"),
        r.count("episodes_per_seed"),
        ci(r, "mean", "mean_low", "mean_high"),
        rate(r.count("falls"), r.count("episodes")),
        fixed(r.num("speed"), 2),
    )
}

/// The controller's best working speed per env: (env, row).
fn controller_best(rows: &[Row]) -> Vec<(String, &Row)> {
    let mut best: Vec<(String, &Row)> = Vec::new();
    for r in rows.iter().filter(|r| r.text("works") == "true") {
        let env = r.text("env").to_string();
        match best.iter_mut().find(|(e, _)| *e == env) {
            Some((_, b)) if r.num("mean") > b.num("mean") => *b = r,
            Some(_) => {}
            None => best.push((env, r)),
        }
    }
    best
}

/// README's results at a glance: every budget row with a policy, beside the controller.
pub(crate) fn glance(report: &Path) -> Result<String> {
    let held_out = read(&report.join(HELD_OUT_CSV))?;
    let versus = read(&report.join(VERSUS_CONTROLLER_CSV))?;
    let controller = read(&report.join(CONTROLLER_CSV))?;
    let best = controller_best(&controller);
    let mut out = String::from(
        "| env | policy | steps | seeds × episodes | return [95% CI] | falls | speed (m/s) | controller at that speed | P(policy > controller there) |\n\
         |---|---|---|---|---|---|---|---|---|\n",
    );
    let mut env_seen = String::new();
    for r in held_out.iter().filter(|r| r.count("seeds") > 0) {
        let env = r.text("env");
        if env != env_seen {
            env_seen = env.to_string();
            if let Some((_, b)) = best.iter().find(|(e, _)| e == env) {
                let _ = writeln!(
                    out,
                    "| {env} | controller, best speed ({} m/s commanded) | – | 1 × {} | {} | {} | {} | – | – |",
                    fixed(b.num("commanded"), 2),
                    b.count("episodes"),
                    ci(b, "mean", "mean_low", "mean_high"),
                    rate(b.count("falls"), b.count("episodes")),
                    fixed(b.num("achieved"), 2),
                );
            }
        }
        let matched = versus.iter().find(|v| {
            v.text("env") == env && v.text("policy") == r.text("policy") && v.text("budget") == r.text("budget")
        });
        let (controller_there, p) = match matched {
            Some(v) if v.text("note").is_empty() => (
                format!(
                    "{} ({} falls)",
                    ci(v, "controller_mean", "controller_low", "controller_high"),
                    v.count("controller_falls")
                ),
                probability(v, "matched"),
            ),
            Some(v) => (v.text("note").to_string(), format!("vs its best: {}", probability(v, "best"))),
            None => ("–".into(), "–".into()),
        };
        let _ = writeln!(
            out,
            "| {env} | {} | {} | {} | {controller_there} | {p} |",
            r.text("policy"),
            budget(r.num("budget") as u64),
            held_out_cells(r),
        );
    }
    Ok(out)
}

/// The rules for keeping an actor at each budget that docs/training.md compares on the Minitaur,
/// and one training change under the 20-episode rule: (the report's row label, the rule in words).
/// The runs are `benches/results/minitaur/LABEL-seedN`.
pub(crate) const MINITAUR_SELECTION: [(&str, &str); 9] = [
    ("td3-combined-ln", "TD3, layer-normalised critics: the actor at that step"),
    ("td3-combined-ln-best", "TD3, layer-normalised critics: highest minimum of 10 fixed starts"),
    ("td3-combined-ln-best20", "TD3, layer-normalised critics: highest minimum of 20 fixed starts"),
    (
        "td3-combined-ln-best20-fric1.2",
        "TD3, layer-normalised critics, trained on feet 1.2 times as grippy: highest minimum of 20 fixed starts",
    ),
    ("td3-combined-ln-best50", "TD3, layer-normalised critics: highest minimum of 50 fixed starts"),
    ("td3-combined-ln-ff50", "TD3, layer-normalised critics: fewest falls of 50 fixed starts"),
    ("crossq-td3-combined-best20", "TD3's actor on CrossQ's critics: highest minimum of 20 fixed starts"),
    ("crossq-combined", "CrossQ: the actor at that step"),
    ("crossq-combined-fresh20", "CrossQ: highest minimum of 20 fresh starts per evaluation"),
];

/// The report's held-out rows of the runs that compare ways of keeping an actor
/// (`MINITAUR_SELECTION`), at 300k and 500k steps.
pub(crate) fn minitaur_selection(report: &Path) -> Result<String> {
    let held_out = read(&report.join(HELD_OUT_CSV))?;
    let mut out = String::from(
        "| budget | runs | kept actor | seeds × episodes | return [95% CI] | falls | speed (m/s) |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for step in [300_000u64, 500_000] {
        for (label, rule) in MINITAUR_SELECTION {
            let row = held_out
                .iter()
                .find(|r| r.text("env") == "minitaur" && r.text("policy") == label && r.num("budget") as u64 == step);
            let Some(r) = row.filter(|r| r.count("seeds") > 0) else { continue };
            let _ = writeln!(out, "| {} | `{label}-seed*` | {rule} | {} |", budget(step), held_out_cells(r));
        }
    }
    Ok(out)
}

/// Evaluation during training at the published curves' marks, ours beside theirs.
pub fn curves(report: &Path) -> Result<String> {
    let rows = read(&report.join(CURVES_CSV))?;
    let mut out = String::from(
        "| env | policy | steps | runs × evaluation episodes (their seeds) | ours: mean [95% CI over runs] | sample std | published: mean ± std (seeds) | ours against the published band |\n\
         |---|---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let (pm, ps) = (r.num("published_mean"), r.num("published_std"));
        let (published, verdict) = if pm.is_nan() {
            ("–".to_string(), "no published curve".to_string())
        } else {
            let mean = r.num("mean");
            let verdict = if mean < pm - ps {
                "below"
            } else if mean > pm + ps {
                "above"
            } else {
                "inside"
            };
            // Columns absent from reports written before the column existed read as "".
            let verdict = if r.text("published_other_settings") == "true" {
                format!("{verdict} (ours with other agent settings than the source's)")
            } else {
                verdict.to_string()
            };
            (format!("{} ± {} ({})", fmt_return(pm), fmt_return(ps), r.text("published_seeds")), verdict)
        };
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} × {} ({}) | {} | {} | {published} | {verdict} |",
            r.text("env"),
            r.text("policy"),
            budget(r.num("step") as u64),
            r.count("seeds"),
            r.text("evaluation_episodes"),
            r.text("seed_values"),
            if r.count("seeds") > 1 { ci(r, "mean", "low", "high") } else { fmt_return(r.num("mean")) },
            fmt_return(r.num("sample_std")),
        );
    }
    Ok(out)
}

/// The controller over its grid of commanded speeds.
pub fn controller(report: &Path) -> Result<String> {
    let rows = read(&report.join(CONTROLLER_CSV))?;
    let mut out = String::from(
        "| env | commanded (m/s) | achieved (m/s) | return [95% CI over episodes] | falls (95% CI) | cost of transport | works |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for r in &rows {
        let works = if r.text("works") == "true" { "yes" } else { "no" };
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} | {} | {works} |",
            r.text("env"),
            fixed(r.num("commanded"), 2),
            fixed(r.num("achieved"), 3),
            ci(r, "mean", "mean_low", "mean_high"),
            rate(r.count("falls"), r.count("episodes")),
            fixed(r.num("cost_of_transport"), 2),
        );
    }
    Ok(out)
}
