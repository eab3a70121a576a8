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
    m: Vec<Tensor>,
    v: Vec<Tensor>,
}

impl DeviceAdam {
    /// Adam over `params` with betas (0.9, 0.999) and eps 1e-8, moments zero on the params' device.
    pub fn new(params: Vec<Var>, lr: f64) -> Result<DeviceAdam> {
        let zeros = |p: &Var| p.as_tensor().zeros_like();
        let m = params.iter().map(zeros).collect::<Result<_>>()?;
        let v = params.iter().map(zeros).collect::<Result<_>>()?;
        Ok(DeviceAdam { lr, beta1: 0.9, beta2: 0.999, eps: 1e-8, step: 0, params, m, v })
    }

    /// One update from the gradients in `grads`; parameters without one are left alone.
    ///
    /// The parameters that have a gradient are updated together: their gradients, moments and
    /// updates as one flat tensor each, so a step costs a few kernels per parameter (gather and
    /// scatter) and a dozen for the arithmetic, instead of a dozen per parameter. On a GPU, where
    /// each kernel costs a launch, that is most of the optimiser's time.
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.step += 1;
        // as the fused step computes them: in f64, then rounded to f32
        let bias_correction1 = (1.0 - self.beta1.powi(self.step as i32)) as f32;
        let bias_correction2 = (1.0 - self.beta2.powi(self.step as i32)) as f32;
        let (b1, b2) = (self.beta1 as f32, self.beta2 as f32);
        let step_size = self.lr as f32 / bias_correction1;
        let inv_sqrt_bc2 = 1.0 / bias_correction2.sqrt();
        let live: Vec<usize> =
            (0..self.params.len()).filter(|&i| grads.get(self.params[i].as_tensor()).is_some()).collect();
        if live.is_empty() {
            return Ok(());
        }
        let flat = |ts: Vec<Tensor>| -> Result<Tensor> {
            let flat = ts.iter().map(|t| t.flatten_all()).collect::<Result<Vec<_>>>()?;
            Tensor::cat(&flat, 0)
        };
        let g = flat(live.iter().map(|&i| grads.get(self.params[i].as_tensor()).expect("live").clone()).collect())?;
        let m = flat(live.iter().map(|&i| self.m[i].clone()).collect())?;
        let v = flat(live.iter().map(|&i| self.v[i].clone()).collect())?;
        let m = (m.affine(b1 as f64, 0.0)? + g.affine((1.0 - b1) as f64, 0.0)?)?;
        let v = (v.affine(b2 as f64, 0.0)? + g.sqr()?.affine((1.0 - b2) as f64, 0.0)?)?;
        let denominator = v.sqrt()?.affine(inv_sqrt_bc2 as f64, self.eps)?;
        let update = (m.affine(step_size as f64, 0.0)? / denominator)?;
        let mut offset = 0;
        for &i in &live {
            let p = &self.params[i];
            let (len, shape) = (p.elem_count(), p.shape().clone());
            let part = |t: &Tensor| t.narrow(0, offset, len)?.reshape(shape.clone());
            p.set(&(p.as_tensor() - part(&update)?)?)?;
            self.m[i] = part(&m)?;
            self.v[i] = part(&v)?;
            offset += len;
        }
        Ok(())
    }
}

impl Optimizer for DeviceAdam {
    fn state(&self, prefix: &str) -> Result<(Vec<(String, Tensor)>, u64)> {
        let mut out = Vec::new();
        for (i, (m, v)) in self.m.iter().zip(&self.v).enumerate() {
            out.push((format!("{prefix}.{i}.m"), m.flatten_all()?.to_device(&Device::Cpu)?));
            out.push((format!("{prefix}.{i}.v"), v.flatten_all()?.to_device(&Device::Cpu)?));
        }
        Ok((out, self.step))
    }

    fn load_state(&mut self, prefix: &str, tensors: &HashMap<String, Tensor>, step: u64) -> anyhow::Result<()> {
        for (i, p) in self.params.iter().enumerate() {
            for (name, slot) in [("m", &mut self.m[i]), ("v", &mut self.v[i])] {
                let key = format!("{prefix}.{i}.{name}");
                let t = tensors.get(&key).ok_or_else(|| anyhow::anyhow!("checkpoint lacks optimiser tensor {key}"))?;
                anyhow::ensure!(
                    t.elem_count() == p.elem_count(),
                    "optimiser tensor {key} has {} values, expected {}",
                    t.elem_count(),
                    p.elem_count()
                );
                *slot = t.reshape(p.shape())?.to_device(p.device())?;
            }
        }
        self.step = step;
        Ok(())
    }
}
