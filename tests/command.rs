//! The velocity-command tasks: what they observe, how they reward, their command stream, and the
//! controller following it.
use locobench::controller::baseline::{baseline_controller_for, baseline_env};
use locobench::controller::command::Command;
use locobench::envs::command::{BaseMotion, REWARD_TERMS};
use locobench::envs::{make, EnvConfig};
use locobench::evaluation::tracking::tracking_grid;
use locobench::evaluation::Protocol;

fn env(name: &str, options: &[(&str, &str)]) -> Box<dyn locobench::envs::Env> {
    let pairs: Vec<(String, String)> = options.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
    make(&EnvConfig::new(name).with_overrides(&pairs).unwrap()).unwrap()
}

#[test]
fn the_observation_is_the_base_s_then_velocities_then_the_command() {
    for (name, base) in [("minitaur-command", "minitaur"), ("ant-command", "ant")] {
        let mut e = env(name, &[("schedule", "\"0:0.7:-0.2\"")]);
        let base_dim = make(&EnvConfig::new(base)).unwrap().spec().observation_space.dim();
        assert_eq!(e.spec().observation_space.dim(), base_dim + 8, "{name}");
        assert_eq!(e.spec().reward_terms, REWARD_TERMS.to_vec());
        let (obs, _) = e.reset(Some(3)).unwrap();
        assert_eq!(obs.len(), base_dim + 8);
        assert_eq!(&obs[obs.len() - 2..], &[0.7, -0.2], "{name}: the command ends the observation");
        let m = BaseMotion::of(
            e.data(),
            e.data().model().body_id(if base == "ant" { "torso" } else { "base" }).unwrap(),
            0,
            e.forward_angle(),
        );
        assert_eq!(&obs[base_dim..base_dim + 3], &m.velocity);
        assert_eq!(&obs[base_dim + 3..base_dim + 6], &m.angular_velocity);
    }
}

#[test]
fn reward_terms_match_a_hand_computation_and_sum_to_the_reward() {
    let mut e = env("minitaur-command", &[("schedule", "\"0:0.5:0.1\""), ("only_positive_rewards", "false")]);
    e.reset(Some(0)).unwrap();
    let dt = e.spec().dt;
    let action = vec![0.3; 8];
    let step = e.step(&action).unwrap();
    let body = e.data().model().body_id("base").unwrap();
    let m = BaseMotion::of(e.data(), body, 0, 0.0);
    let term = |n: &str| step.info.term(n).unwrap();
    let speed_error = (m.velocity[0] - 0.5).powi(2) + m.velocity[1].powi(2);
    assert!((term("tracking_speed") - dt * (-speed_error / 0.25).exp()).abs() < 1e-12);
    let yaw_error = (m.yaw_rate - 0.1).powi(2);
    assert!((term("tracking_yaw_rate") - 0.5 * dt * (-yaw_error / 0.25).exp()).abs() < 1e-12);
    assert!((term("orientation") + dt * (m.gravity[0].powi(2) + m.gravity[1].powi(2))).abs() < 1e-12);
    assert!(
        (term("body_rates") + 0.05 * dt * (m.angular_velocity[0].powi(2) + m.angular_velocity[1].powi(2))).abs()
            < 1e-12
    );
    assert!((term("vertical_velocity") + 2.0 * dt * m.velocity[2].powi(2)).abs() < 1e-12);
    // the first step's action rate is against a zero action: 8 x 0.3^2 (leg mode acts in [-1, 1])
    assert!((term("action_rate") + 0.01 * dt * 8.0 * 0.09).abs() < 1e-12);
    let energy = step.info.metric("mechanical_energy").unwrap();
    assert!((term("energy") + 0.001 * energy.abs()).abs() < 1e-12);
    assert_eq!(term("positive_clip"), 0.0);
    let sum: f64 = step.info.reward_terms.iter().map(|(_, v)| v).sum();
    assert_eq!(step.reward, sum);
}

#[test]
fn a_negative_step_is_lifted_to_zero_by_a_named_term() {
    // Every tracking weight off: what is left is costs, clipped to zero.
    let mut e = env("minitaur-command", &[("tracking_speed_weight", "0"), ("tracking_yaw_rate_weight", "0")]);
    e.reset(Some(0)).unwrap();
    let step = e.step(&[1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0]).unwrap();
    assert_eq!(step.reward, 0.0);
    assert!(step.info.term("positive_clip").unwrap() > 0.0);
}

#[test]
fn the_same_seed_gives_the_same_command_stream_and_another_seed_another() {
    let stream = |seed: u64| {
        let mut e = env("minitaur-command", &[("resample_time_range", "[0.5, 1.0]")]);
        let (obs, _) = e.reset(Some(seed)).unwrap();
        let mut commands = vec![[obs[obs.len() - 2], obs[obs.len() - 1]]];
        for _ in 0..300 {
            let s = e.step(&[0.0; 8]).unwrap();
            if s.done() {
                break;
            }
            commands.push([s.observation[s.observation.len() - 2], s.observation[s.observation.len() - 1]]);
        }
        commands
    };
    let a = stream(4);
    assert_eq!(a, stream(4));
    assert_ne!(a, stream(5));
    let distinct = a.windows(2).filter(|w| w[0] != w[1]).count();
    assert!(distinct >= 2, "a 3 s stream redrawn every 0.5-1 s changes: {distinct}");
    for c in &a {
        assert!(c == &[0.0, 0.0] || ((0.0..=2.5).contains(&c[0]) && (-0.5..=0.5).contains(&c[1])), "{c:?}");
    }
}

#[test]
fn bad_command_options_are_errors_naming_the_option() {
    let err = |options: &[(&str, &str)]| {
        let pairs: Vec<(String, String)> = options.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        match make(&EnvConfig::new("minitaur-command").with_overrides(&pairs).unwrap()) {
            Ok(_) => panic!("{options:?} was accepted"),
            Err(e) => e.to_string(),
        }
    };
    assert!(err(&[("speed_range", "[1.0, 0.5]")]).contains("speed_range"));
    assert!(err(&[("yaw_rate_range", "[0.3, 0.3]")]).contains("yaw_rate_range"));
    assert!(err(&[("schedule", "\"0:1:0 2:0:0 1:1:0\"")]).contains("times must increase"));
    assert!(err(&[("standing_probability", "1.5")]).contains("standing_probability"));
    assert!(err(&[("tracking_speed_weight", "-1")]).contains("tracking_speed_weight"));
    assert!(err(&[("no_such_term_weight", "1")]).contains("no_such_term_weight"));
    assert!(err(&[("forward_angle", "200")]).contains("forward_angle"));
    assert!(err(&[("forward_angle", "nan")]).contains("forward_angle"));
    assert!(err(&[("feet_air_time_target", "-0.1")]).contains("feet_air_time_target"));
    assert!(err(&[("feet_air_time_weight", "-1")]).contains("feet_air_time_weight"));
}

#[test]
fn the_controller_follows_the_stream_it_is_given() {
    let cfg = baseline_env("minitaur-command").unwrap();
    let mut controller = baseline_controller_for("minitaur-command", Command::straight(0.0, 0.0), None).unwrap();
    let grid =
        tracking_grid(&cfg, controller.as_mut(), &[0.5, 1.0], &[0.0], Protocol { episodes: 2, seed: 0 }).unwrap();
    for p in &grid {
        assert_eq!(p.falls(), 0, "{} m/s", p.speed);
        let achieved = p.achieved_speed().estimate;
        assert!((achieved - p.speed).abs() < 0.1, "commanded {} m/s, achieved {achieved}", p.speed);
        assert!(p.speed_rms().estimate < 0.15);
    }
}

/// On `ant-command` the rowing controller rows along the task's forward (45° from the torso's x
/// axis) and takes each new command in stride: speeding up, turning both ways and stopping, the
/// mean speed and yaw rate over the settled part of each 10 s stretch follow the command, with
/// no fall.
#[test]
fn the_ant_controller_follows_a_changing_command_in_stride() {
    let cfg = baseline_env("ant-command")
        .unwrap()
        .with_overrides(&[("schedule".into(), "\"0:0.5:0 10:1.0:0 20:0.5:0.3 30:0.3:-0.3 40:0:0\"".into())])
        .unwrap();
    let mut env = make(&cfg).unwrap();
    let mut controller = baseline_controller_for("ant-command", Command::straight(0.0, 0.0), None).unwrap();
    assert_eq!(controller.name(), "raibert-row@command");
    for seed in [1, 2] {
        let (mut obs, _) = env.reset(Some(seed)).unwrap();
        controller.begin_episode(0);
        let mut sums = [[0.0; 3]; 5];
        for t in 0..1000 {
            let step = env.step(&controller.act(env.as_ref(), &obs).unwrap()).unwrap();
            assert!(!step.terminated, "seed {seed}: fell at step {t}");
            // the last 7 s of each 10 s stretch: the first 3 s change pace
            if t % 200 >= 60 {
                let m = |k: &str| step.info.metric(k).unwrap();
                let s = &mut sums[t / 200];
                s[0] += m("forward_velocity");
                s[1] += m("yaw_rate");
                s[2] += 1.0;
            }
            obs = step.observation;
        }
        for (k, (speed, yaw_rate)) in
            [(0.5, 0.0), (1.0, 0.0), (0.5, 0.3), (0.3, -0.3), (0.0, 0.0)].into_iter().enumerate()
        {
            let [v, w, n] = sums[k];
            let (v, w) = (v / n, w / n);
            assert!((v - speed).abs() < 0.1 * speed.max(0.5), "seed {seed}, {speed} m/s commanded: {v:.3}");
            assert!((w - yaw_rate).abs() < 0.05, "seed {seed}, {yaw_rate} rad/s commanded: {w:.3}");
        }
    }
}

/// The task's forward axis is `forward_angle` degrees from the body's x axis: a torso moving
/// along its own 45° diagonal moves straight forward on `ant-command` (the default) and half
/// forward, half to the right, at 0°.
#[test]
fn forward_is_the_forward_angle_from_the_body_s_x_axis() {
    for (angle, forward, left) in [("45", 1.0, 0.0), ("0", 0.5f64.sqrt(), 0.5f64.sqrt()), ("-45", 0.0, 1.0)] {
        let mut e = env("ant-command", &[("forward_angle", angle), ("schedule", "\"0:0.5:0\"")]);
        e.reset(Some(0)).unwrap();
        let mut q = e.data().qpos().to_vec();
        let mut v = vec![0.0; e.data().qvel().len()];
        q[3..7].copy_from_slice(&[1.0, 0.0, 0.0, 0.0]);
        let d = 0.5f64.sqrt();
        v[0] = d;
        v[1] = d;
        e.set_state(&q, &v).unwrap();
        let body = e.data().model().body_id("torso").unwrap();
        let angle: f64 = angle.parse().unwrap();
        let m = BaseMotion::of(e.data(), body, 0, angle.to_radians());
        assert!(
            (m.velocity[0] - forward).abs() < 1e-9 && (m.velocity[1] - left).abs() < 1e-9,
            "{angle}: {:?}",
            m.velocity
        );
        assert!((e.forward_angle() - angle.to_radians()).abs() < 1e-15);
    }
    assert_eq!(env("minitaur-command", &[]).forward_angle(), 0.0);
}

/// `feet_air_time` against a count kept here from MuJoCo's contacts: on the step a foot lands
/// (pushed up by more than 1 N, at this step or the last) it pays its air time less the 0.5 s
/// target, times the weight per second; nothing while the command is to stand.
#[test]
fn feet_air_time_pays_each_landing_its_air_time_less_the_target() {
    for (schedule, moving) in [("\"0:0.5:0\"", true), ("\"0:0:0.3\"", false)] {
        let options = [("schedule", schedule), ("only_positive_rewards", "false"), ("feet_air_time_weight", "1.0")];
        let mut e = env("ant-command", &options);
        e.reset(Some(4)).unwrap();
        let dt = e.spec().dt;
        let feet: Vec<usize> = ["left_ankle_geom", "right_ankle_geom", "third_ankle_geom", "fourth_ankle_geom"]
            .iter()
            .map(|n| e.data().model().geom_id(n).unwrap())
            .collect();
        let (mut air, mut last) = ([0.0f64; 4], [false; 4]);
        let (mut landings, mut paid) = (0, 0.0);
        for t in 0..300 {
            // hips swing back and forth, ankles lift and drop: feet leave and strike the ground
            let phase = t as f64 * dt * 2.0 * std::f64::consts::PI / 0.8;
            let a: Vec<f64> = (0..8).map(|j| if j % 2 == 0 { phase.sin() } else { (phase + j as f64).cos() }).collect();
            let step = e.step(&a).unwrap();
            let mut expected = 0.0;
            let contacts = e.data().contacts();
            for k in 0..4 {
                let now = contacts.iter().any(|c| (c.geom1 == feet[k] || c.geom2 == feet[k]) && c.force[0] > 1.0);
                let filtered = now || last[k];
                last[k] = now;
                let first = air[k] > 0.0 && filtered;
                air[k] += dt;
                if first {
                    expected += air[k] - 0.5;
                    landings += 1;
                }
                if filtered {
                    air[k] = 0.0;
                }
            }
            let term = step.info.term("feet_air_time").unwrap();
            let want = if moving { expected } else { 0.0 };
            assert!((term - want).abs() < 1e-12, "step {t}: {term} against {want}");
            paid += term.abs();
            if step.terminated {
                break;
            }
        }
        assert!(landings >= 5, "the feet landed {landings} times");
        assert_eq!(paid > 0.0, moving, "{schedule}");
    }
    // off by default
    for name in ["minitaur-command", "ant-command"] {
        let mut m = env(name, &[("schedule", "\"0:1.0:0\"")]);
        m.reset(Some(0)).unwrap();
        let dim = m.spec().action_space.dim();
        for _ in 0..50 {
            let step = m.step(&vec![0.0; dim]).unwrap();
            assert_eq!(step.info.term("feet_air_time").unwrap(), 0.0, "{name}");
            if step.done() {
                break;
            }
        }
    }
}

mod notch {
    use locobench::envs::notch::direction;
    use locobench::envs::{make, EnvConfig};

    fn walker(options: &[(&str, &str)]) -> Box<dyn locobench::envs::Env> {
        let pairs: Vec<(String, String)> = options.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        make(&EnvConfig::new("walker2d-notch").with_overrides(&pairs).unwrap()).unwrap()
    }

    #[test]
    fn each_action_moves_its_joint_target_a_notch_and_the_targets_are_observed() {
        assert_eq!([direction(-1.0), direction(0.0), direction(1.0), direction(0.3)], [-1.0, 0.0, 1.0, 0.0]);
        let mut e = walker(&[("notch", "0.1")]);
        let (obs, _) = e.reset(Some(0)).unwrap();
        assert_eq!(obs.len(), 17 + 6);
        let start: Vec<f64> = obs[17..].to_vec();
        // the targets start at the joints' angles, within the joints' ranges
        let ranges = e.data().model().jnt_range().to_vec();
        for (j, (target, q)) in start.iter().zip(&e.data().qpos()[3..9]).enumerate() {
            assert_eq!(*target, q.clamp(ranges[2 * (3 + j)], ranges[2 * (3 + j) + 1]));
        }
        // the feet (joints 2 and 5, range ±45 degrees) start near 0, a notch from either limit
        let step = e.step(&[0.0, 0.0, 1.0, 0.0, 0.0, -1.0]).unwrap();
        let t = &step.observation[17..];
        assert!((t[2] - (start[2] + 0.1)).abs() < 1e-12 && (t[5] - (start[5] - 0.1)).abs() < 1e-12);
        assert_eq!([t[0], t[1], t[3], t[4]], [start[0], start[1], start[3], start[4]]);
        // a thigh at its upper limit (0 rad) stays there when pushed further up
        let mut at_limit = start.clone();
        for _ in 0..40 {
            let s = e.step(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
            at_limit = s.observation[17..].to_vec();
        }
        assert_eq!(at_limit[0], 0.0);
    }

    #[test]
    fn holding_every_target_keeps_the_walker_standing() {
        let mut e = walker(&[]);
        e.reset(Some(0)).unwrap();
        for t in 0..1000 {
            let s = e.step(&[0.0; 6]).unwrap();
            assert!(!s.terminated, "fell at step {t}");
        }
    }

    #[test]
    fn a_notch_of_zero_or_below_is_refused_naming_it() {
        for bad in ["0", "-0.1"] {
            let e = make(&EnvConfig::new("walker2d-notch").with_overrides(&[("notch".into(), bad.into())]).unwrap());
            assert!(e.err().unwrap().to_string().contains("notch must be"), "{bad}");
        }
    }
}

#[test]
fn commands_outside_a_policy_s_training_ranges_are_named_with_the_range() {
    use locobench::envs::command::{command_ranges, command_warnings, commands_given, outside_training_range};
    let cfg = |options: &[(&str, &str)]| {
        let pairs: Vec<(String, String)> = options.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        EnvConfig::new("minitaur-command").with_overrides(&pairs).unwrap()
    };
    let trained = cfg(&[("speed_range", "[0.0, 1.5]"), ("yaw_rate_range", "[-0.3, 0.3]")]);
    assert_eq!(command_ranges(&trained).unwrap(), Some(([0.0, 1.5], [-0.3, 0.3])));
    assert_eq!(command_ranges(&EnvConfig::new("minitaur")).unwrap(), None);
    // A schedule gives its knots; without one, the corners of the ranges.
    let scheduled = cfg(&[("schedule", "\"0:1.0:0 3:2.0:0.5\"")]);
    assert_eq!(commands_given(&scheduled).unwrap(), vec![[1.0, 0.0], [2.0, 0.5]]);
    assert_eq!(commands_given(&trained).unwrap().len(), 4);
    let lines = outside_training_range(&trained, &commands_given(&scheduled).unwrap(), "p").unwrap();
    assert_eq!(
        lines,
        vec![
            "command speed 2 m/s lies outside p's training speed_range [0, 1.5]".to_string(),
            "command yaw rate 0.5 rad/s lies outside p's training yaw_rate_range [-0.3, 0.3]".to_string(),
        ]
    );
    assert!(outside_training_range(&trained, &[[1.5, -0.3]], "p").unwrap().is_empty(), "the ends are inside");
    assert_eq!(command_warnings(&trained, &scheduled, "p").unwrap(), lines, "what eval and Python warn with");
    assert!(command_warnings(&trained, &trained, "p").unwrap().is_empty());
    assert!(command_warnings(&EnvConfig::new("minitaur"), &scheduled, "p").unwrap().is_empty(), "not a command task");
}
