//! Stance-force QP solve time per control tick (the active-set method the controllers use,
//! clarabel with per-tick settings, clarabel's defaults): 4 stance feet in 3D (12 variables,
//! 24 inequality rows, as for Ant) and 2 feet without abduction (Minitaur). Goal: <= 50 us.
//! Then the whole controller tick on a live state, without the physics step.
//!
//! Run: `cargo bench --bench controller`.
use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use locobench::controller::baseline::{baseline_controller, baseline_env};
use locobench::controller::force_qp::{Dimension, ForceQp, QpMethod};
use locobench::controller::gait::GaitKind;
use locobench::envs::make;
use nalgebra::Vector3;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("controller");
    group.measurement_time(Duration::from_secs(5)).warm_up_time(Duration::from_secs(1));
    // Feet move a little from tick to tick, as in a gait.
    let configs: Vec<Vec<Vector3<f64>>> = (0..16)
        .map(|k| {
            let dx = 0.004 * k as f64;
            vec![
                Vector3::new(0.2 - dx, 0.1, -0.2),
                Vector3::new(-0.2 - dx, 0.1, -0.2),
                Vector3::new(0.2 + dx, -0.1, -0.21),
                Vector3::new(-0.2 + dx, -0.1, -0.19),
            ]
        })
        .collect();
    let wrench = [2.0, -1.0, 60.0, 0.5, -0.3, 0.1];
    let spatial = || ForceQp::new(Dimension::Spatial, 0.6, 1.0, 100.0, vec![1.0; 6], 1e-4);
    let mut qp = spatial();
    qp.method = QpMethod::Clarabel;
    let mut active = spatial();
    let mut k = 0;
    let mut precise = spatial();
    precise.method = QpMethod::ClarabelReference;
    group.bench_function("force QP 4 feet 3D, clarabel default settings (the reference)", |b| {
        b.iter(|| {
            k = (k + 1) % configs.len();
            black_box(precise.solve(&configs[k], &wrench).unwrap())
        })
    });
    group.bench_function("force QP 4 feet 3D (12 vars, 24 rows), active set, warm start", |b| {
        b.iter(|| {
            k = (k + 1) % configs.len();
            black_box(active.solve(&configs[k], &wrench).unwrap())
        })
    });
    group.bench_function("force QP 4 feet 3D, active set, cold start", |b| {
        b.iter(|| {
            k = (k + 1) % configs.len();
            black_box(spatial().solve(&configs[k], &wrench).unwrap())
        })
    });
    group.bench_function("force QP 4 feet 3D (12 vars, 24 rows), clarabel per-tick settings, reused solver", |b| {
        b.iter(|| {
            k = (k + 1) % configs.len();
            black_box(qp.solve(&configs[k], &wrench).unwrap())
        })
    });
    let mut planar = ForceQp::new(Dimension::Planar, 0.6, 1.0, 100.0, vec![1.0; 5], 1e-4);
    let pairs: Vec<Vec<Vector3<f64>>> =
        configs.iter().map(|c| vec![Vector3::new(c[0].x, 0.09, c[0].z), Vector3::new(c[3].x, -0.09, c[3].z)]).collect();
    group.bench_function("force QP 2 feet no abduction (4 vars, 8 rows), active set", |b| {
        b.iter(|| {
            k = (k + 1) % pairs.len();
            black_box(planar.solve(&pairs[k], &[1.0, 60.0, 0.1, 0.3, 0.05]).unwrap())
        })
    });

    // The whole controller tick (state estimate, gait, QP, kinematics), without the physics.
    // A control tick is 10 ms of robot time on Minitaur and 50 ms on Ant.
    for (env_name, gait, label) in
        [("minitaur", None, "minitaur"), ("ant", None, "ant (rowing)"), ("ant", Some(GaitKind::Trot), "ant (trot, QP)")]
    {
        let speed = if env_name == "ant" { 0.5 } else { 0.35 };
        let mut env = make(&baseline_env(env_name).unwrap()).unwrap();
        let mut controller = baseline_controller(env_name, speed, gait).unwrap();
        let (obs, _) = env.reset(Some(0)).unwrap();
        controller.begin_episode(0);
        for _ in 0..50 {
            let a = controller.act(env.as_ref(), &obs).unwrap();
            env.step(&a).unwrap();
        }
        group.bench_function(format!("{label} controller tick"), |b| {
            b.iter(|| black_box(controller.act(env.as_ref(), &obs).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
