//! Velocity-command tasks (`minitaur-command`, `ant-command`): the robot is told a forward speed
//! and a yaw rate, which change during the episode, and is rewarded for following them. This is
//! how legged robots are driven and how legged RL is trained today (legged_gym, Rudin et al.,
//! CoRL 2021, `legged_gym/envs/base/legged_robot.py` and `legged_robot_config.py`; MuJoCo
//! Playground's Go1 joystick task): a command is drawn per episode, redrawn at random moments,
//! put in the observation, and tracked through exponential kernels.
//!
//! The task wraps a base environment (PyBullet's Minitaur, Gymnasium's Ant) and keeps its physics,
//! its action space, its falls (`terminated`) and its time limit; it replaces the reward and
//! extends the observation. The base environments stay as they are under their own names.
//!
//! Observation: the base env's, then the base's linear velocity in its heading frame (forward,
//! left, up; m/s), its angular velocity in its body frame (rad/s), and the command (forward speed,
//! yaw rate), as legged_gym's `compute_observations` puts `base_lin_vel`, `base_ang_vel` and
//! `commands` before the joints.
//!
//! Reward, per control step, each term a weight times the control period (legged_gym scales its
//! terms by `dt` the same way, so the weights are per second of simulated time):
//! - `tracking_speed`: exp(-|(v_fwd, v_left) - (command, 0)|^2 / sigma) (legged_gym's
//!   `_reward_tracking_lin_vel`, weight 1.0, sigma 0.25);
//! - `tracking_yaw_rate`: exp(-(yaw rate - command)^2 / sigma) (`_reward_tracking_ang_vel`, 0.5);
//! - `orientation`: -(g_x^2 + g_y^2), gravity in the body frame (`_reward_orientation`);
//! - `body_rates`: -(roll rate^2 + pitch rate^2) (`_reward_ang_vel_xy`, 0.05);
//! - `vertical_velocity`: -v_up^2 (`_reward_lin_vel_z`, 2.0), the body-height term;
//! - `action_rate`: -|a_t - a_{t-1}|^2 over the normalised action (`_reward_action_rate`, 0.01);
//! - `energy`: -(the motors' mechanical work this step, J) / dt, a power;
//! - `feet_air_time`: on the step a foot touches down, the seconds it was in the air less a target
//!   (0.5 s), summed over the feet, and only while the commanded speed is above 0.1 m/s
//!   (`_reward_feet_air_time`, 1.0 there): what is meant to make a policy lift its feet rather
//!   than stand or shuffle. Off by default: the Minitaur's bounding strides are shorter than the
//!   target, and on Ant it taught PPO to hop in place (benches/results/ant-command/README.md);
//! - `positive_clip`: what lifts a negative total to zero when `only_positive_rewards` is on
//!   (legged_gym's default: it "avoids early termination problems", since a step that costs
//!   more than it earns teaches the robot to fall), zero otherwise. The terms still sum to the
//!   reward.
mod process;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

pub use process::{CommandProcess, Schedule};

/// Whether `env` names a command task (`minitaur-command`, `ant-command`).
pub fn is_command_task(env: &str) -> bool {
    super::command_base(env).is_some()
}

/// A command task's (`speed_range`, `yaw_rate_range`), each [low, high].
pub type CommandRanges = ([f64; 2], [f64; 2]);

/// The ranges a command task draws from; None for another env.
pub fn command_ranges(env: &super::EnvConfig) -> Result<Option<CommandRanges>, EnvError> {
    if !is_command_task(&env.name) {
        return Ok(None);
    }
    let resolved = env.resolved_options()?;
    let range = |key: &str| -> Result<[f64; 2], EnvError> {
        let bad = || EnvError::InvalidOption { env: env.name.clone(), message: format!("{key} must be [low, high]") };
        let a = resolved.get(key).and_then(|v| v.as_array()).ok_or_else(bad)?;
        let number = |v: Option<&toml::Value>| v.and_then(|v| v.as_float().or(v.as_integer().map(|i| i as f64)));
        Ok([number(a.first()).ok_or_else(bad)?, number(a.get(1)).ok_or_else(bad)?])
    };
    Ok(Some((range("speed_range")?, range("yaw_rate_range")?)))
}

/// The commands an env will give: its schedule's, or the corners of its ranges; none for an env
/// that is not a command task.
pub fn commands_given(env: &super::EnvConfig) -> Result<Vec<[f64; 2]>, EnvError> {
    let Some((speeds, yaw_rates)) = command_ranges(env)? else { return Ok(Vec::new()) };
    let resolved = env.resolved_options()?;
    let text = resolved.get("schedule").and_then(|s| s.as_str()).unwrap_or_default();
    let schedule = Schedule::parse(text)
        .map_err(|m| EnvError::InvalidOption { env: env.name.clone(), message: format!("schedule: {m}") })?;
    Ok(match schedule {
        Some(s) => s.commands(),
        None => speeds.iter().flat_map(|&v| yaw_rates.iter().map(move |&w| [v, w])).collect(),
    })
}

/// One line per command in `commands` that lies outside the ranges `trained` (a policy's
/// training env) drew from, naming `policy` and its range: what `eval` and `track` warn with.
pub fn outside_training_range(
    trained: &super::EnvConfig,
    commands: &[[f64; 2]],
    policy: &str,
) -> Result<Vec<String>, EnvError> {
    let Some((speeds, yaw_rates)) = command_ranges(trained)? else { return Ok(Vec::new()) };
    let outside = |x: f64, [lo, hi]: [f64; 2]| x < lo - 1e-9 || x > hi + 1e-9;
    let mut lines = Vec::new();
    for &[v, w] in commands {
        if outside(v, speeds) {
            lines.push(format!(
                "command speed {v} m/s lies outside {policy}'s training speed_range [{}, {}]",
                speeds[0], speeds[1]
            ));
        }
        if outside(w, yaw_rates) {
            lines.push(format!(
                "command yaw rate {w} rad/s lies outside {policy}'s training yaw_rate_range [{}, {}]",
                yaw_rates[0], yaw_rates[1]
            ));
        }
    }
    lines.dedup();
    Ok(lines)
}

/// The warnings for playing a policy trained on `trained` in `evaluated`: one line per command
/// `evaluated` will give ([`commands_given`]) outside the training ranges
/// ([`outside_training_range`]). What `eval` prints and Python's `TrainedPolicy.command_warnings`
/// returns.
pub fn command_warnings(
    trained: &super::EnvConfig,
    evaluated: &super::EnvConfig,
    policy: &str,
) -> Result<Vec<String>, EnvError> {
    outside_training_range(trained, &commands_given(evaluated)?, policy)
}

use super::options::{join_wrapped, split_wrapped};
use super::registry::Registered;
use super::simulation::base_state_accessors;
use super::{BoxSpace, Env, EnvError, EnvSpec, Info, Step};
use crate::mujoco::Data;

/// The reward terms of every command task, in the order `Info::reward_terms` lists them.
pub const REWARD_TERMS: [&str; 9] = [
    "tracking_speed",
    "tracking_yaw_rate",
    "orientation",
    "body_rates",
    "vertical_velocity",
    "action_rate",
    "energy",
    "feet_air_time",
    "positive_clip",
];

/// A foot is on the ground when its contacts push it up by more than this (N), legged_gym's
/// `contact_forces[..., 2] > 1.`.
const FOOT_CONTACT_FORCE: f64 = 1.0;
/// Commands slower than this (m/s) earn no `feet_air_time`: standing is not stepping
/// (legged_gym's `norm(commands[:, :2]) > 0.1`).
const STEPPING_SPEED: f64 = 0.1;

/// What a command task adds to its base env's observation: heading-frame linear velocity (3),
/// body-frame angular velocity (3) and the command (2).
pub const EXTRA_OBSERVATIONS: usize = 8;

/// The command and its reward: the options a command task adds to its base env's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CommandSettings {
    /// Forward-speed commands are drawn uniformly from [low, high] (m/s).
    pub speed_range: [f64; 2],
    /// Yaw-rate commands are drawn uniformly from [low, high] (rad/s, positive turning left).
    pub yaw_rate_range: [f64; 2],
    /// Probability that a drawn command is standing still (0, 0), so that stopping is part of
    /// the range (legged_gym zeroes commands below 0.2 m/s to the same end).
    pub standing_probability: f64,
    /// Seconds between redraws, drawn uniformly from [low, high] after every draw. legged_gym
    /// redraws every 10 s, which is a whole Minitaur episode; the default redraws two to four
    /// times per 10 s episode.
    pub resample_time_range: [f64; 2],
    /// A fixed command stream instead of random draws: `time:speed:yaw_rate` knots, e.g.
    /// `0:0.5:0 3:1.0:0 6:1.0:0.3 8:0:0` (commas or semicolons also separate), each held until the
    /// next (times in s, increasing, the
    /// first at 0). Empty: random draws.
    pub schedule: String,
    /// The tracking kernels' width, sigma in exp(-error^2 / sigma) ((m/s)^2 and (rad/s)^2).
    pub tracking_sigma: f64,
    /// Weight of `tracking_speed` (per second).
    pub tracking_speed_weight: f64,
    /// Weight of `tracking_yaw_rate` (per second).
    pub tracking_yaw_rate_weight: f64,
    /// Weight of `orientation` (per second).
    pub orientation_weight: f64,
    /// Weight of `body_rates` (per second).
    pub body_rates_weight: f64,
    /// Weight of `vertical_velocity` (per second).
    pub vertical_velocity_weight: f64,
    /// Weight of `action_rate` (per second).
    pub action_rate_weight: f64,
    /// Weight of `energy` (per watt of mechanical power, per second).
    pub energy_weight: f64,
    /// Weight of `feet_air_time` (per second).
    pub feet_air_time_weight: f64,
    /// Air time (s) a step must exceed to earn `feet_air_time`; shorter steps cost.
    pub feet_air_time_target: f64,
    /// Clip each step's reward at zero from below (the `positive_clip` term).
    pub only_positive_rewards: bool,
    /// The direction the task calls forward, in degrees counter-clockwise from the commanded
    /// body's x axis: the heading frame of the observed velocity and of the speed tracked. 0 is
    /// the body's x axis, as legged_gym measures in the base frame.
    pub forward_angle: f64,
}

impl Default for CommandSettings {
    /// legged_gym's weights (`legged_robot_config.py`, `rewards.scales`) and its
    /// `only_positive_rewards`, with its orientation term (0 there) at 1.0 and an energy term of
    /// ours (legged_gym penalises squared torques instead; 0.001 per W makes random actions on the
    /// Minitaur cost about what walking earns). The speeds span the controller's range and beyond; the turn rates are the ones it
    /// follows.
    fn default() -> Self {
        CommandSettings {
            speed_range: [0.0, 2.5],
            yaw_rate_range: [-0.5, 0.5],
            standing_probability: 0.1,
            resample_time_range: [2.0, 5.0],
            schedule: String::new(),
            tracking_sigma: 0.25,
            tracking_speed_weight: 1.0,
            tracking_yaw_rate_weight: 0.5,
            orientation_weight: 1.0,
            body_rates_weight: 0.05,
            vertical_velocity_weight: 2.0,
            action_rate_weight: 0.01,
            energy_weight: 0.001,
            feet_air_time_weight: 0.0,
            feet_air_time_target: 0.5,
            only_positive_rewards: true,
            forward_angle: 0.0,
        }
    }
}

impl CommandSettings {
    /// Checks what a command's options must satisfy; the error names the option.
    pub fn validate(&self, env: &str) -> Result<(), EnvError> {
        let fail = |message: String| EnvError::InvalidOption { env: env.to_string(), message };
        for (name, r) in [
            ("speed_range", self.speed_range),
            ("yaw_rate_range", self.yaw_rate_range),
            ("resample_time_range", self.resample_time_range),
        ] {
            if !(r[0].is_finite() && r[1].is_finite() && r[0] < r[1]) {
                return Err(fail(format!("{name} must be [low, high] with finite low < high, got {r:?}")));
            }
        }
        if self.resample_time_range[0] <= 0.0 {
            return Err(fail(format!("resample_time_range must be above 0 s, got {:?}", self.resample_time_range)));
        }
        if !(0.0..=1.0).contains(&self.standing_probability) {
            return Err(fail(format!("standing_probability must lie in [0, 1], got {}", self.standing_probability)));
        }
        if !(self.forward_angle.is_finite() && self.forward_angle.abs() <= 180.0) {
            return Err(fail(format!(
                "forward_angle must be a finite number of degrees in [-180, 180], got {}",
                self.forward_angle
            )));
        }
        if !(self.feet_air_time_target.is_finite() && self.feet_air_time_target >= 0.0) {
            return Err(fail(format!(
                "feet_air_time_target must be a finite number of seconds >= 0, got {}",
                self.feet_air_time_target
            )));
        }
        if !(self.tracking_sigma.is_finite() && self.tracking_sigma > 0.0) {
            return Err(fail(format!("tracking_sigma must be a finite number > 0, got {}", self.tracking_sigma)));
        }
        for (name, w) in self.weights() {
            if !(w.is_finite() && w >= 0.0) {
                return Err(fail(format!("{name}_weight must be a finite number >= 0, got {w}")));
            }
        }
        Schedule::parse(&self.schedule).map_err(|e| fail(format!("schedule: {e}")))?;
        Ok(())
    }

    /// Each weighted reward term's weight, in [`REWARD_TERMS`]' order (all but `positive_clip`).
    pub fn weights(&self) -> [(&'static str, f64); 8] {
        [
            ("tracking_speed", self.tracking_speed_weight),
            ("tracking_yaw_rate", self.tracking_yaw_rate_weight),
            ("orientation", self.orientation_weight),
            ("body_rates", self.body_rates_weight),
            ("vertical_velocity", self.vertical_velocity_weight),
            ("action_rate", self.action_rate_weight),
            ("energy", self.energy_weight),
            ("feet_air_time", self.feet_air_time_weight),
        ]
    }
}

/// A command task's options: its base env's and the command's, read from one flat table. The
/// command's keys go to [`CommandSettings`] (missing ones take this base's defaults), every
/// other key to the base env's options, which refuse a key they do not know (serde's `flatten`
/// would accept any).
#[derive(Debug, Clone, PartialEq)]
pub struct CommandOptions<B: CommandBase> {
    /// The base env's options.
    pub base: B::Options,
    /// The command and its reward.
    pub command: CommandSettings,
}

impl<B: CommandBase> Default for CommandOptions<B> {
    fn default() -> Self {
        CommandOptions { base: B::Options::default(), command: B::command_defaults() }
    }
}

impl<B: CommandBase> Serialize for CommandOptions<B> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        join_wrapped(&self.base, &self.command).map_err(serde::ser::Error::custom)?.serialize(serializer)
    }
}

impl<'de, B: CommandBase> Deserialize<'de> for CommandOptions<B> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let table = toml::Table::deserialize(deserializer)?;
        let (base, command) = split_wrapped(table, &B::command_defaults()).map_err(serde::de::Error::custom)?;
        Ok(CommandOptions { base, command })
    }
}

/// A base environment a command task can wrap: the body whose velocity is commanded.
pub trait CommandBase: Registered<Options: Default + Clone + std::fmt::Debug + PartialEq> {
    /// The registered name of the command task on this base.
    const COMMAND_NAME: &'static str;
    /// The body whose velocity is commanded (Minitaur's `base`, Ant's `torso`).
    const BODY: &'static str;
    /// The feet's geoms, whose touchdowns `feet_air_time` counts.
    const FEET: [&'static str; 4];
    /// The command's defaults on this robot.
    fn command_defaults() -> CommandSettings {
        CommandSettings::default()
    }
}

/// The base's motion, read from MuJoCo's state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BaseMotion {
    /// Linear velocity in the heading frame (yaw removed): forward, left, up (m/s).
    pub velocity: [f64; 3],
    /// Angular velocity in the body frame: roll, pitch, yaw rates (rad/s).
    pub angular_velocity: [f64; 3],
    /// Gravity's direction in the body frame (unit vector; (0, 0, -1) when level).
    pub gravity: [f64; 3],
    /// The heading-frame yaw rate (rad/s): the world's vertical angular velocity.
    pub yaw_rate: f64,
}

impl BaseMotion {
    /// The motion of `body`, whose free joint's velocities start at `qvel[dof]`, with the heading
    /// frame's forward axis `forward_angle` radians counter-clockwise from the body's x axis.
    pub fn of(data: &Data, body: usize, dof: usize, forward_angle: f64) -> BaseMotion {
        let r = &data.xmat()[9 * body..9 * body + 9];
        let v = &data.qvel()[dof..dof + 6];
        // MuJoCo's free joint: linear velocity in the world frame, angular in the body frame.
        let yaw = r[3].atan2(r[0]) + forward_angle;
        let (s, c) = yaw.sin_cos();
        let velocity = [c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]];
        let angular_velocity = [v[3], v[4], v[5]];
        // The world's z axis in the body frame is the third row of R (R maps body to world).
        let gravity = [-r[6], -r[7], -r[8]];
        let yaw_rate = r[6] * v[3] + r[7] * v[4] + r[8] * v[5];
        BaseMotion { velocity, angular_velocity, gravity, yaw_rate }
    }
}

/// A velocity-command task over base env `B`.
pub struct CommandEnv<B: CommandBase> {
    base: B,
    settings: CommandSettings,
    spec: EnvSpec,
    body: usize,
    dof: usize,
    process: CommandProcess,
    rng: ChaCha8Rng,
    last_action: Vec<f64>,
    last_obs: Vec<f64>,
    feet: Feet,
}

/// The feet's geoms, and per foot the seconds since it left the ground and whether it touched
/// it at the last step, for `feet_air_time`.
struct Feet {
    geoms: [usize; 4],
    air_time: [f64; 4],
    last_contact: [bool; 4],
}

impl Feet {
    fn reset(&mut self) {
        self.air_time = [0.0; 4];
        self.last_contact = [false; 4];
    }

    /// After a step of `dt` seconds: the summed air time less `target` of the feet that touch
    /// down now, legged_gym's `_reward_feet_air_time` (contact filtered over two steps, since a
    /// foot bounces).
    fn touchdowns(&mut self, data: &Data, dt: f64, target: f64) -> f64 {
        let mut contact = [false; 4];
        for c in data.contacts() {
            for (k, &g) in self.geoms.iter().enumerate() {
                // The normal force, along the contact frame's first row, is positive pushing the
                // geoms apart; a foot is on the ground when it carries more than FOOT_CONTACT_FORCE.
                if (c.geom1 == g || c.geom2 == g) && c.force[0] > FOOT_CONTACT_FORCE {
                    contact[k] = true;
                }
            }
        }
        let mut reward = 0.0;
        for (k, &now) in contact.iter().enumerate() {
            let filtered = now || self.last_contact[k];
            self.last_contact[k] = now;
            let first_contact = self.air_time[k] > 0.0 && filtered;
            self.air_time[k] += dt;
            if first_contact {
                reward += self.air_time[k] - target;
            }
            if filtered {
                self.air_time[k] = 0.0;
            }
        }
        reward
    }
}

/// Mixes the reset seed so the command stream is not the base env's own stream.
const STREAM: u64 = 0x0063_6f6d_6d61_6e64; // "command" in ASCII

impl<B: CommandBase> CommandEnv<B> {
    /// The base env built from `options.base`, with the command from `options.command`.
    pub fn new(options: CommandOptions<B>) -> Result<Self, EnvError> {
        options.command.validate(B::COMMAND_NAME)?;
        let base = B::build(options.base)?;
        let data = base.data();
        let model = data.model();
        let body = model.body_id(B::BODY)?;
        // The commanded body's free joint is the model's first joint: its velocities are qvel[0..6].
        let dof = 0;
        let base_spec = base.spec();
        let spec = EnvSpec {
            name: B::COMMAND_NAME,
            observation_space: BoxSpace::unbounded(base_spec.observation_space.dim() + EXTRA_OBSERVATIONS),
            action_space: base_spec.action_space.clone(),
            dt: base_spec.dt,
            max_episode_steps: base_spec.max_episode_steps,
            reward_terms: REWARD_TERMS.to_vec(),
        };
        let schedule = Schedule::parse(&options.command.schedule).expect("validated");
        let process = CommandProcess::new(&options.command, schedule);
        let act_dim = spec.action_space.dim();
        let mut geoms = [0; 4];
        for (g, name) in geoms.iter_mut().zip(B::FEET) {
            *g = model.geom_id(name)?;
        }
        Ok(CommandEnv {
            base,
            settings: options.command,
            spec,
            body,
            dof,
            process,
            rng: ChaCha8Rng::seed_from_u64(STREAM),
            last_action: vec![0.0; act_dim],
            last_obs: Vec::new(),
            feet: Feet { geoms, air_time: [0.0; 4], last_contact: [false; 4] },
        })
    }

    fn observe(&self, base_obs: Vec<f64>) -> Vec<f64> {
        let m = BaseMotion::of(self.base.data(), self.body, self.dof, self.settings.forward_angle.to_radians());
        let mut obs = base_obs;
        obs.extend(m.velocity);
        obs.extend(m.angular_velocity);
        obs.extend(self.process.current());
        obs
    }

    fn reward_terms(
        &self,
        m: &BaseMotion,
        command: [f64; 2],
        action: &[f64],
        energy: f64,
        air_time: f64,
    ) -> Vec<(&'static str, f64)> {
        let s = &self.settings;
        let dt = self.spec.dt;
        let speed_error = (m.velocity[0] - command[0]).powi(2) + m.velocity[1].powi(2);
        let yaw_error = (m.yaw_rate - command[1]).powi(2);
        let action_rate: f64 = action.iter().zip(&self.last_action).map(|(a, b)| (a - b).powi(2)).sum();
        let raw = [
            (-speed_error / s.tracking_sigma).exp(),
            (-yaw_error / s.tracking_sigma).exp(),
            -(m.gravity[0].powi(2) + m.gravity[1].powi(2)),
            -(m.angular_velocity[0].powi(2) + m.angular_velocity[1].powi(2)),
            -m.velocity[2].powi(2),
            -action_rate,
            -energy.abs() / dt,
            if command[0].abs() > STEPPING_SPEED { air_time / dt } else { 0.0 },
        ];
        let mut terms: Vec<(&'static str, f64)> =
            self.settings.weights().iter().zip(raw).map(|((name, w), r)| (*name, w * r * dt)).collect();
        let total: f64 = terms.iter().map(|(_, v)| v).sum();
        let clip = if s.only_positive_rewards && total < 0.0 { -total } else { 0.0 };
        terms.push(("positive_clip", clip));
        terms
    }
}

impl<B: CommandBase> Env for CommandEnv<B> {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn reset(&mut self, seed: Option<u64>) -> Result<(Vec<f64>, Info), EnvError> {
        let (obs, mut info) = self.base.reset(seed)?;
        if let Some(s) = seed {
            self.rng = ChaCha8Rng::seed_from_u64(s ^ STREAM);
        }
        self.process.reset(&mut self.rng);
        self.last_action = vec![0.0; self.spec.action_space.dim()];
        self.feet.reset();
        let [speed, yaw_rate] = self.process.current();
        info.metrics.extend([("command_speed", speed), ("command_yaw_rate", yaw_rate)]);
        self.last_obs = self.observe(obs);
        Ok((self.last_obs.clone(), info))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let step = self.base.step(action)?;
        let mut info = step.info;
        if info.unstable {
            // The base env truncated the episode: the last good observation, every term zero.
            info.reward_terms = REWARD_TERMS.iter().map(|n| (*n, 0.0)).collect();
            let observation = self.last_obs.clone();
            return Ok(Step { observation, reward: 0.0, terminated: false, truncated: true, info });
        }
        let command = self.process.current();
        let m = BaseMotion::of(self.base.data(), self.body, self.dof, self.settings.forward_angle.to_radians());
        let space = &self.spec.action_space;
        let normalised: Vec<f64> = (0..space.dim())
            .map(|i| {
                2.0 * (action[i].clamp(space.low[i], space.high[i]) - space.low[i]) / (space.high[i] - space.low[i])
                    - 1.0
            })
            .collect();
        let energy = info.metric("mechanical_energy").unwrap_or(0.0);
        // Counted only when it is rewarded: the contact forces cost time.
        let air_time = if self.settings.feet_air_time_weight != 0.0 {
            self.feet.touchdowns(self.base.data(), self.spec.dt, self.settings.feet_air_time_target)
        } else {
            0.0
        };
        info.reward_terms = self.reward_terms(&m, command, &normalised, energy, air_time);
        self.last_action = normalised;
        self.process.advance(self.spec.dt, &mut self.rng);
        info.metrics.extend([
            ("command_speed", command[0]),
            ("command_yaw_rate", command[1]),
            ("forward_velocity", m.velocity[0]),
            ("lateral_velocity", m.velocity[1]),
            ("yaw_rate", m.yaw_rate),
        ]);
        let reward = info.reward_terms.iter().map(|(_, v)| v).sum();
        self.last_obs = self.observe(step.observation);
        Ok(Step {
            observation: self.last_obs.clone(),
            reward,
            terminated: step.terminated,
            truncated: step.truncated,
            info,
        })
    }

    base_state_accessors!();

    /// The command in force now: (forward speed m/s, yaw rate rad/s).
    fn command(&self) -> Option<[f64; 2]> {
        Some(self.process.current())
    }

    fn forward_angle(&self) -> f64 {
        self.settings.forward_angle.to_radians()
    }

    /// Replaces the command from now on (a joystick): the stream's redraws and schedule stop
    /// until the next reset.
    fn set_command(&mut self, speed: f64, yaw_rate: f64) -> Result<(), EnvError> {
        if !(speed.is_finite() && yaw_rate.is_finite()) {
            return Err(EnvError::InvalidOption {
                env: self.spec.name.to_string(),
                message: format!("a command must be finite, got ({speed}, {yaw_rate})"),
            });
        }
        self.process.hold([speed, yaw_rate]);
        Ok(())
    }
}

impl CommandBase for super::Minitaur {
    const COMMAND_NAME: &'static str = "minitaur-command";
    const BODY: &'static str = "base";
    const FEET: [&'static str; 4] = ["foot_fl", "foot_bl", "foot_fr", "foot_br"];
}

impl CommandBase for super::Ant {
    const COMMAND_NAME: &'static str = "ant-command";
    const BODY: &'static str = "torso";
    const FEET: [&'static str; 4] = ["left_ankle_geom", "right_ankle_geom", "third_ankle_geom", "fourth_ankle_geom"];
    /// Ant's motors (gear 150 on unit controls) spend far more power than the Minitaur's (random
    /// actions: about 1.9 kW against 0.16 kW), so its energy weight is a hundredth; its speeds span
    /// the controller's range, from standing to 1.5 m/s. Its forward is 45° left of the torso's
    /// x axis, along a leg: Gymnasium's Ant (`ant.xml`) has its four legs on the torso's
    /// diagonals and no front, and a gait that rows along a leg's direction
    /// (`controller::ant_row`) is faster than one that trots along the x axis.
    fn command_defaults() -> CommandSettings {
        CommandSettings {
            energy_weight: 0.00001,
            speed_range: [0.0, 1.5],
            forward_angle: 45.0,
            ..CommandSettings::default()
        }
    }
}
