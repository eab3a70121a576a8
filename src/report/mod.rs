//! `locobench report`: every policy of the given runs evaluated under one protocol
//! (`evaluation`), at fixed step budgets, beside published results and, on Minitaur and Ant,
//! beside the controller across its speeds and under pushes; as `index.html` (self-contained, no
//! network) and `README.md`, with SVG charts beside them.
pub mod anchors;
pub mod budgets;
pub mod controller;
pub mod curves;
mod data;
pub(crate) mod document;
pub mod format;
pub mod heldout;
pub mod plots;
pub mod progress;
pub mod robustness;
pub mod robustness_clips;
pub mod runs;
mod sections;
pub mod tracking;
pub mod videos;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::evaluation::Protocol;
use crate::io::write_bytes_atomic;
use curves::{eval_curve, mean_std, EvalCurve};
use document::Document;
use heldout::BudgetRow;
use runs::{find_runs, Group, Run};

pub use format::fmt_return;

/// The held-out rows and the controller grids as data, beside the report (what docs quote).
pub const HELD_OUT_CSV: &str = "held_out.csv";
/// The controller's grid of speeds, as data.
pub const CONTROLLER_CSV: &str = "controller.csv";
/// The learning curves, as data.
pub const CURVES_CSV: &str = "curves.csv";
/// Each learned row against the controller at its speed, as data.
pub const VERSUS_CONTROLLER_CSV: &str = "versus_controller.csv";

pub use crate::evaluation::stats::BOOTSTRAP_SEED;

/// Episodes per seed of the training-return rolling statistics.
pub(crate) const ROLLING_WINDOW: usize = 50;

/// What `write_report` evaluates and how.
#[derive(Debug, Clone)]
pub struct ReportOptions {
    /// The held-out episodes every policy plays (`--episodes`, `--seed`).
    pub protocol: Protocol,
    /// Episodes per push level (0 skips the push table).
    pub push_episodes: usize,
    /// Evaluations run at once; the report is the same for any number.
    pub threads: usize,
    /// Film each algorithm's best row (and the controller beside it) into `videos/`.
    pub videos: bool,
    /// Directories of episodes evaluated outside locobench (`evaluation::external`), added as
    /// rows beside the runs'.
    pub external: Vec<PathBuf>,
    /// Committed robustness suites (`evaluation::robustness`), one section each in its env.
    pub robustness: Vec<PathBuf>,
    /// Where held-out episodes and clips are kept between reports (`evaluation::cache`); off
    /// computes everything.
    pub cache: crate::evaluation::EvalCache,
}

impl Default for ReportOptions {
    fn default() -> Self {
        ReportOptions {
            protocol: Protocol::default(),
            push_episodes: 20,
            threads: crate::evaluation::parallel::default_threads(),
            videos: false,
            external: Vec::new(),
            robustness: Vec::new(),
            cache: crate::evaluation::EvalCache::off(),
        }
    }
}

/// One group of seeds' learning-curve summary.
#[derive(Debug, Clone)]
pub struct GroupSummary {
    /// The runs' env, algorithm, reward and settings.
    pub group: Group,
    /// The in-training evaluation returns over seeds, per step.
    pub curve: EvalCurve,
    /// Runs in the group.
    pub seeds: usize,
    /// Area under the mean evaluation curve, normalised by the steps.
    pub auc: f64,
    /// Mean wall time per run (s).
    pub wall_time: f64,
    /// The longest run's steps.
    pub steps: u64,
}

/// What `write_report` wrote, and the tables behind it.
pub struct Report {
    /// The HTML page.
    pub index: PathBuf,
    /// The Markdown page.
    pub readme: PathBuf,
    /// One learning-curve summary per group.
    pub groups: Vec<GroupSummary>,
    /// Held-out rows per env.
    pub rows: BTreeMap<String, Vec<BudgetRow>>,
    /// The controller's speed grid and matched rows, per env.
    pub controllers: BTreeMap<String, controller::ControllerSection>,
}

/// Groups runs by (env, algorithm, reward, settings), sorted.
/// FNV-1a of `bytes` (Fowler, Noll and Vo): a hash that is the same in every build and on every
/// machine, for names and seeds derived from a group's fields.
pub(crate) fn fnv1a(bytes: impl IntoIterator<Item = u8>) -> u64 {
    bytes.into_iter().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3))
}

pub(crate) fn group_runs(runs: &[Run]) -> BTreeMap<Group, Vec<&Run>> {
    let mut groups: BTreeMap<Group, Vec<&Run>> = BTreeMap::new();
    for r in runs {
        groups.entry(r.group()).or_default().push(r);
    }
    groups
}

pub(crate) fn summarise(group: &Group, runs: &[&Run]) -> GroupSummary {
    let curve = eval_curve(&runs.iter().map(|r| r.evals().collect()).collect::<Vec<_>>());
    GroupSummary {
        group: group.clone(),
        seeds: runs.len(),
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
    // A report killed while writing left its temporary files; this one writes every file again.
    crate::io::remove_temporaries(out)?;
    let externals = opts.external.iter().map(|d| crate::evaluation::external::read(d)).collect::<Result<Vec<_>>>()?;
    let groups = group_runs(&runs);
    let mut envs: BTreeMap<String, Vec<(&Group, &Vec<&Run>)>> = BTreeMap::new();
    for (g, rs) in &groups {
        envs.entry(g.env.clone()).or_default().push((g, rs));
    }

    let suites = opts.robustness.iter().map(|d| robustness::SuiteData::read(d)).collect::<Result<Vec<_>>>()?;
    if let Some(x) = externals.iter().find(|x| !envs.contains_key(&x.meta.env)) {
        anyhow::bail!("{}: its env, {}, has no runs in this report", x.dir.display(), x.meta.env);
    }
    let mut doc = Document::new("locobench report");
    // The summary goes here, once the sections below have computed what it says.
    let summary_at = doc.blocks.len();
    // (not a command task, no controller, fewer runs first, env): the order of the summaries.
    type Order = (bool, bool, usize, String);
    let mut summaries: Vec<(Order, Vec<document::Block>)> = Vec::new();
    sections::protocol(&mut doc, opts);

    // Every clip file this report shows, relative to `out`: the others in its videos folder go.
    let mut filmed: std::collections::BTreeSet<String> = std::collections::BTreeSet::new();
    let mut report = Report {
        index: out.join("index.html"),
        readme: out.join("README.md"),
        groups: Vec::new(),
        rows: BTreeMap::new(),
        controllers: BTreeMap::new(),
    };
    // Command tasks first: the same command for every contender is the fairest comparison.
    let mut ordered: Vec<_> = envs.iter().collect();
    ordered.sort_by_key(|(env, _)| (!crate::envs::command::is_command_task(env), env.to_string()));
    for (env, env_groups) in ordered {
        doc.heading(1, env.as_str());
        let tracked = tracking::section(&mut doc, out, env, env_groups, opts)?;
        filmed.extend(tracked.clips.iter().flat_map(videos::Clip::files));
        report.groups.extend(sections::learning_curves(&mut doc, out, env, env_groups)?);
        let here: Vec<_> = externals.iter().filter(|x| x.meta.env == *env).cloned().collect();
        let rows = sections::held_out(&mut doc, env_groups, opts, &here)?;
        sections::published(&mut doc, env, &rows, env_groups);
        // On a command task the controller follows the task's commands, not a speed: the tracking
        // section above compares it.
        if crate::controller::baseline::baseline_env(env).is_ok() && !crate::envs::command::is_command_task(env) {
            if let Some(c) = sections::controller(&mut doc, out, env, env_groups, &rows, opts)? {
                report.controllers.insert(env.clone(), c);
            }
        }
        for suite in suites.iter().filter(|s| s.meta.env.name == *env) {
            // A command task's suite is not filmed: its same-command section films the schedule,
            // and the report stays small enough to clone.
            let film = opts.videos && !crate::envs::command::is_command_task(env);
            let clips = robustness::section(&mut doc, out, suite, film.then_some(opts.threads), &opts.cache)?;
            filmed.extend(clips.iter().flat_map(videos::Clip::files));
        }
        let section = report.controllers.get(env);
        let clips = if opts.videos {
            sections::gaits(&mut doc, out, env, env_groups, &rows, section, opts)?
        } else {
            Vec::new()
        };
        filmed.extend(clips.iter().flat_map(videos::Clip::files));
        let runs_here: usize = env_groups.iter().map(|(_, rs)| rs.len()).sum();
        summaries.push((
            (!crate::envs::command::is_command_task(env), section.is_none(), usize::MAX - runs_here, env.clone()),
            tracked.summary.into_iter().chain(sections::summary(env, &rows, section, &clips)).collect(),
        ));
        sections::training_returns(&mut doc, out, env, env_groups)?;
        report.rows.insert(env.clone(), rows);
    }
    // Command tasks first, then envs with a controller, then by runs.
    summaries.sort_by(|a, b| a.0.cmp(&b.0));
    let mut first = vec![document::Block::Heading { level: 1, text: "Summary".into() }];
    first.push(document::Block::Paragraph(format!(
        "{} runs ({}; listed in the appendix), each policy on the held-out episodes of the protocol below. \
         Per env: the best learned row (the highest lower 95% bound of the mean return, so a high but \
         uncertain row does not win on luck) and, where the env has one, the controller.",
        runs.len(),
        paths_summary(paths)
    )));
    first.extend(summaries.into_iter().flat_map(|(_, b)| b));
    doc.insert(summary_at, first);
    sections::runs(&mut doc, &runs);
    write_bytes_atomic(&out.join(HELD_OUT_CSV), data::held_out_csv(&report.rows).as_bytes())?;
    write_bytes_atomic(&out.join(CONTROLLER_CSV), data::controller_csv(&report.controllers).as_bytes())?;
    write_bytes_atomic(&out.join(CURVES_CSV), data::curves_csv(&envs).as_bytes())?;
    write_bytes_atomic(
        &out.join(VERSUS_CONTROLLER_CSV),
        data::versus_controller_csv(&report.rows, &report.controllers).as_bytes(),
    )?;
    write_bytes_atomic(&report.index, doc.to_html().as_bytes())?;
    write_bytes_atomic(&report.readme, doc.to_markdown().as_bytes())?;
    remove_unshown_videos(out, &filmed)?;
    Ok(report)
}

/// Removes the files in `out/videos/` that are none of `shown` (paths relative to `out`): clips
/// of an earlier report that this one does not show. The folder is the report's own, so a clip
/// kept from the cache stays and nothing stale is left beside it.
fn remove_unshown_videos(out: &Path, shown: &std::collections::BTreeSet<String>) -> Result<()> {
    let dir = out.join(videos::VIDEO_DIR);
    for entry in std::fs::read_dir(&dir).into_iter().flatten().flatten() {
        let rel = format!("{}/{}", videos::VIDEO_DIR, entry.file_name().to_string_lossy());
        if entry.path().is_file() && !shown.contains(&rel) {
            std::fs::remove_file(entry.path()).with_context(|| format!("removing {}", entry.path().display()))?;
        }
    }
    if shown.is_empty() && dir.is_dir() {
        std::fs::remove_dir(&dir).ok();
    }
    Ok(())
}

/// The paths given, or how many when they are many.
fn paths_summary(paths: &[PathBuf]) -> String {
    if paths.len() <= 3 {
        format!("from {}", paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", "))
    } else {
        format!("from {} paths", paths.len())
    }
}
