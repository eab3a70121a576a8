//! Exploration noise for deterministic policies: Gaussian, or Ornstein-Uhlenbeck with a standard
//! deviation that decays linearly from `sigma_max` to `sigma_min` over `decay_steps`.
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

/// Which exploration noise a deterministic policy adds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseKind {
    /// Independent N(0, sigma) each step.
    Gaussian,
    /// Temporally correlated Ornstein-Uhlenbeck noise with a decaying std.
    OrnsteinUhlenbeck,
}

#[derive(Debug, Clone)]
pub(crate) enum Noise {
    /// N(0, sigma), in units of the action half-range.
    Gaussian { sigma: f64 },
    OrnsteinUhlenbeck {
        theta: f64,
        sigma_max: f64,
        sigma_min: f64,
        decay_steps: u64,
        dt: f64,
        state: Vec<f64>,
        steps: u64,
    },
}

impl Noise {
    pub fn ornstein_uhlenbeck(
        dim: usize,
        theta: f64,
        sigma_max: f64,
        sigma_min: f64,
        decay_steps: u64,
        dt: f64,
    ) -> Noise {
        Noise::OrnsteinUhlenbeck { theta, sigma_max, sigma_min, decay_steps, dt, state: vec![0.0; dim], steps: 0 }
    }

    /// The exploration noise a TD3 or DDPG section asks for, for `dim` actions.
    pub(crate) fn for_config(dpg: &crate::agents::DpgConfig, dim: usize) -> Noise {
        match dpg.noise {
            NoiseKind::Gaussian => Noise::Gaussian { sigma: dpg.exploration_noise },
            NoiseKind::OrnsteinUhlenbeck => Noise::ornstein_uhlenbeck(
                dim,
                dpg.ou_theta,
                dpg.exploration_noise,
                dpg.ou_sigma_min,
                dpg.ou_decay_steps,
                dpg.ou_dt,
            ),
        }
    }

    /// The current standard deviation of the driving noise.
    pub(crate) fn sigma(&self) -> f64 {
        match self {
            Noise::Gaussian { sigma } => *sigma,
            Noise::OrnsteinUhlenbeck { sigma_max, sigma_min, decay_steps, steps, .. } => {
                let frac = if *decay_steps == 0 { 1.0 } else { (*steps as f64 / *decay_steps as f64).min(1.0) };
                sigma_max - (sigma_max - sigma_min) * frac
            }
        }
    }

    /// Forgets the OU process state (at episode start).
    pub fn reset(&mut self) {
        if let Noise::OrnsteinUhlenbeck { state, .. } = self {
            state.iter_mut().for_each(|x| *x = 0.0);
        }
    }

    /// One noise vector of length `dim`.
    pub fn sample(&mut self, dim: usize, rng: &mut impl Rng) -> Vec<f64> {
        let sigma = self.sigma();
        match self {
            Noise::Gaussian { .. } => (0..dim)
                .map(|_| {
                    let z: f64 = StandardNormal.sample(rng);
                    sigma * z
                })
                .collect(),
            Noise::OrnsteinUhlenbeck { theta, dt, state, steps, .. } => {
                for x in state.iter_mut() {
                    let z: f64 = StandardNormal.sample(rng);
                    *x += *theta * (0.0 - *x) * *dt + sigma * dt.sqrt() * z;
                }
                *steps += 1;
                state.clone()
            }
        }
    }

    /// Steps taken (for the OU decay), saved in checkpoints.
    pub fn steps(&self) -> u64 {
        match self {
            Noise::Gaussian { .. } => 0,
            Noise::OrnsteinUhlenbeck { steps, .. } => *steps,
        }
    }

    pub(crate) fn set_steps(&mut self, n: u64) {
        if let Noise::OrnsteinUhlenbeck { steps, .. } = self {
            *steps = n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn ou_sigma_decays_linearly_and_process_mean_reverts() {
        let mut n = Noise::ornstein_uhlenbeck(1, 0.15, 0.3, 0.1, 100, 1e-2);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        assert!((n.sigma() - 0.3).abs() < 1e-12);
        for _ in 0..50 {
            n.sample(1, &mut rng);
        }
        assert!((n.sigma() - 0.2).abs() < 1e-12);
        for _ in 0..100 {
            n.sample(1, &mut rng);
        }
        assert!((n.sigma() - 0.1).abs() < 1e-12);
        // Successive OU samples are strongly correlated; Gaussian ones are not.
        let xs: Vec<f64> = (0..2000).map(|_| n.sample(1, &mut rng)[0]).collect();
        let corr = xs.windows(2).map(|w| w[0] * w[1]).sum::<f64>() / xs.iter().map(|x| x * x).sum::<f64>();
        assert!(corr > 0.9, "{corr}");
        let mut g = Noise::Gaussian { sigma: 0.1 };
        let ys: Vec<f64> = (0..20000).map(|_| g.sample(1, &mut rng)[0]).collect();
        let std = (ys.iter().map(|y| y * y).sum::<f64>() / ys.len() as f64).sqrt();
        assert!((std - 0.1).abs() < 0.005);
    }
}
