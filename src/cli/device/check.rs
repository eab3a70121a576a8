//! The device-generic path against the fused one: from the same seed (so the same initial
//! weights) and the same 100 batches, the losses of every update and the weights after the last
//! agree within a stated tolerance, per algorithm. The two paths round differently (the fused
//! kernels' order of operations against candle's), and Adam amplifies that where a gradient is near
//! zero; over 100 updates the gaps stay a few f32 roundings wide.
use candle_core::{DType, Device, Result, Var};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use locobench::agents::common::device::{make_generic_agent, make_generic_on_policy};
use locobench::agents::ppo::{PpoBatch, PpoLosses};
use locobench::agents::{make_learner, Agent, Algo, Batch, Losses, OnPolicyAgent, PpoAgent, TrainConfig};

/// The comparison's observation and action sizes.
pub const OBS: usize = 7;
/// See [`OBS`].
pub const ACT: usize = 3;
/// Updates each comparison runs.
pub const UPDATES: usize = 100;

/// Tolerances: relative on each loss, and absolute on each weight after the last update.
pub struct Tolerance {
    /// Relative, on every loss and temperature.
    pub loss: f64,
    /// Absolute, on every weight after the last update.
    pub weight: f64,
}

/// A small configuration of `algo` for the comparison.
pub fn config(algo: Algo) -> TrainConfig {
    let mut cfg = TrainConfig::defaults(algo);
    cfg.hidden = vec![32, 32];
    cfg.batch_size = 64;
    if let Some(c) = cfg.crossq.as_mut() {
        c.critic_hidden = vec![48, 48];
        // both normalisation modes within the 100 updates
        c.renorm_warmup_steps = 40;
    }
    if algo == Algo::Ppo {
        // large steps, so that the ratio and value clips engage within the 100 updates
        (cfg.actor_lr, cfg.critic_lr) = (1e-2, 1e-2);
    }
    cfg
}

/// `n` random transitions of `obs` observations and `act` actions (every 13th terminal): the
/// comparison's batches, and the speed measurement's.
pub(crate) fn batch(rng: &mut ChaCha8Rng, n: usize, obs: usize, act: usize) -> Batch {
    let mut normal =
        |count: usize, scale: f32| -> Vec<f32> { (0..count).map(|_| rng.random_range(-1.0f32..1.0) * scale).collect() };
    let obs_now = normal(n * obs, 2.0);
    let actions = normal(n * act, 1.0);
    let next_obs = normal(n * obs, 2.0);
    let rewards = normal(n, 3.0);
    let terminated = (0..n).map(|i| if i % 13 == 0 { 1.0 } else { 0.0 }).collect();
    Batch { size: n, obs: obs_now, actions, rewards, next_obs, terminated }
}

/// The largest differences seen: relative between losses, absolute between weights.
#[derive(Debug, Default)]
pub struct Gap {
    /// Relative, over every loss and temperature.
    pub loss: f64,
    /// Absolute, over every weight.
    pub weight: f64,
    /// The weight with the largest gap.
    pub weight_name: String,
}

/// Runs both paths through `updates` updates; `device` hosts the generic one.
pub fn compare(algo: Algo, device: &Device, updates: usize) -> Gap {
    if algo == Algo::Ppo {
        return compare_ppo(&config(algo), device, updates);
    }
    compare_config(&config(algo), device, updates)
}

/// [`compare`] for any off-policy configuration.
pub fn compare_config(cfg: &TrainConfig, device: &Device, updates: usize) -> Gap {
    let algo = cfg.algo;
    let cfg = cfg.clone();
    let mut fused = make_learner(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(11)).unwrap();
    let mut generic = make_generic_agent(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(11), device).unwrap();
    let (mut rng_f, mut rng_g) = (ChaCha8Rng::seed_from_u64(5), ChaCha8Rng::seed_from_u64(5));
    let mut data = ChaCha8Rng::seed_from_u64(3);
    let mut gap = Gap::default();
    let relative = |a: f64, b: f64| (a - b).abs() / (1.0 + b.abs());
    for u in 0..updates {
        let b = batch(&mut data, cfg.batch_size, OBS, ACT);
        let lf: Losses = fused.update(&b, &mut rng_f).unwrap();
        let lg: Losses = generic.update(&b, &mut rng_g).unwrap();
        assert_eq!(lf.actor.is_some(), lg.actor.is_some(), "{algo:?} update {u}: the actor trained on one path only");
        assert!(lg.critic.is_finite() && lg.actor.is_none_or(f64::is_finite), "{algo:?} update {u}: {lg:?}");
        gap.loss = gap.loss.max(relative(lg.critic, lf.critic));
        if let (Some(a), Some(b)) = (lg.actor, lf.actor) {
            gap.loss = gap.loss.max(relative(a, b));
        }
        if let (Some(a), Some(b)) = (lg.alpha, lf.alpha) {
            gap.loss = gap.loss.max(relative(a, b));
        }
    }
    // the same RNG draws on both paths
    assert_eq!(rng_f.random::<u64>(), rng_g.random::<u64>(), "{algo:?}: the paths drew different noise");
    let fused_names: Vec<_> = fused.optimizers().iter().map(|(n, _)| *n).collect();
    let generic_names: Vec<_> = generic.optimizers().iter().map(|(n, _)| *n).collect();
    assert_eq!(fused_names, generic_names, "{algo:?}: the optimiser state is laid out differently");
    weight_gap(&*fused, &*generic, &mut gap);
    gap
}

/// The largest absolute difference between the two agents' parameters of the same name.
fn weight_gap(fused: &dyn Agent, generic: &dyn Agent, gap: &mut Gap) {
    let generic_params = generic.parameters();
    for (name, var) in fused.parameters() {
        let (_, other) = generic_params.iter().find(|(n, _)| *n == name).unwrap_or_else(|| panic!("no {name}"));
        assert_eq!(var.dims(), other.dims(), "{name}");
        // as f64: PPO's observation statistics are f64
        let values = |v: &Var| -> Vec<f64> {
            v.flatten_all().unwrap().to_device(&Device::Cpu).unwrap().to_dtype(DType::F64).unwrap().to_vec1().unwrap()
        };
        for (x, y) in values(&var).iter().zip(&values(other)) {
            let d = (x - y).abs();
            if d > gap.weight {
                gap.weight = d;
                gap.weight_name = name.clone();
            }
        }
    }
}

/// `n` samples of a rollout for PPO's comparison: observations, the actions `agent` samples there
/// with their log-probabilities and values, random advantages and returns near the values.
/// (The comparison's minibatches, and the speed measurement's.)
pub(crate) fn ppo_batch(agent: &dyn OnPolicyAgent, rng: &mut ChaCha8Rng, n: usize, obs_dim: usize) -> Result<PpoBatch> {
    let obs: Vec<f32> = (0..n * obs_dim).map(|_| rng.random_range(-2.0f32..2.0)).collect();
    let step = agent.policy_step(&obs, rng)?;
    let advantages: Vec<f32> = (0..n).map(|_| rng.random_range(-1.5f32..1.5)).collect();
    let returns = step.values.iter().zip(&advantages).map(|(v, a)| v + a).collect();
    Ok(PpoBatch { obs, actions: step.actions, log_probs: step.log_probs, advantages, returns, values: step.values })
}

/// PPO's comparison: rollouts of 8 minibatches sampled by the fused agent as it learns (so the
/// ratios move away from 1 and the clips engage, as in training), each learned from by both paths,
/// with the learning rate annealed between rollouts.
/// [`compare`] for PPO with the settings `cfg`.
pub fn compare_ppo(cfg: &TrainConfig, device: &Device, updates: usize) -> Gap {
    let cfg = cfg.clone();
    let mut fused = PpoAgent::new(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(11)).unwrap();
    let mut generic = make_generic_on_policy(&cfg, OBS, ACT, &mut ChaCha8Rng::seed_from_u64(11), device).unwrap();
    let mut data = ChaCha8Rng::seed_from_u64(3);
    let raw: Vec<Vec<f64>> = (0..32).map(|_| (0..OBS).map(|_| data.random_range(-3.0..3.0)).collect()).collect();
    fused.observe(&raw).unwrap();
    generic.observe(&raw).unwrap();
    let mut gap = Gap::default();
    let relative = |a: f64, b: f64| (a - b).abs() / (1.0 + b.abs());
    let mut rollout = Vec::new();
    let mut clipped = 0.0f64;
    for u in 0..updates {
        if u % 8 == 0 {
            let fraction = 1.0 - u as f64 / updates as f64;
            fused.anneal(fraction);
            generic.anneal(fraction);
            rollout = (0..8).map(|_| ppo_batch(&fused, &mut data, cfg.batch_size, OBS).unwrap()).collect();
        }
        let b = &rollout[u % 8];
        let lf: PpoLosses = fused.learn(b).unwrap();
        let lg: PpoLosses = generic.learn(b).unwrap();
        for (x, y) in
            [(lg.policy, lf.policy), (lg.value, lf.value), (lg.entropy, lf.entropy), (lg.approx_kl, lf.approx_kl)]
        {
            assert!(x.is_finite(), "ppo update {u}: {lg:?}");
            gap.loss = gap.loss.max(relative(x, y));
        }
        // a share of the minibatch: a ratio on the clip's edge may fall either side
        assert!(
            (lg.clip_fraction - lf.clip_fraction).abs() <= 1.0 / cfg.batch_size as f64,
            "update {u}: {lg:?} vs {lf:?}"
        );
        clipped = clipped.max(lf.clip_fraction);
    }
    assert!(updates < 30 || clipped > 0.05, "ppo: the ratio clip never engaged (largest clip fraction {clipped})");
    let obs: Vec<f32> = (0..4 * OBS).map(|i| (i as f32 * 0.37).sin()).collect();
    let (mut r1, mut r2) = (ChaCha8Rng::seed_from_u64(6), ChaCha8Rng::seed_from_u64(6));
    let (sf, sg) = (fused.policy_step(&obs, &mut r1).unwrap(), generic.policy_step(&obs, &mut r2).unwrap());
    for (x, y) in sf.actions.iter().chain(&sf.values).zip(sg.actions.iter().chain(&sg.values)) {
        gap.loss = gap.loss.max(relative(*y as f64, *x as f64));
    }
    let fused_names: Vec<_> = fused.optimizers().iter().map(|(n, _)| *n).collect();
    let generic_names: Vec<_> = generic.optimizers().iter().map(|(n, _)| *n).collect();
    assert_eq!(fused_names, generic_names, "ppo: the optimiser state is laid out differently");
    weight_gap(&fused, &*generic, &mut gap);
    gap
}

/// Every algorithm, in the order the check reports them.
pub const ALGOS: [Algo; 6] = [Algo::Td3, Algo::Ddpg, Algo::Sac, Algo::Crossq, Algo::Dqn, Algo::Ppo];

/// The stated tolerance per algorithm (docs/gpu.md quotes these): on the CPU the measured gaps
/// are about 1e-7 (losses, relative) and 1e-7 to 1e-6 (weights, absolute; CrossQ's running
/// variances the largest).
pub fn tolerance(algo: Algo) -> Tolerance {
    match algo {
        Algo::Td3 | Algo::Ddpg | Algo::Sac => Tolerance { loss: 1e-5, weight: 1e-5 },
        Algo::Crossq => Tolerance { loss: 1e-5, weight: 2e-5 },
        Algo::Dqn | Algo::Ppo => Tolerance { loss: 1e-5, weight: 1e-5 },
    }
}
