//! Multi-layer perceptrons on candle-nn, initialised from the run's own seeded RNG.
use candle_core::{DType, Device, Result, Tensor, Var};
use candle_nn::Linear;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::dense::dense;
use super::kernels::{Activation, Polyak};

/// What follows the last layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Output {
    Linear,
    Tanh,
}

/// Layers `sizes[0] -> sizes[1] -> ... -> sizes[n]` with ReLU between them.
pub struct Mlp {
    /// (weight `out x in`, bias `out`) per layer.
    params: Vec<(Var, Var)>,
    layers: Vec<Linear>,
    output: Output,
}

impl Mlp {
    /// PyTorch's default initialisation (U(-1/sqrt(fan_in), 1/sqrt(fan_in)) for weights and
    /// biases), drawn from `rng` so that a seed reproduces the network.
    pub fn new(sizes: &[usize], output: Output, rng: &mut ChaCha8Rng) -> Result<Mlp> {
        let mut params = Vec::new();
        for w in sizes.windows(2) {
            let (fan_in, fan_out) = (w[0], w[1]);
            let bound = 1.0 / (fan_in as f32).sqrt();
            let weight: Vec<f32> = (0..fan_in * fan_out).map(|_| rng.random_range(-bound..bound)).collect();
            let bias: Vec<f32> = (0..fan_out).map(|_| rng.random_range(-bound..bound)).collect();
            let weight = Var::from_tensor(&Tensor::from_vec(weight, (fan_out, fan_in), &Device::Cpu)?)?;
            let bias = Var::from_tensor(&Tensor::from_vec(bias, fan_out, &Device::Cpu)?)?;
            params.push((weight, bias));
        }
        Ok(Self::from_params(params, output))
    }

    fn from_params(params: Vec<(Var, Var)>, output: Output) -> Mlp {
        let layers =
            params.iter().map(|(w, b)| Linear::new(w.as_tensor().clone(), Some(b.as_tensor().clone()))).collect();
        Mlp { params, layers, output }
    }

    /// An independent copy with equal weights (for target networks).
    pub fn deep_copy(&self) -> Result<Mlp> {
        let params = self
            .params
            .iter()
            .map(|(w, b)| Ok((Var::from_tensor(&w.as_tensor().copy()?)?, Var::from_tensor(&b.as_tensor().copy()?)?)))
            .collect::<Result<Vec<_>>>()?;
        Ok(Self::from_params(params, self.output))
    }

    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.run(x, self.layers.iter().cloned())
    }

    /// The same function with the weights treated as constants: gradients flow to `x` only.
    /// The actor's loss goes through the critic this way, so its backward pass skips the
    /// critic's weight gradients (which its optimiser never uses).
    pub fn forward_frozen(&self, x: &Tensor) -> Result<Tensor> {
        let frozen = self.params.iter().map(|(w, b)| Linear::new(w.as_tensor().detach(), Some(b.as_tensor().detach())));
        self.run(x, frozen)
    }

    fn run(&self, x: &Tensor, layers: impl ExactSizeIterator<Item = Linear>) -> Result<Tensor> {
        let n = layers.len();
        let mut h = x.clone();
        for (i, layer) in layers.enumerate() {
            let act = if i + 1 < n { Activation::Relu } else { Activation::Identity };
            h = dense(&h, layer.weight(), layer.bias().expect("layers have biases"), act)?;
        }
        match self.output {
            Output::Linear => Ok(h),
            Output::Tanh => h.tanh(),
        }
    }

    /// (weight `out x in`, bias `out`) of layer `i`.
    pub fn layer(&self, i: usize) -> &(Var, Var) {
        &self.params[i]
    }

    pub fn vars(&self) -> Vec<Var> {
        self.params.iter().flat_map(|(w, b)| [w.clone(), b.clone()]).collect()
    }

    /// Parameters named `<prefix>.<layer>.weight` / `.bias`, for checkpoints.
    pub fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.params
            .iter()
            .enumerate()
            .flat_map(|(i, (w, b))| {
                [(format!("{prefix}.{i}.weight"), w.clone()), (format!("{prefix}.{i}.bias"), b.clone())]
            })
            .collect()
    }

    pub fn input_dim(&self) -> usize {
        self.params[0].0.dims()[1]
    }

    pub fn output_dim(&self) -> usize {
        self.params.last().unwrap().0.dims()[0]
    }
}

/// target <- tau * online + (1 - tau) * target, parameter by parameter.
pub fn polyak_update(online: &Mlp, target: &Mlp, tau: f64) -> Result<()> {
    let kernel = Polyak { tau: tau as f32 };
    for ((o_w, o_b), (t_w, t_b)) in online.params.iter().zip(&target.params) {
        t_w.as_tensor().inplace_op2(o_w.as_tensor(), &kernel)?;
        t_b.as_tensor().inplace_op2(o_b.as_tensor(), &kernel)?;
    }
    Ok(())
}

/// A row-major batch as a tensor.
pub fn batch_tensor(data: &[f32], rows: usize, cols: usize) -> Result<Tensor> {
    Tensor::from_slice(data, (rows, cols), &Device::Cpu)
}

pub fn scalar_var(value: f32) -> Result<Var> {
    Var::from_tensor(&Tensor::new(&[value], &Device::Cpu)?.to_dtype(DType::F32)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn same_seed_same_weights_and_polyak() {
        let a = Mlp::new(&[3, 8, 2], Output::Tanh, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let b = Mlp::new(&[3, 8, 2], Output::Tanh, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
        let c = Mlp::new(&[3, 8, 2], Output::Tanh, &mut ChaCha8Rng::seed_from_u64(2)).unwrap();
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
    fn frozen_forward_gives_the_same_values_and_input_gradient_but_no_weight_gradients() {
        let net = Mlp::new(&[3, 8, 1], Output::Linear, &mut ChaCha8Rng::seed_from_u64(3)).unwrap();
        let x =
            Var::from_tensor(&Tensor::new(&[[0.5f32, -1.0, 2.0], [0.1, 0.2, -0.3]], &Device::Cpu).unwrap()).unwrap();
        let live = net.forward(x.as_tensor()).unwrap().sum_all().unwrap();
        let frozen = net.forward_frozen(x.as_tensor()).unwrap().sum_all().unwrap();
        assert_eq!(live.to_scalar::<f32>().unwrap(), frozen.to_scalar::<f32>().unwrap());
        let (g_live, g_frozen) = (live.backward().unwrap(), frozen.backward().unwrap());
        let dx = |g: &candle_core::backprop::GradStore| g.get(x.as_tensor()).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(dx(&g_live), dx(&g_frozen));
        for w in net.vars() {
            assert!(g_live.get(w.as_tensor()).is_some());
            assert!(g_frozen.get(w.as_tensor()).is_none());
        }
    }
}
