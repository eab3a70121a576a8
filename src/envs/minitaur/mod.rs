//! Minitaur as PyBullet's `MinitaurBulletEnv` defines it (bulletphysics/bullet3, `examples/pybullet/gym/pybullet_envs/bullet/minitaur_gym_env.py`): 28-dim observation
//! (motor angles, velocities, observed torques, base quaternion x-y-z-w), 8 actions through the
//! leg model, PD motor model applied every 0.002 s physics step, 100 Hz control, reward
//! distance * dx - energy * |tau . qdot| * dt - drift * |dy| - shake * |dz|, falls end episodes.
pub mod leg_model;
pub mod motor;
pub mod perturb;

use std::f64::consts::FRAC_PI_2;
use std::sync::Arc;

use rand::Rng;
use serde::{Deserialize, Serialize};

use self::leg_model::{motor_angles_from_leg_model, NUM_MOTORS};
use self::motor::{MotorParams, MAX_TORQUE, OBSERVED_TORQUE_LIMIT, OVERHEAT_SECONDS, OVERHEAT_TORQUE};
use super::options::Check;
use super::simulation::{env_core_accessors, unstable_step, EnvCore, Simulation};
use super::{BoxSpace, Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Model;

pub(crate) const MODEL_XML: &str = include_str!("../../../models/minitaur.xml");

/// How actions are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionMode {
    /// 4 swings + 4 extensions in [-1, 1] through the leg model (PyBullet's default).
    Leg,
    /// 8 desired motor angles in [0, pi] tracked by the motor's PD loop.
    MotorAngle,
    /// 8 desired torques in [-3.5, 3.5] N m, passed through the motor's electrical limits.
    Torque,
}

/// PyBullet's `MinitaurBulletEnv-v0` options, with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MinitaurOptions {
    /// Weight of the forward distance travelled per step.
    pub distance_weight: f64,
    /// Weight of the motors' mechanical energy cost.
    pub energy_weight: f64,
    /// Weight of the sideways drift cost.
    pub drift_weight: f64,
    /// Weight of the vertical shaking cost.
    pub shake_weight: f64,
    /// Forward speed (m/s) beyond which the distance term stops paying: each control step pays
    /// for at most this speed times its duration. 0 pays for all distance, as PyBullet does.
    pub max_rewarded_speed: f64,
    /// What the action commands: motor angles (PyBullet's default) or torques.
    pub action_mode: ActionMode,
    /// Fallen when the base's up vector has a world-z component below this.
    pub fall_up_threshold: f64,
    /// Fallen when the base is lower than this (m).
    pub fall_height: f64,
    /// Steps before the episode is truncated.
    pub max_episode_steps: usize,
    /// Physics steps (0.002 s) per control step.
    pub action_repeat: usize,
    /// The motors are held at pi/2 + U(-s, s) during the reset hold.
    pub reset_noise_scale: f64,
    /// Seconds the motors are held at their reset angles before the episode starts.
    pub reset_hold_time: f64,
    /// PyBullet's default randomisation at each reset: masses x U(0.8, 1.2), battery
    /// U(14.8, 16.8) V, motor viscous damping U(0, 0.01), foot friction U(foot_friction_range).
    pub randomize_dynamics: bool,
    /// [low, high] of the feet's sliding friction drawn each episode with the dynamics randomised;
    /// PyBullet's randomiser draws from [0.8, 1.5] (`minitaur_gym_env.py`).
    pub foot_friction_range: [f64; 2],
    /// Motor PD gains (PWM per rad and per rad/s).
    pub motor_kp: f64,
    /// Motor damping gain (PWM per rad/s).
    pub motor_kd: f64,
    /// Switch a motor off after 1 s above 2.45 N m, as the real robot does.
    pub overheat_protection: bool,
    /// Multiplies the sliding friction of every geom, feet and ground (after randomisation).
    pub friction_scale: f64,
    /// Extra mass (kg) carried at the base's centre of mass.
    pub payload_mass: f64,
    /// Moves the base's centre of mass forward by this (m; negative: backward).
    pub com_shift: f64,
    /// Each episode adds a payload drawn uniformly from 0 to this (kg).
    pub random_payload_max: f64,
    /// Each episode moves the base's centre of mass by a shift drawn uniformly from [-this, this]
    /// (m), forward or backward.
    pub random_com_shift_max: f64,
    /// Share of the motors' torque curve they deliver (1: all of it, up to 3.5 N m).
    pub motor_strength: f64,
    /// Battery voltage of every motor (V); 0 keeps PyBullet's: 16 V, or U(14.8, 16.8) when the
    /// dynamics are randomised.
    pub battery_voltage: f64,
    /// With the dynamics randomised, each episode also draws one battery voltage for every motor
    /// from U(this, 16.8) V (for training against a flat battery); 0 leaves PyBullet's draw alone.
    pub random_battery_min: f64,
    /// Delay from an action to the motors acting on it (s), in whole physics steps of 0.002 s:
    /// 0.004 is two sub-steps, 0.01 one control step.
    pub latency: f64,
    /// Each episode adds a latency drawn uniformly from 0 to this (s), in physics steps.
    pub random_latency_max: f64,
    /// Standard deviation of Gaussian noise on the observed motor angles (rad).
    pub noise_angle: f64,
    /// Standard deviation of Gaussian noise on the observed motor velocities (rad/s).
    pub noise_velocity: f64,
    /// The observed orientation is turned by a random rotation with this standard deviation
    /// about each axis (rad).
    pub noise_orientation: f64,
    /// Rough terrain: 0.2 m square tiles each raised by U(0, this) m, drawn anew every episode
    /// (flat around the start); 0 is flat ground.
    pub terrain_step_height: f64,
    /// Ground slope (degrees, positive uphill along +x), modelled by tilting gravity.
    pub slope: f64,
    /// Each episode adds a slope drawn uniformly from [-this, this] degrees.
    pub random_slope_max: f64,
    /// Random shoves as PyBullet's push randomiser gives them (from control step 100, every 200
    /// steps, 10 steps long, any horizontal direction), each a velocity change U(0, this) m/s;
    /// 0 is off.
    pub random_push_max: f64,
}

impl Default for MinitaurOptions {
    fn default() -> Self {
        MinitaurOptions {
            distance_weight: 1.0,
            energy_weight: 0.005,
            drift_weight: 0.0,
            shake_weight: 0.0,
            max_rewarded_speed: 0.0,
            action_mode: ActionMode::Leg,
            fall_up_threshold: 0.85,
            fall_height: 0.13,
            max_episode_steps: 1000,
            action_repeat: 5,
            reset_noise_scale: 0.0,
            reset_hold_time: 0.2,
            randomize_dynamics: true,
            foot_friction_range: [0.8, 1.5],
            motor_kp: 1.0,
            motor_kd: 0.02,
            overheat_protection: true,
            friction_scale: 1.0,
            payload_mass: 0.0,
            com_shift: 0.0,
            random_payload_max: 0.0,
            random_com_shift_max: 0.0,
            motor_strength: 1.0,
            battery_voltage: 0.0,
            random_battery_min: 0.0,
            latency: 0.0,
            random_latency_max: 0.0,
            noise_angle: 0.0,
            noise_velocity: 0.0,
            noise_orientation: 0.0,
            terrain_step_height: 0.0,
            slope: 0.0,
            random_slope_max: 0.0,
            random_push_max: 0.0,
        }
    }
}

impl MinitaurOptions {
    /// Checks each option's range; the error names the option.
    pub fn validate(&self) -> Result<(), EnvError> {
        let c = Check { env: "minitaur" };
        c.non_negative("distance_weight", self.distance_weight)?;
        c.non_negative("energy_weight", self.energy_weight)?;
        c.non_negative("drift_weight", self.drift_weight)?;
        c.non_negative("shake_weight", self.shake_weight)?;
        c.non_negative("max_rewarded_speed", self.max_rewarded_speed)?;
        c.within("fall_up_threshold", self.fall_up_threshold, -1.0, 1.0)?;
        c.non_negative("fall_height", self.fall_height)?;
        c.positive_count("max_episode_steps", self.max_episode_steps)?;
        c.positive_count("action_repeat", self.action_repeat)?;
        c.within("reset_noise_scale", self.reset_noise_scale, 0.0, 0.5)?;
        c.within("reset_hold_time", self.reset_hold_time, 0.0, 10.0)?;
        c.non_negative("motor_kp", self.motor_kp)?;
        c.non_negative("motor_kd", self.motor_kd)?;
        perturb::validate(self)
    }
}

/// Indices of one motor in the model.
#[derive(Debug, Clone, Copy)]
struct MotorJoint {
    qpos: usize,
    dof: usize,
}

/// PyBullet's Minitaur quadruped on MuJoCo, with its motor model, reward and falls.
pub struct Minitaur {
    opts: MinitaurOptions,
    base_model: Arc<Model>,
    core: EnvCore,
    motors: [MotorJoint; NUM_MOTORS],
    base_body: usize,
    foot_geoms: Vec<usize>,
    params: [MotorParams; NUM_MOTORS],
    observed_torque: [f64; NUM_MOTORS],
    applied_torque: [f64; NUM_MOTORS],
    overheat_time: [f64; NUM_MOTORS],
    enabled: [bool; NUM_MOTORS],
    /// This episode's perturbations: the commands in flight, the ground, the shoves.
    delay: perturb::Delay<Command>,
    terrain: perturb::Terrain,
    pushes: perturb::RandomPushes,
    control_step: usize,
}

/// Physics step of the Minitaur model (s).
pub const SIM_DT: f64 = 0.002;

impl Minitaur {
    /// Builds the environment; fails on an invalid option.
    pub fn new(opts: MinitaurOptions) -> Result<Self, EnvError> {
        opts.validate()?;
        let base_model = Arc::new(Model::from_xml_str(&perturb::model_xml(MODEL_XML, &opts))?);
        let sim = Simulation::from_model(Arc::clone(&base_model))?;
        let m = &base_model;
        let trn = m.actuator_trnid();
        let mut motors = [MotorJoint { qpos: 0, dof: 0 }; NUM_MOTORS];
        for (i, motor) in motors.iter_mut().enumerate() {
            let joint = trn[2 * i] as usize;
            *motor = MotorJoint { qpos: m.joint_qpos_adr(joint), dof: m.joint_dof_adr(joint) };
        }
        let foot_geoms =
            ["foot_fl", "foot_bl", "foot_fr", "foot_br"].iter().map(|n| m.geom_id(n)).collect::<Result<Vec<_>, _>>()?;
        let action_space = match opts.action_mode {
            ActionMode::Leg => BoxSpace::uniform(NUM_MOTORS, -1.0, 1.0),
            ActionMode::MotorAngle => BoxSpace::uniform(NUM_MOTORS, 0.0, std::f64::consts::PI),
            ActionMode::Torque => BoxSpace::uniform(NUM_MOTORS, -MAX_TORQUE, MAX_TORQUE),
        };
        let params = Self::nominal_motor(&opts);
        let speed = MotorParams { kp: opts.motor_kp, kd: opts.motor_kd, ..MotorParams::default() }.speed_limit();
        let mut low = vec![-std::f64::consts::PI; 8];
        low.extend([-speed; 8]);
        low.extend([-OBSERVED_TORQUE_LIMIT; 8]);
        low.extend([-1.0; 4]);
        let high = low.iter().map(|v| -v).collect();
        let spec = EnvSpec {
            name: "minitaur",
            observation_space: BoxSpace::new(low, high),
            action_space,
            dt: SIM_DT * opts.action_repeat as f64,
            max_episode_steps: opts.max_episode_steps,
            reward_terms: vec!["distance", "energy", "drift", "shake"],
        };
        let base_body = m.body_id("base")?;
        let repeat = opts.action_repeat;
        Ok(Minitaur {
            params: [params; NUM_MOTORS],
            opts,
            base_model,
            core: EnvCore::new(sim, spec),
            motors,
            base_body,
            foot_geoms,
            observed_torque: [0.0; NUM_MOTORS],
            applied_torque: [0.0; NUM_MOTORS],
            overheat_time: [0.0; NUM_MOTORS],
            enabled: [true; NUM_MOTORS],
            delay: perturb::Delay::new(0, repeat),
            terrain: perturb::Terrain::default(),
            pushes: perturb::RandomPushes::default(),
            control_step: 0,
        })
    }

    fn nominal_motor(o: &MinitaurOptions) -> MotorParams {
        let mut p =
            MotorParams { kp: o.motor_kp, kd: o.motor_kd, strength: o.motor_strength, ..MotorParams::default() };
        if o.battery_voltage > 0.0 {
            p.voltage = o.battery_voltage;
        }
        p
    }

    /// The options it was built with.
    pub fn options(&self) -> &MinitaurOptions {
        &self.opts
    }

    /// Motor angles in the observation's convention (radians from straight up).
    pub fn motor_angles(&self) -> [f64; NUM_MOTORS] {
        std::array::from_fn(|i| self.core.sim.data.qpos()[self.motors[i].qpos])
    }

    pub(crate) fn motor_velocities(&self) -> [f64; NUM_MOTORS] {
        std::array::from_fn(|i| self.core.sim.data.qvel()[self.motors[i].dof])
    }

    /// Torques applied to the joints during the last physics step.
    pub fn applied_torques(&self) -> [f64; NUM_MOTORS] {
        self.applied_torque
    }

    /// The base's position in world coordinates (m).
    pub fn base_position(&self) -> [f64; 3] {
        let p = &self.core.sim.data.xpos()[3 * self.base_body..];
        [p[0], p[1], p[2]]
    }

    /// World-z component of the base's up axis.
    pub fn base_up_z(&self) -> f64 {
        self.core.sim.data.xmat()[9 * self.base_body + 8]
    }

    /// The ground's height (m) under (x, y) this episode: the terrain's tile there, 0 on flat
    /// ground.
    pub fn ground_height(&self, x: f64, y: f64) -> f64 {
        self.terrain.height_at(x, y)
    }

    pub(crate) fn is_fallen(&self) -> bool {
        let p = self.base_position();
        let ground = self.ground_height(p[0], p[1]);
        self.base_up_z() < self.opts.fall_up_threshold || p[2] - ground < self.opts.fall_height
    }

    fn observation(&mut self) -> Vec<f64> {
        let mut obs = Vec::with_capacity(28);
        obs.extend(self.motor_angles());
        obs.extend(self.motor_velocities());
        obs.extend(self.observed_torque);
        let q = &self.core.sim.data.xquat()[4 * self.base_body..4 * self.base_body + 4];
        obs.extend([q[1], q[2], q[3], q[0]]);
        perturb::add_noise(&mut obs, &self.opts, self.core.rng.rng());
        obs
    }

    /// One physics step with the motors driven towards `targets` (angles) or by `torques`.
    fn physics_step(&mut self, command: &Command) -> Result<(bool, f64), EnvError> {
        let angles = self.motor_angles();
        let velocities = self.motor_velocities();
        let mut ctrl = [0.0; NUM_MOTORS];
        let mut power = 0.0;
        for i in 0..NUM_MOTORS {
            let p = &self.params[i];
            let pwm = match command {
                Command::Angles(t) => p.pwm_for_angle(t[i], angles[i], velocities[i]),
                Command::Torques(t) => p.pwm_for_torque(t[i]),
            };
            let (applied, observed) = p.torque(pwm, velocities[i]);
            let applied = if self.enabled[i] { applied } else { 0.0 };
            if self.opts.overheat_protection {
                self.overheat_time[i] =
                    if applied.abs() > OVERHEAT_TORQUE { self.overheat_time[i] + SIM_DT } else { 0.0 };
                if self.overheat_time[i] >= OVERHEAT_SECONDS {
                    self.enabled[i] = false;
                }
            }
            self.observed_torque[i] = if self.enabled[i] { observed } else { 0.0 };
            self.applied_torque[i] = applied;
            ctrl[i] = applied;
            power += (applied * velocities[i]).abs();
        }
        self.core.sim.data.set_ctrl(&ctrl)?;
        let unstable = self.core.sim.step_once()?;
        Ok((unstable, power * SIM_DT))
    }

    /// The model of one episode: PyBullet's randomised dynamics when asked for, then the
    /// perturbations the options set. Draws from the episode's stream in that order.
    fn episode_simulation(&mut self) -> Result<Simulation, EnvError> {
        let mut model = self.base_model.try_clone()?;
        let rng = self.core.rng.rng();
        if self.opts.randomize_dynamics {
            for m in model.body_mass_mut().iter_mut().skip(1) {
                *m *= rng.random_range(0.8..1.2);
            }
            let [low, high] = self.opts.foot_friction_range;
            let friction = rng.random_range(low..high);
            let friction_all = model.geom_friction_mut();
            for &g in &self.foot_geoms {
                friction_all[3 * g] = friction;
            }
            for p in self.params.iter_mut() {
                p.voltage = rng.random_range(14.8..16.8);
                p.viscous_damping = rng.random_range(0.0..0.01);
                if self.opts.battery_voltage > 0.0 {
                    p.voltage = self.opts.battery_voltage;
                }
            }
            // One battery feeds every motor. Drawn after PyBullet's draws, so that an env without
            // this option draws exactly what it did before.
            if self.opts.random_battery_min > 0.0 {
                let voltage = rng.random_range(self.opts.random_battery_min..16.8);
                if self.opts.battery_voltage == 0.0 {
                    self.params.iter_mut().for_each(|p| p.voltage = voltage);
                }
            }
        }
        self.terrain = perturb::edit_model(&mut model, &self.opts, self.base_body, rng)?;
        Simulation::from_model(Arc::new(model))
    }
}

#[derive(Debug, Clone)]
enum Command {
    Angles([f64; NUM_MOTORS]),
    Torques([f64; NUM_MOTORS]),
}

impl Env for Minitaur {
    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        self.core.rng.reseed(seed);
        self.params = [Self::nominal_motor(&self.opts); NUM_MOTORS];
        if self.opts.randomize_dynamics || perturb::edits_model(&self.opts) {
            self.core.sim = self.episode_simulation()?;
        } else if !Arc::ptr_eq(&self.core.sim.model, &self.base_model) {
            self.core.sim = Simulation::from_model(Arc::clone(&self.base_model))?;
        }
        let latency = perturb::latency_steps(&self.opts, self.core.rng.rng(), SIM_DT);
        self.delay = perturb::Delay::new(latency, self.opts.action_repeat);
        self.pushes = perturb::RandomPushes::default();
        self.control_step = 0;
        self.enabled = [true; NUM_MOTORS];
        self.overheat_time = [0.0; NUM_MOTORS];
        self.observed_torque = [0.0; NUM_MOTORS];
        self.applied_torque = [0.0; NUM_MOTORS];

        let noise = self.core.rng.uniform(NUM_MOTORS, self.opts.reset_noise_scale);
        let mut qpos_noise = vec![0.0; self.core.sim.model.nq()];
        for (i, n) in noise.iter().enumerate() {
            qpos_noise[self.motors[i].qpos] = *n;
        }
        let nv = self.core.sim.model.nv();
        self.core.sim.reset_to(&qpos_noise, &vec![0.0; nv])?;
        let hold = Command::Angles(std::array::from_fn(|i| FRAC_PI_2 + noise[i]));
        let hold_steps = (self.opts.reset_hold_time / SIM_DT).round() as usize;
        for _ in 0..hold_steps {
            if self.physics_step(&hold)?.0 {
                return Err(EnvError::Mujoco(crate::mujoco::MjError::Engine(
                    "Minitaur physics became unstable during the reset hold".into(),
                )));
            }
        }
        crate::mujoco::take_warnings();
        self.core.clock.start();
        self.core.last_obs = self.observation();
        let p = self.base_position();
        let info = Info {
            metrics: vec![("x_position", p[0]), ("y_position", p[1]), ("base_height", p[2])],
            ..Info::default()
        };
        Ok((self.core.last_obs.clone(), info))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let start = self.core.begin_step(action)?;
        let (action, clipped) = (&start.action, start.clipped);
        let command = match self.opts.action_mode {
            ActionMode::Leg => Command::Angles(motor_angles_from_leg_model(action)),
            ActionMode::MotorAngle => Command::Angles(std::array::from_fn(|i| action[i])),
            ActionMode::Torque => Command::Torques(std::array::from_fn(|i| action[i])),
        };
        let before = self.base_position();
        let mut mechanical_energy = 0.0;
        let mut unstable = false;
        let step = self.control_step;
        self.control_step += 1;
        self.delay.send(step, command);
        if self.opts.random_push_max > 0.0 {
            let mass: f64 = self.core.sim.model.body_mass().iter().sum();
            let f = self.pushes.force(step, &self.opts, mass, self.core.spec.dt, self.core.rng.rng());
            let applied = self.core.sim.data.qfrc_applied_mut();
            applied[0] = f[0];
            applied[1] = f[1];
        }
        let hold = Command::Angles([FRAC_PI_2; NUM_MOTORS]);
        for j in 0..self.opts.action_repeat {
            // Until the first action reaches the motors they hold the reset pose.
            let command = self.delay.acting(step * self.opts.action_repeat + j).unwrap_or(&hold).clone();
            let (bad, energy) = self.physics_step(&command)?;
            mechanical_energy += energy;
            if bad {
                unstable = true;
                break;
            }
        }
        let warnings = crate::mujoco::take_warnings();
        if unstable {
            self.core.clock.finish_if(true);
            return Ok(unstable_step(&self.core.last_obs, &self.core.spec, clipped, warnings));
        }
        let after = self.base_position();
        let (dx, dy, dz) = (after[0] - before[0], after[1] - before[1], after[2] - before[2]);
        // PyBullet's energy term: |observed torque . velocity| times one physics step.
        let velocities = self.motor_velocities();
        let power: f64 = self.observed_torque.iter().zip(&velocities).map(|(t, v)| t * v).sum();
        let o = &self.opts;
        let paid_dx = if o.max_rewarded_speed > 0.0 { dx.min(o.max_rewarded_speed * self.core.spec.dt) } else { dx };
        let distance = o.distance_weight * paid_dx;
        let energy = -o.energy_weight * power.abs() * SIM_DT;
        let drift = -o.drift_weight * dy.abs();
        let shake = -o.shake_weight * dz.abs();
        let info = Info {
            reward_terms: vec![("distance", distance), ("energy", energy), ("drift", drift), ("shake", shake)],
            metrics: vec![
                ("x_position", after[0]),
                ("y_position", after[1]),
                ("base_height", after[2]),
                ("x_velocity", dx / self.core.spec.dt),
                ("dx", dx),
                ("dy", dy),
                ("dz", dz),
                ("up_z", self.base_up_z()),
                ("mechanical_energy", mechanical_energy),
                ("motors_disabled", self.enabled.iter().filter(|e| !**e).count() as f64),
            ],
            clipped_actions: clipped,
            unstable: false,
            warnings,
        };
        let terminated = self.is_fallen();
        let observation = self.observation();
        Ok(self.core.finish_step(observation, terminated, info))
    }

    env_core_accessors!();
}

#[cfg(test)]
mod tests {
    use super::*;

    fn voltages(opts: MinitaurOptions, seeds: std::ops::Range<u64>) -> Vec<[f64; NUM_MOTORS]> {
        let mut e = Minitaur::new(opts).unwrap();
        seeds
            .map(|s| {
                e.reset(Some(s)).unwrap();
                e.params.map(|p| p.voltage)
            })
            .collect()
    }

    /// `random_battery_min` draws one battery for all eight motors per episode from U(min, 16.8);
    /// without it PyBullet's per-motor U(14.8, 16.8) draws stay as they were.
    #[test]
    fn a_random_battery_feeds_every_motor_one_voltage_from_its_range() {
        let flat = voltages(MinitaurOptions { random_battery_min: 6.0, ..Default::default() }, 0..40);
        for v in &flat {
            assert!(v.iter().all(|&x| x == v[0]) && (6.0..16.8).contains(&v[0]), "{v:?}");
        }
        assert!(flat.iter().any(|v| v[0] < 10.0) && flat.iter().any(|v| v[0] > 13.0));
        for v in voltages(MinitaurOptions::default(), 0..10) {
            assert!(v.iter().all(|x| (14.8..16.8).contains(x)) && v.iter().any(|&x| x != v[0]), "{v:?}");
        }
        // a fixed battery wins over the draw
        let fixed =
            voltages(MinitaurOptions { random_battery_min: 6.0, battery_voltage: 9.0, ..Default::default() }, 0..3);
        assert!(fixed.iter().all(|v| v.iter().all(|&x| x == 9.0)));
        let bad =
            Minitaur::new(MinitaurOptions { random_battery_min: 6.0, randomize_dynamics: false, ..Default::default() });
        assert!(bad.err().unwrap().to_string().contains("random_battery_min"));
        let bad = Minitaur::new(MinitaurOptions { random_battery_min: 20.0, ..Default::default() });
        assert!(bad.err().unwrap().to_string().contains("random_battery_min"));
    }

    /// `foot_friction_range` sets the bounds of PyBullet's per-episode foot friction draw and
    /// nothing else: the masses before it and the motor draws after it are those of the default.
    #[test]
    fn the_foot_friction_is_drawn_from_its_range_and_the_other_draws_stay() {
        let draws = |opts: MinitaurOptions| {
            let mut e = Minitaur::new(opts).unwrap();
            (0..40)
                .map(|s| {
                    e.reset(Some(s)).unwrap();
                    let m = e.core.sim.data.model();
                    let feet: Vec<f64> = e.foot_geoms.iter().map(|&g| m.geom_friction()[3 * g]).collect();
                    (feet, m.body_mass().to_vec(), e.params.map(|p| (p.voltage, p.viscous_damping)))
                })
                .collect::<Vec<_>>()
        };
        let nominal = draws(MinitaurOptions::default());
        let wide = draws(MinitaurOptions { foot_friction_range: [0.4, 2.2], ..Default::default() });
        for ((feet0, mass0, motors0), (feet, mass, motors)) in nominal.iter().zip(&wide) {
            assert!(feet0.iter().all(|&f| f == feet0[0] && (0.8..1.5).contains(&f)), "{feet0:?}");
            assert!(feet.iter().all(|&f| f == feet[0] && (0.4..2.2).contains(&f)), "{feet:?}");
            assert_eq!((mass0, motors0), (mass, motors));
        }
        let wide_feet: Vec<f64> = wide.iter().map(|(f, _, _)| f[0]).collect();
        assert!(wide_feet.iter().any(|&f| f < 0.8) && wide_feet.iter().any(|&f| f > 1.5), "{wide_feet:?}");
        for bad in [[1.5, 0.8], [1.0, 1.0], [-0.2, 1.0], [0.5, f64::NAN]] {
            let err = Minitaur::new(MinitaurOptions { foot_friction_range: bad, ..Default::default() });
            assert!(err.err().unwrap().to_string().contains("foot_friction_range"), "{bad:?}");
        }
        let off = MinitaurOptions { foot_friction_range: [0.4, 2.2], randomize_dynamics: false, ..Default::default() };
        assert!(Minitaur::new(off).err().unwrap().to_string().contains("randomize_dynamics"));
    }
}
