//! The implicit iteration on structure-of-arrays state, for cloths whose
//! springs form a stencil: every spring `(a, a + o)` belongs to one of a few
//! offset families `o` (a grid numbered row by row: the lab's triangle grid
//! has three, `1`, `W` and `W + 1`; the assignment's cloth six).
//!
//! Then the spring pass needs no indices: for a family, the springs' first
//! ends are the positions `x[0 .. n − o]` and their second ends
//! `x[o .. n]`, two contiguous runs, so with positions stored as three
//! `f32` arrays (`x`, `y`, `z`) one SIMD register holds 4, 8 or 16 springs
//! loaded straight from memory — no transposes, no gathers. The vertex
//! pass is contiguous too: vertex `i` adds its family-`f` term at `i`
//! (it starts the spring) and subtracts the one at `i − o` (it ends it).
//! A family's missing springs (a row's last vertex has no right
//! neighbour) have zero coefficients, so their terms are zero.
//!
//! Each spring's term is the same IEEE operations in the same order as the
//! general pass ([`spring_products`](crate::solver::engine::simd::spring_products)): the
//! same bits per spring. A vertex sums its springs family by family rather
//! than in its adjacency's order, so a step agrees with the general path
//! within `f32` rounding, not bitwise.
//!
//! The kernels are plain loops over slices, compiled three times — for the
//! baseline (SSE2 on x86-64, NEON on aarch64), for AVX2 + FMA and for
//! AVX-512F, through `#[target_feature]` functions — and the compiler
//! vectorises each at its width; the level is [`StepParams::simd`]'s,
//! chosen at run time ([`Simd::resolve`]). Every operation is elementwise
//! and none is fused (Rust never contracts `a·b + c`), so **every level
//! gives the same bits**. Written as loops rather than with `pulp`: the
//! compiler's vectorisation of these streams is what a hand-written
//! `f32s` kernel would be (their speed against the general kernels is in
//! `docs/perf.md`), and the loops stay readable.
//!
//! [`StepParams::simd`]: crate::solver::StepParams::simd

use bevy::math::Vec3A;

use super::kernels::{CHUNK, parallel_pool};
use super::phases::run_phases;
use super::simd::Simd;
use crate::collision::PenaltySphere;
use crate::model::stencil::{MAX_FAMILIES, Stencil};

mod kernels;
pub(crate) mod pbd;
pub(crate) mod residual;

use kernels::{Chunk, gradient_run, springs, sums, vertices};
pub(crate) use kernels::{Ends, Terms, padded_rows, to_soa};

/// What one vertex pass does with each vertex's step `g/diag`.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Update {
    /// Plain Jacobi: `x ← x − step`.
    Jacobi,
    /// Chebyshev: `x ← ω(x − step − x_prev) + x_prev`, `x_prev ← x`;
    /// `measure` sums the squared steps (for [`Rho::Auto`](crate::solver::chebyshev::Rho)).
    Chebyshev { omega: f32, measure: bool },
}

/// The per-vertex data of a step that the vertex pass reads besides the
/// stencil's own arrays.
pub(crate) struct VertexData<'a> {
    /// `m/dt²`.
    pub mass_term: &'a [f32],
    /// `1/(m/dt² + Σk)`, 0 for a pinned vertex.
    pub inv_diag: &'a [f32],
    /// `m/dt² + Σk`, to which penalty contacts add their stiffness.
    pub base_diag: &'a [f32],
    pub pinned: &'a [bool],
    pub spheres: &'a [PenaltySphere],
}

/// The stencil iteration's arrays: structure-of-arrays positions, previous
/// iterate and target, per-family coefficients and terms. Sized on first
/// use, reused after.
#[derive(Clone, Debug, Default)]
pub(crate) struct StencilWorkspace {
    n: usize,
    /// Zeros before each term array: the vertex pass reads family `f`'s
    /// term at `i − o` for every `i`.
    pad: usize,
    offsets: Vec<usize>,
    /// Per family, per vertex `a < n − o`: `[α, β]` of its spring (zeros
    /// where there is none); `n` entries per family.
    alpha: Vec<f32>,
    beta: Vec<f32>,
    /// The stencil's id, the stiffness bits and the kind (projection or
    /// not) `alpha` and `beta` are for.
    coefficients: Option<(u64, [u32; 3], bool)>,
    /// `[x…, y…, z…]`, `n` each.
    x: Vec<f32>,
    prev: Vec<f32>,
    target: Vec<f32>,
    /// Per family and component: `pad` zeros, then `n` terms.
    terms: Vec<f32>,
    /// Per iteration and chunk of vertices: the sum of squared steps.
    chunk_sums: Vec<f64>,
    /// `[g_x…, g_y…, g_z…]`: the gradient at the final iterate.
    grad: Vec<f32>,
}

impl StencilWorkspace {
    /// Loads a step: the springs' coefficients `[α, β] = [k, kL]` for the
    /// stiffness per kind `k`, the positions `x` and the targets
    /// `x + offset`, into the structure-of-arrays state.
    pub(crate) fn load(
        &mut self,
        stencil: &Stencil,
        k: [f32; 3],
        x: &[Vec3A],
        offset: Vec3A,
        chebyshev: bool,
    ) {
        self.coefficients_for(stencil, k, false);
        self.positions(stencil, x, Some(offset), chebyshev);
    }

    /// Loads the spring terms' inputs alone (symplectic Euler's forces,
    /// [`spring_sums`](Self::spring_sums)): the coefficients `[k, kL]` and
    /// the positions `x`, no targets.
    pub(crate) fn load_springs(&mut self, stencil: &Stencil, k: [f32; 3], x: &[Vec3A]) {
        self.coefficients_for(stencil, k, false);
        self.positions(stencil, x, None, false);
    }

    /// Loads projective dynamics' local step at `x`: the coefficients
    /// `[α, β] = [0, −kL]`, so that a spring's term is `k·L/l·d`, its
    /// stiffness times its projection.
    pub(crate) fn load_projection(&mut self, stencil: &Stencil, k: [f32; 3], x: &[Vec3A]) {
        self.coefficients_for(stencil, k, true);
        self.positions(stencil, x, None, false);
    }

    /// The coefficients `[k, kL]`, or `[0, −kL]` for `projection`, per
    /// spring; kept while the stencil, `k` and the kind stay the same.
    fn coefficients_for(&mut self, stencil: &Stencil, k: [f32; 3], projection: bool) {
        let key = (stencil.id, k.map(f32::to_bits), projection);
        if self.coefficients == Some(key) {
            return;
        }
        // Per kind, and 0 where no spring starts (NONE = 3).
        let k = [k[0], k[1], k[2], 0.0];
        let stiffness = stencil.kinds.iter().map(|&kind| k[usize::from(kind & 3)]);
        self.alpha.clear();
        self.beta.clear();
        if projection {
            self.alpha.resize(stencil.kinds.len(), 0.0);
            self.beta
                .extend(stiffness.zip(&stencil.rest).map(|(k, l)| -(k * l)));
        } else {
            self.alpha.extend(stiffness);
            // `k·L`, as the general kernels' coefficients.
            self.beta
                .extend(self.alpha.iter().zip(&stencil.rest).map(|(k, l)| k * l));
        }
        self.coefficients = Some(key);
    }

    /// The positions `x`, the targets `x + offset` (none without an
    /// offset: only the vertex and gradient passes read them) and (for
    /// `chebyshev`) the previous iterate, and the terms' zero pads.
    fn positions(
        &mut self,
        stencil: &Stencil,
        x: &[Vec3A],
        offset: Option<Vec3A>,
        chebyshev: bool,
    ) {
        let n = x.len();
        let families = stencil.families();
        self.n = n;
        self.pad = stencil.max_offset();
        self.offsets.clone_from(&stencil.offsets);
        to_soa(x, &mut self.x);
        self.target.clear();
        for (c, o) in offset.iter().flat_map(|o| o.to_array()).enumerate() {
            let row = &self.x[c * n..(c + 1) * n];
            self.target.extend(row.iter().map(|&x| x + o));
        }
        if chebyshev {
            self.prev.clone_from(&self.x);
        }
        padded_rows(&mut self.terms, families * 3, n, self.pad);
    }

    /// The iteration after [`load`](Self::load): `iterations` times a
    /// spring pass and a vertex pass whose update `next(k, squares)` gives
    /// (`squares`: the sum of squared steps the pass before measured, 0 for
    /// the first), then a spring pass at the final iterate, whose gradient
    /// (penalty contacts included, the vertex pass's sums in its order)
    /// goes to `gradient` and positions to `positions`. `chebyshev` says
    /// whether the updates are Chebyshev's (they then write the next
    /// iterate over the one before, and the two buffers take turns).
    ///
    /// All passes run in one parallel region when `parallel` allows
    /// ([`run_phases`]): every pass is a phase of vertex chunks.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn iterate(
        &mut self,
        simd: Simd,
        parallel: bool,
        data: &VertexData<'_>,
        iterations: u32,
        chebyshev: bool,
        mut next: impl FnMut(u32, f64) -> Update + Send,
        gradient: &mut [Vec3A],
        positions: &mut [Vec3A],
    ) {
        let n = self.n;
        let iterations = iterations as usize;
        let chunks = n.div_ceil(CHUNK);
        self.grad.resize(3 * n, 0.0);
        self.chunk_sums.clear();
        self.chunk_sums.resize(iterations * chunks, 0.0);
        let gradient = &mut gradient[..n];
        let positions = &mut positions[..n];
        let outputs = [
            SharedVec3(gradient.as_mut_ptr()),
            SharedVec3(positions.as_mut_ptr()),
        ];
        let run = self.run(simd, data, chebyshev, outputs);
        // Phases: spring pass k at 2k (k = 0..=iterations), vertex pass k at
        // 2k + 1, the gradient at 2·iterations + 1.
        let phases = 2 * iterations + 2;
        let start = |phase: usize| {
            if phase.is_multiple_of(2) || phase == phases - 1 {
                return 0;
            }
            let k = phase / 2;
            // SAFETY: every item of the passes before is done, and no item
            // of this one has started: nothing writes the sums.
            let squares = if k == 0 {
                0.0
            } else {
                unsafe { run.sums.slice((k - 1) * chunks, chunks) }
                    .iter()
                    .sum()
            };
            encode(next(k as u32, squares))
        };
        run_phases(
            parallel_pool(parallel, n),
            phases,
            chunks,
            start,
            |phase, chunk, value| {
                let k = phase / 2;
                // SAFETY (all three): the phases' items touch memory as
                // [`PhasedIteration`] says, and one phase runs at a time.
                unsafe {
                    if phase == phases - 1 {
                        run.gradient_chunk(iterations, chunk);
                    } else if phase.is_multiple_of(2) {
                        run.springs_chunk(k, chunk);
                    } else {
                        run.vertices_chunk(k, chunk, decode(value));
                    }
                }
            },
        );
    }
}

impl StencilWorkspace {
    /// The [`PhasedIteration`] of a step over this workspace's arrays, writing the
    /// gradient (or sums) and positions to `[gradient, positions]`.
    fn run<'a>(
        &'a mut self,
        simd: Simd,
        data: &'a VertexData<'a>,
        chebyshev: bool,
        [gradient, positions]: [SharedVec3; 2],
    ) -> PhasedIteration<'a> {
        let n = self.n;
        PhasedIteration {
            n,
            chunks: n.div_ceil(CHUNK),
            level: simd.resolve(),
            stride: self.pad + n,
            pad: self.pad,
            offsets: &self.offsets,
            alpha: &self.alpha,
            beta: &self.beta,
            // Empty when loaded without targets (no pass then reads them).
            target: [0, 1, 2].map(|c| self.target.get(c * n..(c + 1) * n).unwrap_or(&[])),
            data,
            chebyshev,
            buffers: [
                SharedF32(self.x.as_mut_ptr()),
                SharedF32(self.prev.as_mut_ptr()),
            ],
            terms: (SharedF32(self.terms.as_mut_ptr()), self.terms.len()),
            grad: SharedF32(self.grad.as_mut_ptr()),
            sums: SharedF64(self.chunk_sums.as_mut_ptr()),
            gradient,
            positions,
        }
    }

    /// After [`load`](Self::load): one spring pass at the loaded positions,
    /// and per vertex its springs' terms `Σ (start − end)`, summed family
    /// by family, into `sums` (`k(1 − L/l)(x_a − x_b)` per spring: the
    /// negated spring forces, as symplectic Euler takes them). Both passes
    /// are phases of one parallel region when `parallel` allows.
    pub(crate) fn spring_sums(&mut self, simd: Simd, parallel: bool, sums: &mut [Vec3A]) {
        let n = self.n;
        let chunks = n.div_ceil(CHUNK);
        let sums = &mut sums[..n];
        let none = VertexData {
            mass_term: &[],
            inv_diag: &[],
            base_diag: &[],
            pinned: &[],
            spheres: &[],
        };
        let outputs = [
            SharedVec3(sums.as_mut_ptr()),
            SharedVec3(std::ptr::null_mut()),
        ];
        let run = self.run(simd, &none, false, outputs);
        run_phases(
            parallel_pool(parallel, n),
            2,
            chunks,
            |_| 0,
            |phase, chunk, _| {
                // SAFETY: the spring pass writes the terms by chunk; the
                // sums phase reads them and writes its chunk of `sums`.
                unsafe {
                    if phase == 0 {
                        run.springs_chunk(0, chunk);
                    } else {
                        run.sums_chunk(chunk);
                    }
                }
            },
        );
    }
}

/// A raw pointer to one of the workspace's arrays, shared by the items of
/// [`StencilWorkspace::iterate`]'s phases.
#[derive(Clone, Copy)]
pub(crate) struct SharedF32(pub(crate) *mut f32);
#[derive(Clone, Copy)]
struct SharedF64(*mut f64);
#[derive(Clone, Copy)]
pub(crate) struct SharedVec3(pub(crate) *mut Vec3A);

// SAFETY: the items that share them write disjoint chunks, and read only
// what no item of their phase writes (see `PhasedIteration`).
unsafe impl Send for SharedF32 {}
unsafe impl Sync for SharedF32 {}
unsafe impl Send for SharedF64 {}
unsafe impl Sync for SharedF64 {}
unsafe impl Send for SharedVec3 {}
unsafe impl Sync for SharedVec3 {}

impl SharedF32 {
    /// # Safety
    /// `at + len` within the array, and nothing writes it meanwhile.
    pub(crate) unsafe fn slice<'a>(self, at: usize, len: usize) -> &'a [f32] {
        unsafe { std::slice::from_raw_parts(self.0.add(at), len) }
    }

    /// # Safety
    /// `at + len` within the array, and nothing else reads or writes it
    /// meanwhile.
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn slice_mut<'a>(self, at: usize, len: usize) -> &'a mut [f32] {
        unsafe { std::slice::from_raw_parts_mut(self.0.add(at), len) }
    }
}

impl SharedF64 {
    /// # Safety
    /// As [`SharedF32::slice`].
    unsafe fn slice<'a>(self, at: usize, len: usize) -> &'a [f64] {
        unsafe { std::slice::from_raw_parts(self.0.add(at), len) }
    }
}

/// An [`Update`] as the `u64` a phase's start hands its items.
fn encode(update: Update) -> u64 {
    match update {
        Update::Jacobi => 0,
        Update::Chebyshev { omega, measure } => {
            1 << 32 | u64::from(measure) << 33 | u64::from(omega.to_bits())
        }
    }
}

fn decode(value: u64) -> Update {
    if value & 1 << 32 == 0 {
        Update::Jacobi
    } else {
        Update::Chebyshev {
            omega: f32::from_bits(value as u32),
            measure: value & 1 << 33 != 0,
        }
    }
}

/// One [`StencilWorkspace::iterate`]: what its items read, and the arrays
/// they write through raw pointers. Spring pass `k` reads positions buffer
/// [`current(k)`](Self::current) and writes the terms; vertex pass `k`
/// reads the terms and writes buffer `current(k)` (Jacobi) or the other
/// one (Chebyshev), and the sums of iteration `k`; the gradient phase reads
/// the terms and `current(iterations)` and writes `grad`, `gradient` and
/// `positions`. Every item writes only its own chunk's part.
struct PhasedIteration<'a> {
    n: usize,
    chunks: usize,
    level: Simd,
    stride: usize,
    pad: usize,
    offsets: &'a [usize],
    alpha: &'a [f32],
    beta: &'a [f32],
    target: [&'a [f32]; 3],
    data: &'a VertexData<'a>,
    chebyshev: bool,
    /// The positions and the previous iterate, `[x…, y…, z…]` each.
    buffers: [SharedF32; 2],
    terms: (SharedF32, usize),
    grad: SharedF32,
    /// Per iteration and chunk, the sum of squared steps.
    sums: SharedF64,
    gradient: SharedVec3,
    positions: SharedVec3,
}

impl PhasedIteration<'_> {
    /// The buffer that holds iterate `k` (Chebyshev's alternate).
    fn current(&self, k: usize) -> SharedF32 {
        self.buffers[if self.chebyshev { k % 2 } else { 0 }]
    }

    /// Chunk `c`'s first vertex and length.
    fn span(&self, c: usize) -> (usize, usize) {
        let start = c * CHUNK;
        (start, CHUNK.min(self.n - start))
    }

    /// The terms, whole, for the phases that only read them.
    ///
    /// # Safety
    /// Nothing writes the terms meanwhile.
    unsafe fn terms(&self) -> Terms<'_> {
        Terms {
            data: unsafe { self.terms.0.slice(0, self.terms.1) },
            stride: self.stride,
            pad: self.pad,
            offsets: self.offsets,
        }
    }

    /// Spring pass `k`, chunk `c`: every spring's term `d·(α − β/l)`.
    ///
    /// # Safety
    /// Runs in spring phase `k`.
    unsafe fn springs_chunk(&self, k: usize, c: usize) {
        let (n, x) = (self.n, self.current(k));
        let (start, len) = self.span(c);
        for (f, &o) in self.offsets.iter().enumerate() {
            // Springs start at `a < n − o`.
            let m = (n - o).saturating_sub(start).min(len);
            let coeff = f * n + start..f * n + start + m;
            // SAFETY: in a spring phase nothing writes the positions (and
            // `start + o + m ≤ n`); chunk `c`'s terms are this item's.
            let ends = |comp: usize| unsafe {
                (
                    x.slice(comp * n + start, m),
                    x.slice(comp * n + start + o, m),
                )
            };
            // SAFETY: family `f`'s terms of chunk `c` are this item's
            // alone in a spring phase, and nothing reads them meanwhile.
            let [tx, ty, tz] = [0, 1, 2].map(|comp| unsafe {
                self.terms
                    .0
                    .slice_mut((3 * f + comp) * self.stride + self.pad + start, len)
            });
            springs(
                self.level,
                [ends(0), ends(1), ends(2)],
                (&self.alpha[coeff.clone()], &self.beta[coeff]),
                [&mut tx[..m], &mut ty[..m], &mut tz[..m]],
            );
            for t in [tx, ty, tz] {
                t[m..].fill(0.0);
            }
        }
    }

    /// Vertex pass `k`, chunk `c`, with `update`; its sum of squared steps
    /// into the sums.
    ///
    /// # Safety
    /// Runs in vertex phase `k`.
    unsafe fn vertices_chunk(&self, k: usize, c: usize, update: Update) {
        let n = self.n;
        let (start, len) = self.span(c);
        // SAFETY: in a vertex phase nothing writes the terms; the chunk's
        // positions, previous iterate and sum are this item's.
        let terms = unsafe { self.terms() };
        let (x, other) = (self.current(k), self.buffers[1 - k % 2]);
        let xs = [0, 1, 2].map(|comp| unsafe { x.slice_mut(comp * n + start, len) });
        let prev = if self.chebyshev {
            [0, 1, 2].map(|comp| unsafe { other.slice_mut(comp * n + start, len) })
        } else {
            Default::default()
        };
        let chunk = Chunk {
            start,
            terms: &terms,
            target: self.target,
            data: self.data,
        };
        let squares = vertices(self.level, &chunk, xs, prev, update);
        // SAFETY: slot `(k, c)` of the sums is this item's alone, and the
        // sums have a slot per iteration and chunk.
        unsafe { *self.sums.0.add(k * self.chunks + c) = squares };
    }

    /// Chunk `c`'s term sums into `gradient` (see
    /// [`StencilWorkspace::spring_sums`]).
    ///
    /// # Safety
    /// Runs after the spring pass, in a phase that writes no terms.
    unsafe fn sums_chunk(&self, c: usize) {
        let (start, len) = self.span(c);
        // SAFETY: nothing writes the terms in this phase; the chunk's sums
        // are this item's.
        let terms = unsafe { self.terms() };
        let out = unsafe { std::slice::from_raw_parts_mut(self.gradient.0.add(start), len) };
        sums(self.level, &terms, start, out);
    }

    /// The gradient at iterate `k` (after its spring pass), chunk `c`, and
    /// the positions, into `gradient` and `positions`.
    ///
    /// # Safety
    /// Runs in the gradient phase, after spring pass `k`.
    unsafe fn gradient_chunk(&self, k: usize, c: usize) {
        let (n, x) = (self.n, self.current(k));
        let (start, len) = self.span(c);
        // SAFETY: nothing writes the terms or positions in this phase; the
        // chunk's gradient and outputs are this item's.
        let terms = unsafe { self.terms() };
        let mass = &self.data.mass_term[start..start + len];
        let xs = [0, 1, 2].map(|comp| unsafe { x.slice(comp * n + start, len) });
        let mut gs = [0, 1, 2].map(|comp| unsafe { self.grad.slice_mut(comp * n + start, len) });
        for (comp, g) in gs.iter_mut().enumerate() {
            let target = &self.target[comp][start..start + len];
            gradient_run(&terms, comp, start, g, (xs[comp], target, mass));
        }
        // SAFETY: the chunk's range of the gradient and the output
        // positions (each `n` long) is this item's alone.
        let (gradient, positions) = unsafe {
            (
                std::slice::from_raw_parts_mut(self.gradient.0.add(start), len),
                std::slice::from_raw_parts_mut(self.positions.0.add(start), len),
            )
        };
        for (i, (out, xo)) in gradient.iter_mut().zip(positions.iter_mut()).enumerate() {
            *out = Vec3A::new(gs[0][i], gs[1][i], gs[2][i]);
            *xo = Vec3A::new(xs[0][i], xs[1][i], xs[2][i]);
        }
        if !self.data.spheres.is_empty() {
            for (i, out) in gradient.iter_mut().enumerate() {
                if !self.data.pinned[start + i] {
                    for sphere in self.data.spheres {
                        if let Some(contact) = sphere.contact(positions[i]) {
                            *out -= contact.force;
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests;
