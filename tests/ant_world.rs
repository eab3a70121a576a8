//! Ant's world perturbations (`envs::world`): each option changes the model or the step as it
//! says, nominal values change nothing, bad values are refused by name, and the protocol
//! evaluates in the nominal world.
use locobench::envs::{Ant, AntOptions, Env, EnvConfig};

fn ant(opts: AntOptions) -> Ant {
    Ant::new(opts).unwrap()
}

fn rollout(env: &mut Ant, actions: &[Vec<f64>], seed: u64) -> Vec<Vec<f64>> {
    env.reset(Some(seed)).unwrap();
    actions.iter().map(|a| env.step(a).unwrap().observation).collect()
}

fn actions(n: usize) -> Vec<Vec<f64>> {
    (0..n).map(|t| (0..8).map(|i| (0.3 * (t + i) as f64).sin()).collect()).collect()
}

#[test]
fn nominal_options_step_exactly_as_the_default_env() {
    let explicit = AntOptions {
        friction_scale: 1.0,
        payload_mass: 0.0,
        com_shift: 0.0,
        motor_strength: 1.0,
        latency: 0.0,
        slope: 0.0,
        ..Default::default()
    };
    let a = actions(30);
    assert_eq!(rollout(&mut ant(explicit), &a, 3), rollout(&mut ant(AntOptions::default()), &a, 3));
}

#[test]
fn payload_friction_motors_and_slope_edit_the_model() {
    let plain = ant(AntOptions::default());
    let m0 = plain.data().model();
    let torso = m0.body_id("torso").unwrap();
    let env = ant(AntOptions {
        payload_mass: 2.0,
        com_shift: 0.1,
        friction_scale: 0.1,
        motor_strength: 0.5,
        slope: 10.0,
        ..Default::default()
    });
    let m = env.data().model();
    assert!((m.body_mass()[torso] - m0.body_mass()[torso] - 2.0).abs() < 1e-12);
    assert!((m.body_ipos()[3 * torso] - m0.body_ipos()[3 * torso] - 0.1).abs() < 1e-12);
    assert!(m0.body_sameframe()[torso] && !m.body_sameframe()[torso]);
    for (f, f0) in m.geom_friction().chunks(3).zip(m0.geom_friction().chunks(3)) {
        assert!((f[0] - 0.1 * f0[0]).abs() < 1e-12 && f[1] == f0[1]);
    }
    for (g, g0) in m.actuator_gear().chunks(6).zip(m0.actuator_gear().chunks(6)) {
        assert_eq!(g[0], 0.5 * g0[0]);
    }
    // 10 degrees up along +x: gravity tilted back, its size unchanged.
    let (g, g0) = (m.gravity(), m0.gravity());
    assert!((g[0] - g0[2] * 10f64.to_radians().sin()).abs() < 1e-12 && g[0] < 0.0);
    assert!(((g[0] * g[0] + g[2] * g[2]).sqrt() - g0[2].abs()).abs() < 1e-12);
}

#[test]
fn weaker_motors_give_proportionally_less_torque() {
    // One physics step per control step, from the same state: the joint torques the actuators
    // apply (qfrc_actuator: gear times control) scale with the gear.
    let a = vec![0.7; 8];
    let mut weak = ant(AntOptions { motor_strength: 0.25, frame_skip: 1, ..Default::default() });
    let mut full = ant(AntOptions { frame_skip: 1, ..Default::default() });
    full.reset(Some(1)).unwrap();
    weak.reset(Some(1)).unwrap();
    full.step(&a).unwrap();
    weak.step(&a).unwrap();
    let (w, f) = (weak.data().qfrc_actuator(), full.data().qfrc_actuator());
    assert!(f[6..].iter().all(|t| t.abs() > 1.0), "{f:?}");
    for (w, f) in w.iter().zip(f) {
        assert!((w - 0.25 * f).abs() < 1e-9 * f.abs().max(1.0), "{w} vs {f}");
    }
}

#[test]
fn latency_delays_each_action_by_whole_physics_steps() {
    // One control step is 5 physics steps of 0.01 s. With 0.05 s of latency every action acts
    // one control step late, and until the first arrives the motors get nothing: the delayed env
    // playing a, b, c, ... moves exactly as the plain env playing 0, a, b, ...
    let a = actions(20);
    let mut shifted = vec![vec![0.0; 8]];
    shifted.extend(a[..19].iter().cloned());
    let delayed = rollout(&mut ant(AntOptions { latency: 0.05, ..Default::default() }), &a, 5);
    let plain = rollout(&mut ant(AntOptions::default()), &shifted, 5);
    assert_eq!(delayed, plain);
    // Two physics steps late (0.02 s) is neither of those.
    let partial = rollout(&mut ant(AntOptions { latency: 0.02, ..Default::default() }), &a, 5);
    assert_ne!(partial, plain);
    assert_ne!(partial, rollout(&mut ant(AntOptions::default()), &a, 5));
    // The same seed gives the same episode.
    assert_eq!(partial, rollout(&mut ant(AntOptions { latency: 0.02, ..Default::default() }), &a, 5));
}

#[test]
fn a_payload_and_a_slope_change_the_motion() {
    let a = actions(40);
    let plain = rollout(&mut ant(AntOptions::default()), &a, 2);
    let heavy = rollout(&mut ant(AntOptions { payload_mass: 4.0, ..Default::default() }), &a, 2);
    // Heavier torso sits lower (observation 0 is the torso height).
    let mean_z = |o: &[Vec<f64>]| o.iter().map(|v| v[0]).sum::<f64>() / o.len() as f64;
    assert!(mean_z(&heavy) < mean_z(&plain), "{} vs {}", mean_z(&heavy), mean_z(&plain));
    // A centre of mass moved forward changes the motion (MuJoCo ignores body_ipos for a body
    // compiled with its inertial frame on its own frame, unless that flag is cleared).
    let shifted = rollout(&mut ant(AntOptions { com_shift: 0.2, ..Default::default() }), &a, 2);
    assert_ne!(shifted, plain);
    // Standing still on a steep slope down along +x, the ant slides forward.
    let mut env = ant(AntOptions { slope: -25.0, friction_scale: 0.2, ..Default::default() });
    env.reset(Some(0)).unwrap();
    let x0 = env.data().qpos()[0];
    for _ in 0..40 {
        env.step(&[0.0; 8]).unwrap();
    }
    assert!(env.data().qpos()[0] - x0 > 0.1, "slid {}", env.data().qpos()[0] - x0);
}

#[test]
fn out_of_range_world_options_name_the_option() {
    for (key, value) in [
        ("payload_mass", "-1"),
        ("friction_scale", "-0.5"),
        ("motor_strength", "3"),
        ("latency", "0.9"),
        ("slope", "45"),
        ("com_shift", "0.5"),
    ] {
        let cfg = EnvConfig::new("ant").with_overrides(&[(key.into(), value.into())]).unwrap();
        let err = locobench::envs::make(&cfg).err().expect("refused").to_string();
        assert!(err.contains(key), "{key}={value}: {err}");
    }
}

#[test]
fn the_protocol_evaluates_ant_in_the_nominal_world() {
    let trained = EnvConfig::new("ant")
        .with_overrides(&[("payload_mass".into(), "1".into()), ("ctrl_cost_weight".into(), "0.1".into())])
        .unwrap();
    let eval = trained.for_evaluation();
    assert!(!eval.options.contains_key("payload_mass"));
    assert_eq!(eval.options.get("ctrl_cost_weight"), trained.options.get("ctrl_cost_weight"));
}
