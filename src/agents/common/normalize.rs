//! Observation normalisation: an agent wrapper that feeds its inner agent `(obs - mean) / std`,
//! clipped to +-10, with the statistics estimated once from the warm-up transitions and frozen
//! from then on.
//!
//! Why: Minitaur's observation mixes motor velocities (std about 13 rad/s under random actions)
//! with the base quaternion (std about 0.04), so the orientation a walking policy must balance
//! on is a hundredth of the scale of the velocity noise. rl-baselines-zoo normalises Minitaur's
//! observations (VecNormalize, running statistics, clip 10, epsilon 1e-8); here the statistics
//! are fixed after the warm-up, so the networks never see their input distribution drift and a
//! run is exactly reproducible and resumable.
//!
//! The statistics live in two actor tensors (`actor.obs_mean`, `actor.obs_inv_std`), so
//! checkpoints and exported policies carry them without any other file.
use crate::agents::delegate_to_inner;
use candle_core::{DType, Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;

use crate::agents::{Agent, Batch, Losses, OffPolicyAgent, ReplayBuffer};

/// VecNormalize's defaults (Stable-Baselines3 `vec_normalize.py`).
pub(crate) const CLIP: f32 = 10.0;
pub(crate) const EPSILON: f64 = 1e-8;

/// Wraps an agent so its networks see standardised observations (frozen after warm-up).
pub struct NormalizedAgent {
    inner: Box<dyn OffPolicyAgent>,
    mean: Var,
    inv_std: Var,
    scratch: Batch,
}

impl NormalizedAgent {
    /// Wraps `inner` with the identity normalisation (mean 0, std 1) until `fit_observations`.
    pub fn new(inner: Box<dyn OffPolicyAgent>, obs_dim: usize) -> Result<NormalizedAgent> {
        let dev = Device::Cpu;
        Ok(NormalizedAgent {
            inner,
            mean: Var::from_tensor(&Tensor::zeros(obs_dim, DType::F32, &dev)?)?,
            inv_std: Var::from_tensor(&Tensor::ones(obs_dim, DType::F32, &dev)?)?,
            scratch: Batch::default(),
        })
    }

    fn stats(&self) -> Result<(Vec<f32>, Vec<f32>)> {
        Ok((self.mean.as_tensor().to_vec1::<f32>()?, self.inv_std.as_tensor().to_vec1::<f32>()?))
    }

    /// One observation as the inner agent sees it.
    fn normalized(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let (mean, inv_std) = self.stats()?;
        let mut x = obs.to_vec();
        normalize_rows(&mut x, &mean, &inv_std);
        Ok(x)
    }
}

/// `(x - mean) * inv_std`, clipped, in place over rows of `mean.len()` values.
pub(crate) fn normalize_rows(values: &mut [f32], mean: &[f32], inv_std: &[f32]) {
    for row in values.chunks_exact_mut(mean.len()) {
        for ((v, m), s) in row.iter_mut().zip(mean).zip(inv_std) {
            *v = ((*v - m) * s).clamp(-CLIP, CLIP);
        }
    }
}

/// Per-dimension mean and 1/sqrt(var + eps) of the buffer's stored observations, in f64.
pub(crate) fn observation_stats(buffer: &ReplayBuffer) -> (Vec<f32>, Vec<f32>) {
    let (dim, _) = buffer.dims();
    let n = buffer.len().max(1) as f64;
    let mut mean = vec![0.0f64; dim];
    for i in 0..buffer.len() {
        for (m, &v) in mean.iter_mut().zip(buffer.obs(i)) {
            *m += v as f64;
        }
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut var = vec![0.0f64; dim];
    for i in 0..buffer.len() {
        for ((s, &v), m) in var.iter_mut().zip(buffer.obs(i)).zip(&mean) {
            *s += (v as f64 - m).powi(2);
        }
    }
    let inv_std = var.iter().map(|s| (1.0 / (s / n + EPSILON).sqrt()) as f32).collect();
    (mean.iter().map(|&m| m as f32).collect(), inv_std)
}

impl Agent for NormalizedAgent {
    fn act(&self, obs: &[f32]) -> Result<Vec<f32>> {
        self.inner.act(&self.normalized(obs)?)
    }

    fn explore(&mut self, obs: &[f32], rng: &mut ChaCha8Rng) -> Result<Vec<f32>> {
        let x = self.normalized(obs)?;
        self.inner.explore(&x, rng)
    }

    fn parameters(&self) -> Vec<(String, Var)> {
        let mut out = self.inner.parameters();
        out.push(("actor.obs_mean".to_string(), self.mean.clone()));
        out.push(("actor.obs_inv_std".to_string(), self.inv_std.clone()));
        out
    }

    delegate_to_inner!();
}

impl OffPolicyAgent for NormalizedAgent {
    fn update(&mut self, batch: &Batch, rng: &mut ChaCha8Rng) -> Result<Losses> {
        let (mean, inv_std) = self.stats()?;
        self.scratch.clone_from(batch);
        normalize_rows(&mut self.scratch.obs, &mean, &inv_std);
        normalize_rows(&mut self.scratch.next_obs, &mean, &inv_std);
        self.inner.update(&self.scratch, rng)
    }

    fn fit_observations(&mut self, buffer: &ReplayBuffer) -> Result<()> {
        let (mean, inv_std) = observation_stats(buffer);
        let n = mean.len();
        self.mean.set(&Tensor::from_vec(mean, n, &Device::Cpu)?)?;
        self.inv_std.set(&Tensor::from_vec(inv_std, n, &Device::Cpu)?)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_match_a_hand_computation_and_rows_are_clipped() {
        let mut buffer = ReplayBuffer::new(8, 2, 1);
        let rows = [[1.0f32, 10.0], [3.0, 10.0], [5.0, 10.0]];
        for (i, r) in rows.iter().enumerate() {
            let next = rows.get(i + 1).copied().unwrap_or([0.0, 0.0]);
            buffer.add(r, &[0.0], 0.0, &next, false, false);
        }
        let (mean, inv_std) = observation_stats(&buffer);
        assert_eq!(mean, vec![3.0, 10.0]);
        // population variance of 1, 3, 5 is 8/3; a constant dimension gets 1/sqrt(eps)
        assert!((inv_std[0] as f64 - 1.0 / (8.0f64 / 3.0 + EPSILON).sqrt()).abs() < 1e-6);
        assert!((inv_std[1] as f64 - 1.0 / EPSILON.sqrt()).abs() < 1.0);

        let mut x = vec![5.0, 10.5];
        normalize_rows(&mut x, &mean, &inv_std);
        assert!((x[0] - 2.0 * inv_std[0]).abs() < 1e-6);
        assert_eq!(x[1], CLIP);
    }
}
