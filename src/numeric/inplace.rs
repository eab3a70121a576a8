//! CPU kernels for the per-update hot path: in place, an Adam step and a Polyak average (one pass
//! over the parameter, no temporary tensors).
//! candle's tensor expressions allocate a new tensor per operation, and `Var::set` copies once
//! more; the throughput bench measured those as the biggest cost outside the matmuls
//! (benches/results/2026-11-22-amd-epyc-training/NOTES.md, "Training throughput"). Each kernel is tested against the tensor expression it
//! replaces.
use std::cell::RefCell;

use candle_core::{bail, CpuStorage, InplaceOp1, InplaceOp2, Layout, Result, Storage};

use super::kernel_path;
use super::second_core;
use super::wide::wide;

/// Parameters with at least this many values are updated in two halves, the second on the
/// helper thread when there is one (element by element, so the same bits either way).
const SPLIT_LEN: usize = 1 << 14;

fn contiguous_mut<'a>(storage: &'a mut CpuStorage, layout: &Layout, what: &str) -> Result<&'a mut [f32]> {
    let Some((start, end)) = layout.contiguous_offsets() else { bail!("{what}: destination tensor is not contiguous") };
    match storage {
        CpuStorage::F32(data) => Ok(&mut data[start..end]),
        _ => bail!("{what}: only f32 tensors are supported"),
    }
}

pub(crate) fn contiguous<'a>(storage: &'a CpuStorage, layout: &Layout, what: &str) -> Result<&'a [f32]> {
    let Some((start, end)) = layout.contiguous_offsets() else { bail!("{what}: source tensor is not contiguous") };
    match storage {
        CpuStorage::F32(data) => Ok(&data[start..end]),
        _ => bail!("{what}: only f32 tensors are supported"),
    }
}

/// A tensor's storage as contiguous f32 values on the CPU (what the backward passes read).
pub(super) fn cpu_contiguous<'a>(storage: &'a Storage, layout: &Layout, what: &str) -> Result<&'a [f32]> {
    match storage {
        Storage::Cpu(s) => contiguous(s, layout, what),
        _ => bail!("{what}: only CPU tensors are supported"),
    }
}

/// One Adam step on one parameter, PyTorch's formula in f32:
/// m <- b1 m + (1-b1) g; v <- b2 v + (1-b2) g^2; theta <- theta - (lr/bc1) m / (sqrt(v)/sqrt(bc2) + eps)
/// with bc_i = 1 - b_i^t.
pub(crate) struct AdamStep<'a> {
    pub(crate) lr: f32,
    pub(crate) beta1: f32,
    pub(crate) beta2: f32,
    pub eps: f32,
    /// 1 - beta1^t and 1 - beta2^t for the current step t.
    pub(crate) bias_correction1: f32,
    pub(crate) bias_correction2: f32,
    pub m: RefCell<&'a mut [f32]>,
    pub v: RefCell<&'a mut [f32]>,
}

impl AdamStep<'_> {
    fn apply(&self, theta: &mut [f32], grad: &[f32]) -> Result<()> {
        let (mut m, mut v) = (self.m.borrow_mut(), self.v.borrow_mut());
        if theta.len() != grad.len() || m.len() != grad.len() || v.len() != grad.len() {
            bail!("adam: parameter, gradient and moments differ in length");
        }
        let (b1, b2, eps) = (self.beta1, self.beta2, self.eps);
        let step_size = self.lr / self.bias_correction1;
        let inv_sqrt_bc2 = 1.0 / self.bias_correction2.sqrt();
        let path = kernel_path::active();
        let step = |theta: &mut [f32], grad: &[f32], m: &mut [f32], v: &mut [f32]| {
            // `move`: the constants are copied in, so that the compiler can keep them in
            // registers and vectorise (by reference they are reloaded after every store)
            wide(path, move || {
                for (((t, g), m), v) in theta.iter_mut().zip(grad).zip(m.iter_mut()).zip(v.iter_mut()) {
                    *m = b1 * *m + (1.0 - b1) * g;
                    *v = b2 * *v + (1.0 - b2) * g * g;
                    *t -= step_size * *m / (v.sqrt() * inv_sqrt_bc2 + eps);
                }
            })
        };
        if theta.len() < SPLIT_LEN {
            step(theta, grad, &mut m, &mut v);
        } else {
            let half = theta.len() / 2;
            let (t0, t1) = theta.split_at_mut(half);
            let (g0, g1) = grad.split_at(half);
            let (m0, m1) = m.split_at_mut(half);
            let (v0, v1) = v.split_at_mut(half);
            second_core::join(|| step(t0, g0, m0, v0), || step(t1, g1, m1, v1));
        }
        Ok(())
    }
}

impl InplaceOp2 for AdamStep<'_> {
    fn name(&self) -> &'static str {
        "adam-step"
    }

    fn cpu_fwd(&self, s1: &mut CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<()> {
        self.apply(contiguous_mut(s1, l1, "adam")?, contiguous(s2, l2, "adam")?)
    }
}

/// An Adam step whose gradient is a slice rather than a tensor (one a fused node left in a
/// [`super::stack::GradSlot`]).
pub(crate) struct AdamStepFrom<'a, 'b> {
    pub(crate) step: &'a AdamStep<'b>,
    pub(crate) grad: &'a [f32],
}

impl InplaceOp1 for AdamStepFrom<'_, '_> {
    fn name(&self) -> &'static str {
        "adam-step"
    }

    fn cpu_fwd(&self, s1: &mut CpuStorage, l1: &Layout) -> Result<()> {
        self.step.apply(contiguous_mut(s1, l1, "adam")?, self.grad)
    }
}

/// target <- tau * online + (1 - tau) * target.
pub(crate) struct Polyak {
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
        let (tau, keep) = (self.tau, 1.0 - self.tau);
        let path = kernel_path::active();
        let average = |target: &mut [f32], online: &[f32]| {
            wide(path, move || {
                for (t, o) in target.iter_mut().zip(online) {
                    *t = tau * o + keep * *t;
                }
            })
        };
        if target.len() < SPLIT_LEN {
            average(target, online);
        } else {
            let half = target.len() / 2;
            let (t0, t1) = target.split_at_mut(half);
            let (o0, o1) = online.split_at(half);
            second_core::join(|| average(t0, o0), || average(t1, o1));
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

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Tensor};

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

    /// Parameters large enough to be updated in two halves give the bits of one pass over the
    /// formula, with the helper thread and without.
    #[test]
    fn split_updates_give_the_bits_of_one_pass() {
        let n = SPLIT_LEN * 2 + 7;
        let wave = move |seed: f32| (0..n).map(|i| ((i as f32) * 0.013 + seed).sin()).collect::<Vec<f32>>();
        second_core::with_and_without_helper(|_| {
            let (theta0, grad, m0, v0) =
                (wave(0.1), wave(0.7), wave(1.3), wave(2.1).iter().map(|x| x * x).collect::<Vec<_>>());
            let (lr, b1, b2, eps, bc1, bc2) = (1e-3f32, 0.9f32, 0.999f32, 1e-8f32, 0.19f32, 0.0297f32);
            let (mut m, mut v) = (m0.clone(), v0.clone());
            let theta = Tensor::new(theta0.as_slice(), &Device::Cpu).unwrap();
            let g = Tensor::new(grad.as_slice(), &Device::Cpu).unwrap();
            theta
                .inplace_op2(
                    &g,
                    &AdamStep {
                        lr,
                        beta1: b1,
                        beta2: b2,
                        eps,
                        bias_correction1: bc1,
                        bias_correction2: bc2,
                        m: RefCell::new(&mut m),
                        v: RefCell::new(&mut v),
                    },
                )
                .unwrap();
            let (step_size, inv) = (lr / bc1, 1.0 / bc2.sqrt());
            for i in 0..n {
                let m_i = b1 * m0[i] + (1.0 - b1) * grad[i];
                let v_i = b2 * v0[i] + (1.0 - b2) * grad[i] * grad[i];
                let t_i = theta0[i] - step_size * m_i / (v_i.sqrt() * inv + eps);
                assert_eq!((m[i].to_bits(), v[i].to_bits()), (m_i.to_bits(), v_i.to_bits()), "moment {i}");
                assert_eq!(theta.get(i).unwrap().to_scalar::<f32>().unwrap().to_bits(), t_i.to_bits(), "theta {i}");
            }
            let target = Tensor::new(theta0.as_slice(), &Device::Cpu).unwrap();
            target.inplace_op2(&g, &Polyak { tau: 0.005 }).unwrap();
            let averaged = target.to_vec1::<f32>().unwrap();
            for i in 0..n {
                assert_eq!(averaged[i].to_bits(), (0.005 * grad[i] + (1.0 - 0.005) * theta0[i]).to_bits(), "{i}");
            }
        });
    }
}
