//! K Q-networks of one shape evaluated together: each layer's weights are stacked into one
//! `[k, out, in]` tensor, so the twin critics of TD3 and SAC cost one dense-layer op per layer
//! instead of two, forward and backward.
//!
//! With `critic_layer_norm` every hidden layer's pre-activation is layer-normalised (Ba et al.,
//! "Layer Normalization", arXiv:1607.06450) before its ReLU, with a learned gain and shift per
//! member, as the critics of RLPD (Ball et al., ICML 2023, `ikostrikov/rlpd`,
//! `rlpd/networks/mlp.py`) and of Nauman et al. ("Overestimation, Overfitting, and Plasticity in
//! Actor-Critic", ICML 2024) do. Normalised critics run one dense node per layer with a fused
//! normalisation-and-ReLU node ([`crate::numeric::layer_norm`]) between them.
use candle_core::{DType, Device, Result, Tensor, Var};
use rand_chacha::ChaCha8Rng;

use crate::agents::common::nets::{copy_var, polyak_vars, DenseStack, Mlp, Output};
use crate::agents::common::objectives::critic_mse;
use crate::agents::config::WeightInit;
use crate::numeric::dense::dense;
use crate::numeric::inplace::Activation;
use crate::numeric::layer_norm::layer_norm_relu;
use crate::numeric::optim::Param;
use crate::numeric::stack::relu_stack;

/// Added to each row's variance: PyTorch's `nn.LayerNorm` default.
const LAYER_NORM_EPS: f64 = 1e-5;

pub(crate) struct Critics {
    /// weight `[k, out, in]`, bias `[k, 1, out]` per layer
    body: DenseStack,
    /// gain and shift `[k, 1, out]` per hidden layer, when the critics are layer-normalised
    norms: Option<Vec<(Var, Var)>>,
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
        Ok(Critics { body: DenseStack::new(params), norms: None })
    }

    /// [`Critics::with_layer_norm`] when `layer_norm` (an agent's `critic_layer_norm`), else `self`.
    pub fn layer_normalised_if(self, layer_norm: bool) -> Result<Critics> {
        if layer_norm {
            self.with_layer_norm()
        } else {
            Ok(self)
        }
    }

    /// The same critics with layer normalisation after each hidden layer, gains 1 and shifts 0
    /// (no draws from the RNG, so the weights are those of [`Critics::new`]).
    pub fn with_layer_norm(self) -> Result<Critics> {
        let layers = self.body.layers();
        let norms = layers[..layers.len() - 1]
            .iter()
            .map(|(_, b)| {
                let shape = b.as_tensor().dims().to_vec();
                Ok((
                    Var::ones(shape.as_slice(), DType::F32, &Device::Cpu)?,
                    Var::zeros(shape.as_slice(), DType::F32, &Device::Cpu)?,
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Critics { norms: Some(norms), ..self })
    }

    /// An independent copy with equal weights (for target networks).
    pub(crate) fn deep_copy(&self) -> Result<Critics> {
        let norms = match &self.norms {
            None => None,
            Some(norms) => {
                Some(norms.iter().map(|(g, s)| Ok((copy_var(g)?, copy_var(s)?))).collect::<Result<Vec<_>>>()?)
            }
        };
        Ok(Critics { body: self.body.deep_copy()?, norms })
    }

    /// Q values `[k, n, 1]` of every member for inputs `x` `[n, in]`.
    pub fn forward(&self, x: &Tensor) -> Result<Tensor> {
        match self.norms {
            None => self.body.forward(x),
            Some(_) => self.normalised(x, None, false),
        }
    }

    /// Member 0 alone (`[n, 1]`) with the weights held constant: gradients reach `x` only.
    /// TD3's and DDPG's actor loss.
    pub(crate) fn first_frozen(&self, x: &Tensor) -> Result<Tensor> {
        if self.norms.is_some() {
            return self.normalised(x, Some(0), true)?.squeeze(0);
        }
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
        match self.norms {
            None => self.body.forward_frozen(x),
            Some(_) => self.normalised(x, None, true),
        }
    }

    /// The layer-normalised critics, every member or one (`[1, n, 1]`), their parameters held
    /// constant when `frozen`.
    fn normalised(&self, x: &Tensor, member: Option<usize>, frozen: bool) -> Result<Tensor> {
        let norms = self.norms.as_deref().unwrap_or(&[]);
        let pick = |v: &Var| -> Result<Tensor> {
            let t = match member {
                Some(i) => v.as_tensor().narrow(0, i, 1)?,
                None => v.as_tensor().clone(),
            };
            Ok(if frozen { t.detach() } else { t })
        };
        let layers = self.body.layers();
        let mut h = x.clone();
        for (i, (w, b)) in layers.iter().enumerate() {
            h = dense(&h, &pick(w)?, &pick(b)?, Activation::Identity)?;
            if let Some((gain, shift)) = norms.get(i) {
                h = layer_norm_relu(&h, &pick(gain)?, &pick(shift)?, LAYER_NORM_EPS)?;
            }
        }
        Ok(h)
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
        let mut out = self.body.vars();
        out.extend(self.norm_vars());
        out
    }

    fn norm_vars(&self) -> Vec<Var> {
        self.norms.iter().flatten().flat_map(|(g, s)| [g.clone(), s.clone()]).collect()
    }

    /// The parameters for an optimiser (see [`DenseStack::params`]); the normalisation's gains
    /// and shifts, whose gradients candle's store holds, after the dense layers.
    pub(crate) fn params(&self) -> Vec<Param> {
        let mut out = self.body.params();
        out.extend(self.norm_vars().into_iter().map(Param::from));
        out
    }

    /// Parameters named `<prefix>.<layer>.weight` (`[k, out, in]`) / `.bias` (`[k, 1, out]`),
    /// and with layer normalisation `<prefix>.norm<layer>.gain` / `.shift` (`[k, 1, out]`).
    pub(crate) fn named_vars(&self, prefix: &str) -> Vec<(String, Var)> {
        let mut out = self.body.named_vars(prefix);
        for (i, (g, s)) in self.norms.iter().flatten().enumerate() {
            out.push((format!("{prefix}.norm{i}.gain"), g.clone()));
            out.push((format!("{prefix}.norm{i}.shift"), s.clone()));
        }
        out
    }
}

/// target <- tau * online + (1 - tau) * target.
pub(crate) fn polyak_update_critics(online: &Critics, target: &Critics, tau: f64) -> Result<()> {
    online.body.polyak_into(&target.body, tau)?;
    polyak_vars(&online.norm_vars(), &target.norm_vars(), tau)
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

    #[test]
    fn layer_normalised_critics_equal_a_hand_built_network_and_train_every_parameter() {
        use crate::numeric::dense::dense;
        use candle_core::D;
        let sizes = [5, 16, 8, 1];
        let plain = Critics::new(2, &sizes, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(4)).unwrap();
        let critics = Critics::new(2, &sizes, WeightInit::Uniform, &mut ChaCha8Rng::seed_from_u64(4))
            .unwrap()
            .with_layer_norm()
            .unwrap();
        // the same weights as without normalisation: no extra draws
        for ((_, a), (_, b)) in plain.named_vars("c").iter().zip(critics.named_vars("c")) {
            assert_eq!(
                a.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap(),
                b.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap()
            );
        }
        let names: Vec<String> = critics.named_vars("c").into_iter().map(|(n, _)| n).collect();
        assert_eq!(names[6..], ["c.norm0.gain", "c.norm0.shift", "c.norm1.gain", "c.norm1.shift"]);
        // gains and shifts away from 1 and 0, so that they matter below
        for (i, (_, v)) in critics.named_vars("c").iter().enumerate().skip(6) {
            let t = v.as_tensor();
            v.set(&t.affine(1.0, 0.1 * i as f64).unwrap()).unwrap();
        }
        let x = Tensor::new(
            &[[0.1f32, -0.4, 0.3, 2.0, -1.0], [1.0, 0.5, -0.5, 0.0, 0.2], [0.0, 0.0, 1.0, -2.0, 0.7]],
            &Device::Cpu,
        )
        .unwrap();
        let vars = critics.named_vars("c");
        let t = |i: usize| vars[i].1.as_tensor().clone();
        let norm = |h: &Tensor, g: Tensor, s: Tensor| {
            let c = h.broadcast_sub(&h.mean_keepdim(D::Minus1).unwrap()).unwrap();
            let std = (c.sqr().unwrap().mean_keepdim(D::Minus1).unwrap() + LAYER_NORM_EPS).unwrap().sqrt().unwrap();
            c.broadcast_div(&std).unwrap().broadcast_mul(&g).unwrap().broadcast_add(&s).unwrap().relu().unwrap()
        };
        let mut h = dense(&x, &t(0), &t(1), Activation::Identity).unwrap();
        h = norm(&h, t(6), t(7));
        h = dense(&h, &t(2), &t(3), Activation::Identity).unwrap();
        h = norm(&h, t(8), t(9));
        let expected =
            dense(&h, &t(4), &t(5), Activation::Identity).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let q = critics.forward(&x).unwrap();
        assert_eq!(q.dims(), &[2, 3, 1]);
        for (a, b) in q.flatten_all().unwrap().to_vec1::<f32>().unwrap().iter().zip(&expected) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        assert_ne!(
            q.flatten_all().unwrap().to_vec1::<f32>().unwrap(),
            plain.forward(&x).unwrap().flatten_all().unwrap().to_vec1::<f32>().unwrap()
        );
        let first = critics.first_frozen(&x).unwrap().to_vec2::<f32>().unwrap();
        assert_eq!(first, q.get(0).unwrap().to_vec2::<f32>().unwrap());
        assert_eq!(critics.forward_frozen(&x).unwrap().to_vec3::<f32>().unwrap(), q.to_vec3::<f32>().unwrap());

        // the loss reaches every weight, bias, gain and shift through the optimiser's parameters
        let y = Tensor::new(&[[1.0f32], [-0.5], [0.25]], &Device::Cpu).unwrap();
        let before: Vec<Vec<f32>> =
            critics.vars().iter().map(|v| v.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap()).collect();
        let mut adam = crate::numeric::optim::Adam::new(critics.params(), 1e-3);
        adam.step(&critics.mse_sum(&x, &y).unwrap().backward().unwrap()).unwrap();
        for (i, (v, old)) in critics.vars().iter().zip(&before).enumerate() {
            assert_ne!(
                &v.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap(),
                old,
                "parameter {i} did not move"
            );
        }
        // frozen passes leave every parameter without a gradient
        let g = critics.forward_frozen(&x).unwrap().sum_all().unwrap().backward().unwrap();
        assert!(critics.vars().iter().all(|v| g.get(v.as_tensor()).is_none()));
        let g = critics.first_frozen(&x).unwrap().sum_all().unwrap().backward().unwrap();
        assert!(critics.vars().iter().all(|v| g.get(v.as_tensor()).is_none()));

        // targets: an independent copy that Polyak averaging moves, gains and shifts included
        let target = critics.deep_copy().unwrap();
        assert_eq!(
            target.forward(&x).unwrap().to_vec3::<f32>().unwrap(),
            critics.forward(&x).unwrap().to_vec3::<f32>().unwrap()
        );
        adam.step(&critics.mse_sum(&x, &y).unwrap().backward().unwrap()).unwrap();
        assert_ne!(
            target.forward(&x).unwrap().to_vec3::<f32>().unwrap(),
            critics.forward(&x).unwrap().to_vec3::<f32>().unwrap()
        );
        polyak_update_critics(&critics, &target, 1.0).unwrap();
        for (a, b) in critics.vars().iter().zip(target.vars()) {
            assert_eq!(
                a.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap(),
                b.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap()
            );
        }
    }
}
