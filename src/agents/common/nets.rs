//! Multi-layer perceptrons on candle-nn, initialised from the run's own seeded RNG.
use std::sync::Arc;

use candle_core::{DType, Device, Result, Tensor, Var};
use nalgebra::DMatrix;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::agents::config::WeightInit;
use crate::numeric::inplace::Polyak;
use crate::numeric::optim::Param;
use crate::numeric::stack::{relu_stack, GradSlot};

/// What follows the last layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Output {
    Linear,
    Tanh,
}

/// Dense layers given as (weight, bias) variables, ReLU between them and nothing after the last:
/// the body shared by `Mlp` (weights `out x in`) and `Critics` (k networks stacked, `[k, out, in]`).
/// `forward` runs them as one fused node ([`crate::numeric::stack`]) that leaves the weight
/// gradients in `grads`, where the optimiser built from [`DenseStack::params`] takes them.
pub(crate) struct DenseStack {
    layers: Vec<(Var, Var)>,
    /// one slot per weight and bias, in the order of `vars`
    grads: Arc<[GradSlot]>,
}

impl DenseStack {
    pub fn new(layers: Vec<(Var, Var)>) -> DenseStack {
        let grads = (0..2 * layers.len()).map(|_| GradSlot::default()).collect();
        DenseStack { layers, grads }
    }

    /// An independent copy with equal weights (for target networks).
    pub(crate) fn deep_copy(&self) -> Result<DenseStack> {
        Ok(DenseStack::new(self.layers.iter().map(|(w, b)| Ok((copy_var(w)?, copy_var(b)?))).collect::<Result<_>>()?))
    }

    fn tensors(&self) -> Vec<(Tensor, Tensor)> {
        self.layers.iter().map(|(w, b)| (w.as_tensor().clone(), b.as_tensor().clone())).collect()
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        relu_stack(x, &self.tensors(), Some(&self.grads))
    }

    /// The same function with the weights treated as constants: gradients flow to `x` only.
    /// The actors' losses go through the critics this way, so their backward pass skips the
    /// critics' weight gradients (which the actor's optimiser never uses).
    pub(crate) fn forward_frozen(&self, x: &Tensor) -> Result<Tensor> {
        relu_stack(x, &self.tensors(), None)
    }

    /// The parameters for an optimiser, each with the slot `forward` leaves its gradient in.
    pub(crate) fn params(&self) -> Vec<Param> {
        self.vars().into_iter().enumerate().map(|(i, v)| Param::with_slot(v, self.grads.clone(), i)).collect()
    }

    /// The gradient waiting in the slot of the `i`-th of `vars`, if any.
    #[cfg(test)]
    pub(crate) fn waiting_grad(&self, i: usize) -> Option<Vec<f32>> {
        self.grads[i].peek()
    }

    /// Every waiting gradient, in the order of `vars`, each taken from its slot.
    #[cfg(test)]
    pub(crate) fn take_grads(&self) -> Vec<Option<Vec<f32>>> {
        self.grads
            .iter()
            .map(|slot| {
                let mut taken = None;
                slot.take(|g| {
                    taken = Some(g.to_vec());
                    Ok(())
                })
                .unwrap();
                taken
            })
            .collect()
    }

    /// (weight, bias) per layer.
    pub fn layers(&self) -> &[(Var, Var)] {
        &self.layers
    }

    pub fn vars(&self) -> Vec<Var> {
        self.layers.iter().flat_map(|(w, b)| [w.clone(), b.clone()]).collect()
    }

    /// Parameters named `<prefix>.<layer>.weight` / `.bias`, for checkpoints.
    pub(crate) fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.layers
            .iter()
            .enumerate()
            .flat_map(|(i, (w, b))| {
                [(format!("{prefix}.{i}.weight"), w.clone()), (format!("{prefix}.{i}.bias"), b.clone())]
            })
            .collect()
    }

    /// target <- tau * self + (1 - tau) * target, parameter by parameter, in place.
    pub(crate) fn polyak_into(&self, target: &DenseStack, tau: f64) -> Result<()> {
        polyak_vars(&self.vars(), &target.vars(), tau)
    }
}

/// An independent variable with `v`'s values.
pub(crate) fn copy_var(v: &Var) -> Result<Var> {
    Var::from_tensor(&v.as_tensor().copy()?)
}

/// target <- tau * online + (1 - tau) * target, variable by variable, in place.
pub(crate) fn polyak_vars(online: &[Var], target: &[Var], tau: f64) -> Result<()> {
    let kernel = Polyak { tau: tau as f32 };
    for (o, t) in online.iter().zip(target) {
        t.as_tensor().inplace_op2(o.as_tensor(), &kernel)?;
    }
    Ok(())
}

/// Layers `sizes[0] -> sizes[1] -> ... -> sizes[n]` with ReLU between them.
pub(crate) struct Mlp {
    /// weight `out x in`, bias `out` per layer
    body: DenseStack,
    output: Output,
}

/// PyTorch's `nn.Linear` default: weights, then biases, from U(-1/sqrt(fan_in), 1/sqrt(fan_in)),
/// drawn from `rng` in that order (row-major `fan_out x fan_in` weights).
pub(crate) fn torch_default_layer(fan_in: usize, fan_out: usize, rng: &mut ChaCha8Rng) -> (Vec<f32>, Vec<f32>) {
    let bound = 1.0 / (fan_in as f32).sqrt();
    let weight = (0..fan_in * fan_out).map(|_| rng.random_range(-bound..bound)).collect();
    let bias = (0..fan_out).map(|_| rng.random_range(-bound..bound)).collect();
    (weight, bias)
}

impl Mlp {
    /// Weights and biases drawn by `init` from `rng`, layer by layer, so that a seed reproduces
    /// the network.
    pub fn new(sizes: &[usize], output: Output, init: WeightInit, rng: &mut ChaCha8Rng) -> Result<Mlp> {
        let mut params = Vec::new();
        for w in sizes.windows(2) {
            let (fan_in, fan_out) = (w[0], w[1]);
            let (weight, bias) = match init {
                WeightInit::Uniform => torch_default_layer(fan_in, fan_out, rng),
                WeightInit::Orthogonal => {
                    (orthogonal(fan_out, fan_in, std::f64::consts::SQRT_2, rng), vec![0.0; fan_out])
                }
            };
            let weight = Var::from_tensor(&Tensor::from_vec(weight, (fan_out, fan_in), &Device::Cpu)?)?;
            let bias = Var::from_tensor(&Tensor::from_vec(bias, fan_out, &Device::Cpu)?)?;
            params.push((weight, bias));
        }
        Ok(Mlp { body: DenseStack::new(params), output })
    }

    /// Multiplies rows `rows` of the last layer's weights by `factor` (SAC gives its log-std
    /// rows a smaller orthogonal gain than its mean rows).
    pub(crate) fn scale_output_rows(&self, rows: std::ops::Range<usize>, factor: f64) -> Result<()> {
        let (weight, _) = self.body.layers().last().expect("at least one layer");
        let w = weight.as_tensor();
        let scaled = w.narrow(0, rows.start, rows.len())?.affine(factor, 0.0)?;
        weight.set(&w.slice_assign(&[rows, 0..w.dims()[1]], &scaled)?)
    }

    /// An independent copy with equal weights (for target networks).
    pub(crate) fn deep_copy(&self) -> Result<Mlp> {
        Ok(Mlp { body: self.body.deep_copy()?, output: self.output })
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        let h = self.body.forward(x)?;
        match self.output {
            Output::Linear => Ok(h),
            Output::Tanh => h.tanh(),
        }
    }

    #[cfg(test)]
    pub(crate) fn body(&self) -> &DenseStack {
        &self.body
    }

    /// (weight `out x in`, bias `out`) of layer `i`.
    pub fn layer(&self, i: usize) -> &(Var, Var) {
        &self.body.layers()[i]
    }

    #[cfg(test)]
    pub fn vars(&self) -> Vec<Var> {
        self.body.vars()
    }

    /// The parameters for an optimiser (see [`DenseStack::params`]).
    pub(crate) fn params(&self) -> Vec<Param> {
        self.body.params()
    }

    /// Parameters named `<prefix>.<layer>.weight` / `.bias`, for checkpoints.
    pub(crate) fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.body.named_vars(prefix)
    }
}

/// A `rows x cols` matrix (row-major) whose rows (if rows <= cols) or columns are orthonormal,
/// times `gain`, uniformly distributed over such matrices: the QR factors of a Gaussian matrix
/// with R's diagonal made positive (Saxe et al. 2014; the construction of flax's and PyTorch's
/// `orthogonal` initialisers).
pub(crate) fn orthogonal(rows: usize, cols: usize, gain: f64, rng: &mut ChaCha8Rng) -> Vec<f32> {
    let (tall, narrow) = (rows.max(cols), rows.min(cols));
    let a = DMatrix::<f64>::from_fn(tall, narrow, |_, _| StandardNormal.sample(rng));
    let qr = a.qr();
    let mut q = qr.q();
    for (j, d) in qr.r().diagonal().iter().enumerate() {
        if *d < 0.0 {
            q.column_mut(j).neg_mut();
        }
    }
    let w = if rows >= cols { q } else { q.transpose() };
    (0..rows).flat_map(|i| (0..cols).map(move |j| (i, j))).map(|(i, j)| (gain * w[(i, j)]) as f32).collect()
}

/// target <- tau * online + (1 - tau) * target, parameter by parameter.
pub(crate) fn polyak_update(online: &Mlp, target: &Mlp, tau: f64) -> Result<()> {
    online.body.polyak_into(&target.body, tau)
}

/// A row-major batch as a tensor.
pub(crate) fn batch_tensor(data: &[f32], rows: usize, cols: usize) -> Result<Tensor> {
    Tensor::from_slice(data, (rows, cols), &Device::Cpu)
}

pub(crate) fn scalar_var(value: f32) -> Result<Var> {
    Var::from_tensor(&Tensor::new(&[value], &Device::Cpu)?.to_dtype(DType::F32)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn same_seed_same_weights_and_polyak() {
        let a = Mlp::new(&[3, 8, 2], Output::Tanh, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let b = Mlp::new(&[3, 8, 2], Output::Tanh, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let c = Mlp::new(&[3, 8, 2], Output::Tanh, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(2)).unwrap();
        let flat = |m: &Mlp| {
            m.vars().iter().flat_map(|v| v.flatten_all().unwrap().to_vec1::<f32>().unwrap()).collect::<Vec<_>>()
        };
        assert_eq!(flat(&a), flat(&b));
        assert_ne!(flat(&a), flat(&c));
        let bound = 1.0 / 3f32.sqrt();
        assert!(a.vars()[0].flatten_all().unwrap().to_vec1::<f32>().unwrap().iter().all(|w| w.abs() <= bound));

        let target = c.deep_copy().unwrap();
        let (before_t, online) = (flat(&target), flat(&a));
        polyak_update(&a, &target, 0.1).unwrap();
        for ((t, b), o) in flat(&target).iter().zip(&before_t).zip(&online) {
            assert!((t - (0.1 * o + 0.9 * b)).abs() < 1e-6);
        }
        // deep_copy is independent of its source
        assert_eq!(flat(&c), before_t);
        let x = Tensor::new(&[[0.5f32, -1.0, 2.0]], &Device::Cpu).unwrap();
        let y = a.forward(&x).unwrap().to_vec2::<f32>().unwrap();
        assert!(y[0].iter().all(|v| v.abs() < 1.0));
    }

    #[test]
    fn orthogonal_weights_have_orthonormal_rows_or_columns_times_the_gain() {
        for (rows, cols) in [(8, 3), (3, 8), (5, 5)] {
            let w = orthogonal(rows, cols, 2.0, &mut ChaCha8Rng::seed_from_u64(5));
            let m = DMatrix::from_row_slice(rows, cols, &w.iter().map(|&x| x as f64).collect::<Vec<_>>());
            let gram = if rows <= cols { &m * m.transpose() } else { m.transpose() * &m };
            let expected = DMatrix::<f64>::identity(gram.nrows(), gram.nrows()) * 4.0;
            assert!((gram - expected).abs().max() < 1e-5, "{rows}x{cols}");
            assert_eq!(w, orthogonal(rows, cols, 2.0, &mut ChaCha8Rng::seed_from_u64(5)));
        }
        let net =
            Mlp::new(&[3, 8, 2], Output::Linear, WeightInit::Orthogonal, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let bias = net.layer(0).1.to_vec1::<f32>().unwrap();
        assert!(bias.iter().all(|&b| b == 0.0));
        let w = net.layer(1).0.to_vec2::<f32>().unwrap();
        let row_norm = |r: &[f32]| r.iter().map(|x| x * x).sum::<f32>().sqrt();
        assert!((row_norm(&w[0]) - 2f32.sqrt()).abs() < 1e-5);
        net.scale_output_rows(1..2, 0.5).unwrap();
        let scaled = net.layer(1).0.to_vec2::<f32>().unwrap();
        assert_eq!(scaled[0], w[0]);
        assert!(scaled[1].iter().zip(&w[1]).all(|(s, o)| (s - 0.5 * o).abs() < 1e-7));
    }

    #[test]
    fn frozen_forward_gives_the_same_values_and_input_gradient_but_no_weight_gradients() {
        let net = Mlp::new(&[3, 8, 1], Output::Linear, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let x =
            Var::from_tensor(&Tensor::new(&[[0.5f32, -1.0, 2.0], [0.1, 0.2, -0.3]], &Device::Cpu).unwrap()).unwrap();
        let live = net.body.forward(x.as_tensor()).unwrap().sum_all().unwrap();
        let frozen = net.body.forward_frozen(x.as_tensor()).unwrap().sum_all().unwrap();
        assert_eq!(live.to_scalar::<f32>().unwrap(), frozen.to_scalar::<f32>().unwrap());
        let g_frozen = frozen.backward().unwrap();
        let count = net.vars().len();
        assert!((0..count).all(|i| net.body.waiting_grad(i).is_none()), "a frozen pass wrote a weight gradient");
        let g_live = live.backward().unwrap();
        let dx = |g: &candle_core::backprop::GradStore| g.get(x.as_tensor()).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(dx(&g_live), dx(&g_frozen));
        // the live pass leaves every weight's gradient in its slot, neither in candle's store
        for (i, w) in net.vars().iter().enumerate() {
            assert!(net.body.waiting_grad(i).is_some());
            assert!(g_live.get(w.as_tensor()).is_none() && g_frozen.get(w.as_tensor()).is_none());
        }
    }
}
