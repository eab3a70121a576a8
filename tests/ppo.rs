//! PPO: it learns InvertedPendulum, a run is the same on any thread count, an interrupted run
//! resumes bit for bit mid-episode, and bad settings are refused clearly.
use std::path::Path;

use locobench::agents::Algo;
use locobench::envs::EnvConfig;
use locobench::train::config::{build_config, split_pairs};
use locobench::train::{self, Outcome, RunControl};

fn config(env: &str, overrides: &str) -> locobench::agents::TrainConfig {
    build_config(env, Algo::Ppo, &split_pairs(overrides).unwrap()).unwrap()
}

/// (first evaluation, best evaluation, steps) of one seed with the shipped InvertedPendulum
/// preset, stopping once an evaluation reaches 950.
fn run_seed(seed: u64) -> (f64, f64, u64) {
    let dir = tempfile::tempdir().unwrap();
    let cfg = build_config("inverted-pendulum", Algo::Ppo, &[]).unwrap();
    let control = RunControl { target_return: Some(950.0), ..Default::default() };
    let run = dir.path().join("run");
    let s = train::train(EnvConfig::new("inverted-pendulum"), cfg, seed, &run, None, false, &control).unwrap();
    let rows = train::metrics::read(&run.join("metrics.csv")).unwrap();
    let first = rows.iter().find_map(|r| (r.kind == "eval").then_some(r.eval_mean).flatten()).unwrap();
    (first, s.best_eval_mean.unwrap(), s.steps)
}

/// Two seeds, one per core: both learn, and one solves the task (>= 950 of 1000).
#[test]
fn ppo_learns_inverted_pendulum() {
    let seeds = [0, 1].map(|seed| std::thread::spawn(move || run_seed(seed)));
    let results: Vec<(f64, f64, u64)> = seeds.into_iter().map(|h| h.join().unwrap()).collect();
    for (seed, (first, best, steps)) in results.iter().enumerate() {
        eprintln!("PPO seed {seed}: first evaluation {first:.0}, best {best:.0}, {steps} steps");
        assert!(*best >= 2.0 * first && *best >= first + 100.0, "PPO seed {seed} did not learn: {first} -> {best}");
    }
    assert!(results.iter().any(|r| r.1 >= 950.0), "no seed reached 950: {results:?}");
}

fn file(run: &Path, name: &str) -> Vec<u8> {
    std::fs::read(run.join(name)).unwrap_or_else(|e| panic!("{}: {e}", run.join(name).display()))
}

/// The metrics without the wall-clock columns.
fn metrics(run: &Path) -> Vec<String> {
    std::fs::read_to_string(run.join("metrics.csv"))
        .unwrap()
        .lines()
        .map(|l| l.split(',').take(9).collect::<Vec<_>>().join(","))
        .collect()
}

/// Hopper falls often, so the checkpoint is taken with episodes in progress in every copy, and
/// the resumed run must rebuild them from the snapshot.
const SMALL: &str = "total_steps=2400,num_envs=3,num_steps=100,num_minibatches=4,update_epochs=2,\
                     eval_every=600,eval_episodes=2,checkpoint_every=600,hidden=[16,16]";

#[test]
fn the_same_run_on_any_thread_count_and_after_a_resume() {
    let dir = tempfile::tempdir().unwrap();
    let env = EnvConfig::new("hopper");
    let whole = dir.path().join("whole");
    let one = RunControl { threads: 1, ..Default::default() };
    let a = train::train(env.clone(), config("hopper", SMALL), 3, &whole, None, false, &one).unwrap();
    assert_eq!(a.outcome, Outcome::Finished);
    assert_eq!(a.steps, 2400);

    let split = dir.path().join("split");
    let stop = RunControl { threads: 2, stop_after: Some(1000), ..Default::default() };
    let b = train::train(env, config("hopper", SMALL), 3, &split, None, false, &stop).unwrap();
    assert_eq!((b.outcome, b.steps), (Outcome::Stopped, 1200));
    let snapshot = candle_core::safetensors::load(b.checkpoint.join("rollout.safetensors"), &candle_core::Device::Cpu)
        .unwrap()["action_lengths"]
        .to_vec1::<i64>()
        .unwrap();
    assert!(snapshot.iter().all(|&l| l > 0), "the test needs episodes in progress at the checkpoint: {snapshot:?}");
    let c = train::resume(&split, &RunControl { threads: 2, ..Default::default() }).unwrap();
    assert_eq!((c.outcome, c.steps), (Outcome::Finished, 2400));

    assert!(file(&a.checkpoint, "model.safetensors") == file(&c.checkpoint, "model.safetensors"));
    assert!(file(&a.checkpoint, "optim.safetensors") == file(&c.checkpoint, "optim.safetensors"));
    assert!(file(&a.checkpoint, "rollout.safetensors") == file(&c.checkpoint, "rollout.safetensors"));
    assert_eq!(metrics(&whole), metrics(&split));
    assert!(metrics(&whole).iter().filter(|l| l.starts_with("episode")).count() > 20);
    assert_eq!(train::budget_policy_steps(&whole), vec![2400]);

    // The exported policy acts with the observation statistics it was trained with.
    let (_, policy) = train::load_budget_policy(&whole, 2400).unwrap();
    let (_, from_checkpoint) = train::load_policy(&a.checkpoint).unwrap();
    let obs = vec![1.25, 0.0, 0.1, -0.1, 0.2, 0.5, -0.3, 0.0, 0.4, 0.1, -0.2];
    assert_eq!(policy.act(&obs).unwrap(), from_checkpoint.act(&obs).unwrap());
    let action = policy.act(&obs).unwrap();
    assert_eq!(action.len(), 3);
    assert!(action.iter().all(|a| (-1.0..=1.0).contains(a)));
}

/// A budget that is not a multiple of the rollout: the run ends on the rollout past it, and keeps
/// both the actor that collected the budget's step (the report's row for the budget) and the
/// final one.
#[test]
fn a_budget_inside_a_rollout_keeps_the_actor_that_reached_it() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let settings = SMALL.replace("total_steps=2400", "total_steps=2350");
    let s = train::train(
        EnvConfig::new("hopper"),
        config("hopper", &settings),
        3,
        &run,
        None,
        false,
        &RunControl::default(),
    )
    .unwrap();
    assert_eq!((s.outcome, s.steps), (Outcome::Finished, 2400));
    assert_eq!(train::budget_policy_steps(&run), vec![2350, 2400]);
    let obs = vec![1.25, 0.0, 0.1, -0.1, 0.2, 0.5, -0.3, 0.0, 0.4, 0.1, -0.2];
    let act = |step| train::load_budget_policy(&run, step).unwrap().1.act(&obs).unwrap();
    // the last rollout's update comes after the budget's actor
    assert_ne!(act(2350), act(2400));
}

#[test]
fn bad_settings_are_refused_with_a_clear_error() {
    let err = build_config("hopper", Algo::Ppo, &split_pairs("num_envs=2,num_steps=8,num_minibatches=32").unwrap())
        .unwrap_err()
        .to_string();
    assert!(err.contains("num_minibatches (32)") && err.contains("= 16"), "{err}");
    let err = build_config("hopper", Algo::Ppo, &split_pairs("gae_lambda=1.5").unwrap()).unwrap_err().to_string();
    assert!(err.contains("gae_lambda"), "{err}");
    let err = build_config("hopper", Algo::Ppo, &split_pairs("num_envs=0").unwrap()).unwrap_err().to_string();
    assert!(err.contains("num_envs"), "{err}");
    let err = build_config("hopper", Algo::Td3, &split_pairs("clip_coef=0.1").unwrap()).unwrap_err().to_string();
    assert!(err.contains("clip_coef") && err.contains("ppo"), "{err}");
}
