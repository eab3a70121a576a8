//! Training throughput of one algorithm at HalfCheetah sizes, printed as one JSON line:
//! gradient updates/s (batch 256, one update after another) and environment steps/s while
//! training (one update per step, the real `locobench train` loop, after the warm-up).
//!
//! `cargo bench --bench throughput -- --roofline` instead prints the TD3 update's matmul GFLOP/s
//! against one core's measured matmul peak, and `-- --matmul` the GFLOP/s of every kernel path
//! (`numeric::kernel_path`) on the update's products. `LOCOBENCH_KERNELS` picks the path the
//! other modes run on; each JSON line names it.
//!
//! `cargo bench --bench throughput -- --algo td3 [--updates 300] [--steps 1000] [--threads 1|2]`;
//! used by `benches/sb3/compare.sh`, which alternates it with Stable-Baselines3 in one run.
//! Networks: TD3 and DDPG 400-300, SAC 256-256; candle on one thread, plus our helper thread
//! with `--threads 2`.
use std::time::Instant;

use anyhow::{Context, Result};
use locobench::agents::{make_agent, Algo, Batch, ReplayBuffer, TrainConfig};
use locobench::envs::EnvConfig;
use locobench::train::{metrics, train, RunControl};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const OBS: usize = 17;
const ACT: usize = 6;
const BATCH: usize = 256;
const WARMUP: u64 = 1000;

fn arg(name: &str) -> Option<String> {
    let args: Vec<String> = std::env::args().collect();
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1).cloned())
}

/// `--threads 1|2` (default 1): whether the training thread gets a helper thread
/// (`locobench train --threads`).
fn threads() -> usize {
    arg("--threads").map(|v| v.parse().expect("--threads takes 1 or 2")).unwrap_or(1)
}

fn config(algo: Algo) -> TrainConfig {
    let mut cfg = TrainConfig::defaults(algo);
    cfg.hidden = if algo == Algo::Sac { vec![256, 256] } else { vec![400, 300] };
    cfg.batch_size = BATCH;
    cfg
}

fn updates_per_second(algo: Algo, updates: usize) -> Result<f64> {
    let _runtime = locobench::runtime::Runtime::enter(threads());
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let mut buf = ReplayBuffer::new(50_000, OBS, ACT);
    let mut obs: Vec<f32> = (0..OBS).map(|_| rng.random_range(-1.0..1.0)).collect();
    for t in 0..20_000 {
        let next: Vec<f32> = (0..OBS).map(|_| rng.random_range(-1.0..1.0)).collect();
        let act: Vec<f32> = (0..ACT).map(|_| rng.random_range(-1.0..1.0)).collect();
        buf.add(&obs, &act, rng.random_range(-1.0..1.0), &next, false, t % 1000 == 999);
        obs = next;
    }
    let mut agent = make_agent(&config(algo), OBS, ACT, &mut rng)?;
    let mut batch = Batch::new(BATCH, OBS, ACT);
    for _ in 0..10 {
        buf.sample_into(&mut batch, &mut rng);
        agent.update(&batch, &mut rng)?;
    }
    let started = Instant::now();
    for _ in 0..updates {
        buf.sample_into(&mut batch, &mut rng);
        agent.update(&batch, &mut rng)?;
    }
    Ok(updates as f64 / started.elapsed().as_secs_f64())
}

/// Steps/s of a real training run between the end of warm-up and the end of the run, from the
/// wall times `metrics.csv` records at episode ends (HalfCheetah episodes are 1000 steps).
fn training_steps_per_second(algo: Algo, steps: u64) -> Result<f64> {
    let dir = tempfile::tempdir()?;
    let mut cfg = config(algo);
    cfg.total_steps = WARMUP + steps;
    cfg.warmup_steps = WARMUP;
    cfg.learning_starts = WARMUP;
    cfg.buffer_capacity = (WARMUP + steps) as usize;
    cfg.eval_every = 1 << 40;
    cfg.eval_episodes = 1;
    cfg.checkpoint_every = 1 << 40;
    let run = dir.path().join("run");
    train(
        EnvConfig::new("half-cheetah"),
        cfg,
        0,
        &run,
        None,
        false,
        &RunControl { threads: threads(), ..Default::default() },
    )?;
    let rows = metrics::read(&run.join("metrics.csv"))?;
    let at = |step: u64| rows.iter().find(|r| r.kind == "episode" && r.step == step).map(|r| r.wall_time);
    let (t0, t1) =
        (at(WARMUP).context("no episode end at warm-up")?, at(WARMUP + steps).context("no final episode end")?);
    Ok(steps as f64 / (t1 - t0))
}

/// Matmul FLOPs of one forward pass of an MLP over `batch` rows; `skip_first` leaves out the
/// first layer (a backward pass needs no input gradient for the network's input).
fn mlp_flops(sizes: &[usize], batch: usize, skip_first: bool) -> f64 {
    let layers = sizes.windows(2).skip(skip_first as usize);
    layers.map(|w| 2.0 * (batch * w[0] * w[1]) as f64).sum()
}

/// Matmul FLOPs of one TD3 update at these sizes (about 0.8 GFLOP): target
/// actor + two target critics forward; two critics forward and backward (weight gradients, and
/// input gradients past the first layer); every second update the actor step (actor forward,
/// critic 0 forward and its input gradients down to the action, actor backward).
fn td3_update_flops() -> f64 {
    let actor = [OBS, 400, 300, ACT];
    let critic = [OBS + ACT, 400, 300, 1];
    let (a, c) = (mlp_flops(&actor, BATCH, false), mlp_flops(&critic, BATCH, false));
    let targets = a + 2.0 * c;
    let critic_step = 2.0 * (c + c + mlp_flops(&critic, BATCH, true));
    let actor_step = a + c + c + a + mlp_flops(&actor, BATCH, true);
    targets + critic_step + actor_step / 2.0
}

/// Single-thread f32 matmul rate of the gemm library candle uses, on a large square product:
/// the practical peak of one core, the roofline the TD3 update is measured against.
fn matmul_peak_gflops() -> Result<f64> {
    let _runtime = locobench::runtime::Runtime::enter(1);
    use candle_core::{Device, Tensor};
    let n = 1024;
    let a = Tensor::rand(-1f32, 1f32, (n, n), &Device::Cpu)?;
    let b = Tensor::rand(-1f32, 1f32, (n, n), &Device::Cpu)?;
    let _ = a.matmul(&b)?;
    let reps = 10;
    let started = Instant::now();
    for _ in 0..reps {
        std::hint::black_box(a.matmul(&b)?);
    }
    Ok(reps as f64 * 2.0 * (n * n * n) as f64 / started.elapsed().as_secs_f64() / 1e9)
}

/// GFLOP/s of each kernel path this CPU supports on the products of a TD3 400-300 critic update
/// at batch 256 (forward, weight gradient, input gradient of the 400 -> 300 layer, and the
/// 23 -> 400 first layer), one thread.
fn matmul_paths() -> Result<()> {
    use locobench::numeric::matmul::{matmul, Strided};
    use locobench::numeric::KernelPath;
    let _runtime = locobench::runtime::Runtime::enter(1);
    // (name, (m, n, k), A read transposed, B read transposed)
    type Product = (&'static str, (usize, usize, usize), bool, bool);
    let shapes: [Product; 4] = [
        ("forward 256x300x400 (x W^T)", (BATCH, 300, 400), false, true),
        ("weight grad 300x400x256 (g^T x)", (300, 400, BATCH), true, false),
        ("input grad 256x400x300 (g W)", (BATCH, 400, 300), false, false),
        ("forward 256x400x23 (x W^T)", (BATCH, 400, OBS + ACT), false, true),
    ];
    println!(
        "| product | {} |",
        KernelPath::ALL.iter().filter(|p| p.is_supported()).map(|p| p.name()).collect::<Vec<_>>().join(" | ")
    );
    println!("|---|{}", "---|".repeat(KernelPath::ALL.iter().filter(|p| p.is_supported()).count()));
    for (name, (m, n, k), a_transposed, b_transposed) in shapes {
        let a_data: Vec<f32> = (0..m * k).map(|i| (i as f32 * 0.37).sin()).collect();
        let b_data: Vec<f32> = (0..k * n).map(|i| (i as f32 * 0.11).cos()).collect();
        let a = if a_transposed { Strided::transposed(&a_data, m) } else { Strided::rows(&a_data, k) };
        let b = if b_transposed { Strided::transposed(&b_data, k) } else { Strided::rows(&b_data, n) };
        let mut dst = vec![0f32; m * n];
        let mut row = format!("| {name} |");
        for path in KernelPath::ALL.into_iter().filter(|p| p.is_supported()) {
            let reps = if path == KernelPath::Portable { 3 } else { 200 };
            matmul(path, (m, n, k), &mut dst, n, false, a, b);
            let started = Instant::now();
            for _ in 0..reps {
                matmul(path, (m, n, k), &mut dst, n, false, a, b);
                std::hint::black_box(&mut dst);
            }
            let gflops = reps as f64 * 2.0 * (m * n * k) as f64 / started.elapsed().as_secs_f64() / 1e9;
            row += &format!(" {gflops:.1} |");
        }
        println!("{row}");
    }
    Ok(())
}

fn main() -> Result<()> {
    if std::env::args().any(|a| a == "--matmul") {
        return matmul_paths();
    }
    if std::env::args().any(|a| a == "--roofline") {
        let peak = matmul_peak_gflops()?;
        let flops = td3_update_flops() / 1e9;
        let ups = updates_per_second(Algo::Td3, arg("--updates").map(|v| v.parse()).transpose()?.unwrap_or(300))?;
        println!(
            "{{\"matmul_peak_gflops\": {peak:.1}, \"td3_gflop_per_update\": {flops:.3}, \"threads\": {}, \"kernels\": \"{}\", \"td3_updates_per_s\": {ups:.1}, \"td3_gflops\": {:.1}, \"fraction_of_one_core_peak\": {:.2}, \"fraction_of_peak_of_cores_used\": {:.2}}}",
            threads(),
            locobench::numeric::kernel_path::active(),
            ups * flops,
            ups * flops / peak,
            ups * flops / (peak * threads() as f64)
        );
        return Ok(());
    }
    let smoke = !std::env::args().any(|a| a == "--bench");
    let algo = Algo::parse(&arg("--algo").unwrap_or_else(|| "td3".into()))?;
    let updates: usize = arg("--updates").map(|v| v.parse()).transpose()?.unwrap_or(if smoke { 5 } else { 300 });
    let steps: u64 = arg("--steps").map(|v| v.parse()).transpose()?.unwrap_or(1000);
    anyhow::ensure!(steps.is_multiple_of(1000), "--steps must be a multiple of the 1000-step episode (0 skips it)");
    let ups = updates_per_second(algo, updates)?;
    let sps = if smoke || steps == 0 { f64::NAN } else { training_steps_per_second(algo, steps)? };
    println!(
        "{{\"library\": \"locobench\", \"algo\": \"{}\", \"threads\": {}, \"kernels\": \"{}\", \"updates_per_s\": {ups:.2}, \"train_steps_per_s\": {}}}",
        algo.name(),
        threads(),
        locobench::numeric::kernel_path::active(),
        if sps.is_finite() { format!("{sps:.2}") } else { "null".into() }
    );
    Ok(())
}
