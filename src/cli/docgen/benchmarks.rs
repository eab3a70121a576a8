//! Sections quoting the newest speed and memory measurements (`bash benches/speed.sh`).
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};

use super::csv_rows::{comments, read, Row};
use locobench::evaluation::stats::quantile;
use locobench::report::format::fixed;

/// The newest `benches/results/<date>-<machine>/<file>`: only directories named for a date
/// (`YYYY-MM-DD-...`) count, and they sort by that date, then by name.
pub(super) fn newest(results: &Path, file: &str) -> Result<PathBuf> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(results)
        .with_context(|| format!("reading {}", results.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(is_dated))
        .filter(|p| p.join(file).is_file())
        .collect();
    dirs.sort();
    match dirs.pop() {
        Some(d) => Ok(d.join(file)),
        None => bail!("no {file} under a dated directory of {}: run bash benches/speed.sh", results.display()),
    }
}

/// `YYYY-MM-DD-<machine>`.
fn is_dated(name: &str) -> bool {
    let b = name.as_bytes();
    b.len() > 11
        && b[..10].iter().enumerate().all(|(i, c)| if i == 4 || i == 7 { *c == b'-' } else { c.is_ascii_digit() })
        && b[10] == b'-'
}

fn duration(ns: f64) -> String {
    match ns {
        n if n >= 1e6 => format!("{:.2} ms", n / 1e6),
        n if n >= 1e3 => format!("{:.2} µs", n / 1e3),
        n => format!("{n:.0} ns"),
    }
}

/// How a generated section names its source: the newest file of that name in the dated result
/// directories (the file's own comment line names machine and commit; docs carry no dates).
pub(super) fn source(path: &Path) -> String {
    let file = path.file_name().map_or(String::new(), |f| f.to_string_lossy().to_string());
    format!("the newest benches/results/<date>-<machine>/{file}")
}

/// `text` with every dated result directory it names (`benches/results/YYYY-MM-DD-<machine>`)
/// written `benches/results/<date>-<machine>`, for text quoted from a result file (a suite's
/// command and notes name the earlier suite they reused): docs carry no dates.
pub(super) fn undated(text: &str) -> String {
    const PREFIX: &str = "benches/results/";
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find(PREFIX) {
        let (before, after) = rest.split_at(at + PREFIX.len());
        out.push_str(before);
        let name_end = after.find(|c: char| c == '/' || c.is_whitespace() || c == '`').unwrap_or(after.len());
        if is_dated(&after[..name_end]) {
            out.push_str("<date>");
            rest = &after[10..];
        } else {
            rest = after;
        }
    }
    out.push_str(rest);
    out
}

/// "From <source> (<the file's comment lines>)." : the first line of a section quoting a CSV.
pub(super) fn quoting(path: &Path) -> Result<String> {
    Ok(format!("From {} ({}).", source(path), comments(path)?.join("; ")))
}

/// Every criterion measurement of the newest `speed.csv`, one table per group.
pub fn speed(results: &Path) -> Result<String> {
    let path = newest(results, "speed.csv")?;
    let rows = read(&path)?;
    let mut out = quoting(&path)? + "\n";
    let mut group = String::new();
    for r in &rows {
        if r.text("group") != group {
            group = r.text("group").to_string();
            let _ = write!(out, "\n`{group}`:\n\n| benchmark | mean time | 95% CI |\n|---|---|---|\n");
        }
        let _ = writeln!(
            out,
            "| {} | {} | {} – {} |",
            r.text("benchmark"),
            duration(r.num("mean_ns")),
            duration(r.num("low_ns")),
            duration(r.num("high_ns"))
        );
    }
    Ok(out)
}

/// The newest `memory-bench.md`, as the memory bench printed it.
pub fn memory(results: &Path) -> Result<String> {
    let path = newest(results, "memory-bench.md")?;
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    Ok(format!("From {}: {}", source(&path), text.trim()))
}

/// The newest `vec-env.csv` (`cargo bench --bench env_step -- "vec_env|env.step"`): env steps
/// per second of one env and of the vector env's copies on one and two threads, and how close
/// two threads come to twice one env.
pub(crate) fn vector_env(results: &Path) -> Result<String> {
    let path = newest(results, "vec-env.csv")?;
    let rows = read(&path)?;
    let mut out = quoting(&path)? + "\n\n| env | one env (steps/s) | copies | on 1 thread (steps/s) | on 2 threads (steps/s) | 2 threads / (2 x one env) |\n|---|---|---|---|---|---|\n";
    for single in rows.iter().filter(|r| r.text("benchmark").ends_with("/env.step")) {
        let env = single.text("benchmark").trim_end_matches("/env.step");
        let one = 1e9 / single.num("mean_ns");
        // "<env>/<copies> copies, <threads> thread(s)"
        let vector = |threads: usize| {
            rows.iter().find_map(|r| {
                let rest = r.text("benchmark").strip_prefix(env)?.strip_prefix('/')?;
                let (copies, tail) = rest.split_once(" copies, ")?;
                let copies: f64 = copies.parse().ok()?;
                (tail == format!("{threads} thread(s)")).then(|| (copies, copies * 1e9 / r.num("mean_ns")))
            })
        };
        let (Some((copies, one_thread)), Some((_, two_threads))) = (vector(1), vector(2)) else { continue };
        let _ = writeln!(
            out,
            "| {env} | {} | {copies} | {} | {} | {:.2} |",
            fixed(one, 0),
            fixed(one_thread, 0),
            fixed(two_threads, 0),
            two_threads / (2.0 * one)
        );
    }
    Ok(out)
}

/// The newest `python-speed.csv` (`python python/bench_speed.py`).
pub(crate) fn python_speed(results: &Path) -> Result<String> {
    let path = newest(results, "python-speed.csv")?;
    let rows = read(&path)?;
    let mut out = quoting(&path)? + "\n\n| env | locobench through Gymnasium (steps/s) | raw binding (steps/s) | looped in Rust (steps/s) | binding overhead per step | Gymnasium's own env (steps/s) | vector env, 8 copies, 1 thread (steps/s) | same, 2 threads (steps/s) |\n|---|---|---|---|---|---|---|---|\n";
    for r in &rows {
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {:.1} µs | {} | {} | {} |",
            r.text("env"),
            fixed(r.num("locobench_gym_steps_per_s"), 0),
            fixed(r.num("locobench_raw_steps_per_s"), 0),
            fixed(r.num("locobench_rust_steps_per_s"), 0),
            r.num("binding_overhead_us"),
            fixed(r.num("gymnasium_steps_per_s"), 0),
            fixed(r.num("vec8_1_thread_steps_per_s"), 0),
            fixed(r.num("vec8_2_threads_steps_per_s"), 0),
        );
    }
    if rows.iter().any(|r| r.num("vec8_rust_2_processes_gain").is_finite()) {
        // Files written before bench_speed.py gave intervals have the medians alone.
        let with_intervals = rows.iter().all(|r| r.num("vec8_2_threads_gain_low").is_finite());
        let _ = write!(
            out,
            "\nWhat a second thread gives the vector env, beside the same vector env looped in Rust, its former \
             step (one info dict per copy, batched by Gymnasium's `_add_info`), and two processes each looping \
             a vector env of half the copies in Rust on one thread (as many copies per core as two threads \
             step): the machine's ceiling for a second core, with nothing shared. They took turns over ninety \
             short rounds, in reverse order every other round; each gain is the median of the rounds' own \
             ratios{}. The goal is judged against the machine, not a fixed number: the vector env's gain \
             from a second thread is at least what the same machine gives two independent processes in the \
             same run (the last column, the vector env's gain over the two processes' gain, at 1.00 or \
             more){}:\n\n\
             | env | vector env, 2 threads / 1 | looped in Rust, 2 threads / 1 | former step, 2 threads / 1 | two processes / one | vector env / two processes | goal |\n|---|---|---|---|---|---|---|\n",
            if with_intervals { ", with its 95% bootstrap interval over the rounds" } else { "" },
            if rows.iter().all(|r| r.num("vec8_over_processes").is_finite()) {
                ", the median of the rounds' own ratios of the two gains"
            } else {
                ", here the ratio of the two medians (this file predates the per-round ratio)"
            },
        );
        let gain = |r: &Row, column: &str| {
            let (low, high) = (r.num(&format!("{column}_low")), r.num(&format!("{column}_high")));
            if with_intervals {
                format!("{:.2}x [{low:.2}, {high:.2}]", r.num(column))
            } else {
                format!("{:.2}x", r.num(column))
            }
        };
        for r in &rows {
            let (share, shown) = if r.num("vec8_over_processes").is_finite() {
                let (v, low, high) =
                    (r.num("vec8_over_processes"), r.num("vec8_over_processes_low"), r.num("vec8_over_processes_high"));
                (v, format!("{v:.2} [{low:.2}, {high:.2}]"))
            } else {
                let v = r.num("vec8_2_threads_gain") / r.num("vec8_rust_2_processes_gain");
                (v, format!("{v:.2}"))
            };
            let _ = writeln!(
                out,
                "| {} | {} | {} | {} | {} | {shown} | {} |",
                r.text("env"),
                gain(r, "vec8_2_threads_gain"),
                gain(r, "vec8_rust_2_threads_gain"),
                gain(r, "vec8_dicts_2_threads_gain"),
                gain(r, "vec8_rust_2_processes_gain"),
                if share >= 1.0 { "met" } else { "not met" },
            );
        }
    }
    Ok(out)
}

/// The newest `render-speed.csv` (`cargo bench --bench render -- FILE`): seconds and frames per
/// second to render a 10-second episode's 251 frames and to encode them, per size.
pub(crate) fn render_speed(results: &Path) -> Result<String> {
    let path = newest(results, "render-speed.csv")?;
    let rows = read(&path)?;
    let mut out = quoting(&path)?
        + "\n\n| size | frames | render | encode MP4 | encode WebM | encode GIF | MP4, render + encode |\n|---|---|---|---|---|---|---|\n";
    for r in &rows {
        let frames = r.num("frames");
        let cell = |s: f64| format!("{s:.2} s ({:.0} fps)", frames / s);
        let (render, mp4) = (r.num("render_s"), r.num("encode_mp4_s"));
        let _ = writeln!(
            out,
            "| {}x{} | {frames:.0} | {} | {} | {} | {} | {:.2} s |",
            r.num("width"),
            r.num("height"),
            cell(render),
            cell(mp4),
            cell(r.num("encode_webm_s")),
            cell(r.num("encode_gif_s")),
            render + mp4
        );
    }
    Ok(out)
}

/// The newest `report-timing.csv` (`bash benches/report_timing.sh`): the committed report's
/// regeneration time and size, without and with videos, cold (an empty evaluation cache) and warm
/// (nothing new). Files from before the cache have no `cache` column: every row is cold.
pub(crate) fn report_timing(results: &Path) -> Result<String> {
    let path = newest(results, "report-timing.csv")?;
    let rows = read(&path)?;
    let mut out = quoting(&path)?
        + "\n\n| evaluation cache | videos | wall time | read from the cache | computed | cache's own time | index.html | videos | whole report | clips |\n\
           |---|---|---|---|---|---|---|---|---|---|\n";
    let mb = |b: f64| format!("{:.1} MB", b / 1e6);
    let cache =
        |r: &super::csv_rows::Row| if r.text("cache").is_empty() { "cold" } else { r.text("cache") }.to_string();
    let count = |r: &super::csv_rows::Row, c: &str| {
        if r.text(c).is_empty() {
            "–".to_string()
        } else {
            r.text(c).to_string()
        }
    };
    for r in &rows {
        let wall = r.num("wall_s");
        let _ = writeln!(
            out,
            "| {} | {} | {} | {} | {} | {} | {:.0} KB | {} | {} | {:.0} |",
            cache(r),
            if r.text("videos") == "true" { "yes" } else { "no" },
            if wall < 120.0 { format!("{wall:.1} s") } else { format!("{:.1} min", wall / 60.0) },
            count(r, "read"),
            count(r, "computed"),
            if r.text("cache_overhead_s").is_empty() {
                "–".into()
            } else {
                format!("{} s", r.text("cache_overhead_s"))
            },
            r.num("index_html_bytes") / 1e3,
            mb(r.num("videos_bytes")),
            mb(r.num("report_bytes")),
            r.num("clips")
        );
    }
    let find = |c: &str, v: &str| rows.iter().find(|r| cache(r) == c && r.text("videos") == v);
    if let (Some(plain), Some(filmed)) = (find("cold", "false"), find("cold", "true")) {
        let _ =
            writeln!(out, "\nWith videos the report takes {:.2}x as long.", filmed.num("wall_s") / plain.num("wall_s"));
    }
    if let (Some(cold), Some(warm)) = (find("cold", "true"), find("warm", "true")) {
        let _ = writeln!(
            out,
            "With nothing new, the warm cache regenerates it, videos included, {:.0}x faster than the cold one.",
            cold.num("wall_s") / warm.num("wall_s")
        );
    }
    Ok(out)
}

/// The newest `ppo-vs-sb3.csv` (`benches/ppo_vs_sb3.py`): locobench's PPO and SB3's with the same
/// settings on HalfCheetah, per seed, and how much longer SB3 took in all.
pub(crate) fn ppo_vs_sb3(results: &Path) -> Result<String> {
    let path = newest(results, "ppo-vs-sb3.csv")?;
    let rows = read(&path)?;
    let mut out = quoting(&path)?
        + "\n\n| implementation | seed | steps | wall time | CPU time | held-out return |\n|---|---|---|---|---|---|\n";
    for r in &rows {
        let _ = writeln!(
            out,
            "| {} | {} | {:.0} | {:.0} s | {:.0} s | {:.1} [{:.1}, {:.1}] |",
            r.text("implementation"),
            r.num("seed"),
            r.num("steps"),
            r.num("wall_s"),
            r.num("cpu_s"),
            r.num("held_out_return"),
            r.num("held_out_low"),
            r.num("held_out_high")
        );
    }
    let total = |prefix: &str, col: &str| -> f64 {
        rows.iter().filter(|r| r.text("implementation").starts_with(prefix)).map(|r| r.num(col)).sum()
    };
    let (ours, theirs) = (total("locobench", "cpu_s"), total("stable-baselines3", "cpu_s"));
    if ours > 0.0 && theirs > 0.0 {
        let _ = writeln!(
            out,
            "\nOver the seeds, SB3 took {:.1}x locobench's CPU time ({:.1}x its wall time).",
            theirs / ours,
            total("stable-baselines3", "wall_s") / total("locobench", "wall_s")
        );
    }
    Ok(out)
}

/// The newest `time-to-walk.csv` (`cargo bench --bench time_to_walk`): per algorithm and
/// threshold, how many runs reached it and how long they took.
pub(crate) fn time_to_walk(results: &Path) -> Result<String> {
    let path = newest(results, "time-to-walk.csv")?;
    let returns = |r: &Row| {
        format!(
            "{} [{}, {}]",
            fixed(r.num("heldout_return"), 2),
            fixed(r.num("heldout_low"), 2),
            fixed(r.num("heldout_high"), 2)
        )
    };
    let falls = |r: &Row| format!("{}/{}", r.text("falls"), r.text("episodes"));
    threshold_table(
        &path,
        &[("held-out return when reached, per run", &returns), ("falls when reached, per run", &falls)],
    )
}

/// The newest `time-to-track.csv` (`cargo bench --bench time_to_walk -- --env minitaur-command`):
/// per algorithm and threshold, how many runs reached it, how long they took, and how their
/// tracking compared with the controller's when they did.
pub(crate) fn time_to_track(results: &Path) -> Result<String> {
    let path = newest(results, "time-to-track.csv")?;
    let falls = |r: &Row| format!("{}/{}", r.text("falls"), r.text("episodes"));
    let ratio = |r: &Row| fixed(r.num("worst_rms_ratio"), 2);
    threshold_table(
        &path,
        &[("falls when reached, per run", &falls), ("largest RMS speed error / the controller's, per run", &ratio)],
    )
}

/// A named column of a threshold table, computed from one run's row.
type RunColumn<'a> = (&'a str, &'a dyn Fn(&Row) -> String);

/// A threshold benchmark's table: per (algorithm, threshold), the runs that reached it, their
/// minutes and steps, and `per_run` columns of the runs that did; then the runs that did not.
fn threshold_table(path: &Path, per_run: &[RunColumn]) -> Result<String> {
    let rows = read(path)?;
    let mut out = quoting(path)? + "\n\n| algorithm | threshold | runs that reached it | training minutes, median (range) | env steps, median (range) |";
    for (name, _) in per_run {
        let _ = write!(out, " {name} |");
    }
    out += &format!("\n|---|---|---|---|---|{}\n", "---|".repeat(per_run.len()));
    let mut keys: Vec<(String, String)> = Vec::new();
    for r in &rows {
        let key = (r.text("algo").to_string(), r.text("threshold").to_string());
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    let spread = |mut v: Vec<f64>, scale: f64, unit: &str| -> String {
        if v.is_empty() {
            return "–".into();
        }
        v.sort_by(f64::total_cmp);
        let f = |x: f64| format!("{}{unit}", fixed(x / scale, 1));
        format!("{} ({} – {})", f(quantile(&v, 0.5)), f(v[0]), f(v[v.len() - 1]))
    };
    for (algo, threshold) in keys {
        let runs: Vec<&Row> =
            rows.iter().filter(|r| r.text("algo") == algo && r.text("threshold") == threshold).collect();
        let hits: Vec<&&Row> = runs.iter().filter(|r| r.text("reached") == "true").collect();
        let _ = write!(
            out,
            "| {algo} | {threshold} | {}/{} | {} | {} |",
            hits.len(),
            runs.len(),
            spread(hits.iter().map(|r| r.num("training_s")).collect(), 60.0, ""),
            spread(hits.iter().map(|r| r.num("step")).collect(), 1000.0, "k"),
        );
        for (_, f) in per_run {
            let cell =
                if hits.is_empty() { "–".into() } else { hits.iter().map(|r| f(r)).collect::<Vec<_>>().join(", ") };
            let _ = write!(out, " {cell} |");
        }
        out.push('\n');
    }
    let unreached: Vec<String> = rows
        .iter()
        .filter(|r| r.text("reached") != "true")
        .map(|r| {
            format!(
                "{} seed {} ({}: {} steps, {} min)",
                r.text("algo"),
                r.text("seed"),
                r.text("threshold"),
                r.text("step"),
                fixed(r.num("training_s") / 60.0, 1)
            )
        })
        .collect();
    if !unreached.is_empty() {
        let _ = write!(out, "\nNot reached when the run stopped: {}.\n", unreached.join("; "));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_to_walk_summarises_each_algorithm_and_threshold_and_names_unreached_runs() {
        let dir = tempfile::tempdir().unwrap();
        let results = dir.path().join("2026-01-02-some-cpu");
        std::fs::create_dir_all(&results).unwrap();
        let header = "algo,seed,threads,threshold,reached,step,training_s,heldout_return,heldout_low,heldout_high,speed,falls,episodes,controller_command,controller_matched,controller_return";
        let rows = [
            "ppo,0,1,return-10,true,800000,300.0,12.0,11.0,13.0,1.3,5,50,1.400,true,11.5",
            "ppo,1,1,return-10,true,600000,240.0,10.5,10.0,11.0,1.1,2,50,1.200,true,10.2",
            "ppo,2,1,return-10,false,2000000,900.0,,,,,,,,,",
        ];
        std::fs::write(results.join("time-to-walk.csv"), format!("# machine: test\n{header}\n{}\n", rows.join("\n")))
            .unwrap();
        let text = time_to_walk(dir.path()).unwrap();
        assert!(text.contains("machine: test"), "{text}");
        // Two of three reached it: the median of 4 and 5 minutes is 4.5.
        assert!(text.contains("| ppo | return-10 | 2/3 | 4.5 (4.0 – 5.0) | 700.0k (600.0k – 800.0k) |"), "{text}");
        assert!(text.contains("12.00 [11.00, 13.00], 10.50 [10.00, 11.00]") && text.contains("5/50, 2/50"), "{text}");
        assert!(text.contains("ppo seed 2 (return-10: 2000000 steps, 15.0 min)"), "{text}");
    }

    #[test]
    fn vector_env_rates_come_from_the_mean_times_per_step() {
        let dir = tempfile::tempdir().unwrap();
        let results = dir.path().join("2026-01-02-some-cpu");
        std::fs::create_dir_all(&results).unwrap();
        let csv = "# machine: test\ngroup,benchmark,mean_ns,low_ns,high_ns\n\
                   \"env_step\",\"hopper/env.step\",50000,49000,51000\n\
                   \"vec_env\",\"hopper/16 copies, 1 thread(s)\",800000,1,1\n\
                   \"vec_env\",\"hopper/16 copies, 2 thread(s)\",500000,1,1\n";
        std::fs::write(results.join("vec-env.csv"), csv).unwrap();
        let text = vector_env(dir.path()).unwrap();
        // one env: 1e9 / 50000 = 20000/s; 16 copies: 16e9 / 800000 = 20000/s and 16e9 / 500000 = 32000/s
        assert!(text.contains("| hopper | 20000 | 16 | 20000 | 32000 | 0.80 |"), "{text}");
        assert!(text.contains("machine: test"), "{text}");
    }

    #[test]
    fn dated_directories_lose_their_date_and_keep_their_machine() {
        assert_eq!(
            undated("REUSE=benches/results/2026-11-27-epyc-zen3-avx2 cargo bench; in benches/results/2026-11-27-x/ant, benches/results/minitaur/ppo"),
            "REUSE=benches/results/<date>-epyc-zen3-avx2 cargo bench; in benches/results/<date>-x/ant, benches/results/minitaur/ppo"
        );
    }

    #[test]
    fn newest_takes_the_latest_dated_directory() {
        let dir = tempfile::tempdir().unwrap();
        for (sub, has) in
            [("2026-01-02-b-cpu", true), ("2026-01-03-a-cpu", true), ("2026-01-04-c-cpu", false), ("zebra", true)]
        {
            std::fs::create_dir_all(dir.path().join(sub)).unwrap();
            if has {
                std::fs::write(dir.path().join(sub).join("speed.csv"), "x").unwrap();
            }
        }
        let path = newest(dir.path(), "speed.csv").unwrap();
        assert!(path.ends_with("2026-01-03-a-cpu/speed.csv"), "{}", path.display());
        assert_eq!(source(&path), "the newest benches/results/<date>-<machine>/speed.csv");
        let err = newest(dir.path(), "memory.md").unwrap_err().to_string();
        assert!(err.contains("memory.md"), "{err}");
        assert!(!is_dated("2026-1-03-x") && !is_dated("2026-01-03") && is_dated("2026-01-03-x"));
    }
}
