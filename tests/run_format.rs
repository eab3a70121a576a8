//! Run directories written by earlier versions keep working: the fixture was written by the
//! main branch of 2026-11-23 (format 1, before `config.toml` had a version), and every run
//! committed under benches/results and models/policies still loads.
use std::path::{Path, PathBuf};

use locobench::agents::TrainConfig;
use locobench::train::{self, Outcome, RunControl};

const FIXTURE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/run-2026-11-23");

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap().flatten() {
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).unwrap();
        }
    }
}

#[test]
fn a_format_1_run_directory_evaluates_and_resumes() {
    let fixture = Path::new(FIXTURE);
    let text = std::fs::read_to_string(fixture.join("config.toml")).unwrap();
    assert!(!text.contains("format"), "the fixture must stay a format-1 file");
    let run = train::read_run_config(fixture).unwrap();
    assert_eq!((run.seed, run.train.total_steps, run.train.hidden.clone()), (3, 600, vec![8, 8]));

    let (_, agent) = train::load_policy(fixture).unwrap();
    assert_eq!(agent.act(&[0.0; 4]).unwrap().len(), 1);

    // Train it on from its checkpoint: the rewritten config is the current format and the run
    // finishes.
    let dir = tempfile::tempdir().unwrap();
    let copy = dir.path().join("run");
    copy_dir(fixture, &copy);
    assert!(train::extend(&copy, 900).is_ok());
    let s = train::resume(&copy, &RunControl::default()).unwrap();
    assert_eq!((s.outcome, s.steps), (Outcome::Finished, 900));
    let rewritten = std::fs::read_to_string(copy.join("config.toml")).unwrap();
    assert!(rewritten.starts_with("format = 3") && rewritten.contains("[train.td3]"), "{rewritten}");
    assert_eq!(train::read_run_config(&copy).unwrap().train, TrainConfig { total_steps: 900, ..run.train });
}

fn configs_under(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap().flatten() {
        let p = entry.path();
        if p.is_dir() {
            configs_under(&p, out);
        } else if p.file_name().is_some_and(|n| n == "config.toml") {
            out.push(p);
        }
    }
}

#[test]
fn every_committed_run_still_loads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut configs = Vec::new();
    configs_under(&root.join("benches/results"), &mut configs);
    configs_under(&root.join("models/policies"), &mut configs);
    assert!(configs.len() >= 10, "{configs:?}");
    for config in configs {
        let run = train::read_run_config(config.parent().unwrap());
        assert!(run.is_ok(), "{}: {:#}", config.display(), run.unwrap_err());
    }
}

#[test]
fn a_garbage_config_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("config.toml"), "this is not toml ]]").unwrap();
    let err = format!("{:#}", train::read_run_config(dir.path()).unwrap_err());
    assert!(err.contains(&dir.path().join("config.toml").display().to_string()), "{err}");
}

#[test]
fn results_kept_without_checkpoints_count_as_finished_when_their_metrics_reach_the_budget() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let kept = root.join("benches/results/half-cheetah/td3-seed0-300k");
    assert!(!kept.join("checkpoints").exists());
    assert!(train::run_progress(&kept).unwrap().finished());

    // The same files with a larger budget are not finished; with checkpoints, the checkpoint
    // decides.
    let dir = tempfile::tempdir().unwrap();
    let short = dir.path().join("short");
    std::fs::create_dir_all(&short).unwrap();
    std::fs::copy(kept.join("metrics.csv"), short.join("metrics.csv")).unwrap();
    let config = std::fs::read_to_string(kept.join("config.toml")).unwrap();
    std::fs::write(short.join("config.toml"), config.replace("total_steps = 300000", "total_steps = 400000")).unwrap();
    assert!(!train::run_progress(&short).unwrap().finished());
    assert!(train::run_progress(Path::new(FIXTURE)).unwrap().finished(), "its checkpoint is at the budget");
}
