//! The robustness suite through the binary: the same episodes for every contender, a CSV that
//! reads back, thread-count independence, clear errors, and the report's section from it.
mod common;

use common::locobench;
use locobench::evaluation::robustness::output::read_dir;

const PPO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/models/policies/minitaur-ppo");

fn suite(out: &std::path::Path, threads: &str) -> (bool, String, String) {
    suite_of(&format!("ppo={PPO}"), out, threads, &[])
}

/// The small suite (payload and latency, 2 episodes, the controller at 1 m/s) for `policy`.
fn suite_of(policy: &str, out: &std::path::Path, threads: &str, extra: &[&str]) -> (bool, String, String) {
    let mut args = vec![
        "robustness",
        "--env",
        "minitaur",
        "--policy",
        policy,
        "--controller",
        "1.0",
        "--axes",
        "payload,latency",
        "--episodes",
        "2",
        "--seed",
        "100",
        "--threads",
        threads,
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    locobench(&args)
}

#[test]
fn a_small_suite_writes_every_cell_the_same_on_any_thread_count() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let (ok, out, err) = suite(&a, "1");
    assert!(ok, "{err}");
    assert!(out.contains("payload (kg):") && out.contains("90% up to"), "{out}");
    let (cells, meta) = read_dir(&a).unwrap();
    // Two contenders x (nominal + 4 payload levels + 5 latency levels).
    assert_eq!(cells.len(), 2 * 10);
    assert!(cells.iter().all(|c| c.outcomes.len() == 2));
    assert_eq!(meta.episodes, 2);
    assert_eq!(meta.protocol_seed, 100);
    assert!(meta.command.contains("robustness") && meta.wall_seconds > 0.0);
    // Each cell names the commit of the binary that played it: here, this one.
    assert!(cells.iter().all(|c| c.commit == meta.git_commit && !c.commit.is_empty()));
    // A heavier payload never helps the controller's survival on the same episodes.
    let ctrl: Vec<_> = cells.iter().filter(|c| c.kind == "controller" && c.axis == "payload").collect();
    assert_eq!(ctrl.len(), 4);
    assert!(ctrl.last().unwrap().survived() <= ctrl.first().unwrap().survived());
    assert!(suite(&b, "2").0);
    // The same file, to the last digit (a policy's commanded speed is NaN, so compare text).
    let text = |d: &std::path::Path| std::fs::read_to_string(d.join("robustness.csv")).unwrap();
    assert!(text(&a) == text(&b), "thread count changes nothing");

    // With an evaluation cache, a second suite reads every cell's episodes: the same file.
    let cache = dir.path().join("cache");
    let cached = |out: &str, threads: &str| {
        let (ok, stdout, err) =
            suite_of(&format!("ppo={PPO}"), &dir.path().join(out), threads, &["--cache", cache.to_str().unwrap()]);
        assert!(ok, "{err}");
        stdout
    };
    let first = cached("cached-1", "2");
    assert!(first.contains("evaluation cache") && first.contains(" 0 read, 20 computed"), "{first}");
    let second = cached("cached-2", "1");
    assert!(second.contains(" 20 read, 0 computed"), "{second}");
    assert!(text(&dir.path().join("cached-1")) == text(&a) && text(&dir.path().join("cached-2")) == text(&a));

    // --reuse keeps a cell only where its label still names the same policy: the same suite takes
    // every cell; the label "ppo" moved to another policy plays that policy's cells again.
    let reuse = |out: &std::path::Path, policy: &str| {
        let (ok, stdout, err) = suite_of(policy, out, "2", &["--reuse", a.to_str().unwrap()]);
        assert!(ok, "{err}");
        stdout
    };
    let same = reuse(&dir.path().join("same"), &format!("ppo={PPO}"));
    assert!(same.contains("20 of the 20 cells were taken"), "{same}");
    assert_eq!(text(&dir.path().join("same")), text(&a));
    let td3 = concat!(env!("CARGO_MANIFEST_DIR"), "/models/policies/minitaur-td3");
    let moved = reuse(&dir.path().join("moved"), &format!("ppo={td3}"));
    assert!(moved.contains("10 of the 20 cells were taken"), "only the controller's: {moved}");

    // A suite written before cells carried their commit is still read and reused; its cells say
    // they were played at its commit or an earlier one.
    let legacy = dir.path().join("legacy");
    std::fs::create_dir(&legacy).unwrap();
    std::fs::copy(a.join("robustness.toml"), legacy.join("robustness.toml")).unwrap();
    let old: String = text(&a).lines().map(|l| l.rsplit_once(',').unwrap().0.to_string() + "\n").collect();
    std::fs::write(legacy.join("robustness.csv"), old).unwrap();
    let (ok, _, err) =
        suite_of(&format!("ppo={PPO}"), &dir.path().join("from-legacy"), "2", &["--reuse", legacy.to_str().unwrap()]);
    assert!(ok, "{err}");
    let (carried, _) = read_dir(&dir.path().join("from-legacy")).unwrap();
    assert!(carried.iter().all(|c| c.commit == format!("<={}", meta.git_commit)), "{:?}", carried[0].commit);

    // The report's section from it: summary, goal, a chart per axis.
    let report = dir.path().join("report");
    let (ok, _, err) = locobench(&[
        "report",
        "--runs",
        PPO,
        "--out",
        report.to_str().unwrap(),
        "--episodes",
        "2",
        "--push-episodes",
        "0",
        "--robustness",
        a.to_str().unwrap(),
        "--videos",
    ]);
    assert!(ok, "{err}");
    let md = std::fs::read_to_string(report.join("README.md")).unwrap();
    assert!(md.contains("## Robustness suite") && md.contains("furthest at 90%"), "{md}");
    for axis in ["payload", "latency"] {
        let svg = std::fs::read_to_string(report.join(format!("minitaur_robustness_{axis}.svg"))).unwrap();
        assert!(svg.contains("survival") && svg.contains("ppo"));
        // Its side-by-side clip: the policy and the controller replaying an episode of the suite,
        // ending as the suite recorded it.
        let stem = format!("minitaur_robustness_{axis}");
        let mp4 = std::fs::read(report.join("videos").join(format!("{stem}.mp4"))).unwrap();
        assert_eq!(&mp4[4..8], b"ftyp", "{stem}.mp4");
        // No GIF: the Markdown page shows the poster, linked to the MP4.
        assert!(!report.join("videos").join(format!("{stem}.gif")).exists(), "{stem}.gif");
        let jpg = std::fs::read(report.join("videos").join(format!("{stem}.jpg"))).unwrap();
        assert!(jpg.starts_with(&[0xff, 0xd8]), "{stem}.jpg");
        assert!(md.contains(&format!("](videos/{stem}.jpg)](videos/{stem}.mp4)")), "{stem} in the Markdown");
        let caption = md.split(&format!("videos/{stem}.jpg")).next().unwrap().rsplit("![").next().unwrap();
        assert!(caption.contains("left to right ppo (") && caption.contains("as the suite recorded them"), "{caption}");
        assert!(!caption.contains("The replay ended otherwise"), "{caption}");
    }
    // Every clip on the page lasts, in a player (frames / fps), the episode time it claims, to
    // within a frame: a clip cut after the last fall keeps whole frames only.
    let html = std::fs::read_to_string(report.join("index.html")).unwrap();
    for tag in html.split("<video ").skip(1) {
        let attr =
            |name: &str| tag.split(&format!("{name}=\"")).nth(1).map(|v| v.split('"').next().unwrap().to_string());
        let (Some(src), Some(duration), Some(fps)) = (attr("src"), attr("data-duration"), attr("data-fps")) else {
            continue;
        };
        let (duration, fps): (f64, f64) = (duration.parse().unwrap(), fps.parse().unwrap());
        let probe = std::process::Command::new("ffprobe")
            .args(["-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries"])
            .args(["stream=nb_read_frames", "-of", "csv=p=0"])
            .arg(report.join(&src))
            .output()
            .expect("ffprobe (Debian's ffmpeg, installed by scripts/setup.sh)");
        let frames: f64 = String::from_utf8_lossy(&probe.stdout).trim().parse().unwrap();
        assert!(
            (frames / fps - duration).abs() <= 1.0 / fps + 1e-3,
            "{src}: {frames} frames at {fps} fps, {duration} s"
        );
    }
}

#[test]
fn bad_axes_policies_and_levels_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x");
    let o = out.to_str().unwrap();
    let (ok, _, err) = locobench(&["robustness", "--axes", "wind", "--out", o]);
    assert!(!ok && err.contains("unknown robustness axis 'wind'") && err.contains("payload"), "{err}");
    let (ok, _, err) = locobench(&["robustness", "--policy", PPO, "--out", o]);
    assert!(!ok && err.contains("LABEL=REFERENCE"), "{err}");
    let (ok, _, err) = locobench(&["robustness", "--controller", "fast", "--out", o]);
    assert!(!ok && err.contains("best, matched or a speed"), "{err}");
    let (ok, _, err) = locobench(&["robustness", "--env", "hopper", "--out", o]);
    assert!(!ok && err.contains("hopper"), "{err}");
    let (ok, _, err) = locobench(&["eval", "--policy", PPO, "--episodes", "1", "--option", "payload_mass=-2"]);
    assert!(!ok && err.contains("payload_mass"), "{err}");
    let (ok, _, err) = locobench(&["eval", "--policy", PPO, "--episodes", "1", "--option", "terrain_step_height=0.3"]);
    assert!(!ok && err.contains("terrain_step_height"), "{err}");
    assert!(!out.exists(), "no output from a refused suite");
}

#[test]
fn the_protocol_evaluates_a_policy_trained_under_perturbations_in_the_nominal_world() {
    use locobench::envs::EnvConfig;
    let trained = EnvConfig::new("minitaur")
        .with_overrides(&[
            ("random_push_max".into(), "0.75".into()),
            ("terrain_step_height".into(), "0.02".into()),
            ("foot_friction_range".into(), "[0.5, 2.0]".into()),
            ("drift_weight".into(), "0.5".into()),
        ])
        .unwrap();
    let eval = trained.for_evaluation();
    for perturbation in ["random_push_max", "terrain_step_height", "foot_friction_range"] {
        assert!(!eval.options.contains_key(perturbation), "{perturbation}");
    }
    assert_eq!(eval.options.get("drift_weight"), trained.options.get("drift_weight"), "the reward stays the run's");
    assert_eq!(EnvConfig::new("ant").for_evaluation(), EnvConfig::new("ant"));
    // a command task's base perturbations too, its command settings kept
    let trained = EnvConfig::new("minitaur-command")
        .with_overrides(&[
            ("random_push_max".into(), "1.0".into()),
            ("random_battery_min".into(), "6.0".into()),
            ("tracking_sigma".into(), "0.05".into()),
        ])
        .unwrap();
    let eval = trained.for_evaluation();
    assert!(!eval.options.contains_key("random_push_max") && !eval.options.contains_key("random_battery_min"));
    assert_eq!(eval.options.get("tracking_sigma"), trained.options.get("tracking_sigma"));
    let ant = EnvConfig::new("ant-command").with_overrides(&[("payload_mass".into(), "2.0".into())]).unwrap();
    assert_eq!(ant.for_evaluation(), EnvConfig::new("ant-command"));
}
