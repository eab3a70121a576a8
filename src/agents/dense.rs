//! A dense layer `act(x W^T + b)` as one autograd node, for one network or k stacked ones.
//!
//! Built from candle's ops the same layer is three graph nodes (transpose, matmul, bias add) plus
//! one for the ReLU, and candle's backward pass allocates a zero gradient and adds into it for
//! every input of every node, including a strided add for the transposed weight. perf showed that
//! bookkeeping at about a fifth of a TD3 update once the matmuls were fast; as one node the
//! forward pass is a single gemm call that accumulates onto the bias, and the backward pass is
//! two matmuls, a mask and a row sum.
use candle_core::{bail, CpuStorage, CustomOp3, Layout, Result, Shape, Tensor, D};

use super::kernels::{contiguous, relu_mask, row_sum, Activation};

struct Dense(Activation);

/// Sizes of `x [n, in] | [k, n, in]`, `w [out, in] | [k, out, in]` and `b` (k * out values).
struct Dims {
    k: usize,
    n: usize,
    inp: usize,
    out: usize,
    /// x is one `[n, in]` block used by every member.
    shared_x: bool,
}

fn dims(x: &[usize], w: &[usize], b_len: usize) -> Result<Dims> {
    let (k, out, inp) = match w {
        [out, inp] => (1, *out, *inp),
        [k, out, inp] => (*k, *out, *inp),
        _ => bail!("dense: weight must be [out, in] or [k, out, in], got {w:?}"),
    };
    let (n, shared_x) = match x {
        [n, i] if *i == inp => (*n, true),
        [kx, n, i] if *i == inp && *kx == k => (*n, false),
        _ => bail!("dense: input {x:?} does not match weight {w:?}"),
    };
    if b_len != k * out {
        bail!("dense: bias has {b_len} values, weight {w:?} needs {}", k * out);
    }
    Ok(Dims { k, n, inp, out, shared_x })
}

impl CustomOp3 for Dense {
    fn name(&self) -> &'static str {
        "dense"
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
        let (x, w, b) = (contiguous(s1, l1, "dense")?, contiguous(s2, l2, "dense")?, contiguous(s3, l3, "dense")?);
        let d = dims(l1.dims(), l2.dims(), b.len())?;
        let mut y = vec![0f32; d.k * d.n * d.out];
        for g in 0..d.k {
            let bias = &b[g * d.out..(g + 1) * d.out];
            let dst = &mut y[g * d.n * d.out..(g + 1) * d.n * d.out];
            for row in dst.chunks_exact_mut(d.out) {
                row.copy_from_slice(bias);
            }
            let lhs = if d.shared_x { x } else { &x[g * d.n * d.inp..(g + 1) * d.n * d.inp] };
            let rhs = &w[g * d.out * d.inp..(g + 1) * d.out * d.inp];
            // SAFETY: dst is n x out (row stride out), lhs n x in (row stride in) and rhs = W^T,
            // in x out read from the out x in weight (row stride 1, column stride in); all three
            // slices hold exactly those elements.
            unsafe {
                gemm::gemm(
                    d.n,
                    d.out,
                    d.inp,
                    dst.as_mut_ptr(),
                    1,
                    d.out as isize,
                    true,
                    lhs.as_ptr(),
                    1,
                    d.inp as isize,
                    rhs.as_ptr(),
                    d.inp as isize,
                    1,
                    1.0,
                    1.0,
                    false,
                    false,
                    false,
                    gemm::Parallelism::None,
                );
            }
        }
        if self.0 == Activation::Relu {
            y.iter_mut().for_each(|v| *v = v.max(0.0));
        }
        let shape: Shape = if l2.dims().len() == 2 { (d.n, d.out).into() } else { (d.k, d.n, d.out).into() };
        Ok((CpuStorage::F32(y), shape))
    }

    fn bwd(
        &self,
        x: &Tensor,
        w: &Tensor,
        b: &Tensor,
        y: &Tensor,
        grad: &Tensor,
    ) -> Result<(Option<Tensor>, Option<Tensor>, Option<Tensor>)> {
        let d = dims(x.dims(), w.dims(), b.elem_count())?;
        // inputs from the replay buffer need no gradient; hidden activations and the actor's
        // action do
        let need_grad_x = x.track_op();
        let (x, w, grad) = (x.detach(), w.detach(), grad.detach().contiguous()?);
        let grad_pre = match self.0 {
            Activation::Identity => grad,
            Activation::Relu => relu_mask(&grad, &y.detach())?,
        };
        let g3 = grad_pre.reshape((d.k, d.n, d.out))?;
        let w3 = w.reshape((d.k, d.out, d.inp))?;
        let x3 = if d.shared_x {
            x.reshape((1, d.n, d.inp))?.broadcast_as((d.k, d.n, d.inp))?.contiguous()?
        } else {
            x.clone()
        };
        let grad_w = g3.transpose(D::Minus1, D::Minus2)?.matmul(&x3)?.reshape(w.shape())?;
        let grad_b = row_sum(&grad_pre, d.k)?.reshape(b.shape())?;
        let grad_x = if need_grad_x {
            let per_member = g3.matmul(&w3)?;
            if d.shared_x {
                // summed member by member: candle's sum over a leading axis divides per element
                let mut total = per_member.get(0)?;
                for g in 1..d.k {
                    total = (total + per_member.get(g)?)?;
                }
                Some(total.reshape(x.shape())?)
            } else {
                Some(per_member.reshape(x.shape())?)
            }
        } else {
            None
        };
        Ok((grad_x, Some(grad_w), Some(grad_b)))
    }
}

/// `act(x W^T + b)`: x `[n, in]` with w `[out, in]`, b `[out]` (one network), or w `[k, out, in]`,
/// b `[k, 1, out]` with x `[k, n, in]` or a shared `[n, in]` (k stacked networks, output `[k, n, out]`).
pub fn dense(x: &Tensor, w: &Tensor, b: &Tensor, act: Activation) -> Result<Tensor> {
    x.contiguous()?.apply_op3(&w.contiguous()?, &b.contiguous()?, Dense(act))
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var};

    fn values(n: usize, seed: f32) -> Vec<f32> {
        (0..n).map(|i| (i as f32 * 0.37 + seed).sin()).collect()
    }

    /// Value and gradients of x, W and b equal candle's matmul + broadcast add + ReLU.
    #[test]
    fn dense_matches_candle_ops_for_one_and_stacked_networks() {
        let dev = Device::Cpu;
        let cases: [(&[usize], &[usize], &[usize]); 3] =
            [(&[5, 3], &[4, 3], &[4]), (&[2, 5, 3], &[2, 4, 3], &[2, 1, 4]), (&[5, 3], &[2, 4, 3], &[2, 1, 4])];
        for (xs, ws, bs) in cases {
            for act in [Activation::Identity, Activation::Relu] {
                let var = |shape: &[usize], seed| {
                    Var::from_tensor(&Tensor::from_vec(values(shape.iter().product(), seed), shape, &dev).unwrap())
                        .unwrap()
                };
                let (x, w, b) = (var(xs, 0.1), var(ws, 0.7), var(bs, 1.9));
                let out_shape: Vec<usize> = if ws.len() == 2 { vec![xs[0], ws[0]] } else { vec![ws[0], 5, ws[1]] };
                let probe = Tensor::from_vec(values(out_shape.iter().product(), 2.3), out_shape, &dev).unwrap();
                let reference = {
                    let x_b = if xs.len() < ws.len() {
                        x.as_tensor().unsqueeze(0).unwrap().broadcast_as((ws[0], xs[0], xs[1])).unwrap()
                    } else {
                        x.as_tensor().clone()
                    };
                    let pre = x_b.matmul(&w.as_tensor().transpose(D::Minus1, D::Minus2).unwrap().contiguous().unwrap());
                    let pre = pre.unwrap().broadcast_add(b.as_tensor()).unwrap();
                    if act == Activation::Relu {
                        pre.relu().unwrap()
                    } else {
                        pre
                    }
                };
                let ours = dense(x.as_tensor(), w.as_tensor(), b.as_tensor(), act).unwrap();
                let flat = |t: &Tensor| t.flatten_all().unwrap().to_vec1::<f32>().unwrap();
                assert_eq!(ours.dims(), reference.dims());
                for (a, e) in flat(&ours).iter().zip(flat(&reference)) {
                    assert!((a - e).abs() < 1e-5, "{xs:?} {act:?}: {a} vs {e}");
                }
                let g_ref = (reference * &probe).unwrap().sum_all().unwrap().backward().unwrap();
                let g_ours = (ours * &probe).unwrap().sum_all().unwrap().backward().unwrap();
                for v in [&x, &w, &b] {
                    let (a, e) = (g_ours.get(v.as_tensor()).unwrap(), g_ref.get(v.as_tensor()).unwrap());
                    assert_eq!(a.dims(), v.dims());
                    for (a, e) in flat(a).iter().zip(flat(e)) {
                        assert!((a - e).abs() < 1e-4, "{xs:?} {act:?}: {a} vs {e}");
                    }
                }
            }
        }
        let bad = dense(
            &Tensor::zeros((5, 3), candle_core::DType::F32, &dev).unwrap(),
            &Tensor::zeros((4, 2), candle_core::DType::F32, &dev).unwrap(),
            &Tensor::zeros(4, candle_core::DType::F32, &dev).unwrap(),
            Activation::Relu,
        );
        assert!(bad.is_err());
    }
}
