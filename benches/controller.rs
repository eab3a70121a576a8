//! Stance-force QP solve time (clarabel), per control tick: 4 stance feet in 3D (12 variables,
//! 24 inequality rows, as for Ant) and 2 feet without abduction (Minitaur). Goal: <= 50 us.
//! Then the whole controller tick on a live state, without the physics step.
//!
//! Run: `cargo bench --bench controller`.
use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion};
use locobench::controller::baseline::{baseline_controller, baseline_env};
use locobench::controller::force_qp::{Dimension, ForceQp};
use locobench::envs::make;
use nalgebra::Vector3;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("controller");
    group.measurement_time(Duration::from_secs(5)).warm_up_time(Duration::from_secs(1));
    let spatial = ForceQp {
        dimension: Dimension::Spatial,
        friction: 0.6,
        f_min: 1.0,
        f_max: 100.0,
        wrench_weights: vec![1.0; 6],
        regularisation: 1e-4,
    };
    let feet = [
        Vector3::new(0.2, 0.1, -0.2),
        Vector3::new(-0.2, 0.1, -0.2),
        Vector3::new(0.2, -0.1, -0.2),
        Vector3::new(-0.2, -0.1, -0.2),
    ];
    let wrench = [2.0, -1.0, 60.0, 0.5, -0.3, 0.1];
    group.bench_function("force QP 4 feet 3D (12 vars, 24 rows)", |b| {
        b.iter(|| black_box(spatial.solve(&feet, &wrench).unwrap()))
    });
    let planar = ForceQp { dimension: Dimension::Planar, wrench_weights: vec![1.0; 4], ..spatial };
    let feet2 = [Vector3::new(0.21, 0.09, -0.2), Vector3::new(-0.21, -0.09, -0.2)];
    group.bench_function("force QP 2 feet no abduction (4 vars, 8 rows)", |b| {
        b.iter(|| black_box(planar.solve(&feet2, &[1.0, 60.0, 0.1, 0.3]).unwrap()))
    });

    // The whole controller tick (state estimate, gait, QP, kinematics), without the physics.
    // A control tick is 10 ms of robot time on Minitaur and 50 ms on Ant.
    for (env_name, speed) in [("minitaur", 0.35), ("ant", 0.5)] {
        let mut env = make(&baseline_env(env_name).unwrap()).unwrap();
        let mut controller = baseline_controller(env_name, speed, None).unwrap();
        let (obs, _) = env.reset(Some(0)).unwrap();
        controller.begin_episode(0);
        for _ in 0..50 {
            let a = controller.act(env.as_ref(), &obs).unwrap();
            env.step(&a).unwrap();
        }
        group.bench_function(format!("{env_name} controller tick"), |b| {
            b.iter(|| black_box(controller.act(env.as_ref(), &obs).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
