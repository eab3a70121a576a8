//! The report's sections, each written into the document in the order a reader needs them.
use std::path::Path;

use anyhow::Result;

use super::anchors::{bundled_anchors, published_curve, Anchor};
use super::controller::{
    controller_pushes, controller_section, return_interval, ControllerSection, PushRow, GRID_STEP, PUSH_LEVELS,
};
use super::curves::{eval_curve, rolling};
use super::document::Document;
use super::format::{budget, fixed, fmt_return, interval, rate};
use super::heldout::{evaluate_row, BudgetRow, FEW_SEEDS};
use super::plots::{bands_svg, Band, Marker};
use super::runs::{Group, Run};
use super::{summarise, GroupSummary, ReportOptions, BOOTSTRAP_SEED, ROLLING_WINDOW};
use crate::envs::{make, EnvConfig};
use crate::evaluation::parallel::map_in_order;
use crate::evaluation::stats::{self, Verdict};
use crate::evaluation::{Protocol, Push};
use crate::io::write_bytes_atomic;
use crate::policy::RandomPolicy;

/// Points per curve in the charts.
const CURVE_POINTS: usize = 120;

pub fn protocol(doc: &mut Document, opts: &ReportOptions) {
    let p = &opts.protocol;
    doc.heading(1, "Protocol");
    doc.lines(vec![
        format!(
            "Every policy (trained agent or controller) plays the same {} held-out episodes per seed: reset seeds from \
             their own stream (protocol seed {}), checked disjoint from every run's training and in-training \
             evaluation seeds; the run's own env options and reward; deterministic actions.",
            p.episodes, p.seed
        ),
        "A row is one step budget: each run contributes the actor it saved when it passed that budget, never a \
         later one. Runs that reached the budget without a saved actor are listed under the table."
            .into(),
        "Return: mean and interquartile mean (IQM, Agarwal et al. 2021) of the per-seed mean returns, each with a 95% \
         percentile bootstrap interval over seeds (20,000 resamples, seeded). A row with one seed resamples its \
         episodes instead and says so (\"over: episodes\"). Spread, where shown, is the sample standard deviation."
            .into(),
        "Falls: episodes ended by a fall or a physics blow-up, with the 95% Wilson interval of the rate.".into(),
        format!(
            "Controller (Minitaur, Ant): commanded {GRID_STEP} m/s, {} m/s, ... up to the first speed with a fall or a \
             mean speed more than 10% off the command. Each learned row meets the controller commanded to reach the \
             row's own mean speed, on the same episodes; P(RL > controller) is the share of paired episodes the \
             learned policy scores higher on (ties count half), with the same kind of interval.",
            2.0 * GRID_STEP
        ),
        format!(
            "Pushes: once per episode, 2-6 s in, a sideways impulse that would change the whole robot's velocity by \
             Δv (spread over 0.1 s); {} episodes per level; survival = episodes without a fall.",
            opts.push_episodes
        ),
    ]);
}

/// Evaluation curves during training and their summary table.
pub(crate) fn learning_curves(
    doc: &mut Document,
    out: &Path,
    env: &str,
    groups: &[(&Group, &Vec<&Run>)],
) -> Result<Vec<GroupSummary>> {
    doc.heading(2, "Groups");
    doc.table(
        &["name", "runs", "algorithm, reward, settings (what differs from `locobench train --env E --algo A`)"],
        groups.iter().map(|(g, rs)| vec![g.label(), rs.len().to_string(), g.description()]).collect(),
    );
    doc.heading(2, "Learning curves (evaluation during training)");
    let summaries: Vec<GroupSummary> = groups.iter().map(|(g, rs)| summarise(g, rs)).collect();
    let mut bands = Vec::new();
    let mut markers = Vec::new();
    for (i, ((g, rs), s)) in groups.iter().zip(&summaries).enumerate() {
        let per_seed: Vec<Vec<(u64, f64)>> = rs.iter().map(|r| r.evals().collect()).collect();
        let curve = eval_curve(&per_seed);
        let (mut low, mut high) = (Vec::new(), Vec::new());
        for &step in &curve.steps {
            let values: Vec<f64> =
                per_seed.iter().filter_map(|p| p.iter().find(|(t, _)| *t == step).map(|(_, v)| *v)).collect();
            let ci = stats::stratified_bootstrap(&[values], |v| stats::mean(&v[0]), 2000, BOOTSTRAP_SEED ^ step);
            low.push(ci.low);
            high.push(ci.high);
        }
        let x = curve.steps.iter().map(|&x| x as f64).collect();
        bands.push(
            Band { label: format!("{} ({} seeds)", g.label(), s.seeds), x, mean: curve.mean.clone(), low, high }
                .thinned(CURVE_POINTS),
        );
        if let Some(c) = published_curve(env, &g.algo) {
            let reach = s.curve.steps.last().copied().unwrap_or(0);
            for (j, &step) in c.steps.iter().enumerate().filter(|(_, &st)| st <= reach.max(1)) {
                markers.push(Marker {
                    label: format!("{} published, mean ± std over {} seeds", g.algo, c.seeds),
                    x: step as f64,
                    y: c.mean[j],
                    low: c.mean[j] - c.std[j],
                    high: c.mean[j] + c.std[j],
                    color_of: i,
                });
            }
        }
    }
    let file = format!("{env}_evaluation.svg");
    let svg = bands_svg(
        &format!("{env}: evaluation return during training, mean and 95% interval over seeds"),
        "environment steps",
        "return",
        &bands,
        &markers,
    )?;
    write_bytes_atomic(&out.join(&file), svg.as_bytes())?;
    doc.figure(file, svg, "evaluation during training (the run's own evaluation seeds)");
    doc.table(
        &[
            "policy",
            "seeds",
            "evaluation episodes",
            "last common step",
            "evaluation there (mean ± sample std over seeds)",
            "normalised AUC",
            "wall time (min)",
        ],
        summaries
            .iter()
            .zip(groups)
            .map(|(s, (_, rs))| {
                let finals: Vec<f64> = rs
                    .iter()
                    .filter_map(|r| {
                        s.curve.last().and_then(|(t, _, _)| r.evals().find(|(u, _)| *u == t).map(|(_, v)| v))
                    })
                    .collect();
                let mut episodes: Vec<usize> = rs.iter().map(|r| r.config.train.eval_episodes).collect();
                episodes.dedup();
                vec![
                    s.group.label(),
                    s.seeds.to_string(),
                    episodes.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("/"),
                    s.curve.last().map_or("–".into(), |(t, _, _)| budget(t)),
                    format!("{} ± {}", fmt_return(stats::mean(&finals)), fmt_return(stats::sample_std(&finals))),
                    fmt_return(s.auc),
                    fixed(s.wall_time / 60.0, 1),
                ]
            })
            .collect(),
    );
    Ok(summaries)
}

/// The held-out rows of every group at every budget its runs reached.
pub fn held_out(
    doc: &mut Document,
    groups: &[(&Group, &Vec<&Run>)],
    opts: &ReportOptions,
    externals: &[crate::evaluation::external::External],
) -> Result<Vec<BudgetRow>> {
    doc.heading(2, "Held-out evaluation at fixed budgets");
    let jobs: Vec<(&Group, &Vec<&Run>, u64)> =
        groups.iter().flat_map(|(g, rs)| super::budgets::budgets(rs).into_iter().map(move |b| (*g, *rs, b))).collect();
    let mut rows =
        map_in_order(&jobs, opts.threads, |(g, rs, b)| evaluate_row(g, rs, *b, &opts.protocol, None, &opts.cache))?;
    if !externals.is_empty() {
        // Each external row joins the group played under its options and reward.
        let mut envs: Vec<EnvConfig> = Vec::new();
        for cfg in rows.iter().filter_map(|r| r.env_config.clone()) {
            if !envs.contains(&cfg) {
                envs.push(cfg);
            }
        }
        if envs.is_empty() {
            envs.push(EnvConfig::new(&groups[0].0.env));
        }
        rows.extend(BudgetRow::external_rows(externals, &envs, &opts.protocol)?);
    }
    let mut notes = Vec::new();
    let table = rows
        .iter()
        .map(|r| {
            let (falls, n) = r.falls();
            let (m, q) = (r.mean_return(BOOTSTRAP_SEED), r.iqm_return(BOOTSTRAP_SEED));
            if r.seeds() > 0 && r.seeds() < FEW_SEEDS {
                notes.push(format!(
                    "{} at {}: {} seed(s) with a policy, fewer than {FEW_SEEDS}; the interval is rough.",
                    r.group.label(),
                    budget(r.budget),
                    r.seeds()
                ));
            }
            if !r.duplicate_seeds.is_empty() {
                notes.push(format!(
                    "{} at {}: seed(s) {:?} appear in more than one run; those runs are not independent samples.",
                    r.group.label(),
                    budget(r.budget),
                    r.duplicate_seeds
                ));
            }
            if r.external {
                notes.push(format!(
                    "{}: from the episodes in {} ({}); the same statistics, computed here from those episodes.",
                    r.group.label(),
                    r.evaluated.iter().map(|s| format!("`{}`", s.run_dir.display())).collect::<Vec<_>>().join(", "),
                    r.provenance
                ));
            } else if r.mixed_provenance {
                notes.push(format!(
                    "{} at {}: pools runs computed on different machines or commits ({}).",
                    r.group.label(),
                    budget(r.budget),
                    r.provenance
                ));
            }
            for (dir, why) in &r.missing {
                notes.push(format!("{} at {}: `{}`: {why}.", r.group.label(), budget(r.budget), dir.display()));
            }
            if r.seeds() == 0 {
                return vec![
                    r.group.label(),
                    budget(r.budget),
                    "0".into(),
                    "–".into(),
                    "no policy at this budget (see below)".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                ];
            }
            vec![
                r.group.label(),
                budget(r.budget),
                format!("{} of {}", r.seeds(), r.seeds() + r.missing.len()),
                r.episodes_per_seed().to_string(),
                interval(m.interval, fmt_return),
                interval(q.interval, fmt_return),
                m.over.to_string(),
                rate(falls, n),
                fixed(r.speed(), 3),
                fixed(r.cost_of_transport(), 2),
                r.wall_time.map_or("–".into(), |w| fixed(w / 60.0, 0)),
                r.provenance.clone(),
            ]
        })
        .collect();
    doc.table(
        &[
            "policy",
            "budget",
            "seeds",
            "episodes per seed",
            "return: mean [95% CI]",
            "IQM [95% CI]",
            "over",
            "falls (95% CI)",
            "speed m/s",
            "CoT",
            "minutes to budget",
            "machine",
        ],
        table,
    );
    if !notes.is_empty() {
        doc.lines(notes);
    }
    // What no learning scores under the same protocol.
    let env_config = reference_env(&groups[0].0.env, &rows)?;
    let key = crate::evaluation::cache::Key::episodes(&env_config, &opts.protocol, "random 0", None, None)?;
    let random = opts.cache.episodes(&key, || {
        let mut env = make(&env_config)?;
        opts.protocol.run(env.as_mut(), &mut RandomPolicy::new(0), None, None)
    })?;
    let returns: Vec<f64> = random.iter().map(|e| e.episode_return).collect();
    let ci = stats::stratified_bootstrap(&[returns], |v| stats::mean(&v[0]), stats::BOOTSTRAP_REPS, BOOTSTRAP_SEED);
    doc.paragraph(format!(
        "Uniform random actions on the same episodes: return {} (95% CI over {} episodes), falls {}.",
        interval(ci, fmt_return),
        random.len(),
        rate(random.iter().filter(|e| e.fell).count(), random.len())
    ));
    Ok(rows)
}

/// Our runs measured as the anchor was: per comparable group, each seed's value; a group with
/// other settings than the shipped ones says which.
fn ours_same_measure(anchor: &Anchor, groups: &[(&Group, &Vec<&Run>)]) -> String {
    if !anchor.is_measurable() {
        return "–".into();
    }
    let mut parts = Vec::new();
    for (g, runs) in groups {
        let values: Vec<f64> = runs.iter().filter(|r| anchor.comparable(r)).filter_map(|r| anchor.measure(r)).collect();
        if values.is_empty() {
            continue;
        }
        let name = if g.settings.is_empty() { g.label() } else { format!("{} ({})", g.label(), g.settings) };
        let each = values.iter().map(|&v| fmt_return(v)).collect::<Vec<_>>().join(", ");
        parts.push(if values.len() == 1 {
            format!("{name}: {each} (1 seed)")
        } else {
            format!("{name}: mean {} ({each}; {} seeds)", fmt_return(stats::mean(&values)), values.len())
        });
    }
    if parts.is_empty() {
        "no run of ours at this budget with these options".into()
    } else {
        parts.join("; ")
    }
}

/// Published results at our budgets, with a verdict from the two intervals; anchors measured on
/// training episodes beside ours measured the same way.
pub fn published(doc: &mut Document, env: &str, rows: &[BudgetRow], groups: &[(&Group, &Vec<&Run>)]) {
    let mut table = Vec::new();
    for r in rows.iter().filter(|r| r.seeds() > 0 && r.group.settings.is_empty()) {
        let Some(c) = published_curve(env, &r.group.algo) else { continue };
        let Some((mean, std)) = c.at(r.budget) else { continue };
        let ours = r.mean_return(BOOTSTRAP_SEED);
        // Their mean's 95% interval from mean ± std over n seeds (normal approximation).
        let half = 1.96 * std / (c.seeds as f64).sqrt();
        let verdict = Verdict::of(ours.interval, mean - half, mean + half);
        table.push(vec![
            r.group.label(),
            budget(r.budget),
            format!(
                "{} ({} seeds x {} episodes, over {})",
                interval(ours.interval, fmt_return),
                r.seeds(),
                r.episodes_per_seed(),
                ours.over
            ),
            format!("{} ± {}", fmt_return(mean), fmt_return(std)),
            c.seeds.to_string(),
            format!("[{}, {}]", fmt_return(mean - half), fmt_return(mean + half)),
            verdict.word().to_string(),
            c.source.clone(),
        ]);
    }
    let anchors: Vec<_> = bundled_anchors().into_iter().filter(|a| a.env == env).collect();
    if table.is_empty() && anchors.is_empty() {
        return;
    }
    doc.heading(2, "Published results");
    if !table.is_empty() {
        doc.paragraph(
            "At the same budget. Verdict: below or above when our 95% interval and the published mean's (mean ± 1.96 \
             std / sqrt(seeds)) do not overlap, else inside. Published runs use older Gym/Gymnasium versions of the \
             models (named in the source); compare magnitudes, not decimals.",
        );
        doc.table(
            &[
                "policy",
                "budget",
                "ours: mean [95% CI]",
                "published mean ± std",
                "seeds",
                "published 95% CI",
                "verdict",
                "source",
            ],
            table,
        );
    }
    if !anchors.is_empty() {
        if env == "minitaur" {
            doc.paragraph(
                "Minitaur anchors come from PyBullet's MinitaurBulletEnv-v0, whose reward this env reproduces on MuJoCo \
                 physics (contacts, motors and friction differ): they place our numbers, they do not grade them. \
                 PyBullet registers a reward threshold of 15 for the env (about 1.5 m/s held for 10 s).",
            );
        }
        doc.paragraph(
            "Where a source says how its number was measured (a mean of training-episode returns, the stochastic \
             policy while it learns; or a deterministic evaluation at the budget), the last column measures our \
             runs of that algorithm with the source's environment options the same way, per seed (a deterministic \
             evaluation: the run's own in-training evaluation there), naming the settings where they differ from our \
             shipped ones; held-out results are in the tables above.",
        );
        doc.table(
            &["algorithm", "steps", "return", "spread", "seeds", "source", "ours, same measure (per seed)"],
            anchors
                .iter()
                .map(|a| {
                    vec![
                        a.algo.clone(),
                        budget(a.steps),
                        fmt_return(a.value),
                        a.std.map_or("–".into(), fmt_return),
                        a.seeds.map_or("not stated".into(), |s| s.to_string()),
                        format!("{}{}", a.source, a.spread.as_ref().map_or(String::new(), |s| format!("; ± over {s}"))),
                        ours_same_measure(a, groups),
                    ]
                })
                .collect(),
        );
    }
}

/// Whether `row` was trained under `options` (resolved); None when the row has no env (no policy
/// was evaluated).
fn trained_under(row: &BudgetRow, options: &toml::Table) -> Option<bool> {
    row.env_config.as_ref().map(|c| c.resolved_options().ok().as_ref() == Some(options))
}

/// The env the controller and the random policy play, with its options resolved: the env's
/// defaults where any learned row was trained on them, else the first row's options and reward.
/// Rows trained under other options are then not compared with the controller. Taking the first
/// row alone would let a group's name, which orders the rows, decide that env (and its control
/// rate).
fn reference_env(env: &str, rows: &[BudgetRow]) -> Result<EnvConfig> {
    let defaults = EnvConfig::new(env).resolved_options()?;
    if rows.iter().any(|r| trained_under(r, &defaults) == Some(true)) {
        return Ok(EnvConfig { name: env.to_string(), options: defaults });
    }
    let first = rows.iter().find_map(|r| r.env_config.clone()).unwrap_or_else(|| EnvConfig::new(env));
    Ok(EnvConfig { options: first.resolved_options()?, ..first })
}

/// The controller's grid, the learned rows against it, and pushes.
pub fn controller(
    doc: &mut Document,
    out: &Path,
    env: &str,
    groups: &[(&Group, &Vec<&Run>)],
    rows: &[BudgetRow],
    opts: &ReportOptions,
) -> Result<Option<ControllerSection>> {
    let env_config = reference_env(env, rows)?;
    let same_env = |r: &BudgetRow| trained_under(r, &env_config.options).unwrap_or(true);
    let comparable: Vec<&BudgetRow> = rows.iter().filter(|r| same_env(r)).collect();
    let mut section =
        controller_section(&env_config, rows, same_env, &opts.protocol, BOOTSTRAP_SEED, opts.threads, &opts.cache)?;

    doc.heading(2, "Controller across commanded speeds");
    doc.table(
        &["commanded m/s", "achieved m/s", "return: mean [95% CI over episodes]", "falls (95% CI)", "CoT", "works"],
        section
            .grid
            .iter()
            .map(|p| {
                vec![
                    fixed(p.commanded, 2),
                    fixed(p.achieved(), 3),
                    interval(return_interval(p), fmt_return),
                    rate(p.falls(), p.episodes.len()),
                    fixed(crate::controller::measure::mean_cost_of_transport(&p.episodes), 2),
                    if p.works() {
                        "yes".into()
                    } else if p.falls() > 0 {
                        "no (falls)".into()
                    } else {
                        format!("no (tracking error {:.0}%)", 100.0 * p.tracking_error())
                    },
                ]
            })
            .collect(),
    );
    match &section.best {
        Some(b) => doc.paragraph(format!(
            "Best return: {} at {:.2} m/s commanded ({:.3} m/s achieved).",
            interval(return_interval(b), fmt_return),
            b.commanded,
            b.achieved()
        )),
        None => doc.paragraph("The controller works at no speed of the grid."),
    }
    speed_charts(doc, out, env, &section, &comparable)?;

    doc.heading(2, "Learned policies against the controller");
    doc.table(
        &[
            "policy",
            "budget",
            "seeds",
            "episodes per seed",
            "speed m/s",
            "return [95% CI]",
            "controller at that speed: commanded → achieved",
            "controller return [95% CI]",
            "P(RL > controller there) [95% CI]",
            "P(RL > controller's best) [95% CI]",
            "falls RL / controller",
            "CoT RL / controller",
        ],
        section
            .matched
            .iter()
            .map(|m| {
                let r = &rows[m.row];
                let p = |e: &Option<super::heldout::Estimate>| {
                    e.map_or("–".into(), |e| format!("{} (over {})", interval(e.interval, |v| fixed(v, 2)), e.over))
                };
                let (falls, n) = r.falls();
                let (c_speed, c_return, c_falls, c_cot) = match &m.controller {
                    Ok(c) => (
                        format!("{:.3} → {:.3}", c.commanded, c.achieved()),
                        interval(return_interval(c), fmt_return),
                        rate(c.falls(), c.episodes.len()),
                        fixed(crate::controller::measure::mean_cost_of_transport(&c.episodes), 2),
                    ),
                    Err(why) => (why.clone(), "–".into(), "–".into(), "–".into()),
                };
                vec![
                    r.group.label(),
                    budget(r.budget),
                    r.seeds().to_string(),
                    r.episodes_per_seed().to_string(),
                    fixed(m.rl_speed, 3),
                    interval(r.mean_return(BOOTSTRAP_SEED).interval, fmt_return),
                    c_speed,
                    c_return,
                    p(&m.beats_matched),
                    p(&m.beats_best),
                    format!("{} / {c_falls}", rate(falls, n)),
                    format!("{} / {c_cot}", fixed(r.cost_of_transport(), 2)),
                ]
            })
            .collect(),
    );
    let skipped = rows.len() - comparable.len();
    if skipped > 0 {
        doc.paragraph(format!(
            "{skipped} row(s) trained under other env options or rewards than the first are not compared with the controller."
        ));
    }

    if opts.push_episodes > 0 {
        section.pushes = pushes(groups, rows, &env_config, &section, opts)?;
        doc.heading(2, "Pushes");
        let mut header = vec!["policy".to_string(), "speed m/s".to_string(), "episodes per level".to_string()];
        header.extend(PUSH_LEVELS.iter().map(|dv| format!("survived, Δv {dv} m/s (95% CI)")));
        let header: Vec<&str> = header.iter().map(String::as_str).collect();
        doc.table(
            &header,
            section
                .pushes
                .iter()
                .map(|p| {
                    let n = p.survived.first().map_or(0, |s| s.1);
                    let mut cells = vec![p.policy.clone(), fixed(p.speed, 3), n.to_string()];
                    cells.extend(p.survived.iter().map(|&(k, n)| rate(k, n)));
                    cells
                })
                .collect(),
        );
    }
    Ok(Some(section))
}

/// Push survival of the controller (at its best speed and at each pushed row's speed) and of
/// each algorithm's best row (highest mean held-out return) among those compared with the
/// controller.
fn pushes(
    groups: &[(&Group, &Vec<&Run>)],
    rows: &[BudgetRow],
    env_config: &crate::envs::EnvConfig,
    section: &ControllerSection,
    opts: &ReportOptions,
) -> Result<Vec<PushRow>> {
    let protocol = Protocol { episodes: opts.push_episodes, ..opts.protocol };
    let mut family = crate::evaluation::ControllerFamily::new(env_config, protocol)?;
    family.threads = opts.threads;
    family.disk = opts.cache.clone();
    // Each algorithm's best row, and the controller at its speed.
    let compared: std::collections::BTreeSet<usize> = section.matched.iter().map(|m| m.row).collect();
    let pushed_rows: Vec<(usize, &Group, &Vec<&Run>)> = super::videos::best_rows(rows, |i| compared.contains(&i))
        .into_iter()
        .filter_map(|i| groups.iter().find(|(g, _)| **g == rows[i].group).map(|(g, rs)| (i, *g, *rs)))
        .collect();
    let matched_speed = |i: usize| {
        section.matched.iter().find(|m| m.row == i).and_then(|m| m.controller.as_ref().ok()).map(|c| c.commanded)
    };
    let mut controller_jobs = Vec::new();
    for speed in
        section.best.iter().map(|b| b.commanded).chain(pushed_rows.iter().filter_map(|(i, _, _)| matched_speed(*i)))
    {
        controller_jobs.extend(PUSH_LEVELS.iter().map(|&dv| (speed, Some(Push::lateral(dv)))));
    }
    family.prefetch(&controller_jobs)?;
    let rl_jobs: Vec<(usize, f64)> =
        pushed_rows.iter().flat_map(|(i, _, _)| PUSH_LEVELS.iter().map(move |&dv| (*i, dv))).collect();
    let rl = map_in_order(&rl_jobs, opts.threads, |&(i, dv)| {
        let (_, g, rs) = pushed_rows.iter().find(|(j, _, _)| *j == i).unwrap();
        evaluate_row(g, rs, rows[i].budget, &protocol, Some(Push::lateral(dv)), &opts.cache).map(|r| r.falls())
    })?;
    let mut out = Vec::new();
    if let Some(b) = &section.best {
        out.push(controller_pushes(&mut family, b.commanded, "controller at its best speed".into())?);
    }
    for (k, (i, g, _)) in pushed_rows.iter().enumerate() {
        let row = &rows[*i];
        let survived =
            rl[k * PUSH_LEVELS.len()..(k + 1) * PUSH_LEVELS.len()].iter().map(|&(f, n)| (n - f, n)).collect();
        out.push(PushRow {
            policy: format!("{} at {} ({} seeds)", g.label(), budget(row.budget), row.seeds()),
            speed: row.speed(),
            survived,
        });
        if let Some(c) = matched_speed(*i) {
            out.push(controller_pushes(&mut family, c, format!("controller at the speed of {}", g.label()))?);
        }
    }
    Ok(out)
}

/// Return, cost of transport and fall rate against speed: the controller's grid as a line with
/// its interval, the learned rows as points with theirs.
fn speed_charts(
    doc: &mut Document,
    out: &Path,
    env: &str,
    section: &ControllerSection,
    rows: &[&BudgetRow],
) -> Result<()> {
    type Measure = fn(&[crate::controller::measure::GaitEpisode]) -> (f64, f64, f64);
    let ret: Measure = |eps| {
        let i = stats::stratified_bootstrap(
            &[eps.iter().map(|e| e.episode_return).collect()],
            |v| stats::mean(&v[0]),
            2000,
            BOOTSTRAP_SEED,
        );
        (i.estimate, i.low, i.high)
    };
    let cot: Measure = |eps| {
        let c = crate::controller::measure::mean_cost_of_transport(eps);
        (c, c, c)
    };
    let falls: Measure = |eps| {
        let w = stats::wilson(eps.iter().filter(|e| e.fell).count(), eps.len());
        (w.estimate, w.low, w.high)
    };
    for (name, y_label, measure) in
        [("return", "return", ret), ("cot", "cost of transport", cot), ("falls", "fall rate", falls)]
    {
        let grid: Vec<(f64, (f64, f64, f64))> =
            section.grid.iter().map(|p| (p.achieved(), measure(&p.episodes))).collect();
        let band = Band {
            label: "controller (commanded grid)".into(),
            x: grid.iter().map(|g| g.0).collect(),
            mean: grid.iter().map(|g| g.1 .0).collect(),
            low: grid.iter().map(|g| g.1 .1).collect(),
            high: grid.iter().map(|g| g.1 .2).collect(),
        };
        let markers: Vec<Marker> = rows
            .iter()
            .enumerate()
            .filter(|(_, r)| r.seeds() > 0)
            .map(|(i, r)| {
                let eps: Vec<_> = r.all_episodes().cloned().collect();
                let (y, low, high) = if name == "return" {
                    let e = r.mean_return(BOOTSTRAP_SEED).interval;
                    (e.estimate, e.low, e.high)
                } else {
                    measure(&eps)
                };
                Marker {
                    label: format!("{} at {}", r.group.label(), budget(r.budget)),
                    x: r.speed(),
                    y,
                    low,
                    high,
                    color_of: i + 1,
                }
            })
            .filter(|m| m.y.is_finite())
            .collect();
        let file = format!("{env}_speed_{name}.svg");
        let svg = bands_svg(&format!("{env}: {y_label} against speed"), "mean speed m/s", y_label, &[band], &markers)?;
        write_bytes_atomic(&out.join(&file), svg.as_bytes())?;
        // Shown from its file, not embedded: three per env would take most of the page's size.
        doc.image(file, format!("{y_label} against speed (95% intervals)"));
    }
    Ok(())
}

/// Training returns per group: each seed's rolling mean, thinned; linked, not embedded.
pub(crate) fn training_returns(
    doc: &mut Document,
    out: &Path,
    env: &str,
    groups: &[(&Group, &Vec<&Run>)],
) -> Result<()> {
    doc.heading(2, "Training returns");
    for (g, rs) in groups {
        let bands: Vec<Band> = rs
            .iter()
            .map(|r| {
                let (x, y): (Vec<f64>, Vec<f64>) = r.episodes().map(|(s, v)| (s as f64, v)).unzip();
                let (mean, _) = rolling(&y, ROLLING_WINDOW);
                Band { label: format!("seed {}", r.config.seed), x, low: mean.clone(), high: mean.clone(), mean }
                    .thinned(CURVE_POINTS * 2)
            })
            .collect();
        let file = format!("{env}_{}_training.svg", file_stem(g));
        let title = format!("{env} {}: {ROLLING_WINDOW}-episode rolling mean of training returns", g.label());
        let svg = bands_svg(&title, "environment steps", "episode return", &bands, &[])?;
        write_bytes_atomic(&out.join(&file), svg.as_bytes())?;
        doc.linked_figure(file, format!("training returns: {}", g.label()));
    }
    Ok(())
}

/// A short file name for a group: algorithm, then a hash of its reward and settings when they
/// differ from the defaults (the label says what they are).
fn file_stem(g: &Group) -> String {
    if g.is_default_setting() {
        return g.algo.clone();
    }
    let text = format!("{}|{}", g.reward, g.settings);
    let hash = super::fnv1a(text.bytes());
    format!("{}-{:08x}", g.algo, hash as u32)
}

pub fn runs(doc: &mut Document, runs: &[Run]) {
    doc.heading(1, "Appendix: the runs");
    doc.lines(
        runs.iter()
            .map(|r| {
                let mut held = crate::train::budget_policy_steps(&r.dir);
                held.extend(super::budgets::shipped_step(&r.dir));
                held.sort_unstable();
                let policies = if held.is_empty() {
                    "no policy kept".to_string()
                } else {
                    format!("policies at {}", held.iter().map(|&s| budget(s)).collect::<Vec<_>>().join(", "))
                };
                if let Some(x) = &r.imported {
                    let file =
                        if x.model_file.is_empty() { "no model file stated".into() } else { x.model_file.clone() };
                    let sha =
                        if x.model_sha256.is_empty() { String::new() } else { format!(", SHA-256 {}", x.model_sha256) };
                    let steps = super::budgets::shipped_step(&r.dir)
                        .map_or("its training steps not stated".into(), |s| format!("trained for {}", budget(s)));
                    return format!(
                        "`{}`: {}, imported from {} ({file}{sha}), {steps}",
                        r.dir.display(),
                        r.group().label(),
                        x.library
                    );
                }
                format!(
                    "`{}`: {} seed {}, reached {}, {policies}; {}",
                    r.dir.display(),
                    r.group().label(),
                    r.config.seed,
                    budget(super::budgets::reached(r)),
                    super::heldout::machine_of(r, u64::MAX)
                )
            })
            .collect(),
    );
}

/// The clips of one env's best rows (`report --videos`), under a heading.
pub(crate) fn gaits(
    doc: &mut Document,
    out: &Path,
    env: &str,
    groups: &[(&Group, &Vec<&Run>)],
    rows: &[BudgetRow],
    section: Option<&ControllerSection>,
    opts: &ReportOptions,
) -> Result<Vec<super::videos::Clip>> {
    use super::videos::ControllerSpeed;
    let speed = |i: usize| {
        let s = section?;
        let compared = s.matched.iter().find(|m| m.row == i);
        match compared.and_then(|m| m.controller.as_ref().ok()) {
            Some(c) => Some(ControllerSpeed::Matched(c.commanded)),
            None if compared.is_none() => s.best.as_ref().map(|b| ControllerSpeed::Unmatched(b.commanded)),
            None => s.best.as_ref().map(|b| ControllerSpeed::Best(b.commanded)),
        }
    };
    let best = super::videos::best_rows(rows, |i| !rows[i].external);
    let plans = super::videos::plan(env, rows, &best, &speed, section.is_some() && opts.push_episodes > 0);
    if plans.is_empty() {
        return Ok(Vec::new());
    }
    let clips = super::videos::film(&plans, groups, out, &opts.protocol, opts.threads, &opts.cache)?;
    doc.heading(2, "Gaits");
    doc.paragraph(format!(
        "Per algorithm, its best row's policy (the row with the highest lower 95% bound of its mean return; the \
         seed with the row's median return) on the first held-out episode{}. Captions in the frame: step, return and mean forward speed so far. The GIFs show at most \
         {} s at {} frames/s (from a second before the push, or else ending half a second after a fall, or else the first \
         seconds); the videos show the whole episode.",
        if section.is_some() {
            ", beside the controller commanded to the row's speed, and the pair under a push"
        } else {
            ""
        },
        super::videos::GIF_SECONDS,
        super::videos::GIF_FPS
    ));
    for clip in &clips {
        doc.video(clip);
    }
    Ok(clips)
}

/// What the first screen says about one env: who wins, at which speed and by how much, from the
/// numbers of the tables below, and the best learned policy's clip.
pub(crate) fn summary(
    env: &str,
    rows: &[BudgetRow],
    section: Option<&ControllerSection>,
    clips: &[super::videos::Clip],
) -> Vec<super::document::Block> {
    use super::document::Block;
    let est = |r: &BudgetRow| r.mean_return(BOOTSTRAP_SEED);
    let describe = |r: &BudgetRow| {
        let (falls, n) = r.falls();
        // A return on another reward than the env's default is not comparable with the others':
        // say so where it is named. A command task's rows are all played on its default reward
        // (`heldout::evaluation_env`), so there only the training reward is named.
        let reward = if r.group.has_default_reward() || r.group.reward.is_empty() {
            String::new()
        } else if crate::envs::command::is_command_task(env) {
            format!("; trained on {}, return on the task's default reward", r.group.reward)
        } else {
            format!("; its own reward, {}", r.group.reward)
        };
        format!(
            "{} at {} ({} seed{}{reward}): return {} at {} m/s, falls {}",
            r.group.label(),
            budget(r.budget),
            r.seeds(),
            if r.seeds() == 1 { "" } else { "s" },
            interval(est(r).interval, fmt_return),
            fixed(r.speed(), 2),
            rate(falls, n)
        )
    };
    let mut ranked = super::videos::best_rows(rows, |_| true);
    let key = |i: usize| super::videos::rank_key(&rows[i]);
    ranked.sort_by(|&a, &b| key(b).partial_cmp(&key(a)).unwrap_or(std::cmp::Ordering::Equal));
    let mut text = format!("{env}: ");
    let Some(&top) = ranked.first() else {
        text.push_str("No run kept a policy, so nothing was evaluated on the held-out episodes; learning curves only.");
        return vec![Block::Paragraph(text)];
    };
    let row = &rows[top];
    let winner_clip = clips.iter().find(|c| c.stem == format!("{env}_{}", row.group.algo));
    match section.and_then(|s| s.best.as_ref().map(|b| (s, b))) {
        Some((s, controller_best)) => {
            let c = return_interval(controller_best);
            let (cf, cn) = (controller_best.falls(), controller_best.episodes.len());
            let learned = est(row).interval;
            let (winner, by) = if learned.estimate >= c.estimate {
                (format!("{} at {}", row.group.label(), budget(row.budget)), learned.estimate - c.estimate)
            } else {
                ("the controller".to_string(), c.estimate - learned.estimate)
            };
            let separated = learned.low > c.high || c.low > learned.high;
            text.push_str(&format!(
                "Best learned (the highest lower bound): {}. The controller's best: {} at {} m/s commanded ({} achieved), falls {}. \
                 Higher mean return: {winner}, by {}{}.",
                describe(row),
                interval(c, fmt_return),
                fixed(controller_best.commanded, 2),
                fixed(controller_best.achieved(), 2),
                rate(cf, cn),
                fmt_return(by),
                if separated { " (the 95% intervals do not overlap)" } else { " (the 95% intervals overlap)" }
            ));
            if let Some(m) = s.matched.iter().find(|m| m.row == top) {
                if let (Ok(cp), Some(p)) = (&m.controller, &m.beats_matched) {
                    text.push_str(&format!(
                        " At the learned policy's speed the controller (commanded {} m/s, achieved {}) returns {}, \
                         falls {}; the learned policy scores higher on {} of the paired episodes.",
                        fixed(cp.commanded, 2),
                        fixed(cp.achieved(), 2),
                        interval(return_interval(cp), fmt_return),
                        rate(cp.falls(), cp.episodes.len()),
                        interval(p.interval, |v| format!("{:.0}%", 100.0 * v))
                    ));
                }
            }
        }
        None if section.is_some() => {
            text.push_str(&format!(
                "Best learned: {}. The controller works at none of its commanded speeds here (its table below).",
                describe(row)
            ));
        }
        None => {
            text.push_str(&format!("Best learned: {}.", describe(row)));
        }
    }
    let mut blocks = vec![Block::Paragraph(text)];
    if ranked.len() > 1 {
        // Every algorithm's own best row, so a reader sees where each stands, not only the winner;
        // where a controller is compared, a row trained under other env options or rewards says
        // that its return is not on the controller's scale.
        let apart = |i: usize| section.is_some_and(|s| !s.matched.iter().any(|m| m.row == i));
        blocks.push(Block::Paragraph(format!(
            "{env}, each algorithm at its best row (the highest lower 95% bound of its held-out return):"
        )));
        blocks.push(Block::Lines(
            ranked
                .iter()
                .map(|&i| {
                    let line = describe(&rows[i]);
                    if apart(i) {
                        line + " (trained under other env options or rewards than the controller's: not compared with it)"
                    } else {
                        line
                    }
                })
                .collect(),
        ));
    }
    blocks.extend(winner_clip.map(Block::clip));
    blocks
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(algo: &str, overrides: &str) -> BudgetRow {
        let group = Group {
            env: "minitaur".into(),
            algo: algo.into(),
            reward: String::new(),
            settings: String::new(),
            variant: String::new(),
        };
        let mut row = BudgetRow::empty(group, 100_000);
        let pairs = crate::envs::parse_overrides(overrides).unwrap();
        row.env_config = Some(EnvConfig::new("minitaur").with_overrides(&pairs).unwrap().for_evaluation());
        row
    }

    #[test]
    fn the_controller_plays_the_default_env_when_any_row_trained_on_it() {
        let defaults = EnvConfig::new("minitaur").resolved_options().unwrap();
        // A 50 Hz group whose name sorts first does not move the controller to 50 Hz.
        let rows = [row("crossq", "action_repeat=10,max_episode_steps=500"), row("ppo", "")];
        let chosen = reference_env("minitaur", &rows).unwrap();
        assert_eq!(chosen.name, "minitaur");
        assert_eq!(chosen.options, defaults);
        // With no row on the defaults, the first row's options (resolved) are the controller's.
        let rows = [row("sac", "action_repeat=10,max_episode_steps=500"), row("td3", "energy_weight=0")];
        let chosen = reference_env("minitaur", &rows).unwrap();
        assert_eq!(chosen.options, rows[0].env_config.as_ref().unwrap().resolved_options().unwrap());
        assert_ne!(chosen.options, defaults);
        // No row with an env: the defaults.
        assert_eq!(reference_env("minitaur", &[]).unwrap().options, defaults);
    }
}
