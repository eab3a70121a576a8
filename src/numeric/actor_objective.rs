//! SAC's actor objective, `mean(alpha log_pi(a|s) - min_k Q_k(s, a))`, as two graph nodes around
//! the frozen critics: [`critic_input`] (the critics' input `[s, a]`) and [`actor_objective`] (the
//! minimum over the critics and the mean).
//!
//! Written with candle's operations the objective is about fifteen small nodes between the policy
//! head and the loss (two `narrow`s of the head's output, a `cat`, the minimum, an `affine`, a
//! difference, a sum and a division), and candle's backward pass adds as many again (zero
//! tensors for every padding and every first gradient). All of it ran on the training thread
//! alone while the helper thread waited: about 20 us of a two-thread SAC update.
//!
//! The two nodes give the bits of that graph (tested in `agents::sac` against it):
//! - the loss is computed by the same candle operations, on plain tensors inside the node (its
//!   sum is candle's, whose order depends on the CPU's AVX2 only);
//! - the gradients follow candle's rules (`backprop.rs` in candle-core 0.11): the minimum's
//!   gradient goes to each critic whose value equals it (`mask * g`), the difference gives `+g`
//!   and `-g`, the `affine`s multiply by their factor, and every gradient that candle starts
//!   from a zero tensor is written `0.0 + g` here, which turns -0.0 into +0.0 as candle does.
// Each step is written as the candle op it stands for, so that the correspondence can be read
// line by line.
#![allow(clippy::assign_op_pattern)]

use candle_core::{bail, CpuStorage, CustomOp2, Device, Layout, Result, Shape, Tensor};

use super::inplace::contiguous;

struct CriticInput {
    obs_dim: usize,
    act_dim: usize,
}

impl CustomOp2 for CriticInput {
    fn name(&self) -> &'static str {
        "critic-input"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (o, a) = (self.obs_dim, self.act_dim);
        let obs = contiguous(s1, l1, "critic input")?;
        let y = contiguous(s2, l2, "critic input")?;
        let n = obs.len() / o;
        let mut out = Vec::with_capacity(n * (o + a));
        for (obs, y) in obs.chunks_exact(o).zip(y.chunks_exact(a + 1)) {
            out.extend_from_slice(obs);
            out.extend_from_slice(&y[..a]);
        }
        Ok((CpuStorage::F32(out), Shape::from((n, o + a))))
    }

    fn bwd(&self, _obs: &Tensor, y: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let (o, a) = (self.obs_dim, self.act_dim);
        let grad = grad.contiguous()?.flatten_all()?.to_vec1::<f32>()?;
        // cat's gradient for the action is a narrow that starts from zero; the head's `narrow`
        // of the action pads it with a zero for the log-density
        let mut gy = Vec::with_capacity(grad.len() / (o + a) * (a + 1));
        for row in grad.chunks_exact(o + a) {
            gy.extend(row[o..].iter().map(|g| 0.0 + g));
            gy.push(0.0);
        }
        Ok((None, Some(Tensor::from_vec(gy, y.shape(), y.device())?)))
    }
}

/// The critics' input `[obs, action]` (`[n, obs_dim + act_dim]`) from the observations and the
/// policy head's output `y` (`[n, act_dim + 1]`: the action, then its log-density). Passes the
/// action's gradient back to `y`, none to `obs`.
pub fn critic_input(obs: &Tensor, y: &Tensor) -> Result<Tensor> {
    let (n, obs_dim) = obs.dims2()?;
    let (ny, width) = y.dims2()?;
    if ny != n || width < 2 {
        bail!("critic input: {n} observations but a policy output of shape [{ny}, {width}]");
    }
    obs.apply_op2(y, CriticInput { obs_dim, act_dim: width - 1 })
}

struct ActorObjective {
    alpha: f64,
}

impl ActorObjective {
    /// `min_k q_k` per row, as candle's `min(0)` keeps the first of equal values.
    fn minimum(q: &[f32], n: usize) -> Vec<f32> {
        (0..n)
            .map(|i| {
                let mut m = q[i];
                for member in q[n..].chunks_exact(n) {
                    if m > member[i] {
                        m = member[i];
                    }
                }
                m
            })
            .collect()
    }
}

impl CustomOp2 for ActorObjective {
    fn name(&self) -> &'static str {
        "actor-objective"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let q = contiguous(s1, l1, "actor objective")?;
        let y = contiguous(s2, l2, "actor objective")?;
        let (n, width) = l2.shape().dims2()?;
        let log_pi: Vec<f32> = y.chunks_exact(width).map(|row| row[width - 1]).collect();
        // candle's operations on plain tensors, for candle's sum
        let log_pi = Tensor::from_vec(log_pi, (n, 1), &Device::Cpu)?;
        let q_min = Tensor::from_vec(Self::minimum(q, n), (n, 1), &Device::Cpu)?;
        let loss = (log_pi.affine(self.alpha, 0.0)? - q_min)?.mean_all()?;
        Ok((CpuStorage::F32(vec![loss.to_scalar::<f32>()?]), Shape::from(())))
    }

    fn bwd(&self, q: &Tensor, y: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let (n, width) = y.dims2()?;
        let g_loss = grad.flatten_all()?.to_vec1::<f32>()?[0];
        // mean = sum * (1/n) + 0, then the squeeze, then the sum's broadcast
        let g_mean = 0.0 + (g_loss * (1.0 / n as f64) as f32 + 0.0);
        let g_sum = 0.0 + g_mean;
        let g_diff = 0.0 + g_sum;
        let g_lhs = 0.0 + g_diff;
        let g_rhs = 0.0 - g_diff;
        // alpha log_pi: affine(alpha, 0); log_pi is the last column of y
        let g_log_pi = 0.0 + (g_lhs * self.alpha as f32 + 0.0);
        let mut gy = vec![0f32; n * width];
        gy.iter_mut().skip(width - 1).step_by(width).for_each(|g| *g = g_log_pi);
        // the minimum: mask (its value equals q_k) times the gradient
        let q_values = q.flatten_all()?.to_vec1::<f32>()?;
        let q_min = Self::minimum(&q_values, n);
        let gq: Vec<f32> = q_values
            .chunks_exact(n)
            .flat_map(|member| {
                member.iter().zip(&q_min).map(|(q, m)| if q == m { 1f32 } else { 0.0 } * g_rhs).collect::<Vec<_>>()
            })
            .collect();
        Ok((Some(Tensor::from_vec(gq, q.shape(), q.device())?), Some(Tensor::from_vec(gy, y.shape(), y.device())?)))
    }
}

/// `mean(alpha log_pi - min_k q_k)`, a scalar, from the critics' values `q` (`[k, n, 1]`) and the
/// policy head's output `y` (`[n, act_dim + 1]`, the log-density last).
pub fn actor_objective(q: &Tensor, y: &Tensor, alpha: f64) -> Result<Tensor> {
    let (_, n, one) = q.dims3()?;
    let (ny, width) = y.dims2()?;
    if one != 1 || ny != n || width < 2 {
        bail!("actor objective: critic values of shape {:?} and a policy output of shape [{ny}, {width}]", q.dims());
    }
    q.apply_op2(y, ActorObjective { alpha })
}
