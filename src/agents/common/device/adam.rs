//! Adam on any candle device, from candle's tensor operations: the same update as the fused
//! [`crate::numeric::optim::Adam`] (m and v per parameter, bias corrections folded into the step
//! size and the root of v), with its moments kept on the device and saved under the same names,
//! so a checkpoint moves between the two.
use std::collections::HashMap;

use candle_core::backprop::GradStore;
use candle_core::{Device, Result, Tensor, Var};

use crate::numeric::optim::Optimizer;

/// Adam over variables on one device.
pub struct DeviceAdam {
    /// Learning rate.
    pub lr: f64,
    /// Decay of the first-moment estimate.
    pub beta1: f64,
    /// Decay of the second-moment estimate.
    pub beta2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
    step: u64,
    params: Vec<Var>,
    /// Where each parameter's values start in the flat moments.
    offsets: Vec<usize>,
    /// Both moments of every parameter, as one flat tensor each.
    m: Tensor,
    v: Tensor,
}

impl DeviceAdam {
    /// Adam over `params` with betas (0.9, 0.999) and eps 1e-8, moments zero on the params' device.
    pub fn new(params: Vec<Var>, lr: f64) -> Result<DeviceAdam> {
        let mut offsets = Vec::with_capacity(params.len());
        let mut total = 0;
        for p in &params {
            offsets.push(total);
            total += p.elem_count();
        }
        let device = params.first().map_or(Device::Cpu, |p| p.device().clone());
        let m = Tensor::zeros(total, candle_core::DType::F32, &device)?;
        Ok(DeviceAdam { lr, beta1: 0.9, beta2: 0.999, eps: 1e-8, step: 0, params, offsets, v: m.clone(), m })
    }

    fn part(&self, flat: &Tensor, i: usize) -> Result<Tensor> {
        let p = &self.params[i];
        flat.narrow(0, self.offsets[i], p.elem_count())?.reshape(p.shape())
    }

    /// One update from the gradients in `grads`; parameters without one are left alone.
    ///
    /// The gradients, moments and updates are one flat tensor each, so a step costs two kernels
    /// per parameter (gathering its gradient, writing its update) and a dozen for the arithmetic,
    /// instead of a dozen per parameter. On a GPU, where each kernel costs a launch, that is most
    /// of the optimiser's time.
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        if self.params.is_empty() {
            return Ok(());
        }
        self.step += 1;
        // as the fused step computes them: in f64, then rounded to f32
        let bias_correction1 = (1.0 - self.beta1.powi(self.step as i32)) as f32;
        let bias_correction2 = (1.0 - self.beta2.powi(self.step as i32)) as f32;
        let (b1, b2) = (self.beta1 as f32, self.beta2 as f32);
        let step_size = self.lr as f32 / bias_correction1;
        let inv_sqrt_bc2 = 1.0 / bias_correction2.sqrt();
        let grad = |i: usize| grads.get(self.params[i].as_tensor());
        let live: Vec<bool> = (0..self.params.len()).map(|i| grad(i).is_some()).collect();
        if !live.contains(&true) {
            return Ok(());
        }
        // a parameter without a gradient gets zeros here, and its old moments back below
        let g = (0..self.params.len())
            .map(|i| match grad(i) {
                Some(g) => g.flatten_all(),
                None => self.params[i].as_tensor().zeros_like()?.flatten_all(),
            })
            .collect::<Result<Vec<_>>>()?;
        let g = Tensor::cat(&g, 0)?;
        let m = (self.m.affine(b1 as f64, 0.0)? + g.affine((1.0 - b1) as f64, 0.0)?)?;
        let v = (self.v.affine(b2 as f64, 0.0)? + g.sqr()?.affine((1.0 - b2) as f64, 0.0)?)?;
        let denominator = v.sqrt()?.affine(inv_sqrt_bc2 as f64, self.eps)?;
        let update = (m.affine(step_size as f64, 0.0)? / denominator)?;
        for (i, &live) in live.iter().enumerate() {
            if live {
                let p = &self.params[i];
                p.set(&(p.as_tensor() - self.part(&update, i)?)?)?;
            }
        }
        if live.iter().all(|&l| l) {
            (self.m, self.v) = (m, v);
        } else {
            let keep = |new: &Tensor, old: &Tensor| -> Result<Tensor> {
                let parts = (0..self.params.len())
                    .map(|i| self.part(if live[i] { new } else { old }, i)?.flatten_all())
                    .collect::<Result<Vec<_>>>()?;
                Tensor::cat(&parts, 0)
            };
            (self.m, self.v) = (keep(&m, &self.m)?, keep(&v, &self.v)?);
        }
        Ok(())
    }
}

impl Optimizer for DeviceAdam {
    fn state(&self, prefix: &str) -> Result<(Vec<(String, Tensor)>, u64)> {
        let mut out = Vec::new();
        for i in 0..self.params.len() {
            out.push((format!("{prefix}.{i}.m"), self.part(&self.m, i)?.flatten_all()?.to_device(&Device::Cpu)?));
            out.push((format!("{prefix}.{i}.v"), self.part(&self.v, i)?.flatten_all()?.to_device(&Device::Cpu)?));
        }
        Ok((out, self.step))
    }

    fn load_state(&mut self, prefix: &str, tensors: &HashMap<String, Tensor>, step: u64) -> anyhow::Result<()> {
        let flat = |name: &str| -> anyhow::Result<Tensor> {
            let mut parts = Vec::with_capacity(self.params.len());
            for (i, p) in self.params.iter().enumerate() {
                let key = format!("{prefix}.{i}.{name}");
                let t = tensors.get(&key).ok_or_else(|| anyhow::anyhow!("checkpoint lacks optimiser tensor {key}"))?;
                anyhow::ensure!(
                    t.elem_count() == p.elem_count(),
                    "optimiser tensor {key} has {} values, expected {}",
                    t.elem_count(),
                    p.elem_count()
                );
                parts.push(t.flatten_all()?.to_dtype(candle_core::DType::F32)?);
            }
            Ok(Tensor::cat(&parts, 0)?.to_device(self.m.device())?)
        };
        let (m, v) = (flat("m")?, flat("v")?);
        (self.m, self.v) = (m, v);
        self.step = step;
        Ok(())
    }
}
