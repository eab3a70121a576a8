//! Environment steps per second next to bare `mj_step` x frame_skip on the same model, in the
//! same run. The difference is what the safe layer and the environment logic cost.
//!
//! The `vec_env` group steps a vector environment of `COPIES` copies on one thread and on two,
//! counting env steps, to set beside `env.step` (the ideal on two threads is twice its rate).
//!
//! Run: `cargo bench --bench env_step`. Environments run with termination off (where they have
//! it) and a long time limit so that both sides mostly just step; InvertedPendulum's pole still
//! falls under random actions, so its env figure includes the resets.
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use locobench::envs::{make, model_xml, EnvConfig, VecEnv};
use locobench::mujoco::{sys, Data, Model};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

struct Case {
    name: &'static str,
    frame_skip: usize,
    /// The env's definition needs `cfrc_ext`, so it calls mj_rnePostConstraint after stepping.
    contact_forces: bool,
    options: &'static [(&'static str, &'static str)],
}

const CASES: [Case; 7] = [
    Case { name: "half-cheetah", frame_skip: 5, contact_forces: false, options: &[] },
    Case { name: "ant", frame_skip: 5, contact_forces: true, options: &[("terminate_when_unhealthy", "false")] },
    Case { name: "humanoid", frame_skip: 5, contact_forces: true, options: &[("terminate_when_unhealthy", "false")] },
    Case { name: "inverted-pendulum", frame_skip: 2, contact_forces: false, options: &[("max_pole_angle", "1.5707")] },
    Case { name: "walker2d", frame_skip: 4, contact_forces: false, options: &[("terminate_when_unhealthy", "false")] },
    Case { name: "hopper", frame_skip: 4, contact_forces: false, options: &[("terminate_when_unhealthy", "false")] },
    Case {
        name: "minitaur",
        frame_skip: 5,
        contact_forces: false,
        options: &[("fall_height", "0"), ("fall_up_threshold", "-1"), ("randomize_dynamics", "false")],
    },
];

fn actions(dim: usize, low: f64, high: f64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    (0..256).map(|_| (0..dim).map(|_| rng.random_range(low..high)).collect()).collect()
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("env_step");
    group.throughput(Throughput::Elements(1));
    group.measurement_time(Duration::from_secs(4)).warm_up_time(Duration::from_secs(1)).sample_size(30);
    for case in &CASES {
        let mut pairs: Vec<(String, String)> =
            case.options.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        pairs.push(("max_episode_steps".into(), "100000000".into()));
        let cfg = EnvConfig::new(case.name).with_overrides(&pairs).unwrap();
        let mut env = make(&cfg).unwrap();
        let space = env.spec().action_space.clone();
        let acts = actions(space.dim(), space.low[0], space.high[0]);
        env.reset(Some(0)).unwrap();
        let mut i = 0;
        group.bench_function(format!("{}/env.step", case.name), |b| {
            b.iter(|| {
                i = (i + 1) % acts.len();
                let s = env.step(&acts[i]).unwrap();
                if s.done() {
                    env.reset(None).unwrap();
                }
                black_box(s);
            })
        });

        // Bare MuJoCo: copy ctrl, then mj_step frame_skip times, nothing else.
        let model = Arc::new(Model::from_xml_str(model_xml(case.name).unwrap()).unwrap());
        let mut data = Data::new(&model).unwrap();
        let (m, d) = (model.as_raw(), data.as_raw_mut());
        let nu = model.nu();
        let ctrl_acts = if case.name == "minitaur" { actions(nu, -3.5, 3.5) } else { acts.clone() };
        let mut j = 0;
        group.bench_function(format!("{}/raw mj_step x{}", case.name, case.frame_skip), |b| {
            b.iter(|| unsafe {
                j = (j + 1) % ctrl_acts.len();
                std::ptr::copy_nonoverlapping(ctrl_acts[j].as_ptr(), (*d).ctrl, nu);
                for _ in 0..case.frame_skip {
                    sys::mj_step(m, d);
                }
                black_box((*d).time);
            })
        });
        if case.contact_forces {
            group.bench_function(format!("{}/raw mj_step x{} + rnePostConstraint", case.name, case.frame_skip), |b| {
                b.iter(|| unsafe {
                    j = (j + 1) % ctrl_acts.len();
                    std::ptr::copy_nonoverlapping(ctrl_acts[j].as_ptr(), (*d).ctrl, nu);
                    for _ in 0..case.frame_skip {
                        sys::mj_step(m, d);
                    }
                    sys::mj_rnePostConstraint(m, d);
                    black_box((*d).time);
                })
            });
        }
    }
    group.finish();
}

/// Copies in the vector environment benchmark: enough that each thread's block of copies takes far
/// longer than handing it to a thread.
const COPIES: usize = 16;

fn bench_vector(c: &mut Criterion) {
    let mut group = c.benchmark_group("vec_env");
    group.throughput(Throughput::Elements(COPIES as u64));
    group.measurement_time(Duration::from_secs(4)).warm_up_time(Duration::from_secs(1)).sample_size(20);
    for case in CASES.iter().filter(|c| ["half-cheetah", "hopper", "ant"].contains(&c.name)) {
        let mut pairs: Vec<(String, String)> =
            case.options.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        pairs.push(("max_episode_steps".into(), "100000000".into()));
        let cfg = EnvConfig::new(case.name).with_overrides(&pairs).unwrap();
        for threads in [1, 2] {
            // As training runs it: two threads means the runtime's helper thread.
            let _runtime = locobench::runtime::Runtime::enter(threads);
            let mut env = VecEnv::new(&cfg, COPIES, threads).unwrap();
            let space = env.spec().action_space.clone();
            let acts = actions(space.dim(), space.low[0], space.high[0]);
            env.reset(0).unwrap();
            let mut i = 0;
            group.bench_function(format!("{}/{COPIES} copies, {threads} thread(s)", case.name), |b| {
                b.iter(|| {
                    i = (i + 1) % acts.len();
                    let batch: Vec<Vec<f64>> = (0..COPIES).map(|k| acts[(i + k) % acts.len()].clone()).collect();
                    black_box(env.step(&batch).unwrap());
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench, bench_vector);
criterion_main!(benches);
