//! K Q-networks of one shape evaluated together: each layer's weights are stacked into one
//! `[k, out, in]` tensor, so the twin critics of TD3 and SAC cost one dense-layer op per layer
//! instead of two, forward and backward.
use candle_core::{Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;

use crate::agents::common::nets::{DenseStack, Mlp, Output};
use crate::agents::common::objectives::critic_mse;
use crate::agents::config::WeightInit;
use crate::numeric::optim::Param;
use crate::numeric::stack::relu_stack;

pub(crate) struct Critics {
    /// weight `[k, out, in]`, bias `[k, 1, out]` per layer
    body: DenseStack,
}

impl Critics {
    /// `k` networks `sizes[0] -> ... -> 1`, initialised exactly as `k` consecutive `Mlp::new`
    /// calls on `rng` would (same draws, same order), so a seed gives the same critics either way.
    pub fn new(k: usize, sizes: &[usize], init: WeightInit, rng: &mut ChaCha8Rng) -> Result<Critics> {
        let members = (0..k).map(|_| Mlp::new(sizes, Output::Linear, init, rng)).collect::<Result<Vec<_>>>()?;
        let layers = sizes.len() - 1;
        let mut params = Vec::with_capacity(layers);
        for l in 0..layers {
            let stack = |pick: fn(&Mlp, usize) -> Tensor| {
                Tensor::stack(&members.iter().map(|m| pick(m, l)).collect::<Vec<_>>(), 0)
            };
            let w = stack(|m, l| m.layer(l).0.as_tensor().clone())?;
            let b = stack(|m, l| m.layer(l).1.as_tensor().clone())?.unsqueeze(1)?;
            params.push((Var::from_tensor(&w)?, Var::from_tensor(&b)?));
        }
        Ok(Critics { body: DenseStack::new(params) })
    }

    /// An independent copy with equal weights (for target networks).
    pub(crate) fn deep_copy(&self) -> Result<Critics> {
        Ok(Critics { body: self.body.deep_copy()? })
    }

    /// Q values `[k, n, 1]` of every member for inputs `x` `[n, in]`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        self.body.forward(x)
    }

    /// Member 0 alone (`[n, 1]`) with the weights held constant: gradients reach `x` only.
    /// TD3's and DDPG's actor loss.
    pub(crate) fn first_frozen(&self, x: &Tensor) -> Result<Tensor> {
        let first = self
            .body
            .layers()
            .iter()
            .map(|(w, b)| Ok((w.as_tensor().narrow(0, 0, 1)?, b.as_tensor().narrow(0, 0, 1)?)));
        relu_stack(x, &first.collect::<Result<Vec<_>>>()?, None)?.squeeze(0)
    }

    /// Q values `[k, n, 1]` with the weights held constant: gradients reach `x` only. SAC's
    /// actor loss.
    pub(crate) fn forward_frozen(&self, x: &Tensor) -> Result<Tensor> {
        self.body.forward_frozen(x)
    }

    /// min over members (`[n, 1]`) with the weights held constant.
    #[cfg(test)]
    pub(crate) fn min_frozen(&self, x: &Tensor) -> Result<Tensor> {
        self.forward_frozen(x)?.min(0)
    }

    /// min over members, `[n, 1]`.
    pub fn min(&self, x: &Tensor) -> Result<Tensor> {
        self.forward(x)?.min(0)
    }

    /// sum over members of the mean squared error against `y` `[n, 1]`.
    pub(crate) fn mse_sum(&self, x: &Tensor, y: &Tensor) -> Result<Tensor> {
        critic_mse(&self.forward(x)?, y)
    }

    #[cfg(test)]
    pub fn vars(&self) -> Vec<Var> {
        self.body.vars()
    }

    /// The parameters for an optimiser (see [`DenseStack::params`]).
    pub(crate) fn params(&self) -> Vec<Param> {
        self.body.params()
    }

    /// Parameters named `<prefix>.<layer>.weight` (`[k, out, in]`) / `.bias` (`[k, 1, out]`).
    pub(crate) fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        self.body.named_vars(prefix)
    }
}

/// target <- tau * online + (1 - tau) * target.
pub(crate) fn polyak_update_critics(online: &Critics, target: &Critics, tau: f64) -> Result<()> {
    online.body.polyak_into(&target.body, tau)
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::Device;
    use rand::SeedableRng;

    #[test]
    fn the_critic_loss_node_gives_the_bits_of_candles_graph() {
        use crate::numeric::second_core;
        use rand_distr::{Distribution, StandardNormal};
        second_core::with_and_without_helper(|helper| {
            let mut rng = ChaCha8Rng::seed_from_u64(8);
            for (k, n, inputs) in [(2, 1, 3), (2, 7, 5), (3, 256, 23)] {
                let critics = Critics::new(k, &[inputs, 32, 32, 1], WeightInit::Uniform, &mut rng).unwrap();
                let mut normal =
                    |count: usize| -> Vec<f32> { (0..count).map(|_| StandardNormal.sample(&mut rng)).collect() };
                let x = Tensor::from_vec(normal(n * inputs), (n, inputs), &Device::Cpu).unwrap();
                let y = Tensor::from_vec(normal(n), (n, 1), &Device::Cpu).unwrap();
                let run = |fused: bool| {
                    let q = critics.forward(&x).unwrap();
                    let loss = if fused {
                        critics.mse_sum(&x, &y).unwrap()
                    } else {
                        (q.broadcast_sub(&y).unwrap().sqr().unwrap().mean_all().unwrap() * k as f64).unwrap()
                    };
                    let grads = loss.backward().unwrap();
                    let mut out = vec![loss.to_scalar::<f32>().unwrap().to_bits()];
                    assert!(critics.body.vars().iter().all(|v| grads.get(v.as_tensor()).is_none()));
                    for g in critics.body.take_grads() {
                        out.extend(g.expect("a gradient for every weight").iter().map(|v| v.to_bits()));
                    }
                    out
                };
                let graph = run(false);
                let fused = run(true);
                assert_eq!(graph, fused, "k {k}, n {n}, helper {helper}");
            }
        });
    }

    #[test]
    fn stacked_critics_equal_separate_networks_in_value_and_gradient() {
        let sizes = [5, 16, 8, 1];
        let critics = Critics::new(2, &sizes, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(4)).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let separate = [
            Mlp::new(&sizes, Output::Linear, WeightInit::Uniform, &mut rng).unwrap(),
            Mlp::new(&sizes, Output::Linear, WeightInit::Uniform, &mut rng).unwrap(),
        ];
        let x = Tensor::new(
            &[[0.1f32, -0.4, 0.3, 2.0, -1.0], [1.0, 0.5, -0.5, 0.0, 0.2], [0.0, 0.0, 1.0, -2.0, 0.7]],
            &Device::Cpu,
        )
        .unwrap();
        let y = Tensor::new(&[[1.0f32], [-0.5], [0.25]], &Device::Cpu).unwrap();
        let q = critics.forward(&x).unwrap();
        assert_eq!(q.dims(), &[2, 3, 1]);
        for (i, net) in separate.iter().enumerate() {
            let expected = net.forward(&x).unwrap().to_vec2::<f32>().unwrap();
            let got = q.get(i).unwrap().to_vec2::<f32>().unwrap();
            for (a, b) in got.iter().flatten().zip(expected.iter().flatten()) {
                assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            }
        }
        let min = critics.min(&x).unwrap().to_vec2::<f32>().unwrap();
        let frozen_min = critics.min_frozen(&x).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(min, frozen_min);
        let first = critics.first_frozen(&x).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(first, q.get(0).unwrap().to_vec2::<f32>().unwrap());

        // the summed loss gives each member the gradient its own loss gives it
        critics.mse_sum(&x, &y).unwrap().backward().unwrap();
        let w1 = critics.body.waiting_grad(2).unwrap();
        for (i, net) in separate.iter().enumerate() {
            let own = net.forward(&x).unwrap().sub(&y).unwrap().sqr().unwrap().mean_all().unwrap();
            own.backward().unwrap();
            let expected = net.body().waiting_grad(2).unwrap();
            let got = &w1[i * expected.len()..(i + 1) * expected.len()];
            for (a, b) in got.iter().zip(&expected) {
                assert!((a - b).abs() < 1e-5, "{a} vs {b}");
            }
        }
        // frozen evaluation leaves the weights without gradients
        let g = critics.min_frozen(&x).unwrap().sum_all().unwrap().backward().unwrap();
        assert!(critics.vars().iter().all(|v| g.get(v.as_tensor()).is_none()));
        assert!((0..critics.vars().len()).all(|i| i == 2 || critics.body.waiting_grad(i).is_some()));

        let target = Critics::new(2, &sizes, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(9)).unwrap();
        assert_ne!(target.forward(&x).unwrap().to_vec3::<f32>().unwrap(), q.to_vec3::<f32>().unwrap());
        polyak_update_critics(&critics, &target, 1.0).unwrap();
        assert_eq!(
            target.forward(&x).unwrap().to_vec3::<f32>().unwrap(),
            critics.forward(&x).unwrap().to_vec3::<f32>().unwrap()
        );
    }
}
