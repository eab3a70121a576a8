//! CPU kernels for the per-update hot path: in place, an Adam step and a Polyak average (one pass
//! over the parameter, no temporary tensors); for the dense layer's backward pass, a ReLU mask
//! and a row sum.
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

pub(super) fn contiguous<'a>(storage: &'a CpuStorage, layout: &Layout, what: &str) -> Result<&'a [f32]> {
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

/// What a layer applies after adding its bias.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Activation {
    Identity,
    Relu,
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
        let (groups, out) = (self.groups, *l.dims().last().unwrap_or(&0));
        if out == 0 || groups == 0 || x.len() % (groups * out) != 0 {
            bail!("row-sum: {} values do not split into {groups} groups of rows of {out}", x.len());
        }
        let rows = x.len() / (groups * out);
        let mut sums = vec![0f32; groups * out];
        for (g, acc) in sums.chunks_exact_mut(out).enumerate() {
            for row in x[g * rows * out..(g + 1) * rows * out].chunks_exact(out) {
                acc.iter_mut().zip(row).for_each(|(a, x)| *a += x);
            }
        }
        Ok((CpuStorage::F32(sums), Shape::from((groups, out))))
    }
}

/// `grad` where the ReLU output `y` is positive, 0 elsewhere.
pub fn relu_mask(grad: &Tensor, y: &Tensor) -> Result<Tensor> {
    grad.contiguous()?.apply_op2_no_bwd(&y.contiguous()?, &ReluMask)
}

/// Sums `[groups * rows, out]` (any leading shape) over the rows of each group: `[groups, out]`.
pub fn row_sum(t: &Tensor, groups: usize) -> Result<Tensor> {
    t.contiguous()?.apply_op1_no_bwd(&RowSum { groups })
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

    #[test]
    fn relu_mask_and_row_sum_by_hand() {
        let dev = Device::Cpu;
        let grad = Tensor::new(&[[1.0f32, 2.0], [3.0, 4.0], [5.0, 6.0], [7.0, 8.0]], &dev).unwrap();
        let y = Tensor::new(&[[0.5f32, 0.0], [0.0, 1.0], [2.0, 2.0], [0.0, 0.0]], &dev).unwrap();
        let masked = relu_mask(&grad, &y).unwrap();
        assert_eq!(
            masked.to_vec2::<f32>().unwrap(),
            vec![vec![1.0, 0.0], vec![0.0, 4.0], vec![5.0, 6.0], vec![0.0, 0.0]]
        );
        assert_eq!(row_sum(&grad, 1).unwrap().to_vec2::<f32>().unwrap(), vec![vec![16.0, 20.0]]);
        assert_eq!(row_sum(&grad, 2).unwrap().to_vec2::<f32>().unwrap(), vec![vec![4.0, 6.0], vec![12.0, 14.0]]);
        assert!(row_sum(&grad, 3).is_err());
    }
}
