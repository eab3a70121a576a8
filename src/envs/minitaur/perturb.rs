//! What the world does to Minitaur beyond PyBullet's default randomisation: ground friction,
//! payload, motor strength and battery, control latency, sensor noise, rough terrain, slopes and
//! random shoves. Each is an option of the env (so training and evaluation use the same code);
//! all are off by default, and off they draw nothing from the episode's random stream, so a
//! nominal env steps exactly as before.
//!
//! The random shoves follow PyBullet's push randomiser (bulletphysics/bullet3,
//! `examples/pybullet/gym/pybullet_envs/minitaur/envs/env_randomizers/minitaur_push_randomizer.py`):
//! from control step 100, every 200 steps, a horizontal force in a random direction for 10 steps.
//! Its size is given here as the velocity change it would give the whole robot, as the
//! evaluation's pushes are.
use std::f64::consts::PI;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::MinitaurOptions;
use crate::envs::options::Check;
pub(crate) use crate::envs::world::Delay;
use crate::envs::world::{delay_steps, edit_body_and_ground};
use crate::envs::EnvError;
use crate::mujoco::Model;

/// Side of one terrain tile (m) and the heightfield's sample spacing (m).
const TILE: f64 = 0.2;
const SAMPLE: f64 = 0.05;
/// The terrain spans x in [-2, 22] m and y in [-3, 3] m; the robot starts at the origin on a flat
/// patch |x|, |y| < `FLAT` m.
const TERRAIN_X: [f64; 2] = [-2.0, 22.0];
const TERRAIN_HALF_Y: f64 = 3.0;
const FLAT: f64 = 0.6;
/// The highest terrain step the model represents (m): above this a foot (0.2 m below the
/// motors when standing) cannot be placed on the next tile.
pub(crate) const MAX_STEP_HEIGHT: f64 = 0.1;
/// PyBullet's push randomiser schedule, in control steps.
const PUSH_START: usize = 100;
const PUSH_INTERVAL: usize = 200;
const PUSH_DURATION: usize = 10;

/// Every perturbation option: what the held-out protocol resets to nominal, so a policy trained
/// under perturbations is evaluated in the same world as every other.
pub const OPTIONS: [&str; 18] = [
    "friction_scale",
    "foot_friction_range",
    "payload_mass",
    "com_shift",
    "random_payload_max",
    "random_com_shift_max",
    "motor_strength",
    "battery_voltage",
    "random_battery_min",
    "latency",
    "random_latency_max",
    "noise_angle",
    "noise_velocity",
    "noise_orientation",
    "terrain_step_height",
    "slope",
    "random_slope_max",
    "random_push_max",
];

/// An option that changes one of PyBullet's randomised draws means nothing without them.
fn drawn_with_randomized_dynamics(name: &str, o: &MinitaurOptions) -> Result<(), EnvError> {
    if o.randomize_dynamics {
        return Ok(());
    }
    Err(EnvError::InvalidOption {
        env: "minitaur".into(),
        message: format!("{name} draws with the randomised dynamics: set randomize_dynamics = true"),
    })
}

/// Checks the perturbation options; the error names the option.
pub(crate) fn validate(o: &MinitaurOptions) -> Result<(), EnvError> {
    let c = Check { env: "minitaur" };
    c.within("friction_scale", o.friction_scale, 0.0, 10.0)?;
    c.range("foot_friction_range", o.foot_friction_range)?;
    for bound in o.foot_friction_range {
        c.within("foot_friction_range", bound, 0.0, 10.0)?;
    }
    if o.foot_friction_range != MinitaurOptions::default().foot_friction_range {
        drawn_with_randomized_dynamics("foot_friction_range", o)?;
    }
    c.within("payload_mass", o.payload_mass, 0.0, 60.0)?;
    c.within("com_shift", o.com_shift, -0.3, 0.3)?;
    c.within("random_payload_max", o.random_payload_max, 0.0, 60.0)?;
    c.within("random_com_shift_max", o.random_com_shift_max, 0.0, 0.3)?;
    // The fixed and the random part together stay within the single option's range.
    for (name, fixed, random, limit) in [
        ("random_com_shift_max", o.com_shift.abs(), o.random_com_shift_max, 0.3),
        ("random_payload_max", o.payload_mass, o.random_payload_max, 60.0),
    ] {
        if fixed + random > limit {
            let message =
                format!("{name} {random} on top of the fixed {fixed} can exceed {limit}, the most the model takes");
            return Err(EnvError::InvalidOption { env: "minitaur".into(), message });
        }
    }
    c.within("motor_strength", o.motor_strength, 0.0, 2.0)?;
    if o.battery_voltage != 0.0 {
        c.within("battery_voltage", o.battery_voltage, 1.0, 50.0)?;
    }
    if o.random_battery_min != 0.0 {
        c.within("random_battery_min", o.random_battery_min, 1.0, 16.7)?;
        drawn_with_randomized_dynamics("random_battery_min", o)?;
    }
    c.within("latency", o.latency, 0.0, 0.5)?;
    c.within("random_latency_max", o.random_latency_max, 0.0, 0.5)?;
    c.within("noise_angle", o.noise_angle, 0.0, 1.0)?;
    c.within("noise_velocity", o.noise_velocity, 0.0, 100.0)?;
    c.within("noise_orientation", o.noise_orientation, 0.0, 1.0)?;
    c.within("terrain_step_height", o.terrain_step_height, 0.0, MAX_STEP_HEIGHT)?;
    c.within("slope", o.slope, -30.0, 30.0)?;
    c.within("random_slope_max", o.random_slope_max, 0.0, 30.0)?;
    c.within("random_push_max", o.random_push_max, 0.0, 5.0)
}

/// The model text with a heightfield over the floor when the terrain is rough.
pub(crate) fn model_xml(base: &str, o: &MinitaurOptions) -> String {
    if o.terrain_step_height <= 0.0 {
        return base.to_string();
    }
    let (rx, ry) = (0.5 * (TERRAIN_X[1] - TERRAIN_X[0]), TERRAIN_HALF_Y);
    let ncol = (2.0 * rx / SAMPLE).round() as usize + 1;
    let nrow = (2.0 * ry / SAMPLE).round() as usize + 1;
    let asset = format!(
        "<asset>\n    <hfield name=\"terrain\" nrow=\"{nrow}\" ncol=\"{ncol}\" size=\"{rx} {ry} {h} 0.05\"/>",
        h = o.terrain_step_height
    );
    // Only the feet touch the terrain (collision bit 2): a heightfield against every link of
    // the legs costs several times a flat step, and a link that touches the ground before its
    // foot does is a fall in all but name.
    let geom = format!(
        "<geom name=\"terrain\" type=\"hfield\" hfield=\"terrain\" pos=\"{} 0 0\" material=\"floor\" contype=\"0\" \
         conaffinity=\"2\" friction=\"0.1 0.005 0.0001\"/>\n    <body name=\"base\"",
        0.5 * (TERRAIN_X[0] + TERRAIN_X[1])
    );
    let foot = "<default class=\"foot\">\n      <geom ";
    assert!(base.contains(foot), "the Minitaur model has a foot class");
    base.replacen("<asset>", &asset, 1).replacen("<body name=\"base\"", &geom, 1).replacen(
        foot,
        &format!("{foot}contype=\"3\" "),
        1,
    )
}

/// The terrain of one episode: each tile's height as a fraction of the step height.
#[derive(Debug, Clone, Default)]
pub(crate) struct Terrain {
    heights: Vec<f64>,
    columns: usize,
    step_height: f64,
}

impl Terrain {
    fn tiles() -> (usize, usize) {
        let cols = ((TERRAIN_X[1] - TERRAIN_X[0]) / TILE).ceil() as usize;
        let rows = (2.0 * TERRAIN_HALF_Y / TILE).ceil() as usize;
        (rows, cols)
    }

    fn tile_of(x: f64, y: f64) -> Option<(usize, usize)> {
        let (rows, cols) = Self::tiles();
        let (c, r) = ((x - TERRAIN_X[0]) / TILE, (y + TERRAIN_HALF_Y) / TILE);
        (c >= 0.0 && r >= 0.0 && (c as usize) < cols && (r as usize) < rows).then_some((r as usize, c as usize))
    }

    /// Draws every tile's height, U(0, 1), flat near the start.
    fn draw(rng: &mut ChaCha8Rng, step_height: f64) -> Terrain {
        let (rows, cols) = Self::tiles();
        let mut heights = vec![0.0; rows * cols];
        for r in 0..rows {
            for c in 0..cols {
                let x = TERRAIN_X[0] + (c as f64 + 0.5) * TILE;
                let y = -TERRAIN_HALF_Y + (r as f64 + 0.5) * TILE;
                let u: f64 = rng.random();
                let flat = x.abs() < FLAT && y.abs() < FLAT;
                heights[r * cols + c] = if flat { 0.0 } else { u };
            }
        }
        Terrain { heights, columns: cols, step_height }
    }

    /// Ground height (m) under (x, y); 0 off the terrain.
    pub(crate) fn height_at(&self, x: f64, y: f64) -> f64 {
        if self.heights.is_empty() {
            return 0.0;
        }
        Self::tile_of(x, y).map_or(0.0, |(r, c)| self.step_height * self.heights[r * self.columns + c])
    }

    /// Writes the tiles into the model's heightfield samples.
    fn write(&self, model: &mut Model) {
        let (nrow, ncol, data) = model.hfield_data_mut(0);
        let dx = (TERRAIN_X[1] - TERRAIN_X[0]) / (ncol - 1) as f64;
        let dy = 2.0 * TERRAIN_HALF_Y / (nrow - 1) as f64;
        for r in 0..nrow {
            for c in 0..ncol {
                let (x, y) = (TERRAIN_X[0] + c as f64 * dx, -TERRAIN_HALF_Y + r as f64 * dy);
                // A sample on a tile edge takes the tile it starts, so each tile is a flat top.
                let tile = Self::tile_of(x.min(TERRAIN_X[1] - 1e-9), y.min(TERRAIN_HALF_Y - 1e-9));
                data[r * ncol + c] = tile.map_or(0.0, |(tr, tc)| self.heights[tr * self.columns + tc]) as f32;
            }
        }
    }
}

/// Whether resets must rebuild the model (anything the model holds is perturbed).
pub(crate) fn edits_model(o: &MinitaurOptions) -> bool {
    o.friction_scale != 1.0
        || o.payload_mass != 0.0
        || o.com_shift != 0.0
        || o.random_payload_max > 0.0
        || o.random_com_shift_max > 0.0
        || o.terrain_step_height > 0.0
        || o.slope != 0.0
        || o.random_slope_max > 0.0
}

/// Applies the model-side perturbations of one episode to a fresh copy of the model, drawing
/// from `rng` only what the options randomise. Returns the episode's terrain.
pub(crate) fn edit_model(
    model: &mut Model,
    o: &MinitaurOptions,
    base_body: usize,
    rng: &mut ChaCha8Rng,
) -> Result<Terrain, EnvError> {
    // Drawn only when randomised, so the other options' draws stay where they were.
    let mut payload = o.payload_mass;
    if o.random_payload_max > 0.0 {
        payload += rng.random_range(0.0..=o.random_payload_max);
    }
    let mut com_shift = o.com_shift;
    if o.random_com_shift_max > 0.0 {
        com_shift += rng.random_range(-o.random_com_shift_max..=o.random_com_shift_max);
    }
    let mut slope = o.slope;
    if o.random_slope_max > 0.0 {
        slope += rng.random_range(-o.random_slope_max..=o.random_slope_max);
    }
    edit_body_and_ground(model, base_body, o.friction_scale, payload, com_shift, slope);
    if o.terrain_step_height > 0.0 {
        let terrain = Terrain::draw(rng, o.terrain_step_height);
        terrain.write(model);
        return Ok(terrain);
    }
    Ok(Terrain::default())
}

/// Physics steps of delay for one episode: the fixed latency plus its random part.
pub(crate) fn latency_steps(o: &MinitaurOptions, rng: &mut ChaCha8Rng, sim_dt: f64) -> usize {
    let fixed = delay_steps(o.latency, sim_dt);
    if o.random_latency_max > 0.0 {
        fixed + rng.random_range(0..=delay_steps(o.random_latency_max, sim_dt))
    } else {
        fixed
    }
}

/// Gaussian noise on the observation: motor angles, velocities, and the orientation turned by a
/// small random rotation.
pub(crate) fn add_noise(obs: &mut [f64], o: &MinitaurOptions, rng: &mut ChaCha8Rng) {
    let mut normal = |scale: f64| -> f64 {
        let z: f64 = StandardNormal.sample(rng);
        scale * z
    };
    if o.noise_angle > 0.0 {
        obs[..8].iter_mut().for_each(|a| *a += normal(o.noise_angle));
    }
    if o.noise_velocity > 0.0 {
        obs[8..16].iter_mut().for_each(|v| *v += normal(o.noise_velocity));
    }
    if o.noise_orientation > 0.0 {
        let r = [normal(o.noise_orientation), normal(o.noise_orientation), normal(o.noise_orientation)];
        let angle = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        if angle > 0.0 {
            let s = (0.5 * angle).sin() / angle;
            let d = [r[0] * s, r[1] * s, r[2] * s, (0.5 * angle).cos()];
            let q = [obs[24], obs[25], obs[26], obs[27]];
            // d * q, both x-y-z-w.
            let out = [
                d[3] * q[0] + d[0] * q[3] + d[1] * q[2] - d[2] * q[1],
                d[3] * q[1] - d[0] * q[2] + d[1] * q[3] + d[2] * q[0],
                d[3] * q[2] + d[0] * q[1] - d[1] * q[0] + d[2] * q[3],
                d[3] * q[3] - d[0] * q[0] - d[1] * q[1] - d[2] * q[2],
            ];
            obs[24..28].copy_from_slice(&out);
        }
    }
}

/// PyBullet's push randomiser: the horizontal force (N, world x and y) at control step `step`.
#[derive(Debug, Clone, Default)]
pub(crate) struct RandomPushes {
    force: [f64; 2],
}

impl RandomPushes {
    /// The force for control step `step`, drawing a new shove at the start of each interval.
    pub fn force(&mut self, step: usize, o: &MinitaurOptions, mass: f64, dt: f64, rng: &mut ChaCha8Rng) -> [f64; 2] {
        if step < PUSH_START {
            return [0.0; 2];
        }
        let phase = (step - PUSH_START) % PUSH_INTERVAL;
        if phase == 0 {
            let dv = rng.random_range(0.0..=o.random_push_max);
            let theta = rng.random_range(0.0..2.0 * PI);
            let f = mass * dv / (PUSH_DURATION as f64 * dt);
            self.force = [f * theta.cos(), f * theta.sin()];
        }
        if phase < PUSH_DURATION {
            self.force
        } else {
            [0.0; 2]
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_are_flat_topped_and_the_start_is_flat() {
        let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(1);
        let t = Terrain::draw(&mut rng, 0.05);
        assert_eq!(t.height_at(0.0, 0.0), 0.0);
        assert_eq!(t.height_at(0.1, 0.05), t.height_at(0.15, 0.1));
        let far = t.height_at(3.05, 0.3);
        assert!(far > 0.0 && far <= 0.05, "{far}");
        assert_eq!(t.height_at(3.05, 0.3), t.height_at(3.19, 0.39));
        assert_eq!(t.height_at(100.0, 0.0), 0.0);
    }

    #[test]
    fn orientation_noise_keeps_a_unit_quaternion() {
        let o = MinitaurOptions { noise_orientation: 0.1, ..Default::default() };
        let mut rng = <ChaCha8Rng as rand::SeedableRng>::seed_from_u64(2);
        let mut obs = vec![0.0; 28];
        obs[27] = 1.0;
        add_noise(&mut obs, &o, &mut rng);
        let norm: f64 = obs[24..28].iter().map(|v| v * v).sum();
        assert!((norm - 1.0).abs() < 1e-12);
        assert!(obs[27] < 1.0 && obs[..24].iter().all(|v| *v == 0.0));
    }
}
