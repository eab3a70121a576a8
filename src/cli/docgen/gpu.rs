//! docs/gpu.md's numbers, from the newest dated directory holding the GPU check's files
//! (`bash benches/gpu/check.sh`): update speed beside Stable-Baselines3 on the same GPU, the
//! generic path's gaps on the GPU, determinism, and the CrossQ-2048 curve.
use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;

use super::benchmarks::{newest, quoting};
use super::csv_rows::{read, Row};
use locobench::report::anchors::bundled_anchors;

/// Update speed, ours and SB3's, per algorithm and width.
pub(crate) fn speed(results: &Path) -> Result<String> {
    let ours_path = newest(results, "locobench-updates.csv")?;
    let sb3_path = ours_path.with_file_name("sb3-updates.csv");
    let (ours, sb3) = (read(&ours_path)?, read(&sb3_path)?);
    let mut out = quoting(&ours_path)? + " SB3: " + &quoting(&sb3_path)?;
    out += "\n\n| algorithm | actor | critics | batch | locobench, updates/s | SB3, updates/s | locobench / SB3 |\n|---|---|---|---|---|---|---|\n";
    let widths = |r: &Row| (r.text("hidden").to_string(), r.text("critic_hidden").to_string());
    let mut floor = None;
    for r in &ours {
        if r.num("batch") < 64.0 && r.text("algo") != "ppo" {
            floor = Some(r);
            continue;
        }
        let theirs = sb3.iter().find(|s| s.text("algo") == r.text("algo") && widths(s) == widths(r));
        let (sb3_rate, ratio) = match theirs {
            Some(s) => (format!("{:.0}", s.num("rate")), format!("{:.2}x", r.num("updates_per_s") / s.num("rate"))),
            None => ("–".into(), "–".into()),
        };
        if r.text("algo") == "ppo" {
            // timed in epochs: one pass over a 2048-step rollout
            let _ = writeln!(
                out,
                "| ppo (epochs/s: one pass over a 2048-step rollout) | {} | {} | {} | {:.1} | {} | {ratio} |",
                r.text("hidden"),
                r.text("hidden"),
                r.text("batch"),
                r.num("updates_per_s"),
                theirs.map_or("–".into(), |s| format!("{:.1}", s.num("rate")))
            );
            continue;
        }
        let critics = if r.text("critic_hidden").is_empty() { r.text("hidden") } else { r.text("critic_hidden") };
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {:.0} | {sb3_rate} | {ratio} |",
            r.text("algo"),
            r.text("hidden"),
            critics,
            r.text("batch"),
            r.num("updates_per_s")
        );
    }
    if let Some(p) =
        sb3.iter().find(|s| s.text("algo") == "ppo").filter(|_| !ours.iter().any(|r| r.text("algo") == "ppo"))
    {
        let _ = writeln!(
            out,
            "| ppo (epochs/s: one pass over a 2048-step rollout) | {} | {} | 64 | not measured | {:.1} | – |",
            p.text("hidden"),
            p.text("hidden"),
            p.num("rate")
        );
    }
    if let Some(first) = ours.first() {
        let _ = write!(
            out,
            "\nPer update the batch's upload (one host-to-device copy, then a wait for it) took {:.0} µs, and a \
             read-back of one value {:.0} µs.",
            first.num("upload_us"),
            first.num("readback_us")
        );
    }
    let baseline_path = ours_path.with_file_name("baseline-updates.csv");
    let mut baseline = String::new();
    if baseline_path.is_file() {
        let before = read(&baseline_path)?;
        baseline += "\nThe same rows in the same run from the baseline build (the previous version of the path; \
                `BASELINE_LOCOBENCH`, benches/gpu/check.sh):\n\n| algorithm | critics | batch | baseline, updates/s | \
                this build, updates/s | speed-up |\n|---|---|---|---|---|---|\n";
        for b in &before {
            let now = ours.iter().find(|r| {
                r.text("algo") == b.text("algo") && widths(r) == widths(b) && r.text("batch") == b.text("batch")
            });
            if let Some(r) = now {
                let _ = writeln!(
                    baseline,
                    "| {} | {} | {} | {:.0} | {:.0} | {:.2}x |",
                    b.text("algo"),
                    b.text("critic_hidden"),
                    b.text("batch"),
                    b.num("updates_per_s"),
                    r.num("updates_per_s"),
                    r.num("updates_per_s") / b.num("updates_per_s")
                );
            }
        }
    }
    if let Some(f) = floor {
        let _ = write!(
            out,
            " CrossQ with every layer {} wide at batch {} ran {:.0} updates/s: that is the cost of launching the \
             update's kernels, with almost no arithmetic in them.",
            f.text("critic_hidden").split('-').next().unwrap_or(""),
            f.text("batch"),
            f.num("updates_per_s")
        );
    }
    Ok(out + "\n" + &baseline)
}

/// The generic path against the fused one on the GPU, and same-seed determinism there.
pub(crate) fn check(results: &Path) -> Result<String> {
    let path = newest(results, "generic-check.csv")?;
    let mut out = quoting(&path)?
        + "\n\n| algorithm | device | updates | largest loss gap (relative) | tolerance | largest weight gap | tolerance |\n|---|---|---|---|---|---|---|\n";
    for r in read(&path)? {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {:.1e} | {:.0e} | {:.1e} ({}) | {:.0e} |",
            r.text("algo"),
            r.text("device"),
            r.text("updates"),
            r.num("loss_gap"),
            r.num("loss_tolerance"),
            r.num("weight_gap"),
            r.text("largest_weight_gap_at"),
            r.num("weight_tolerance")
        );
    }
    let det = path.with_file_name("determinism.csv");
    if det.is_file() {
        out +=
            "\nSame seed, same numbers on that GPU (short runs, step 3 of benches/gpu/check.sh: CrossQ with critics \
                2048-2048 on HalfCheetah, PPO on Hopper):\n\n";
        for r in read(&det)? {
            let _ = writeln!(out, "- {}: metrics rows identical: {}", r.text("what"), r.text("identical_metrics_rows"));
        }
    }
    Ok(out)
}

/// CrossQ-2048's evaluations on the GPU beside the committed CPU run with 256-wide critics and
/// the published curve where it reaches a published budget.
pub(crate) fn crossq_curve(results: &Path, cpu_run: &Path, root: &Path) -> Result<String> {
    let path = newest(results, "crossq2048-metrics.csv")?;
    let evals: Vec<Row> = read(&path)?.into_iter().filter(|r| r.text("kind") == "eval").collect();
    let cpu: Vec<Row> =
        read(&root.join(cpu_run).join("metrics.csv"))?.into_iter().filter(|r| r.text("kind") == "eval").collect();
    let published: Vec<_> =
        bundled_anchors().into_iter().filter(|a| a.env == "half-cheetah" && a.algo == "crossq").collect();
    let mut out = format!(
        "From the newest benches/results/<date>-<gpu>/crossq2048-metrics.csv (seed 0, the run's own evaluations: \
         10 deterministic episodes each, mean ± std over episodes), beside {} (same settings but critics 256-256, \
         on the CPU).\n\n| step | CrossQ 2048-2048 on the GPU | CrossQ 256-256 on the CPU | wall time on the GPU |\n|---|---|---|---|\n",
        cpu_run.display()
    );
    for e in &evals {
        let step = e.text("step");
        let theirs = cpu
            .iter()
            .find(|c| c.text("step") == step)
            .map_or("–".to_string(), |c| format!("{:.0} ± {:.0}", c.num("eval_mean"), c.num("eval_std")));
        let _ = writeln!(
            out,
            "| {step} | {:.0} ± {:.0} | {theirs} | {:.0} s |",
            e.num("eval_mean"),
            e.num("eval_std"),
            e.num("wall_time")
        );
    }
    let last = evals.last().map_or(0.0, |e| e.num("step"));
    for a in &published {
        let reached = if (a.steps as f64) <= last { "" } else { " (beyond this run)" };
        let _ = writeln!(
            out,
            "\nPublished at {} steps{reached}: {:.0} ± {:.0} over {} seeds ({}).",
            a.steps,
            a.value,
            a.std.unwrap_or(f64::NAN),
            a.seeds.unwrap_or(0),
            a.source
        );
    }
    Ok(out)
}
