//! Gymnasium semantics of the standard environments: sizes, reward terms recomputed by hand,
//! health and termination, reset noise, determinism, bad input.
use locobench::envs::Ant;
use locobench::envs::{
    make, AntOptions, Env, EnvConfig, EnvError, HalfCheetah, HalfCheetahOptions, Hopper, HopperOptions, Humanoid,
    HumanoidOptions, InvertedPendulum, InvertedPendulumOptions, Walker2d, Walker2dOptions,
};
use locobench::mujoco::{Data, Model};

fn wiggle(t: usize, n: usize, scale: f64) -> Vec<f64> {
    (0..n).map(|i| scale * ((t * 7 + i * 3) as f64 * 0.37).sin()).collect()
}

#[test]
fn spaces_and_dt_match_gymnasium_v5() {
    let expect = [
        ("half-cheetah", 17, 6, 0.05, 1.0),
        ("ant", 105, 8, 0.05, 1.0),
        ("humanoid", 348, 17, 0.015, 0.4),
        ("inverted-pendulum", 4, 1, 0.04, 3.0),
        ("walker2d", 17, 6, 0.008, 1.0),
        ("hopper", 11, 3, 0.008, 1.0),
        ("minitaur", 28, 8, 0.01, 1.0),
    ];
    for (name, obs, act, dt, high) in expect {
        let mut env = make(&EnvConfig::new(name)).unwrap();
        let spec = env.spec().clone();
        assert_eq!(spec.observation_space.dim(), obs, "{name}");
        assert_eq!(spec.action_space.dim(), act, "{name}");
        assert!((spec.dt - dt).abs() < 1e-12, "{name} dt {}", spec.dt);
        assert_eq!(spec.max_episode_steps, 1000);
        assert!(spec.action_space.high.iter().all(|&h| h == high), "{name}");
        let (o, _) = env.reset(Some(0)).unwrap();
        assert_eq!(o.len(), obs);
        let s = env.step(&vec![0.0; act]).unwrap();
        assert_eq!(s.observation.len(), obs);
        let names: Vec<_> = s.info.reward_terms.iter().map(|(n, _)| *n).collect();
        assert_eq!(names, spec.reward_terms, "{name}");
    }
}

#[test]
fn half_cheetah_reward_by_hand_and_observation_layout() {
    let mut env = HalfCheetah::new(HalfCheetahOptions::default()).unwrap();
    env.reset(Some(4)).unwrap();
    for t in 0..20 {
        let x0 = env.data().qpos()[0];
        let a = wiggle(t, 6, 0.9);
        let s = env.step(&a).unwrap();
        let d = env.data();
        let forward = (d.qpos()[0] - x0) / 0.05;
        let ctrl = 0.1 * a.iter().map(|v| v * v).sum::<f64>();
        assert!((s.info.term("forward").unwrap() - forward).abs() < 1e-12);
        assert!((s.info.term("ctrl_cost").unwrap() + ctrl).abs() < 1e-12);
        assert!((s.reward - (forward - ctrl)).abs() < 1e-12);
        assert_eq!(&s.observation[..8], &d.qpos()[1..]);
        assert_eq!(&s.observation[8..], d.qvel());
        assert!(!s.terminated);
    }
}

#[test]
fn ant_reward_by_hand_and_contact_observation() {
    let mut env = Ant::new(AntOptions::default()).unwrap();
    env.reset(Some(2)).unwrap();
    let mut saw_contact = false;
    for t in 0..40 {
        let torso = env.data().model().body_id("torso").unwrap();
        let x0 = env.data().xpos()[3 * torso];
        let a = wiggle(t, 8, 0.8);
        let s = env.step(&a).unwrap();
        let d = env.data();
        let forward = (d.xpos()[3 * torso] - x0) / 0.05;
        let z = d.qpos()[2];
        let healthy = if (0.2..=1.0).contains(&z) { 1.0 } else { 0.0 };
        let ctrl = 0.5 * a.iter().map(|v| v * v).sum::<f64>();
        let contact = 5e-4 * d.cfrc_ext().iter().map(|f| f.clamp(-1.0, 1.0).powi(2)).sum::<f64>();
        saw_contact |= contact > 0.0;
        assert!((s.info.term("forward").unwrap() - forward).abs() < 1e-12);
        assert_eq!(s.info.term("healthy").unwrap(), healthy);
        assert!((s.info.term("ctrl_cost").unwrap() + ctrl).abs() < 1e-12);
        assert!((s.info.term("contact_cost").unwrap() + contact).abs() < 1e-15);
        assert!((s.reward - (forward + healthy - ctrl - contact)).abs() < 1e-12);
        assert_eq!(&s.observation[..13], &d.qpos()[2..]);
        assert_eq!(&s.observation[13..27], d.qvel());
        for (o, f) in s.observation[27..].iter().zip(&d.cfrc_ext()[6..]) {
            assert_eq!(*o, f.clamp(-1.0, 1.0));
        }
    }
    assert!(saw_contact);
}

#[test]
fn humanoid_reward_by_hand() {
    let mut env = Humanoid::new(HumanoidOptions::default()).unwrap();
    env.reset(Some(5)).unwrap();
    let com_x = |d: &Data| {
        let m = d.model();
        let total: f64 = m.body_mass().iter().sum();
        m.body_mass().iter().enumerate().map(|(b, mass)| mass * d.xipos()[3 * b]).sum::<f64>() / total
    };
    for t in 0..30 {
        let x0 = com_x(env.data());
        let a = wiggle(t, 17, 0.6); // partly outside [-0.4, 0.4]: clipped
        let s = env.step(&a).unwrap();
        let d = env.data();
        let forward = 1.25 * (com_x(d) - x0) / 0.015;
        let z = d.qpos()[2];
        let healthy = if z > 1.0 && z < 2.0 { 5.0 } else { 0.0 };
        let ctrl = 0.1 * d.ctrl().iter().map(|v| v * v).sum::<f64>();
        let contact = (5e-7 * d.cfrc_ext().iter().map(|f| f * f).sum::<f64>()).min(10.0);
        assert!((s.info.term("forward").unwrap() - forward).abs() < 1e-9);
        assert_eq!(s.info.term("healthy").unwrap(), healthy);
        assert!((s.info.term("ctrl_cost").unwrap() + ctrl).abs() < 1e-12);
        assert!((s.info.term("contact_cost").unwrap() + contact).abs() < 1e-12);
        assert!(d.ctrl().iter().all(|c| c.abs() <= 0.4));
        assert!(s.info.clipped_actions > 0);
        assert_eq!(s.terminated, healthy == 0.0);
        assert_eq!(&s.observation[45..175], &d.cinert()[10..]);
        assert_eq!(&s.observation[253..270], &d.qfrc_actuator()[6..]);
        if s.done() {
            break;
        }
    }
}

#[test]
fn humanoid_observation_parts_can_be_left_out_as_in_gymnasium_v5() {
    let full = |o: HumanoidOptions| {
        let mut env = Humanoid::new(o).unwrap();
        let (obs, _) = env.reset(Some(1)).unwrap();
        let s = env.step(&[0.1; 17]).unwrap();
        assert_eq!(obs.len(), env.spec().observation_space.dim());
        (s.observation, s.reward)
    };
    let (all, reward) = full(HumanoidOptions::default());
    let (no_contact, reward_no_contact) =
        full(HumanoidOptions { include_cfrc_ext_in_observation: false, ..Default::default() });
    assert_eq!((all.len(), no_contact.len()), (348, 270));
    assert_eq!(&all[..270], &no_contact[..], "the same state, its contact forces left out");
    assert_eq!(reward, reward_no_contact, "the contact cost still counts");
    let (bare, _) = full(HumanoidOptions {
        include_cinert_in_observation: false,
        include_cvel_in_observation: false,
        include_qfrc_actuator_in_observation: false,
        include_cfrc_ext_in_observation: false,
        ..Default::default()
    });
    assert_eq!(&bare[..], &all[..45]);
}

#[test]
fn humanoid_falls_and_terminates_under_zero_action() {
    let mut env = Humanoid::new(HumanoidOptions::default()).unwrap();
    env.reset(Some(0)).unwrap();
    let mut steps = 0;
    loop {
        let s = env.step(&[0.0; 17]).unwrap();
        steps += 1;
        if s.terminated {
            assert!(env.data().qpos()[2] <= 1.0);
            assert_eq!(s.info.term("healthy").unwrap(), 0.0);
            break;
        }
        assert!(steps < 1000, "a limp humanoid must fall");
    }
    // Without termination the same fall keeps going, unrewarded.
    let mut env = Humanoid::new(HumanoidOptions { terminate_when_unhealthy: false, ..Default::default() }).unwrap();
    env.reset(Some(0)).unwrap();
    for _ in 0..steps + 5 {
        let s = env.step(&[0.0; 17]).unwrap();
        assert!(!s.terminated);
    }
}

/// Hopper and Walker2d: forward + healthy - 1e-3 |a|^2 recomputed from the state, the
/// observation qpos[1:] + clip(qvel, ±10), and termination exactly when the health rule fails.
#[test]
fn planar_walkers_reward_by_hand_health_and_clipped_velocities() {
    type Healthy = fn(&[f64], &[f64]) -> bool;
    let hopper_healthy: Healthy =
        |q, v| q[2..].iter().chain(v).all(|x| x.abs() < 100.0) && q[1] > 0.7 && q[2].abs() < 0.2;
    let walker_healthy: Healthy = |q, _| q[1] > 0.8 && q[1] < 2.0 && q[2].abs() < 1.0;
    let envs: [(Box<dyn Env>, Healthy); 2] = [
        (Box::new(Hopper::new(HopperOptions::default()).unwrap()), hopper_healthy),
        (Box::new(Walker2d::new(Walker2dOptions::default()).unwrap()), walker_healthy),
    ];
    for (mut env, healthy_rule) in envs {
        let name = env.spec().name;
        let n = env.spec().action_space.dim();
        env.reset(Some(3)).unwrap();
        let mut terminated = false;
        for t in 0..1000 {
            let x0 = env.data().qpos()[0];
            let a = wiggle(t, n, 1.0);
            let s = env.step(&a).unwrap();
            let d = env.data();
            let forward = (d.qpos()[0] - x0) / 0.008;
            let healthy = healthy_rule(d.qpos(), d.qvel());
            let ctrl = 1e-3 * a.iter().map(|v| v * v).sum::<f64>();
            assert!((s.info.term("forward").unwrap() - forward).abs() < 1e-9, "{name} step {t}");
            assert_eq!(s.info.term("healthy").unwrap(), if healthy { 1.0 } else { 0.0 }, "{name}");
            assert!((s.info.term("ctrl_cost").unwrap() + ctrl).abs() < 1e-15, "{name}");
            assert!((s.reward - (forward + f64::from(u8::from(healthy)) - ctrl)).abs() < 1e-9, "{name}");
            let nq = d.qpos().len();
            assert_eq!(&s.observation[..nq - 1], &d.qpos()[1..], "{name}");
            for (o, v) in s.observation[nq - 1..].iter().zip(d.qvel()) {
                assert_eq!(*o, v.clamp(-10.0, 10.0));
            }
            assert_eq!(s.terminated, !healthy, "{name} step {t}");
            if s.done() {
                terminated = s.terminated;
                break;
            }
        }
        assert!(terminated, "{name}: full-scale wiggling must make it fall");
        // Thrown forward at 50 m/s: the observation reads 10, the reward the true speed.
        env.reset(Some(3)).unwrap();
        let mut qvel = vec![0.0; env.data().qvel().len()];
        qvel[0] = 50.0;
        let qpos = env.data().qpos().to_vec();
        env.set_state(&qpos, &qvel).unwrap();
        let s = env.step(&vec![0.0; n]).unwrap();
        let nq = env.data().qpos().len();
        assert!(env.data().qvel()[0] > 40.0, "{name}");
        assert_eq!(s.observation[nq - 1], 10.0, "{name}");
        assert!(s.info.term("forward").unwrap() > 40.0, "{name}");
    }
}

#[test]
fn planar_walker_health_ranges_are_options() {
    // Standing still is healthy; a height range above the standing height is not.
    let mut env = Walker2d::new(Walker2dOptions::default()).unwrap();
    env.reset(Some(0)).unwrap();
    assert!(!env.step(&[0.0; 6]).unwrap().terminated);
    let mut env = Walker2d::new(Walker2dOptions { healthy_z_range: [1.3, 2.0], ..Default::default() }).unwrap();
    env.reset(Some(0)).unwrap();
    assert!(env.step(&[0.0; 6]).unwrap().terminated);
    let mut env = Hopper::new(HopperOptions { healthy_angle_range: [0.1, 0.2], ..Default::default() }).unwrap();
    env.reset(Some(0)).unwrap();
    assert!(env.step(&[0.0; 3]).unwrap().terminated);
    for bad in ["healthy_z_range=[1.0,0.5]", "frame_skip=0", "ctrl_cost_weight=-1", "healthy_state_range=3"] {
        for env in ["hopper", "walker2d"] {
            let cfg = EnvConfig::new(env).with_overrides(&locobench::envs::parse_overrides(bad).unwrap()).unwrap();
            if env == "walker2d" && bad.starts_with("healthy_state") {
                assert!(make(&cfg).is_err(), "walker2d has no healthy_state_range");
                continue;
            }
            assert!(matches!(make(&cfg).err(), Some(EnvError::InvalidOption { .. })), "{env} {bad}");
        }
    }
}

#[test]
fn ant_healthy_range_controls_termination() {
    // The ant rests around 0.55-0.75 m: a healthy range above that terminates on the first step.
    let mut env = Ant::new(AntOptions { healthy_z_range: [0.9, 2.0], ..Default::default() }).unwrap();
    env.reset(Some(0)).unwrap();
    let s = env.step(&[0.0; 8]).unwrap();
    assert!(s.terminated && !s.truncated);
    assert_eq!(s.info.term("healthy").unwrap(), 0.0);
    let mut env =
        Ant::new(AntOptions { healthy_z_range: [0.9, 2.0], terminate_when_unhealthy: false, ..Default::default() })
            .unwrap();
    env.reset(Some(0)).unwrap();
    assert!(!env.step(&[0.0; 8]).unwrap().terminated);
}

#[test]
fn inverted_pendulum_terminates_past_0_2_rad() {
    let mut env = InvertedPendulum::new(InvertedPendulumOptions::default()).unwrap();
    env.reset(Some(0)).unwrap();
    let mut n = 0;
    loop {
        let s = env.step(&[3.0]).unwrap();
        n += 1;
        if s.terminated {
            assert!(s.observation[1].abs() > 0.2);
            assert_eq!(s.reward, 0.0);
            break;
        }
        assert!(s.observation[1].abs() <= 0.2);
        assert_eq!(s.reward, 1.0);
    }
    assert!(n < 100);
}

#[test]
fn time_limit_truncates() {
    let mut env =
        make(&EnvConfig::new("half-cheetah").with_overrides(&[("max_episode_steps".into(), "7".into())]).unwrap())
            .unwrap();
    env.reset(Some(0)).unwrap();
    for t in 1..=7 {
        let s = env.step(&[0.0; 6]).unwrap();
        assert_eq!(s.truncated, t == 7);
    }
    assert!(matches!(env.step(&[0.0; 6]), Err(EnvError::EpisodeOver)));
    env.reset(None).unwrap();
    assert!(env.step(&[0.0; 6]).is_ok());
}

#[test]
fn reset_noise_has_the_documented_distribution() {
    let m = Model::from_xml_str(locobench::envs::model_xml("half-cheetah").unwrap()).unwrap();
    let qpos0 = m.qpos0().to_vec();
    let mut env = HalfCheetah::new(HalfCheetahOptions::default()).unwrap();
    let mut max_pos: f64 = 0.0;
    let mut vel_sq = 0.0;
    let mut n = 0.0;
    for seed in 0..200 {
        env.reset(Some(seed)).unwrap();
        let d = env.data();
        for (q, q0) in d.qpos().iter().zip(&qpos0) {
            max_pos = max_pos.max((q - q0).abs());
        }
        for v in d.qvel() {
            vel_sq += v * v;
            n += 1.0;
        }
    }
    assert!(max_pos <= 0.1 && max_pos > 0.09, "uniform noise bound {max_pos}");
    let std = (vel_sq / n).sqrt();
    assert!((std - 0.1).abs() < 0.01, "velocity noise std {std}");
    // Humanoid: uniform on both, scale 0.01.
    let mut env = Humanoid::new(HumanoidOptions::default()).unwrap();
    for seed in 0..50 {
        env.reset(Some(seed)).unwrap();
        assert!(env.data().qvel().iter().all(|v| v.abs() <= 0.01));
    }
    // Zero noise gives exactly the initial state.
    let mut env = HalfCheetah::new(HalfCheetahOptions { reset_noise_scale: 0.0, ..Default::default() }).unwrap();
    env.reset(Some(9)).unwrap();
    assert_eq!(env.data().qpos(), &qpos0[..]);
    assert!(env.data().qvel().iter().all(|&v| v == 0.0));
}

fn trajectory(name: &str, seed: u64, steps: usize) -> Vec<u64> {
    let mut env = make(&EnvConfig::new(name)).unwrap();
    let dim = env.spec().action_space.dim();
    let (obs, _) = env.reset(Some(seed)).unwrap();
    let mut bits: Vec<u64> = obs.iter().map(|v| v.to_bits()).collect();
    for t in 0..steps {
        let s = env.step(&wiggle(t, dim, 0.5)).unwrap();
        bits.extend(s.observation.iter().map(|v| v.to_bits()));
        bits.push(s.reward.to_bits());
        if s.done() {
            break;
        }
    }
    bits
}

#[test]
fn same_seed_gives_bit_identical_trajectories() {
    for name in locobench::envs::env_names() {
        let a = trajectory(name, 11, 60);
        assert_eq!(a, trajectory(name, 11, 60), "{name}");
        assert_ne!(a, trajectory(name, 12, 60), "{name}: different seeds should differ");
    }
}

#[test]
fn reset_without_seed_continues_the_stream() {
    let mut env = make(&EnvConfig::new("ant")).unwrap();
    let (a, _) = env.reset(Some(1)).unwrap();
    let (b, _) = env.reset(None).unwrap();
    assert_ne!(a, b);
    let (c, _) = env.reset(Some(1)).unwrap();
    assert_eq!(a, c);
}

#[test]
fn bad_actions_are_clear_errors() {
    let mut env = make(&EnvConfig::new("half-cheetah")).unwrap();
    assert!(matches!(env.step(&[0.0; 6]), Err(EnvError::NotReset)));
    env.reset(Some(0)).unwrap();
    let e = env.step(&[0.0; 5]).unwrap_err();
    assert!(matches!(e, EnvError::ActionLength { expected: 6, got: 5 }));
    assert!(e.to_string().contains("expects 6"));
    let e = env.step(&[0.0, f64::NAN, 0.0, 0.0, 0.0, 0.0]).unwrap_err();
    assert!(matches!(e, EnvError::NonFiniteAction { index: 1, .. }), "{e}");
    let e = env.step(&[0.0, 0.0, 0.0, f64::INFINITY, 0.0, 0.0]).unwrap_err();
    assert!(matches!(e, EnvError::NonFiniteAction { index: 3, .. }));
    // Nothing was lost: the episode continues.
    let s = env.step(&[2.0, -3.0, 0.0, 0.0, 0.0, 0.5]).unwrap();
    assert_eq!(s.info.clipped_actions, 2);
    assert_eq!(env.data().ctrl(), &[1.0, -1.0, 0.0, 0.0, 0.0, 0.5]);
}

#[test]
fn unknown_env_and_invalid_options_are_clear_errors() {
    let e = make(&EnvConfig::new("hoper")).err().unwrap();
    assert!(e.to_string().contains("unknown environment 'hoper'") && e.to_string().contains("half-cheetah"));
    let bad = |name: &str, key: &str, value: &str| {
        let cfg = EnvConfig::new(name).with_overrides(&[(key.into(), value.into())]).unwrap();
        make(&cfg).err().map(|e| e.to_string()).unwrap_or_default()
    };
    assert!(bad("ant", "ctrl_cost_weight", "-1").contains("ctrl_cost_weight"));
    assert!(bad("ant", "healthy_z_range", "[1.0, 0.2]").contains("healthy_z_range"));
    assert!(bad("ant", "reset_noise_scale", "nan").contains("reset_noise_scale"));
    assert!(bad("ant", "no_such_option", "1").contains("no_such_option"));
    assert!(bad("minitaur", "action_mode", "teleport").contains("action_mode"));
    assert!(bad("minitaur", "max_episode_steps", "0").contains("max_episode_steps"));
    assert!(bad("half-cheetah", "frame_skip", "\"five\"").contains("frame_skip"));
}

#[test]
fn options_round_trip_through_toml() {
    let cfg = EnvConfig::from_toml(
        r#"
        name = "minitaur"
        [options]
        drift_weight = 0.25
        shake_weight = 0.1
        action_mode = "torque"
        "#,
    )
    .unwrap();
    let resolved = cfg.resolved_options().unwrap();
    assert_eq!(resolved["drift_weight"].as_float(), Some(0.25));
    assert_eq!(resolved["energy_weight"].as_float(), Some(0.005));
    assert_eq!(resolved["fall_up_threshold"].as_float(), Some(0.85));
    assert_eq!(resolved["action_mode"].as_str(), Some("torque"));
    let env = make(&cfg).unwrap();
    assert_eq!(env.spec().action_space.high[0], 3.5);
}

#[test]
fn a_blow_up_ends_the_episode_with_a_flag() {
    let mut env = InvertedPendulum::new(InvertedPendulumOptions::default()).unwrap();
    env.reset(Some(0)).unwrap();
    let s = env.step(&[3.0]).unwrap();
    assert!(!s.info.unstable);
    // An absurd velocity makes the integration overflow; MuJoCo would silently reset.
    let qpos = env.data().qpos().to_vec();
    env.set_state(&qpos, &[1e300, -1e300]).unwrap();
    let s = env.step(&[0.0]).unwrap();
    assert!(s.info.unstable, "the blow-up must be reported");
    assert!(s.truncated && !s.terminated);
    assert!(s.observation.iter().all(|v| v.is_finite()));
    assert_eq!(s.reward, 0.0);
    assert!(matches!(env.step(&[0.0]), Err(EnvError::EpisodeOver)));
}

#[test]
fn override_lists_keep_arrays_whole() {
    let pairs = locobench::envs::parse_overrides("healthy_z_range=[0.3,0.9],reset_noise_scale=0").unwrap();
    assert_eq!(pairs.len(), 2);
    let cfg = EnvConfig::new("ant").with_overrides(&pairs).unwrap();
    let resolved = cfg.resolved_options().unwrap();
    let range: Vec<f64> =
        resolved["healthy_z_range"].as_array().unwrap().iter().map(|v| v.as_float().unwrap()).collect();
    assert_eq!(range, vec![0.3, 0.9]);
    assert!(locobench::envs::parse_overrides("a=1,b").is_err());
}
