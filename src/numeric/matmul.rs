//! `C (+)= A B` in one fixed order of operations, whatever the vector width.
//!
//! Every output element starts from its old value (or zero) and takes one fused multiply-add per
//! term, `c = fma(a[i][p], b[p][j], c)` for `p = 0, 1, ..., k-1`, in that order. The vector paths
//! compute 16 (AVX-512) or 8 (AVX2) neighbouring elements of a row at once, each lane doing
//! exactly that sequence, and the portable path one element at a time with `f32::mul_add`; an
//! IEEE fused multiply-add rounds once, so all three give the same bits on every CPU. Nothing is
//! summed across lanes, and partial sums are never added to each other.
//!
//! The loops are those of Goto and van de Geijn ("Anatomy of High-Performance Matrix
//! Multiplication", ACM TOMS 34(3), 2008): `k` is cut into chunks of [`K_CHUNK`] terms, a chunk of
//! B is packed into column panels so that the innermost loop reads its vectors from one
//! contiguous stream in L1 (a row-major B of a product with one or two row tiles is read where
//! it lies, `DIRECT_B_TILES`), and a register tile (8 rows by three vectors with AVX-512, 6 rows
//! by two with AVX2) takes one chunk at a time. A is not packed: each term of a tile needs only one
//! broadcast element per row, which the tile reads where it lies (packing A measured at a sixth of
//! a TD3 update, mostly in per-term copies of a few floats). Cutting `k` keeps the order exact because a tile carries its partial
//! result into the next chunk through C (a stored f32 is the value itself), rather than summing
//! chunks computed from zero as BLAS libraries do. The `gemm` crate remains available as
//! [`KernelPath::Library`] and is the reference the tests compare with.
use std::cell::RefCell;

use super::kernel_path::KernelPath;

/// A matrix read through strides: element (i, j) is `data[i * row_stride + j * col_stride]`.
#[derive(Clone, Copy)]
pub struct Strided<'a> {
    /// The elements.
    pub data: &'a [f32],
    /// Distance between consecutive rows.
    pub row_stride: usize,
    /// Distance between consecutive columns.
    pub col_stride: usize,
}

impl<'a> Strided<'a> {
    /// A row-major matrix with `cols` columns.
    pub fn rows(data: &'a [f32], cols: usize) -> Strided<'a> {
        Strided { data, row_stride: cols, col_stride: 1 }
    }

    /// The transpose of a row-major matrix with `cols` columns.
    pub fn transposed(data: &'a [f32], cols: usize) -> Strided<'a> {
        Strided { data, row_stride: 1, col_stride: cols }
    }

    /// The same elements read as the transpose.
    pub fn transpose(self) -> Strided<'a> {
        Strided { data: self.data, row_stride: self.col_stride, col_stride: self.row_stride }
    }

    fn holds(&self, rows: usize, cols: usize) -> bool {
        rows == 0 || cols == 0 || self.data.len() > (rows - 1) * self.row_stride + (cols - 1) * self.col_stride
    }
}

/// `dst [m x n] (+)= a [m x k] * b [k x n]` on `path`; `dst` is row-major with row stride
/// `dst_stride`; with `accumulate` false its old values are ignored.
///
/// # Panics
/// When a slice is too short for the sizes and strides, or `path` is not supported here.
#[allow(clippy::too_many_arguments)]
pub fn matmul(
    path: KernelPath,
    dims: (usize, usize, usize),
    dst: &mut [f32],
    dst_stride: usize,
    accumulate: bool,
    a: Strided,
    b: Strided,
) {
    let start = if accumulate { Start::Dst } else { Start::Zero };
    product(path, dims, dst, dst_stride, start, false, a, b)
}

/// A dense layer's product: `dst [m x n] = act(bias + a [m x k] * b [k x n])` with `bias` (n
/// values) added to every row first and `act` ReLU (`x > 0 ? x : 0`) when `relu`. The same bits as
/// filling `dst` with the bias, [`matmul`] accumulating onto it, and applying the ReLU after; the
/// vector paths start their registers from the bias and apply the ReLU as they store, instead of
/// passing over `dst` twice more.
///
/// # Panics
/// As [`matmul`], and when `bias` does not hold n values.
#[allow(clippy::too_many_arguments)]
pub fn matmul_bias(
    path: KernelPath,
    dims: (usize, usize, usize),
    dst: &mut [f32],
    dst_stride: usize,
    bias: &[f32],
    relu: bool,
    a: Strided,
    b: Strided,
) {
    assert_eq!(bias.len(), dims.1, "matmul: the bias needs one value per column");
    product(path, dims, dst, dst_stride, Start::Row(bias), relu, a, b)
}

/// The ReLU every path applies: a select, so that -0 and NaN give +0 everywhere.
#[inline]
pub fn relu_of(v: f32) -> f32 {
    if v > 0.0 {
        v
    } else {
        0.0
    }
}

/// What a product's output starts from: zero, dst's old values, or a row (the bias) repeated.
#[derive(Clone, Copy)]
enum Start<'a> {
    Zero,
    Dst,
    Row(&'a [f32]),
}

#[allow(clippy::too_many_arguments)]
fn product(
    path: KernelPath,
    (m, n, k): (usize, usize, usize),
    dst: &mut [f32],
    dst_stride: usize,
    start: Start,
    relu: bool,
    a: Strided,
    b: Strided,
) {
    debug_assert!(!relu || matches!(start, Start::Row(_)), "the ReLU comes with a start row");
    assert!(m == 0 || n == 0 || dst.len() >= (m - 1) * dst_stride + n, "matmul: destination too short");
    assert!(a.holds(m, k) && b.holds(k, n), "matmul: operand too short for {m}x{k} * {k}x{n}");
    if m == 0 || n == 0 {
        return;
    }
    if let Start::Row(bias) = start {
        if path == KernelPath::Library || k == 0 || (n == 1 && m > 1 && dst_stride == 1) {
            // The library takes no start row, k = 0 has no tile to start, and a single column is
            // computed as its transpose below, whose rows would need the bias value repeated:
            // write the bias rows, accumulate onto them, and apply the ReLU after (the same bits).
            dst.chunks_mut(dst_stride).take(m).for_each(|row| row[..n].copy_from_slice(bias));
            product(path, (m, n, k), dst, dst_stride, Start::Dst, false, a, b);
            if relu {
                dst.chunks_mut(dst_stride).take(m).for_each(|row| row[..n].iter_mut().for_each(|v| *v = relu_of(*v)));
            }
            return;
        }
    }
    let accumulate = matches!(start, Start::Dst);
    if path == KernelPath::Library {
        // SAFETY: the asserts above bound every element the strides address.
        unsafe { library(m, n, k, dst, dst_stride, accumulate, a, b) };
        return;
    }
    assert!(path.is_supported(), "matmul: the {path} kernels need CPU features this machine lacks");
    if n == 1 && m > 1 && dst_stride == 1 {
        // One output column (a critic's value layer) would fill one lane of each vector; its
        // transpose C^T = B^T A^T is one row of m outputs across full vectors. Each element
        // takes the same products (b * a = a * b exactly) in the same order: the same bits.
        return matmul(path, (1, m, k), dst, m, accumulate, b.transpose(), a.transpose());
    }
    let (tile, Geometry { tile_rows, panel }): (TileKernel, Geometry) = match path {
        #[cfg(target_arch = "x86_64")]
        KernelPath::Avx512 => (avx512::tile, avx512::GEOMETRY),
        #[cfg(target_arch = "x86_64")]
        KernelPath::Avx2 => (avx2::tile, avx2::GEOMETRY),
        _ => (portable_tile, PORTABLE),
    };
    if k == 0 {
        if !accumulate {
            dst.chunks_mut(dst_stride).take(m).for_each(|row| row[..n].fill(0.0));
        }
        return;
    }
    let direct = b.col_stride == 1 && m <= DIRECT_B_TILES * tile_rows;
    SCRATCH.with(|scratch| {
        let b_pack = &mut *scratch.borrow_mut();
        for p0 in (0..k).step_by(K_CHUNK) {
            let kc = K_CHUNK.min(k - p0);
            let last_chunk = p0 + kc == k;
            for j0 in (0..n).step_by(panel) {
                let cols = panel.min(n - j0);
                let b_tile = if direct {
                    (b.data[p0 * b.row_stride + j0..].as_ptr(), b.row_stride)
                } else {
                    pack_b(b, p0, kc, j0, cols, panel, path != KernelPath::Portable, b_pack);
                    (b_pack.as_ptr(), panel)
                };
                let tile_start = match start {
                    _ if p0 > 0 => TileStart::C,
                    Start::Zero => TileStart::Zero,
                    Start::Dst => TileStart::C,
                    Start::Row(bias) => TileStart::Row(bias[j0..].as_ptr()),
                };
                for i0 in (0..m).step_by(tile_rows) {
                    let rows = tile_rows.min(m - i0);
                    let c = &mut dst[i0 * dst_stride + j0..];
                    assert!(c.len() >= (rows - 1) * dst_stride + cols);
                    // A is read where it lies: rows i0.., terms p0.. (within bounds by `holds`).
                    let a_tile = a.data[i0 * a.row_stride + p0 * a.col_stride..].as_ptr();
                    // SAFETY: the CPU has the path's features (asserted above); A holds rows
                    // i0..i0+rows and terms p0..p0+kc at its strides (`holds`), B kc terms of
                    // `cols` columns at its stride (the packed panel, or B itself, which holds
                    // terms p0..p0+kc of columns j0..j0+cols by `holds`), c `rows` rows of `cols`
                    // elements at `dst_stride` (asserted), and a bias row `cols` values from j0.
                    unsafe {
                        tile(
                            Tile { rows, cols, kc },
                            (a_tile, a.row_stride, a.col_stride),
                            b_tile,
                            (c.as_mut_ptr(), dst_stride),
                            tile_start,
                            relu && last_chunk,
                        )
                    };
                }
            }
        }
    });
}

/// Terms per chunk of k: AVX-512's 48-column panel of B is then 24 KB, half a 48 KB L1 data cache
/// (128 measured faster than 192 and 256 on the TD3 products, `cargo bench --bench throughput --
/// --matmul`).
const K_CHUNK: usize = 128;

/// Products of at most this many row tiles read a row-major B unpacked: a packed panel would be
/// read only once or twice (a value layer's weight gradient has one row; measured 3x faster).
const DIRECT_B_TILES: usize = 2;

/// A path's register tile: `tile_rows` rows of A (read where they lie) by `panel` columns (a
/// packed column panel of B, whole vectors).
#[derive(Clone, Copy)]
struct Geometry {
    tile_rows: usize,
    panel: usize,
}

const PORTABLE: Geometry = Geometry { tile_rows: 6, panel: 16 };

thread_local! {
    /// The packed column panel of B, reused between calls.
    static SCRATCH: RefCell<Vec<f32>> = const { RefCell::new(Vec::new()) };
}

/// Terms p0..p0+kc of columns j0..j0+cols of B, row by row, `panel` wide (zeros past cols).
/// `avx`: the CPU has AVX (every vector path), so a transposed weight is packed by 8 x 8 blocks
/// in registers; the packed values are the same either way.
#[allow(clippy::too_many_arguments)]
fn pack_b(b: Strided, p0: usize, kc: usize, j0: usize, cols: usize, panel: usize, avx: bool, out: &mut Vec<f32>) {
    // every element is written below, so the buffer is only resized, not cleared
    out.resize(kc * panel, 0.0);
    if cols < panel {
        out.chunks_exact_mut(panel).for_each(|row| row[cols..].fill(0.0));
    }
    if b.col_stride == 1 {
        for (p, row) in out.chunks_exact_mut(panel).enumerate() {
            let start = (p0 + p) * b.row_stride + j0;
            copy_short(&mut row[..cols], &b.data[start..start + cols]);
        }
        return;
    }
    // A transposed weight: each packed row gathers one term of `cols` weight rows.
    let last = (j0 + cols - 1) * b.col_stride + (p0 + kc - 1) * b.row_stride;
    assert!(last < b.data.len());
    let (mut j_done, mut p_done) = (0, 0);
    #[cfg(target_arch = "x86_64")]
    if avx && b.row_stride == 1 {
        (j_done, p_done) = (cols / 8 * 8, kc / 8 * 8);
        // SAFETY: the caller's path implies AVX; every element read is at most `last` (asserted)
        // and every write is inside `out` (kc rows of `panel`).
        unsafe {
            transpose_blocks(b.data.as_ptr().add(j0 * b.col_stride + p0), b.col_stride, j_done, p_done, panel, out)
        };
    }
    // whatever the blocks left: columns past j_done for every term, terms past p_done below it
    for (p, row) in out.chunks_exact_mut(panel).enumerate() {
        let base = (p0 + p) * b.row_stride + j0 * b.col_stride;
        let first = if p < p_done { j_done } else { 0 };
        for (j, dst) in row[..cols].iter_mut().enumerate().skip(first) {
            // SAFETY: base + j * col_stride <= last < len (asserted above).
            *dst = unsafe { *b.data.get_unchecked(base + j * b.col_stride) };
        }
    }
}

/// `dst.copy_from_slice(src)` for a few dozen floats, in 16-float pieces the compiler copies
/// inline: as a `memcpy` call per panel row, packing cost about 4% of a SAC update.
#[inline]
fn copy_short(dst: &mut [f32], src: &[f32]) {
    let mut d = dst.chunks_exact_mut(16);
    let mut s = src.chunks_exact(16);
    for (d, s) in d.by_ref().zip(s.by_ref()) {
        d.copy_from_slice(s);
    }
    for (d, s) in d.into_remainder().iter_mut().zip(s.remainder()) {
        *d = *s;
    }
}

/// `out[p * panel + j] = src[j * stride + p]` for `j < cols`, `p < terms`, both multiples of 8:
/// 8 rows of 8 terms loaded, transposed in registers, stored as 8 rows of the panel.
///
/// # Safety
/// The CPU has AVX; src holds `cols` rows of `terms` at `stride`; out holds `terms` rows of `panel`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn transpose_blocks(src: *const f32, stride: usize, cols: usize, terms: usize, panel: usize, out: &mut [f32]) {
    use std::arch::x86_64::*;
    let dst = out.as_mut_ptr();
    // SAFETY: (whole body) within the bounds the caller guarantees.
    unsafe {
        for j in (0..cols).step_by(8) {
            for p in (0..terms).step_by(8) {
                let row = |i: usize| _mm256_loadu_ps(src.add((j + i) * stride + p));
                let (r0, r1, r2, r3, r4, r5, r6, r7) = (row(0), row(1), row(2), row(3), row(4), row(5), row(6), row(7));
                let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
                let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
                let (t4, t5) = (_mm256_unpacklo_ps(r4, r5), _mm256_unpackhi_ps(r4, r5));
                let (t6, t7) = (_mm256_unpacklo_ps(r6, r7), _mm256_unpackhi_ps(r6, r7));
                let (u0, u1) = (_mm256_shuffle_ps::<0x44>(t0, t2), _mm256_shuffle_ps::<0xEE>(t0, t2));
                let (u2, u3) = (_mm256_shuffle_ps::<0x44>(t1, t3), _mm256_shuffle_ps::<0xEE>(t1, t3));
                let (u4, u5) = (_mm256_shuffle_ps::<0x44>(t4, t6), _mm256_shuffle_ps::<0xEE>(t4, t6));
                let (u6, u7) = (_mm256_shuffle_ps::<0x44>(t5, t7), _mm256_shuffle_ps::<0xEE>(t5, t7));
                let columns = [
                    _mm256_permute2f128_ps::<0x20>(u0, u4),
                    _mm256_permute2f128_ps::<0x20>(u1, u5),
                    _mm256_permute2f128_ps::<0x20>(u2, u6),
                    _mm256_permute2f128_ps::<0x20>(u3, u7),
                    _mm256_permute2f128_ps::<0x31>(u0, u4),
                    _mm256_permute2f128_ps::<0x31>(u1, u5),
                    _mm256_permute2f128_ps::<0x31>(u2, u6),
                    _mm256_permute2f128_ps::<0x31>(u3, u7),
                ];
                for (i, column) in columns.into_iter().enumerate() {
                    _mm256_storeu_ps(dst.add((p + i) * panel + j), column);
                }
            }
        }
    }
}

/// The sizes of one register tile's work: `rows` rows of C (at most the path's tile rows) by
/// `cols` columns (at most its panel), over `kc` terms.
#[derive(Clone, Copy)]
struct Tile {
    rows: usize,
    cols: usize,
    kc: usize,
}

/// A tile's A operand where it lies: element (r, p) at `ptr + r * row_stride + p * col_stride`.
type TileA = (*const f32, usize, usize);

/// What a tile's registers start from: zero, C's values, or a row (`cols` values) in every row.
#[derive(Clone, Copy)]
enum TileStart {
    Zero,
    C,
    Row(*const f32),
}

/// Adds `kc` terms of A times B (pointer and distance between terms: a packed panel, or B where it
/// lies) to `rows x cols` of C (pointer and row stride), starting from `TileStart`, and stores
/// them through the ReLU when the flag is set. Only B's first `cols` values of each term are read.
type TileKernel = unsafe fn(Tile, TileA, (*const f32, usize), (*mut f32, usize), TileStart, bool);

/// One element at a time, in the order every path follows.
///
/// SAFETY (caller): as for [`TileKernel`]: A and B hold kc terms, C its tile.
unsafe fn portable_tile(
    Tile { rows, cols, kc }: Tile,
    (a, a_rs, a_cs): TileA,
    (b, b_stride): (*const f32, usize),
    (c, c_stride): (*mut f32, usize),
    start: TileStart,
    relu: bool,
) {
    // SAFETY: forwarded from the caller.
    unsafe {
        for r in 0..rows {
            for j in 0..cols {
                let out = c.add(r * c_stride + j);
                let mut acc = match start {
                    TileStart::Zero => 0.0,
                    TileStart::C => *out,
                    TileStart::Row(row) => *row.add(j),
                };
                for p in 0..kc {
                    acc = (*a.add(r * a_rs + p * a_cs)).mul_add(*b.add(p * b_stride + j), acc);
                }
                *out = if relu { relu_of(acc) } else { acc };
            }
        }
    }
}

/// One vector kernel family: `$width` lanes of type `$vec`, C's partial last vector read and
/// written with masks (lanes outside the mask are not accessed).
#[cfg(target_arch = "x86_64")]
macro_rules! vector_kernels {
    ($module:ident, $feature:literal, $width:expr, $tile_rows:expr, $vectors:expr, $vec:ty, $mask:ty, $mask_for:expr, $zero:expr,
     $load:expr, $store:expr, $masked_load:expr, $masked_store:expr, $splat:expr, $fma:expr, $max:expr) => {
        mod $module {
            use std::arch::x86_64::*;

            use super::{Geometry, Tile, TileA, TileStart};

            const W: usize = $width;
            const TILE_ROWS: usize = $tile_rows;
            const PANEL: usize = $vectors * W;
            pub(super) const GEOMETRY: Geometry = Geometry { tile_rows: TILE_ROWS, panel: PANEL };

            /// [`super::TileKernel`] for this family.
            ///
            /// # Safety
            /// The CPU has the features; the operands hold what [`super::TileKernel`] says.
            #[target_feature(enable = $feature)]
            #[allow(clippy::too_many_arguments)]
            pub(super) unsafe fn tile(
                Tile { rows, cols, kc }: Tile,
                a: TileA,
                b: (*const f32, usize),
                c: (*mut f32, usize),
                start: TileStart,
                relu: bool,
            ) {
                let vectors = cols.div_ceil(W);
                let last = cols - (vectors - 1) * W;
                let mask = ($mask_for)(last);
                let full = last == W;
                // SAFETY: forwarded from the caller.
                unsafe {
                    match rows {
                        8 => by_vectors::<8>(vectors, full, kc, a, b, c, start, relu, mask),
                        7 => by_vectors::<7>(vectors, full, kc, a, b, c, start, relu, mask),
                        6 => by_vectors::<6>(vectors, full, kc, a, b, c, start, relu, mask),
                        5 => by_vectors::<5>(vectors, full, kc, a, b, c, start, relu, mask),
                        4 => by_vectors::<4>(vectors, full, kc, a, b, c, start, relu, mask),
                        3 => by_vectors::<3>(vectors, full, kc, a, b, c, start, relu, mask),
                        2 => by_vectors::<2>(vectors, full, kc, a, b, c, start, relu, mask),
                        _ => by_vectors::<1>(vectors, full, kc, a, b, c, start, relu, mask),
                    }
                }
            }

            #[target_feature(enable = $feature)]
            #[allow(clippy::too_many_arguments)]
            unsafe fn by_vectors<const R: usize>(
                vectors: usize,
                full: bool,
                kc: usize,
                a: TileA,
                b: (*const f32, usize),
                c: (*mut f32, usize),
                start: TileStart,
                relu: bool,
                mask: $mask,
            ) {
                // SAFETY: forwarded from `tile`.
                unsafe {
                    match (vectors, full) {
                        (3, true) => rows_tile::<R, 3, true>(kc, a, b, c, start, relu, mask),
                        (3, false) => rows_tile::<R, 3, false>(kc, a, b, c, start, relu, mask),
                        (2, true) => rows_tile::<R, 2, true>(kc, a, b, c, start, relu, mask),
                        (2, false) => rows_tile::<R, 2, false>(kc, a, b, c, start, relu, mask),
                        (_, true) => rows_tile::<R, 1, true>(kc, a, b, c, start, relu, mask),
                        (_, false) => rows_tile::<R, 1, false>(kc, a, b, c, start, relu, mask),
                    }
                }
            }

            /// `R` rows by `V` vectors; C's last vector is masked unless `FULL`.
            #[target_feature(enable = $feature)]
            #[inline]
            #[allow(clippy::too_many_arguments)]
            unsafe fn rows_tile<const R: usize, const V: usize, const FULL: bool>(
                kc: usize,
                (a, a_rs, a_cs): TileA,
                (b, b_stride): (*const f32, usize),
                (c, c_stride): (*mut f32, usize),
                start: TileStart,
                relu: bool,
                mask: $mask,
            ) {
                // SAFETY: (whole body) A holds R rows of kc terms at its strides, B kc terms at
                // `b_stride`, read in lanes inside the mask; C is read and written in rows < R
                // and lanes inside the mask, and a start row holds the tile's columns.
                unsafe {
                    let mut acc: [[$vec; V]; R] = [[$zero; V]; R];
                    let lanes = |p: *const f32, v: usize| {
                        if FULL || v + 1 < V {
                            ($load)(p.add(v * W))
                        } else {
                            ($masked_load)(p.add(v * W), mask)
                        }
                    };
                    match start {
                        TileStart::Zero => {}
                        TileStart::C => {
                            for (r, acc_r) in acc.iter_mut().enumerate() {
                                for (v, acc_rv) in acc_r.iter_mut().enumerate() {
                                    *acc_rv = lanes(c.add(r * c_stride), v);
                                }
                            }
                        }
                        TileStart::Row(row) => {
                            for v in 0..V {
                                let start = lanes(row, v);
                                acc.iter_mut().for_each(|acc_r| acc_r[v] = start);
                            }
                        }
                    }
                    let (mut a, mut b) = (a, b);
                    for _ in 0..kc {
                        // a partial last vector of B: masked, as B may end there (the lanes past
                        // `cols` are zero, as in a packed panel, and never stored)
                        let mut b_vec: [$vec; V] = [$zero; V];
                        for (v, bv) in b_vec.iter_mut().enumerate() {
                            *bv = lanes(b, v);
                        }
                        for (r, acc_r) in acc.iter_mut().enumerate() {
                            let a_r = ($splat)(*a.add(r * a_rs));
                            for (acc_rv, bv) in acc_r.iter_mut().zip(&b_vec) {
                                *acc_rv = ($fma)(a_r, *bv, *acc_rv);
                            }
                        }
                        a = a.add(a_cs);
                        b = b.add(b_stride);
                    }
                    if relu {
                        acc.iter_mut().flatten().for_each(|v| *v = ($max)(*v, $zero));
                    }
                    for (r, acc_r) in acc.iter().enumerate() {
                        let row = c.add(r * c_stride);
                        for (v, acc_rv) in acc_r.iter().enumerate() {
                            if FULL || v + 1 < V {
                                ($store)(row.add(v * W), *acc_rv);
                            } else {
                                ($masked_store)(row.add(v * W), mask, *acc_rv);
                            }
                        }
                    }
                }
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
vector_kernels!(
    avx512,
    "avx512f,fma",
    16,
    8,
    3,
    __m512,
    __mmask16,
    |lanes: usize| if lanes >= 16 { 0xffffu16 } else { ((1u32 << lanes) - 1) as u16 },
    _mm512_setzero_ps(),
    |p: *const f32| _mm512_loadu_ps(p),
    |p: *mut f32, v: __m512| _mm512_storeu_ps(p, v),
    |p: *const f32, m: __mmask16| _mm512_maskz_loadu_ps(m, p),
    |p: *mut f32, m: __mmask16, v: __m512| _mm512_mask_storeu_ps(p, m, v),
    |x: f32| _mm512_set1_ps(x),
    |a: __m512, b: __m512, c: __m512| _mm512_fmadd_ps(a, b, c),
    // max(v, 0) returns its second operand when v is NaN or either zero: v > 0 ? v : +0
    |v: __m512, zero: __m512| _mm512_max_ps(v, zero)
);

#[cfg(target_arch = "x86_64")]
vector_kernels!(
    avx2,
    "avx2,fma",
    8,
    6,
    2,
    __m256,
    __m256i,
    |lanes: usize| _mm256_cmpgt_epi32(_mm256_set1_epi32(lanes as i32), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7)),
    _mm256_setzero_ps(),
    |p: *const f32| _mm256_loadu_ps(p),
    |p: *mut f32, v: __m256| _mm256_storeu_ps(p, v),
    |p: *const f32, m: __m256i| _mm256_maskload_ps(p, m),
    |p: *mut f32, m: __m256i, v: __m256| _mm256_maskstore_ps(p, m, v),
    |x: f32| _mm256_set1_ps(x),
    |a: __m256, b: __m256, c: __m256| _mm256_fmadd_ps(a, b, c),
    |v: __m256, zero: __m256| _mm256_max_ps(v, zero)
);

/// The `gemm` crate, as candle calls it, on one thread.
///
/// SAFETY (caller): each slice holds every element its strides and sizes address.
#[allow(clippy::too_many_arguments)]
unsafe fn library(
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    dst_stride: usize,
    accumulate: bool,
    a: Strided,
    b: Strided,
) {
    // SAFETY: forwarded from the caller.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            dst_stride as isize,
            accumulate,
            a.data.as_ptr(),
            a.col_stride as isize,
            a.row_stride as isize,
            b.data.as_ptr(),
            b.col_stride as isize,
            b.row_stride as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            gemm::Parallelism::None,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn values(n: usize, seed: f32) -> Vec<f32> {
        (0..n).map(|i| ((i as f32 * 0.37 + seed).sin() * 3.0).tan().clamp(-50.0, 50.0)).collect()
    }

    /// Every shape class the kernels branch on: full and partial tiles in rows and vector
    /// columns, a single row (acting), k = 0 and 1, and the network sizes.
    const SHAPES: [(usize, usize, usize); 12] = [
        (1, 1, 1),
        (1, 300, 400),
        (5, 3, 7),
        (6, 16, 9),
        (7, 17, 3),
        (13, 33, 20),
        (12, 8, 1),
        (4, 5, 0),
        (64, 40, 23),
        (256, 300, 400),
        (300, 23, 256),
        (257, 31, 6),
    ];

    /// The operands of an m x k by k x n product, read with one of the stride patterns the dense
    /// layer uses: 0 both row-major, 1 A transposed, 2 B transposed.
    fn operands<'a>(
        a_data: &'a [f32],
        b_data: &'a [f32],
        (m, n, k): (usize, usize, usize),
        layout: usize,
    ) -> (Strided<'a>, Strided<'a>) {
        match layout {
            0 => (Strided::rows(a_data, k), Strided::rows(b_data, n)),
            1 => (Strided::transposed(a_data, m), Strided::rows(b_data, n)),
            _ => (Strided::rows(a_data, k), Strided::transposed(b_data, k)),
        }
    }

    /// The same product with every stride pattern the dense layer uses.
    fn product(path: KernelPath, (m, n, k): (usize, usize, usize), layout: usize, accumulate: bool) -> Vec<f32> {
        let a_data = values(m * k, 0.3);
        let b_data = values(k * n, 1.1);
        let (a, b) = operands(&a_data, &b_data, (m, n, k), layout);
        let stride = n + 3;
        let mut dst = values(m * stride, 2.7);
        matmul(path, (m, n, k), &mut dst, stride, accumulate, a, b);
        dst
    }

    /// The reference: f64 sums, which every f32 order must approach.
    #[test]
    fn every_exact_path_gives_the_same_bits_and_matches_the_library() {
        let paths: Vec<KernelPath> = KernelPath::ALL.into_iter().filter(|p| p.is_supported()).collect();
        assert!(paths.contains(&KernelPath::Portable) && paths.contains(&KernelPath::Library));
        for shape in SHAPES {
            for layout in 0..3 {
                for accumulate in [false, true] {
                    let portable = product(KernelPath::Portable, shape, layout, accumulate);
                    for path in paths.iter().filter(|p| p.is_exact()) {
                        let ours = product(*path, shape, layout, accumulate);
                        let same = ours.iter().zip(&portable).all(|(a, b)| a.to_bits() == b.to_bits());
                        assert!(
                            same,
                            "{path} differs from portable at {shape:?} layout {layout} accumulate {accumulate}"
                        );
                    }
                    let library = product(KernelPath::Library, shape, layout, accumulate);
                    let scale = shape.2 as f32 * 2500.0 * f32::EPSILON * 4.0 + 1e-6;
                    for (i, (a, l)) in portable.iter().zip(&library).enumerate() {
                        assert!(
                            (a - l).abs() <= scale * (1.0 + l.abs()),
                            "{shape:?} layout {layout} element {i}: {a} vs gemm {l}"
                        );
                    }
                }
            }
        }
    }

    /// Every exact path against the definition: one `mul_add` per term, in order, from the old
    /// value (or zero), element by element.
    #[test]
    fn every_exact_path_is_the_element_by_element_definition() {
        let shapes = SHAPES.iter().copied().chain([(256, 1, 300), (9, 1, 5), (1, 1, 7)]);
        for (m, n, k) in shapes {
            for layout in 0..3 {
                for accumulate in [false, true] {
                    let a_data = values(m * k, 0.3);
                    let b_data = values(k * n, 1.1);
                    let (a, b) = operands(&a_data, &b_data, (m, n, k), layout);
                    // a single column is also written unpadded (stride 1), as a value layer's is
                    let stride = if n == 1 { 1 } else { n + 3 };
                    let start = values(m * stride, 2.7);
                    let mut expected = start.clone();
                    for i in 0..m {
                        for j in 0..n {
                            let at = |s: &Strided, r: usize, c: usize| s.data[r * s.row_stride + c * s.col_stride];
                            let mut acc = if accumulate { start[i * stride + j] } else { 0.0 };
                            for p in 0..k {
                                acc = at(&a, i, p).mul_add(at(&b, p, j), acc);
                            }
                            expected[i * stride + j] = acc;
                        }
                    }
                    for path in KernelPath::ALL.into_iter().filter(|p| p.is_exact() && p.is_supported()) {
                        let mut dst = start.clone();
                        matmul(path, (m, n, k), &mut dst, stride, accumulate, a, b);
                        let same = dst.iter().zip(&expected).all(|(x, y)| x.to_bits() == y.to_bits());
                        assert!(same, "{path} at {:?} layout {layout} accumulate {accumulate}", (m, n, k));
                    }
                }
            }
        }
    }

    /// `matmul_bias` is the bias written first, `matmul` accumulating onto it and the ReLU after,
    /// bit for bit on every path, whatever the chunk of k the tile ends in (the ReLU is applied
    /// only as the last chunk stores) and including -0, NaN and infinite sums.
    #[test]
    fn bias_and_relu_in_the_product_equal_them_applied_around_it() {
        let shapes = SHAPES.iter().copied().chain([(256, 1, 300), (9, 1, 5), (33, 70, 300), (8, 48, 129)]);
        for (m, n, k) in shapes {
            let mut bias = values(n, 2.9);
            if n > 3 {
                bias[0] = -0.0;
                bias[1] = f32::NAN;
                bias[2] = f32::INFINITY;
            }
            let a_data = values(m * k, 0.3);
            let b_data = values(k * n, 1.1);
            for layout in 0..3 {
                let (a, b) = operands(&a_data, &b_data, (m, n, k), layout);
                for relu in [false, true] {
                    let stride = n + 3;
                    let mut expected = vec![7.0f32; m.max(1) * stride];
                    expected.chunks_mut(stride).take(m).for_each(|row| row[..n].copy_from_slice(&bias));
                    matmul(KernelPath::Portable, (m, n, k), &mut expected, stride, true, a, b);
                    if relu {
                        expected
                            .chunks_mut(stride)
                            .take(m)
                            .for_each(|r| r[..n].iter_mut().for_each(|v| *v = relu_of(*v)));
                    }
                    for path in KernelPath::ALL.into_iter().filter(|p| p.is_supported()) {
                        let mut dst = vec![7.0f32; m.max(1) * stride];
                        matmul_bias(path, (m, n, k), &mut dst, stride, &bias, relu, a, b);
                        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        if path.is_exact() {
                            assert_eq!(
                                bits(&dst),
                                bits(&expected),
                                "{path} {:?} layout {layout} relu {relu}",
                                (m, n, k)
                            );
                        } else if relu {
                            assert!(dst.iter().all(|v| *v >= 0.0 || *v == 7.0), "{path} {:?}", (m, n, k));
                        }
                    }
                }
            }
        }
        assert_eq!(
            (relu_of(-0.0).to_bits(), relu_of(f32::NAN).to_bits(), relu_of(-3.0), relu_of(2.5)),
            (0, 0, 0.0, 2.5)
        );
    }

    #[test]
    fn the_order_is_one_fused_multiply_add_per_term_from_the_old_value() {
        let exact_paths = || KernelPath::ALL.into_iter().filter(|p| p.is_exact() && p.is_supported());
        // (1 + e)(1 - e) - 1 = -e^2 survives a fused multiply-add and is 0 after a rounded product.
        let e = f32::EPSILON;
        for path in exact_paths() {
            let mut dst = [-1.0f32];
            matmul(path, (1, 1, 1), &mut dst, 1, true, Strided::rows(&[1.0 + e], 1), Strided::rows(&[1.0 - e], 1));
            assert_eq!(dst[0], -e * e, "{path}");
        }
        // Terms in order from the old value: (0 + 1e8) + 1 rounds back to 1e8, so the sum is 0;
        // any other grouping gives 1.
        let b = [1e8f32, 1.0, -1e8];
        for path in exact_paths() {
            let mut dst = [0.0f32; 17];
            let ones = [1.0f32; 3];
            let wide: Vec<f32> = b.iter().flat_map(|v| [*v; 17]).collect();
            matmul(path, (1, 17, 3), &mut dst, 17, false, Strided::rows(&ones, 3), Strided::rows(&wide, 17));
            assert!(dst.iter().all(|v| *v == 0.0), "{path}: {dst:?}");
        }
    }

    #[test]
    fn packing_a_transposed_weight_by_blocks_gives_the_element_by_element_panel() {
        if !KernelPath::Avx2.is_supported() {
            return;
        }
        // a weight of 53 rows (columns of B) by 70 terms, packed from term 5, column 3
        let w = values(53 * 70, 0.9);
        let b = Strided::transposed(&w, 70);
        for (cols, kc) in [(48, 64), (45, 61), (8, 8), (7, 9), (16, 1)] {
            let (mut blocks, mut scalar) = (vec![f32::NAN; 3], vec![f32::NAN; 3]);
            pack_b(b, 5, kc, 3, cols, 48, true, &mut blocks);
            pack_b(b, 5, kc, 3, cols, 48, false, &mut scalar);
            assert_eq!(blocks.len(), kc * 48);
            assert!(blocks.iter().zip(&scalar).all(|(x, y)| x.to_bits() == y.to_bits()), "{cols} x {kc}");
            // element (term p, column j) is w[(3 + j) * 70 + 5 + p]; zeros past the columns
            assert_eq!(blocks[1], w[4 * 70 + 5]);
            assert_eq!(blocks[(kc - 1) * 48 + cols - 1], w[(3 + cols - 1) * 70 + 5 + kc - 1]);
            assert!(blocks.chunks(48).all(|row| row[cols..].iter().all(|v| *v == 0.0)));
        }
    }

    #[test]
    #[should_panic(expected = "operand too short")]
    fn short_operands_are_refused() {
        let mut dst = [0f32; 4];
        matmul(
            KernelPath::Portable,
            (2, 2, 3),
            &mut dst,
            2,
            false,
            Strided::rows(&[0.0; 5], 3),
            Strided::rows(&[0.0; 6], 2),
        );
    }
}
