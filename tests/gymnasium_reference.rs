//! locobench's environments against Gymnasium's own v5 environments (MuJoCo 4.0): same initial
//! state (reset noise 0), same actions, compare observations and rewards step by step.
//! The reference files come from `tests/reference/make_gymnasium_reference.py`.
//!
//! MuJoCo versions differ (Debian's 2.2.2 here): HalfCheetah and InvertedPendulum have no
//! version-sensitive contact paths and must agree to rounding; Humanoid and Ant contacts diverge
//! slowly between versions (measured here, docs/environments.md), so they are compared over
//! their first steps only.
//! Walker2d agrees to rounding through its contacts; Hopper's contacts (margin 0.001, condim 1
//! geoms) part between the versions, so it is compared before its foot lands.
use locobench::envs::{make, EnvConfig};

fn action(t: usize, n: usize, scale: f64) -> Vec<f64> {
    (0..n).map(|i| scale * ((t * 7 + i * 3) as f64 * 0.37).sin()).collect()
}

struct Row {
    reward: f64,
    terminated: bool,
    obs: Vec<f64>,
}

fn load(name: &str) -> Vec<Row> {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("tests/reference/{name}.csv"));
    let text = std::fs::read_to_string(&path).unwrap();
    text.lines()
        .skip(1)
        .map(|line| {
            let f: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
            Row { reward: f[1], terminated: f[2] != 0.0, obs: f[3..].to_vec() }
        })
        .collect()
}

/// Largest absolute difference in observation and reward over the first `steps` steps.
fn max_difference(name: &str, scale: f64, steps: usize) -> (f64, f64) {
    let rows = load(name);
    let cfg = EnvConfig::new(name).with_overrides(&[("reset_noise_scale".into(), "0.0".into())]).unwrap();
    let mut env = make(&cfg).unwrap();
    let n = env.spec().action_space.dim();
    let (obs, _) = env.reset(Some(0)).unwrap();
    let diff = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    assert_eq!(obs.len(), rows[0].obs.len());
    let mut worst_obs = diff(&obs, &rows[0].obs);
    let mut worst_reward: f64 = 0.0;
    for (t, row) in rows.iter().enumerate().skip(1).take(steps) {
        let s = env.step(&action(t - 1, n, scale)).unwrap();
        worst_obs = worst_obs.max(diff(&s.observation, &row.obs));
        worst_reward = worst_reward.max((s.reward - row.reward).abs());
        assert_eq!(s.terminated, row.terminated, "{name} step {t}");
        if s.done() {
            break;
        }
    }
    (worst_obs, worst_reward)
}

#[test]
fn half_cheetah_matches_gymnasium() {
    let (obs, reward) = max_difference("half-cheetah", 0.5, 200);
    assert!(obs < 1e-9 && reward < 1e-9, "obs {obs:e} reward {reward:e}");
}

#[test]
fn inverted_pendulum_matches_gymnasium() {
    let (obs, reward) = max_difference("inverted-pendulum", 0.5, 200);
    assert!(obs < 1e-9 && reward < 1e-9, "obs {obs:e} reward {reward:e}");
}

#[test]
fn humanoid_matches_gymnasium_over_the_first_steps() {
    // Measured: 1.3e-5 after 10 steps; the feet reach the floor around step 20 and the
    // versions' contact solutions then part.
    let (obs, reward) = max_difference("humanoid", 0.3, 10);
    assert!(obs < 1e-4 && reward < 1e-4, "obs {obs:e} reward {reward:e}");
}

#[test]
fn ant_matches_gymnasium_before_contact() {
    // Measured: 1.1e-6 after 3 steps; from step 5 on, contact dynamics differ between versions.
    let (obs, reward) = max_difference("ant", 0.5, 3);
    assert!(obs < 1e-5 && reward < 1e-5, "obs {obs:e} reward {reward:e}");
}

#[test]
fn walker2d_matches_gymnasium_through_contact_and_termination() {
    // Measured: 7e-14 over the whole reference episode (68 steps, ends by falling).
    let (obs, reward) = max_difference("walker2d", 0.5, 100);
    assert!(obs < 1e-9 && reward < 1e-9, "obs {obs:e} reward {reward:e}");
}

#[test]
fn hopper_matches_gymnasium_before_contact() {
    // Measured: 2e-15 over the first 10 steps; the foot lands at step 11 and MuJoCo 2.2.2 and
    // 4.0 then part (4e-2 by step 15). Under one MuJoCo (4.0, `compare_models.py`) this model
    // and Gymnasium's agree to 1e-14 over 100 steps with contact, so the model is the same.
    let (obs, reward) = max_difference("hopper", 0.5, 10);
    assert!(obs < 1e-9 && reward < 1e-9, "obs {obs:e} reward {reward:e}");
}
