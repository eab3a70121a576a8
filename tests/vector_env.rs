//! The vector environment: shapes, automatic reset, per-copy seeds, the same bits on any thread
//! count, agreement with stepping the copies one by one, exact snapshots, and errors for bad input.
use locobench::envs::{episode_seed, make, EnvConfig, EnvError, VecEnv};

/// A deterministic action sequence that differs between copies.
fn action(t: usize, copy: usize, dim: usize) -> Vec<f64> {
    (0..dim).map(|j| ((t * 13 + copy * 7 + j * 3) as f64 * 0.41).sin()).collect()
}

/// Every observation, reward and flag of `steps` vector steps, as bits.
fn trace(name: &str, copies: usize, threads: usize, steps: usize, seed: u64) -> Vec<u64> {
    let mut env = VecEnv::new(&EnvConfig::new(name), copies, threads).unwrap();
    let dim = env.spec().action_space.dim();
    let mut bits: Vec<u64> = env.reset(seed).unwrap().iter().flatten().map(|x| x.to_bits()).collect();
    for t in 0..steps {
        let actions: Vec<Vec<f64>> = (0..copies).map(|c| action(t, c, dim)).collect();
        let s = env.step(&actions).unwrap();
        bits.extend(s.observations.iter().flatten().map(|x| x.to_bits()));
        bits.extend(s.rewards.iter().map(|x| x.to_bits()));
        bits.extend(s.terminated.iter().zip(&s.truncated).map(|(&a, &b)| a as u64 * 2 + b as u64));
    }
    bits
}

#[test]
fn shapes_follow_the_copies() {
    let mut env = VecEnv::new(&EnvConfig::new("hopper"), 3, 2).unwrap();
    assert_eq!(env.len(), 3);
    let obs = env.reset(0).unwrap();
    assert_eq!(obs.len(), 3);
    assert!(obs.iter().all(|o| o.len() == 11));
    let s = env.step(&vec![vec![0.0; 3]; 3]).unwrap();
    assert_eq!((s.observations.len(), s.rewards.len(), s.infos.len()), (3, 3, 3));
    assert_eq!((s.terminated.len(), s.truncated.len(), s.final_observations.len()), (3, 3, 3));
    // Each reward is the sum of its named terms, as in a single env.
    for (r, info) in s.rewards.iter().zip(&s.infos) {
        let sum: f64 = info.reward_terms.iter().map(|(_, v)| v).sum();
        assert!((r - sum).abs() < 1e-12);
    }
}

#[test]
fn same_bits_on_any_thread_count() {
    // Hopper falls within these steps, so automatic resets are part of the trace.
    let one = trace("hopper", 5, 1, 120, 7);
    for threads in [2, 3, 5, 8] {
        assert!(one == trace("hopper", 5, threads, 120, 7), "{threads} threads differ from one");
    }
    // With the training runtime's helper thread, two threads split the copies between the
    // caller and the helper.
    let helper = std::thread::spawn(|| {
        let _runtime = locobench::runtime::Runtime::enter(2);
        trace("hopper", 5, 2, 120, 7)
    });
    assert!(one == helper.join().unwrap(), "the helper thread's split differs from one thread");
    assert!(one != trace("hopper", 5, 1, 120, 8), "another seed gives another trace");
}

#[test]
fn each_copy_is_the_single_env_it_stands_for() {
    // Copy i of a vector env is a plain env reset with episode_seed(seed, i, k) for its k-th
    // episode.
    let (copies, steps, seed) = (3, 150, 11);
    let config = EnvConfig::new("hopper");
    let mut vector = VecEnv::new(&config, copies, 2).unwrap();
    let first = vector.reset(seed).unwrap();
    let mut singles: Vec<_> = (0..copies).map(|_| make(&config).unwrap()).collect();
    for (i, env) in singles.iter_mut().enumerate() {
        assert_eq!(env.reset(Some(episode_seed(seed, i, 0))).unwrap().0, first[i]);
    }
    let mut episodes = vec![1u64; copies];
    for t in 0..steps {
        let actions: Vec<Vec<f64>> = (0..copies).map(|c| action(t, c, 3)).collect();
        let v = vector.step(&actions).unwrap();
        for (i, env) in singles.iter_mut().enumerate() {
            let s = env.step(&actions[i]).unwrap();
            assert_eq!(v.rewards[i], s.reward);
            assert_eq!((v.terminated[i], v.truncated[i]), (s.terminated, s.truncated));
            if s.done() {
                assert_eq!(v.final_observations[i].as_ref(), Some(&s.observation));
                assert_eq!(v.observations[i], env.reset(Some(episode_seed(seed, i, episodes[i]))).unwrap().0);
                episodes[i] += 1;
            } else {
                assert_eq!(v.final_observations[i], None);
                assert_eq!(v.observations[i], s.observation);
            }
        }
    }
    assert!(episodes.iter().any(|&k| k > 1), "the test must cover automatic resets");
}

#[test]
fn copies_get_distinct_seeds() {
    let seeds: std::collections::BTreeSet<u64> = (0..4)
        .flat_map(|seed| (0..16).flat_map(move |copy| (0..16).map(move |k| episode_seed(seed, copy, k))))
        .collect();
    assert_eq!(seeds.len(), 4 * 16 * 16);
    let mut env = VecEnv::new(&EnvConfig::new("ant"), 2, 1).unwrap();
    let obs = env.reset(0).unwrap();
    assert_ne!(obs[0], obs[1], "reset noise differs between copies");
}

#[test]
fn bad_input_is_refused_with_a_clear_error() {
    let config = EnvConfig::new("inverted-pendulum");
    let zero = VecEnv::new(&config, 0, 1).err().expect("zero copies is an error");
    assert!(zero.to_string().contains("at least one copy"), "{zero}");
    assert!(matches!(VecEnv::new(&EnvConfig::new("no-such-env"), 2, 1), Err(EnvError::UnknownEnv { .. })));

    let mut env = VecEnv::new(&config, 2, 2).unwrap();
    let before = env.step(&[vec![0.0], vec![0.0]]).expect_err("step before reset");
    assert!(before.to_string().contains("before reset"), "{before}");
    env.reset(0).unwrap();
    let count = env.step(&[vec![0.0]]).expect_err("one action for two copies");
    assert!(matches!(count, EnvError::ActionCount { expected: 2, got: 1 }), "{count}");
    let nan = env.step(&[vec![0.0], vec![f64::NAN]]).expect_err("NaN action");
    assert!(nan.to_string().starts_with("environment copy 1: "), "{nan}");
    let long = env.step(&[vec![0.0, 1.0], vec![0.0]]).expect_err("wrong length");
    assert!(matches!(long, EnvError::InCopy { copy: 0, .. }), "{long}");
}

#[test]
fn a_snapshot_mid_episode_restores_every_copy_exactly() {
    for name in ["hopper", "minitaur"] {
        let config = EnvConfig::new(name);
        let mut env = VecEnv::new(&config, 3, 2).unwrap();
        let dim = env.spec().action_space.dim();
        let batch = |t: usize| -> Vec<Vec<f64>> { (0..3).map(|c| action(t, c, dim)).collect() };
        env.reset(5).unwrap();
        for t in 0..90 {
            env.step(&batch(t)).unwrap();
        }
        let snapshot = env.snapshot();
        assert!(snapshot.actions.iter().any(|a| !a.is_empty()), "{name}: taken mid-episode");
        let go_on = |env: &mut VecEnv| -> Vec<u64> {
            (90..150)
                .flat_map(|t| {
                    let s = env.step(&batch(t)).unwrap();
                    s.observations.concat().into_iter().chain(s.rewards).map(f64::to_bits).collect::<Vec<_>>()
                })
                .collect()
        };
        let expected = go_on(&mut env);
        // A fresh vector env, on another thread count, restored from the snapshot.
        let mut restored = VecEnv::new(&config, 3, 1).unwrap();
        restored.restore(&snapshot).unwrap();
        assert_eq!(restored.snapshot(), snapshot, "{name}");
        assert!(go_on(&mut restored) == expected, "{name}: the restored copies continue bit for bit");
    }
}

#[test]
fn a_snapshot_that_does_not_fit_is_refused() {
    let mut env = VecEnv::new(&EnvConfig::new("hopper"), 2, 1).unwrap();
    env.reset(0).unwrap();
    env.step(&[vec![0.1; 3], vec![0.2; 3]]).unwrap();
    let snapshot = env.snapshot();
    let mut three = VecEnv::new(&EnvConfig::new("hopper"), 3, 1).unwrap();
    assert!(matches!(three.restore(&snapshot), Err(EnvError::ActionCount { expected: 3, got: 2 })));
    let mut ant = VecEnv::new(&EnvConfig::new("ant"), 2, 1).unwrap();
    let err = ant.restore(&snapshot).expect_err("hopper's 3-dim actions do not fit ant");
    assert!(err.to_string().contains("partial action"), "{err}");
}
