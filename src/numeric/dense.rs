//! A dense layer `act(x W^T + b)` as one autograd node, for one network or k stacked ones.
//!
//! Built from candle's ops the same layer is three graph nodes (transpose, matmul, bias add) plus
//! one for the ReLU, and candle's backward pass allocates a zero gradient and adds into it for
//! every input of every node, including a strided add for the transposed weight. perf showed that
//! bookkeeping at about a fifth of a TD3 update once the matmuls were fast; as one node the
//! forward pass is a single matrix product ([`super::matmul`]) that starts from the bias, and
//! the backward pass is two products, a mask and a row sum.
//!
//! Large layers are cut in two independent halves (stacked networks by member, one network by
//! rows of the batch for outputs and input gradients, by output units for weight gradients),
//! handed to [`second_core::join`]. The cut depends only on the sizes, never on whether a helper
//! thread exists, so results are the same with one thread or two. A stack of layers
//! ([`super::stack`]) is cut once for all its layers ([`stack_forward`], [`rows_stack_backward`],
//! [`members_stack_backward`]), one hand-off instead of one per layer.
use candle_core::{bail, CpuStorage, CustomOp3, Layout, Result, Shape, Tensor};

use super::inplace::{contiguous, cpu_contiguous, Activation};
use super::kernel_path::{self, KernelPath};
use super::matmul::{matmul, matmul_bias, Strided};
use super::second_core;
use super::wide::wide;

/// Layers with fewer multiply-adds (k * n * in * out) than this run as one piece (a single
/// observation while acting, the 300 -> 1 output layer). TD3 400-300 updates/s with two
/// threads measured the same within noise for thresholds from 1 << 17 to 1 << 22.
const SPLIT_MACS: usize = 1 << 20;

/// The layer's activation, and the kernel path its forward pass ran on (the backward pass uses
/// the same one, whichever thread runs it).
struct Dense {
    act: Activation,
    path: KernelPath,
}

/// Sizes of `x [n, in] | [k, n, in]`, `w [out, in] | [k, out, in]` and `b` (k * out values).
pub(super) struct Dims {
    pub(super) k: usize,
    pub(super) n: usize,
    pub(super) inp: usize,
    pub(super) out: usize,
    /// x is one `[n, in]` block used by every member.
    pub(super) shared_x: bool,
}

impl Dims {
    fn split(&self) -> bool {
        self.k * self.n * self.inp * self.out >= SPLIT_MACS && (self.k >= 2 || self.n >= 2)
    }

    /// Where member g's input lies in x.
    fn x_range(&self, g: usize) -> std::ops::Range<usize> {
        if self.shared_x {
            0..self.n * self.inp
        } else {
            g * self.n * self.inp..(g + 1) * self.n * self.inp
        }
    }
}

pub(super) fn dims(x: &[usize], w: &[usize], b_len: usize) -> Result<Dims> {
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

/// `y = act(x W^T + b)` for a block of rows: x `[rows, in]`, w `[out, in]`, y `[rows, out]`.
#[allow(clippy::too_many_arguments)]
fn forward_block(
    path: KernelPath,
    x: &[f32],
    w: &[f32],
    b: &[f32],
    y: &mut [f32],
    inp: usize,
    out: usize,
    act: Activation,
) {
    let rows = y.len() / out;
    let relu = act == Activation::Relu;
    matmul_bias(
        path,
        (rows, out, inp),
        y,
        out,
        b,
        relu,
        Strided::rows(&x[..rows * inp], inp),
        Strided::transposed(w, inp),
    );
}

/// Every layer of a stack, ReLU after each but the last: `ys[l]` receives layer l's output
/// `[k, n, out]` from `ws[l]` and `bs[l]`. A stack with enough work runs in two halves from its
/// input to its output, with one hand-off to the helper thread: the rows of the batch for one
/// network, the members for stacked ones. Rows and members never mix, so the bits are those of
/// one layer at a time.
pub(super) fn stack_forward(
    path: KernelPath,
    ds: &[Dims],
    x: &[f32],
    ws: &[&[f32]],
    bs: &[&[f32]],
    ys: &mut [&mut [f32]],
) {
    let d0 = &ds[0];
    if !split_stack(ds) {
        return if d0.k == 1 {
            rows_forward(path, ds, x, ws, bs, ys)
        } else {
            members_forward(path, ds, x, ws, bs, ys, 0)
        };
    }
    if d0.k == 1 {
        // every layer's output cut after half the rows
        let rows = d0.n / 2;
        let [mut a, mut z] = cut(ys, |l| rows * ds[l].out);
        let (x_a, x_z) = x.split_at(rows * d0.inp);
        second_core::join(
            || rows_forward(path, ds, x_a, ws, bs, &mut a),
            || rows_forward(path, ds, x_z, ws, bs, &mut z),
        );
    } else {
        // every layer's output cut after half the members
        let first = d0.k / 2;
        let [mut a, mut z] = cut(ys, |l| first * ds[l].n * ds[l].out);
        second_core::join(
            || members_forward(path, ds, x, ws, bs, &mut a, 0),
            || members_forward(path, ds, x, ws, bs, &mut z, first),
        );
    }
}

fn stack_activation(l: usize, layers: usize) -> Activation {
    if l + 1 == layers {
        Activation::Identity
    } else {
        Activation::Relu
    }
}

/// One network's layers for the rows of `x` (`ys[l]`: those rows of layer l's output).
fn rows_forward(path: KernelPath, ds: &[Dims], x: &[f32], ws: &[&[f32]], bs: &[&[f32]], ys: &mut [&mut [f32]]) {
    for (l, d) in ds.iter().enumerate() {
        let (done, todo) = ys.split_at_mut(l);
        let input: &[f32] = if l == 0 { x } else { done[l - 1] };
        forward_block(path, input, ws[l], bs[l], todo[0], d.inp, d.out, stack_activation(l, ds.len()));
    }
}

/// Members `g0, g0 + 1, ...` of stacked networks through every layer (`ys[l]`: their blocks of
/// layer l's output).
fn members_forward(
    path: KernelPath,
    ds: &[Dims],
    x: &[f32],
    ws: &[&[f32]],
    bs: &[&[f32]],
    ys: &mut [&mut [f32]],
    g0: usize,
) {
    for (l, d) in ds.iter().enumerate() {
        let (done, todo) = ys.split_at_mut(l);
        let (n, inp, out) = (d.n, d.inp, d.out);
        for (i, y) in todo[0].chunks_exact_mut(n * out).enumerate() {
            let g = g0 + i;
            let input = if l == 0 { &x[d.x_range(g)] } else { &done[l - 1][i * n * inp..(i + 1) * n * inp] };
            let (w, b) = (&ws[l][g * out * inp..(g + 1) * out * inp], &bs[l][g * out..(g + 1) * out]);
            forward_block(path, input, w, b, y, inp, out, stack_activation(l, ds.len()));
        }
    }
}

/// Weight and bias gradients of `units` output units: `gw [units, in] = gp^T x`, `gb = sum of gp's
/// rows`, where `gp` starts at the first of those units, `rows` rows of stride `out`.
#[allow(clippy::too_many_arguments)]
fn weight_grads(
    path: KernelPath,
    gp: &[f32],
    out: usize,
    x: &[f32],
    gw: &mut [f32],
    gb: &mut [f32],
    rows: usize,
    inp: usize,
) {
    let units = gb.len();
    // gp^T (units x rows) is gp read with row stride 1 and column stride out.
    let gp_t = Strided { data: gp, row_stride: 1, col_stride: out };
    matmul(path, (units, inp, rows), gw, inp, false, gp_t, Strided::rows(x, inp));
    gb.fill(0.0);
    wide(path, move || {
        for r in 0..rows {
            gb.iter_mut().zip(&gp[r * out..r * out + units]).for_each(|(a, g)| *a += g);
        }
    });
}

/// Input gradient of a block of rows: `gx [rows, in] = gp [rows, out] W [out, in]`.
fn input_grad(path: KernelPath, gp: &[f32], w: &[f32], gx: &mut [f32], inp: usize, out: usize) {
    let rows = gx.len() / inp;
    matmul(path, (rows, inp, out), gx, inp, false, Strided::rows(gp, out), Strided::rows(w, inp));
}

/// `y [k, n, out] = act(x W^T + b)` for every member, every element written. Large layers run
/// in two halves, the second offered to the helper thread.
#[allow(clippy::too_many_arguments)]
pub(super) fn layer_forward(
    path: KernelPath,
    d: &Dims,
    x: &[f32],
    w: &[f32],
    b: &[f32],
    act: Activation,
    y: &mut [f32],
) {
    // members g0, g0 + 1, ... into consecutive `[n, out]` blocks of y
    let members = |g0: usize, y: &mut [f32]| {
        for (i, y) in y.chunks_exact_mut(d.n * d.out).enumerate() {
            let g = g0 + i;
            let w = &w[g * d.out * d.inp..(g + 1) * d.out * d.inp];
            forward_block(path, &x[d.x_range(g)], w, &b[g * d.out..(g + 1) * d.out], y, d.inp, d.out, act)
        }
    };
    if !d.split() {
        members(0, y);
    } else if d.k == 1 {
        let half = d.n / 2;
        let (top, bottom) = y.split_at_mut(half * d.out);
        second_core::join(
            || forward_block(path, &x[..half * d.inp], w, b, top, d.inp, d.out, act),
            || forward_block(path, &x[half * d.inp..], w, b, bottom, d.inp, d.out, act),
        );
    } else {
        let first = d.k / 2;
        let (a, z) = y.split_at_mut(first * d.n * d.out);
        second_core::join(|| members(0, a), || members(first, z));
    }
}

/// A layer's gradients from `gp [k, n, out]`, the gradient of its output before the activation:
/// with `params`, the weight and bias gradients (`[k, out, in]`, `[k, out]`); with `gx`
/// (`k * n * in` values), the input gradient of each member, and when the members share one
/// input, their sum (member 0 + member 1 + ..., in that order) in the first `n * in` values.
/// `relu_input`: x is the output of a ReLU, and gx is wanted before it (zero where x is not
/// positive), computed in the same halves as gx itself.
#[allow(clippy::too_many_arguments)]
pub(super) fn layer_backward(
    path: KernelPath,
    d: &Dims,
    x: &[f32],
    w: &[f32],
    gp: &[f32],
    params: Option<(&mut [f32], &mut [f32])>,
    gx: Option<&mut [f32]>,
    relu_input: bool,
) {
    assert!(!(relu_input && d.shared_x && d.k > 1), "a shared input's gradient is summed before any ReLU");
    let (need_grad_params, need_grad_x) = (params.is_some(), gx.is_some());
    let (gw, gb) = params.unwrap_or_default();
    let gx = gx.unwrap_or_default();
    let (n, inp, out) = (d.n, d.inp, d.out);
    let gx_len = if need_grad_x { n * inp } else { 0 };
    let input_grad = |gp: &[f32], w: &[f32], gx: &mut [f32], x: &[f32]| {
        input_grad(path, gp, w, gx, inp, out);
        if relu_input {
            relu_mask(path, gx, x);
        }
    };
    // members g0, g0 + 1, ... into consecutive blocks of gw, gb and gx
    let members = |g0: usize, count: usize, gw: &mut [f32], gb: &mut [f32], gx: &mut [f32]| {
        for i in 0..count {
            let g = g0 + i;
            let gp = &gp[g * n * out..(g + 1) * n * out];
            if need_grad_params {
                let (gw, gb) = (&mut gw[i * out * inp..(i + 1) * out * inp], &mut gb[i * out..(i + 1) * out]);
                weight_grads(path, gp, out, &x[d.x_range(g)], gw, gb, n, inp);
            }
            if need_grad_x {
                let (w, x) = (&w[g * out * inp..(g + 1) * out * inp], &x[d.x_range(g)]);
                input_grad(gp, w, &mut gx[i * gx_len..(i + 1) * gx_len], x);
            }
        }
    };
    if !d.split() {
        members(0, d.k, gw, gb, gx);
    } else if d.k == 1 {
        // weight gradients split by output units, input gradients by rows
        let (units, rows) = (out / 2, n / 2);
        let (gw_a, gw_z) = gw.split_at_mut(if need_grad_params { units * inp } else { 0 });
        let (gb_a, gb_z) = gb.split_at_mut(if need_grad_params { units } else { 0 });
        let (gx_a, gx_z) = gx.split_at_mut(if need_grad_x { rows * inp } else { 0 });
        let half =
            |gp_units: &[f32], gw: &mut [f32], gb: &mut [f32], gp_rows: &[f32], gx: &mut [f32], x_rows: &[f32]| {
                if need_grad_params {
                    weight_grads(path, gp_units, out, x, gw, gb, n, inp);
                }
                if need_grad_x {
                    input_grad(gp_rows, w, gx, x_rows);
                }
            };
        second_core::join(
            || half(gp, gw_a, gb_a, &gp[..rows * out], gx_a, &x[..rows * inp]),
            || half(&gp[units..], gw_z, gb_z, &gp[rows * out..], gx_z, &x[rows * inp..]),
        );
    } else {
        let first = d.k / 2;
        let (gw_a, gw_z) = gw.split_at_mut(if need_grad_params { first * out * inp } else { 0 });
        let (gb_a, gb_z) = gb.split_at_mut(if need_grad_params { first * out } else { 0 });
        let (gx_a, gx_z) = gx.split_at_mut(first * gx_len);
        second_core::join(|| members(0, first, gw_a, gb_a, gx_a), || members(first, d.k - first, gw_z, gb_z, gx_z));
    }
    if need_grad_x && d.shared_x && d.k > 1 {
        sum_members_into_first(path, gx, gx_len);
    }
}

/// The members' gradients of a shared input (`len` values each, one after another) summed into
/// the first: member 0 + member 1 + ..., in that order.
fn sum_members_into_first(path: KernelPath, gx: &mut [f32], len: usize) {
    let (total, rest) = gx.split_at_mut(len);
    for member in rest.chunks_exact(len) {
        let total = &mut *total;
        wide(path, move || total.iter_mut().zip(member).for_each(|(t, m)| *t += m));
    }
}

/// Whether a stack of layers with these dims is cut in two halves (see [`stack_forward`]).
pub(super) fn split_stack(ds: &[Dims]) -> bool {
    let macs: usize = ds.iter().map(|d| d.k * d.n * d.inp * d.out).sum();
    macs >= SPLIT_MACS && (ds[0].k >= 2 || ds[0].n >= 2)
}

/// Gradient buffers of a stack's backward pass, one entry per layer: `gw [k, out, in]` and
/// `gb [k, out]` (empty when the weights are constant), and `gx [k, n, in]`, the gradient of
/// the layer's input, before the ReLU that made it for layers after the first (the first
/// layer's is empty when the stack's input needs none).
pub(super) struct StackGrads<'a> {
    pub(super) gw: Vec<&'a mut [f32]>,
    pub(super) gb: Vec<&'a mut [f32]>,
    pub(super) gx: Vec<&'a mut [f32]>,
}

/// `g` through the ReLU whose output is `x` (zero where x is not positive): the same select as
/// `gradient_before`.
fn relu_mask(path: KernelPath, g: &mut [f32], x: &[f32]) {
    wide(path, move || g.iter_mut().zip(x).for_each(|(g, x)| *g = if *x > 0.0 { *g } else { 0.0 }));
}

/// Each layer's buffer cut in two at `at(l)` values (an empty one stays empty).
fn cut<'b>(parts: &'b mut [&mut [f32]], at: impl Fn(usize) -> usize) -> [Vec<&'b mut [f32]>; 2] {
    let (a, z) = parts.iter_mut().enumerate().map(|(l, p)| p.split_at_mut(at(l).min(p.len()))).unzip();
    [a, z]
}

/// The backward pass of one network (k = 1) from `g_out [n, out]`, the gradient of the last
/// layer's output; `xs[l]` is layer l's input. First every layer's input gradient, rows of the
/// batch being independent all the way down; then every layer's weight gradients, output units
/// being independent. A large stack runs each of the two in halves (rows, then units), with one
/// hand-off to the helper thread each. Each product is [`layer_backward`]'s, so are the bits.
pub(super) fn rows_stack_backward(
    path: KernelPath,
    ds: &[Dims],
    xs: &[&[f32]],
    ws: &[&[f32]],
    g_out: &[f32],
    grads: StackGrads<'_>,
) {
    assert!(ds[0].k == 1, "rows_stack_backward is for one network");
    let StackGrads { mut gw, mut gb, mut gx } = grads;
    let layers = ds.len();
    let split = split_stack(ds);
    let n = ds[0].n;
    let rows = if split { n / 2 } else { n };
    {
        let [mut gx_a, mut gx_z] = cut(&mut gx, |l| rows * ds[l].inp);
        let chain = |r0: usize, gx: &mut [&mut [f32]]| {
            for l in (0..layers).rev() {
                let d = &ds[l];
                let (below, above) = gx.split_at_mut(l + 1);
                let gx = &mut *below[l];
                if gx.is_empty() {
                    continue;
                }
                let count = gx.len() / d.inp;
                let gp = if l + 1 == layers { &g_out[r0 * d.out..(r0 + count) * d.out] } else { &*above[0] };
                input_grad(path, gp, ws[l], gx, d.inp, d.out);
                if l > 0 {
                    relu_mask(path, gx, &xs[l][r0 * d.inp..(r0 + count) * d.inp]);
                }
            }
        };
        if split {
            second_core::join(|| chain(0, &mut gx_a), || chain(rows, &mut gx_z));
        } else {
            chain(0, &mut gx_a);
        }
    }
    if gw.iter().all(|g| g.is_empty()) {
        return;
    }
    // gradient of each layer's output before its activation
    let gps: Vec<&[f32]> = (0..layers).map(|l| if l + 1 == layers { g_out } else { &*gx[l + 1] }).collect();
    let units = |l: usize| if split { ds[l].out / 2 } else { ds[l].out };
    let [mut gw_a, mut gw_z] = cut(&mut gw, |l| units(l) * ds[l].inp);
    let [mut gb_a, mut gb_z] = cut(&mut gb, units);
    let weights = |first_unit: &dyn Fn(usize) -> usize, gw: &mut [&mut [f32]], gb: &mut [&mut [f32]]| {
        for (l, d) in ds.iter().enumerate() {
            if !gb[l].is_empty() {
                weight_grads(path, &gps[l][first_unit(l)..], d.out, xs[l], gw[l], gb[l], d.n, d.inp);
            }
        }
    };
    if split {
        second_core::join(|| weights(&|_| 0, &mut gw_a, &mut gb_a), || weights(&units, &mut gw_z, &mut gb_z));
    } else {
        weights(&|_| 0, &mut gw_a, &mut gb_a);
    }
}

/// The backward pass of stacked networks (k >= 2) from `g_out [k, n, out]`, the gradient of the
/// last layer's output, down to the first layer, member by member; `xs[l]` is layer l's input
/// (`x` shared or `[k, n, in]`, then the hidden outputs). Large stacks run in two halves of the
/// members with one hand-off to the helper thread. Each member's arithmetic is
/// [`layer_backward`]'s, and a shared input's gradient is the same sum, member 0 first.
pub(super) fn members_stack_backward(
    path: KernelPath,
    ds: &[Dims],
    xs: &[&[f32]],
    ws: &[&[f32]],
    g_out: &[f32],
    grads: StackGrads<'_>,
) {
    let d0 = &ds[0];
    assert!(d0.k >= 2, "members_stack_backward is for stacked networks");
    let StackGrads { mut gw, mut gb, mut gx } = grads;
    if !split_stack(ds) {
        members_backward(path, ds, xs, ws, g_out, &mut gw, &mut gb, &mut gx, 0, d0.k);
    } else {
        let first = d0.k / 2;
        let [mut gw_a, mut gw_z] = cut(&mut gw, |l| first * ds[l].out * ds[l].inp);
        let [mut gb_a, mut gb_z] = cut(&mut gb, |l| first * ds[l].out);
        let [mut gx_a, mut gx_z] = cut(&mut gx, |l| first * ds[l].n * ds[l].inp);
        second_core::join(
            || members_backward(path, ds, xs, ws, g_out, &mut gw_a, &mut gb_a, &mut gx_a, 0, first),
            || members_backward(path, ds, xs, ws, g_out, &mut gw_z, &mut gb_z, &mut gx_z, first, d0.k - first),
        );
    }
    if d0.shared_x && !gx[0].is_empty() {
        sum_members_into_first(path, gx[0], d0.n * d0.inp);
    }
}

/// Members `g0..g0 + count` of [`members_stack_backward`], whose blocks `gw`, `gb` and `gx` hold.
#[allow(clippy::too_many_arguments)]
fn members_backward(
    path: KernelPath,
    ds: &[Dims],
    xs: &[&[f32]],
    ws: &[&[f32]],
    g_out: &[f32],
    gw: &mut [&mut [f32]],
    gb: &mut [&mut [f32]],
    gx: &mut [&mut [f32]],
    g0: usize,
    count: usize,
) {
    let layers = ds.len();
    for l in (0..layers).rev() {
        let d = &ds[l];
        let (n, inp, out) = (d.n, d.inp, d.out);
        let (below, above) = gx.split_at_mut(l + 1);
        for i in 0..count {
            let g = g0 + i;
            let gp = if l + 1 == layers {
                &g_out[g * n * out..(g + 1) * n * out]
            } else {
                &above[0][i * n * out..(i + 1) * n * out]
            };
            let x = if l == 0 { &xs[0][d.x_range(g)] } else { &xs[l][g * n * inp..(g + 1) * n * inp] };
            if !gw[l].is_empty() {
                let gw = &mut gw[l][i * out * inp..(i + 1) * out * inp];
                let gb = &mut gb[l][i * out..(i + 1) * out];
                weight_grads(path, gp, out, x, gw, gb, n, inp);
            }
            if !below[l].is_empty() {
                let gx = &mut below[l][i * n * inp..(i + 1) * n * inp];
                input_grad(path, gp, &ws[l][g * out * inp..(g + 1) * out * inp], gx, inp, out);
                if l > 0 {
                    relu_mask(path, gx, x);
                }
            }
        }
    }
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
        layer_forward(self.path, &d, x, w, b, self.act, &mut y);
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
        // weights held constant (an actor loss through frozen critics) need none either
        let need_grad_params = w.track_op() || b.track_op();
        let grad = grad.contiguous()?;
        let (xs, xl) = x.storage_and_layout();
        let (ws, wl) = w.storage_and_layout();
        let (ys, yl) = y.storage_and_layout();
        let (gs, gl) = grad.storage_and_layout();
        let (xv, wv, yv) =
            (cpu_contiguous(&xs, xl, "dense")?, cpu_contiguous(&ws, wl, "dense")?, cpu_contiguous(&ys, yl, "dense")?);
        let gv = cpu_contiguous(&gs, gl, "dense")?;
        let gp = gradient_before(self.act, gv, yv);
        let mut gw = vec![0f32; if need_grad_params { d.k * d.out * d.inp } else { 0 }];
        let mut gb = vec![0f32; if need_grad_params { d.k * d.out } else { 0 }];
        let mut gx = vec![0f32; if need_grad_x { d.k * d.n * d.inp } else { 0 }];
        layer_backward(
            self.path,
            &d,
            xv,
            wv,
            &gp,
            need_grad_params.then_some((gw.as_mut_slice(), gb.as_mut_slice())),
            need_grad_x.then_some(gx.as_mut_slice()),
            false,
        );
        drop((xs, ws, ys, gs));
        let dev = x.device();
        gx.truncate(if d.shared_x { d.n * d.inp } else { d.k * d.n * d.inp });
        let grad_x = if need_grad_x { Some(Tensor::from_vec(gx, x.shape(), dev)?) } else { None };
        let (grad_w, grad_b) = if need_grad_params {
            (Some(Tensor::from_vec(gw, w.shape(), dev)?), Some(Tensor::from_vec(gb, b.shape(), dev)?))
        } else {
            (None, None)
        };
        Ok((grad_x, grad_w, grad_b))
    }
}

/// The gradient before the activation, from the gradient `g` of the output `y` (a select, not a
/// branch, so that it vectorises).
fn gradient_before(act: Activation, g: &[f32], y: &[f32]) -> Vec<f32> {
    match act {
        Activation::Identity => g.to_vec(),
        Activation::Relu => g.iter().zip(y).map(|(g, y)| if *y > 0.0 { *g } else { 0.0 }).collect(),
    }
}

/// `act(x W^T + b)`: x `[n, in]` with w `[out, in]`, b `[out]` (one network), or w `[k, out, in]`,
/// b `[k, 1, out]` with x `[k, n, in]` or a shared `[n, in]` (k stacked networks, output `[k, n, out]`).
pub fn dense(x: &Tensor, w: &Tensor, b: &Tensor, act: Activation) -> Result<Tensor> {
    x.contiguous()?.apply_op3(&w.contiguous()?, &b.contiguous()?, Dense { act, path: kernel_path::active() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use candle_core::{Device, Var, D};

    fn values(n: usize, seed: f32) -> Vec<f32> {
        (0..n).map(|i| (i as f32 * 0.37 + seed).sin()).collect()
    }

    type Case = (&'static [usize], &'static [usize], &'static [usize]);

    /// x, w, b shapes: one network, k stacked with their own inputs, k sharing one input; small
    /// (one piece) and large enough to be split in two.
    const CASES: [Case; 6] = [
        (&[5, 3], &[4, 3], &[4]),
        (&[2, 5, 3], &[2, 4, 3], &[2, 1, 4]),
        (&[5, 3], &[2, 4, 3], &[2, 1, 4]),
        (&[65, 70], &[301, 70], &[301]),
        (&[2, 64, 40], &[2, 300, 40], &[2, 1, 300]),
        (&[64, 40], &[2, 300, 40], &[2, 1, 300]),
    ];

    fn var(shape: &[usize], seed: f32) -> Var {
        let dev = Device::Cpu;
        Var::from_tensor(&Tensor::from_vec(values(shape.iter().product(), seed), shape, &dev).unwrap()).unwrap()
    }

    fn flat(t: &Tensor) -> Vec<f32> {
        t.flatten_all().unwrap().to_vec1::<f32>().unwrap()
    }

    fn out_shape(xs: &[usize], ws: &[usize]) -> Vec<usize> {
        if ws.len() == 2 {
            vec![xs[0], ws[0]]
        } else {
            vec![ws[0], xs[xs.len() - 2], ws[1]]
        }
    }

    /// Output and the gradients of x, W and b of `sum(dense(x, W, b) * probe)`.
    fn run(case: Case, act: Activation) -> Vec<Vec<f32>> {
        let (xs, ws, bs) = case;
        let (x, w, b) = (var(xs, 0.1), var(ws, 0.7), var(bs, 1.9));
        let shape = out_shape(xs, ws);
        let probe = Tensor::from_vec(values(shape.iter().product(), 2.3), shape, &Device::Cpu).unwrap();
        let y = dense(x.as_tensor(), w.as_tensor(), b.as_tensor(), act).unwrap();
        let grads = (&y * &probe).unwrap().sum_all().unwrap().backward().unwrap();
        let mut out = vec![flat(&y)];
        out.extend([&x, &w, &b].iter().map(|v| flat(grads.get(v.as_tensor()).unwrap())));
        out
    }

    /// Value and gradients of x, W and b equal candle's matmul + broadcast add + ReLU.
    #[test]
    fn dense_matches_candle_ops_for_one_and_stacked_networks() {
        for case in CASES {
            let (xs, ws, bs) = case;
            for act in [Activation::Identity, Activation::Relu] {
                let (x, w, b) = (var(xs, 0.1), var(ws, 0.7), var(bs, 1.9));
                let shape = out_shape(xs, ws);
                let probe = Tensor::from_vec(values(shape.iter().product(), 2.3), shape, &Device::Cpu).unwrap();
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
                let g_ref = (&reference * &probe).unwrap().sum_all().unwrap().backward().unwrap();
                let mut expected = vec![flat(&reference)];
                expected.extend([&x, &w, &b].iter().map(|v| flat(g_ref.get(v.as_tensor()).unwrap())));
                let ours = run(case, act);
                for (what, (a, e)) in ["y", "dx", "dw", "db"].iter().zip(ours.iter().zip(&expected)) {
                    assert_eq!(a.len(), e.len(), "{xs:?} {act:?} {what}");
                    for (a, e) in a.iter().zip(e) {
                        assert!((a - e).abs() <= 1e-4 * (1.0 + e.abs()), "{xs:?} {act:?} {what}: {a} vs {e}");
                    }
                }
            }
        }
        let zeros = |shape: &[usize]| Tensor::zeros(shape, candle_core::DType::F32, &Device::Cpu).unwrap();
        assert!(dense(&zeros(&[5, 3]), &zeros(&[4, 2]), &zeros(&[4]), Activation::Relu).is_err());
        assert!(dense(&zeros(&[5, 3]), &zeros(&[4, 3]), &zeros(&[3]), Activation::Relu).is_err());
    }

    /// Every exact kernel path gives the same output and gradients, bit for bit.
    #[test]
    fn every_exact_kernel_path_gives_the_same_layer() {
        let on = |path: KernelPath| {
            let _forced = kernel_path::force_on_this_thread(path).unwrap();
            let act = [Activation::Identity, Activation::Relu];
            CASES.iter().flat_map(|c| act.map(|a| run(*c, a))).collect::<Vec<_>>()
        };
        let portable = on(KernelPath::Portable);
        for path in KernelPath::ALL.into_iter().filter(|p| p.is_exact() && p.is_supported()) {
            assert_eq!(on(path), portable, "{path}");
        }
    }

    /// The halves of a split layer give the same bits whichever thread runs them.
    #[test]
    fn a_helper_thread_changes_no_bit() {
        let all = |helper: bool| {
            std::thread::spawn(move || {
                if helper {
                    second_core::enable_on_this_thread();
                }
                let act = [Activation::Identity, Activation::Relu];
                CASES.iter().flat_map(|c| act.map(|a| run(*c, a))).collect::<Vec<_>>()
            })
            .join()
            .unwrap()
        };
        assert_eq!(all(false), all(true));
    }

    /// Weights held constant: the input gradient is unchanged and no weight gradient is made.
    #[test]
    fn frozen_weights_pass_the_input_gradient_and_get_none() {
        second_core::with_and_without_helper(|_| {
            for case in CASES {
                let (xs, ws, bs) = case;
                for act in [Activation::Identity, Activation::Relu] {
                    let trained = run(case, act);
                    let (x, w, b) = (var(xs, 0.1), var(ws, 0.7), var(bs, 1.9));
                    let shape = out_shape(xs, ws);
                    let probe = Tensor::from_vec(values(shape.iter().product(), 2.3), shape, &Device::Cpu).unwrap();
                    let (w, b) = (w.as_tensor().detach(), b.as_tensor().detach());
                    let y = dense(x.as_tensor(), &w, &b, act).unwrap();
                    let grads = (&y * &probe).unwrap().sum_all().unwrap().backward().unwrap();
                    assert_eq!(flat(&y), trained[0], "{xs:?} {act:?}");
                    assert_eq!(flat(grads.get(x.as_tensor()).unwrap()), trained[1], "{xs:?} {act:?}");
                    // (candle would store a gradient for the detached tensors had one been made)
                    assert!(grads.get(&w).is_none() && grads.get(&b).is_none(), "{xs:?} {act:?}");
                }
            }
        });
    }
}
