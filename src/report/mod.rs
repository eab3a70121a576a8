//! `locobench report`: learning curves across seeds, training-return curves, and the baseline
//! controller against trained agents, as `index.html` (self-contained, no network) and
//! `README.md` with SVG charts beside them.
pub mod anchors;
pub mod compare;
pub mod curves;
pub mod document;
pub mod plots;
pub mod runs;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::controller::measure::{summary_cells, SUMMARY_COLUMNS};
use crate::io::write_bytes_atomic;
use compare::{compare, ComparisonRow};
use curves::{eval_curve, mean_std, rolling, EvalCurve};
use document::Document;
use plots::{bands_svg, Band, Marker};
use runs::{find_runs, Group, Run};

/// Episodes per seed of the training-return rolling statistics.
pub const ROLLING_WINDOW: usize = 50;

#[derive(Debug, Clone)]
pub struct ReportOptions {
    /// Episodes per policy and reward in the baseline comparison (0 skips it).
    pub compare_episodes: usize,
    pub seed: u64,
    /// Speed set-point of the baseline controller per env (m/s).
    pub baseline_speed: BTreeMap<String, f64>,
}

impl Default for ReportOptions {
    fn default() -> Self {
        ReportOptions {
            compare_episodes: 5,
            seed: 0,
            baseline_speed: [("minitaur".to_string(), 0.35), ("ant".to_string(), 0.5)].into_iter().collect(),
        }
    }
}

/// One group of seeds' summary line.
#[derive(Debug, Clone)]
pub struct GroupSummary {
    pub group: Group,
    pub curve: EvalCurve,
    pub seeds: usize,
    pub final_mean: f64,
    pub final_std: f64,
    pub auc: f64,
    pub wall_time: f64,
    pub steps: u64,
}

pub struct Report {
    pub index: PathBuf,
    pub readme: PathBuf,
    pub groups: Vec<GroupSummary>,
    pub comparisons: BTreeMap<String, Vec<ComparisonRow>>,
}

/// Returns span from about 0.01 (short Minitaur episodes) to 10,000 (HalfCheetah): more
/// decimals below 1.
pub fn fmt_return(v: f64) -> String {
    match v.abs() {
        a if !a.is_finite() => "–".into(),
        a if a < 1.0 => format!("{v:.3}"),
        a if a < 1000.0 => format!("{v:.1}"),
        _ => format!("{v:.0}"),
    }
}

fn fmt(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "–".into()
    }
}

/// Groups runs by (env, algorithm, reward), sorted.
pub fn group_runs(runs: &[Run]) -> BTreeMap<Group, Vec<&Run>> {
    let mut groups: BTreeMap<Group, Vec<&Run>> = BTreeMap::new();
    for r in runs {
        groups.entry(r.group()).or_default().push(r);
    }
    groups
}

pub fn summarise(group: &Group, runs: &[&Run]) -> GroupSummary {
    let curve = eval_curve(&runs.iter().map(|r| r.evals().collect()).collect::<Vec<_>>());
    let (_, final_mean, final_std) = curve.last().unwrap_or((0, f64::NAN, f64::NAN));
    GroupSummary {
        group: group.clone(),
        seeds: runs.len(),
        final_mean,
        final_std,
        auc: curve.normalised_auc().unwrap_or(f64::NAN),
        wall_time: mean_std(&runs.iter().map(|r| r.wall_time()).collect::<Vec<_>>()).0,
        steps: runs.iter().map(|r| r.steps()).max().unwrap_or(0),
        curve,
    }
}

/// Writes the report for the runs found under `paths` into `out`.
pub fn write_report(paths: &[PathBuf], out: &Path, opts: &ReportOptions) -> Result<Report> {
    let runs = find_runs(paths)?;
    std::fs::create_dir_all(out)?;
    let groups = group_runs(&runs);
    let mut envs: BTreeMap<String, Vec<(&Group, &Vec<&Run>)>> = BTreeMap::new();
    for (g, rs) in &groups {
        envs.entry(g.env.clone()).or_default().push((g, rs));
    }

    let mut doc = Document::new("locobench report");
    let mut summaries = Vec::new();
    let mut comparisons = BTreeMap::new();
    doc.paragraph(format!("{} runs from {}.", runs.len(), paths_list(paths)));

    for (env, env_groups) in &envs {
        doc.heading(1, env.as_str());

        // Evaluation curves: mean ± std across seeds per group.
        let env_summaries: Vec<GroupSummary> = env_groups.iter().map(|(g, rs)| summarise(g, rs)).collect();
        let bands: Vec<Band> = env_summaries
            .iter()
            .map(|s| Band {
                label: format!("{} (n={})", s.group.label(), s.seeds),
                x: s.curve.steps.iter().map(|&x| x as f64).collect(),
                mean: s.curve.mean.clone(),
                std: s.curve.std.clone(),
                raw: vec![],
            })
            .collect();
        // Published learning curves at their marks, within the steps these runs reached.
        let mut markers = Vec::new();
        for (i, s) in env_summaries.iter().enumerate() {
            if let Some(c) = anchors::published_curve(env, &s.group.algo) {
                let reach = s.curve.steps.last().copied().unwrap_or(0);
                for (j, &step) in c.steps.iter().enumerate().filter(|(_, &st)| st <= reach.max(1)) {
                    markers.push(Marker {
                        label: format!("{} published (mean ± std)", s.group.algo),
                        x: step as f64,
                        y: c.mean[j],
                        err: c.std[j],
                        color_of: i,
                    });
                }
            }
        }
        let eval_svg = format!("{env}_evaluation.svg");
        let svg = bands_svg(
            &format!("{env}: evaluation return, mean ± std over seeds"),
            "environment steps",
            "return",
            &bands,
            &markers,
        )?;
        write_bytes_atomic(&out.join(&eval_svg), svg.as_bytes())?;
        doc.figure(eval_svg, svg, "evaluation curves");
        doc.table(
            &[
                "algorithm",
                "reward",
                "seeds",
                "steps",
                "final eval (mean ± std over seeds)",
                "normalised AUC",
                "wall time (min)",
            ],
            env_summaries
                .iter()
                .map(|s| {
                    vec![
                        s.group.label(),
                        s.group.reward.clone(),
                        s.seeds.to_string(),
                        s.steps.to_string(),
                        format!("{} ± {}", fmt_return(s.final_mean), fmt_return(s.final_std)),
                        fmt_return(s.auc),
                        fmt(s.wall_time / 60.0, 1),
                    ]
                })
                .collect(),
        );

        // Training returns per episode: 50-episode rolling mean and std, one chart per group.
        for (g, rs) in env_groups {
            let bands: Vec<Band> = rs
                .iter()
                .map(|r| {
                    let (x, y): (Vec<f64>, Vec<f64>) = r.episodes().map(|(s, v)| (s as f64, v)).unzip();
                    let (mean, std) = rolling(&y, ROLLING_WINDOW);
                    Band { label: format!("seed {}", r.config.seed), x, mean, std, raw: y }
                })
                .collect();
            let mut file = format!("{env}_{}_{}", g.algo, slug(&g.reward));
            if !g.settings.is_empty() {
                file += &format!("_{}", slug(&g.settings));
            }
            file += "_training.svg";
            let title =
                format!("{env} {}: episode returns (faint), {ROLLING_WINDOW}-episode rolling mean ± std", g.label());
            let svg = bands_svg(&title, "environment steps", "episode return", &bands, &[])?;
            write_bytes_atomic(&out.join(&file), svg.as_bytes())?;
            doc.figure(file, svg, "training returns");
        }

        // Baseline against RL.
        let speed = opts.baseline_speed.get(env.as_str()).copied();
        if let (Some(speed), true) = (speed, opts.compare_episodes > 0) {
            let gs: Vec<Vec<&Run>> = env_groups.iter().map(|(_, rs)| (*rs).clone()).collect();
            let rows = compare(env, &gs, opts.compare_episodes, opts.seed, speed)?;
            doc.heading(2, "Baseline vs RL");
            doc.paragraph(format!(
                "{} episodes per policy and seed; baseline set-point {speed} m/s. Speed error is measured against \
                 the baseline's set-point for every policy. The baseline runs in the runs' env options with its own \
                 action mode.",
                opts.compare_episodes
            ));
            let header: Vec<&str> = ["reward", "policy"].into_iter().chain(SUMMARY_COLUMNS).collect();
            doc.table(
                &header,
                rows.iter()
                    .map(|row| {
                        let mut cells = vec![row.reward.clone(), row.policy.clone()];
                        cells.extend(summary_cells(&row.episodes, fmt_return));
                        cells
                    })
                    .collect(),
            );
            comparisons.insert(env.clone(), rows);
        }
        summaries.extend(env_summaries);
    }

    doc.heading(1, "Runs");
    doc.lines(
        runs.iter().map(|r| format!("`{}`: {} seed {}", r.dir.display(), r.group().label(), r.config.seed)).collect(),
    );
    let index = out.join("index.html");
    let readme = out.join("README.md");
    write_bytes_atomic(&index, doc.to_html().as_bytes())?;
    write_bytes_atomic(&readme, doc.to_markdown().as_bytes())?;
    Ok(Report { index, readme, groups: summaries, comparisons })
}

fn paths_list(paths: &[PathBuf]) -> String {
    paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
}

fn slug(s: &str) -> String {
    s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '.' { c } else { '-' }).collect()
}
