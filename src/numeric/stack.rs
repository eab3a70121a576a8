//! A stack of dense layers (ReLU between them, nothing after the last) as one autograd node,
//! whose weight gradients bypass candle's gradient store.
//!
//! With one node per layer ([`super::dense`]), candle's backward pass allocates a zero gradient
//! for every input of every node, weights and hidden activations alike, and adds the layer's
//! gradient into it; the optimiser then reads the weight gradients from that store. perf put
//! those fills, adds and copies at about a tenth of a SAC update. As one node the stack keeps its
//! hidden activations in reused buffers, runs the layers' backward passes from one buffer to the
//! next, and writes the weight gradients into the network's [`GradSlot`]s, where
//! [`super::optim::Adam`] takes them. Each layer's arithmetic is [`super::dense`]'s, so a stack
//! gives the bits its layers give one node at a time (tested below).
use std::cell::RefCell;
use std::sync::{Arc, Mutex, MutexGuard};

use candle_core::{bail, CpuStorage, CustomOp2, Layout, Result, Shape, Tensor};

use super::dense::{dims, members_stack_backward, rows_stack_backward, stack_forward, Dims, StackGrads};
use super::inplace::{contiguous, cpu_contiguous};
use super::kernel_path::{self, KernelPath};

/// Where the backward pass leaves one parameter's gradient until the optimiser takes it.
#[derive(Default)]
pub struct GradSlot(Mutex<Slot>);

#[derive(Default)]
struct Slot {
    values: Vec<f32>,
    /// `values` holds a gradient not yet taken.
    fresh: bool,
}

impl GradSlot {
    fn lock(&self) -> MutexGuard<'_, Slot> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Runs `f` on the waiting gradient and marks it taken; false (and `f` not run) when none waits.
    pub fn take(&self, f: impl FnOnce(&[f32]) -> Result<()>) -> Result<bool> {
        let mut slot = self.lock();
        if !slot.fresh {
            return Ok(false);
        }
        slot.fresh = false;
        f(&slot.values).map(|()| true)
    }

    /// A copy of the waiting gradient, if any (tests and diagnostics; the slot keeps it).
    pub fn peek(&self) -> Option<Vec<f32>> {
        let slot = self.lock();
        slot.fresh.then(|| slot.values.clone())
    }
}

/// `len` values for a new gradient: the slot's own buffer when none waits, otherwise (the network
/// used twice in one loss) a scratch buffer that [`deposit`] adds to the waiting one.
fn deposit_buffer(slot: &mut Slot, len: usize) -> Vec<f32> {
    if slot.fresh {
        take_buffer(len)
    } else {
        slot.values.resize(len, 0.0);
        std::mem::take(&mut slot.values)
    }
}

fn deposit(slot: &mut Slot, mut buffer: Vec<f32>, len: usize) {
    if slot.fresh {
        slot.values.iter_mut().zip(&buffer[..len]).for_each(|(a, g)| *a += g);
        give_buffer(buffer);
    } else {
        buffer.truncate(len);
        slot.values = buffer;
        slot.fresh = true;
    }
}

thread_local! {
    /// Buffers of earlier forward and backward passes, reused so that each pass neither
    /// allocates nor clears its activations and gradients (every value is written before use).
    static FREE: RefCell<Vec<Vec<f32>>> = const { RefCell::new(Vec::new()) };
}

/// A buffer of at least `len` values (old contents); none from the pool when `len` is 0.
fn take_buffer(len: usize) -> Vec<f32> {
    if len == 0 {
        return Vec::new();
    }
    FREE.with(|free| {
        let mut free = free.borrow_mut();
        let best = free.iter().enumerate().filter(|(_, b)| b.len() >= len).min_by_key(|(_, b)| b.len()).map(|(i, _)| i);
        match best {
            Some(i) => free.swap_remove(i),
            None => vec![0.0; len],
        }
    })
}

fn give_buffer(buffer: Vec<f32>) {
    const KEEP: usize = 32;
    FREE.with(|free| {
        let mut free = free.borrow_mut();
        if free.len() < KEEP && !buffer.is_empty() {
            free.push(buffer);
        }
    });
}

/// The node: layers after the first (the first is the op's second input), the slots of every
/// weight and bias in layer order (none when the weights are held constant), and the outputs of
/// the hidden layers, kept from the forward pass for the backward pass.
struct Stack {
    rest: Vec<(Tensor, Tensor)>,
    first_bias: Tensor,
    grads: Option<Arc<[GradSlot]>>,
    path: KernelPath,
    hidden: Mutex<Vec<Vec<f32>>>,
}

impl Drop for Stack {
    fn drop(&mut self) {
        let hidden = std::mem::take(self.hidden.get_mut().unwrap_or_else(|e| e.into_inner()));
        hidden.into_iter().for_each(give_buffer);
    }
}

/// The dims of a layer after the first, whose input is the previous layer's output: `[k, n, in]`,
/// or `[n, in]` for one network.
fn hidden_layer_dims(w: &Tensor, b: &Tensor, n: usize) -> Result<Dims> {
    let wd = w.dims();
    let x: Vec<usize> = if wd.len() == 3 { vec![wd[0], n, wd[2]] } else { vec![n, wd[1]] };
    dims(&x, wd, b.elem_count())
}

fn values<'a>(storage: &'a candle_core::Storage, layout: &Layout) -> Result<&'a [f32]> {
    cpu_contiguous(storage, layout, "dense stack")
}

impl Stack {
    fn bias(&self, l: usize) -> &Tensor {
        if l == 0 {
            &self.first_bias
        } else {
            &self.rest[l - 1].1
        }
    }

    /// Every layer's dims for an input of `x_dims` (n rows).
    fn layer_dims(&self, x_dims: &[usize], w0_dims: &[usize], n: usize) -> Result<Vec<Dims>> {
        let mut ds = vec![dims(x_dims, w0_dims, self.first_bias.elem_count())?];
        for (w, b) in &self.rest {
            ds.push(hidden_layer_dims(w, b, n)?);
        }
        Ok(ds)
    }

    /// The backward pass into buffers and gradient slots, by `rows_stack_backward` for one
    /// network and `members_stack_backward` for stacked ones; returns x's gradient.
    #[allow(clippy::too_many_arguments)]
    fn stack_bwd(
        &self,
        ds: &[Dims],
        x: &Tensor,
        w0: &Tensor,
        x_values: &[f32],
        hidden: &[Vec<f32>],
        g_out: &[f32],
        need_grad_x: bool,
    ) -> Result<Option<Tensor>> {
        let w_guards: Vec<_> = self.rest.iter().map(|(w, _)| w.storage_and_layout()).collect();
        let (w0_guard, w0_layout) = w0.storage_and_layout();
        let mut ws = vec![values(&w0_guard, w0_layout)?];
        for (guard, layout) in &w_guards {
            ws.push(values(guard, layout)?);
        }
        let mut xs = vec![x_values];
        xs.extend(hidden.iter().zip(&ds[1..]).map(|(h, d)| &h[..d.k * d.n * d.inp]));
        let wanted = |l: usize, d: &Dims| if l > 0 || need_grad_x { d.k * d.n * d.inp } else { 0 };
        let mut gx_buffers: Vec<Vec<f32>> = ds.iter().enumerate().map(|(l, d)| take_buffer(wanted(l, d))).collect();
        let mut slots: Vec<MutexGuard<'_, Slot>> =
            self.grads.iter().flat_map(|s| s.iter().map(GradSlot::lock)).collect();
        let mut params: Vec<(Vec<f32>, usize)> = slots
            .iter_mut()
            .enumerate()
            .map(|(i, slot)| {
                let d = &ds[i / 2];
                let len = if i % 2 == 0 { d.k * d.out * d.inp } else { d.k * d.out };
                (deposit_buffer(slot, len), len)
            })
            .collect();
        {
            // weights held constant: an empty buffer per layer
            let (mut gw, mut gb): (Vec<&mut [f32]>, Vec<&mut [f32]>) = if params.is_empty() {
                (ds.iter().map(|_| Default::default()).collect(), ds.iter().map(|_| Default::default()).collect())
            } else {
                (Vec::new(), Vec::new())
            };
            for (i, (buffer, len)) in params.iter_mut().enumerate() {
                if i % 2 == 0 { &mut gw } else { &mut gb }.push(&mut buffer[..*len]);
            }
            let gx = gx_buffers.iter_mut().enumerate().map(|(l, b)| &mut b[..wanted(l, &ds[l])]).collect();
            let grads = StackGrads { gw, gb, gx };
            if ds[0].k == 1 {
                rows_stack_backward(self.path, ds, &xs, &ws, g_out, grads);
            } else {
                members_stack_backward(self.path, ds, &xs, &ws, g_out, grads);
            }
        }
        for (slot, (buffer, len)) in slots.iter_mut().zip(params) {
            deposit(slot, buffer, len);
        }
        let mut gx_buffers = gx_buffers.into_iter();
        let mut gx0 = gx_buffers.next().expect("a first layer");
        gx_buffers.for_each(give_buffer);
        if !need_grad_x {
            give_buffer(gx0);
            return Ok(None);
        }
        let d = &ds[0];
        gx0.truncate(if d.shared_x { d.n * d.inp } else { d.k * d.n * d.inp });
        Ok(Some(Tensor::from_vec(gx0, x.shape(), x.device())?))
    }
}

impl CustomOp2 for Stack {
    fn name(&self) -> &'static str {
        "dense-stack"
    }

    fn cpu_fwd(&self, s1: &CpuStorage, l1: &Layout, s2: &CpuStorage, l2: &Layout) -> Result<(CpuStorage, Shape)> {
        let x = contiguous(s1, l1, "dense stack")?;
        let layers = self.rest.len() + 1;
        let n = l1.dims()[l1.dims().len() - 2];
        let guards: Vec<_> = self.rest.iter().map(|(w, _)| w.storage_and_layout()).collect();
        let bias_guards: Vec<_> = (0..layers).map(|l| self.bias(l).storage_and_layout()).collect();
        let mut weights = vec![contiguous(s2, l2, "dense stack")?];
        for (guard, layout) in &guards {
            weights.push(values(guard, layout)?);
        }
        let biases = bias_guards.iter().map(|(guard, layout)| values(guard, layout)).collect::<Result<Vec<_>>>()?;
        let ds = self.layer_dims(l1.dims(), l2.dims(), n)?;
        let mut hidden = self.hidden.lock().unwrap_or_else(|e| e.into_inner());
        let mut outputs: Vec<Vec<f32>> = ds[..layers - 1].iter().map(|d| take_buffer(d.k * d.n * d.out)).collect();
        let last = &ds[layers - 1];
        outputs.push(vec![0f32; last.k * last.n * last.out]);
        let mut slices: Vec<&mut [f32]> =
            outputs.iter_mut().zip(&ds).map(|(y, d)| &mut y[..d.k * d.n * d.out]).collect();
        stack_forward(self.path, &ds, x, &weights, &biases, &mut slices);
        drop(slices);
        let output = outputs.pop().expect("the last layer's output");
        *hidden = outputs;
        let w_dims = if layers == 1 { l2.dims() } else { self.rest[layers - 2].0.dims() };
        let shape: Shape =
            if w_dims.len() == 2 { (last.n, last.out).into() } else { (last.k, last.n, last.out).into() };
        Ok((CpuStorage::F32(output), shape))
    }

    fn bwd(&self, x: &Tensor, w0: &Tensor, _res: &Tensor, grad: &Tensor) -> Result<(Option<Tensor>, Option<Tensor>)> {
        let need_grad_x = x.track_op();
        let hidden = self.hidden.lock().unwrap_or_else(|e| e.into_inner());
        let layers = self.rest.len() + 1;
        if hidden.len() + 1 != layers {
            bail!("dense stack: backward pass without a forward pass");
        }
        let n = x.dims()[x.dims().len() - 2];
        let grad = grad.contiguous()?;
        let (gs, gl) = grad.storage_and_layout();
        let (xs, xl) = x.storage_and_layout();
        let x_values = values(&xs, xl)?;
        let ds = self.layer_dims(x.dims(), w0.dims(), n)?;
        Ok((self.stack_bwd(&ds, x, w0, x_values, &hidden, values(&gs, gl)?, need_grad_x)?, None))
    }
}

/// `layers` (weight `[out, in]` or `[k, out, in]`, bias `out` or `[k, 1, out]` values) applied to
/// `x` with ReLU between them, as [`super::dense::dense`] would one at a time. With `grads` (one
/// slot per weight and bias, in order) the backward pass leaves the parameters' gradients there
/// instead of in candle's gradient store; without, the parameters are held constant and only
/// `x` gets a gradient.
pub fn relu_stack(x: &Tensor, layers: &[(Tensor, Tensor)], grads: Option<&Arc<[GradSlot]>>) -> Result<Tensor> {
    let Some(((w0, b0), rest)) = layers.split_first() else { bail!("dense stack: no layers") };
    if let Some(slots) = grads {
        if slots.len() != 2 * layers.len() {
            bail!("dense stack: {} gradient slots for {} layers", slots.len(), layers.len());
        }
    }
    let mut width = x.dims().last().copied().unwrap_or(0);
    for (i, (w, b)) in layers.iter().enumerate() {
        let ok = match (w.dims(), layers[0].0.rank()) {
            ([out, inp], 2) => *inp == width && b.elem_count() == *out,
            ([k, out, inp], 3) => *inp == width && *k == layers[0].0.dims()[0] && b.elem_count() == k * out,
            _ => false,
        };
        if !ok {
            bail!(
                "dense stack: layer {i} (weight {:?}, bias {:?}) does not follow a width of {width}",
                w.dims(),
                b.dims()
            );
        }
        width = w.dims()[w.rank() - 2];
    }
    let contiguous = |t: &Tensor| t.contiguous();
    let rest = rest.iter().map(|(w, b)| Ok((contiguous(w)?, contiguous(b)?))).collect::<Result<Vec<_>>>()?;
    let op = Stack {
        rest,
        first_bias: b0.contiguous()?,
        grads: grads.cloned(),
        path: kernel_path::active(),
        hidden: Mutex::new(Vec::new()),
    };
    // The first weight is an input of the node only so that candle keeps the node in the graph
    // when x needs no gradient (a critic's loss); it never receives a gradient from candle.
    let w0 = if grads.is_some() { w0.contiguous()? } else { w0.detach().contiguous()? };
    x.contiguous()?.apply_op2(&w0, op)
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Var};

    use super::*;
    use crate::numeric::dense::dense;
    use crate::numeric::inplace::Activation;
    use crate::numeric::second_core;

    fn values(n: usize, seed: f32) -> Vec<f32> {
        (0..n).map(|i| (i as f32 * 0.37 + seed).sin() * 0.5).collect()
    }

    fn var(shape: &[usize], seed: f32) -> Var {
        Var::from_tensor(&Tensor::from_vec(values(shape.iter().product(), seed), shape, &Device::Cpu).unwrap()).unwrap()
    }

    fn flat(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    }

    /// (input shape, members k (0: one network), layer sizes): small ones in one piece, large
    /// ones split in halves.
    const CASES: [(&[usize], usize, &[usize]); 8] = [
        (&[5, 3], 0, &[3, 8, 6, 2]),
        (&[5, 3], 2, &[3, 8, 6, 1]),
        (&[64, 23], 0, &[23, 400, 300, 12]),
        (&[64, 23], 2, &[23, 256, 256, 1]),
        (&[7, 4], 0, &[4, 3]),
        // one network in stacked form (DDPG's single critic), an odd number of members, and
        // members with inputs of their own
        (&[64, 23], 1, &[23, 400, 300, 1]),
        (&[64, 23], 3, &[23, 256, 128, 1]),
        (&[2, 64, 23], 2, &[23, 256, 256, 1]),
    ];

    fn layers(k: usize, sizes: &[usize]) -> Vec<(Var, Var)> {
        sizes
            .windows(2)
            .enumerate()
            .map(|(i, s)| {
                let (w, b): (Vec<usize>, Vec<usize>) =
                    if k == 0 { (vec![s[1], s[0]], vec![s[1]]) } else { (vec![k, s[1], s[0]], vec![k, 1, s[1]]) };
                (var(&w, 0.3 + i as f32), var(&b, 1.1 + i as f32))
            })
            .collect()
    }

    /// The layers one node each (`dense`), as the agents ran them before the stack.
    fn one_node_per_layer(x: &Tensor, layers: &[(Var, Var)]) -> Tensor {
        let mut h = x.clone();
        for (i, (w, b)) in layers.iter().enumerate() {
            let act = if i + 1 < layers.len() { Activation::Relu } else { Activation::Identity };
            h = dense(&h, w.as_tensor(), b.as_tensor(), act).unwrap();
        }
        h
    }

    /// Output, input gradient and parameter gradients of `sum(y * probe)` (twice the same
    /// network when `twice`): by one node per layer, and by the stack.
    fn both(case: usize, twice: bool) -> [Vec<Vec<f32>>; 2] {
        let (x_shape, k, sizes) = CASES[case];
        let x = var(x_shape, 0.9);
        let params = layers(k, sizes);
        let tensors: Vec<(Tensor, Tensor)> =
            params.iter().map(|(w, b)| (w.as_tensor().clone(), b.as_tensor().clone())).collect();
        let slots: Arc<[GradSlot]> = (0..2 * params.len()).map(|_| GradSlot::default()).collect();
        let vars: Vec<&Var> = params.iter().flat_map(|(w, b)| [w, b]).collect();
        let run = |fused: bool| {
            let forward = |x: &Tensor| {
                if fused {
                    relu_stack(x, &tensors, Some(&slots)).unwrap()
                } else {
                    one_node_per_layer(x, &params)
                }
            };
            let y = forward(x.as_tensor());
            let probe = Tensor::from_vec(values(y.elem_count(), 2.3), y.shape(), &Device::Cpu).unwrap();
            let mut loss = (&y * &probe).unwrap().sum_all().unwrap();
            if twice {
                let again = forward(&x.as_tensor().affine(0.5, 0.1).unwrap());
                loss = (loss + (again * &probe).unwrap().sum_all().unwrap()).unwrap();
            }
            let grads = loss.backward().unwrap();
            let mut out = vec![flat(&y), flat(grads.get(x.as_tensor()).unwrap())];
            for (i, v) in vars.iter().enumerate() {
                out.push(if fused {
                    assert!(grads.get(v.as_tensor()).is_none(), "a fused gradient reached candle's store");
                    slots[i].peek().expect("a gradient in the slot")
                } else {
                    flat(grads.get(v.as_tensor()).unwrap())
                });
            }
            out
        };
        [run(false), run(true)]
    }

    /// Same values and gradients as the layers run one node at a time, compared bit for bit
    /// (as f32 equality: candle adds every gradient to a zero, which turns a -0 into +0).
    #[test]
    fn a_stack_gives_the_bits_of_its_layers_one_node_at_a_time() {
        second_core::with_and_without_helper(|helper| {
            for case in 0..CASES.len() {
                for twice in [false, true] {
                    let [reference, fused] = both(case, twice);
                    assert_eq!(reference.len(), fused.len());
                    for (i, (r, f)) in reference.iter().zip(&fused).enumerate() {
                        assert_eq!(r, f, "case {case}, twice {twice}, helper {helper}, item {i}");
                    }
                }
            }
        });
    }

    /// Without slots the weights are constants: the input gradient is unchanged, no weight
    /// gradient is made anywhere; and a stack whose input needs no gradient still reaches its
    /// weights (a critic's loss).
    #[test]
    fn frozen_stacks_pass_the_input_gradient_and_inputs_without_gradient_still_train() {
        let (x_shape, k, sizes) = CASES[3];
        let x = var(x_shape, 0.9);
        let params = layers(k, sizes);
        let tensors: Vec<(Tensor, Tensor)> =
            params.iter().map(|(w, b)| (w.as_tensor().clone(), b.as_tensor().clone())).collect();
        let slots: Arc<[GradSlot]> = (0..2 * params.len()).map(|_| GradSlot::default()).collect();
        let frozen = relu_stack(x.as_tensor(), &tensors, None).unwrap();
        let live = one_node_per_layer(x.as_tensor(), &params);
        assert_eq!(flat(&frozen), flat(&live));
        let g_frozen = frozen.sum_all().unwrap().backward().unwrap();
        let g_live = live.sum_all().unwrap().backward().unwrap();
        assert_eq!(flat(g_frozen.get(x.as_tensor()).unwrap()), flat(g_live.get(x.as_tensor()).unwrap()));
        assert!(params
            .iter()
            .all(|(w, b)| g_frozen.get(w.as_tensor()).is_none() && g_frozen.get(b.as_tensor()).is_none()));

        let constant_x = x.as_tensor().detach();
        let y = relu_stack(&constant_x, &tensors, Some(&slots)).unwrap();
        let grads = y.sum_all().unwrap().backward().unwrap();
        assert!(grads.get(&constant_x).is_none());
        let g_w0 = g_live.get(params[0].0.as_tensor()).unwrap();
        assert_eq!(slots[0].peek().unwrap(), flat(g_w0));
        // taken once
        assert!(slots[0].take(|_| Ok(())).unwrap());
        assert!(!slots[0].take(|_| Ok(())).unwrap());
        assert!(slots[0].peek().is_none());
    }

    #[test]
    fn bad_stacks_are_refused() {
        let x = Tensor::zeros((4, 3), candle_core::DType::F32, &Device::Cpu).unwrap();
        let layer = |out: usize, inp: usize| {
            (
                Tensor::zeros((out, inp), candle_core::DType::F32, &Device::Cpu).unwrap(),
                Tensor::zeros(out, candle_core::DType::F32, &Device::Cpu).unwrap(),
            )
        };
        assert!(relu_stack(&x, &[], None).is_err());
        assert!(relu_stack(&x, &[layer(5, 2)], None).is_err());
        assert!(relu_stack(&x, &[layer(5, 3), layer(2, 4)], None).is_err());
        let two_slots: Arc<[GradSlot]> = (0..2).map(|_| GradSlot::default()).collect();
        assert!(relu_stack(&x, &[layer(5, 3), layer(2, 5)], Some(&two_slots)).is_err());
    }
}
