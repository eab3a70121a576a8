//! Same seed, same bits on every CPU: training on each exact kernel path (AVX-512, AVX2, portable;
//! whichever this CPU has) gives byte-identical checkpoints and metrics for every algorithm, a run
//! stopped on one path resumes on another exactly, and the `LOCOBENCH_KERNELS` switch reaches the
//! command line and is recorded in the run directory.
//!
//! Running the same binary under `qemu-x86_64 -cpu Haswell` (an AVX2 CPU without AVX-512) is the
//! cross-machine check of the same claim; `benches/cross_cpu.sh` does it.
mod common;

use std::path::Path;

use common::locobench;
use locobench::agents::{Algo, TrainConfig};
use locobench::envs::EnvConfig;
use locobench::numeric::kernel_path::{force_on_this_thread, KernelPath};
use locobench::train::config::{build_config, split_pairs};
use locobench::train::{self, Outcome, RunControl};

fn exact_paths() -> Vec<KernelPath> {
    KernelPath::ALL.into_iter().filter(|p| p.is_exact() && p.is_supported()).collect()
}

/// 2,500 steps: 2,200 updates. Hidden sizes that leave partial vectors on both widths (40 = 2.5
/// AVX-512 vectors, 5 AVX2 vectors; 24 = 1.5 and 3), and a batch that splits over two threads.
fn config(algo: Algo) -> TrainConfig {
    let set = if algo.is_on_policy() {
        // 2,560 steps: 5 rollouts of 2 x 256, 4 epochs of 8 minibatches each.
        "total_steps=2500,eval_every=1000,checkpoint_every=600,eval_episodes=2,hidden=[40,24],num_envs=2,num_steps=256,\
         num_minibatches=8,update_epochs=4"
    } else if algo == Algo::Dqn {
        "total_steps=2500,learning_starts=300,eval_every=1000,checkpoint_every=600,eval_episodes=2,hidden=[40,24],\
         batch_size=64,exploration_steps=1000"
    } else if algo == Algo::Crossq {
        "total_steps=2500,warmup_steps=300,learning_starts=300,eval_every=1000,checkpoint_every=600,eval_episodes=2,\
         hidden=[40,24],critic_hidden=[40,24],batch_size=64"
    } else {
        "total_steps=2500,warmup_steps=300,learning_starts=300,eval_every=1000,checkpoint_every=600,eval_episodes=2,\
         hidden=[40,24],batch_size=64"
    };
    build_config("inverted-pendulum", algo, &split_pairs(set).unwrap()).unwrap()
}

/// Everything a run computes, without wall times: the checkpoint's weights, optimiser state and
/// replay buffer (PPO: rollout state) as bytes, and metrics.csv without its timing columns.
fn fingerprint(run: &Path, checkpoint: &Path) -> Vec<Vec<u8>> {
    let trainer_file =
        if checkpoint.join("rollout.safetensors").exists() { "rollout.safetensors" } else { "buffer.safetensors" };
    let mut out: Vec<Vec<u8>> = ["model.safetensors", "optim.safetensors", trainer_file]
        .iter()
        .map(|f| std::fs::read(checkpoint.join(f)).unwrap())
        .collect();
    let metrics = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    let header: Vec<&str> = metrics.lines().next().unwrap().split(',').collect();
    let timing: Vec<usize> =
        ["steps_per_s", "wall_time"].iter().map(|c| header.iter().position(|h| h == c).unwrap()).collect();
    let rows = metrics.lines().map(|l| {
        l.split(',').enumerate().filter(|(i, _)| !timing.contains(i)).map(|(_, v)| v).collect::<Vec<_>>().join(",")
    });
    out.push(rows.collect::<Vec<_>>().join("\n").into_bytes());
    out
}

fn train_on(path: KernelPath, algo: Algo, run: &Path, control: &RunControl) -> train::RunSummary {
    let _forced = force_on_this_thread(path).unwrap();
    train::train(EnvConfig::new("inverted-pendulum"), config(algo), 7, run, None, false, control).unwrap()
}

#[test]
fn every_exact_kernel_path_trains_the_same_run_bit_for_bit() {
    let paths = exact_paths();
    eprintln!("exact paths on this CPU: {paths:?}");
    let dir = tempfile::tempdir().unwrap();
    for algo in [Algo::Td3, Algo::Sac, Algo::Ddpg, Algo::Ppo, Algo::Crossq, Algo::Dqn] {
        let runs: Vec<(KernelPath, Vec<Vec<u8>>)> = paths
            .iter()
            .map(|&path| {
                let run = dir.path().join(format!("{}-{path}", algo.name()));
                let s = train_on(path, algo, &run, &RunControl::default());
                assert_eq!(s.outcome, Outcome::Finished);
                let stretches = train::provenance::read(&run).unwrap();
                assert_eq!(stretches.len(), 1);
                assert_eq!(stretches[0].kernel_path, path.name());
                (path, fingerprint(&run, &s.checkpoint))
            })
            .collect();
        for (path, fp) in &runs[1..] {
            assert!(fp == &runs[0].1, "{algo:?}: {path} trains a different run than {}", runs[0].0);
        }
        // The library's kernels are not exact, but they compute the same function.
        let library = train_on(
            KernelPath::Library,
            algo,
            &dir.path().join(format!("{}-lib", algo.name())),
            &RunControl::default(),
        );
        assert_eq!(library.outcome, Outcome::Finished);
    }
}

/// A run stopped on one path and resumed on another (a requeued cluster job landing on another
/// kind of node) ends exactly like the uninterrupted run, with one provenance row per stretch.
#[test]
fn a_run_resumed_on_another_kernel_path_continues_exactly() {
    let paths = exact_paths();
    let (first, second) = (paths[0], *paths.last().unwrap());
    let dir = tempfile::tempdir().unwrap();
    for algo in [Algo::Td3, Algo::Sac, Algo::Ppo, Algo::Crossq, Algo::Dqn] {
        let whole = dir.path().join(format!("{}-whole", algo.name()));
        let a = train_on(second, algo, &whole, &RunControl::default());

        let split = dir.path().join(format!("{}-split", algo.name()));
        let stop = RunControl { stop_after: Some(1200), threads: 2, ..Default::default() };
        let b = train_on(first, algo, &split, &stop);
        assert_eq!(b.outcome, Outcome::Stopped);
        let c = {
            let _forced = force_on_this_thread(second).unwrap();
            train::resume(&split, &RunControl::default()).unwrap()
        };
        assert_eq!(c.outcome, Outcome::Finished);
        assert!(
            fingerprint(&whole, &a.checkpoint) == fingerprint(&split, &c.checkpoint),
            "{algo:?}: resumed on {second} after {first} differs from an uninterrupted run"
        );
        let stretches = train::provenance::read(&split).unwrap();
        let kinds: Vec<(u64, &str, usize)> =
            stretches.iter().map(|s| (s.from_step, s.kernel_path.as_str(), s.threads)).collect();
        assert_eq!(kinds, [(0, first.name(), 2), (b.steps, second.name(), 1)]);
    }
}

#[test]
fn the_switch_reaches_the_command_line_and_bad_values_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let train = |path: &str, out: &Path| {
        let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_locobench"));
        let o = out.to_str().unwrap();
        cmd.env("LOCOBENCH_KERNELS", path).args([
            "train",
            "--env",
            "inverted-pendulum",
            "--algo",
            "td3",
            "--steps",
            "700",
            "--set",
            "warmup_steps=200,learning_starts=200,eval_every=700,eval_episodes=1,hidden=[24,24],batch_size=32",
            "--out",
            o,
            "--quiet",
        ]);
        cmd.output().unwrap()
    };
    let (a, b) = (dir.path().join("portable"), dir.path().join("auto"));
    for (value, run) in [("portable", &a), ("auto", &b)] {
        let out = train(value, run);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let weights =
        |run: &Path| std::fs::read(train::checkpoint::latest(run).unwrap().join("model.safetensors")).unwrap();
    assert_eq!(weights(&a), weights(&b), "portable and auto ({}) differ", KernelPath::best_exact());
    let recorded = |run: &Path| train::provenance::read(run).unwrap()[0].kernel_path.clone();
    assert_eq!((recorded(&a), recorded(&b)), ("portable".to_string(), KernelPath::best_exact().name().to_string()));

    // Extending the portable run on the gemm crate's kernels says it will not be exact.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_locobench"))
        .env("LOCOBENCH_KERNELS", "library")
        .args(["train", "--resume", a.to_str().unwrap(), "--steps", "900", "--quiet"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success()
            && text.contains("note: resuming will not match")
            && text.contains("portable kernels, this one on library"),
        "{text}"
    );
    let stretches = train::provenance::read(&a).unwrap();
    assert_eq!(stretches.iter().map(|s| s.kernel_path.as_str()).collect::<Vec<_>>(), ["portable", "library"]);

    let bad = train("avx1024", &dir.path().join("bad"));
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("LOCOBENCH_KERNELS") && err.contains("avx1024"), "{err}");
    assert!(!dir.path().join("bad").exists(), "nothing is written on a bad switch");
    let (ok, _, _) = locobench(&["envs"]);
    assert!(ok);
}
