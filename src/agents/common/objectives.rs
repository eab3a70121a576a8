//! The off-policy agents' objectives as single graph nodes: the critics' mean squared error
//! ([`critic_mse`], TD3, DDPG and SAC), and SAC's actor objective `mean(alpha log_pi(a|s) - min_k
//! Q_k(s, a))` around the frozen critics ([`critic_input`], the critics' input `[s, a]`, and
//! [`actor_objective`], the minimum over the critics and the mean).
//!
//! Written with candle's operations these are small nodes on `[n, 1]` tensors (SAC's actor
//! objective about fifteen: two `narrow`s of the head's output, a `cat`, the minimum, an
//! `affine`, a difference, a sum and a division), and candle's backward pass adds as many again
//! (a zero tensor for every padding and every first gradient). All of it ran on the training
//! thread alone while the helper thread waited: about 20 us of a two-thread SAC update.
//!
//! The nodes give the bits of those graphs (tested in `agents::sac` and `agents::critics`):
//! - a loss is computed by the graph's own candle operations on the detached values, before the
//!   node, which holds it (candle's sum takes an order that depends on whether the CPU has AVX2,
//!   nothing else);
//! - the gradients follow candle's rules (`backprop.rs` in candle-core 0.11): the minimum's
//!   gradient goes to each critic whose value equals it (`mask * g`), a difference gives `+g` and
//!   `-g`, a square `(d * g) * 2`, an `affine` multiplies by its factor, and every gradient that
//!   candle starts from a zero tensor is written `0.0 + g` here, which turns -0.0 into +0.0 as
//!   candle does.
// Each step is written as the candle op it stands for, so that the correspondence can be read
// line by line.
#![allow(clippy::assign_op_pattern)]

use candle_core::{bail, CpuStorage, CustomOp2, Device, Layout, Result, Shape, Tensor, Var};

use crate::numeric::inplace::contiguous;

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

/// `min_k q_k` per row of the critics' values `q` (`[k, n, 1]`, flat), as candle's `min(0)`
/// computes it: the first member, replaced by each later one that is smaller.
pub fn critic_minimum(q: &[f32], n: usize) -> Vec<f32> {
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

struct ActorObjective {
    alpha: f64,
    /// The loss, computed before the node by candle's operations (for candle's sum).
    loss: f32,
}

impl CustomOp2 for ActorObjective {
    fn name(&self) -> &'static str {
        "actor-objective"
    }

    fn cpu_fwd(&self, _: &CpuStorage, _: &Layout, _: &CpuStorage, _: &Layout) -> Result<(CpuStorage, Shape)> {
        Ok((CpuStorage::F32(vec![self.loss]), Shape::from(())))
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
        let q_min = critic_minimum(&q_values, n);
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
    // the graph this node replaces, on the values alone
    let log_pi = y.detach().narrow(1, width - 1, 1)?;
    let loss = (log_pi.affine(alpha, 0.0)? - q.detach().min(0)?)?.mean_all()?.to_scalar::<f32>()?;
    q.apply_op2(y, ActorObjective { alpha, loss })
}

struct CriticMse {
    members: usize,
    /// The loss, computed before the node by candle's operations (for candle's sum).
    loss: f32,
}

impl CustomOp2 for CriticMse {
    fn name(&self) -> &'static str {
        "critic-mse"
    }

    fn cpu_fwd(&self, _: &CpuStorage, _: &Layout, _: &CpuStorage, _: &Layout) -> Result<(CpuStorage, Shape)> {
        Ok((CpuStorage::F32(vec![self.loss]), Shape::from(())))
    }

    fn bwd(&self, q: &Tensor, y: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let count = q.elem_count();
        let g_loss = grad.flatten_all()?.to_vec1::<f32>()?[0];
        // `* k` and the mean are affines, then the squeeze, then the sum's broadcast
        let g_mean = 0.0 + (g_loss * self.members as f32 + 0.0);
        let g_sum = 0.0 + (g_mean * (1.0 / count as f64) as f32 + 0.0);
        let g_square = 0.0 + (0.0 + g_sum);
        let y = y.flatten_all()?.to_vec1::<f32>()?;
        let q_values = q.flatten_all()?.to_vec1::<f32>()?;
        // sqr: (d * g) * 2 + 0 with d = q - y; the difference passes it to q
        let gq: Vec<f32> = q_values
            .chunks_exact(y.len())
            .flat_map(|member| {
                member.iter().zip(&y).map(|(q, y)| 0.0 + (0.0 + (((q - y) * g_square) * 2.0 + 0.0))).collect::<Vec<_>>()
            })
            .collect();
        Ok((Some(Tensor::from_vec(gq, q.shape(), q.device())?), None))
    }
}

/// The critics' loss, the sum over the `k` members of the mean squared error of their values `q`
/// (`[k, n, 1]`) against the target `y` (`[n, 1]`, no gradient): `k * mean((q - y)^2)`.
pub fn critic_mse(q: &Tensor, y: &Tensor) -> Result<Tensor> {
    let (k, n, one) = q.dims3()?;
    if one != 1 || y.dims() != [n, 1] {
        bail!("critic mse: critic values of shape {:?} and targets of shape {:?}", q.dims(), y.dims());
    }
    // the graph this node replaces, on the values alone
    let y = y.detach();
    let loss = (q.detach().broadcast_sub(&y)?.sqr()?.mean_all()? * k as f64)?.to_scalar::<f32>()?;
    q.apply_op2(&y, CriticMse { members: k, loss })
}

/// The critics' regression target `r + gamma (1 - terminated) v'` per row (`[n, 1]`, no
/// gradient), with candle's arithmetic for `rewards + (terminated.affine(-1, 1) * v').affine(gamma,
/// 0)`: the graph it replaces, computed without its five nodes.
pub fn td_target(rewards: &[f32], terminated: &[f32], next_value: &[f32], gamma: f64) -> Result<Tensor> {
    let n = rewards.len();
    if terminated.len() != n || next_value.len() != n {
        bail!("td target: {n} rewards, {} terminal flags and {} next values", terminated.len(), next_value.len());
    }
    let gamma = gamma as f32;
    let y = (rewards.iter().zip(terminated).zip(next_value))
        .map(|((r, t), v)| {
            let not_done = t * -1.0 + 1.0;
            r + ((not_done * v) * gamma + 0.0)
        })
        .collect();
    Tensor::from_vec(y, (n, 1), &Device::Cpu)
}

/// SAC's soft value of the next state per row, `min_k q_k - alpha log_pi`, from the target
/// critics' values `q` (`[k, n, 1]`) and the policy head's output `y` (`[n, act_dim + 1]`), with
/// candle's arithmetic for `q.min(0) - log_pi.affine(alpha, 0)`. Values only, no gradient.
pub fn soft_value(q: &Tensor, y: &Tensor, alpha: f64) -> Result<Vec<f32>> {
    let (_, n, _) = q.dims3()?;
    let width = y.dims2()?.1;
    let q_min = critic_minimum(&q.flatten_all()?.to_vec1::<f32>()?, n);
    let y = y.flatten_all()?.to_vec1::<f32>()?;
    let alpha = alpha as f32;
    Ok(q_min.iter().zip(y.chunks_exact(width)).map(|(m, row)| m - (row[width - 1] * alpha + 0.0)).collect())
}

/// The temperature exp(log_alpha).
pub(crate) fn temperature(log_alpha: &Var) -> Result<f64> {
    Ok(log_alpha.as_tensor().exp()?.flatten_all()?.to_vec1::<f32>()?[0] as f64)
}

/// The temperature's loss, -log_alpha (log pi + target entropy), averaged over the batch.
pub(crate) fn temperature_loss(log_alpha: &Var, log_prob: &Tensor, target_entropy: f64) -> Result<Tensor> {
    let gap = log_prob.detach().affine(1.0, target_entropy)?;
    log_alpha.as_tensor().broadcast_mul(&gap)?.mean_all()?.neg()
}
