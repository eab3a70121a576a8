//! Raibert-style trotting controller for Ant with 3D QP force distribution.
//!
//! Diagonal pairs trot (legs 1+3, then 2+4). Stance legs: a body PD gives the desired wrench
//! (speed tracking, height, attitude and heading); the clarabel QP spreads it over the stance
//! feet within the friction pyramid; torques tau = -J^T f with J the foot's translational
//! Jacobian over the leg's hip and ankle (each column: joint axis x (foot - anchor), from
//! MuJoCo's joint frames). Swing legs: the ankle lifts the foot and the hip swings it forward to
//! a Raibert foothold, (T_st/2) v + k (v - v_des) ahead of the hip's neutral reach, converted
//! to a hip angle; tracked by joint PD. Runs through the env's ordinary action (gear 150).
use anyhow::{bail, Result};
use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

use super::command::{integrate_speed_error, wrap_angle, Command, HeadingFrame};
use super::force_qp::{Dimension, ForceQp};
use super::gait::{GaitKind, GaitScheduler, LEGS};
use super::raibert_foothold;
use crate::envs::Env;
use crate::mujoco::Data;
use crate::policy::{Policy, Telemetry};

/// Ant's legs in the scheduler's order (FL, BL, FR, BR): leg 1 (+x+y), leg 2 (-x+y), leg 4
/// (+x-y), leg 3 (-x-y), so a trot pairs legs 1+3 and 2+4.
const ANT_LEGS: [usize; LEGS] = [1, 2, 4, 3];

#[derive(Debug, Clone)]
pub(crate) struct AntGaitParams {
    /// Forward speed profile and yaw rate.
    pub command: Command,
    pub(crate) stance_duration: f64,
    pub(crate) duty_factor: f64,
    pub(crate) body_height: f64,
    pub(crate) foothold_gain: f64,
    pub(crate) kp_height: f64,
    pub(crate) kd_height: f64,
    pub(crate) kd_speed: f64,
    /// Integral gain on the forward-speed error (1/s^2).
    pub(crate) ki_speed: f64,
    pub(crate) kp_attitude: f64,
    pub(crate) kd_attitude: f64,
    /// Ankle angle magnitude while in swing (rad; the range is 30-70 degrees).
    pub(crate) swing_ankle: f64,
    pub(crate) joint_kp: f64,
    pub(crate) joint_kd: f64,
    pub friction: f64,
}

impl Default for AntGaitParams {
    fn default() -> Self {
        AntGaitParams {
            command: Command::straight(0.5, 1.0),
            stance_duration: 0.25,
            duty_factor: 0.6,
            body_height: 0.55,
            foothold_gain: 0.05,
            kp_height: 100.0,
            kd_height: 10.0,
            kd_speed: 30.0,
            ki_speed: 20.0,
            kp_attitude: 100.0,
            kd_attitude: 10.0,
            swing_ankle: 0.55,
            joint_kp: 60.0,
            joint_kd: 3.0,
            friction: 0.8,
        }
    }
}

struct Leg {
    hip_joint: usize,
    ankle_joint: usize,
    hip_act: usize,
    ankle_act: usize,
    foot_site: usize,
    /// +1 when a positive hip angle moves the foot forward.
    forward_sign: f64,
    /// Sign of the ankle range (+1 for 30..70 degrees, -1 for -70..-30).
    ankle_sign: f64,
}

pub(crate) struct AntController {
    pub params: AntGaitParams,
    gait: GaitScheduler,
    qp: ForceQp,
    legs: Option<Vec<Leg>>,
    pub qp_failures: u64,
    time: f64,
    speed_integral: f64,
    heading_goal: f64,
    /// Stance flags and phase progress per leg during the latest tick, for recorders.
    last_phase: [(bool, f64); LEGS],
    /// Where each swing foot lands when its hip reaches the touchdown angle (world).
    foot_targets: [[f64; 3]; LEGS],
}

impl AntController {
    pub fn new(params: AntGaitParams) -> Result<AntController> {
        let gait = GaitScheduler::new(GaitKind::Trot, params.stance_duration, params.duty_factor)?;
        params.command.validate()?;
        let qp =
            ForceQp::new(Dimension::Spatial, params.friction, 0.1, 50.0, vec![1.0, 1.0, 1.0, 10.0, 10.0, 10.0], 1e-4);
        Ok(AntController {
            params,
            gait,
            qp,
            legs: None,
            qp_failures: 0,
            time: 0.0,
            speed_integral: 0.0,
            heading_goal: 0.0,
            last_phase: [(true, 0.0); LEGS],
            foot_targets: [[0.0; 3]; LEGS],
        })
    }

    fn legs(d: &Data) -> Result<Vec<Leg>> {
        let m = d.model();
        ANT_LEGS
            .iter()
            .map(|&i| {
                let hip_joint = m.joint_id(&format!("hip_{i}"))?;
                let ankle_joint = m.joint_id(&format!("ankle_{i}"))?;
                let range = m.jnt_range();
                Ok(Leg {
                    hip_joint,
                    ankle_joint,
                    hip_act: m.actuator_id(&format!("hip_{i}"))?,
                    ankle_act: m.actuator_id(&format!("ankle_{i}"))?,
                    foot_site: m.site_id(&format!("foot_{i}"))?,
                    // Hip yaw about +z moves a foot at (rx, ry) along (-ry, rx): forward for legs
                    // whose foot lies at negative y.
                    forward_sign: if i == 3 || i == 4 { 1.0 } else { -1.0 },
                    ankle_sign: if range[2 * ankle_joint] > 0.0 { 1.0 } else { -1.0 },
                })
            })
            .collect()
    }

    fn v3(s: &[f64], i: usize) -> Vector3<f64> {
        Vector3::new(s[3 * i], s[3 * i + 1], s[3 * i + 2])
    }

    pub(crate) fn controls(&mut self, env: &dyn Env) -> Result<Vec<f64>> {
        let spec = env.spec();
        if !["ant", "ant-command"].contains(&spec.name) {
            bail!("the Ant controller drives the ant environment only");
        }
        let d = env.data();
        if self.legs.is_none() {
            self.legs = Some(Self::legs(d)?);
        }
        let legs = self.legs.as_ref().unwrap();
        let m = d.model();
        let p = &self.params;
        let torso = m.body_id("torso")?;
        let r = Matrix3::from_row_slice(&d.xmat()[9 * torso..9 * torso + 9]);
        let (q, v) = (d.qpos(), d.qvel());
        let vel = Vector3::new(v[0], v[1], v[2]);
        let omega = r * Vector3::new(v[3], v[4], v[5]);
        let masses = m.body_mass();
        let total_mass: f64 = masses.iter().sum();
        let com = masses.iter().enumerate().fold(Vector3::zeros(), |a, (b, mass)| a + Self::v3(d.xipos(), b) * *mass)
            / total_mass;
        let g = -m.gravity()[2];
        // Heading frame (yaw only): speeds and the wrench are set in it.
        let frame = HeadingFrame::new(&r, vel, omega);
        let (yaw, heading, body) = (frame.yaw, frame.heading, frame.body);
        let (local_vel, local_omega) = (frame.velocity, frame.angular_velocity);
        if self.time == 0.0 {
            // Walk along world x, where Ant's reward counts progress, whatever yaw the reset
            // left the body at (as the rowing gait does).
            self.heading_goal = 0.0;
        }
        let v_des = p.command.speed.at(self.time);
        let yaw_rate_des = p.command.yaw_rate;
        // Roll and pitch error as a rotation vector (small-angle: the skew part of the body
        // attitude in the heading frame); yaw against the commanded heading.
        let att = Vector3::new(
            0.5 * (body[(2, 1)] - body[(1, 2)]),
            0.5 * (body[(0, 2)] - body[(2, 0)]),
            -wrap_angle(self.heading_goal - yaw),
        );
        let speed_error = v_des - local_vel.x;
        self.speed_integral = integrate_speed_error(self.speed_integral, speed_error, spec.dt, p.kd_speed, p.ki_speed);

        let phases = self.gait.legs();
        self.last_phase = phases.map(|l| (l.in_stance, l.progress));
        let mut ctrl = vec![0.0; m.nu()];
        let stance: Vec<usize> = (0..LEGS).filter(|&k| phases[k].in_stance).collect();
        if !stance.is_empty() {
            let force = heading
                * Vector3::new(
                    total_mass * (p.kd_speed * speed_error + p.ki_speed * self.speed_integral),
                    total_mass * p.kd_speed * (0.0 - local_vel.y),
                    total_mass * (g + p.kp_height * (p.body_height - q[2]) - p.kd_height * vel.z),
                );
            let inertia = 0.05;
            let rate_error = local_omega - Vector3::new(0.0, 0.0, yaw_rate_des);
            let moment = heading * ((-att * p.kp_attitude - rate_error * p.kd_attitude) * inertia);
            let feet: Vec<Vector3<f64>> =
                stance.iter().map(|&k| Self::v3(d.site_xpos(), legs[k].foot_site) - com).collect();
            let wrench = [force.x, force.y, force.z.max(0.0), moment.x, moment.y, moment.z];
            let forces = self.qp.solve(&feet, &wrench).unwrap_or_else(|_| {
                self.qp_failures += 1;
                stance.iter().flat_map(|_| [0.0, 0.0, total_mass * g / stance.len() as f64]).collect()
            });
            for (n, &k) in stance.iter().enumerate() {
                let leg = &legs[k];
                let f = Vector3::new(forces[3 * n], forces[3 * n + 1], forces[3 * n + 2]);
                let foot = Self::v3(d.site_xpos(), leg.foot_site);
                for (joint, act) in [(leg.hip_joint, leg.hip_act), (leg.ankle_joint, leg.ankle_act)] {
                    let column = Self::v3(d.xaxis(), joint).cross(&(foot - Self::v3(d.xanchor(), joint)));
                    let gear = 150.0;
                    ctrl[act] = -column.dot(&f) / gear;
                }
            }
        }
        // Hip sweep: the foothold (T_st/2) v + k (v - v_des) ahead of the hip at touchdown plus
        // the stride the set-point needs, (T_st/2) v_des, swept back through stance; a step dx
        // needs a hip yaw of about dx / 0.4 m. Signed, so the same law walks backwards.
        let offset = raibert_foothold(p.stance_duration, [local_vel.x, local_vel.y], [v_des, 0.0], p.foothold_gain);
        let amplitude = ((offset[0] + 0.5 * p.stance_duration * v_des) / 0.4).clamp(-0.5, 0.5);
        for k in 0..LEGS {
            let leg = &legs[k];
            let (hq, hv) = (q[m.joint_qpos_adr(leg.hip_joint)], v[m.joint_dof_adr(leg.hip_joint)]);
            let (aq, av) = (q[m.joint_qpos_adr(leg.ankle_joint)], v[m.joint_dof_adr(leg.ankle_joint)]);
            let s = phases[k].progress;
            let blend = 0.5 - 0.5 * (std::f64::consts::PI * s).cos();
            if phases[k].in_stance {
                let hip_target = leg.forward_sign * amplitude * (1.0 - 2.0 * blend);
                ctrl[leg.hip_act] += (p.joint_kp * (hip_target - hq) - p.joint_kd * hv) / 150.0;
                continue;
            }
            let hip_target = leg.forward_sign * amplitude * (2.0 * blend - 1.0);
            let (axis, anchor) = (Self::v3(d.xaxis(), leg.hip_joint), Self::v3(d.xanchor(), leg.hip_joint));
            let to_touchdown =
                Rotation3::from_axis_angle(&Unit::new_normalize(axis), leg.forward_sign * amplitude - hq);
            let landing = anchor + to_touchdown * (Self::v3(d.site_xpos(), leg.foot_site) - anchor);
            self.foot_targets[k] = [landing.x, landing.y, 0.0];
            let ankle_target = leg.ankle_sign * p.swing_ankle;
            ctrl[leg.hip_act] = (p.joint_kp * (hip_target - hq) - p.joint_kd * hv) / 150.0;
            ctrl[leg.ankle_act] = (p.joint_kp * (ankle_target - aq) - p.joint_kd * av) / 150.0;
        }
        self.gait.advance(spec.dt);
        self.time += spec.dt;
        self.heading_goal = wrap_angle(self.heading_goal + yaw_rate_des * spec.dt);
        Ok(ctrl.into_iter().map(|c| c.clamp(-1.0, 1.0)).collect())
    }
}

impl Policy for AntController {
    fn name(&self) -> String {
        self.params.command.controller_name("trot")
    }
    fn begin_episode(&mut self, _episode: usize) {
        self.gait.reset();
        self.qp_failures = 0;
        self.time = 0.0;
        self.speed_integral = 0.0;
    }
    fn act(&mut self, env: &dyn Env, _observation: &[f64]) -> Result<Vec<f64>> {
        self.controls(env)
    }
    fn diagnostics(&self) -> Vec<(&'static str, f64)> {
        vec![("qp_failures", self.qp_failures as f64)]
    }
    fn telemetry(&self) -> Telemetry {
        super::gait::gait_telemetry(&self.last_phase, |leg| self.foot_targets[leg])
    }
}
