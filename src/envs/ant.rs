//! Ant as Gymnasium v5 defines it: observation qpos[2:] + qvel + clipped cfrc_ext of bodies 1..
//! (105), reward forward + healthy - ctrl_cost - contact_cost, terminates when unhealthy. It also
//! takes the world perturbations of `world` (friction, payload, motors, latency, slopes), off by
//! default.
use serde::{Deserialize, Serialize};

use super::mujoco_env::MujocoEnv;
use super::options::read_by_name;
use super::simulation::{Simulation, VelocityNoise};
use super::task::{legged_step, locomotion_metrics, planar_position, LeggedWeights, Task, TaskStep};
use super::world::World;
use super::EnvError;
use crate::mujoco::Model;

pub(crate) const MODEL_XML: &str = include_str!("../../models/ant.xml");

/// Gymnasium Ant-v5's options, with its defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AntOptions {
    /// Weight of the forward-velocity reward.
    pub forward_reward_weight: f64,
    /// Weight of the squared-action cost.
    pub ctrl_cost_weight: f64,
    /// Weight of the squared clipped contact-force cost.
    pub contact_cost_weight: f64,
    /// Reward per step while healthy.
    pub healthy_reward: f64,
    /// End the episode when the torso leaves `healthy_z_range`.
    pub terminate_when_unhealthy: bool,
    /// Healthy while the torso height lies in this closed interval (and the state is finite).
    pub healthy_z_range: [f64; 2],
    /// cfrc_ext entries are clipped to this range for the observation and the contact cost.
    pub contact_force_range: [f64; 2],
    /// qpos += U(-s, s), qvel = s * N(0, 1) at reset.
    pub reset_noise_scale: f64,
    /// Steps before the episode is truncated.
    pub max_episode_steps: usize,
    /// Physics steps per `step`.
    pub frame_skip: usize,
    /// World perturbations (not Gymnasium's; `world::World`), nominal by default: every geom's
    /// sliding friction times this,
    pub friction_scale: f64,
    /// mass added to the torso (kg),
    pub payload_mass: f64,
    /// the torso's centre of mass moved forward (m),
    pub com_shift: f64,
    /// every motor's gear times this,
    pub motor_strength: f64,
    /// delay from an action to the motors (s, whole physics steps of 0.01 s),
    pub latency: f64,
    /// and a slope along +x (degrees, up positive).
    pub slope: f64,
}

impl Default for AntOptions {
    fn default() -> Self {
        AntOptions {
            forward_reward_weight: 1.0,
            ctrl_cost_weight: 0.5,
            contact_cost_weight: 5e-4,
            healthy_reward: 1.0,
            terminate_when_unhealthy: true,
            healthy_z_range: [0.2, 1.0],
            contact_force_range: [-1.0, 1.0],
            reset_noise_scale: 0.1,
            max_episode_steps: 1000,
            frame_skip: 5,
            friction_scale: 1.0,
            payload_mass: 0.0,
            com_shift: 0.0,
            motor_strength: 1.0,
            latency: 0.0,
            slope: 0.0,
        }
    }
}

pub struct AntTask {
    weights: LeggedWeights,
    world: World,
    opts: AntOptions,
    torso: usize,
}

/// Gymnasium's Ant-v5 on MuJoCo: a four-legged robot rewarded for running along x.
pub type Ant = MujocoEnv<AntTask>;

/// The torso's x and y (of its body frame, as Gymnasium's `get_body_com("torso")`) and z.
pub struct AntBefore {
    xy: [f64; 2],
    z: f64,
}

impl AntTask {
    fn clipped_contact_forces<'a>(&self, sim: &'a Simulation) -> impl Iterator<Item = f64> + 'a {
        let [lo, hi] = self.opts.contact_force_range;
        sim.data.cfrc_ext().iter().map(move |f| f.clamp(lo, hi))
    }

    fn is_healthy(&self, sim: &Simulation) -> bool {
        let d = &sim.data;
        let [lo, hi] = self.opts.healthy_z_range;
        let finite = d.qpos().iter().chain(d.qvel()).all(|v| v.is_finite());
        finite && d.qpos()[2] >= lo && d.qpos()[2] <= hi
    }

    fn torso_xy(&self, sim: &Simulation) -> [f64; 2] {
        let p = &sim.data.xpos()[3 * self.torso..];
        [p[0], p[1]]
    }
}

impl Task for AntTask {
    type Options = AntOptions;
    type Before = AntBefore;
    const NAME: &'static str = "ant";
    const MODEL_XML: &'static str = MODEL_XML;
    const VELOCITY_NOISE: VelocityNoise = VelocityNoise::Normal;
    const REWARD_TERMS: &'static [&'static str] = &["forward", "healthy", "ctrl_cost", "contact_cost"];

    fn new(opts: AntOptions, model: &Model) -> Result<Self, EnvError> {
        Ok(AntTask { weights: read_by_name(&opts), world: read_by_name(&opts), opts, torso: model.body_id("torso")? })
    }

    fn options(&self) -> &Self::Options {
        &self.opts
    }

    fn world(&self) -> Option<(&World, usize)> {
        Some((&self.world, self.torso))
    }

    fn observation_dim(&self, m: &Model) -> usize {
        m.nq() - 2 + m.nv() + 6 * (m.nbody() - 1)
    }

    fn observe(&self, sim: &Simulation, out: &mut Vec<f64>) {
        out.extend_from_slice(&sim.data.qpos()[2..]);
        out.extend_from_slice(sim.data.qvel());
        out.extend(self.clipped_contact_forces(sim).skip(6));
    }

    fn reset_metrics(&self, sim: &Simulation) -> Vec<(&'static str, f64)> {
        planar_position(sim)
    }

    fn before(&self, sim: &Simulation) -> AntBefore {
        AntBefore { xy: self.torso_xy(sim), z: sim.data.qpos()[2] }
    }

    fn after(&self, sim: &mut Simulation, before: &AntBefore, action: &[f64], dt: f64) -> Result<TaskStep, EnvError> {
        sim.data.rne_post_constraint()?;
        let after = self.torso_xy(sim);
        let velocity = [(after[0] - before.xy[0]) / dt, (after[1] - before.xy[1]) / dt];
        let healthy = self.is_healthy(sim);
        let contact_cost = self.opts.contact_cost_weight * self.clipped_contact_forces(sim).map(|f| f * f).sum::<f64>();
        let mut metrics = locomotion_metrics(sim, velocity);
        metrics.extend([("dy", after[1] - before.xy[1]), ("dz", sim.data.qpos()[2] - before.z)]);
        Ok(legged_step(&self.weights, velocity[0], healthy, action, contact_cost, metrics))
    }
}
