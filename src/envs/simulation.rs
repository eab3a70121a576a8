//! What the MuJoCo environments share: a model and its data, stepping with instability checks,
//! the seeded random stream and reset noise.
use std::sync::Arc;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal, Uniform};

use super::{EnvError, EnvSpec, Info, Step};
use crate::mujoco::{take_warnings, Data, Model};

/// The random stream of an environment: reseeded by `reset(Some(seed))`, continued otherwise.
pub(crate) struct EnvRng(ChaCha8Rng);

impl EnvRng {
    pub fn new() -> EnvRng {
        EnvRng(ChaCha8Rng::seed_from_u64(0))
    }
    pub fn reseed(&mut self, seed: Option<u64>) {
        if let Some(s) = seed {
            self.0 = ChaCha8Rng::seed_from_u64(s);
        }
    }
    pub fn rng(&mut self) -> &mut ChaCha8Rng {
        &mut self.0
    }
    /// `n` samples of U[-scale, scale).
    pub fn uniform(&mut self, n: usize, scale: f64) -> Vec<f64> {
        if scale <= 0.0 {
            return vec![0.0; n];
        }
        let dist = Uniform::new(-scale, scale).expect("scale > 0");
        (0..n).map(|_| dist.sample(&mut self.0)).collect()
    }
    /// `n` samples of scale * N(0, 1).
    pub fn normal(&mut self, n: usize, scale: f64) -> Vec<f64> {
        (0..n)
            .map(|_| {
                let z: f64 = StandardNormal.sample(&mut self.0);
                scale * z
            })
            .collect()
    }
}

/// Outcome of advancing the physics.
#[derive(Debug, Default)]
pub(crate) struct Advance {
    pub unstable: bool,
    pub warnings: Vec<String>,
}

pub(crate) struct Simulation {
    pub model: Arc<Model>,
    pub data: Data,
}

impl Simulation {
    pub fn from_xml(xml: &str) -> Result<Simulation, EnvError> {
        let model = Arc::new(Model::from_xml_str(xml)?);
        Self::from_model(model)
    }

    pub fn from_model(model: Arc<Model>) -> Result<Simulation, EnvError> {
        let data = Data::new(&model)?;
        Ok(Simulation { model, data })
    }

    /// Resets to `qpos0 + qpos_noise`, `qvel_noise`, then computes derived quantities (as
    /// Gymnasium's `set_state` does; `cfrc_ext` stays zero until the first step).
    pub fn reset_to(&mut self, qpos_noise: &[f64], qvel_noise: &[f64]) -> Result<(), EnvError> {
        self.data.reset()?;
        let qpos: Vec<f64> = self
            .model
            .qpos0()
            .iter()
            .zip(qpos_noise)
            .map(|(a, b)| a + b)
            .collect();
        self.data.set_state(&qpos, qvel_noise)?;
        take_warnings();
        Ok(())
    }

    /// Sets `ctrl` and runs `frames` MuJoCo steps, stopping at the first sign of instability.
    pub fn advance(&mut self, ctrl: &[f64], frames: usize) -> Result<Advance, EnvError> {
        self.data.set_ctrl(ctrl)?;
        let mut out = Advance::default();
        for _ in 0..frames {
            if self.step_once()? {
                out.unstable = true;
                break;
            }
        }
        out.warnings = take_warnings();
        Ok(out)
    }

    /// One `mj_step`; returns true when MuJoCo reported or hid an instability.
    pub fn step_once(&mut self) -> Result<bool, EnvError> {
        let (before, time_before) = (self.data.instability_counts(), self.data.time());
        self.data.step()?;
        let after = self.data.instability_counts();
        // MuJoCo's automatic reset also rewinds time, which catches a repeat of the same warning.
        let rewound = self.data.time() <= time_before;
        let finite = self
            .data
            .qpos()
            .iter()
            .chain(self.data.qvel())
            .all(|v| v.is_finite());
        Ok(after != before || rewound || !finite)
    }
}

/// The step reported when the physics blew up: last good observation, zero reward, truncated.
pub(crate) fn unstable_step(
    last_obs: &[f64],
    spec: &EnvSpec,
    clipped: usize,
    warnings: Vec<String>,
) -> Step {
    Step {
        observation: last_obs.to_vec(),
        reward: 0.0,
        terminated: false,
        truncated: true,
        info: Info {
            reward_terms: spec.reward_terms.iter().map(|&n| (n, 0.0)).collect(),
            metrics: vec![],
            clipped_actions: clipped,
            unstable: true,
            warnings,
        },
    }
}
