//! Mechanical energy is integrated every physics step (not sampled once per control step), the
//! same way for Ant (MuJoCo actuators) and Minitaur (its motor model), so costs of transport of
//! controllers and agents compare.
use locobench::envs::{make, EnvConfig};

fn ant(frame_skip: usize) -> Box<dyn locobench::envs::Env> {
    let cfg = EnvConfig::new("ant")
        .with_overrides(&[
            ("frame_skip".into(), frame_skip.to_string()),
            ("reset_noise_scale".into(), "0.0".into()),
            ("terminate_when_unhealthy".into(), "false".into()),
        ])
        .unwrap();
    make(&cfg).unwrap()
}

#[test]
fn ant_energy_of_a_control_step_is_the_sum_over_its_physics_steps() {
    let action = [0.6, -0.4, 0.3, 0.8, -0.7, 0.2, -0.5, 0.9];
    let (mut coarse, mut fine) = (ant(5), ant(1));
    coarse.reset(Some(3)).unwrap();
    fine.reset(Some(3)).unwrap();
    for control_step in 0..20 {
        let energy = coarse.step(&action).unwrap().info.metric("mechanical_energy").unwrap();
        let mut by_hand = 0.0;
        for _ in 0..5 {
            // Power at the start of the physics step: actuator force (gear x ctrl, the action
            // is applied unchanged) times the joint velocity before the step.
            let d = fine.data();
            let qvel = d.qvel().to_vec();
            let gear = 150.0;
            // Motors in models/ant.xml order drive hip_4, ankle_4, hip_1, ankle_1, ... while the
            // joints (qvel after the free joint's 6) run hip_1, ankle_1, ..., hip_4, ankle_4.
            let joint_of_motor = [6, 7, 0, 1, 2, 3, 4, 5];
            let power: f64 = action.iter().zip(joint_of_motor).map(|(a, j)| (gear * a * qvel[6 + j]).abs()).sum();
            let step_energy = power * d.model().timestep();
            by_hand += step_energy;
            let reported = fine.step(&action).unwrap().info.metric("mechanical_energy").unwrap();
            assert!((reported - step_energy).abs() <= 1e-9 * (1.0 + reported), "{reported} vs {step_energy}");
        }
        assert!(
            (energy - by_hand).abs() <= 1e-9 * (1.0 + by_hand),
            "control step {control_step}: reported {energy}, summed by hand {by_hand}"
        );
        if control_step > 2 {
            assert!(energy > 0.0);
        }
    }
}

/// Every MuJoCo env reports its motors' work the same way, so a cost of transport exists for
/// each: HalfCheetah's checked by hand (power = |gear x action x joint velocity| summed over the
/// physics steps), the others present and positive once the robot moves.
#[test]
fn every_env_reports_the_motors_work() {
    let cheetah = |frame_skip: usize| {
        let cfg = EnvConfig::new("half-cheetah")
            .with_overrides(&[
                ("frame_skip".into(), frame_skip.to_string()),
                ("reset_noise_scale".into(), "0.0".into()),
            ])
            .unwrap();
        make(&cfg).unwrap()
    };
    let (mut coarse, mut fine) = (cheetah(5), cheetah(1));
    coarse.reset(Some(1)).unwrap();
    fine.reset(Some(1)).unwrap();
    let action = [0.7, -0.3, 0.5, -0.9, 0.4, -0.6];
    let gear = [120.0, 90.0, 60.0, 120.0, 60.0, 30.0];
    for control_step in 0..10 {
        let energy = coarse.step(&action).unwrap().info.metric("mechanical_energy").unwrap();
        let mut by_hand = 0.0;
        for _ in 0..5 {
            // qvel: rootx, rootz, rooty, then the six joints in motor order.
            let d = fine.data();
            let power: f64 = (0..6).map(|j| (gear[j] * action[j] * d.qvel()[3 + j]).abs()).sum();
            by_hand += power * d.model().timestep();
            fine.step(&action).unwrap();
        }
        assert!(
            (energy - by_hand).abs() <= 1e-9 * (1.0 + by_hand),
            "control step {control_step}: reported {energy}, by hand {by_hand}"
        );
    }
    for name in ["hopper", "walker2d", "humanoid", "inverted-pendulum", "ant", "minitaur"] {
        let mut env = make(&EnvConfig::new(name)).unwrap();
        env.reset(Some(0)).unwrap();
        let action: Vec<f64> = env.spec().action_space.high.iter().map(|h| 0.5 * h).collect();
        let total: f64 = (0..3).map(|_| env.step(&action).unwrap().info.metric("mechanical_energy").unwrap()).sum();
        assert!(total > 0.0 && total.is_finite(), "{name}: {total}");
    }
}
