//! Training throughput of one algorithm at HalfCheetah sizes, printed as one JSON line:
//! gradient updates/s (batch 256, one update after another) and environment steps/s while
//! training (one update per step, the real `locobench train` loop, after the warm-up).
//!
//! `cargo bench --bench throughput -- --roofline [--algo td3|sac] [--threads 1|2]` instead prints
//! the update's matmul GFLOP/s against the FP32 peak of the cores used (an FMA loop at the kernel
//! path's vector width, see `fma_peak_gflops`) and against gemm's 1024^3 rate, with the
//! core-to-core round trip before and after (`core_to_core_round_trip_ns`), and `-- --matmul` the GFLOP/s of every kernel path
//! (`numeric::kernel_path`) on the update's products. `LOCOBENCH_KERNELS` picks the path the
//! other modes run on; each JSON line names it.
//!
//! `cargo bench --bench throughput -- --algo td3 [--updates 300] [--steps 1000] [--threads 1|2]`;
//! used by `benches/sb3/compare.sh`, which alternates it with Stable-Baselines3 in one run.
//! Networks: TD3 and DDPG 400-300, SAC 256-256; candle on one thread, plus our helper thread
//! with `--threads 2`.
use std::time::Instant;

use anyhow::{Context, Result};
use locobench::agents::{make_learner, Algo, Batch, ReplayBuffer, TrainConfig};
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

/// The round trip of one cache line between two threads (this one and a new one, placed by the
/// OS as the helper thread is), in ns: the cost of every hand-off between the training thread and
/// its helper. On a VM it depends on where the host runs the two virtual CPUs; two-thread rates
/// are only comparable at similar round trips. Measured before and after the updates.
fn core_to_core_round_trip_ns() -> f64 {
    use std::sync::atomic::{AtomicU64, Ordering};
    #[repr(align(64))]
    struct Line(AtomicU64);
    const TRIPS: u64 = 200_000;
    let line = Line(AtomicU64::new(0));
    let started = std::thread::scope(|s| {
        s.spawn(|| {
            for i in 0..TRIPS {
                while line.0.load(Ordering::Acquire) != 2 * i + 1 {}
                line.0.store(2 * i + 2, Ordering::Release);
            }
        });
        let started = Instant::now();
        for i in 0..TRIPS {
            line.0.store(2 * i + 1, Ordering::Release);
            while line.0.load(Ordering::Acquire) != 2 * i + 2 {}
        }
        started
    });
    started.elapsed().as_secs_f64() / TRIPS as f64 * 1e9
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
    let mut agent = make_learner(&config(algo), OBS, ACT, &mut rng)?;
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

/// Matmul FLOPs of one update of an actor and twin critics at these sizes: the target actor and
/// two target critics forward; two critics forward and backward (weight gradients, and input
/// gradients past the first layer); and, `actor_steps` times per update, the actor step: actor
/// forward, `loss_critics` critics forward and their input gradients down to the action, actor
/// backward.
fn update_flops(actor: &[usize], critic: &[usize], loss_critics: f64, actor_steps: f64) -> f64 {
    let (a, c) = (mlp_flops(actor, BATCH, false), mlp_flops(critic, BATCH, false));
    let targets = a + 2.0 * c;
    let critic_step = 2.0 * (c + c + mlp_flops(critic, BATCH, true));
    let actor_step = a + loss_critics * (c + c) + a + mlp_flops(actor, BATCH, true);
    targets + critic_step + actor_steps * actor_step
}

/// TD3 400-300 (about 0.75 GFLOP): the actor step every second update, through critic 0.
fn td3_update_flops() -> f64 {
    update_flops(&[OBS, 400, 300, ACT], &[OBS + ACT, 400, 300, 1], 1.0, 0.5)
}

/// SAC 256-256 (about 0.58 GFLOP; the actor has mean and log-std heads): the actor step every
/// update, through the minimum of both critics.
fn sac_update_flops() -> f64 {
    update_flops(&[OBS, 256, 256, 2 * ACT], &[OBS + ACT, 256, 256, 1], 2.0, 1.0)
}

/// Single-thread f32 matmul rate of the gemm library candle uses, on a large square product:
/// a practical peak of one core, printed beside the FMA peak.
fn gemm_1024_gflops() -> Result<f64> {
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

/// The FP32 peak of one core at the vector width `path` computes with: a loop of independent
/// fused multiply-adds on registers, more chains than latency x FMA ports on current x86 cores,
/// so that nothing but the FMA units limits it; FLOPs = chains x lanes x 2 per iteration. The
/// library path is measured at the widest width the CPU has (gemm uses it); the portable path
/// is one scalar FMA per term, whose peak is not what limits it, so it gets the widest width too.
fn fma_peak_gflops(path: locobench::numeric::KernelPath) -> f64 {
    use locobench::numeric::KernelPath;
    let wide = if path == KernelPath::Avx2 { KernelPath::Avx2 } else { KernelPath::best_exact() };
    let (lanes, chains) = match wide {
        KernelPath::Avx512 => (16, fma_chains::CHAINS_512),
        KernelPath::Avx2 => (8, fma_chains::CHAINS_256),
        _ => return f64::NAN,
    };
    let iters = 10_000_000usize;
    let run = || {
        // SAFETY: `best_exact` and the Avx2 path (forced only where supported) have the features.
        unsafe {
            if wide == KernelPath::Avx512 {
                fma_chains::avx512(iters)
            } else {
                fma_chains::avx2(iters)
            }
        }
    };
    run();
    (0..3)
        .map(|_| {
            let started = Instant::now();
            run();
            (iters * chains * lanes * 2) as f64 / started.elapsed().as_secs_f64() / 1e9
        })
        .fold(0.0, f64::max)
}

/// Register-only FMA loops in assembly (a compiler may spill accumulators to the stack, which
/// would measure store forwarding instead of the FMA units): `CHAINS` independent
/// `acc += m * c` per iteration, accumulators zeroed first.
mod fma_chains {
    use std::arch::asm;

    /// `pub unsafe fn $name(iters)` and `pub const $chains`: one `vfmadd231ps acc, m, c` per
    /// accumulator register per iteration, `m` and `c` broadcast into their own registers.
    macro_rules! fma_loop {
        ($(#[$doc:meta])* $name:ident, $chains:ident, $feature:literal, $m:tt, $c:tt, [$($acc:tt),+]) => {
            /// Independent accumulators per iteration.
            pub const $chains: usize = [$($acc),+].len();

            $(#[$doc])*
            #[target_feature(enable = $feature)]
            pub unsafe fn $name(iters: usize) {
                let (m, c) = (std::hint::black_box(0.999_999f32), std::hint::black_box(1e-6f32));
                // SAFETY: registers only; the caller checked the features.
                unsafe {
                    asm!(
                        concat!("vbroadcastss ", $m, ", dword ptr [{m}]"),
                        concat!("vbroadcastss ", $c, ", dword ptr [{c}]"),
                        $(concat!("vxorps ", $acc, ", ", $acc, ", ", $acc),)+
                        "2:",
                        $(concat!("vfmadd231ps ", $acc, ", ", $m, ", ", $c),)+
                        "dec {n}",
                        "jnz 2b",
                        m = in(reg) &m,
                        c = in(reg) &c,
                        n = inout(reg) iters => _,
                        $(out($acc) _,)+ out($m) _, out($c) _,
                        options(nostack, readonly),
                    );
                }
            }
        };
    }

    fma_loop!(
        /// # Safety
        /// The CPU has AVX-512F.
        avx512, CHAINS_512, "avx512f", "zmm16", "zmm17",
        ["zmm0", "zmm1", "zmm2", "zmm3", "zmm4", "zmm5", "zmm6", "zmm7",
         "zmm8", "zmm9", "zmm10", "zmm11", "zmm12", "zmm13", "zmm14", "zmm15"]
    );

    // AVX2 has 16 registers: 14 accumulators and the two inputs.
    fma_loop!(
        /// # Safety
        /// The CPU has AVX2 and FMA.
        avx2, CHAINS_256, "avx2,fma", "ymm14", "ymm15",
        ["ymm0", "ymm1", "ymm2", "ymm3", "ymm4", "ymm5", "ymm6", "ymm7",
         "ymm8", "ymm9", "ymm10", "ymm11", "ymm12", "ymm13"]
    );
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
    let shapes: [Product; 10] = [
        ("TD3 forward 256x300x400 (x W^T)", (BATCH, 300, 400), false, true),
        ("TD3 weight grad 300x400x256 (g^T x)", (300, 400, BATCH), true, false),
        ("TD3 input grad 256x400x300 (g W)", (BATCH, 400, 300), false, false),
        ("TD3 forward 256x400x23 (x W^T)", (BATCH, 400, OBS + ACT), false, true),
        ("TD3 critic output 256x1x300 (x W^T)", (BATCH, 1, 300), false, true),
        ("SAC forward 256x256x256 (x W^T)", (BATCH, 256, 256), false, true),
        ("SAC weight grad 256x256x256 (g^T x)", (256, 256, BATCH), true, false),
        ("SAC input grad 256x256x256 (g W)", (BATCH, 256, 256), false, false),
        ("SAC action grad 256x23x256 (g W)", (BATCH, OBS + ACT, 256), false, false),
        ("SAC actor heads 256x12x256 (x W^T)", (BATCH, 2 * ACT, 256), false, true),
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

/// Nanoseconds per element of SAC's policy-head transcendentals on a batch's worth of inputs
/// (256 x 6): the system libm, one call per element (what `f32::exp` and the others do), against
/// `numeric::glibc_math` (the same bits) on each exact path this CPU supports. One thread.
fn libm_paths() -> Result<()> {
    use locobench::numeric::{glibc_math, KernelPath};
    type Function = (&'static str, fn(f32) -> f32, fn(KernelPath, &mut [f32]), fn(f32) -> f32);
    let functions: [Function; 3] = [
        ("exp, x in [-4, 0]", f32::exp, glibc_math::exp_in_place, |s| -4.0 * s.abs()),
        ("ln, x in [1, 2]", f32::ln, glibc_math::ln_in_place, |s| 1.0 + s.abs()),
        ("tanh, x in [-3, 3]", f32::tanh, glibc_math::tanh_in_place, |s| 3.0 * s),
    ];
    let paths: Vec<KernelPath> = KernelPath::ALL.into_iter().filter(|p| p.is_exact() && p.is_supported()).collect();
    println!("| function | system libm | {} |", paths.iter().map(|p| p.name()).collect::<Vec<_>>().join(" | "));
    println!("|---|---|{}", "---|".repeat(paths.len()));
    let reps = 2000;
    for (name, system, ours, input) in functions {
        let xs: Vec<f32> = (0..BATCH * ACT).map(|i| input((i as f32 * 0.37).sin())).collect();
        let mut buf = xs.clone();
        let mut time = |apply: &dyn Fn(&mut [f32])| {
            let started = Instant::now();
            for _ in 0..reps {
                buf.copy_from_slice(&xs);
                apply(&mut buf);
                std::hint::black_box(&mut buf);
            }
            started.elapsed().as_secs_f64() * 1e9 / (reps * xs.len()) as f64
        };
        let mut row = format!("| {name} | {:.2} |", time(&|b| b.iter_mut().for_each(|x| *x = system(*x))));
        for &path in &paths {
            row += &format!(" {:.2} |", time(&|b| ours(path, b)));
        }
        println!("{row}");
    }
    Ok(())
}

fn main() -> Result<()> {
    // candle's pools on one thread, as the CLI runs them (before any candle call)
    locobench::runtime::configure_process();
    if std::env::args().any(|a| a == "--matmul") {
        return matmul_paths();
    }
    if std::env::args().any(|a| a == "--libm") {
        return libm_paths();
    }
    if std::env::args().any(|a| a == "--roofline") {
        let algo = Algo::parse(&arg("--algo").unwrap_or_else(|| "td3".into()))?;
        let flops = match algo {
            Algo::Td3 => td3_update_flops(),
            Algo::Sac => sac_update_flops(),
            _ => anyhow::bail!("--roofline measures td3 or sac"),
        } / 1e9;
        let path = locobench::numeric::kernel_path::active();
        let (peak, gemm) = (fma_peak_gflops(path), gemm_1024_gflops()?);
        let round_trip_before = core_to_core_round_trip_ns();
        let ups = updates_per_second(algo, arg("--updates").map(|v| v.parse()).transpose()?.unwrap_or(300))?;
        let round_trip_after = core_to_core_round_trip_ns();
        let cores = threads() as f64;
        println!(
            "{{\"algo\": \"{}\", \"threads\": {}, \"kernels\": \"{path}\", \"fma_peak_gflops_per_core\": {peak:.1}, \"gemm_1024_gflops_one_core\": {gemm:.1}, \"gflop_per_update\": {flops:.3}, \"updates_per_s\": {ups:.1}, \"gflops\": {:.1}, \"fraction_of_fma_peak_of_cores_used\": {:.2}, \"fraction_of_gemm_rate_of_cores_used\": {:.2}, \"core_to_core_round_trip_ns\": [{round_trip_before:.0}, {round_trip_after:.0}]}}",
            algo.name(),
            threads(),
            ups * flops,
            ups * flops / (peak * cores),
            ups * flops / (gemm * cores)
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
