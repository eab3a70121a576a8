//! Minitaur: standing, leg model through the env, motor model, falls, reward terms.
use locobench::envs::minitaur::leg_model::motor_angles_from_leg_model;
use locobench::envs::minitaur::{ActionMode, SIM_DT};
use locobench::envs::{Env, Minitaur, MinitaurOptions};

fn env(opts: MinitaurOptions) -> Minitaur {
    Minitaur::new(opts).unwrap()
}

#[test]
fn stands_for_ten_seconds_under_default_targets() {
    for randomize in [false, true] {
        let mut e = env(MinitaurOptions { randomize_dynamics: randomize, ..Default::default() });
        let (obs, info) = e.reset(Some(3)).unwrap();
        assert_eq!(obs.len(), 28);
        let h0 = info.metric("base_height").unwrap();
        assert!(h0 > 0.14 && h0 < 0.19, "height after the reset hold {h0}");
        let mut min_h = f64::INFINITY;
        for t in 0..1000 {
            let s = e.step(&[0.0; 8]).unwrap();
            assert!(!s.terminated, "fell at step {t} (randomize={randomize})");
            assert!(!s.info.unstable);
            min_h = min_h.min(s.info.metric("base_height").unwrap());
            if t == 999 {
                assert!(s.truncated);
            }
        }
        let p = e.base_position();
        assert!(p[2] > 0.17 && p[2] < 0.24, "standing height {p:?}");
        assert!(p[0].abs() < 0.05 && p[1].abs() < 0.05, "drifted to {p:?}");
        assert!(e.base_up_z() > 0.99);
        assert!(min_h > 0.13);
    }
}

#[test]
fn motors_track_the_leg_model_targets() {
    let mut e = env(MinitaurOptions { randomize_dynamics: false, ..Default::default() });
    e.reset(Some(0)).unwrap();
    let action = [0.2, 0.2, -0.1, -0.1, 0.2, 0.2, 0.2, 0.2];
    let targets = motor_angles_from_leg_model(&action);
    for _ in 0..100 {
        e.step(&action).unwrap();
    }
    // The PD loop is soft (kp = 1 PWM/rad, about 8 N m/rad) and carries the body's weight, so a
    // loaded motor sits a little off its target; the differential (swing) part tracks closely.
    let angles = e.motor_angles();
    for i in 0..8 {
        assert!((angles[i] - targets[i]).abs() < 0.2, "motor {i}: {} vs {}", angles[i], targets[i]);
    }
    for leg in 0..4 {
        let swing = (angles[2 * leg] - angles[2 * leg + 1]) / 2.0;
        let wanted = (targets[2 * leg] - targets[2 * leg + 1]) / 2.0;
        assert!((swing - wanted).abs() < 0.05, "leg {leg}: swing {swing} vs {wanted}");
    }
}

#[test]
fn extension_raises_and_lowers_the_base() {
    let height_with = |ext: f64| {
        let mut e = env(MinitaurOptions { randomize_dynamics: false, ..Default::default() });
        e.reset(Some(0)).unwrap();
        let a = [0.0, 0.0, 0.0, 0.0, ext, ext, ext, ext];
        for _ in 0..200 {
            e.step(&a).unwrap();
        }
        e.base_position()[2]
    };
    let (low, mid, high) = (height_with(0.5), height_with(0.0), height_with(-0.5));
    assert!(low < mid && mid < high, "{low} {mid} {high}");
    assert!(mid - low > 0.03, "extension +0.5 should lower the base by several cm: {low} {mid}");
}

#[test]
fn reward_terms_match_the_definition() {
    let opts = MinitaurOptions {
        randomize_dynamics: false,
        drift_weight: 0.3,
        shake_weight: 0.2,
        energy_weight: 0.01,
        distance_weight: 1.5,
        ..Default::default()
    };
    let mut e = env(opts);
    e.reset(Some(1)).unwrap();
    for t in 0..30 {
        let before = e.base_position();
        let a: Vec<f64> = (0..8).map(|i| ((t + i) as f64 * 0.7).sin() * 0.6).collect();
        let s = e.step(&a).unwrap();
        let after = e.base_position();
        let obs = &s.observation;
        let power: f64 = (0..8).map(|i| obs[16 + i] * obs[8 + i]).sum();
        let expect = [
            ("distance", 1.5 * (after[0] - before[0])),
            ("energy", -0.01 * power.abs() * SIM_DT),
            ("drift", -0.3 * (after[1] - before[1]).abs()),
            ("shake", -0.2 * (after[2] - before[2]).abs()),
        ];
        for (name, v) in expect {
            let got = s.info.term(name).unwrap();
            assert!((got - v).abs() < 1e-12, "{name}: {got} vs {v}");
        }
        let sum: f64 = s.info.reward_terms.iter().map(|(_, v)| v).sum();
        assert!((sum - s.reward).abs() < 1e-12);
    }
}

#[test]
fn a_speed_cap_pays_distance_up_to_it() {
    // 0.05 m/s pays at most 0.5 mm per 0.01 s control step; the swinging legs move the base
    // both less and more than that, so both sides of the cap are checked.
    let cap = 0.05;
    let opts = MinitaurOptions {
        randomize_dynamics: false,
        distance_weight: 2.0,
        max_rewarded_speed: cap,
        ..Default::default()
    };
    let mut e = env(opts);
    e.reset(Some(1)).unwrap();
    let dt = e.spec().dt;
    assert!((dt - 0.01).abs() < 1e-12);
    let (mut capped, mut paid_in_full) = (0, 0);
    for t in 0..300 {
        let before = e.base_position();
        let a: Vec<f64> = (0..8).map(|i| ((t + i) as f64 * 0.7).sin() * 0.6).collect();
        let s = e.step(&a).unwrap();
        if s.terminated {
            break;
        }
        let dx = e.base_position()[0] - before[0];
        let got = s.info.term("distance").unwrap();
        if dx > cap * dt {
            capped += 1;
            assert!((got - 2.0 * cap * dt).abs() < 1e-12, "step {t}: {got} for dx {dx}");
        } else {
            paid_in_full += 1;
            assert!((got - 2.0 * dx).abs() < 1e-12, "step {t}: {got} for dx {dx}");
        }
        let sum: f64 = s.info.reward_terms.iter().map(|(_, v)| v).sum();
        assert!((sum - s.reward).abs() < 1e-12);
    }
    assert!(capped > 10 && paid_in_full > 10, "{capped} capped, {paid_in_full} paid in full");

    let bad = Minitaur::new(MinitaurOptions { max_rewarded_speed: -1.0, ..Default::default() });
    let err = bad.err().expect("a negative cap is refused").to_string();
    assert!(err.contains("max_rewarded_speed") && err.contains("-1"), "{err}");
}

#[test]
fn fall_thresholds_end_the_episode() {
    // Legs fully retracted and swung hard: the robot drops below a strict height threshold.
    let mut e = env(MinitaurOptions { randomize_dynamics: false, fall_height: 0.17, ..Default::default() });
    e.reset(Some(0)).unwrap();
    let mut terminated = false;
    for _ in 0..300 {
        let s = e.step(&[0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]).unwrap();
        if s.terminated {
            terminated = true;
            assert!(e.base_position()[2] < 0.17);
            break;
        }
    }
    assert!(terminated);
    assert!(e.step(&[0.0; 8]).is_err(), "stepping a finished episode is an error");
}

#[test]
fn torque_mode_drives_motors_within_limits() {
    let mut e =
        env(MinitaurOptions { randomize_dynamics: false, action_mode: ActionMode::Torque, ..Default::default() });
    assert_eq!(e.spec().action_space.high[0], 3.5);
    e.reset(Some(0)).unwrap();
    let s = e.step(&[1.0; 8]).unwrap();
    for t in e.applied_torques() {
        assert!(t.abs() <= 3.5 + 1e-12 && t > 0.0);
    }
    // Out-of-range torque commands are clipped and counted.
    assert_eq!(s.info.clipped_actions, 0);
    let s = e.step(&[9.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -9.0]).unwrap();
    assert_eq!(s.info.clipped_actions, 2);
}

#[test]
fn four_bar_kinematics_match_the_simulated_legs() {
    use locobench::controller::fourbar;
    let mut e = env(MinitaurOptions { randomize_dynamics: false, ..Default::default() });
    e.reset(Some(0)).unwrap();
    for _ in 0..50 {
        e.step(&[0.3, -0.2, 0.1, 0.0, 0.2, 0.1, 0.0, -0.1]).unwrap();
    }
    let d = e.data();
    let m = d.model();
    let base = m.body_id("base").unwrap();
    let r = &d.xmat()[9 * base..9 * base + 9];
    let angles = e.motor_angles();
    for (leg, name) in ["fl", "bl", "fr", "br"].iter().enumerate() {
        let (outer, inner) =
            if leg < 2 { (angles[2 * leg], angles[2 * leg + 1]) } else { (angles[2 * leg + 1], angles[2 * leg]) };
        let foot = m.site_id(&format!("foot_{name}")).unwrap();
        let hip = m.site_id(&format!("hip_{name}")).unwrap();
        let w: Vec<f64> = (0..3).map(|k| d.site_xpos()[3 * foot + k] - d.site_xpos()[3 * hip + k]).collect();
        // World offset into the base frame (R^T w); keep x and z.
        let local: Vec<f64> = (0..3).map(|c| (0..3).map(|k| r[3 * k + c] * w[k]).sum()).collect();
        let predicted = fourbar::forward(outer, inner).unwrap();
        assert!(
            (local[0] - predicted[0]).abs() < 2e-3 && (local[2] - predicted[1]).abs() < 2e-3,
            "leg {name}: simulated {local:?}, kinematics {predicted:?}"
        );
    }
}

/// PyBullet's own MinitaurBulletEnv under constant leg-model actions (randomisation off), from
/// `tests/reference/minitaur-pybullet.csv` (script beside it): the same actions fall here or
/// stand here as they do there, at a similar time, with a similar pose. The two engines'
/// contacts differ, so times may differ by a few control steps, not by their nature.
#[test]
fn constant_actions_fall_or_stand_as_in_pybullet() {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/reference/minitaur-pybullet.csv")).unwrap();
    let mut report = Vec::new();
    let mut ok = true;
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let action: Vec<f64> = f[1].split(' ').map(|v| v.parse().unwrap()).collect();
        let (pb_steps, pb_fell): (usize, bool) = (f[2].parse().unwrap(), f[3] == "1");
        let (pb_height, pb_up): (f64, f64) = (f[4].parse().unwrap(), f[5].parse().unwrap());
        let mut e = env(MinitaurOptions { randomize_dynamics: false, ..Default::default() });
        e.reset(Some(0)).unwrap();
        let (mut steps, mut fell) = (0usize, false);
        while steps < 300 && !fell {
            fell = e.step(&action).unwrap().terminated;
            steps += 1;
        }
        let (height, up) = (e.base_position()[2], e.base_up_z());
        report.push(format!(
            "{:24} pybullet {pb_steps:3} steps fell={pb_fell} h={pb_height:.3} up={pb_up:.3} | here {steps:3} fell={fell} \
             h={height:.3} up={up:.3}",
            f[0]
        ));
        let steps_close = steps.abs_diff(pb_steps) <= 3 + pb_steps / 4;
        // A standing pose's height and tilt; a fallen one's end condition (tilt or height).
        let pose_close = if pb_fell { (up < 0.85) == (pb_up < 0.85) } else { (height - pb_height).abs() < 0.03 };
        ok &= fell == pb_fell && steps_close && pose_close;
    }
    eprintln!("{}", report.join("\n"));
    assert!(ok, "differs from PyBullet (above)");
}

// ---- Perturbations: each option does what it says, and nothing when off ----

fn fixed(opts: MinitaurOptions) -> Minitaur {
    env(MinitaurOptions { randomize_dynamics: false, ..opts })
}

#[test]
fn payload_friction_and_slope_change_the_episode_model() {
    let mut plain = fixed(MinitaurOptions::default());
    plain.reset(Some(1)).unwrap();
    let m0 = plain.data().model().clone();
    let mut e = fixed(MinitaurOptions { payload_mass: 2.5, friction_scale: 0.25, slope: 10.0, ..Default::default() });
    e.reset(Some(1)).unwrap();
    let m = e.data().model();
    let total = |m: &locobench::mujoco::Model| m.body_mass().iter().sum::<f64>();
    assert!((total(m) - total(&m0) - 2.5).abs() < 1e-12);
    for (a, b) in m.geom_friction().chunks(3).zip(m0.geom_friction().chunks(3)) {
        assert!((a[0] - 0.25 * b[0]).abs() < 1e-15 && a[1] == b[1]);
    }
    let g = m.gravity();
    let theta = 10f64.to_radians();
    assert!((g[0] + 10.0 * theta.sin()).abs() < 1e-12 && (g[2] + 10.0 * theta.cos()).abs() < 1e-12);
    // Uphill the same gait covers less ground than on the flat.
    let walk = |e: &mut Minitaur| {
        for _ in 0..300 {
            e.step(&[0.3, -0.3, -0.3, 0.3, 0.0, 0.0, 0.0, 0.0]).unwrap();
        }
        e.base_position()[0]
    };
    let up = walk(&mut fixed(MinitaurOptions { slope: 15.0, ..Default::default() }).tap_reset());
    let flat = walk(&mut fixed(MinitaurOptions::default()).tap_reset());
    assert!(up < flat, "uphill {up} vs flat {flat}");
    // A centre of mass moved forward changes the gait's course too.
    let forward = walk(&mut fixed(MinitaurOptions { com_shift: 0.1, ..Default::default() }).tap_reset());
    assert_ne!(forward, flat);
}

#[test]
fn random_payload_and_centre_of_mass_are_drawn_per_episode_within_their_range() {
    let mut plain = fixed(MinitaurOptions::default());
    plain.reset(Some(1)).unwrap();
    let m0 = plain.data().model().clone();
    let base = (0..m0.body_mass().len()).max_by(|a, b| m0.body_mass()[*a].total_cmp(&m0.body_mass()[*b])).unwrap();
    let opts = MinitaurOptions { random_payload_max: 2.0, random_com_shift_max: 0.1, ..Default::default() };
    let mut e = fixed(opts.clone());
    let mut draws = Vec::new();
    for seed in 0..8 {
        e.reset(Some(seed)).unwrap();
        let m = e.data().model();
        let payload = m.body_mass()[base] - m0.body_mass()[base];
        let shift = m.body_ipos()[3 * base] - m0.body_ipos()[3 * base];
        assert!((0.0..=2.0).contains(&payload) && (-0.1..=0.1).contains(&shift), "{payload} {shift}");
        draws.push((payload, shift));
    }
    assert!(draws.iter().any(|d| d.1 > 0.0) && draws.iter().any(|d| d.1 < 0.0), "both ways: {draws:?}");
    assert!(draws.windows(2).all(|w| w[0] != w[1]), "a new draw each episode: {draws:?}");
    // The same seed draws the same world.
    let mut again = fixed(opts);
    again.reset(Some(3)).unwrap();
    let m = again.data().model();
    assert_eq!(m.body_mass()[base] - m0.body_mass()[base], draws[3].0);
}

trait TapReset {
    fn tap_reset(self) -> Self;
}
impl TapReset for Minitaur {
    fn tap_reset(mut self) -> Self {
        self.reset(Some(4)).unwrap();
        self
    }
}

#[test]
fn latency_delays_each_action_by_whole_physics_steps() {
    // With one control step of latency, the first step still holds the reset pose: the leg
    // model's action (0, .., 0.5, ..) is exactly that pose, so a delayed run matches an undelayed
    // run that sent the pose first.
    let hold = [0.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.5, 0.5];
    let actions = [[0.3, -0.2, 0.1, 0.0, 0.2, -0.1, 0.0, 0.3], [-0.2, 0.1, 0.3, -0.3, 0.0, 0.2, 0.1, -0.1], hold];
    let mut delayed = fixed(MinitaurOptions { latency: 0.01, ..Default::default() });
    let mut prompt = fixed(MinitaurOptions::default());
    delayed.reset(Some(2)).unwrap();
    prompt.reset(Some(2)).unwrap();
    for (sent, arrived) in actions.iter().zip([hold, actions[0], actions[1]]) {
        let d = delayed.step(sent).unwrap();
        let p = prompt.step(&arrived).unwrap();
        assert_eq!(d.observation, p.observation);
    }
    // A sub-step delay (2 of the 5 physics steps) gives something in between.
    let mut sub = fixed(MinitaurOptions { latency: 0.004, ..Default::default() });
    sub.reset(Some(2)).unwrap();
    let s = sub.step(&actions[0]).unwrap().observation;
    let mut now = fixed(MinitaurOptions::default());
    now.reset(Some(2)).unwrap();
    assert_ne!(s, now.step(&actions[0]).unwrap().observation);
}

#[test]
fn sensor_noise_is_seeded_and_leaves_the_physics_alone() {
    let noisy = || {
        fixed(MinitaurOptions { noise_angle: 0.05, noise_velocity: 1.0, noise_orientation: 0.05, ..Default::default() })
    };
    let (mut a, mut b, mut clean) = (noisy(), noisy(), fixed(MinitaurOptions::default()));
    let (oa, _) = a.reset(Some(5)).unwrap();
    let (ob, _) = b.reset(Some(5)).unwrap();
    let (oc, _) = clean.reset(Some(5)).unwrap();
    assert_eq!(oa, ob, "same seed, same noise");
    assert_ne!(oa, oc);
    let err: f64 = oa[..8].iter().zip(&oc[..8]).map(|(x, y)| (x - y).abs()).sum::<f64>() / 8.0;
    assert!(err > 0.005 && err < 0.2, "mean angle error {err}");
    a.step(&[0.1; 8]).unwrap();
    clean.step(&[0.1; 8]).unwrap();
    assert_eq!(a.base_position(), clean.base_position(), "noise is in the observation only");
}

#[test]
fn terrain_is_new_each_episode_and_falls_are_measured_above_it() {
    let mut e = fixed(MinitaurOptions { terrain_step_height: 0.05, ..Default::default() });
    e.reset(Some(1)).unwrap();
    assert_eq!(e.data().model().geom_type().iter().filter(|t| **t == 1).count(), 1, "one heightfield");
    let ahead: Vec<f64> = (0..20).map(|i| e.ground_height(1.0 + 0.2 * i as f64, 0.1)).collect();
    assert!(ahead.iter().all(|h| (0.0..=0.05).contains(h)) && ahead.iter().any(|h| *h > 0.01), "{ahead:?}");
    assert_eq!(e.ground_height(0.0, 0.0), 0.0, "flat where it starts");
    // Standing on the flat start patch works as on flat ground.
    for _ in 0..200 {
        assert!(!e.step(&[0.0; 8]).unwrap().terminated);
    }
    e.reset(Some(2)).unwrap();
    let other: Vec<f64> = (0..20).map(|i| e.ground_height(1.0 + 0.2 * i as f64, 0.1)).collect();
    assert_ne!(ahead, other, "each episode draws its own ground");
    let mut flat = fixed(MinitaurOptions::default());
    flat.reset(Some(1)).unwrap();
    assert_eq!(flat.ground_height(1.0, 0.1), 0.0);
}

#[test]
fn random_pushes_follow_pybullets_schedule() {
    let mut e = fixed(MinitaurOptions { random_push_max: 1.0, ..Default::default() });
    e.reset(Some(3)).unwrap();
    let mut pushed = Vec::new();
    for t in 0..320 {
        let s = e.step(&[0.0; 8]).unwrap();
        if s.terminated {
            break;
        }
        let f = e.data().qfrc_applied();
        if f[0] != 0.0 || f[1] != 0.0 {
            pushed.push(t);
        }
    }
    assert_eq!(pushed, (100..110).chain(300..310).filter(|t| *t < 320).collect::<Vec<_>>());
}

#[test]
fn weak_motors_and_a_low_battery_hold_the_body_lower() {
    let height = |opts: MinitaurOptions| {
        let mut e = fixed(opts);
        e.reset(Some(0)).unwrap();
        // Its lowest point while standing (a robot too weak to stand sinks until it falls).
        let mut low = f64::INFINITY;
        for _ in 0..100 {
            let s = e.step(&[0.0; 8]).unwrap();
            low = low.min(e.base_position()[2]);
            if s.terminated {
                break;
            }
        }
        low
    };
    let full = height(MinitaurOptions::default());
    assert!(height(MinitaurOptions { motor_strength: 0.3, ..Default::default() }) < full - 0.005);
    assert!(height(MinitaurOptions { battery_voltage: 4.0, ..Default::default() }) < full - 0.005);
}

#[test]
fn perturbation_options_out_of_range_name_the_option() {
    for (opts, name) in [
        (MinitaurOptions { payload_mass: -1.0, ..Default::default() }, "payload_mass"),
        (MinitaurOptions { friction_scale: -0.1, ..Default::default() }, "friction_scale"),
        (MinitaurOptions { terrain_step_height: 0.5, ..Default::default() }, "terrain_step_height"),
        (MinitaurOptions { slope: 45.0, ..Default::default() }, "slope"),
        (MinitaurOptions { latency: f64::NAN, ..Default::default() }, "latency"),
        (MinitaurOptions { noise_angle: -0.01, ..Default::default() }, "noise_angle"),
        (MinitaurOptions { battery_voltage: 0.5, ..Default::default() }, "battery_voltage"),
        (MinitaurOptions { random_push_max: 10.0, ..Default::default() }, "random_push_max"),
        (MinitaurOptions { random_payload_max: -1.0, ..Default::default() }, "random_payload_max"),
        (MinitaurOptions { com_shift: 0.2, random_com_shift_max: 0.2, ..Default::default() }, "random_com_shift_max"),
    ] {
        let e = Minitaur::new(opts).err().expect("refused").to_string();
        assert!(e.contains(name), "{e}");
    }
}
