//! The `locobench` binary: envs listing, rollouts to CSV, exact replays, clear errors.
mod common;

use std::process::Command;

use common::locobench;

#[test]
fn envs_lists_every_environment_with_sizes() {
    let (ok, out, _) = locobench(&["envs"]);
    assert!(ok);
    for (name, obs, act) in [
        ("half-cheetah", 17, 6),
        ("ant", 105, 8),
        ("humanoid", 348, 17),
        ("inverted-pendulum", 4, 1),
        ("minitaur", 28, 8),
    ] {
        let line = out.lines().find(|l| l.starts_with(name)).unwrap_or_else(|| panic!("{name} missing:\n{out}"));
        let cols: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(cols[1], obs.to_string(), "{line}");
        assert_eq!(cols[2], act.to_string(), "{line}");
    }
}

#[test]
fn rollout_writes_one_row_per_step_and_replays_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let first = dir.path().join("first.csv");
    let (ok, out, err) = locobench(&[
        "rollout",
        "--env",
        "half-cheetah",
        "--policy",
        "random",
        "--episodes",
        "2",
        "--seed",
        "7",
        "--option",
        "max_episode_steps=30",
        "--out",
        first.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("episode 1"));
    let text = std::fs::read_to_string(&first).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(&header[..3], &["episode", "step", "action_0"]);
    for col in ["reward", "forward", "ctrl_cost", "terminated", "truncated", "obs_16"] {
        assert!(header.contains(&col), "missing {col}");
    }
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 60);
    let truncated = header.iter().position(|c| *c == "truncated").unwrap();
    assert_eq!(rows[29][truncated], "1");
    assert_eq!(rows[30][0], "1");
    // reward = sum of the terms in every row
    let (r, f, c) = (
        header.iter().position(|c| *c == "reward").unwrap(),
        header.iter().position(|c| *c == "forward").unwrap(),
        header.iter().position(|c| *c == "ctrl_cost").unwrap(),
    );
    for row in &rows {
        let v = |i: usize| row[i].parse::<f64>().unwrap();
        assert!((v(r) - v(f) - v(c)).abs() < 1e-12);
    }

    let replay = dir.path().join("replay.csv");
    let actions = format!("actions:{}", first.display());
    let (ok, _, err) = locobench(&[
        "rollout",
        "--env",
        "half-cheetah",
        "--policy",
        &actions,
        "--episodes",
        "2",
        "--seed",
        "7",
        "--option",
        "max_episode_steps=30",
        "--out",
        replay.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert_eq!(std::fs::read_to_string(&replay).unwrap(), text, "a replay must reproduce the trajectory exactly");
}

#[test]
fn plain_action_files_and_reset_noise() {
    let dir = tempfile::tempdir().unwrap();
    let actions = dir.path().join("a.csv");
    std::fs::write(&actions, "0.5\n-0.5\n0.25\n").unwrap();
    let out = dir.path().join("out.csv");
    let (ok, stdout, err) = locobench(&[
        "rollout",
        "--env",
        "inverted-pendulum",
        "--policy",
        &format!("actions:{}", actions.display()),
        "--reset-noise",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(stdout.contains("over 3 steps"), "{stdout}");
    let text = std::fs::read_to_string(&out).unwrap();
    let row: Vec<&str> = text.lines().nth(1).unwrap().split(',').collect();
    assert_eq!(row[2], "0.5");
}

#[test]
fn bad_input_fails_with_a_clear_message_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("never.csv");
    let o = out.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (&["rollout", "--env", "hoppr", "--out", o], "unknown environment 'hoppr'"),
        (&["rollout", "--env", "ant", "--policy", "smart", "--out", o], "unknown policy 'smart'"),
        (&["rollout", "--env", "ant", "--policy", "actions:/no/such.csv", "--out", o], "/no/such.csv"),
        (&["rollout", "--env", "ant", "--option", "ctrl_cost_weight=-2", "--out", o], "ctrl_cost_weight"),
        (&["rollout", "--env", "ant", "--option", "bogus", "--out", o], "not key=value"),
    ];
    for (args, expect) in cases {
        let (ok, _, err) = locobench(args);
        assert!(!ok, "{args:?} should fail");
        assert!(err.contains(expect), "{args:?}: {err}");
    }
    // An action file for another env: wrong action length.
    let wrong = dir.path().join("wrong.csv");
    std::fs::write(&wrong, "0.1,0.2\n").unwrap();
    let (ok, _, err) =
        locobench(&["rollout", "--env", "ant", "--policy", &format!("actions:{}", wrong.display()), "--out", o]);
    assert!(!ok && err.contains("expects 8"), "{err}");
    assert!(!out.exists(), "a failed rollout must not leave a partial file");
}

/// A run whose evaluations each drew fresh starts: `eval --training-seeds` asks which evaluation,
/// and replays the one named by its step, to the logged mean.
#[test]
fn eval_replays_a_fresh_start_evaluation_named_by_its_step() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let r = run.to_str().unwrap();
    let set = "warmup_steps=200,learning_starts=200,eval_every=300,eval_episodes=2,hidden=[16,16],batch_size=32,\
               eval_starts=\"fresh\"";
    let train = ["train", "--env", "hopper", "--algo", "sac", "--steps", "600", "--set", set, "--out", r, "--quiet"];
    let (ok, _, err) = locobench(&train);
    assert!(ok, "{err}");
    let (ok, _, err) = locobench(&["eval", "--policy", r, "--training-seeds"]);
    assert!(!ok && err.contains("--eval-step STEP") && err.contains("eval_starts = \"fresh\""), "{err}");
    let (ok, _, err) = locobench(&["eval", "--policy", r, "--training-seeds", "--eval-step", "0"]);
    assert!(!ok && err.contains("--eval-step must be"), "{err}");
    let (ok, _, err) = locobench(&["eval", "--policy", r, "--eval-step", "600"]);
    assert!(!ok && err.contains("--training-seeds"), "--eval-step alone is refused: {err}");

    let metrics = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    let logged = |step: &str| -> f64 {
        let row = metrics.lines().find(|l| l.starts_with(&format!("eval,{step},"))).unwrap();
        row.split(',').nth(4).unwrap().parse().unwrap()
    };
    let replay = |step: &str| {
        let (ok, out, err) =
            locobench(&["eval", "--policy", r, "--training-seeds", "--eval-step", step, "--episodes", "2"]);
        assert!(ok, "{err}");
        out
    };
    let at_600 = replay("600");
    assert!(at_600.contains(&format!("return {:.3} ", logged("600"))), "{at_600}\n{metrics}");
    assert_ne!(logged("300"), logged("600"));
    assert!(!replay("300").contains(&format!("return {:.3} ", logged("600"))), "another step plays other starts");
}

#[test]
fn train_eval_resume_and_fine_tune_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let r = run.to_str().unwrap();
    let set = "warmup_steps=200,learning_starts=200,eval_every=500,eval_episodes=2,hidden=[16,16],batch_size=32,checkpoint_every=400";
    let (ok, out, err) = locobench(&[
        "train",
        "--env",
        "inverted-pendulum",
        "--algo",
        "sac",
        "--seed",
        "3",
        "--steps",
        "600",
        "--set",
        set,
        "--out",
        r,
        "--quiet",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("finished"), "{out}");
    assert!(run.join("metrics.csv").exists() && run.join("config.toml").exists());

    let (ok, out, err) = locobench(&["eval", "--policy", r, "--episodes", "3"]);
    assert!(ok, "{err}");
    assert!(out.contains("3 held-out episodes") && out.contains("healthy") && out.contains("IQM"), "{out}");
    // The run's own evaluation episodes, as during training, on request.
    let (ok, out, err) = locobench(&["eval", "--policy", r, "--episodes", "3", "--training-seeds"]);
    assert!(ok && out.contains("the run's evaluation episodes") && out.contains("over 3 episodes"), "{out}\n{err}");
    // Its evaluations all played the same starts: no evaluation to name.
    let (ok, _, err) = locobench(&["eval", "--policy", r, "--training-seeds", "--eval-step", "500"]);
    assert!(!ok && err.contains("--eval-step") && err.contains("eval_starts = \"fixed\""), "{err}");
    // The actor saved at the run's budget; a budget it never passed is a clear error.
    let (ok, out, err) = locobench(&["eval", "--policy", r, "--episodes", "3", "--budget", "600"]);
    assert!(ok && out.contains("3 held-out episodes"), "{out}\n{err}");
    let (ok, _, err) = locobench(&["eval", "--policy", r, "--budget", "500"]);
    assert!(!ok && err.contains("no policy at step 500"), "{err}");
    // The old spelling still works, with a note.
    let (ok, out, err) = locobench(&["eval", "--checkpoint", r, "--episodes", "3"]);
    assert!(ok && out.contains("3 held-out episodes") && err.contains("--checkpoint is deprecated"), "{out}\n{err}");

    // Same directory again: refused without --force.
    let (ok, _, err) =
        locobench(&["train", "--env", "inverted-pendulum", "--algo", "sac", "--steps", "600", "--out", r, "--quiet"]);
    assert!(!ok && err.contains("--force"), "{err}");

    // Resuming a finished run is a no-op that still succeeds.
    let (ok, out, err) = locobench(&["train", "--resume", r, "--quiet"]);
    assert!(ok, "{err}");
    assert!(out.contains("finished"), "{out}");

    // Fine-tune under new reward weights (Minitaur terms) is refused for a pendulum checkpoint.
    let ft = dir.path().join("ft");
    let (ok, _, err) = locobench(&[
        "train",
        "--env",
        "minitaur",
        "--algo",
        "sac",
        "--init-from",
        r,
        "--reward",
        "drift=0.25,shake=0.1",
        "--set",
        "hidden=[16,16]",
        "--steps",
        "10",
        "--out",
        ft.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(!ok && err.contains("shape"), "{err}");
}

#[test]
fn train_rejects_bad_arguments() {
    let dir = tempfile::tempdir().unwrap();
    let o = dir.path().join("x");
    let o = o.to_str().unwrap();
    let cases: [(&[&str], &str); 6] = [
        (&["train", "--env", "ant", "--algo", "a2c", "--out", o], "unknown algorithm 'a2c'"),
        (&["train", "--env", "hoppr", "--algo", "td3", "--out", o], "unknown environment 'hoppr'"),
        (&["train", "--env", "ant", "--algo", "td3", "--set", "tau=7", "--out", o], "tau"),
        (&["train", "--env", "ant", "--algo", "td3", "--reward", "wobble=1", "--out", o], "wobble"),
        (&["eval", "--policy", "/no/such/run"], "no policy at /no/such/run"),
        (&["train", "--env", "ant", "--algo", "td3", "--threads", "3", "--out", o], "3 is not in 1..=2"),
    ];
    for (args, expect) in cases {
        let (ok, _, err) = locobench(args);
        assert!(!ok, "{args:?} should fail");
        assert!(err.contains(expect), "{args:?}: {err}");
    }
}

#[test]
fn ctrl_c_stops_training_with_a_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let r = run.to_str().unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_locobench"))
        .args([
            "train",
            "--env",
            "inverted-pendulum",
            "--algo",
            "td3",
            "--steps",
            "200000",
            "--set",
            "hidden=[16,16],batch_size=32,warmup_steps=100,learning_starts=100",
            "--out",
            r,
            "--quiet",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(2500));
    let status = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(stdout.contains("stopped at step"), "{stdout}");
    let latest = std::fs::read_to_string(run.join("checkpoints/latest")).unwrap();
    assert!(run.join("checkpoints").join(latest.trim()).join("model.safetensors").exists());
}

#[test]
fn an_exported_policy_acts_exactly_as_its_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let (r, exported) = (run.to_str().unwrap(), dir.path().join("policy"));
    let set = "warmup_steps=100,learning_starts=100,eval_every=300,eval_episodes=2,batch_size=32";
    let args =
        ["train", "--env", "inverted-pendulum", "--algo", "td3", "--steps", "300", "--set", set, "--out", r, "--quiet"];
    let (ok, _, err) = locobench(&args);
    assert!(ok, "{err}");
    let (ok, out, err) = locobench(&["export", "--policy", r, "--out", exported.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(out.contains("policy.safetensors"), "{out}");
    let policy = std::fs::metadata(exported.join("policy.safetensors")).unwrap().len();
    let latest = std::fs::read_to_string(run.join("checkpoints/latest")).unwrap();
    let model = std::fs::metadata(run.join("checkpoints").join(latest.trim()).join("model.safetensors")).unwrap().len();
    assert!(policy * 3 < model, "the actor alone ({policy} B) is a fraction of the checkpoint ({model} B)");
    assert!(exported.join("config.toml").exists() && exported.join("metrics.csv").exists());
    // Same evaluation, number for number, from the export and from the checkpoint.
    let eval = |p: &str| {
        let (ok, out, err) = locobench(&["eval", "--policy", p, "--episodes", "3", "--seed", "7"]);
        assert!(ok, "{err}");
        out.split_once(": ").unwrap().1.to_string()
    };
    assert_eq!(eval(exported.to_str().unwrap()), eval(r));
    // An export is not a checkpoint to resume or fine-tune from.
    let (ok, _, err) = locobench(&["train", "--resume", exported.to_str().unwrap(), "--quiet"]);
    assert!(!ok && err.contains("no checkpoint"), "{err}");
}

/// Every command that builds an environment takes the same option group: a TOML file, then
/// `--option`, then `--reward`, in that order.
#[test]
fn env_options_file_option_and_reward_work_alike_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("env.toml");
    std::fs::write(&file, "[options]\nmax_episode_steps = 30\ndrift_weight = 0.5\n").unwrap();
    let f = file.to_str().unwrap();
    let run = dir.path().join("run");
    let r = run.to_str().unwrap();
    let (ok, out, err) = locobench(&[
        "train",
        "--env",
        "minitaur",
        "--algo",
        "sac",
        "--steps",
        "60",
        "--env-config",
        f,
        "--option",
        "drift_weight=0.75",
        "--reward",
        "shake=0.25",
        "--set",
        "hidden=[8,8],batch_size=16,warmup_steps=20,learning_starts=20,eval_every=60,eval_episodes=1",
        "--out",
        r,
        "--quiet",
        "--threads",
        "1",
    ]);
    assert!(ok, "{out}\n{err}");
    let config = std::fs::read_to_string(run.join("config.toml")).unwrap();
    for line in ["max_episode_steps = 30", "drift_weight = 0.75", "shake_weight = 0.25"] {
        assert!(config.contains(line), "{line} missing:\n{config}");
    }
    // eval, baseline and rollout read the same file; a reward term an env lacks is an error.
    let (ok, out, err) = locobench(&["eval", "--policy", r, "--episodes", "1", "--env-config", f]);
    assert!(ok && out.contains("length  30.0"), "{out}\n{err}");
    let (ok, out, err) =
        locobench(&["baseline", "--env", "minitaur", "--episodes", "1", "--env-config", f, "--reward", "drift=1"]);
    let row = out.lines().nth(1).unwrap_or_default();
    assert!(ok && row.split_whitespace().any(|c| c == "30"), "episode length 30 expected:\n{out}\n{err}");
    let csv = dir.path().join("r.csv");
    let (ok, _, err) = locobench(&["rollout", "--env", "minitaur", "--env-config", f, "--out", csv.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(std::fs::read_to_string(&csv).unwrap().lines().count() <= 31);
    let (ok, _, err) = locobench(&["baseline", "--env", "ant", "--episodes", "1", "--reward", "energy=1"]);
    assert!(!ok && err.contains("energy"), "{err}");
}

#[test]
fn every_command_help_shows_defaults_and_ends_with_an_example() {
    for cmd in ["envs", "rollout", "train", "eval", "export", "baseline", "record", "report", "sweep", "docs"] {
        let (ok, out, err) = locobench(&[cmd, "--help"]);
        assert!(ok, "{cmd}: {err}");
        let last = out.trim_end().lines().last().unwrap_or("");
        assert!(last.trim_start().starts_with(&format!("locobench {cmd}")), "{cmd} --help ends with: {last}");
    }
    // The commands that evaluate share their defaults, and say so.
    for cmd in ["eval", "report", "baseline"] {
        let (_, out, _) = locobench(&[cmd, "--help"]);
        assert!(out.contains("[default: 50]") && out.contains("[default: 0]"), "{cmd}:\n{out}");
    }
}

/// A policy reference means the same thing in `eval`, `record`, `export` and `train --init-from`:
/// a run directory (newest checkpoint, or with `--budget` the actor saved there), a result run
/// kept without checkpoints (newest budget policy by default), a checkpoint, a budget policy file
/// and an exported policy; a budget it does not hold is an error listing those it does.
#[test]
fn every_kind_of_policy_reference_loads_the_same_policy_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let r = run.to_str().unwrap();
    let set = "warmup_steps=100,learning_starts=100,eval_every=300,eval_episodes=2,batch_size=32,hidden=[16,16]";
    let train = ["train", "--env", "inverted-pendulum", "--algo", "td3", "--steps", "600", "--set", set, "--out", r];
    let (ok, _, err) = locobench(&[&train[..], &["--quiet"]].concat());
    assert!(ok, "{err}");
    // Extended to 1200 steps: budget policies at 600 (its first budget) and 1200.
    let (ok, _, err) = locobench(&["train", "--resume", r, "--steps", "1200", "--quiet"]);
    assert!(ok, "{err}");
    let eval = |args: &[&str]| {
        let (ok, out, err) = locobench(&[&["eval", "--episodes", "3", "--seed", "7"], args].concat());
        assert!(ok, "{args:?}: {err}");
        out.split_once(": ").unwrap().1.to_string()
    };
    let newest = eval(&["--policy", r]);
    let at_600 = eval(&["--policy", r, "--budget", "600"]);
    assert_ne!(newest, at_600, "the actors at 600 and 1200 steps act alike");
    assert_eq!(
        eval(&["--policy", r, "--budget", "1200"]),
        newest,
        "the budget actor at the last step is the checkpoint's"
    );
    let checkpoint =
        run.join("checkpoints").join(std::fs::read_to_string(run.join("checkpoints/latest")).unwrap().trim());
    assert_eq!(eval(&["--policy", checkpoint.to_str().unwrap()]), newest);
    assert_eq!(eval(&["--policy", checkpoint.join("model.safetensors").to_str().unwrap()]), newest);
    let file_600 = run.join("policies/step-600.safetensors");
    assert_eq!(eval(&["--policy", file_600.to_str().unwrap()]), at_600);

    // A result run as committed under benches/results: config, metrics and policies only.
    let result = dir.path().join("result");
    std::fs::create_dir_all(result.join("policies")).unwrap();
    for f in ["config.toml", "metrics.csv", "policies/step-600.safetensors", "policies/step-1200.safetensors"] {
        std::fs::copy(run.join(f), result.join(f)).unwrap();
    }
    let res = result.to_str().unwrap();
    assert_eq!(eval(&["--policy", res]), newest, "a result run's default is its newest budget policy");
    assert_eq!(eval(&["--policy", res, "--budget", "600"]), at_600);
    let (ok, _, err) = locobench(&["train", "--resume", res, "--quiet"]);
    assert!(!ok && err.contains("no checkpoint to resume from"), "{err}");
    assert!(!result.join("run.lock").exists() && result.join("policies/step-600.safetensors").exists());

    // Exported from the result run at a budget: a shippable policy that acts the same.
    let exported = dir.path().join("exported");
    let ex = exported.to_str().unwrap();
    let (ok, _, err) = locobench(&["export", "--policy", res, "--budget", "600", "--out", ex]);
    assert!(ok, "{err}");
    assert_eq!(eval(&["--policy", ex]), at_600);
    assert!(std::fs::read_to_string(exported.join("source.toml")).unwrap().contains("step = 600"));
    assert_eq!(eval(&["--policy", exported.join("policy.safetensors").to_str().unwrap()]), at_600);

    // record and train --init-from read the same references.
    let rrd = dir.path().join("r.rrd");
    let (ok, _, err) = locobench(&["record", "--policy", res, "--budget", "600", "--out", rrd.to_str().unwrap()]);
    assert!(ok && rrd.exists(), "{err}");
    let tuned = dir.path().join("tuned");
    let t = tuned.to_str().unwrap();
    let init = ["--init-from", res, "--init-budget", "600", "--steps", "300", "--set", "hidden=[16,16],eval_every=300"];
    let (ok, _, err) = locobench(
        &[&["train", "--env", "inverted-pendulum", "--algo", "td3", "--out", t, "--quiet"][..], &init].concat(),
    );
    assert!(ok, "{err}");
    let config = std::fs::read_to_string(tuned.join("config.toml")).unwrap();
    assert!(config.contains("step-600.safetensors"), "{config}");

    // Errors name the path and what it holds.
    for (args, expect) in [
        (vec!["--policy", r, "--budget", "5"], "has no policy at step 5 (it holds policies at 600, 1200)"),
        (vec!["--policy", checkpoint.to_str().unwrap(), "--budget", "600"], "applies to a run directory"),
        (vec!["--policy", ex, "--budget", "1200"], "exported policy at step 600"),
        (vec!["--policy", file_600.to_str().unwrap(), "--budget", "1200"], "not at --budget 1200"),
        (vec!["--policy", "no/such/run"], "the path does not exist"),
    ] {
        let (ok, _, err) = locobench(&[&["eval", "--episodes", "1"], &args[..]].concat());
        assert!(!ok && err.contains(expect), "{args:?}: {err}");
    }
}

#[test]
fn device_commands_compare_the_paths_and_refuse_what_they_cannot_do() {
    let (ok, out, err) = locobench(&["device", "check"]);
    assert!(ok, "{err}");
    let rows: Vec<&str> = out.lines().skip(1).collect();
    assert_eq!(rows.len(), 6, "{out}");
    for (row, algo) in rows.iter().zip(["td3", "ddpg", "sac", "crossq", "dqn", "ppo"]) {
        assert!(row.starts_with(&format!("{algo},cpu,100,")) && row.ends_with(",true"), "{row}");
    }
    let (ok, out, err) = locobench(&[
        "device",
        "speed",
        "--algo",
        "sac",
        "--hidden",
        "16,16",
        "--batch",
        "8",
        "--seconds",
        "0.2",
        "--header",
    ]);
    assert!(ok, "{err}");
    let row = out.lines().nth(1).unwrap();
    assert!(row.starts_with("sac,cpu,generic,16-16,,8,"), "{row}");

    let (ok, _, err) = locobench(&["device", "speed", "--algo", "sac", "--path", "fused", "--device", "cuda"]);
    assert!(!ok && err.contains("fused path runs on the CPU only"), "{err}");
    let (ok, out, err) =
        locobench(&["device", "speed", "--algo", "ppo", "--hidden", "8,8", "--batch", "512", "--seconds", "0.1"]);
    assert!(ok, "{err}");
    assert!(out.starts_with("ppo,cpu,generic,8-8,,512,") && out.trim_end().ends_with(",epochs"), "{out}");
    if !cfg!(feature = "cuda") {
        let dir = tempfile::tempdir().unwrap();
        let out_dir = dir.path().join("run");
        let (ok, _, err) = locobench(&[
            "train",
            "--env",
            "inverted-pendulum",
            "--algo",
            "td3",
            "--device",
            "cuda:1",
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        assert!(!ok && err.contains("--device cuda:1") && err.contains("without the `cuda` feature"), "{err}");
        assert!(!out_dir.exists(), "a refused run left {}", out_dir.display());
        let (ok, _, err) = locobench(&["train", "--env", "inverted-pendulum", "--algo", "td3", "--device", "tpu"]);
        assert!(!ok && err.contains("unknown device 'tpu'"), "{err}");
        // the on-policy trainer refuses it the same way, before making the run directory
        let (ok, _, err) = locobench(&[
            "train",
            "--env",
            "inverted-pendulum",
            "--algo",
            "ppo",
            "--device",
            "cuda",
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        assert!(!ok && err.contains("without the `cuda` feature"), "{err}");
        assert!(!out_dir.exists(), "a refused run left {}", out_dir.display());
        let (ok, _, err) =
            locobench(&["eval", "--policy", "models/policies/minitaur-td3", "--episodes", "1", "--device", "cuda:0"]);
        assert!(!ok && err.contains("--device cuda:0") && err.contains("without the `cuda` feature"), "{err}");
    }
}
