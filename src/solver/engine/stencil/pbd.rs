//! PBD's Jacobi strain limiting ([`pbd`](super::pbd)) on the stencil's
//! structure-of-arrays state, for cloths whose springs form a stencil (see
//! [`stencil`](super::stencil): offset families, positions as three `f32`
//! arrays, compiled for the baseline, AVX2 + FMA and AVX-512F and chosen at
//! run time).
//!
//! The proposal pass writes, per family, each spring's two proposals
//! (`mid ± L/2·d/‖d‖`) at its first end `a`: the proposals for `a` in one
//! array, those for `b = a + o` in another. The vertex pass then reads, for
//! vertex `i`, family `f`'s first-end proposal at `i` and its second-end
//! proposal at `i − o`, both contiguous runs; a missing spring proposes
//! zero. Each proposal is the general pass's operations in its order (the
//! same bits per spring); a vertex sums them family by family, so a step
//! agrees with the general path within `f32` rounding, not bitwise. The
//! velocities take the step's whole move at the end,
//! `v ← v + (x_K − x_0)/dt` (the general path adds each iteration's move).
//!
//! Every pass is a phase of vertex chunks in one parallel region
//! ([`run_phases`]): the same bits on any thread count and at every SIMD
//! level (every operation elementwise, none fused).

use bevy::math::Vec3A;

use super::{Ends, SharedF32, SharedVec3, Terms, padded_rows, to_soa};
use crate::model::stencil::{NONE, Stencil};
use crate::solver::engine::kernels::{CHUNK, parallel_pool};
use crate::solver::engine::phases::run_phases;
use crate::solver::engine::simd::{Simd, at_level};

/// The weight of a vertex's own position in the lab's Jacobi average (the
/// PBD method's constant, defined here with the grid kernel that uses it
/// and re-exported as [`solver::pbd::SELF_WEIGHT`](crate::solver::pbd::SELF_WEIGHT)).
pub const SELF_WEIGHT: f32 = 0.2;

/// The PBD iteration's arrays, sized on first use and reused after.
#[derive(Clone, Debug, Default)]
pub(crate) struct PbdStencilWorkspace {
    n: usize,
    /// Zeros before each proposal array (the vertex pass reads the second
    /// ends' proposals at `i − o`).
    pad: usize,
    offsets: Vec<usize>,
    /// Per family, per vertex `a`: half the rest length of the spring
    /// `(a, a + o)`, or −1 where there is none; `n` per family.
    half_rest: Vec<f32>,
    /// The stencil `half_rest` is for.
    stencil_id: Option<u64>,
    /// Per vertex, `1/(0.2 + nᵢ)`; 0 for a pinned vertex.
    inv_weight: Vec<f32>,
    /// The pinned vertices, increasing.
    pins: Vec<usize>,
    /// `[x…, y…, z…]`: the iterate, and the step's start.
    x: Vec<f32>,
    x0: Vec<f32>,
    /// Per family and component, `pad` zeros then `n` proposals: for the
    /// springs' first ends, and for their second ends (both at `a`).
    first: Vec<f32>,
    second: Vec<f32>,
}

impl PbdStencilWorkspace {
    /// Loads a step from the predicted positions `x`; `degree(i)` is vertex
    /// `i`'s spring count.
    pub(crate) fn load(
        &mut self,
        stencil: &Stencil,
        x: &[Vec3A],
        degree: impl Fn(usize) -> usize,
        pinned: &[bool],
    ) {
        let n = x.len();
        self.n = n;
        self.pad = stencil.max_offset();
        self.offsets.clone_from(&stencil.offsets);
        if self.stencil_id != Some(stencil.id) {
            self.half_rest.clear();
            self.half_rest.extend(
                stencil
                    .kinds
                    .iter()
                    .zip(&stencil.rest)
                    .map(|(&kind, &l)| if kind == NONE { -1.0 } else { 0.5 * l }),
            );
            self.stencil_id = Some(stencil.id);
        }
        self.inv_weight.clear();
        self.inv_weight.extend((0..n).map(|i| {
            if pinned[i] {
                0.0
            } else {
                1.0 / (SELF_WEIGHT + degree(i) as f32)
            }
        }));
        self.pins.clear();
        self.pins.extend((0..n).filter(|&i| pinned[i]));
        to_soa(x, &mut self.x);
        self.x0.clone_from(&self.x);
        for buffer in [&mut self.first, &mut self.second] {
            padded_rows(buffer, stencil.families() * 3, n, self.pad);
        }
    }

    /// `iterations` proposal and vertex passes after [`load`](Self::load),
    /// then the positions into `positions` and each vertex's move over
    /// `dt` (`inv_dt = 1/dt`) added to `velocities`.
    pub(crate) fn iterate(
        &mut self,
        simd: Simd,
        parallel: bool,
        iterations: u32,
        inv_dt: f32,
        positions: &mut [Vec3A],
        velocities: &mut [Vec3A],
    ) {
        let n = self.n;
        let chunks = n.div_ceil(CHUNK);
        let stride = self.pad + n;
        let len = self.first.len();
        let positions = &mut positions[..n];
        let velocities = &mut velocities[..n];
        let run = PhasedIteration {
            n,
            level: simd.resolve(),
            stride,
            pad: self.pad,
            offsets: &self.offsets,
            half_rest: &self.half_rest,
            inv_weight: &self.inv_weight,
            pins: &self.pins,
            x0: &self.x0,
            inv_dt,
            x: SharedF32(self.x.as_mut_ptr()),
            first: (SharedF32(self.first.as_mut_ptr()), len),
            second: (SharedF32(self.second.as_mut_ptr()), len),
            positions: SharedVec3(positions.as_mut_ptr()),
            velocities: SharedVec3(velocities.as_mut_ptr()),
        };
        // Proposal pass k at 2k, vertex pass k at 2k + 1, the output last.
        let phases = 2 * iterations as usize + 1;
        run_phases(
            parallel_pool(parallel, n),
            phases,
            chunks,
            |_| 0,
            |phase, chunk, _| {
                // SAFETY (all three): the items touch memory as `PhasedIteration` says,
                // and one phase runs at a time.
                unsafe {
                    if phase == phases - 1 {
                        run.output_chunk(chunk);
                    } else if phase.is_multiple_of(2) {
                        run.proposals_chunk(chunk);
                    } else {
                        run.vertices_chunk(chunk);
                    }
                }
            },
        );
    }
}

/// One [`PbdStencilWorkspace::iterate`]: a proposal pass reads `x` and
/// writes the proposals; a vertex pass reads the proposals and writes `x`;
/// the output reads `x` and writes `positions` and `velocities`. Every
/// item writes only its own chunk's part.
struct PhasedIteration<'a> {
    n: usize,
    level: Simd,
    stride: usize,
    pad: usize,
    offsets: &'a [usize],
    half_rest: &'a [f32],
    inv_weight: &'a [f32],
    pins: &'a [usize],
    x0: &'a [f32],
    inv_dt: f32,
    x: SharedF32,
    first: (SharedF32, usize),
    second: (SharedF32, usize),
    positions: SharedVec3,
    velocities: SharedVec3,
}

impl PhasedIteration<'_> {
    /// Chunk `c`'s first vertex and length.
    fn span(&self, c: usize) -> (usize, usize) {
        let start = c * CHUNK;
        (start, CHUNK.min(self.n - start))
    }

    /// One proposal array, whole, as the vertex pass reads it.
    ///
    /// # Safety
    /// Nothing writes it meanwhile.
    unsafe fn read(&self, (data, len): (SharedF32, usize)) -> Terms<'_> {
        Terms {
            data: unsafe { data.slice(0, len) },
            stride: self.stride,
            pad: self.pad,
            offsets: self.offsets,
        }
    }

    /// The proposals of the springs that start in chunk `c`.
    ///
    /// # Safety
    /// Runs in a proposal phase.
    unsafe fn proposals_chunk(&self, c: usize) {
        let (n, x) = (self.n, self.x);
        let (start, len) = self.span(c);
        for (f, &o) in self.offsets.iter().enumerate() {
            // Springs start at `a < n − o`.
            let m = (n - o).saturating_sub(start).min(len);
            // SAFETY: nothing writes the positions in this phase (and
            // `start + o + m ≤ n`); chunk `c`'s proposals are this item's.
            let ends = |comp: usize| unsafe {
                (
                    x.slice(comp * n + start, m),
                    x.slice(comp * n + start + o, m),
                )
            };
            let out = |(data, _): (SharedF32, usize)| {
                // SAFETY: chunk `c`'s proposals of family `f` are this
                // item's alone in a proposal phase.
                [0, 1, 2].map(|comp| unsafe {
                    data.slice_mut((3 * f + comp) * self.stride + self.pad + start, len)
                })
            };
            let (mut first, mut second) = (out(self.first), out(self.second));
            proposals(
                self.level,
                [ends(0), ends(1), ends(2)],
                &self.half_rest[f * n + start..f * n + start + m],
                first.each_mut().map(|p| &mut p[..m]),
                second.each_mut().map(|p| &mut p[..m]),
            );
            for p in first.into_iter().chain(second) {
                p[m..].fill(0.0);
            }
        }
    }

    /// The vertex update of chunk `c`.
    ///
    /// # Safety
    /// Runs in a vertex phase.
    unsafe fn vertices_chunk(&self, c: usize) {
        let n = self.n;
        let (start, len) = self.span(c);
        // SAFETY: nothing writes the proposals in a vertex phase; the
        // chunk's positions are this item's.
        let (first, second) = unsafe { (self.read(self.first), self.read(self.second)) };
        let w = &self.inv_weight[start..start + len];
        // The chunk's pinned vertices.
        let pins = &self.pins[self.pins.partition_point(|&p| p < start)
            ..self.pins.partition_point(|&p| p < start + len)];
        for comp in 0..3 {
            // SAFETY: the chunk's positions are this item's alone in a
            // vertex phase.
            let x = unsafe { self.x.slice_mut(comp * n + start, len) };
            vertices(self.level, &first, &second, comp, start, x, w);
            // Pinned vertices never move: back to where the step began.
            for &p in pins {
                x[p - start] = self.x0[comp * n + p];
            }
        }
    }

    /// Chunk `c`'s positions out, and its moves over `dt` added to the
    /// velocities.
    ///
    /// # Safety
    /// Runs in the output phase.
    unsafe fn output_chunk(&self, c: usize) {
        let n = self.n;
        let (start, len) = self.span(c);
        // SAFETY: nothing writes `x` in this phase; the chunk's outputs
        // are this item's.
        let xs = [0, 1, 2].map(|comp| unsafe { self.x.slice(comp * n + start, len) });
        let x0 = [0, 1, 2].map(|comp| &self.x0[comp * n + start..comp * n + start + len]);
        let (positions, velocities) = unsafe {
            (
                std::slice::from_raw_parts_mut(self.positions.0.add(start), len),
                std::slice::from_raw_parts_mut(self.velocities.0.add(start), len),
            )
        };
        let w = &self.inv_weight[start..start + len];
        for i in 0..len {
            if w[i] == 0.0 {
                continue;
            }
            let p = Vec3A::new(xs[0][i], xs[1][i], xs[2][i]);
            let p0 = Vec3A::new(x0[0][i], x0[1][i], x0[2][i]);
            velocities[i] += (p - p0) * self.inv_dt;
            positions[i] = p;
        }
    }
}

type Out<'a> = [&'a mut [f32]; 3];

at_level! {
    /// The proposal kernel at `level` (see [`proposals_kernel`]).
    fn proposals(ends: Ends<'_>, half_rest: &[f32], first: Out<'_>, second: Out<'_>) => proposals_kernel
}

/// Each spring's proposals `mid ± d·L/(2l)` for its first and its second
/// end (`mid = ½(x_a + x_b)`, `d = x_a − x_b`, `l = ‖d‖`, the scale 0 for a
/// zero length): the general pass's operations in its order. Zero where
/// there is no spring (`half_rest` < 0).
#[inline(always)]
fn proposals_kernel(ends: Ends<'_>, half_rest: &[f32], first: Out<'_>, second: Out<'_>) {
    let m = half_rest.len();
    let [(ax, bx), (ay, by), (az, bz)] = ends;
    let (ax, bx, ay, by, az, bz) = (&ax[..m], &bx[..m], &ay[..m], &by[..m], &az[..m], &bz[..m]);
    let [fx, fy, fz] = first;
    let [sx, sy, sz] = second;
    let (fx, fy, fz) = (&mut fx[..m], &mut fy[..m], &mut fz[..m]);
    let (sx, sy, sz) = (&mut sx[..m], &mut sy[..m], &mut sz[..m]);
    for i in 0..m {
        let (dx, dy, dz) = (ax[i] - bx[i], ay[i] - by[i], az[i] - bz[i]);
        let l2 = (dx * dx + dy * dy) + dz * dz;
        let h = half_rest[i];
        // Computed for every lane, then selected: no branch in the loop.
        let raw = h / l2.sqrt();
        let scale = if l2 > 0.0 { raw } else { 0.0 };
        let keep = h >= 0.0;
        let (mx, my, mz) = (
            0.5 * (ax[i] + bx[i]),
            0.5 * (ay[i] + by[i]),
            0.5 * (az[i] + bz[i]),
        );
        let (hx, hy, hz) = (dx * scale, dy * scale, dz * scale);
        fx[i] = if keep { mx + hx } else { 0.0 };
        fy[i] = if keep { my + hy } else { 0.0 };
        fz[i] = if keep { mz + hz } else { 0.0 };
        sx[i] = if keep { mx - hx } else { 0.0 };
        sy[i] = if keep { my - hy } else { 0.0 };
        sz[i] = if keep { mz - hz } else { 0.0 };
    }
}

at_level! {
    /// The vertex kernel at `level` (see [`vertices_by_families`]), for
    /// component `comp` of the vertices from `start`.
    fn vertices(
        first: &Terms<'_>,
        second: &Terms<'_>,
        comp: usize,
        start: usize,
        x: &mut [f32],
        w: &[f32],
    ) => vertices_by_families
}

/// [`vertices_kernel`] for the stencil's number of families (a constant in
/// each copy, so its sum unrolls).
#[inline(always)]
fn vertices_by_families(
    first: &Terms<'_>,
    second: &Terms<'_>,
    comp: usize,
    start: usize,
    x: &mut [f32],
    w: &[f32],
) {
    let at = (first, second, comp, start, x, w);
    match first.offsets.len() {
        1 => vertices_kernel::<1>(at),
        2 => vertices_kernel::<2>(at),
        3 => vertices_kernel::<3>(at),
        4 => vertices_kernel::<4>(at),
        5 => vertices_kernel::<5>(at),
        6 => vertices_kernel::<6>(at),
        7 => vertices_kernel::<7>(at),
        _ => vertices_kernel::<{ crate::solver::engine::stencil::MAX_FAMILIES }>(at),
    }
}

/// `x ← (0.2·x + Σ proposals)·w`, the proposals summed family by family
/// (a pinned vertex, `w = 0`, is then 0 until the caller restores it).
#[inline(always)]
fn vertices_kernel<const F: usize>(
    (first, second, comp, start, x, w): (&Terms<'_>, &Terms<'_>, usize, usize, &mut [f32], &[f32]),
) {
    let len = x.len();
    let w = &w[..len];
    let a: [&[f32]; F] = std::array::from_fn(|f| &first.runs(f, comp, start, len).0[..len]);
    let b: [&[f32]; F] = std::array::from_fn(|f| &second.runs(f, comp, start, len).1[..len]);
    // Every vertex stored, pinned ones too (their `w = 0`): a store kept
    // only where `w ≠ 0` compiles to a masked store, which made this loop
    // 2× slower on the perf page's AMD EPYC. The caller puts the pinned
    // vertices back.
    for i in 0..len {
        let mut sum = a[0][i] + b[0][i];
        for f in 1..F {
            sum += a[f][i] + b[f][i];
        }
        x[i] = (SELF_WEIGHT * x[i] + sum) * w[i];
    }
}
