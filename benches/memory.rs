//! Replay-buffer memory: bytes per stored transition for every environment, what a 1M buffer
//! takes, and the resident memory a full 1M-transition Humanoid buffer actually adds (filled
//! transition by transition, as training fills it), read from /proc/self/status.
//!
//! Then the peak resident memory (VmHWM) of a 1M-step run for every environment and algorithm,
//! each in a process of its own: the agent its preset builds, the environment, a replay buffer
//! filled with 1M transitions, 20 updates, and a checkpoint written with the real
//! `train::checkpoint::save` (which copies the buffer while writing it: the run's peak). The
//! transitions are synthetic, so the figure is the run's memory without its hours of stepping.
//!
//! `cargo bench --bench memory` (under `cargo test` it fills a 10k buffer and measures one pair).

use anyhow::{Context, Result};
use locobench::agents::{make_learner, Algo, Batch, ReplayBuffer};
use locobench::envs::{env_names, make, EnvConfig};
use locobench::train::checkpoint::{self, TrainState};
use locobench::train::config::build_config;
use locobench::train::seeds::RngState;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn status_bytes(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// One (env, algo) run's memory, in this process: prints `peak_bytes buffer_bytes`.
fn child(env_name: &str, algo: Algo, capacity: usize) -> Result<()> {
    let _runtime = locobench::runtime::Runtime::enter(1);
    let mut cfg = build_config(env_name, algo, &[])?;
    cfg.buffer_capacity = capacity;
    let env = make(&EnvConfig::new(env_name))?;
    let (obs_dim, act_dim) = (env.spec().observation_space.dim(), env.spec().action_space.dim());
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut agent = make_learner(&cfg, obs_dim, act_dim, &mut rng)?;
    let mut buf = ReplayBuffer::new(capacity, obs_dim, act_dim);
    let (mut obs, action) = (vec![0.5f32; obs_dim], vec![0.1f32; act_dim]);
    for t in 0..capacity {
        let mut next = obs.clone();
        next[0] = (t % 977) as f32 * 1e-3;
        buf.add(&obs, &action, 1.0, &next, false, t % 1000 == 999);
        obs = next;
    }
    agent.fit_observations(&buf)?;
    let mut batch = Batch::new(cfg.batch_size, obs_dim, act_dim);
    for _ in 0..20 {
        buf.sample_into(&mut batch, &mut rng);
        agent.update(&batch, &mut rng)?;
    }
    let dir = tempfile::tempdir()?;
    let state = TrainState {
        step: capacity as u64,
        episodes: (capacity / 1000) as u64,
        at_episode_boundary: true,
        wall_time: 0.0,
        rng: RngState::of(&rng),
        optimizer_steps: Default::default(),
        counters: Default::default(),
        losses: None,
        best_eval_mean: None,
        best_policy: None,
    };
    checkpoint::save(dir.path(), agent.as_mut(), &buf, &state, &[])?;
    let peak = status_bytes("VmHWM:").context("no /proc/self/status")?;
    println!("{peak} {}", buf.bytes_per_transition() * capacity);
    Ok(())
}

/// Runs every (env, algo) pair in a child process and prints the table.
fn peak_per_run(smoke: bool) -> Result<()> {
    let capacity = if smoke { 10_000 } else { 1_000_000 };
    let envs: Vec<&str> = if smoke { vec!["hopper"] } else { env_names().to_vec() };
    let algos: &[Algo] = if smoke { &[Algo::Td3] } else { &[Algo::Td3, Algo::Sac, Algo::Ddpg] };
    println!("\n| env | algo | networks | buffer ({capacity} transitions) | peak resident memory of the run |");
    println!("|---|---|---|---|---|");
    for env in envs {
        for algo in algos {
            let out = std::process::Command::new(std::env::current_exe()?)
                .args(["--child", env, algo.name(), &capacity.to_string()])
                .output()?;
            anyhow::ensure!(out.status.success(), "{env} {}: {}", algo.name(), String::from_utf8_lossy(&out.stderr));
            let text = String::from_utf8_lossy(&out.stdout);
            let nums: Vec<u64> = text.split_whitespace().filter_map(|v| v.parse().ok()).collect();
            anyhow::ensure!(nums.len() == 2, "{env} {}: unexpected output {text:?}", algo.name());
            let hidden = build_config(env, *algo, &[])?.hidden;
            println!(
                "| {env} | {} | {hidden:?} | {:.2} GiB | {:.2} GiB |",
                algo.name(),
                gib(nums[1] as f64),
                gib(nums[0] as f64)
            );
        }
    }
    Ok(())
}

fn resident_bytes() -> Option<u64> {
    status_bytes("VmRSS:")
}

fn gib(bytes: f64) -> f64 {
    bytes / (1u64 << 30) as f64
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--child") {
        let (env, algo, capacity) = (&args[i + 1], Algo::parse(&args[i + 2])?, args[i + 3].parse()?);
        return child(env, algo, capacity);
    }
    let smoke = !std::env::args().any(|a| a == "--bench");
    println!("| env | obs | act | bytes/transition | 1M transitions |");
    println!("|---|---|---|---|---|");
    let mut humanoid = (0, 0);
    for name in env_names() {
        let env = make(&EnvConfig::new(name))?;
        let (obs, act) = (env.spec().observation_space.dim(), env.spec().action_space.dim());
        let per = ReplayBuffer::new(1, obs, act).bytes_per_transition();
        println!("| {name} | {obs} | {act} | {per} | {:.2} GiB |", gib(per as f64 * 1e6));
        if name == "humanoid" {
            humanoid = (obs, act);
        }
    }

    let capacity = if smoke { 10_000 } else { 1_000_000 };
    let (obs_dim, act_dim) = humanoid;
    let before = resident_bytes();
    let mut buf = ReplayBuffer::new(capacity, obs_dim, act_dim);
    let (mut obs, action) = (vec![0.5f32; obs_dim], vec![0.1f32; act_dim]);
    for t in 0..capacity {
        let mut next = obs.clone();
        next[0] = t as f32;
        // 1000-step episodes ending by time limit: the side table keeps one observation per episode.
        buf.add(&obs, &action, 1.0, &next, false, t % 1000 == 999);
        obs = next;
    }
    let after = resident_bytes();
    match (before, after) {
        (Some(b), Some(a)) => println!(
            "humanoid buffer of {capacity} transitions, filled: resident memory +{:.2} GiB ({:.0} bytes/transition)",
            gib(a.saturating_sub(b) as f64),
            a.saturating_sub(b) as f64 / capacity as f64
        ),
        _ => println!("humanoid buffer of {capacity} transitions filled (no /proc/self/status to read)"),
    }
    assert_eq!(buf.len(), capacity);
    drop(buf);
    peak_per_run(smoke)
}
