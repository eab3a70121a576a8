//! Raibert-style gait controller for Minitaur with QP stance-force distribution.
//!
//! Minitaur bounds by default (front pair, then back pair), with legs overlapping in stance
//! (duty factor 0.7). A trot is available but falls on this robot: with no abduction, a
//! diagonal support pair cannot resist rolling and the feet cannot be placed sideways to catch
//! it (measured: at 0.35 m/s no trot episode lasted beyond about 3 s). In a bound both support
//! feet straddle the body, so roll is controlled through their vertical forces, and pitch
//! through Raibert's fore-aft foot placement, which the legs can do.
//!
//! Every control tick: the gait scheduler says which legs are in stance. Stance legs: a body PD
//! gives the desired planar wrench (forward force to track the speed set-point, vertical force
//! for weight and height, pitching moment for attitude); the clarabel QP spreads it over the
//! stance feet within the friction pyramid; each leg's torques are tau = -J^T f through the
//! four-bar Jacobian. Swing legs: Raibert's foothold (T_st/2) v + k (v - v_des) ahead of the
//! hip, reached along a raised arc, tracked in leg space (inverse kinematics + joint PD).
//! It drives the environment in its torque action mode, so it is scored by the same reward.
use anyhow::{bail, Context, Result};
use nalgebra::{Matrix3, Vector3};

use super::command::{integrate_speed_error, wrap_angle, Command, HeadingFrame};
use super::force_qp::{Dimension, ForceQp};
use super::fourbar;
use super::gait::{gait_telemetry, GaitKind, GaitScheduler, LEGS, LEG_NAMES};
use super::raibert_foothold;
use crate::envs::Env;
use crate::mujoco::Data;
use crate::policy::{Policy, Telemetry};

#[derive(Debug, Clone)]
pub(crate) struct MinitaurGaitParams {
    /// Forward speed profile and yaw rate (on a command task: the task's stream instead).
    pub command: Command,
    /// Built for a command task: named after it rather than after `command`.
    pub(crate) on_command_task: bool,
    pub gait: GaitKind,
    pub(crate) stance_duration: f64,
    pub(crate) duty_factor: f64,
    pub(crate) body_height: f64,
    /// Raibert speed-correction gain k.
    pub(crate) foothold_gain: f64,
    pub(crate) swing_clearance: f64,
    pub(crate) kp_height: f64,
    pub(crate) kd_height: f64,
    pub(crate) kd_speed: f64,
    /// Integral gain on the speed error (1/s^2): removes the steady lag of the pure damping term.
    pub(crate) ki_speed: f64,
    pub(crate) kp_yaw: f64,
    pub(crate) kd_yaw: f64,
    /// Integral gain on the heading error (1/s^3) while a turn is commanded: removes the turn's
    /// steady lag. Straight walking has no such lag and keeps the plain PD, because the integral
    /// of heading noise costs balance at speed (measured at 1.5 m/s: 2 falls in 10 with it, none
    /// without).
    pub(crate) ki_yaw: f64,
    pub(crate) kp_pitch: f64,
    pub(crate) kd_pitch: f64,
    pub(crate) swing_kp: f64,
    pub(crate) swing_kd: f64,
    /// The swing gain grows with the commanded speed, swing_kp x clamp(|v| / this, 1, 2): a
    /// swing lasts about 43 ms whatever the speed while the stride grows with it, and with the
    /// low-speed gain the feet landed 10-11 cm short of their footholds at 1.1-1.2 m/s and the
    /// robot fell (`baseline --limits`; benches/results/2026-11-23-amd-epyc-controller/NOTES.md). A stiffer
    /// swing at low speed only costs energy.
    pub(crate) swing_gain_speed: f64,
    /// Friction coefficient the force QP assumes: the lowest foot friction PyBullet's
    /// randomisation draws (0.8).
    pub friction: f64,
}

impl Default for MinitaurGaitParams {
    fn default() -> Self {
        MinitaurGaitParams {
            command: Command::straight(0.35, 1.0),
            on_command_task: false,
            gait: GaitKind::Bound,
            stance_duration: 0.1,
            duty_factor: 0.7,
            body_height: 0.18,
            foothold_gain: 0.03,
            swing_clearance: 0.04,
            kp_height: 300.0,
            kd_height: 30.0,
            kd_speed: 25.0,
            ki_speed: 20.0,
            kp_yaw: 40.0,
            kd_yaw: 10.0,
            ki_yaw: 50.0,
            kp_pitch: 200.0,
            kd_pitch: 10.0,
            swing_kp: 3.0,
            swing_kd: 0.05,
            swing_gain_speed: 0.75,
            friction: 0.8,
        }
    }
}

/// What the controller counted over an episode, including where it ran into the robot's limits
/// (`MinitaurController::limits`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct ControllerStats {
    pub(crate) ticks: u64,
    pub qp_failures: u64,
    /// Motor commands, and those the 3.5 N m limit clipped (stance and swing legs).
    pub(crate) motor_commands: u64,
    pub stance_torque_clipped: u64,
    pub swing_torque_clipped: u64,
    /// Stance foot-ticks, those whose QP force lies on the friction cone, and those whose foot
    /// slid more than 5 mm over the tick (0.5 m/s).
    pub(crate) stance_ticks: u64,
    pub on_friction_cone: u64,
    pub slipping: u64,
    /// Swing foot-ticks, and those whose target lay outside the four-bar's reach.
    pub(crate) swing_ticks: u64,
    pub(crate) out_of_reach: u64,
    /// Touchdowns, and the summed horizontal distance from foot to target at touchdown (m).
    pub(crate) touchdowns: u64,
    pub(crate) touchdown_miss: f64,
}

/// How fast the speed set-point follows a command task's speed (m/s^2): the straight-line
/// command's ramp (1.5 m/s within `baseline::RAMP_TIME`, 1 s).
const COMMAND_ACCELERATION: f64 = 1.5;

/// On a command task, the command its observation ends with: (speed m/s, yaw rate rad/s).
fn observed_command(spec: &crate::envs::EnvSpec, obs: &[f64]) -> Option<[f64; 2]> {
    (spec.name == "minitaur-command").then(|| [obs[obs.len() - 2], obs[obs.len() - 1]])
}

/// Where each leg's motors sit in the action vector: (outer, inner).
fn motor_slots(leg: usize) -> (usize, usize) {
    if leg < 2 {
        (2 * leg, 2 * leg + 1)
    } else {
        (2 * leg + 1, 2 * leg)
    }
}

pub(crate) struct MinitaurController {
    pub params: MinitaurGaitParams,
    gait: GaitScheduler,
    qp: ForceQp,
    time: f64,
    /// Integral of the forward-speed error (m).
    speed_integral: f64,
    /// Commanded heading, the integral of the yaw-rate command (rad).
    heading_goal: f64,
    /// On a command task: the speed set-point, moving towards the command (m/s).
    reference: Option<f64>,
    /// Integral of the heading error (rad s).
    heading_integral: f64,
    was_stance: [bool; LEGS],
    liftoff: [Vector3<f64>; LEGS],
    /// Each foot's position at the previous tick (slip measure).
    last_foot: [Option<Vector3<f64>>; LEGS],
    pub stats: ControllerStats,
    /// The latest swing targets (world), for recorders.
    pub foot_targets: [Vector3<f64>; LEGS],
    /// Stance flags and phase progress each leg had during the latest tick.
    last_phase: [(bool, f64); LEGS],
}

impl MinitaurController {
    pub fn new(params: MinitaurGaitParams) -> Result<MinitaurController> {
        anyhow::ensure!(params.gait != GaitKind::Row, "rowing is a gait of Ant's, not Minitaur's");
        let gait = GaitScheduler::new(params.gait, params.stance_duration, params.duty_factor)?;
        params.command.validate()?;
        let qp = ForceQp::new(Dimension::Planar, params.friction, 2.0, 80.0, vec![1.0, 1.0, 20.0, 20.0, 20.0], 1e-4);
        Ok(MinitaurController {
            params,
            gait,
            qp,
            time: 0.0,
            speed_integral: 0.0,
            heading_goal: 0.0,
            reference: None,
            heading_integral: 0.0,
            was_stance: [true; LEGS],
            liftoff: [Vector3::zeros(); LEGS],
            last_foot: [None; LEGS],
            stats: ControllerStats::default(),
            foot_targets: [Vector3::zeros(); LEGS],
            last_phase: [(true, 0.0); LEGS],
        })
    }

    fn site(d: &Data, name: &str) -> Result<Vector3<f64>> {
        let id = d.model().site_id(name)?;
        let p = &d.site_xpos()[3 * id..3 * id + 3];
        Ok(Vector3::new(p[0], p[1], p[2]))
    }

    /// Torques (actuator order) for the current state.
    pub fn torques(&mut self, env: &dyn Env, obs: &[f64]) -> Result<[f64; 8]> {
        let spec = env.spec();
        if !["minitaur", "minitaur-command"].contains(&spec.name) || spec.action_space.high[0] < 1.5 {
            bail!(
                "the Minitaur controller needs the minitaur or minitaur-command env in its torque action mode \
                 (action_mode = \"torque\")"
            );
        }
        let d = env.data();
        let m = d.model();
        let dt = spec.dt;
        let p = &self.params;
        let base = m.body_id("base")?;
        let r = Matrix3::from_row_slice(&d.xmat()[9 * base..9 * base + 9]);
        let q = d.qpos();
        let v = d.qvel();
        let vel = Vector3::new(v[0], v[1], v[2]);
        // Base angular velocity: MuJoCo's free joint gives it in the body frame.
        let omega = r * Vector3::new(v[3], v[4], v[5]);
        // Heading frame: yaw only. Speeds, footholds and the force QP live in it, so the same
        // laws hold whichever way the robot faces.
        let frame = HeadingFrame::new(&r, vel, omega);
        let (yaw, heading, body) = (frame.yaw, frame.heading, frame.body);
        let to_heading = heading.inverse();
        let pitch = (-body[(2, 0)]).atan2(body[(0, 0)]);
        let roll = body[(2, 1)].atan2(body[(2, 2)]);
        let (local_vel, local_omega) = (frame.velocity, frame.angular_velocity);
        let masses = m.body_mass();
        let total_mass: f64 = masses.iter().sum();
        let com = masses.iter().enumerate().fold(Vector3::zeros(), |acc, (b, mass)| {
            acc + Vector3::new(d.xipos()[3 * b], d.xipos()[3 * b + 1], d.xipos()[3 * b + 2]) * *mass
        }) / total_mass;
        let g = -m.gravity()[2];
        if self.stats.ticks == 0 {
            self.heading_goal = yaw;
        }
        let (v_des, yaw_rate_des) = match observed_command(spec, obs) {
            // A command task's stream: its speed reached at a bounded acceleration.
            Some([speed, yaw_rate]) => {
                let v = self.reference.unwrap_or(local_vel.x.max(0.0));
                let step = COMMAND_ACCELERATION * dt;
                let v = v + (speed - v).clamp(-step, step);
                self.reference = Some(v);
                (v, yaw_rate)
            }
            None => (p.command.speed.at(self.time), p.command.yaw_rate),
        };

        let legs = self.gait.legs();
        self.last_phase = legs.map(|l| (l.in_stance, l.progress));
        let angles: [f64; 8] = std::array::from_fn(|i| obs[i]);
        let speeds: [f64; 8] = std::array::from_fn(|i| obs[8 + i]);
        let mut tau = [0.0; 8];

        // Speed error integral, bounded so that a stumble cannot wind it up.
        let speed_error = v_des - local_vel.x;
        self.speed_integral = integrate_speed_error(self.speed_integral, speed_error, dt, p.kd_speed, p.ki_speed);

        // Stance: body wrench -> QP -> torques.
        let stance: Vec<usize> = (0..LEGS).filter(|&l| legs[l].in_stance).collect();
        if !stance.is_empty() {
            let fx = total_mass * (p.kd_speed * speed_error + p.ki_speed * self.speed_integral);
            let fz = total_mass * (g + p.kp_height * (p.body_height - q[2]) - p.kd_height * vel.z);
            // Body inertia (kg m^2), the order of the real robot's.
            let (inertia_x, inertia_y, inertia_z) = (0.03, 0.12, 0.12);
            let mx = inertia_x * (-p.kp_pitch * roll - p.kd_pitch * local_omega.x);
            let my = inertia_y * (-p.kp_pitch * pitch - p.kd_pitch * local_omega.y);
            let heading_error = wrap_angle(self.heading_goal - yaw);
            if yaw_rate_des != 0.0 {
                self.heading_integral = (self.heading_integral + heading_error * dt).clamp(-0.5, 0.5);
            }
            let mz = inertia_z
                * (p.kp_yaw * heading_error
                    + p.ki_yaw * self.heading_integral
                    + p.kd_yaw * (yaw_rate_des - local_omega.z));
            let feet: Vec<Vector3<f64>> = stance
                .iter()
                .map(|&l| Self::site(d, &format!("foot_{}", LEG_NAMES[l])).map(|f| to_heading * (f - com)))
                .collect::<Result<_>>()?;
            let forces = match self.qp.solve(&feet, &[fx, fz.max(0.0), mx, my, mz]) {
                Ok(f) => f,
                Err(_) => {
                    // Fall back to sharing the weight equally.
                    self.stats.qp_failures += 1;
                    stance.iter().flat_map(|_| [0.0, total_mass * g / stance.len() as f64]).collect()
                }
            };
            for (k, &leg) in stance.iter().enumerate() {
                let (fx, fz) = (forces[2 * k], forces[2 * k + 1]);
                self.stats.stance_ticks += 1;
                self.stats.on_friction_cone += (fx.abs() >= p.friction * fz * (1.0 - 1e-6)) as u64;
                let world = heading * Vector3::new(fx, 0.0, fz);
                let local = r.transpose() * world;
                let (o, i) = motor_slots(leg);
                let t = fourbar::torques_for_ground_force(angles[o], angles[i], [local.x, local.z])
                    .context("stance leg outside the four-bar's reach")?;
                tau[o] = t[0];
                tau[i] = t[1];
            }
        }

        // Swing: Raibert foothold along a raised arc, tracked in leg space. Each hip has its own
        // forward speed when turning (v - w y), so the outer legs take longer strides.
        let forward = heading * Vector3::x();
        let swing_kp = p.swing_kp * (v_des.abs() / p.swing_gain_speed).clamp(1.0, 2.0);
        for leg in 0..LEGS {
            let name = LEG_NAMES[leg];
            let foot = Self::site(d, &format!("foot_{name}"))?;
            let moved = self.last_foot[leg].map(|last| (foot - last).xy().norm());
            self.last_foot[leg] = Some(foot);
            if legs[leg].in_stance {
                if !self.was_stance[leg] {
                    self.stats.touchdowns += 1;
                    self.stats.touchdown_miss += (foot - self.foot_targets[leg]).xy().norm();
                } else if moved.is_some_and(|m| m > 0.005) {
                    self.stats.slipping += 1;
                }
                self.was_stance[leg] = true;
                continue;
            }
            self.stats.swing_ticks += 1;
            if self.was_stance[leg] {
                self.liftoff[leg] = foot;
                self.was_stance[leg] = false;
            }
            let hip = Self::site(d, &format!("hip_{name}"))?;
            let lateral = (to_heading * (hip - com)).y;
            let hip_speed = local_vel.x - local_omega.z * lateral;
            let hip_speed_des = v_des - yaw_rate_des * lateral;
            let offset = raibert_foothold(p.stance_duration, [hip_speed, 0.0], [hip_speed_des, 0.0], p.foothold_gain);
            // Aim where the hip will be at touchdown.
            let remaining = (1.0 - legs[leg].progress) * self.gait.swing_duration();
            let mut target = hip + forward * (hip_speed * remaining + offset[0]);
            target.z = 0.0;
            self.foot_targets[leg] = target;
            let s = legs[leg].progress;
            let blend = 0.5 - 0.5 * (std::f64::consts::PI * s).cos();
            let lift = p.swing_clearance * (std::f64::consts::PI * s).sin();
            let desired = self.liftoff[leg] + (target - self.liftoff[leg]) * blend + Vector3::z() * lift;
            let local = r.transpose() * (desired - hip);
            let (o, i) = motor_slots(leg);
            match fourbar::inverse([local.x, local.z]) {
                Some(goal) => {
                    tau[o] = swing_kp * (goal[0] - angles[o]) - p.swing_kd * speeds[o];
                    tau[i] = swing_kp * (goal[1] - angles[i]) - p.swing_kd * speeds[i];
                }
                None => self.stats.out_of_reach += 1,
            }
        }

        self.heading_goal = wrap_angle(self.heading_goal + yaw_rate_des * dt);
        self.gait.advance(dt);
        self.time += dt;
        self.stats.ticks += 1;
        self.stats.motor_commands += 8;
        for (leg, phase) in legs.iter().enumerate() {
            let (o, i) = motor_slots(leg);
            let clipped = [tau[o], tau[i]].iter().filter(|t| t.abs() > 3.5).count() as u64;
            if phase.in_stance {
                self.stats.stance_torque_clipped += clipped;
            } else {
                self.stats.swing_torque_clipped += clipped;
            }
        }
        Ok(tau.map(|t| t.clamp(-3.5, 3.5)))
    }

    /// Where the controller ran into the robot's limits this episode, as fractions (and the mean
    /// touchdown miss in metres): what sets the highest speed it sustains.
    pub fn limits(&self) -> Vec<(&'static str, f64)> {
        let s = &self.stats;
        let frac = |n: u64, d: u64| if d == 0 { 0.0 } else { n as f64 / d as f64 };
        vec![
            ("stance_torque_clipped", frac(s.stance_torque_clipped, s.motor_commands)),
            ("swing_torque_clipped", frac(s.swing_torque_clipped, s.motor_commands)),
            ("on_friction_cone", frac(s.on_friction_cone, s.stance_ticks)),
            ("slipping", frac(s.slipping, s.stance_ticks)),
            ("out_of_reach", frac(s.out_of_reach, s.swing_ticks)),
            ("touchdown_miss_m", if s.touchdowns == 0 { 0.0 } else { s.touchdown_miss / s.touchdowns as f64 }),
        ]
    }
}

impl Policy for MinitaurController {
    fn name(&self) -> String {
        let gait = format!("{:?}", self.params.gait).to_lowercase();
        if self.params.on_command_task {
            format!("raibert-{gait}@command")
        } else {
            self.params.command.controller_name(&gait)
        }
    }
    fn begin_episode(&mut self, _episode: usize) {
        self.gait.reset();
        self.time = 0.0;
        self.speed_integral = 0.0;
        self.heading_goal = 0.0;
        self.reference = None;
        self.heading_integral = 0.0;
        self.was_stance = [true; LEGS];
        self.last_foot = [None; LEGS];
        self.stats = ControllerStats::default();
    }
    fn act(&mut self, env: &dyn Env, observation: &[f64]) -> Result<Vec<f64>> {
        Ok(self.torques(env, observation)?.to_vec())
    }
    fn diagnostics(&self) -> Vec<(&'static str, f64)> {
        let mut d = vec![("ticks", self.stats.ticks as f64), ("qp_failures", self.stats.qp_failures as f64)];
        d.extend(self.limits());
        d
    }
    fn telemetry(&self) -> Telemetry {
        gait_telemetry(&self.last_phase, |leg| {
            let t = self.foot_targets[leg];
            [t.x, t.y, t.z]
        })
    }
}
