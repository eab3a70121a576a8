//! Update speed of one agent on one device (`locobench device speed`), and the cost of the
//! per-update host-to-device copy of the batch. Every timed update reads its losses back, so the
//! clock sees the device's work, not just its queue.
use std::time::Instant;

use candle_core::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use locobench::agents::common::device::{make_generic_agent, make_generic_on_policy, DeviceBatch};
use locobench::agents::ppo::PpoBatch;
use locobench::agents::{make_learner, Algo, Batch, OnPolicyAgent, PpoAgent, TrainConfig};

/// Which implementation to time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Path {
    /// The exact fused CPU path.
    Fused,
    /// The device-generic path on the given device.
    Generic,
}

/// One measurement.
#[derive(Debug, Clone)]
pub struct Speed {
    /// Updates per second over the timed stretch (for PPO: epochs per second).
    pub updates_per_s: f64,
    /// Updates timed (for PPO: epochs, each a pass over a rollout in minibatches).
    pub updates: u64,
    /// Microseconds per batch upload (one host-to-device copy, then a read-back of one value
    /// to wait for it); 0 for the fused path, which copies nothing.
    pub upload_us: f64,
}

/// Times `cfg`'s updates for about `seconds` after `warmup` untimed ones, on HalfCheetah-sized
/// inputs (`obs`, `act`). PPO's unit is an epoch: one pass over a rollout of `num_steps` samples
/// in minibatches of `batch_size` (SB3's `n_steps` and `batch_size`).
pub fn measure(
    cfg: &TrainConfig,
    obs: usize,
    act: usize,
    path: Path,
    device: &Device,
    warmup: usize,
    seconds: f64,
) -> anyhow::Result<Speed> {
    if cfg.algo == Algo::Ppo {
        return measure_ppo(cfg, obs, act, path, device, seconds);
    }
    let mut init = ChaCha8Rng::seed_from_u64(0);
    let mut agent = match path {
        Path::Fused => make_learner(cfg, obs, act, &mut init)?,
        Path::Generic => make_generic_agent(cfg, obs, act, &mut init, device)?,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let batches: Vec<Batch> = (0..16).map(|_| super::check::batch(&mut rng, cfg.batch_size, obs, act)).collect();
    for b in batches.iter().cycle().take(warmup) {
        agent.update(b, &mut rng)?;
    }
    let start = Instant::now();
    let mut updates = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        agent.update(&batches[updates as usize % batches.len()], &mut rng)?;
        updates += 1;
    }
    let updates_per_s = updates as f64 / start.elapsed().as_secs_f64();

    let upload_us = if path == Path::Generic {
        let noise = vec![vec![0.0; cfg.batch_size * act]; 2];
        let rounds = 200;
        let start = Instant::now();
        for b in batches.iter().cycle().take(rounds) {
            let d = DeviceBatch::upload(b, obs, act, &noise, device)?;
            let _: Vec<f32> = d.rewards.narrow(0, 0, 1)?.flatten_all()?.to_vec1()?;
        }
        start.elapsed().as_secs_f64() * 1e6 / rounds as f64
    } else {
        0.0
    };
    Ok(Speed { updates_per_s, updates, upload_us })
}

fn measure_ppo(
    cfg: &TrainConfig,
    obs: usize,
    act: usize,
    path: Path,
    device: &Device,
    seconds: f64,
) -> anyhow::Result<Speed> {
    let mut init = ChaCha8Rng::seed_from_u64(0);
    let mut agent: Box<dyn OnPolicyAgent> = match path {
        Path::Fused => Box::new(PpoAgent::new(cfg, obs, act, &mut init)?),
        Path::Generic => make_generic_on_policy(cfg, obs, act, &mut init, device)?,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let rollout = cfg.ppo().num_steps;
    let minibatches: Vec<PpoBatch> = (0..rollout.div_ceil(cfg.batch_size))
        .map(|_| super::check::ppo_batch(agent.as_ref(), &mut rng, cfg.batch_size, obs))
        .collect::<candle_core::Result<_>>()?;
    let epoch = |agent: &mut Box<dyn OnPolicyAgent>| -> anyhow::Result<()> {
        for b in &minibatches {
            agent.learn(b)?;
        }
        Ok(())
    };
    epoch(&mut agent)?;
    let start = Instant::now();
    let mut epochs = 0u64;
    while start.elapsed().as_secs_f64() < seconds {
        epoch(&mut agent)?;
        epochs += 1;
    }
    Ok(Speed { updates_per_s: epochs as f64 / start.elapsed().as_secs_f64(), updates: epochs, upload_us: 0.0 })
}

/// Microseconds per read-back of one value already on the device (the floor under any
/// synchronisation).
pub fn readback_us(device: &Device) -> anyhow::Result<f64> {
    let t = Tensor::new(&[1f32], device)?;
    let rounds = 200;
    let start = Instant::now();
    for _ in 0..rounds {
        let _: Vec<f32> = (&t + 1.0)?.to_vec1()?;
    }
    Ok(start.elapsed().as_secs_f64() * 1e6 / rounds as f64)
}

/// `algo`'s default configuration with the given widths and batch size.
pub fn sized_config(algo: Algo, hidden: &[usize], critic_hidden: Option<&[usize]>, batch: usize) -> TrainConfig {
    let mut cfg = TrainConfig::defaults(algo);
    cfg.hidden = hidden.to_vec();
    cfg.batch_size = batch;
    if let Some(p) = cfg.ppo.as_mut() {
        // SB3's PPO defaults: rollouts of 2048 steps from one env
        (p.num_envs, p.num_steps) = (1, 2048);
    }
    if let (Some(c), Some(w)) = (cfg.crossq.as_mut(), critic_hidden) {
        c.critic_hidden = w.to_vec();
    }
    cfg
}
