//! `locobench sweep` and `locobench report` end to end on tiny Minitaur runs.
mod common;

use common::locobench;

#[test]
fn sweep_then_report_evaluates_every_run_at_its_budget_beside_the_controller() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = dir.path().join("sweep");
    let s = sweep.to_str().unwrap();
    let args = [
        "sweep",
        "--env",
        "minitaur",
        "--algo",
        "sac,td3",
        "--grid",
        "drift=0:0.5:0.5",
        "--seeds",
        "2",
        "--jobs",
        "2",
        "--steps",
        "240",
        "--set",
        "hidden=[16,16],batch_size=32,warmup_steps=80,learning_starts=80,eval_every=80,eval_episodes=1",
        "--option",
        "max_episode_steps=40",
        "--out",
        s,
    ];
    let (ok, out, err) = locobench(&args);
    assert!(ok, "{out}\n{err}");
    assert!(out.contains("8 jobs"), "{out}");
    let jobs = std::fs::read_to_string(sweep.join("jobs.txt")).unwrap();
    assert_eq!(jobs.lines().count(), 8);
    assert!(jobs.lines().all(|l| l.starts_with("locobench train --env minitaur")), "{jobs}");
    assert!(jobs.contains("--reward drift=0.5"));
    for line in jobs.lines() {
        let run = line.split(" --out ").nth(1).unwrap().split(' ').next().unwrap();
        assert!(std::path::Path::new(run).join("metrics.csv").exists(), "{run}");
    }

    // Running the same sweep again resumes: finished runs are left as they are.
    let metrics = sweep.join("runs/sac-drift0.5-seed1/metrics.csv");
    let before = std::fs::read(&metrics).unwrap();
    let (ok, _, err) = locobench(&args);
    assert!(ok, "{err}");
    assert_eq!(std::fs::read(&metrics).unwrap(), before);

    let report = dir.path().join("report");
    let (ok, out, err) = locobench(&[
        "report",
        "--runs",
        s,
        "--out",
        report.to_str().unwrap(),
        "--episodes",
        "2",
        "--push-episodes",
        "1",
        "--videos",
    ]);
    assert!(ok, "{out}\n{err}");
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    let md = std::fs::read_to_string(report.join("README.md")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.contains("<svg"), "inline charts");
    assert!(!html.contains("<script"), "no scripts, no network");
    for needle in [
        "## Protocol",
        "2 held-out episodes per seed",
        "Held-out evaluation at fixed budgets",
        "Controller across commanded speeds",
        "Learned policies against the controller",
        "Pushes",
        "sac-drift0.5",
        "| sac-drift0.5 | 2 | sac, drift=0.5, batch_size=32,",
        "2 row(s) trained under other env options",
    ] {
        assert!(md.contains(needle), "{needle} missing:\n{md}");
    }
    // Four groups (2 algorithms x 2 drift weights), each evaluated at its one budget (240 steps)
    // from both seeds' policies, 2 episodes each; no budget row borrows from another.
    assert_eq!(md.matches("| 240 | 2 of 2 | 2 |").count(), 4, "{md}");
    assert!(!md.contains("| 100k |"), "no run reached 100k: no such row");
    // Only the rows trained under the controller's reward (drift 0) stand beside it, each with
    // its own numbers: the speed in versus_controller.csv is the held-out row's.
    // each row as column name -> value, by the file's header
    let csv = |file: &str| -> Vec<std::collections::HashMap<String, String>> {
        let text = std::fs::read_to_string(report.join(file)).unwrap();
        let mut lines = text.lines();
        let header: Vec<String> = lines.next().unwrap().split(',').map(str::to_string).collect();
        lines.map(|l| header.iter().cloned().zip(l.split(',').map(str::to_string)).collect()).collect()
    };
    let (versus, held_out) = (csv("versus_controller.csv"), csv("held_out.csv"));
    let policies: Vec<&str> = versus.iter().map(|v| v["policy"].as_str()).collect();
    assert_eq!(policies, ["sac-drift0", "td3-drift0"], "{versus:?}");
    for v in &versus {
        let h = held_out.iter().find(|h| h["policy"] == v["policy"] && h["budget"] == v["budget"]).unwrap();
        assert_eq!(
            h["speed"], v["speed"],
            "{} at {}: held-out speed against the compared one",
            v["policy"], v["budget"]
        );
    }
    let svgs: Vec<String> = std::fs::read_dir(&report)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".svg"))
        .collect();
    assert_eq!(svgs.len(), 1 + 3 + 4, "evaluation, three speed charts, one training chart per group: {svgs:?}");
    // The speed charts are shown from their files, so the page stays light.
    for name in ["return", "cot", "falls"] {
        assert!(html.contains(&format!("<img src=\"minitaur_speed_{name}.svg\"")), "{name} chart shown from its file");
    }
    assert!(svgs.iter().all(|n| n.len() <= 40), "short file names: {svgs:?}");
    for n in svgs.iter().filter(|n| n.ends_with("_training.svg")) {
        assert!(html.contains(&format!("<a href=\"{n}\">")), "{n} linked, not embedded");
    }

    // The first screen: the summary, then the protocol; the run list in the appendix.
    let at = |needle: &str| md.find(needle).unwrap_or_else(|| panic!("{needle} missing:\n{md}"));
    assert!(at("## Summary") < at("## Protocol") && at("## Protocol") < at("## minitaur"));
    assert!(at("## minitaur") < at("## Appendix: the runs"));
    let summary = &md[at("## Summary")..at("## Protocol")];
    assert!(summary.contains("minitaur: Best learned: ") && summary.contains("The controller"), "{summary}");
    // Each algorithm's own best row is listed under the winner, one line per algorithm.
    let per_algo = &summary[summary.find("each algorithm at its best row").expect("per-algorithm list")..];
    for algo in ["sac", "td3"] {
        assert_eq!(per_algo.matches(&format!("\n- {algo}-drift")).count(), 1, "{algo}: {per_algo}");
    }
    // --videos: per algorithm its best row's clip beside the controller, and the pair pushed;
    // the page plays MP4s with posters, the Markdown shows GIFs.
    for algo in ["sac", "td3"] {
        for stem in [format!("minitaur_{algo}"), format!("minitaur_{algo}_push")] {
            let file = |ext: &str| std::fs::read(report.join("videos").join(format!("{stem}.{ext}"))).unwrap();
            assert_eq!(&file("mp4")[4..8], b"ftyp", "{stem}.mp4");
            assert!(file("gif").starts_with(b"GIF89a"), "{stem}.gif");
            assert!(file("jpg").starts_with(&[0xff, 0xd8]), "{stem}.jpg");
            assert!(
                html.contains(&format!("poster=\"videos/{stem}.jpg\" src=\"videos/{stem}.mp4\"")),
                "{stem} on the page"
            );
            assert!(md.contains(&format!("](videos/{stem}.gif)")), "{stem} in the Markdown");
        }
    }
    // Each clip lasts its longest panel's episode: at most the 40 steps of 10 ms these runs have.
    for d in html.split("data-duration=\"").skip(1) {
        let seconds: f64 = d.split('"').next().unwrap().parse().unwrap();
        assert!(seconds > 0.0 && seconds <= 0.4 + 1e-9, "{seconds}");
    }

    // The same report, byte for byte, on one thread and computed again without the cache.
    let first = report_files(&report);
    let cache = report.join(".cache");
    assert!(std::fs::read_dir(&cache).unwrap().count() > 0, "the default cache is OUT/.cache");
    let again = dir.path().join("report-1");
    let report_at = |out: &std::path::Path, extra: &[&str]| {
        let mut args = vec![
            "report",
            "--runs",
            s,
            "--out",
            out.to_str().unwrap(),
            "--episodes",
            "2",
            "--push-episodes",
            "1",
            "--videos",
        ];
        args.extend_from_slice(extra);
        let (ok, stdout, err) = locobench(&args);
        assert!(ok, "{stdout}\n{err}");
        (stdout, err)
    };
    let (printed, _) = report_at(&again, &["--threads", "1", "--no-cache"]);
    assert!(!printed.contains("evaluation cache") && !again.join(".cache").exists(), "--no-cache keeps nothing");
    assert_eq!(report_files(&again), first, "recomputed without the cache");

    // Again into the same directory: everything read from the cache, nothing computed, the
    // same bytes (videos included).
    let (printed, _) = report_at(&report, &[]);
    assert!(printed.contains(" read, 0 computed"), "{printed}");
    assert_eq!(report_files(&report), first, "read from the cache");

    // A damaged entry is recomputed with a warning, to the same numbers.
    let entry = std::fs::read_dir(&cache).unwrap().flatten().map(|e| e.path()).find(|p| p.is_file()).unwrap();
    let text = std::fs::read_to_string(&entry).unwrap();
    std::fs::write(&entry, &text[..text.len() / 2]).unwrap();
    let (printed, err) = report_at(&report, &[]);
    assert!(
        err.contains("is damaged") && err.contains(&entry.file_name().unwrap().to_string_lossy().to_string()),
        "{err}"
    );
    assert!(printed.contains(" read, 1 computed (1 damaged entries recomputed)"), "{printed}");
    assert_eq!(report_files(&report), first);
    assert_eq!(std::fs::read_to_string(&entry).unwrap(), text, "rewritten whole");

    // Another policy's bytes in one run: its evaluations (and only those) are computed afresh.
    let runs = sweep.join("runs");
    std::fs::copy(
        runs.join("sac-drift0-seed1/policies/step-240.safetensors"),
        runs.join("sac-drift0-seed0/policies/step-240.safetensors"),
    )
    .unwrap();
    let (printed, _) = report_at(&report, &[]);
    let computed: usize = printed
        .split(" computed")
        .next()
        .and_then(|p| p.rsplit(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{printed}"));
    assert!(computed >= 1, "{printed}");
    assert!(!printed.contains(" 0 read"), "the other runs are read: {printed}");
    assert_ne!(report_files(&report)["held_out.csv"], first["held_out.csv"], "the changed run's row changed");

    // A cache directory that cannot be written: an error naming it, and no report written.
    let blocked = dir.path().join("blocked");
    std::fs::write(&blocked, "a file").unwrap();
    let bad_cache = blocked.join("cache");
    let elsewhere = dir.path().join("report-2");
    let (ok, _, err) = locobench(&[
        "report",
        "--runs",
        s,
        "--out",
        elsewhere.to_str().unwrap(),
        "--episodes",
        "2",
        "--cache",
        bad_cache.to_str().unwrap(),
    ]);
    assert!(!ok && err.contains(bad_cache.to_str().unwrap()), "{err}");
    assert!(!elsewhere.join("index.html").exists());
}

/// Every file of a report directory (its cache aside) with its bytes, by path relative to it.
fn report_files(dir: &std::path::Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let path = e.path();
            if path.is_dir() {
                if e.file_name() != ".cache" {
                    stack.push(path);
                }
            } else {
                let rel = path.strip_prefix(dir).unwrap().to_string_lossy().to_string();
                out.insert(rel, std::fs::read(&path).unwrap());
            }
        }
    }
    out
}

/// A run whose policy file is damaged is a line in the report, not a panic or a silent gap.
#[test]
fn report_lists_a_run_whose_policy_is_unreadable() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (ok, _, err) = locobench(&[
        "train",
        "--env",
        "minitaur",
        "--algo",
        "td3",
        "--steps",
        "200",
        "--set",
        "hidden=[8,8],batch_size=16,warmup_steps=50,learning_starts=50,eval_every=100,eval_episodes=1",
        "--option",
        "max_episode_steps=30",
        "--out",
        run.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let policy = run.join("policies/step-200.safetensors");
    assert!(policy.is_file());
    std::fs::write(&policy, b"not a safetensors file").unwrap();
    let out_dir = dir.path().join("report");
    let (ok, out, err) = locobench(&[
        "report",
        "--runs",
        run.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--episodes",
        "1",
        "--push-episodes",
        "0",
    ]);
    assert!(ok, "{out}\n{err}");
    let md = std::fs::read_to_string(out_dir.join("README.md")).unwrap();
    assert!(md.contains("policy unreadable"), "{md}");
    assert!(md.contains("| 200 | 0 |"), "{md}");
}

#[test]
fn sweep_and_report_reject_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s");
    let s = s.to_str().unwrap();
    let (ok, _, err) = locobench(&["sweep", "--env", "minitaur", "--algo", "a2c", "--out", s]);
    assert!(!ok && err.contains("a2c"), "{err}");
    let (ok, _, err) = locobench(&["sweep", "--env", "nope", "--algo", "sac", "--out", s]);
    assert!(!ok && err.contains("nope"), "{err}");
    let (ok, _, err) =
        locobench(&["sweep", "--env", "minitaur", "--algo", "sac", "--grid", "drift=1:0:0.5", "--out", s]);
    assert!(!ok && err.contains("END >= START"), "{err}");
    let (ok, out, err) =
        locobench(&["sweep", "--env", "minitaur", "--algo", "sac", "--grid", "drift=0,1", "--out", s, "--dry-run"]);
    assert!(ok, "{err}");
    assert!(out.contains("6 jobs"), "{out}");
    assert!(!dir.path().join("s/runs").exists(), "a dry run trains nothing");
    let (ok, _, err) = locobench(&["report", "--runs", s, "--out", dir.path().join("r").to_str().unwrap()]);
    assert!(!ok && err.contains("no run directories"), "{err}");
}

/// The committed reports stay light and open without a network.
#[test]
fn committed_reports_are_light_and_self_contained() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/results");
    for report in ["report", "returns/quick/report"] {
        let index = root.join(report).join("index.html");
        let html = std::fs::read_to_string(&index).unwrap();
        assert!(html.len() < 500_000, "{}: {} bytes", index.display(), html.len());
        assert!(!html.contains("<script") && !html.contains("src=\"http"), "{}", index.display());
        assert!(html.contains("Protocol") && html.contains("held-out episodes"), "{}", index.display());
        // Every video, poster and GIF the pages show is committed beside them.
        let md = std::fs::read_to_string(root.join(report).join("README.md")).unwrap();
        let referenced = html
            .split(" src=\"")
            .chain(html.split(" poster=\""))
            .skip(1)
            .map(|s| s.split('"').next().unwrap().to_string())
            .filter(|s| s.starts_with("videos/"))
            .chain(md.split("](videos/").skip(1).map(|s| format!("videos/{}", s.split(')').next().unwrap())));
        for file in referenced {
            assert!(root.join(report).join(&file).is_file(), "{report}/{file}");
        }
        for file in ["held_out.csv", "controller.csv", "README.md"] {
            assert!(root.join(report).join(file).is_file(), "{report}/{file}");
        }
        // Every regeneration that changes a clip adds its bytes to the repository's history, so
        // the whole folder has a budget, and no single file takes much of it.
        let mut files = Vec::new();
        let mut dirs = vec![root.join(report)];
        while let Some(dir) = dirs.pop() {
            for entry in std::fs::read_dir(&dir).unwrap().map(Result::unwrap) {
                let meta = entry.metadata().unwrap();
                if meta.is_dir() {
                    dirs.push(entry.path());
                } else {
                    files.push((entry.path(), meta.len()));
                }
            }
        }
        let total: u64 = files.iter().map(|f| f.1).sum();
        assert!(total < REPORT_BYTES, "{report}: {total} bytes in {} files", files.len());
        for (path, bytes) in &files {
            assert!(*bytes < FILE_BYTES, "{}: {bytes} bytes", path.display());
        }
    }
}

/// The committed report's budgets: the whole folder, and any one file in it.
const REPORT_BYTES: u64 = 18_000_000;
const FILE_BYTES: u64 = 800_000;
