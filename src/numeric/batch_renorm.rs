//! Batch renormalisation (Ioffe, "Batch Renormalization", NeurIPS 2017) of `[n, features]` rows
//! as one autograd node, forward and backward.
//!
//! Written with candle's broadcast operations the layer is about ten graph nodes forward and
//! more backward, each a pass over the whole `[n, features]` block with generic strided loops; at
//! CrossQ's sizes (512 rows of 512 features, six layers per update) those passes cost several
//! times the matrix products (`cargo bench --bench agents`, crossq line). Here the forward pass is
//! two column passes for the statistics and one for the output, the backward pass two more.
//! The statistics are summed in f64, the gradient sums in f32, all row by row: one fixed order
//! on every CPU. Per-column constants are computed in f64, per-element work is f32 multiply-adds
//! without divisions.
//!
//! With per-column batch mean mu, variance v and s = sqrt(v), and r, d held constant:
//! mu_c = mu - d s / r, v_c = v / r^2, D = sqrt(v_c + eps), x^ = (x - mu_c) / D, y = scale x^ + bias.
//! Before renormalisation starts r = 1 and d = 0 (plain batch normalisation); in evaluation mode
//! the running statistics replace mu_c and v_c and carry no gradient.
use candle_core::{bail, CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};

use super::inplace::{contiguous, cpu_contiguous};

/// How a pass normalises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RenormMode {
    /// The batch's own statistics (batch normalisation; the renormalisation warm-up).
    Batch,
    /// The batch's statistics corrected towards the running ones by r and d.
    Renorm,
    /// The running statistics alone (evaluation).
    Running,
}

/// The constants of the layer: variance epsilon and the limits on r and d.
#[derive(Debug, Clone, Copy)]
pub struct RenormLimits {
    /// Added to every variance.
    pub eps: f64,
    /// r is clipped to [1 / r_max, r_max].
    pub r_max: f64,
    /// d is clipped to [-d_max, d_max].
    pub d_max: f64,
}

/// Per-column constants of one pass (f64, computed once in the forward pass).
struct Columns {
    /// Centre and divisor of the normalisation: mu_c and D.
    centre: Vec<f64>,
    divisor: Vec<f64>,
    /// Batch statistics and the corrections, for the backward pass (empty in `Running` mode).
    mean: Vec<f64>,
    std: Vec<f64>,
    r: Vec<f64>,
    d: Vec<f64>,
}

struct BatchRenormOp {
    columns: Columns,
    from_batch: bool,
}

/// Column means and (biased) variances of row-major `[n, f]` data, summed row by row in f64.
fn column_stats(x: &[f32], f: usize) -> (Vec<f64>, Vec<f64>) {
    let n = (x.len() / f) as f64;
    let mut mean = vec![0f64; f];
    for row in x.chunks_exact(f) {
        mean.iter_mut().zip(row).for_each(|(m, &v)| *m += v as f64);
    }
    mean.iter_mut().for_each(|m| *m /= n);
    let mut var = vec![0f64; f];
    for row in x.chunks_exact(f) {
        var.iter_mut().zip(row).zip(&mean).for_each(|((s, &v), m)| *s += (v as f64 - m) * (v as f64 - m));
    }
    var.iter_mut().for_each(|s| *s /= n);
    (mean, var)
}

impl CustomOp3 for BatchRenormOp {
    fn name(&self) -> &'static str {
        "batch_renorm"
    }

    fn cpu_fwd(
        &self,
        s1: &CpuStorage,
        l1: &Layout,
        s2: &CpuStorage,
        l2: &Layout,
        s3: &CpuStorage,
        l3: &Layout,
    ) -> Result<(CpuStorage, Shape)> {
        let x = contiguous(s1, l1, "batch_renorm")?;
        let (scale, bias) = (contiguous(s2, l2, "batch_renorm")?, contiguous(s3, l3, "batch_renorm")?);
        let c = &self.columns;
        // y = (x - centre) * (scale / D) + bias, in f32 per element (column constants in f64 first).
        let gain: Vec<f32> = scale.iter().zip(&c.divisor).map(|(&g, &d)| (g as f64 / d) as f32).collect();
        let centre: Vec<f32> = c.centre.iter().map(|&m| m as f32).collect();
        let mut y = vec![0f32; x.len()];
        for (yr, xr) in y.chunks_exact_mut(scale.len()).zip(x.chunks_exact(scale.len())) {
            for j in 0..yr.len() {
                yr[j] = (xr[j] - centre[j]) * gain[j] + bias[j];
            }
        }
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(
        &self,
        x: &Tensor,
        scale: &Tensor,
        _bias: &Tensor,
        _y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let grad = grad.contiguous()?;
        let (xs, xl) = x.storage_and_layout();
        let (ss, sl) = scale.storage_and_layout();
        let (gs, gl) = grad.storage_and_layout();
        let (xv, sv, gv) = (
            cpu_contiguous(&xs, xl, "batch_renorm")?,
            cpu_contiguous(&ss, sl, "batch_renorm")?,
            cpu_contiguous(&gs, gl, "batch_renorm")?,
        );
        let f = sv.len();
        let n = xv.len() / f;
        let c = &self.columns;
        let inv_divisor: Vec<f32> = c.divisor.iter().map(|&d| (1.0 / d) as f32).collect();
        let centre: Vec<f32> = c.centre.iter().map(|&m| m as f32).collect();
        // dscale = sum g x^, dbias = sum g, per column, summed row by row in f32.
        let (mut dscale, mut dbias) = (vec![0f32; f], vec![0f32; f]);
        for (xr, gr) in xv.chunks_exact(f).zip(gv.chunks_exact(f)) {
            for j in 0..f {
                dscale[j] += gr[j] * ((xr[j] - centre[j]) * inv_divisor[j]);
                dbias[j] += gr[j];
            }
        }
        let grad_x = if x.track_op() {
            // dx = g scale / D + dL/dmu / n + dL/dv 2 (x - mu) / n, where dL/dmu and dL/dv are the
            // gradients through the batch statistics (see the module comment), zero in `Running`.
            let gain: Vec<f32> = sv.iter().zip(&inv_divisor).map(|(&g, &i)| g * i).collect();
            let (mut shift, mut slope, mut mean) = (vec![0f32; f], vec![0f32; f], vec![0f32; f]);
            if self.from_batch {
                let n = n as f64;
                for j in 0..f {
                    let gamma = sv[j] as f64;
                    let (sum_g, sum_gx) = (gamma * dbias[j] as f64, gamma * dscale[j] as f64);
                    let (divisor, r, d) = (c.divisor[j], c.r[j], c.d[j]);
                    let d_centre = -sum_g / divisor;
                    let d_divisor = -sum_gx / divisor;
                    let through_std =
                        if d != 0.0 && c.std[j] > 0.0 { d_centre * (-d / r) / (2.0 * c.std[j]) } else { 0.0 };
                    let d_var = d_divisor / (2.0 * divisor * r * r) + through_std;
                    shift[j] = (d_centre / n) as f32;
                    slope[j] = (2.0 * d_var / n) as f32;
                    mean[j] = c.mean[j] as f32;
                }
            }
            let mut gx = vec![0f32; xv.len()];
            for ((out, xr), gr) in gx.chunks_exact_mut(f).zip(xv.chunks_exact(f)).zip(gv.chunks_exact(f)) {
                for j in 0..f {
                    out[j] = gr[j] * gain[j] + shift[j] + slope[j] * (xr[j] - mean[j]);
                }
            }
            Some(Tensor::from_vec(gx, x.shape(), x.device())?)
        } else {
            None
        };
        drop((xs, ss, gs));
        Ok((grad_x, Some(Tensor::from_vec(dscale, f, x.device())?), Some(Tensor::from_vec(dbias, f, x.device())?)))
    }
}

/// One batch-renormalisation pass over `x [n, features]` with `scale` and `bias` (`[features]`)
/// and the layer's running statistics. Returns the output and, when the batch's statistics were
/// used, the batch mean and variance (for the running averages), as f32.
#[allow(clippy::type_complexity)]
pub fn batch_renorm(
    x: &Tensor,
    scale: &Tensor,
    bias: &Tensor,
    running_mean: &[f32],
    running_var: &[f32],
    mode: RenormMode,
    limits: RenormLimits,
) -> Result<(Tensor, Option<(Vec<f32>, Vec<f32>)>)> {
    let x = &x.contiguous()?;
    let (n, f) = x.dims2()?;
    if scale.elem_count() != f || bias.elem_count() != f || running_mean.len() != f || running_var.len() != f {
        bail!("batch_renorm: {f} features, but scale, bias and running statistics of other sizes");
    }
    if mode != RenormMode::Running && n < 2 {
        bail!("batch_renorm: batch statistics need at least 2 rows, got {n}");
    }
    let eps = limits.eps;
    let (columns, stats) = if mode == RenormMode::Running {
        let columns = Columns {
            centre: running_mean.iter().map(|&m| m as f64).collect(),
            divisor: running_var.iter().map(|&v| (v as f64 + eps).sqrt()).collect(),
            mean: Vec::new(),
            std: Vec::new(),
            r: Vec::new(),
            d: Vec::new(),
        };
        (columns, None)
    } else {
        let (xs, xl) = x.storage_and_layout();
        let (mean, var) = column_stats(cpu_contiguous(&xs, xl, "batch_renorm")?, f);
        drop(xs);
        let std: Vec<f64> = var.iter().map(|v| v.sqrt()).collect();
        let (mut r, mut d) = (vec![1f64; f], vec![0f64; f]);
        if mode == RenormMode::Renorm {
            for j in 0..f {
                let running_std = (running_var[j] as f64 + eps).sqrt();
                r[j] = ((var[j] + eps).sqrt() / running_std).clamp(1.0 / limits.r_max, limits.r_max);
                d[j] = ((mean[j] - running_mean[j] as f64) / running_std).clamp(-limits.d_max, limits.d_max);
            }
        }
        let centre: Vec<f64> = (0..f).map(|j| mean[j] - d[j] * std[j] / r[j]).collect();
        let divisor: Vec<f64> = (0..f).map(|j| (var[j] / (r[j] * r[j]) + eps).sqrt()).collect();
        let stats = (mean.iter().map(|&m| m as f32).collect(), var.iter().map(|&v| v as f32).collect());
        (Columns { centre, divisor, mean, std, r, d }, Some(stats))
    };
    let op = BatchRenormOp { columns, from_batch: mode != RenormMode::Running };
    Ok((x.apply_op3(scale, bias, op)?, stats))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    const LIMITS: RenormLimits = RenormLimits { eps: 1e-3, r_max: 3.0, d_max: 5.0 };

    /// The same layer from candle's own operations, as the agents first wrote it.
    fn reference(
        x: &Tensor,
        scale: &Tensor,
        bias: &Tensor,
        rm: &[f32],
        rv: &[f32],
        mode: RenormMode,
    ) -> Result<Tensor> {
        let f = rm.len();
        let rm = Tensor::from_slice(rm, (1, f), &Device::Cpu)?;
        let rv = Tensor::from_slice(rv, (1, f), &Device::Cpu)?;
        let (mean, var) = if mode == RenormMode::Running {
            (rm, rv)
        } else {
            let mean = x.mean_keepdim(0)?;
            let var = x.broadcast_sub(&mean)?.sqr()?.mean_keepdim(0)?;
            if mode == RenormMode::Renorm {
                let running_std = rv.affine(1.0, LIMITS.eps)?.sqrt()?;
                let std = var.detach().affine(1.0, LIMITS.eps)?.sqrt()?;
                let r = (std / &running_std)?.clamp(1.0 / LIMITS.r_max, LIMITS.r_max)?;
                let d = mean
                    .detach()
                    .broadcast_sub(&rm)?
                    .broadcast_div(&running_std)?
                    .clamp(-LIMITS.d_max, LIMITS.d_max)?;
                let corrected_var = var.broadcast_div(&r.sqr()?)?;
                let corrected_mean = (&mean - (d * var.sqrt()? / &r)?)?;
                (corrected_mean, corrected_var)
            } else {
                (mean, var)
            }
        };
        let normalised = x.broadcast_sub(&mean)?.broadcast_div(&var.affine(1.0, LIMITS.eps)?.sqrt()?)?;
        normalised.broadcast_mul(scale)?.broadcast_add(bias)
    }

    fn close(a: &Tensor, b: &Tensor, tol: f32, what: &str) {
        let (a, b) =
            (a.flatten_all().unwrap().to_vec1::<f32>().unwrap(), b.flatten_all().unwrap().to_vec1::<f32>().unwrap());
        assert_eq!(a.len(), b.len());
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!((x - y).abs() <= tol * (1.0 + y.abs()), "{what}[{i}]: {x} vs {y}");
        }
    }

    #[test]
    fn output_and_gradients_match_candles_operations_in_every_mode() {
        let dev = &Device::Cpu;
        let (n, f) = (64, 7);
        let data: Vec<f32> =
            (0..n * f).map(|i| ((i * 37 % 101) as f32 * 0.13).sin() * (1.0 + (i % f) as f32)).collect();
        let x = Var::from_tensor(&Tensor::from_vec(data, (n, f), dev).unwrap()).unwrap();
        let scale =
            Var::from_tensor(&Tensor::from_vec((0..f).map(|j| 0.5 + 0.2 * j as f32).collect(), f, dev).unwrap())
                .unwrap();
        let bias = Var::from_tensor(&Tensor::from_vec((0..f).map(|j| 0.1 * j as f32 - 0.3).collect(), f, dev).unwrap())
            .unwrap();
        // Running statistics far enough from the batch's that r and d clip in some columns.
        let rm: Vec<f32> = (0..f).map(|j| if j % 2 == 0 { 0.05 } else { 3.0 }).collect();
        let rv: Vec<f32> = (0..f).map(|j| if j % 3 == 0 { 0.02 } else { 1.5 }).collect();
        // A loss whose gradient differs per element, so that sums of gradients are not trivial.
        let weights =
            Tensor::from_vec((0..n * f).map(|i| ((i * 13 % 29) as f32 - 14.0) * 0.1).collect(), (n, f), dev).unwrap();
        for mode in [RenormMode::Batch, RenormMode::Renorm, RenormMode::Running] {
            let (ours, stats) =
                batch_renorm(x.as_tensor(), scale.as_tensor(), bias.as_tensor(), &rm, &rv, mode, LIMITS).unwrap();
            let theirs = reference(x.as_tensor(), scale.as_tensor(), bias.as_tensor(), &rm, &rv, mode).unwrap();
            close(&ours, &theirs, 1e-5, &format!("{mode:?} output"));
            assert_eq!(stats.is_some(), mode != RenormMode::Running);
            if let Some((mean, var)) = stats {
                close(&Tensor::new(mean, dev).unwrap(), &x.as_tensor().mean(0).unwrap(), 1e-6, "mean");
                let v = x
                    .as_tensor()
                    .broadcast_sub(&x.as_tensor().mean_keepdim(0).unwrap())
                    .unwrap()
                    .sqr()
                    .unwrap()
                    .mean(0)
                    .unwrap();
                close(&Tensor::new(var, dev).unwrap(), &v, 1e-5, "variance");
            }
            let g_ours = (ours * &weights).unwrap().sum_all().unwrap().backward().unwrap();
            let g_theirs = (theirs * &weights).unwrap().sum_all().unwrap().backward().unwrap();
            for (var, name) in [(&x, "x"), (&scale, "scale"), (&bias, "bias")] {
                let (a, b) = (g_ours.get(var.as_tensor()).unwrap(), g_theirs.get(var.as_tensor()).unwrap());
                close(a, b, 1e-4, &format!("{mode:?} gradient of {name}"));
            }
        }
    }

    #[test]
    fn bad_sizes_and_one_row_batches_are_refused() {
        let dev = &Device::Cpu;
        let x = Tensor::zeros((1, 3), candle_core::DType::F32, dev).unwrap();
        let p = Tensor::zeros(3, candle_core::DType::F32, dev).unwrap();
        let err = batch_renorm(&x, &p, &p, &[0.0; 3], &[1.0; 3], RenormMode::Batch, LIMITS).unwrap_err();
        assert!(err.to_string().contains("at least 2 rows"), "{err}");
        assert!(batch_renorm(&x, &p, &p, &[0.0; 3], &[1.0; 3], RenormMode::Running, LIMITS).is_ok());
        let err = batch_renorm(&x, &p, &p, &[0.0; 2], &[1.0; 2], RenormMode::Running, LIMITS).unwrap_err();
        assert!(err.to_string().contains("3 features"), "{err}");
    }
}
