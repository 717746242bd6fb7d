//! The grid kernels themselves: plain loops over structure-of-arrays
//! slices, each compiled at every SIMD level (`at_level!`), and the
//! layout helpers the workspaces share.

use bevy::math::Vec3A;

use super::{Update, VertexData};
use crate::model::stencil::MAX_FAMILIES;
use crate::solver::engine::kernels::blend;
use crate::solver::engine::simd::at_level;

/// Vertices per block of the vertex pass: its sums live in stack arrays.
const BLOCK: usize = 128;

/// Sizes `buffer` as `rows` rows of `pad` zeros then `n` values, and
/// zeroes the pads (the vertex passes read a family's terms at `i − o`);
/// the spring passes write the rest.
pub(crate) fn padded_rows(buffer: &mut Vec<f32>, rows: usize, n: usize, pad: usize) {
    let stride = pad + n;
    buffer.resize(rows * stride, 0.0);
    for row in buffer.chunks_mut(stride) {
        row[..pad].fill(0.0);
    }
}

/// `[x…, y…, z…]` from `v`.
pub(crate) fn to_soa(v: &[Vec3A], out: &mut Vec<f32>) {
    out.clear();
    out.extend(v.iter().map(|p| p.x));
    out.extend(v.iter().map(|p| p.y));
    out.extend(v.iter().map(|p| p.z));
}

/// The families' terms as the vertex pass reads them.
pub(crate) struct Terms<'a> {
    pub(crate) data: &'a [f32],
    pub(crate) stride: usize,
    pub(crate) pad: usize,
    pub(crate) offsets: &'a [usize],
}

impl Terms<'_> {
    /// Family `f`'s component-`c` terms from vertex `start`: the ones the
    /// vertices start (`a`) and the ones they end (`b`, at `i − o`), `len`
    /// each.
    #[inline(always)]
    pub(crate) fn runs(&self, f: usize, c: usize, start: usize, len: usize) -> (&[f32], &[f32]) {
        let row = &self.data[(3 * f + c) * self.stride..(3 * f + c + 1) * self.stride];
        let i = self.pad + start;
        let o = self.offsets[f];
        (&row[i..i + len], &row[i - o..i - o + len])
    }
}

/// One vertex chunk's shared inputs.
pub(super) struct Chunk<'a> {
    pub(super) start: usize,
    pub(super) terms: &'a Terms<'a>,
    pub(super) target: [&'a [f32]; 3],
    pub(super) data: &'a VertexData<'a>,
}

pub(crate) type Ends<'a> = [(&'a [f32], &'a [f32]); 3];

at_level! {
    /// The spring kernel at `level` (see [`springs_kernel`]).
    pub(super) fn springs(ends: Ends<'_>, coeffs: (&[f32], &[f32]), out: [&mut [f32]; 3]) => springs_kernel
}

/// `t = d·(α − β/l)` for each spring of a run, `d = x_a − x_b`, `l = ‖d‖`
/// (0 for a zero length): the general pass's operations in its order.
#[inline(always)]
pub(super) fn springs_kernel(
    ends: Ends<'_>,
    (alpha, beta): (&[f32], &[f32]),
    out: [&mut [f32]; 3],
) {
    let [tx, ty, tz] = out;
    let m = tx.len();
    let [(ax, bx), (ay, by), (az, bz)] = ends;
    let (ax, bx, ay, by, az, bz) = (&ax[..m], &bx[..m], &ay[..m], &by[..m], &az[..m], &bz[..m]);
    let (alpha, beta, ty, tz) = (&alpha[..m], &beta[..m], &mut ty[..m], &mut tz[..m]);
    for i in 0..m {
        let (dx, dy, dz) = (ax[i] - bx[i], ay[i] - by[i], az[i] - bz[i]);
        let l2 = (dx * dx + dy * dy) + dz * dz;
        // Computed for every lane, then selected: no branch in the loop.
        let raw = alpha[i] - beta[i] / l2.sqrt();
        let scale = if l2 > 0.0 { raw } else { 0.0 };
        tx[i] = dx * scale;
        ty[i] = dy * scale;
        tz[i] = dz * scale;
    }
}

at_level! {
    /// The vertex kernel at `level` (see [`vertices_by_families`]).
    pub(super) fn vertices(
        chunk: &Chunk<'_>,
        x: [&mut [f32]; 3],
        prev: [&mut [f32]; 3],
        update: Update,
    ) -> f64 => vertices_by_families
}

/// [`vertices_fused`] for the stencil's number of families (a constant in
/// each copy, so its sum unrolls), or [`vertices_blocked`] where it does
/// not apply.
#[inline(always)]
pub(super) fn vertices_by_families(
    chunk: &Chunk<'_>,
    x: [&mut [f32]; 3],
    prev: [&mut [f32]; 3],
    update: Update,
) -> f64 {
    let measure = matches!(update, Update::Chebyshev { measure: true, .. });
    if !chunk.data.spheres.is_empty() || measure {
        return vertices_blocked(chunk, x, prev, update);
    }
    match chunk.terms.offsets.len() {
        1 => vertices_fused::<1>(chunk, x, prev, update),
        2 => vertices_fused::<2>(chunk, x, prev, update),
        3 => vertices_fused::<3>(chunk, x, prev, update),
        4 => vertices_fused::<4>(chunk, x, prev, update),
        5 => vertices_fused::<5>(chunk, x, prev, update),
        6 => vertices_fused::<6>(chunk, x, prev, update),
        7 => vertices_fused::<7>(chunk, x, prev, update),
        _ => vertices_fused::<MAX_FAMILIES>(chunk, x, prev, update),
    }
}

/// One chunk of the vertex pass without penalty contacts or measured
/// steps (the lab's): per component one loop, each vertex's `F` family
/// terms summed, its gradient, step and update — the same operations in
/// the same order as [`vertices_blocked`], so the same bits.
#[inline(always)]
pub(super) fn vertices_fused<const F: usize>(
    chunk: &Chunk<'_>,
    x: [&mut [f32]; 3],
    prev: [&mut [f32]; 3],
    update: Update,
) -> f64 {
    let data = chunk.data;
    let (len, at) = (x[0].len(), chunk.start);
    let (mass, inv) = (&data.mass_term[at..at + len], &data.inv_diag[at..at + len]);
    for (c, (xc, pc)) in x.into_iter().zip(prev).enumerate() {
        let runs: [(&[f32], &[f32]); F] = std::array::from_fn(|f| chunk.terms.runs(f, c, at, len));
        let starts: [&[f32]; F] = std::array::from_fn(|f| &runs[f].0[..len]);
        let ends: [&[f32]; F] = std::array::from_fn(|f| &runs[f].1[..len]);
        let vertex = Vertices {
            starts: &starts,
            ends: &ends,
            target: &chunk.target[c][at..at + len],
            mass,
            inv,
        };
        match update {
            Update::Jacobi => jacobi_update(xc, &vertex),
            Update::Chebyshev { omega, .. } => chebyshev_update(xc, pc, &vertex, omega),
        }
    }
    0.0
}

/// What a chunk's update reads, per vertex (one component).
pub(super) struct Vertices<'a, const F: usize> {
    /// Per family, the terms the vertices start and the ones they end.
    pub(super) starts: &'a [&'a [f32]; F],
    pub(super) ends: &'a [&'a [f32]; F],
    pub(super) target: &'a [f32],
    /// `m/dt²`.
    pub(super) mass: &'a [f32],
    /// `1/diag`.
    pub(super) inv: &'a [f32],
}

impl<const F: usize> Vertices<'_, F> {
    /// Vertex `i`'s diagonal-Newton step `g/diag` at position `x`, with
    /// `g = Σ (start − end) + m/dt²·(x − target)` summed in family order.
    #[inline(always)]
    pub(super) fn step(&self, i: usize, x: f32) -> f32 {
        let mut sum = self.starts[0][i] - self.ends[0][i];
        for f in 1..F {
            sum += self.starts[f][i] - self.ends[f][i];
        }
        (sum + (x - self.target[i]) * self.mass[i]) * self.inv[i]
    }
}

// The two updates are functions of their own with the positions (and the
// previous iterate) as `&mut` arguments: the compiler then knows that
// nothing else they read overlaps them, and vectorises the loop without
// run-time overlap checks (with those, it would not: too many).

/// `x ← x − step`, elementwise.
#[inline(always)]
pub(super) fn jacobi_update<const F: usize>(x: &mut [f32], v: &Vertices<'_, F>) {
    for (i, xi) in x.iter_mut().enumerate() {
        *xi -= v.step(i, *xi);
    }
}

/// `prev ← ω(x − step − prev) + prev`, elementwise: the next iterate over
/// the one before the current (the pass then swaps the two buffers, so one
/// store per vertex instead of two).
#[inline(always)]
pub(super) fn chebyshev_update<const F: usize>(
    x: &mut [f32],
    prev: &mut [f32],
    v: &Vertices<'_, F>,
    omega: f32,
) {
    let prev = &mut prev[..x.len()];
    for i in 0..x.len() {
        let x_hat = x[i] - v.step(i, x[i]);
        let before = prev[i];
        prev[i] = blend(omega, x_hat, before);
    }
}

/// One chunk of the vertex pass, in blocks of [`BLOCK`] vertices: per
/// component, the families' terms summed in family order and the gradient
/// `m/dt²(x − target) + Σ`; penalty contacts (per vertex, for the few in
/// contact); then the step `g/diag` and the update.
#[inline(always)]
pub(super) fn vertices_blocked(
    chunk: &Chunk<'_>,
    x: [&mut [f32]; 3],
    prev: [&mut [f32]; 3],
    update: Update,
) -> f64 {
    let data = chunk.data;
    let len = x[0].len();
    let mut measured = 0.0f64;
    let mut grad = [[0.0f32; BLOCK]; 3];
    let mut inv = [0.0f32; BLOCK];
    let [x0, x1, x2] = x;
    let xs = [x0, x1, x2];
    let [p0, p1, p2] = prev;
    let prevs = [p0, p1, p2];
    for b in (0..len).step_by(BLOCK) {
        let bl = BLOCK.min(len - b);
        let at = chunk.start + b;
        let (mass, inv_diag) = (&data.mass_term[at..at + bl], &data.inv_diag[at..at + bl]);
        for c in 0..3 {
            let (xc, tc) = (&xs[c][b..b + bl], &chunk.target[c][at..at + bl]);
            gradient_run(chunk.terms, c, at, &mut grad[c][..bl], (xc, tc, mass));
        }
        // `g = (x − target)·m + Σ` in the line above is `Σ + (x − target)·m`:
        // the same value (addition commutes bitwise).
        inv[..bl].copy_from_slice(inv_diag);
        if !data.spheres.is_empty() {
            for j in 0..bl {
                let i = at + j;
                if data.pinned[i] {
                    continue;
                }
                let xi = Vec3A::new(xs[0][b + j], xs[1][b + j], xs[2][b + j]);
                let mut diag = data.base_diag[i];
                let mut hit = false;
                for sphere in data.spheres {
                    if let Some(contact) = sphere.contact(xi) {
                        for (c, f) in contact.force.to_array().into_iter().enumerate() {
                            grad[c][j] -= f;
                        }
                        diag += sphere.stiffness;
                        hit = true;
                    }
                }
                if hit {
                    inv[j] = 1.0 / diag;
                }
            }
        }
        let inv = &inv[..bl];
        if let Update::Chebyshev { measure: true, .. } = update {
            let mut squares = [0.0f32; BLOCK];
            let sq = &mut squares[..bl];
            for (c, g) in grad.iter().enumerate() {
                for j in 0..bl {
                    let s = g[j] * inv[j];
                    sq[j] = if c == 0 { s * s } else { sq[j] + s * s };
                }
            }
            measured += sq.iter().map(|&s| f64::from(s)).sum::<f64>();
        }
        for c in 0..3 {
            let (g, xc) = (&grad[c][..bl], &mut xs[c][b..b + bl]);
            match update {
                Update::Jacobi => {
                    for i in 0..bl {
                        xc[i] -= g[i] * inv[i];
                    }
                }
                Update::Chebyshev { omega, .. } => {
                    let pc = &mut prevs[c][b..b + bl];
                    // As `chebyshev_update`: the buffers swap after the pass.
                    for i in 0..bl {
                        let x_hat = xc[i] - g[i] * inv[i];
                        let before = pc[i];
                        pc[i] = blend(omega, x_hat, before);
                    }
                }
            }
        }
    }
    measured
}

/// Component `c` of the gradient of the vertices from `at` (`g.len()` of
/// them): `g = Σ_f (start_f − end_f) + (x − target)·m`, the families
/// summed in order, from `x`, `target` and `m/dt²` of those vertices.
#[inline(always)]
pub(super) fn gradient_run(
    terms: &Terms<'_>,
    c: usize,
    at: usize,
    g: &mut [f32],
    (x, target, mass): (&[f32], &[f32], &[f32]),
) {
    let len = g.len();
    term_sums(terms, c, at, g);
    let (x, target, mass) = (&x[..len], &target[..len], &mass[..len]);
    for i in 0..len {
        g[i] += (x[i] - target[i]) * mass[i];
    }
}

at_level! {
    /// [`sums_kernel`] at `level`.
    pub(super) fn sums(terms: &Terms<'_>, start: usize, out: &mut [Vec3A]) => sums_kernel
}

/// `Σ_f (start_f − end_f)` of the vertices from `start` (`out.len()` of
/// them), in blocks of [`BLOCK`].
#[inline(always)]
pub(super) fn sums_kernel(terms: &Terms<'_>, start: usize, out: &mut [Vec3A]) {
    let mut block = [[0.0f32; BLOCK]; 3];
    for (b, out) in out.chunks_mut(BLOCK).enumerate() {
        let (at, bl) = (start + b * BLOCK, out.len());
        for (comp, g) in block.iter_mut().enumerate() {
            term_sums(terms, comp, at, &mut g[..bl]);
        }
        for (i, o) in out.iter_mut().enumerate() {
            *o = Vec3A::new(block[0][i], block[1][i], block[2][i]);
        }
    }
}

/// Component `c` of `Σ_f (start_f − end_f)` for the vertices from `at`
/// (`g.len()` of them), the families summed in order.
#[inline(always)]
pub(super) fn term_sums(terms: &Terms<'_>, c: usize, at: usize, g: &mut [f32]) {
    let len = g.len();
    for f in 0..terms.offsets.len() {
        let (ta, tb) = terms.runs(f, c, at, len);
        if f == 0 {
            for i in 0..len {
                g[i] = ta[i] - tb[i];
            }
        } else {
            for i in 0..len {
                g[i] += ta[i] - tb[i];
            }
        }
    }
}
