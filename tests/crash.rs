//! Crash safety: a training run killed with SIGKILL at each dangerous moment (half-way through a
//! checkpoint, right after one, mid-episode, during an evaluation, half-way through a budget
//! policy) and then resumed leaves exactly the files an unbroken run leaves: `metrics.csv`, every
//! checkpoint, the budget policies and `provenance.csv`, byte for byte but for the wall-time and
//! rate columns. The kills come from the binary's own crash points (`LOCOBENCH_FAULT`, see
//! `src/train/fault.rs`), so each lands exactly where it is meant to, every time.
//!
//! Also the edges of resume: a run killed before its first checkpoint, a damaged newest
//! checkpoint, a disk that fills up mid-checkpoint, two processes on one run directory, and a
//! damaged `metrics.csv`.
use std::collections::BTreeMap;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const STEPS: &str = "1500";

/// Small networks on the small task: a run takes about a second.
fn settings(algo: &str) -> &'static str {
    match algo {
        "ppo" => {
            "hidden=[16,16],num_envs=2,num_steps=50,num_minibatches=2,update_epochs=2,eval_every=500,eval_episodes=2,\
             checkpoint_every=300"
        }
        "crossq" => {
            "hidden=[16,16],critic_hidden=[32,32],batch_size=32,warmup_steps=200,learning_starts=200,eval_every=500,\
             eval_episodes=2,checkpoint_every=300"
        }
        "dqn" => {
            "hidden=[16,16],batch_size=32,exploration_steps=500,learning_starts=200,eval_every=500,eval_episodes=2,\
             checkpoint_every=300"
        }
        _ => {
            "hidden=[16,16],batch_size=32,warmup_steps=200,learning_starts=200,eval_every=500,eval_episodes=2,\
             checkpoint_every=300"
        }
    }
}

fn locobench(args: &[&str], fault: Option<&str>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_locobench"));
    cmd.args(args);
    match fault {
        Some(f) => cmd.env("LOCOBENCH_FAULT", f),
        None => cmd.env_remove("LOCOBENCH_FAULT"),
    };
    cmd.output().unwrap()
}

fn train_args<'a>(algo: &'a str, out: &'a str, extra: &'a str) -> Vec<&'a str> {
    let mut args = vec!["train", "--env", "inverted-pendulum", "--algo", algo, "--seed", "5", "--steps", STEPS];
    args.extend(["--set", settings(algo), "--out", out, "--quiet", "--threads", "1"]);
    if !extra.is_empty() {
        args.extend(["--set", extra]);
    }
    args
}

fn train(algo: &str, out: &Path, fault: Option<&str>) -> Output {
    locobench(&train_args(algo, out.to_str().unwrap(), ""), fault)
}

fn resume(out: &Path) -> Output {
    locobench(&["train", "--resume", out.to_str().unwrap(), "--quiet", "--threads", "1"], None)
}

fn ok(out: &Output, what: &str) {
    assert!(
        out.status.success(),
        "{what} failed: {}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

fn killed(out: &Output, what: &str) {
    assert_eq!(
        out.status.signal(),
        Some(libc_sigkill()),
        "{what} was not killed at its crash point: {:?}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

fn libc_sigkill() -> i32 {
    9
}

/// Every file of a run directory by relative path, with the wall-time and rate columns of
/// `metrics.csv` and the wall time of `state.toml` left out. `checksums.toml` is listed without
/// its contents, since it sums those two files with their wall times.
fn contents(run: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).unwrap().flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(root, &path, out);
                continue;
            }
            let rel = path.strip_prefix(root).unwrap().to_string_lossy().into_owned();
            let name = entry.file_name().to_string_lossy().into_owned();
            let bytes = std::fs::read(&path).unwrap();
            let kept = match name.as_str() {
                "metrics.csv" => String::from_utf8(bytes)
                    .unwrap()
                    .lines()
                    .map(|l| {
                        let f: Vec<&str> = l.split(',').collect();
                        f.iter()
                            .enumerate()
                            .filter(|(i, _)| *i != 9 && *i != 10)
                            .map(|(_, v)| *v)
                            .collect::<Vec<_>>()
                            .join(",")
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
                    .into_bytes(),
                "state.toml" => String::from_utf8(bytes)
                    .unwrap()
                    .lines()
                    .filter(|l| !l.starts_with("wall_time"))
                    .collect::<Vec<_>>()
                    .join("\n")
                    .into_bytes(),
                "checksums.toml" => Vec::new(),
                _ => bytes,
            };
            out.insert(rel, kept);
        }
    }
    let mut out = BTreeMap::new();
    walk(run, run, &mut out);
    out
}

fn assert_same_run(whole: &Path, resumed: &Path, what: &str) {
    let (a, b) = (contents(whole), contents(resumed));
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>(), "{what}: the files differ");
    for (name, bytes) in &a {
        if *bytes != b[name] {
            panic!(
                "{what}: {name} differs from the unbroken run's{}",
                if name.ends_with(".csv") || name.ends_with(".toml") {
                    format!(
                        ":\n--- unbroken\n{}\n--- resumed\n{}",
                        String::from_utf8_lossy(bytes),
                        String::from_utf8_lossy(&b[name])
                    )
                } else {
                    String::new()
                }
            );
        }
    }
}

/// The unbroken run, then one killed run per crash point, each resumed and compared.
fn crash_and_resume(algo: &str, points: &[&str]) {
    crash_and_resume_with(algo, "", points);
}

/// [`crash_and_resume`] with `extra` settings on top of the algorithm's.
fn crash_and_resume_with(algo: &str, extra: &str, points: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    let train = |out: &Path, fault| locobench(&train_args(algo, out.to_str().unwrap(), extra), fault);
    ok(&train(&whole, None), "the unbroken run");
    assert!(contents(&whole).keys().any(|k| k.starts_with("policies/step-1500")), "no budget policy");
    for point in points {
        let run = dir.path().join(point.replace(':', "-"));
        let what = format!("{algo} {extra} killed at {point}");
        killed(&train(&run, Some(point)), &what);
        let out = resume(&run);
        ok(&out, &format!("resuming {what}"));
        assert_same_run(&whole, &run, &what);
    }
}

/// Where to kill: a checkpoint's second write, right after the first checkpoint, a step inside
/// an episode, the second evaluation after its first episode, and the final budget policy.
fn points(algo: &str) -> [&'static str; 5] {
    // PPO's step point counts steps of its two copies at once.
    let step = if algo == "ppo" { "step:333" } else { "step:777" };
    ["checkpoint-write:2", "after-checkpoint:1", step, "evaluation:3", "budget-policy-write:1"]
}

#[test]
fn td3_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume("td3", &points("td3"));
}

#[test]
fn sac_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume("sac", &points("sac"));
}

#[test]
fn layer_normalised_critics_killed_anywhere_resume_to_the_unbroken_run() {
    crash_and_resume_with("td3", "critic_layer_norm=true", &["checkpoint-write:2", "step:777"]);
    crash_and_resume_with("sac", "critic_layer_norm=true", &["after-checkpoint:1", "evaluation:3"]);
}

/// SAC with CrossQ's optimiser settings: the delayed actor's phase comes back with the run.
#[test]
fn sac_with_a_delayed_actor_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume_with("sac", "policy_delay=3,adam_beta1=0.5,tau=1", &["after-checkpoint:1", "step:777"]);
}

/// Keeping the best evaluated actor: its files (`policies/best-step-N`, `selected.csv`) come back
/// with the run too. The budget-policy point here kills the first best actor's write.
#[test]
fn td3_keeping_its_best_actor_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume_with("td3", "budget_policy=best", &points("td3"));
}

/// The same with the fewest falls deciding: the falls each kept actor's evaluation counted come
/// back from the checkpoint.
#[test]
fn td3_keeping_its_actor_with_fewest_falls_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume_with(
        "td3",
        "budget_policy=fewest_falls",
        &["after-checkpoint:1", "budget-policy-write:1", "step:777"],
    );
}

/// Keeping the best actor of evaluations that each draw fresh starts: the starts follow the step,
/// so a run killed at an evaluation replays the same ones when it resumes.
#[test]
fn td3_picking_on_fresh_evaluation_starts_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume_with(
        "td3",
        "budget_policy=best,eval_starts=fresh",
        &["evaluation:3", "budget-policy-write:2", "step:777"],
    );
}

#[test]
fn ppo_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume("ppo", &points("ppo"));
}

#[test]
fn crossq_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume("crossq", &points("crossq"));
}

#[test]
fn dqn_killed_anywhere_resumes_to_the_unbroken_run() {
    crash_and_resume("dqn", &points("dqn"));
}

/// Killed before its first checkpoint: `--resume` and `--resume-if-exists` start it afresh from
/// its config, and the result is the unbroken run.
#[test]
fn a_run_killed_before_its_first_checkpoint_starts_afresh() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    ok(&train("td3", &whole, None), "the unbroken run");
    let early = dir.path().join("early");
    killed(&train("td3", &early, Some("step:100")), "td3 at step 100");
    assert!(!early.join("checkpoints").exists());
    let out = resume(&early);
    ok(&out, "resume");
    assert!(String::from_utf8_lossy(&out.stderr).contains("starting it afresh"), "{out:?}");
    assert_same_run(&whole, &early, "resumed before its first checkpoint");

    let again = dir.path().join("again");
    killed(&train("td3", &again, Some("step:100")), "td3 at step 100");
    let mut args = train_args("td3", again.to_str().unwrap(), "");
    args.push("--resume-if-exists");
    let out = locobench(&args, None);
    ok(&out, "--resume-if-exists");
    assert_same_run(&whole, &again, "--resume-if-exists before its first checkpoint");
}

fn newest_checkpoint(run: &Path) -> PathBuf {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(run.join("checkpoints"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with("step_"))
        .collect();
    dirs.sort();
    dirs.pop().unwrap()
}

/// A damaged newest checkpoint (a flipped byte in its weights, or its buffer cut short) is passed
/// over with a warning on stderr, and the previous one resumes to the unbroken run.
#[test]
fn a_damaged_newest_checkpoint_falls_back_to_the_previous_one() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    ok(&train("sac", &whole, None), "the unbroken run");
    for (file, damage) in [("model.safetensors", "flip"), ("buffer.safetensors", "cut")] {
        let run = dir.path().join(file);
        killed(&train("sac", &run, Some("step:1200")), "sac at step 1200");
        let newest = newest_checkpoint(&run);
        let path = newest.join(file);
        let mut bytes = std::fs::read(&path).unwrap();
        match damage {
            "flip" => {
                let at = bytes.len() - 9;
                bytes[at] ^= 0x40;
            }
            _ => bytes.truncate(bytes.len() / 2),
        }
        std::fs::write(&path, bytes).unwrap();
        let out = resume(&run);
        ok(&out, &format!("resume past a damaged {file}"));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains("passing over a damaged checkpoint")
                && stderr.contains(&*path.to_string_lossy())
                && stderr.contains("resuming from"),
            "{stderr}"
        );
        // The resumed run rewrote the damaged checkpoint as the unbroken run wrote it.
        assert_same_run(&whole, &run, &format!("resumed past a damaged {file}"));
    }
}

/// A disk that fills up mid-checkpoint: a clear error, nothing half-written left behind, and the
/// previous checkpoint resumes (elsewhere) to the unbroken run. Needs a small tmpfs, so root.
#[test]
fn a_full_disk_mid_checkpoint_is_a_clear_error_and_the_previous_checkpoint_still_loads() {
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small");
    std::fs::create_dir(&small).unwrap();
    let mounted = Command::new("mount").args(["-t", "tmpfs", "-o", "size=4m", "tmpfs"]).arg(&small).output();
    if !mounted.as_ref().is_ok_and(|o| o.status.success()) {
        eprintln!(
            "skipped: cannot mount a 4 MB tmpfs here (needs root): {}",
            mounted.map(|o| String::from_utf8_lossy(&o.stderr).into_owned()).unwrap_or_else(|e| e.to_string())
        );
        return;
    }
    struct Unmount(PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }
    let _unmount = Unmount(small.clone());
    // Wide networks: each checkpoint is about 1.3 MB, so the disk fills a few checkpoints in.
    let wide = "hidden=[128,128]";
    let full = small.join("run");
    let out = locobench(&train_args("td3", full.to_str().unwrap(), wide), None);
    assert!(!out.status.success(), "the run should not fit in 4 MB");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("No space left on device"), "{stderr}");
    assert!(stderr.contains("writing checkpoint") && stderr.contains("earlier checkpoints are untouched"), "{stderr}");
    let leftovers: Vec<String> = ["", "checkpoints", "policies"]
        .iter()
        .flat_map(|d| std::fs::read_dir(full.join(d)).into_iter().flatten().flatten())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "half-written files left: {leftovers:?}");
    assert!(!full.join("run.lock").exists());

    // Copied to a disk with room, the run resumes from its newest intact checkpoint.
    let moved = dir.path().join("moved");
    let copied = Command::new("cp").arg("-a").arg(&full).arg(&moved).status().unwrap();
    assert!(copied.success());
    ok(&resume(&moved), "resume after the disk filled up");
    let whole = dir.path().join("whole");
    ok(&locobench(&train_args("td3", whole.to_str().unwrap(), wide), None), "the unbroken run");
    assert_same_run(&whole, &moved, "resumed after a full disk");
}

/// Two processes on one run directory: the second is refused, naming the first; once the first
/// is killed, its lock is taken over.
#[test]
fn a_second_process_on_a_run_directory_is_refused_until_the_first_dies() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let r = run.to_str().unwrap();
    let long = ["train", "--env", "inverted-pendulum", "--algo", "td3", "--steps", "1000000", "--quiet"];
    let mut first = Command::new(env!("CARGO_BIN_EXE_locobench"))
        .args(long)
        .args(["--set", "hidden=[16,16],batch_size=32", "--out", r])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    while !(run.join("run.lock").exists() && run.join("config.toml").exists()) {
        assert!(std::time::Instant::now() < deadline, "the first process never took the lock");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let pid = first.id().to_string();
    let refused = |args: &[&str]| {
        let out = locobench(args, None);
        assert!(!out.status.success(), "{args:?} ran beside the first process");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(stderr.contains("is being trained by process") && stderr.contains(&pid), "{args:?}: {stderr}");
    };
    refused(&["train", "--resume", r, "--quiet"]);
    refused(&["train", "--env", "inverted-pendulum", "--algo", "td3", "--out", r, "--force", "--quiet"]);
    refused(&["train", "--resume", r, "--steps", "2000000", "--quiet"]);
    first.kill().unwrap();
    first.wait().unwrap();
    // Dead: its lock no longer holds anyone out. The next process gets past the lock and trains
    // (until its own crash point stops it).
    killed(&locobench(&["train", "--resume", r, "--steps", "2000000", "--quiet"], Some("step:1")), "taking over");
}

/// A `metrics.csv` cut to its header line, or with a garbled row, is an error that names the
/// file and the checkpoint's copy, and changes nothing; restored from that copy, the run resumes
/// to the unbroken run.
#[test]
fn a_damaged_metrics_file_is_an_error_never_a_silent_rewrite() {
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole");
    ok(&train("td3", &whole, None), "the unbroken run");
    let run = dir.path().join("run");
    killed(&train("td3", &run, Some("step:1200")), "td3 at step 1200");
    let metrics = run.join("metrics.csv");
    let original = std::fs::read_to_string(&metrics).unwrap();
    let header = original.lines().next().unwrap().to_string();
    let mut garbled: Vec<&str> = original.lines().collect();
    garbled[3] = "episode,12x,,,,,,,,0.0,0.000,";
    for (damaged, expect) in [
        (format!("{header}\n"), "ends after line 1"),
        (garbled.join("\n") + "\n", "line 4 is not a metrics row"),
        (original.lines().take(4).collect::<Vec<_>>().join("\n"), "ends after line 4"),
    ] {
        std::fs::write(&metrics, &damaged).unwrap();
        // The killed process's lock file (it holds no lock) is the one thing a resume may remove.
        let _ = std::fs::remove_file(run.join("run.lock"));
        let before = contents(&run);
        let out = resume(&run);
        assert!(!out.status.success(), "resumed over a damaged metrics.csv");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(&*metrics.to_string_lossy()) && stderr.contains(expect) && stderr.contains("copy that one"),
            "{stderr}"
        );
        assert_eq!(before, contents(&run), "a failed resume changed the run directory");
    }
    let copy = newest_checkpoint(&run).join("metrics.csv");
    std::fs::copy(copy, &metrics).unwrap();
    ok(&resume(&run), "resume from the restored metrics");
    assert_same_run(&whole, &run, "resumed after restoring metrics.csv");
}
