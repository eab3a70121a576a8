//! Humanoid as Gymnasium v5 defines it: observation qpos[2:], qvel, cinert[1:], cvel[1:],
//! qfrc_actuator[6:], cfrc_ext[1:] (348); reward 1.25 * centre-of-mass dx/dt + 5 while healthy
//! - 0.1 |ctrl|^2 - min(5e-7 |cfrc_ext|^2, 10); terminates when the torso leaves (1, 2) m.
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::options::read_by_name;
use super::simulation::{Simulation, VelocityNoise};
use super::task::{legged_step, locomotion_metrics, planar_position, quadratic_cost, LeggedWeights, Task, TaskStep};
use super::EnvError;
use crate::mujoco::Model;

pub(crate) const MODEL_XML: &str = include_str!("../../models/humanoid.xml");

/// Gymnasium Humanoid-v5's options, with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HumanoidOptions {
    /// Weight of the forward-velocity reward (of the centre of mass).
    pub forward_reward_weight: f64,
    /// Weight of the squared-action cost.
    pub ctrl_cost_weight: f64,
    /// Weight of the squared external contact-force cost.
    pub contact_cost_weight: f64,
    /// The contact cost is clipped above at this value.
    pub contact_cost_max: f64,
    /// Reward per step while healthy.
    pub healthy_reward: f64,
    /// End the episode when the torso leaves `healthy_z_range`.
    pub terminate_when_unhealthy: bool,
    /// Healthy while the torso height lies strictly inside this interval.
    pub healthy_z_range: [f64; 2],
    /// qpos and qvel += U(-s, s) at reset.
    pub reset_noise_scale: f64,
    /// Steps before the episode is truncated.
    pub max_episode_steps: usize,
    /// Physics steps per `step`.
    pub frame_skip: usize,
    /// Gymnasium v5's switches for the observation's parts after qpos[2:] and qvel. Gymnasium
    /// v4, on which most published Humanoid results ran, read `cfrc_ext` as zeros (a bug fixed
    /// in v5); `include_cfrc_ext_in_observation = false` drops what v4 could not see.
    pub include_cinert_in_observation: bool,
    /// Include the bodies' centre-of-mass velocities (`cvel`).
    pub include_cvel_in_observation: bool,
    /// Include the actuator forces in joint space (`qfrc_actuator`).
    pub include_qfrc_actuator_in_observation: bool,
    /// Include the external contact forces (`cfrc_ext`).
    pub include_cfrc_ext_in_observation: bool,
}

impl Default for HumanoidOptions {
    fn default() -> Self {
        HumanoidOptions {
            forward_reward_weight: 1.25,
            ctrl_cost_weight: 0.1,
            contact_cost_weight: 5e-7,
            contact_cost_max: 10.0,
            healthy_reward: 5.0,
            terminate_when_unhealthy: true,
            healthy_z_range: [1.0, 2.0],
            reset_noise_scale: 1e-2,
            max_episode_steps: 1000,
            frame_skip: 5,
            include_cinert_in_observation: true,
            include_cvel_in_observation: true,
            include_qfrc_actuator_in_observation: true,
            include_cfrc_ext_in_observation: true,
        }
    }
}

pub struct HumanoidTask {
    weights: LeggedWeights,
    opts: HumanoidOptions,
}

/// Gymnasium's Humanoid-v5: a 3D biped rewarded for walking along x without falling.
pub type Humanoid = MujocoEnv<HumanoidTask>;

impl HumanoidTask {
    /// Mass-weighted centre of mass, x and y.
    fn mass_center(sim: &Simulation) -> [f64; 2] {
        let mass = sim.model.body_mass();
        let xipos = sim.data.xipos();
        let total: f64 = mass.iter().sum();
        let mut c = [0.0; 2];
        for (b, m) in mass.iter().enumerate() {
            c[0] += m * xipos[3 * b];
            c[1] += m * xipos[3 * b + 1];
        }
        [c[0] / total, c[1] / total]
    }

    fn is_healthy(&self, sim: &Simulation) -> bool {
        let z = sim.data.qpos()[2];
        let [lo, hi] = self.opts.healthy_z_range;
        lo < z && z < hi
    }
}

impl Task for HumanoidTask {
    type Options = HumanoidOptions;
    type Before = [f64; 2];
    const NAME: &'static str = "humanoid";
    const MODEL_XML: &'static str = MODEL_XML;
    const VELOCITY_NOISE: VelocityNoise = VelocityNoise::Uniform;
    const REWARD_TERMS: &'static [&'static str] = &["forward", "healthy", "ctrl_cost", "contact_cost"];

    fn new(opts: HumanoidOptions, _model: &Model) -> Result<Self, EnvError> {
        Ok(HumanoidTask { weights: read_by_name(&opts), opts })
    }

    fn options(&self) -> &Self::Options {
        &self.opts
    }

    fn observation_dim(&self, m: &Model) -> usize {
        let (nb, o) = (m.nbody() - 1, &self.opts);
        let part = |include: bool, n: usize| if include { n } else { 0 };
        (m.nq() - 2)
            + m.nv()
            + part(o.include_cinert_in_observation, 10 * nb)
            + part(o.include_cvel_in_observation, 6 * nb)
            + part(o.include_qfrc_actuator_in_observation, m.nv() - 6)
            + part(o.include_cfrc_ext_in_observation, 6 * nb)
    }

    fn observe(&self, sim: &Simulation, out: &mut Vec<f64>) {
        let d = &sim.data;
        out.extend_from_slice(&d.qpos()[2..]);
        out.extend_from_slice(d.qvel());
        let o = &self.opts;
        if o.include_cinert_in_observation {
            out.extend_from_slice(&d.cinert()[10..]);
        }
        if o.include_cvel_in_observation {
            out.extend_from_slice(&d.cvel()[6..]);
        }
        if o.include_qfrc_actuator_in_observation {
            out.extend_from_slice(&d.qfrc_actuator()[6..]);
        }
        if o.include_cfrc_ext_in_observation {
            out.extend_from_slice(&d.cfrc_ext()[6..]);
        }
    }

    fn reset_metrics(&self, sim: &Simulation) -> Vec<(&'static str, f64)> {
        planar_position(sim)
    }

    fn before(&self, sim: &Simulation) -> [f64; 2] {
        Self::mass_center(sim)
    }

    fn after(&self, sim: &mut Simulation, before: &[f64; 2], action: &[f64], dt: f64) -> Result<TaskStep, EnvError> {
        sim.data.rne_post_constraint()?;
        let after = Self::mass_center(sim);
        let velocity = [(after[0] - before[0]) / dt, (after[1] - before[1]) / dt];
        let healthy = self.is_healthy(sim);
        let contact_cost =
            quadratic_cost(self.opts.contact_cost_weight, sim.data.cfrc_ext()).min(self.opts.contact_cost_max);
        Ok(legged_step(&self.weights, velocity[0], healthy, action, contact_cost, locomotion_metrics(sim, velocity)))
    }
}
