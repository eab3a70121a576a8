//! `locobench sweep` and `locobench report` end to end on tiny Minitaur runs.
mod common;

use common::locobench;

#[test]
fn sweep_then_report_with_baseline_comparison_under_three_rewards() {
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
    let (ok, out, err) = locobench(&["report", "--runs", s, "--out", report.to_str().unwrap(), "--episodes", "1"]);
    assert!(ok, "{out}\n{err}");
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    let md = std::fs::read_to_string(report.join("README.md")).unwrap();
    assert!(html.starts_with("<!DOCTYPE html>") && html.contains("<svg"), "inline charts");
    assert!(!html.contains("<script"), "no scripts, no network");
    for needle in ["Baseline vs RL", "no penalty", "full penalty", "trained reward (drift=0.5)", "baseline (raibert"] {
        assert!(md.contains(needle), "{needle} missing:\n{md}");
    }
    // Four groups (2 algorithms x 2 drift weights), each with 2 seeds.
    assert_eq!(md.matches("| 2 | 240 |").count(), 4, "{md}");
    let svgs: Vec<_> = std::fs::read_dir(&report)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().extension().is_some_and(|x| x == "svg"))
        .collect();
    assert_eq!(svgs.len(), 1 + 4, "one evaluation chart and one training chart per group");
    for e in svgs {
        let svg = std::fs::read_to_string(e.path()).unwrap();
        assert!(svg.contains("<svg") && (svg.contains("seed 1") || svg.contains("n=2")), "{}", e.path().display());
    }
}

#[test]
fn sweep_and_report_reject_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let s = dir.path().join("s");
    let s = s.to_str().unwrap();
    let (ok, _, err) = locobench(&["sweep", "--env", "minitaur", "--algo", "ppo", "--out", s]);
    assert!(!ok && err.contains("ppo"), "{err}");
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
