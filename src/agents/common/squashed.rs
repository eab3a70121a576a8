//! SAC's policy head, a tanh-squashed Gaussian sample and its log-density, as one autograd node.
//!
//! Written with candle's operations the head is about thirty small graph nodes forward and as
//! many backward on `[batch, act_dim]` tensors, every one allocating its output; on two threads
//! the helper sat idle while the training thread went through them. [`squashed_sample`] is one
//! node: the forward pass and the backward pass are one loop over the elements, cut in two halves
//! of the batch for the helper thread when the batch is large.
//!
//! Its arithmetic is the candle graph's, operation for operation and in candle's order, so the
//! bits are the same (tested against that graph, `agents::sac`'s `sample_squashed_graph`):
//! - the forward pass computes each intermediate value as candle's op computes it (`affine` is a
//!   multiply then an add, `clamp` is `maximum` then `minimum`, the sum over the action runs
//!   from zero in index order, and exp, ln and tanh give the bits of Rust's, which candle calls:
//!   they are [`glibc_math`]'s, glibc's code over whole arrays at the path's vector width);
//! - the backward pass follows candle's rules (`backprop.rs` in candle-core 0.11): each node's
//!   gradient starts from zero and receives its consumers' contributions in the order candle's
//!   topological sort visits them for SAC's actor loss, `mean(alpha * log_pi - Q(s, a))`: the
//!   action's tanh first, then the log-density's nodes from the output back. Only `u`, used
//!   three times, depends on that order.
//!
//! The log-density's squashing term is either the exact `log(1 - tanh(u)^2)` computed stably as
//! `2 (log 2 - u - softplus(-2u))`, or Stable-Baselines3's `log(1 - tanh(u)^2 + 1e-6)`
//! ([`TanhCorrection`]).
// Each step is written as the candle op it stands for (`affine(-1, c)` is `x * -1.0 + c`, a
// gradient accumulates as `sum = sum + g`), so that the correspondence can be read line by line.
#![allow(clippy::neg_multiply, clippy::assign_op_pattern)]

use std::sync::Mutex;

use candle_core::{bail, CpuStorage, CustomOp1, Layout, Result, Shape, Tensor};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::numeric::glibc_math;
use crate::numeric::inplace::contiguous;
use crate::numeric::kernel_path::{self, KernelPath};
use crate::numeric::second_core;
use crate::numeric::wide::wide;

/// How SAC's log-density accounts for the tanh squashing, log(1 - tanh(u)^2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TanhCorrection {
    /// Exact and stable, 2 (log 2 - u - softplus(-2u)): the SAC paper's formula (Haarnoja et al.
    /// 2018, appendix C) as jaxrl's tanh bijector computes it.
    Exact,
    /// log(1 - a^2 + 1e-6) with a = tanh(u) in f32, as Stable-Baselines3 and CleanRL compute it:
    /// bounded below by log(1e-6), so a saturated action costs at most 13.8 nats per dimension.
    Epsilon,
}

/// The policy's log-std is clamped to this range (SAC's and CrossQ's).
pub(crate) const LOG_STD_MIN: f64 = -20.0;
pub(crate) const LOG_STD_MAX: f64 = 2.0;

/// A reparameterised sample of the squashed Gaussian whose mean and raw log-std are the two
/// halves of the policy's output `out` (`[n, 2 act_dim]`), the log-std clamped to
/// [LOG_STD_MIN, LOG_STD_MAX]: (tanh(u), log pi(a|s)), u = mean + std * eps, eps drawn from
/// `rng`. SAC's and CrossQ's policy, one graph node ([`squashed_sample`]).
pub(crate) fn sample_squashed(
    out: &Tensor,
    correction: TanhCorrection,
    rng: &mut ChaCha8Rng,
) -> Result<(Tensor, Tensor)> {
    let sample = sample_squashed_joint(out, correction, rng)?;
    let act_dim = sample.dims2()?.1 - 1;
    Ok((sample.narrow(1, 0, act_dim)?, sample.narrow(1, act_dim, 1)?))
}

/// [`sample_squashed`]'s action and log-density side by side, `[n, act_dim + 1]`.
pub(crate) fn sample_squashed_joint(out: &Tensor, correction: TanhCorrection, rng: &mut ChaCha8Rng) -> Result<Tensor> {
    let (n, width) = out.dims2()?;
    let act_dim = width / 2;
    let eps: Vec<f32> = (0..n * act_dim).map(|_| StandardNormal.sample(rng)).collect();
    squashed_sample(out, eps, (LOG_STD_MIN as f32, LOG_STD_MAX as f32), correction)
}

/// The deterministic action of the squashed Gaussian policy with output `out` (`[1, 2 act_dim]`):
/// tanh of the mean half.
pub(crate) fn squashed_mean(out: &Tensor) -> Result<Vec<f32>> {
    out.narrow(1, 0, out.dims2()?.1 / 2)?.tanh()?.flatten_all()?.to_vec1::<f32>()
}

/// Batches of at least this many rows run in two halves (both passes).
const SPLIT_ROWS: usize = 32;

/// Per element, what the backward pass reads of the forward pass.
#[derive(Clone, Copy, Default)]
struct Saved {
    /// The raw log-std, after `maximum` and after `minimum` (the clamp's two steps).
    raw: f32,
    floored: f32,
    log_std: f32,
    std: f32,
    action: f32,
    /// Exact: -2u, exp(-|-2u|) and 1 + exp(-|-2u|). Epsilon: 1 - tanh(u)^2 + 1e-6 in `shifted`.
    minus_2u: f32,
    exp_term: f32,
    shifted: f32,
}

struct SquashedSample {
    eps: Vec<f32>,
    act_dim: usize,
    log_std_range: (f32, f32),
    correction: TanhCorrection,
    path: KernelPath,
    saved: Mutex<Vec<Saved>>,
}

fn half_log_2pi() -> f32 {
    (0.5 * (2.0 * std::f64::consts::PI).ln()) as f32
}

impl SquashedSample {
    /// Rows of `out` (`[rows, 2 act_dim]`) into rows of `y` (`[rows, act_dim + 1]`) and `saved`.
    ///
    /// The exponentials, tanh and logarithms run over whole arrays ([`glibc_math`], glibc's bits at
    /// the path's vector width); the rest is a loop over the elements in row order.
    fn forward_rows(&self, out: &[f32], eps: &[f32], y: &mut [f32], saved: &mut [Saved]) {
        let a = self.act_dim;
        let (lo, hi) = self.log_std_range;
        let half_log_2pi = half_log_2pi();
        let ln_2 = 2f64.ln() as f32;
        let one_plus_eps = (1.0 + 1e-6f64) as f32;
        let path = self.path;
        let exact = self.correction == TanhCorrection::Exact;
        let means = || out.chunks_exact(2 * a).flat_map(|row| &row[..a]);

        // the clamp (`maximum`, then `minimum`), and std = exp(log_std)
        for (raw, s) in out.chunks_exact(2 * a).flat_map(|row| &row[a..]).zip(saved.iter_mut()) {
            let floored = if *raw < lo { lo } else { *raw };
            let log_std = if floored > hi { hi } else { floored };
            (s.raw, s.floored, s.log_std) = (*raw, floored, log_std);
        }
        let mut std: Vec<f32> = saved.iter().map(|s| s.log_std).collect();
        glibc_math::exp_in_place(path, &mut std);

        // u = mean + std * eps; the action tanh(u), and for the exact correction exp(-|-2u|)
        let u: Vec<f32> = means().zip(&std).zip(eps).map(|((mean, std), e)| mean + std * e).collect();
        let mut action = u.clone();
        glibc_math::tanh_in_place(path, &mut action);
        let mut exp_term = Vec::new();
        if exact {
            exp_term = u.iter().map(|u| -(u * -2.0 + 0.0).abs()).collect();
            glibc_math::exp_in_place(path, &mut exp_term);
        }

        // the argument of the correction's logarithm
        let shifted: Vec<f32> = if exact {
            exp_term.iter().map(|e| e * 1.0 + 1.0).collect()
        } else {
            action.iter().map(|t| (t * t) * -1.0 + one_plus_eps).collect()
        };
        let mut log_shifted = shifted.clone();
        glibc_math::ln_in_place(path, &mut log_shifted);

        for (r, (y, saved)) in y.chunks_exact_mut(a + 1).zip(saved.chunks_exact_mut(a)).enumerate() {
            let mut log_prob = 0f32;
            for (j, s) in saved.iter_mut().enumerate() {
                let i = r * a + j;
                let (e, u) = (eps[i], u[i]);
                let gaussian = (e * e) * -0.5 + -half_log_2pi - s.log_std;
                let squash = if exact {
                    let minus_2u = u * -2.0 + 0.0;
                    let softplus = minus_2u.max(0.0) + log_shifted[i];
                    (s.minus_2u, s.exp_term, s.shifted) = (minus_2u, exp_term[i], shifted[i]);
                    ((-u - softplus) * 1.0 + ln_2) * 2.0 + 0.0
                } else {
                    s.shifted = shifted[i];
                    log_shifted[i]
                };
                log_prob += gaussian - squash;
                (s.std, s.action) = (std[i], action[i]);
                y[j] = action[i];
            }
            y[a] = log_prob;
        }
    }

    /// Rows of the gradient `g` (`[rows, act_dim + 1]`) into rows of `gx` (`[rows, 2 act_dim]`).
    fn backward_rows(&self, g: &[f32], eps: &[f32], saved: &[Saved], gx: &mut [f32]) {
        let a = self.act_dim;
        let (lo, hi) = self.log_std_range;
        let correction = self.correction;
        for (((g, eps), saved), gx) in
            g.chunks_exact(a + 1).zip(eps.chunks_exact(a)).zip(saved.chunks_exact(a)).zip(gx.chunks_exact_mut(2 * a))
        {
            // the sum over the action passes its gradient to every term, then the difference
            let g_term = 0.0 + g[a];
            let g_gaussian = 0.0 + g_term;
            let g_squash = 0.0 - g_term;
            for j in 0..a {
                let s = &saved[j];
                // tanh of the action: d tanh = -(tanh^2 - 1)
                let mut g_u = 0.0 - g[j] * ((s.action * s.action) * 1.0 + -1.0);
                match correction {
                    TanhCorrection::Exact => {
                        // squash = 2 (d + ln 2), d = -u - softplus, softplus = relu(-2u) + ln(1 + exp(-|-2u|))
                        let g_d = 0.0 + ((0.0 + (g_squash * 2.0 + 0.0)) * 1.0 + 0.0);
                        let g_neg_u = 0.0 + g_d;
                        let g_softplus = 0.0 - g_d;
                        let g_relu = 0.0 + g_softplus;
                        let g_shifted = 0.0 + (0.0 + g_softplus) / s.shifted;
                        let g_exp = 0.0 + (g_shifted * 1.0 + 0.0);
                        let g_neg_abs = 0.0 + g_exp * s.exp_term;
                        let g_abs = 0.0 - g_neg_abs;
                        let non_negative = s.minus_2u >= 0.0;
                        let mut g_minus_2u = 0.0 + g_abs * if non_negative { 1.0 } else { -1.0 };
                        g_minus_2u = g_minus_2u + g_relu * if non_negative { 1.0 } else { 0.0 };
                        g_u = g_u + (g_minus_2u * -2.0 + 0.0);
                        g_u = g_u - g_neg_u;
                    }
                    TanhCorrection::Epsilon => {
                        // squash = ln(shifted), shifted = -t^2 + 1 + 1e-6, t = tanh(u) (= action)
                        let g_shifted = 0.0 + g_squash / s.shifted;
                        let g_sq = 0.0 + (g_shifted * -1.0 + 0.0);
                        let g_t = 0.0 + ((s.action * g_sq) * 2.0 + 0.0);
                        g_u = g_u - g_t * ((s.action * s.action) * 1.0 + -1.0);
                    }
                }
                // u = mean + std * eps, std = exp(log_std)
                let g_mean = 0.0 + g_u;
                let g_std = 0.0 + (0.0 + g_u) * eps[j];
                let g_log_std = (0.0 + g_std * s.std) - g_gaussian;
                // clamp = minimum(maximum(raw, lo), hi); a tie shares the gradient in halves
                let mask = |a: f32, b: f32| if a == b { 1f32 } else { 0.0 };
                let g_floored = 0.0 + (mask(s.log_std, s.floored) * g_log_std) / (mask(s.log_std, hi) * 1.0 + 1.0);
                let g_raw = 0.0 + (mask(s.floored, s.raw) * g_floored) / (mask(s.floored, lo) * 1.0 + 1.0);
                gx[j] = 0.0 + g_mean;
                gx[a + j] = 0.0 + g_raw;
            }
        }
    }
}

impl CustomOp1 for SquashedSample {
    fn name(&self) -> &'static str {
        "squashed-gaussian-sample"
    }

    fn cpu_fwd(&self, storage: &CpuStorage, layout: &Layout) -> Result<(CpuStorage, Shape)> {
        let out = contiguous(storage, layout, "squashed sample")?;
        let a = self.act_dim;
        let n = out.len() / (2 * a);
        let mut y = vec![0f32; n * (a + 1)];
        let mut saved = vec![Saved::default(); n * a];
        if n >= SPLIT_ROWS {
            let half = n / 2;
            let (y_a, y_z) = y.split_at_mut(half * (a + 1));
            let (s_a, s_z) = saved.split_at_mut(half * a);
            let (out_a, out_z) = out.split_at(half * 2 * a);
            let (eps_a, eps_z) = self.eps.split_at(half * a);
            second_core::join(
                || self.forward_rows(out_a, eps_a, y_a, s_a),
                || self.forward_rows(out_z, eps_z, y_z, s_z),
            );
        } else {
            self.forward_rows(out, &self.eps, &mut y, &mut saved);
        }
        *self.saved.lock().unwrap_or_else(|e| e.into_inner()) = saved;
        Ok((CpuStorage::F32(y), Shape::from((n, a + 1))))
    }

    fn bwd(&self, arg: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<Option<Tensor>> {
        let saved = self.saved.lock().unwrap_or_else(|e| e.into_inner());
        let a = self.act_dim;
        let n = saved.len() / a;
        if n == 0 && !self.eps.is_empty() {
            bail!("squashed sample: backward pass without a forward pass");
        }
        let grad = grad.contiguous()?.flatten_all()?.to_vec1::<f32>()?;
        let mut gx = vec![0f32; n * 2 * a];
        let path = self.path;
        if n >= SPLIT_ROWS {
            let half = n / 2;
            let (g_a, g_z) = grad.split_at(half * (a + 1));
            let (gx_a, gx_z) = gx.split_at_mut(half * 2 * a);
            let (s_a, s_z) = saved.split_at(half * a);
            let (eps_a, eps_z) = self.eps.split_at(half * a);
            second_core::join(
                || wide(path, || self.backward_rows(g_a, eps_a, s_a, gx_a)),
                || wide(path, || self.backward_rows(g_z, eps_z, s_z, gx_z)),
            );
        } else {
            wide(path, || self.backward_rows(&grad, &self.eps, &saved, &mut gx));
        }
        Ok(Some(Tensor::from_vec(gx, arg.shape(), arg.device())?))
    }
}

/// A reparameterised sample of the tanh-squashed Gaussian whose mean and raw log-std are the two
/// halves of `out` (`[n, 2 act_dim]`), the log-std clamped to `log_std_range`, with standard
/// normal noise `eps` (`n * act_dim` values): returns `[n, act_dim + 1]`, the action
/// `tanh(mean + exp(log_std) eps)` followed by its log-density summed over the action.
pub fn squashed_sample(
    out: &Tensor,
    eps: Vec<f32>,
    log_std_range: (f32, f32),
    correction: TanhCorrection,
) -> Result<Tensor> {
    let (n, width) = out.dims2()?;
    if width % 2 != 0 || width == 0 {
        bail!("squashed sample: the policy output has {width} columns, not 2 x act_dim");
    }
    let act_dim = width / 2;
    if eps.len() != n * act_dim {
        bail!("squashed sample: {} noise values for {n} x {act_dim} actions", eps.len());
    }
    let op = SquashedSample {
        eps,
        act_dim,
        log_std_range,
        correction,
        path: kernel_path::active(),
        saved: Mutex::new(Vec::new()),
    };
    out.apply_op1(op)
}
