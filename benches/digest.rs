//! Digests of what this binary computes, to compare CPUs bit for bit: `benches/cross_cpu.sh`
//! runs it natively and under `qemu-x86_64 -cpu Haswell|Nehalem`.
//!
//! - `physics`: an Ant episode of random actions (MuJoCo and the env's Rust code alone);
//! - `controller`: a Minitaur episode of the Raibert/QP controller at 1.0 m/s;
//! - `policy`: two episodes of the shipped TD3 Minitaur policy (the networks acting);
//! - `training`: a short TD3 run on InvertedPendulum (weights, optimiser state, metrics);
//! - `training-sac`: the same with SAC (its `exp`, `log` and sampling on top of TD3's `tanh`).
//!
//! Every f64 and f32 is hashed by its bits, so equal digests mean equal bits. The kernel path is
//! whatever `LOCOBENCH_KERNELS` selects, printed first.
//!
//! `cargo bench --bench digest -- --bench` (under `cargo test` the training run is shorter).
use std::hash::{DefaultHasher, Hasher};
use std::path::Path;

use anyhow::Result;
use locobench::agents::Algo;
use locobench::controller::baseline::{baseline_controller_for, baseline_env, RAMP_TIME};
use locobench::controller::command::{Command, SpeedProfile};
use locobench::envs::{make, EnvConfig};
use locobench::policy::{AgentPolicy, Policy, RandomPolicy};
use locobench::rollout::{run_episodes, StepView};
use locobench::train::config::{build_config, split_pairs};
use locobench::train::{self, RunControl};

/// Hash of every step's action, reward and observation.
fn episodes(cfg: &EnvConfig, policy: &mut dyn Policy, count: usize, seed: u64) -> Result<u64> {
    let mut env = make(cfg)?;
    let mut h = DefaultHasher::new();
    run_episodes(env.as_mut(), policy, count, seed, &mut |v: &StepView| {
        v.action.iter().for_each(|a| h.write_u64(a.to_bits()));
        h.write_u64(v.step.reward.to_bits());
        v.step.observation.iter().for_each(|o| h.write_u64(o.to_bits()));
        Ok(())
    })?;
    Ok(h.finish())
}

fn training(algo: Algo, steps: u64) -> Result<u64> {
    let dir = tempfile::tempdir()?;
    let set = format!(
        "total_steps={steps},warmup_steps=500,learning_starts=500,eval_every=1000,eval_episodes=2,hidden=[64,64],batch_size=64"
    );
    let cfg = build_config("inverted-pendulum", algo, &split_pairs(&set)?)?;
    let run = dir.path().join("run");
    let s = train::train(EnvConfig::new("inverted-pendulum"), cfg, 1, &run, None, false, &RunControl::default())?;
    let mut h = DefaultHasher::new();
    for f in ["model.safetensors", "optim.safetensors"] {
        h.write(&std::fs::read(s.checkpoint.join(f))?);
    }
    for row in train::metrics::read(&run.join("metrics.csv"))? {
        h.write(row.kind.as_bytes());
        h.write_u64(row.step);
        for v in [row.episode_return, row.eval_mean, row.critic_loss, row.actor_loss].into_iter().flatten() {
            h.write_u64(v.to_bits());
        }
    }
    Ok(h.finish())
}

fn main() -> Result<()> {
    let smoke = !std::env::args().any(|a| a == "--bench");
    let _runtime = locobench::runtime::Runtime::enter(1);
    println!("kernels {}", locobench::numeric::kernel_path::active());

    let physics = episodes(&EnvConfig::new("ant"), &mut RandomPolicy::new(3), 1, 3)?;
    println!("physics {physics:016x}");

    let command = Command { speed: SpeedProfile::ramp(1.0, RAMP_TIME), yaw_rate: 0.0 };
    let mut controller = baseline_controller_for("minitaur", command, None)?;
    println!("controller {:016x}", episodes(&baseline_env("minitaur")?, controller.as_mut(), 1, 0)?);

    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/policies/minitaur-td3");
    let (run, agent) = train::load_policy(&shipped)?;
    let mut policy = AgentPolicy { agent: agent.as_ref(), label: "td3".into() };
    println!("policy {:016x}", episodes(&run.env, &mut policy, 2, 6000)?);

    let steps = if smoke { 1000 } else { 3000 };
    println!("training {:016x}", training(Algo::Td3, steps)?);
    println!("training-sac {:016x}", training(Algo::Sac, steps)?);
    Ok(())
}
