//! One gradient update at HalfCheetah sizes (17-dim observation, 6-dim action, batch 256) for
//! each off-policy algorithm (CrossQ with 512-512 critics), one PPO minibatch update (64-64 tanh networks, minibatch 64: CleanRL's
//! 2048-step rollout in 32 minibatches), single-observation policy inference, and replay-buffer
//! sampling.
//!
//! Run: `cargo bench --bench agents`. Networks as in the throughput comparison: TD3 and DDPG
//! 400-300, SAC 256-256. candle runs on one thread (see .cargo/config.toml); updates are timed
//! on that thread alone and with its helper thread (`train --threads 2`). The process uses the
//! allocator and FPU settings `train` uses.
use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use locobench::agents::ppo::PpoBatch;
use locobench::agents::{make_learner, Agent, Algo, Batch, OnPolicyAgent, PpoAgent, ReplayBuffer, TrainConfig};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const OBS: usize = 17;
const ACT: usize = 6;
const BATCH: usize = 256;

fn filled_buffer(rng: &mut ChaCha8Rng) -> ReplayBuffer {
    let mut buf = ReplayBuffer::new(100_000, OBS, ACT);
    let mut obs: Vec<f32> = (0..OBS).map(|_| rng.random_range(-1.0..1.0)).collect();
    for t in 0..20_000 {
        let next: Vec<f32> = (0..OBS).map(|_| rng.random_range(-1.0..1.0)).collect();
        let act: Vec<f32> = (0..ACT).map(|_| rng.random_range(-1.0..1.0)).collect();
        let end = t % 1000 == 999;
        buf.add(&obs, &act, rng.random_range(-1.0..1.0), &next, false, end);
        obs = next;
    }
    buf
}

fn bench(c: &mut Criterion) {
    let _runtime = locobench::runtime::Runtime::enter(1);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let buf = filled_buffer(&mut rng);
    let mut group = c.benchmark_group("agents");
    group.measurement_time(Duration::from_secs(8)).warm_up_time(Duration::from_secs(2)).sample_size(20);
    // CrossQ's critics are a setting of their own: 256 and 512 wide are what two cores afford
    // (the paper's are 2048 wide); 256 is the width of SAC's, for the same-compute comparison.
    // The branching DQN runs at its own defaults (512-256 torso, batch 64), three levels for each
    // of the 6 action dimensions.
    let cases = [
        (Algo::Td3, vec![400, 300], None, BATCH),
        (Algo::Sac, vec![256, 256], None, BATCH),
        (Algo::Ddpg, vec![400, 300], None, BATCH),
        (Algo::Crossq, vec![256, 256], Some(256), BATCH),
        (Algo::Crossq, vec![256, 256], Some(512), BATCH),
        (Algo::Dqn, vec![512, 256], None, 64),
    ];
    for (algo, hidden, critic_width, batch_size) in cases {
        let mut cfg = TrainConfig::defaults(algo);
        cfg.hidden = hidden.clone();
        cfg.batch_size = batch_size;
        let mut label = format!("{}-{}", hidden[0], hidden[1]);
        if let (Some(c), Some(width)) = (cfg.crossq.as_mut(), critic_width) {
            c.critic_hidden = vec![width, width];
            label += &format!(", critics {width}-{width},");
        }
        let mut agent = make_learner(&cfg, OBS, ACT, &mut rng).unwrap();
        let mut batch = Batch::new(batch_size, OBS, ACT);
        group.throughput(Throughput::Elements(1));
        for threads in [1, 2] {
            let _runtime = locobench::runtime::Runtime::enter(threads);
            group.bench_function(
                format!("{}/update {label} batch {batch_size}, {threads} thread(s)", algo.name()),
                |b| {
                    b.iter(|| {
                        buf.sample_into(&mut batch, &mut rng);
                        black_box(agent.update(&batch, &mut rng).unwrap());
                    })
                },
            );
        }
        if critic_width == Some(512) {
            continue; // acting does not involve the critics: measured once
        }
        let obs: Vec<f32> = (0..OBS).map(|i| (i as f32 * 0.1).sin()).collect();
        group.bench_function(format!("{}/act one observation {}-{}", algo.name(), hidden[0], hidden[1]), |b| {
            b.iter(|| black_box(agent.act(black_box(&obs)).unwrap()))
        });
    }
    // PPO: one minibatch of a rollout collected by the policy itself.
    let cfg = TrainConfig::defaults(Algo::Ppo);
    let mut ppo = PpoAgent::new(&cfg, OBS, ACT, &mut rng).unwrap();
    let minibatch = cfg.ppo().rollout_size() / cfg.ppo().num_minibatches;
    let obs: Vec<f32> = (0..minibatch * OBS).map(|_| rng.random_range(-1.0..1.0)).collect();
    let step = ppo.policy_step(&obs, &mut rng).unwrap();
    let batch = PpoBatch {
        obs,
        actions: step.actions,
        log_probs: step.log_probs,
        advantages: (0..minibatch).map(|_| rng.random_range(-1.0..1.0)).collect(),
        returns: (0..minibatch).map(|_| rng.random_range(-1.0..1.0)).collect(),
        values: step.values,
    };
    group.bench_function(format!("ppo/update 64-64 minibatch {minibatch}"), |b| {
        b.iter(|| black_box(ppo.learn(&batch).unwrap()))
    });
    let one: Vec<f32> = (0..OBS).map(|i| (i as f32 * 0.1).sin()).collect();
    group.bench_function("ppo/act one observation 64-64", |b| b.iter(|| black_box(ppo.act(black_box(&one)).unwrap())));
    let mut batch = Batch::new(BATCH, OBS, ACT);
    group.bench_function(format!("buffer/sample batch {BATCH}"), |b| b.iter(|| buf.sample_into(&mut batch, &mut rng)));
    group.finish();
    println!(
        "replay buffer at HalfCheetah sizes: {} bytes per transition (+ one observation per truncated episode)",
        buf.bytes_per_transition()
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
