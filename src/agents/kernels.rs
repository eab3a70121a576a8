//! CPU kernels for the per-update hot path: in place, an Adam step and a Polyak average (one pass
//! over the parameter, no temporary tensors); as autograd nodes, bias + activation.
//! candle's tensor expressions allocate a new tensor per operation, and `Var::set` copies once
//! more; the throughput bench measured those as the biggest cost outside the matmuls
//! (README, "Training throughput"). Each kernel is tested against the tensor expression it
//! replaces.
use std::cell::RefCell;

use candle_core::{bail, CpuStorage, InplaceOp2, Layout, Result, Shape, Tensor};

fn contiguous_mut<'a>(storage: &'a mut CpuStorage, layout: &Layout, what: &str) -> Result<&'a mut [f32]> {
    let Some((start, end)) = layout.contiguous_offsets() else { bail!("{what}: destination tensor is not contiguous") };
    match storage {
        CpuStorage::F32(data) => Ok(&mut data[start..end]),
        _ => bail!("{what}: only f32 tensors are supported"),
    }
}

fn contiguous<'a>(storage: &'a CpuStorage, layout: &Layout, what: &str) -> Result<&'a [f32]> {
    let Some((start, end)) = layout.contiguous_offsets() else { bail!("{what}: source tensor is not contiguous") };
    match storage {
        CpuStorage::F32(data) => Ok(&data[start..end]),
        _ => bail!("{what}: only f32 tensors are supported"),
    }
}

/// One Adam step on one parameter, PyTorch's formula in f32:
/// m <- b1 m + (1-b1) g; v <- b2 v + (1-b2) g^2; theta <- theta - (lr/bc1) m / (sqrt(v)/sqrt(bc2) + eps)
/// with bc_i = 1 - b_i^t.
pub struct AdamStep<'a> {
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    /// 1 - beta1^t and 1 - beta2^t for the current step t.
    pub bias_correction1: f32,
    pub bias_correction2: f32,
    pub m: RefCell<&'a mut [f32]>,
    pub v: RefCell<&'a mut [f32]>,
}

impl InplaceOp2 for AdamStep<'_> {
    fn name(&self) -> &'static str {
        "adam-step"
    }

    fn cpu_fwd(&self, s1: &mut CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<()> {
        let theta = contiguous_mut(s1, l1, "adam")?;
        let grad = contiguous(s2, l2, "adam")?;
        let (mut m, mut v) = (self.m.borrow_mut(), self.v.borrow_mut());
        if theta.len() != grad.len() || m.len() != grad.len() || v.len() != grad.len() {
            bail!("adam: parameter, gradient and moments differ in length");
        }
        let (b1, b2) = (self.beta1, self.beta2);
        let step_size = self.lr / self.bias_correction1;
        let inv_sqrt_bc2 = 1.0 / self.bias_correction2.sqrt();
        for (((t, g), m), v) in theta.iter_mut().zip(grad).zip(m.iter_mut()).zip(v.iter_mut()) {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            *t -= step_size * *m / (v.sqrt() * inv_sqrt_bc2 + self.eps);
        }
        Ok(())
    }
}

/// target <- tau * online + (1 - tau) * target.
pub struct Polyak {
    pub tau: f32,
}

impl InplaceOp2 for Polyak {
    fn name(&self) -> &'static str {
        "polyak"
    }

    fn cpu_fwd(&self, s1: &mut CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<()> {
        let target = contiguous_mut(s1, l1, "polyak")?;
        let online = contiguous(s2, l2, "polyak")?;
        if target.len() != online.len() {
            bail!("polyak: online and target differ in length");
        }
        let keep = 1.0 - self.tau;
        for (t, o) in target.iter_mut().zip(online) {
            *t = self.tau * o + keep * *t;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;

    #[test]
    fn polyak_matches_the_tensor_expression_and_refuses_strided_targets() {
        let online = Tensor::new(&[1.0f32, -2.0, 3.5], &Device::Cpu).unwrap();
        let target = Tensor::new(&[0.5f32, 0.25, -1.0], &Device::Cpu).unwrap();
        let expected = ((&online * 0.1).unwrap() + (&target * 0.9).unwrap()).unwrap().to_vec1::<f32>().unwrap();
        target.inplace_op2(&online, &Polyak { tau: 0.1 }).unwrap();
        for (a, b) in target.to_vec1::<f32>().unwrap().iter().zip(&expected) {
            assert!((a - b).abs() < 1e-6);
        }
        let transposed = Tensor::zeros((3, 3), candle_core::DType::F32, &Device::Cpu).unwrap().t().unwrap();
        assert!(transposed
            .inplace_op2(&Tensor::zeros((3, 3), candle_core::DType::F32, &Device::Cpu).unwrap(), &Polyak { tau: 0.5 })
            .is_err());
    }
}

/// What a layer applies after adding its bias.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Activation {
    Identity,
    Relu,
}

/// `act(x + b)` as one autograd node. `x` is `[.., rows, out]` (a matmul's output), `b` holds
/// `groups * out` values (`[out]` for one network, `[k, 1, out]` for k stacked networks), group g's
/// bias going to the g-th block of rows. candle builds the same thing from a broadcast add and a
/// ReLU, whose backward passes allocate and sweep the activations about eight times and reduce
/// the bias gradient with a per-element index division; here the backward is one mask pass and
/// one row sum.
pub struct BiasAct(pub Activation);

fn groups(x_len: usize, b_len: usize, out: usize, what: &str) -> Result<(usize, usize)> {
    if out == 0 || b_len % out != 0 || x_len % b_len != 0 {
        bail!("{what}: {x_len} activations do not split into rows of {out} for {b_len} bias values");
    }
    let groups = b_len / out;
    Ok((groups, x_len / b_len))
}

impl candle_core::CustomOp2 for BiasAct {
    fn name(&self) -> &'static str {
        "bias-act"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (x, b) = (contiguous(s1, l1, "bias-act")?, contiguous(s2, l2, "bias-act")?);
        let out = *l1.dims().last().unwrap_or(&0);
        let (groups, rows) = groups(x.len(), b.len(), out, "bias-act")?;
        let mut y = Vec::with_capacity(x.len());
        for g in 0..groups {
            let bias = &b[g * out..(g + 1) * out];
            for row in x[g * rows * out..(g + 1) * rows * out].chunks_exact(out) {
                match self.0 {
                    Activation::Identity => y.extend(row.iter().zip(bias).map(|(x, b)| x + b)),
                    Activation::Relu => y.extend(row.iter().zip(bias).map(|(x, b)| (x + b).max(0.0))),
                }
            }
        }
        Ok((CpuStorage::F32(y), l1.shape().clone()))
    }

    fn bwd(&self, _x: &Tensor, b: &Tensor, y: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let grad_pre = match self.0 {
            Activation::Identity => grad.clone(),
            Activation::Relu => grad.contiguous()?.apply_op2_no_bwd(y, &ReluMask)?,
        };
        let groups = b.elem_count() / y.dims().last().copied().unwrap_or(1).max(1);
        let grad_b = grad_pre.contiguous()?.apply_op1_no_bwd(&RowSum { groups })?.reshape(b.shape())?;
        Ok((Some(grad_pre), Some(grad_b)))
    }
}

/// grad where the ReLU's output is positive, 0 elsewhere.
struct ReluMask;

impl candle_core::CustomOp2 for ReluMask {
    fn name(&self) -> &'static str {
        "relu-mask"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let (grad, y) = (contiguous(s1, l1, "relu-mask")?, contiguous(s2, l2, "relu-mask")?);
        if grad.len() != y.len() {
            bail!("relu-mask: gradient and output differ in length");
        }
        let masked = grad.iter().zip(y).map(|(g, y)| if *y > 0.0 { *g } else { 0.0 }).collect();
        Ok((CpuStorage::F32(masked), l1.shape().clone()))
    }
}

/// Sums `[groups * rows, out]` over the rows of each group: `[groups, out]`.
struct RowSum {
    groups: usize,
}

impl candle_core::CustomOp1 for RowSum {
    fn name(&self) -> &'static str {
        "row-sum"
    }

    fn cpu_fwd(&self, s: &CpuStorage, l: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = contiguous(s, l, "row-sum")?;
        let out = *l.dims().last().unwrap_or(&0);
        let (groups, rows) = groups(x.len(), self.groups * out, out, "row-sum")?;
        let mut sums = vec![0f32; groups * out];
        for (g, acc) in sums.chunks_exact_mut(out).enumerate() {
            for row in x[g * rows * out..(g + 1) * rows * out].chunks_exact(out) {
                acc.iter_mut().zip(row).for_each(|(a, x)| *a += x);
            }
        }
        Ok((CpuStorage::F32(sums), Shape::from((groups, out))))
    }
}

/// `act(x + b)` with the backward pass of `BiasAct`.
pub fn bias_act(x: &Tensor, b: &Tensor, act: Activation) -> Result<Tensor> {
    x.contiguous()?.apply_op2(&b.contiguous()?, BiasAct(act))
}

#[cfg(test)]
mod bias_act_tests {
    use super::*;
    use candle_core::{DType, Device, Var};

    /// Value and gradients equal candle's broadcast add + ReLU, for one network and for two
    /// stacked ones.
    #[test]
    fn bias_act_matches_broadcast_add_and_relu() {
        let dev = Device::Cpu;
        let values = |n: usize, seed: f32| (0..n).map(|i| ((i as f32 * 0.37 + seed).sin() * 2.0)).collect::<Vec<_>>();
        for (x_shape, b_shape) in [(vec![5, 4], vec![4]), (vec![2, 5, 4], vec![2, 1, 4])] {
            for act in [Activation::Identity, Activation::Relu] {
                let n: usize = x_shape.iter().product();
                let x = Var::from_tensor(&Tensor::from_vec(values(n, 0.1), x_shape.clone(), &dev).unwrap()).unwrap();
                let b = Var::from_tensor(
                    &Tensor::from_vec(values(b_shape.iter().product(), 0.5), b_shape.clone(), &dev).unwrap(),
                )
                .unwrap();
                let w = Tensor::from_vec(values(n, 1.3), x_shape.clone(), &dev).unwrap();
                let reference = {
                    let pre = x.as_tensor().broadcast_add(b.as_tensor()).unwrap();
                    if act == Activation::Relu {
                        pre.relu().unwrap()
                    } else {
                        pre
                    }
                };
                let ours = bias_act(x.as_tensor(), b.as_tensor(), act).unwrap();
                let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
                assert_eq!(flat(&ours), flat(&reference));
                let g_ref = (reference * &w).unwrap().sum_all().unwrap().backward().unwrap();
                let g_ours = (ours * &w).unwrap().sum_all().unwrap().backward().unwrap();
                for v in [&x, &b] {
                    let (a, e) = (flat(g_ours.get(v.as_tensor()).unwrap()), flat(g_ref.get(v.as_tensor()).unwrap()));
                    assert_eq!(g_ours.get(v.as_tensor()).unwrap().dims(), v.dims());
                    for (a, e) in a.iter().zip(&e) {
                        assert!((a - e).abs() < 1e-5, "{act:?} {x_shape:?}: {a} vs {e}");
                    }
                }
            }
        }
        let bad = bias_act(
            &Tensor::zeros((3, 4), DType::F32, &dev).unwrap(),
            &Tensor::zeros(3, DType::F32, &dev).unwrap(),
            Activation::Relu,
        );
        assert!(bad.is_err());
    }
}
