//! The Raibert/QP baseline's walking targets, with fixed seeds and the environments' default
//! (honest) physics: PyBullet's dynamics randomisation on, full motor model, overheat cut-off.
use locobench::controller::baseline::{baseline_controller, baseline_env};
use locobench::controller::gait::GaitKind;
use locobench::controller::measure::{measure, GaitEpisode};
use locobench::envs::make;

fn run(env: &str, speed: f64, gait: Option<GaitKind>) -> Vec<GaitEpisode> {
    let mut e = make(&baseline_env(env).unwrap()).unwrap();
    let mut c = baseline_controller(env, speed, gait).unwrap();
    measure(e.as_mut(), c.as_mut(), 10, 0, speed).unwrap()
}

#[test]
fn minitaur_at_0_35_walks_without_falling_near_the_set_point() {
    let eps = run("minitaur", 0.35, None);
    let good = eps.iter().filter(|e| !e.fell && e.length == 1000 && (e.mean_speed - 0.35).abs() <= 0.2 * 0.35).count();
    assert!(good >= 9, "only {good}/10 episodes walked 1000 steps within 20% of 0.35 m/s: {eps:?}");
}

#[test]
fn minitaur_at_1_0_rarely_falls() {
    let eps = run("minitaur", 1.0, None);
    let standing = eps.iter().filter(|e| !e.fell).count();
    assert!(standing >= 8, "{standing}/10 without a fall");
    assert!(eps.iter().all(|e| e.mean_speed > 0.5), "{eps:?}");
}

#[test]
fn ant_at_0_5_does_not_fall_and_moves_forward() {
    let eps = run("ant", 0.5, None);
    assert!(eps.iter().all(|e| !e.fell && e.length == 1000), "{eps:?}");
    assert!(eps.iter().all(|e| e.mean_speed > 0.0), "{eps:?}");
}

#[test]
fn wrong_env_or_mode_is_a_clear_error() {
    assert!(baseline_env("humanoid").is_err());
    assert!(baseline_controller("ant", 0.5, Some(GaitKind::Bound)).is_err());
    assert!(baseline_controller("minitaur", f64::NAN, None).is_err());
    // The Minitaur controller refuses the leg-model action mode (it commands torques).
    let mut env = make(&locobench::envs::EnvConfig::new("minitaur")).unwrap();
    let mut c = baseline_controller("minitaur", 0.35, None).unwrap();
    let err = measure(env.as_mut(), c.as_mut(), 1, 0, 0.35).unwrap_err();
    assert!(err.to_string().contains("torque"), "{err}");
}
