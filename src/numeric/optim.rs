//! Adam whose state (moments and step count) can be saved and restored, so that a resumed run
//! continues with exactly the optimiser it stopped with. candle-nn's `AdamW` keeps its moments
//! private; this one computes the same update (tested against it) in one pass per parameter,
//! in place (`inplace::AdamStep`).
use std::cell::RefCell;
use std::sync::Arc;

use candle_core::backprop::GradStore;
use candle_core::{Device, Result, Tensor, Var};

use super::inplace::{AdamStep, AdamStepFrom};
use super::stack::GradSlot;

/// A parameter an optimiser updates, and where its gradient is found: in candle's gradient
/// store, or first in a slot that a fused node ([`super::stack`]) writes.
#[derive(Clone)]
pub struct Param {
    var: Var,
    slot: Option<(Arc<[GradSlot]>, usize)>,
}

impl Param {
    /// `var`, whose gradient a fused node leaves in `slots[index]`.
    pub fn with_slot(var: Var, slots: Arc<[GradSlot]>, index: usize) -> Param {
        Param { var, slot: Some((slots, index)) }
    }
}

impl From<Var> for Param {
    fn from(var: Var) -> Param {
        Param { var, slot: None }
    }
}

/// An optimiser's state as a checkpoint holds it: named tensors (on the CPU) and a step count.
/// The fused [`Adam`] and the device-generic one (`agents::common::device::adam`) write the same names,
/// so a checkpoint moves between them.
pub trait Optimizer {
    /// Moments as named CPU tensors plus the step count.
    fn state(&self, prefix: &str) -> Result<(Vec<(String, Tensor)>, u64)>;
    /// Restores the moments and step count saved under `prefix`.
    fn load_state(
        &mut self,
        prefix: &str,
        tensors: &std::collections::HashMap<String, Tensor>,
        step: u64,
    ) -> anyhow::Result<()>;
}

/// Adam (Kingma and Ba, 2015) over candle variables, updated in place with fixed-order arithmetic.
pub struct Adam {
    /// Learning rate.
    pub lr: f64,
    /// Decay of the first-moment estimate.
    pub beta1: f64,
    /// Decay of the second-moment estimate.
    pub beta2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
    step: u64,
    params: Vec<Param>,
    m: Vec<Vec<f32>>,
    v: Vec<Vec<f32>>,
}

impl Adam {
    /// Adam over `params` with the usual betas (0.9, 0.999) and eps 1e-8.
    pub fn new<P: Into<Param>>(params: Vec<P>, lr: f64) -> Adam {
        let params: Vec<Param> = params.into_iter().map(Into::into).collect();
        let m = params.iter().map(|p| vec![0.0; p.var.elem_count()]).collect();
        let v = params.iter().map(|p| vec![0.0; p.var.elem_count()]).collect();
        Adam { lr, beta1: 0.9, beta2: 0.999, eps: 1e-8, step: 0, params, m, v }
    }

    /// [`Adam::new`] with another `beta1` (CrossQ's 0.5, for one).
    pub fn with_beta1<P: Into<Param>>(params: Vec<P>, lr: f64, beta1: f64) -> Adam {
        Adam { beta1, ..Adam::new(params, lr) }
    }

    /// Updates done so far.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// One update from the gradients of the parameters (each from its slot if one waits there,
    /// else from `grads`); parameters without a gradient are left alone.
    pub fn step(&mut self, grads: &GradStore) -> Result<()> {
        self.step += 1;
        let bias_correction1 = (1.0 - self.beta1.powi(self.step as i32)) as f32;
        let bias_correction2 = (1.0 - self.beta2.powi(self.step as i32)) as f32;
        for ((p, m), v) in self.params.iter().zip(&mut self.m).zip(&mut self.v) {
            let kernel = AdamStep {
                lr: self.lr as f32,
                beta1: self.beta1 as f32,
                beta2: self.beta2 as f32,
                eps: self.eps as f32,
                bias_correction1,
                bias_correction2,
                m: RefCell::new(m.as_mut_slice()),
                v: RefCell::new(v.as_mut_slice()),
            };
            let theta = p.var.as_tensor();
            if let Some((slots, i)) = &p.slot {
                if slots[*i].take(|grad| theta.inplace_op1(&AdamStepFrom { step: &kernel, grad }))? {
                    continue;
                }
            }
            if let Some(g) = grads.get(theta) {
                theta.inplace_op2(&g.contiguous()?, &kernel)?;
            }
        }
        Ok(())
    }
}

impl Optimizer for Adam {
    fn state(&self, prefix: &str) -> Result<(Vec<(String, Tensor)>, u64)> {
        let mut out = Vec::new();
        for (i, (m, v)) in self.m.iter().zip(&self.v).enumerate() {
            out.push((format!("{prefix}.{i}.m"), Tensor::from_slice(m, m.len(), &Device::Cpu)?));
            out.push((format!("{prefix}.{i}.v"), Tensor::from_slice(v, v.len(), &Device::Cpu)?));
        }
        Ok((out, self.step))
    }

    fn load_state(
        &mut self,
        prefix: &str,
        tensors: &std::collections::HashMap<String, Tensor>,
        step: u64,
    ) -> anyhow::Result<()> {
        for i in 0..self.params.len() {
            for (name, slot) in [("m", &mut self.m[i]), ("v", &mut self.v[i])] {
                let key = format!("{prefix}.{i}.{name}");
                let t = tensors.get(&key).ok_or_else(|| anyhow::anyhow!("checkpoint lacks optimiser tensor {key}"))?;
                let data = t.flatten_all()?.to_vec1::<f32>()?;
                if data.len() != slot.len() {
                    anyhow::bail!("optimiser tensor {key} has {} values, expected {}", data.len(), slot.len());
                }
                *slot = data;
            }
        }
        self.step = step;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_nn::{AdamW, Optimizer, ParamsAdamW};

    #[test]
    fn matches_candle_adamw_without_weight_decay() {
        let init = Tensor::new(&[[0.3f32, -0.7], [1.2, 0.05]], &Device::Cpu).unwrap();
        let ours_p = Var::from_tensor(&init).unwrap();
        let theirs_p = Var::from_tensor(&init.copy().unwrap()).unwrap();
        let mut ours = Adam::new(vec![ours_p.clone()], 1e-2);
        let params = ParamsAdamW { lr: 1e-2, weight_decay: 0.0, ..Default::default() };
        let mut theirs = AdamW::new(vec![theirs_p.clone()], params).unwrap();
        let target = Tensor::new(&[[1.0f32, 2.0], [-1.0, 0.5]], &Device::Cpu).unwrap();
        for _ in 0..50 {
            for (p, step) in [(&ours_p, 0), (&theirs_p, 1)] {
                let loss = (p.as_tensor() - &target).unwrap().sqr().unwrap().sum_all().unwrap();
                let grads = loss.backward().unwrap();
                if step == 0 {
                    ours.step(&grads).unwrap()
                } else {
                    theirs.step(&grads).unwrap()
                }
            }
        }
        let a = ours_p.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        let b = theirs_p.flatten_all().unwrap().to_vec1::<f32>().unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-5, "{a:?} vs {b:?}");
        }
        assert_eq!(ours.steps(), 50);
    }
}
