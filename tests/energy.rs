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
