//! The networks of the device-generic path, from candle's own operations: dense stacks (one
//! network `[out, in]`, or k networks stacked `[k, out, in]`), batch renormalisation, and SAC's
//! tanh-squashed Gaussian head. Each is the fused CPU node's function written as candle's graph
//! (the graphs the fused nodes are tested against in `numeric::`).
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use candle_core::{Device, DeviceLocation, Result, Tensor, Var, D};

use crate::agents::common::squashed::{LOG_STD_MAX, LOG_STD_MIN};
use crate::agents::config::TanhCorrection;

/// `value` as a one-element tensor on `device`, uploaded once and kept. candle's scalar forms
/// (`clamp(lo, hi)`, `maximum(lo)`) upload their scalar on every call, and on a GPU each such
/// upload is a synchronous copy that drains the queue of launched kernels.
pub(crate) fn constant(value: f32, device: &Device) -> Result<Tensor> {
    static KEPT: OnceLock<Mutex<HashMap<(DeviceLocation, u32), Tensor>>> = OnceLock::new();
    let key = (device.location(), value.to_bits());
    let mut kept = KEPT.get_or_init(Default::default).lock().unwrap_or_else(|e| e.into_inner());
    if let Some(t) = kept.get(&key) {
        return Ok(t.clone());
    }
    let t = Tensor::new(&[value], device)?;
    kept.insert(key, t.clone());
    Ok(t)
}

/// `x` clamped to `[lo, hi]`: candle's `clamp` (the same two operations, so the same values and
/// gradients) with its bounds kept on the device.
pub(crate) fn clamp(x: &Tensor, lo: f32, hi: f32) -> Result<Tensor> {
    x.broadcast_maximum(&constant(lo, x.device())?)?.broadcast_minimum(&constant(hi, x.device())?)
}

/// Dense layers with ReLU (or tanh, [`DeviceStack::with_tanh`]) between them and nothing after
/// the last. Weights are `[out, in]` (one network) or `[k, out, in]` with biases `[k, 1, out]` (k
/// networks evaluated together).
pub(crate) struct DeviceStack {
    layers: Vec<(Var, Var)>,
    tanh: bool,
}

impl DeviceStack {
    /// The layers `prefix.0.weight`, `prefix.0.bias`, ... of `params`, copied to `device`.
    pub fn from_named(params: &[(String, Var)], prefix: &str, device: &Device) -> Result<DeviceStack> {
        let find = |name: String| -> Result<Option<Var>> {
            match params.iter().find(|(n, _)| *n == name) {
                Some((_, v)) => Ok(Some(Var::from_tensor(&v.as_tensor().to_device(device)?)?)),
                None => Ok(None),
            }
        };
        let mut layers = Vec::new();
        while let Some(w) = find(format!("{prefix}.{}.weight", layers.len()))? {
            let b = find(format!("{prefix}.{}.bias", layers.len()))?.ok_or_else(|| {
                candle_core::Error::Msg(format!("{prefix}.{}: a weight without a bias", layers.len()))
            })?;
            layers.push((w, b));
        }
        if layers.is_empty() {
            candle_core::bail!("no layers named {prefix}.N.weight");
        }
        Ok(DeviceStack { layers, tanh: false })
    }

    /// The same layers with tanh between them (PPO's networks).
    pub fn with_tanh(self) -> DeviceStack {
        DeviceStack { tanh: true, ..self }
    }

    pub fn layers(&self) -> &[(Var, Var)] {
        &self.layers
    }

    /// `x` `[n, in]` through layer `i` (with ReLU after every layer but the last); stacked
    /// networks give `[k, n, out]`. `frozen`: the weights as constants.
    pub fn layer(&self, i: usize, x: &Tensor, frozen: bool) -> Result<Tensor> {
        let (w, b) = &self.layers[i];
        let (w, b) = if frozen {
            (w.as_tensor().detach(), b.as_tensor().detach())
        } else {
            (w.as_tensor().clone(), b.as_tensor().clone())
        };
        let h = if w.rank() == 3 { x.broadcast_matmul(&w.transpose(1, 2)?)? } else { x.matmul(&w.t()?)? };
        let h = h.broadcast_add(&b)?;
        match i + 1 < self.layers.len() {
            true if self.tanh => h.tanh(),
            true => h.relu(),
            false => Ok(h),
        }
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        (0..self.layers.len()).try_fold(x.clone(), |h, i| self.layer(i, &h, false))
    }

    /// The same function with the weights held constant: gradients reach `x` only.
    pub fn forward_frozen(&self, x: &Tensor) -> Result<Tensor> {
        (0..self.layers.len()).try_fold(x.clone(), |h, i| self.layer(i, &h, true))
    }

    /// Weights and biases, layer by layer (the fused stack's optimiser order).
    pub fn vars(&self) -> Vec<Var> {
        self.layers.iter().flat_map(|(w, b)| [w.clone(), b.clone()]).collect()
    }

    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        let mut out = Vec::new();
        for (i, (w, b)) in self.layers.iter().enumerate() {
            out.push((format!("{prefix}.{i}.weight"), w.clone()));
            out.push((format!("{prefix}.{i}.bias"), b.clone()));
        }
        out
    }

    /// target <- tau * self + (1 - tau) * target.
    pub fn polyak_into(&self, target: &DeviceStack, tau: f64) -> Result<()> {
        for (o, t) in self.vars().iter().zip(target.vars()) {
            t.set(&(o.as_tensor().affine(tau, 0.0)? + t.as_tensor().affine(1.0 - tau, 0.0)?)?)?;
        }
        Ok(())
    }
}

/// Batch renormalisation's constants (`agents::crossq`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct RenormConstants {
    pub eps: f64,
    pub r_max: f64,
    pub d_max: f64,
    pub momentum: f64,
    pub warmup: u64,
}

/// Batch renormalisation (Ioffe 2017) with its running statistics on the device.
pub(crate) struct DeviceRenorm {
    pub scale: Var,
    pub bias: Var,
    pub running_mean: Var,
    pub running_var: Var,
}

impl DeviceRenorm {
    /// The layer `prefix.{scale,bias,running_mean,running_var}` of `params`, copied to `device`.
    pub fn from_named(params: &[(String, Var)], prefix: &str, device: &Device) -> Result<DeviceRenorm> {
        let get = |what: &str| -> Result<Var> {
            let name = format!("{prefix}.{what}");
            let (_, v) = params
                .iter()
                .find(|(n, _)| *n == name)
                .ok_or_else(|| candle_core::Error::Msg(format!("no parameter {name}")))?;
            Var::from_tensor(&v.as_tensor().to_device(device)?)
        };
        Ok(DeviceRenorm {
            scale: get("scale")?,
            bias: get("bias")?,
            running_mean: get("running_mean")?,
            running_var: get("running_var")?,
        })
    }

    /// `x` `[n, f]` normalised: batch statistics when `train` (corrected by r and d, held
    /// constant, once `steps` reaches the warm-up; the running statistics move), the running
    /// ones otherwise. `frozen`: scale and bias as constants.
    pub fn forward(&self, x: &Tensor, train: bool, steps: u64, frozen: bool, c: RenormConstants) -> Result<Tensor> {
        let (scale, bias) = if frozen {
            (self.scale.as_tensor().detach(), self.bias.as_tensor().detach())
        } else {
            (self.scale.as_tensor().clone(), self.bias.as_tensor().clone())
        };
        let f = scale.elem_count();
        // Views of the statistics, which are no parameters. `set` below overwrites their storage:
        // that is safe because candle runs each operation when it is called (on a GPU, in stream
        // order), and no gradient reads these values back.
        let rm = self.running_mean.as_tensor().detach().reshape((1, f))?;
        let rv = self.running_var.as_tensor().detach().reshape((1, f))?;
        let (mean, var) = if !train {
            (rm, rv)
        } else {
            let mean = x.mean_keepdim(0)?;
            let var = x.broadcast_sub(&mean)?.sqr()?.mean_keepdim(0)?;
            let m = c.momentum;
            let moved = |running: &Tensor, batch: &Tensor| -> Result<Tensor> {
                (running.affine(m, 0.0)? + batch.detach().affine(1.0 - m, 0.0)?)?.reshape(f)
            };
            let (new_mean, new_var) = (moved(&rm, &mean)?, moved(&rv, &var)?);
            let corrected = if steps >= c.warmup {
                let running_std = rv.affine(1.0, c.eps)?.sqrt()?;
                let std = var.detach().affine(1.0, c.eps)?.sqrt()?;
                let r = clamp(&(std / &running_std)?, (1.0 / c.r_max) as f32, c.r_max as f32)?;
                let d = mean.detach().broadcast_sub(&rm)?.broadcast_div(&running_std)?;
                let d = clamp(&d, -c.d_max as f32, c.d_max as f32)?;
                let corrected_var = var.broadcast_div(&r.sqr()?)?;
                // sqrt's gradient is infinite at a constant column's zero variance, where the fused
                // node takes the term's gradient as zero; flooring the variance does the same
                let std = var.broadcast_maximum(&constant(1e-30, var.device())?)?.sqrt()?;
                let corrected_mean = (&mean - (d * std / &r)?)?;
                (corrected_mean, corrected_var)
            } else {
                (mean, var)
            };
            self.running_mean.set(&new_mean)?;
            self.running_var.set(&new_var)?;
            corrected
        };
        let normalised = x.broadcast_sub(&mean)?.broadcast_div(&var.affine(1.0, c.eps)?.sqrt()?)?;
        normalised.broadcast_mul(&scale)?.broadcast_add(&bias)
    }

    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        vec![
            (format!("{prefix}.scale"), self.scale.clone()),
            (format!("{prefix}.bias"), self.bias.clone()),
            (format!("{prefix}.running_mean"), self.running_mean.clone()),
            (format!("{prefix}.running_var"), self.running_var.clone()),
        ]
    }
}

/// A reparameterised sample of the tanh-squashed Gaussian whose mean and raw log-std are the
/// halves of `out` (`[n, 2a]`), with standard normal noise `eps` (`[n, a]`): the action `[n, a]`
/// and its log-density `[n, 1]` (`agents::squashed`'s function).
pub(crate) fn squashed_sample(out: &Tensor, eps: &Tensor, correction: TanhCorrection) -> Result<(Tensor, Tensor)> {
    let a = out.dim(1)? / 2;
    let mean = out.narrow(1, 0, a)?;
    let log_std = clamp(&out.narrow(1, a, a)?, LOG_STD_MIN as f32, LOG_STD_MAX as f32)?;
    let u = (mean + (log_std.exp()? * eps)?)?;
    let half_log_2pi = 0.5 * (2.0 * std::f64::consts::PI).ln();
    let gaussian = (eps.sqr()?.affine(-0.5, -half_log_2pi)? - &log_std)?;
    let squash = match correction {
        TanhCorrection::Exact => {
            // log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)), softplus(x) = max(x, 0) + log(1 + exp(-|x|))
            let minus_2u = u.affine(-2.0, 0.0)?;
            let exp_term = minus_2u.abs()?.neg()?.exp()?;
            let softplus = (minus_2u.relu()? + exp_term.affine(1.0, 1.0)?.log()?)?;
            ((u.neg()? - softplus)? + 2f64.ln())?.affine(2.0, 0.0)?
        }
        TanhCorrection::Epsilon => u.tanh()?.sqr()?.affine(-1.0, 1.0 + 1e-6)?.log()?,
    };
    let log_prob = (gaussian - squash)?.sum_keepdim(D::Minus1)?;
    Ok((u.tanh()?, log_prob))
}
