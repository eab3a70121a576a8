//! `locobench sweep`: status of a local sweep, the Slurm array script, and what `--slurm` does
//! without a cluster. The real-cluster test is `tests/slurm/cluster.sh`.
mod common;

use common::{locobench, locobench_with_path};

const TINY: &str = "hidden=[16,16],batch_size=32,warmup_steps=100,learning_starts=100,eval_every=100,eval_episodes=1";

fn sweep_args(out: &str) -> Vec<String> {
    [
        "sweep",
        "--env",
        "inverted-pendulum",
        "--algo",
        "td3,sac",
        "--seeds",
        "2",
        "--steps",
        "200",
        "--set",
        TINY,
        "--out",
        out,
    ]
    .map(String::from)
    .to_vec()
}

#[test]
fn status_of_a_local_sweep_before_during_and_after() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = dir.path().join("sw");
    let s = sweep.to_str().unwrap();
    let mut dry = sweep_args(s);
    dry.push("--dry-run".into());
    let (ok, _, err) = locobench(&dry.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    let (ok, out, err) = locobench(&["sweep", "status", s]);
    assert!(ok, "{err}");
    assert!(out.contains("4 jobs: 0 finished, 0 running, 4 pending"), "{out}");

    let args = sweep_args(s);
    let (ok, out, err) = locobench(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{out}\n{err}");
    let (ok, out, _) = locobench(&["sweep", "status", s]);
    assert!(ok);
    assert!(out.contains("4 jobs: 4 finished"), "{out}");
    assert!(out.contains("200/200"), "{out}");

    // A job whose process failed: its exit status and log tail are shown.
    std::fs::write(sweep.join("logs/td3-seed1.exit"), "1\n").unwrap();
    std::fs::write(sweep.join("logs/td3-seed1.log"), "line one\nerror: something broke\n").unwrap();
    std::fs::remove_dir_all(sweep.join("runs/td3-seed1")).unwrap();
    let (_, out, _) = locobench(&["sweep", "status", s]);
    assert!(out.contains("failed") && out.contains("| error: something broke"), "{out}");

    // Another sweep into the same directory is refused (job numbers would change meaning).
    let mut other = sweep_args(s);
    other[8] = "300".into();
    let (ok, _, err) = locobench(&other.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(!ok && err.contains("holds another sweep"), "{err}");

    let (ok, _, err) = locobench(&["sweep", "status", dir.path().to_str().unwrap()]);
    assert!(!ok && err.contains("not a sweep directory"), "{err}");
}

#[test]
fn slurm_dry_run_writes_the_array_script_and_missing_sbatch_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = dir.path().join("sw");
    let s = sweep.to_str().unwrap();
    let mut args = sweep_args(s);
    args.extend(
        [
            "--slurm",
            "--partition",
            "cpu",
            "--time",
            "2:00:00",
            "--cpus-per-task",
            "2",
            "--mem",
            "3G",
            "--max-parallel",
            "2",
            "--sbatch-arg=--account=lab",
        ]
        .map(String::from),
    );
    let mut dry = args.clone();
    dry.push("--dry-run".into());
    let (ok, out, err) = locobench(&dry.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{err}");
    assert!(out.contains("would submit 4 of 4 jobs"), "{out}");
    let script = std::fs::read_to_string(sweep.join("slurm.sh")).unwrap();
    for needle in [
        "#SBATCH --array=0-3%2",
        "#SBATCH --partition=cpu",
        "#SBATCH --time=2:00:00",
        "#SBATCH --cpus-per-task=2",
        "#SBATCH --mem=3G",
        "#SBATCH --signal=B:USR1@120",
        "#SBATCH --account=lab",
        "names=(td3-seed0 td3-seed1 sac-seed0 sac-seed1)",
    ] {
        assert!(script.contains(needle), "{needle} missing:\n{script}");
    }
    let jobs = std::fs::read_to_string(sweep.join("jobs.txt")).unwrap();
    assert!(jobs.lines().all(|l| l.contains("--resume-if-exists")), "{jobs}");

    // Without sbatch: a clear error, nothing recorded, the directory ready for the same command.
    let (ok, _, err) = locobench_with_path(&args.iter().map(String::as_str).collect::<Vec<_>>(), Some("/nonexistent"));
    assert!(!ok && err.contains("needs Slurm's `sbatch` on the PATH"), "{err}");
    assert!(sweep.join("slurm.sh").exists() && !sweep.join("slurm.toml").exists());

    // Slurm options without --slurm are refused.
    let (ok, _, err) = locobench(&["sweep", "--env", "ant", "--algo", "td3", "--out", s, "--partition", "x"]);
    assert!(!ok && err.contains("--slurm"), "{err}");
}

#[test]
fn train_resume_if_exists_continues_only_the_same_run() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let r = run.to_str().unwrap();
    let base = ["train", "--env", "inverted-pendulum", "--algo", "td3", "--seed", "1", "--set", TINY, "--out", r];
    let with = |extra: &[&str]| {
        let mut a = base.to_vec();
        a.extend_from_slice(extra);
        locobench(&a)
    };
    let (ok, _, err) = with(&["--steps", "200", "--resume-if-exists", "--quiet"]);
    assert!(ok, "{err}");
    let metrics = std::fs::read(run.join("metrics.csv")).unwrap();
    // Again: the finished run is left alone.
    let (ok, out, err) = with(&["--steps", "200", "--resume-if-exists", "--quiet"]);
    assert!(ok, "{err}");
    assert!(out.contains("already finished at step 200"), "{out}");
    assert_eq!(std::fs::read(run.join("metrics.csv")).unwrap(), metrics);
    // A different run in that directory is refused, naming what differs.
    let (ok, _, err) = with(&["--steps", "300", "--resume-if-exists", "--quiet"]);
    assert!(!ok && err.contains("hyperparameters"), "{err}");
    let (ok, _, err) = with(&["--steps", "200", "--resume-if-exists", "--force"]);
    assert!(!ok && err.contains("cannot be used with"), "{err}");
}
