//! Replay-buffer memory: bytes per stored transition for every environment, what a 1M buffer
//! takes, and the resident memory a full 1M-transition Humanoid buffer actually adds (filled
//! transition by transition, as training fills it), read from /proc/self/status.
//!
//! `cargo bench --bench memory` (under `cargo test` it fills a 10k buffer only).
use anyhow::Result;
use locobench::agents::ReplayBuffer;
use locobench::envs::{env_names, make, EnvConfig};

fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

fn gib(bytes: f64) -> f64 {
    bytes / (1u64 << 30) as f64
}

fn main() -> Result<()> {
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
    Ok(())
}
