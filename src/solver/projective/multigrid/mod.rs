//! Smoothed-aggregation algebraic multigrid (Vaněk, Mandel, Brezina 1996)
//! for projective dynamics' global matrix on large cloths.
//!
//! The global matrix `S = M/h² + Σ k_e A_eᵀA_e` is a weighted graph
//! Laplacian plus a positive diagonal. A direct solve of it reads the whole
//! Cholesky factor twice per iteration: at 201² that is 15 MB, and the solve
//! is bound by the latency of its short supernode columns (`docs/perf.md`).
//! A multigrid V-cycle costs a few sparse products with `S` and reduces the
//! error by a fixed factor whatever the stiffness, and projective dynamics
//! needs no exact global solve: started from the current iterate, one cycle
//! per iteration keeps the iteration's fixed point (`S x = b(x)`) and most of
//! its progress.
//!
//! The hierarchy is built from `S` alone (no grid is needed, so any mesh
//! works):
//! - **aggregates**: greedy, each a vertex and its strongly connected
//!   neighbours (`|s_ij| ≥ θ √(s_ii s_jj)`), then the rest joined to a
//!   neighbouring aggregate;
//! - **prolongation**: the piecewise-constant one smoothed by one damped
//!   Jacobi step, `P = (I − ω D⁻¹ S) P₀`, `ω = 4/(3λ)` with `λ` the
//!   Gershgorin bound on `D⁻¹S`'s spectrum;
//! - **coarse matrices**: Galerkin, `S_c = Pᵀ S P`, until at most
//!   [`COARSEST`] unknowns remain, or until aggregation stalls (a level
//!   whose off-diagonal entries are all weak, as when `M/h²` dominates the
//!   springs: a heavy or soft cloth, or the guard's halved steps);
//! - **a changed diagonal** (a penalty sphere's contacts, each step they
//!   change) keeps the aggregates and prolongations: each coarse matrix
//!   takes the Galerkin image of the change, `Pᵀ ΔS P`, and only the
//!   coarsest factor is made again (`Multigrid::set_diagonal`), with the
//!   same iterations and per-step error as a new hierarchy per change, at
//!   a fraction of its cost (`docs/measurements.md`). The
//!   prolongations stay those of the matrix without contacts, so where a
//!   penalty dominates the diagonal a cycle gains a little less (the
//!   assignment's 80² cloth under its sweeping sphere: 9 of 600 steps
//!   flagged as not converged, against none);
//! - **the coarsest level** is solved exactly: by a dense Cholesky factor
//!   up to [`DENSE_MAX`] unknowns, by faer's sparse Cholesky above (a
//!   stalled finest level makes the cycle the direct solve).
//!
//! The cycle is a V(1,1) with damped Jacobi smoothing (weight `ω` as above)
//! on the three coordinates at once, in `f32` (the caller solves for a
//! small correction: see [`Multigrid::solve`]); a cycle from zero skips the
//! finest level's pre-smoothing, so its first residual is the right-hand
//! side itself. On a grid cloth the finest level runs on the cloth's
//! stencil ([`FineStencil`]): structure-of-arrays residuals with no
//! indices, compiled for the baseline, AVX2 and AVX-512 and chosen at run
//! time; every operation is elementwise in a fixed order, so every level
//! gives the same bits. The coarser products are serial.
//!
//! Hand-written rather than a crate: `nalgebra-sparse-linalg` (feature
//! `amg`) and `scirs2-sparse` have algebraic multigrid, but on their own
//! matrix types (a second sparse stack beside faer) and for one `f64`
//! right-hand side at a time, while this solve needs three columns in
//! `f32` and its finest level on the cloth's stencil. Not benchmarked
//! against them.

use bevy::math::{DVec3, Vec3A};

use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};

use crate::solver::SolveError;
use crate::solver::engine::cholesky::{SparseCholesky, cholesky_in_place};
use crate::solver::engine::simd::Simd;
use crate::solver::engine::stencil::residual::{StencilMatrix, stencil_residual};

mod coarsening;

use coarsening::{Csr, aggregate, diagonal, product, prolongation, residual};

/// Coarsening stops at or below this many unknowns.
pub(super) const COARSEST: usize = 32;

/// A coarsest level of at most this many unknowns is solved by a dense
/// Cholesky factor, a larger one (left by stalled coarsening) by a sparse
/// one: a stalled aggregation can leave thousands of unknowns (a heavy
/// 101² sheet under the guard's substeps once left all 10199), whose dense
/// factor takes minutes and hundreds of megabytes.
pub(super) const DENSE_MAX: usize = 256;

/// One level above the coarsest: its matrix, smoother and transfer to the
/// next level, and the next level's vectors.
#[derive(Clone, Debug, Default)]
struct Level {
    a: Csr,
    /// `ω / s_ii` per row, and `ω`.
    smooth: Vec<f32>,
    omega: f64,
    /// Prolongation (this level's rows × the next level's) and its
    /// transpose.
    p: Csr,
    pt: Csr,
    /// Residual on this level.
    r: Vec<Vec3A>,
    /// The next level's solution and right-hand side.
    xc: Vec<Vec3A>,
    bc: Vec<Vec3A>,
}

/// The coarsest level: its matrix's Cholesky factor, dense up to
/// [`DENSE_MAX`] unknowns, sparse above.
#[derive(Default)]
struct Coarse {
    /// `L` (row-major, lower), `n × n`, when dense.
    l: Vec<f64>,
    n: usize,
    /// The dense solve's `f64` scratch.
    y: Vec<DVec3>,
    /// The sparse factor, and its right-hand sides (`n×3`, column-major).
    sparse: Option<SparseCholesky>,
    xyz: Vec<f64>,
}

impl std::fmt::Debug for Coarse {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Coarse")
            .field("n", &self.n)
            .field("sparse", &self.sparse.is_some())
            .finish()
    }
}

impl Coarse {
    /// The factor of `a` (rows; symmetric, both triangles).
    fn new(a: &Csr) -> Result<Self, SolveError> {
        let n = a.rows();
        if n > DENSE_MAX {
            // `a` is symmetric: its rows are its columns, each entry once
            // (`S` is built so, and Galerkin products sum into one slot per
            // column), but a product's rows are not sorted, as faer needs.
            let (mut ptr, mut idx, mut val) = (vec![0], Vec::new(), Vec::new());
            let mut row: Vec<(usize, f64)> = Vec::new();
            for i in 0..n {
                let (cols, vals) = a.row(i);
                row.clear();
                row.extend(cols.iter().map(|&j| j as usize).zip(vals.iter().copied()));
                row.sort_by_key(|e| e.0);
                idx.extend(row.iter().map(|e| e.0));
                val.extend(row.iter().map(|e| e.1));
                ptr.push(idx.len());
            }
            let symbolic = SymbolicSparseColMatRef::new_checked(n, n, &ptr, None, &idx);
            let mut factor = SparseCholesky::default();
            factor.factorize_llt(SparseColMatRef::new(symbolic, &val), 3)?;
            return Ok(Self {
                n,
                sparse: Some(factor),
                xyz: vec![0.0; 3 * n],
                ..Self::default()
            });
        }
        let mut l = vec![0.0; n * n];
        for i in 0..n {
            let (cols, vals) = a.row(i);
            for (&j, &v) in cols.iter().zip(vals) {
                l[i * n + j as usize] += v;
            }
        }
        if !cholesky_in_place(&mut l, n) {
            return Err(SolveError::NotPositiveDefinite);
        }
        Ok(Self {
            l,
            n,
            y: Vec::with_capacity(n),
            ..Self::default()
        })
    }

    /// Solves `L Lᵀ x = x` in place (in `f64`). A sparse solve that is not
    /// finite leaves `x` NaN, for the guard to report.
    fn solve(&mut self, x: &mut [Vec3A]) {
        if let Some(factor) = &mut self.sparse {
            let n = self.n;
            for (i, v) in x.iter().enumerate() {
                let v = v.as_dvec3();
                (self.xyz[i], self.xyz[n + i], self.xyz[2 * n + i]) = (v.x, v.y, v.z);
            }
            if factor
                .solve_factored_xyz(&mut self.xyz, false, Simd::Auto)
                .is_err()
            {
                x.fill(Vec3A::NAN);
                return;
            }
            for (i, x) in x.iter_mut().enumerate() {
                *x = DVec3::new(self.xyz[i], self.xyz[n + i], self.xyz[2 * n + i]).as_vec3a();
            }
            return;
        }
        let (l, n, y) = (&self.l, self.n, &mut self.y);
        y.clear();
        y.extend(x.iter().map(|v| v.as_dvec3()));
        for i in 0..n {
            let mut v = y[i];
            for k in 0..i {
                v -= l[i * n + k] * y[k];
            }
            y[i] = v / l[i * n + i];
        }
        for i in (0..n).rev() {
            let mut v = y[i];
            for k in i + 1..n {
                v -= l[k * n + i] * y[k];
            }
            y[i] = v / l[i * n + i];
        }
        for (x, y) in x.iter_mut().zip(y.iter()) {
            *x = y.as_vec3a();
        }
    }
}

/// The finest matrix as a stencil, for a cloth whose springs form one
/// ([`Multigrid::build`]'s `fine`): vertex `i`'s row is
/// `s_ii x_i − Σ_f (c_f[i] x_{i+o_f} + c_f[i−o_f] x_{i−o_f})`, over all `n`
/// vertices (pinned ones too: their rows are decoupled and their
/// corrections stay zero).
#[derive(Clone, Debug)]
pub(super) struct FineStencil {
    /// The families' offsets `o_f`.
    pub offsets: Vec<usize>,
    /// Per family, per vertex `i`: the stiffness of the spring
    /// `(i, i + o_f)` if there is one and both its ends are free, else 0
    /// (`n` per family).
    pub coeffs: Vec<Vec<f32>>,
    /// The free vertex of each row of the matrix `build` is given.
    pub free: Vec<u32>,
    /// Vertices.
    pub n: usize,
}

/// The finest level's cycle on structure-of-arrays vectors (see
/// [`FineStencil`]): no indices in its residuals, and contiguous streams
/// the compiler vectorises at the CPU's widest SIMD (the level of
/// [`StepParams::simd`](super::StepParams::simd), chosen at run time).
#[derive(Clone, Debug, Default)]
struct Fine {
    op: StencilMatrix,
    /// Per vertex: `ω / s_ii` (0 where pinned).
    smooth: Vec<f32>,
    free: Vec<u32>,
    /// The prolongation's transpose with its columns as vertices.
    pt: Csr,
    /// `x` (padded), `b` and `r`, per coordinate.
    x: [Vec<f32>; 3],
    b: [Vec<f32>; 3],
    r: [Vec<f32>; 3],
}

impl Fine {
    fn new(stencil: FineStencil, a: &Csr, omega: f64, pt: &Csr) -> Self {
        let FineStencil {
            offsets,
            coeffs,
            free,
            n,
        } = stencil;
        let pad = offsets.iter().copied().max().unwrap_or(0);
        let padded = |v: &[f32]| {
            let mut out = vec![0.0; n + 2 * pad];
            out[pad..pad + n].copy_from_slice(v);
            out
        };
        let mut diag = vec![1.0; n];
        let mut smooth = vec![0.0; n];
        for (f, d) in diagonal(a).into_iter().enumerate() {
            let i = free[f] as usize;
            diag[i] = d as f32;
            smooth[i] = (omega / d) as f32;
        }
        let mut pt = pt.clone();
        for j in &mut pt.idx {
            *j = free[*j as usize];
        }
        pt.cols = n;
        Self {
            op: StencilMatrix {
                coeffs: coeffs.iter().map(|c| padded(c)).collect(),
                offsets,
                pad,
                diag,
            },
            smooth,
            free,
            pt,
            x: core::array::from_fn(|_| vec![0.0; n + 2 * pad]),
            b: core::array::from_fn(|_| vec![0.0; n]),
            r: core::array::from_fn(|_| vec![0.0; n]),
        }
    }

    /// `r = b − S x`, each coordinate.
    fn residual(&mut self, simd: Simd) {
        for c in 0..3 {
            stencil_residual(simd, &self.op, &self.x[c], &self.b[c], &mut self.r[c]);
        }
    }

    /// `x += ω D⁻¹ r`, each coordinate.
    fn jacobi(&mut self) {
        let p = self.op.pad;
        for c in 0..3 {
            let x = &mut self.x[c][p..];
            for ((x, r), w) in x.iter_mut().zip(&self.r[c]).zip(&self.smooth) {
                *x += *w * *r;
            }
        }
    }

    /// One V(1,1) cycle with `level` (this matrix's hierarchy level, for
    /// its prolongation) and the levels below.
    fn cycle(
        &mut self,
        simd: Simd,
        (level, rest): (&mut Level, &mut [Level]),
        coarse: &mut Coarse,
        zero: bool,
    ) {
        let p = self.op.pad;
        // From zero the finest level skips its pre-smoothing: the residual
        // is `b` itself, one product with `S` fewer (as close to the exact
        // step in the tests and the report's 101² scene).
        if zero {
            for x in &mut self.x {
                x[p..].fill(0.0);
            }
        } else {
            self.residual(simd);
            self.jacobi();
            self.residual(simd);
        }
        let [rx, ry, rz] = if zero { &self.b } else { &self.r };
        for (k, bc) in level.bc.iter_mut().enumerate() {
            let r = self.pt.ptr[k]..self.pt.ptr[k + 1];
            let mut acc = Vec3A::ZERO;
            for (&j, &v) in self.pt.idx[r.clone()].iter().zip(&self.pt.val32[r]) {
                let j = j as usize;
                acc += v * Vec3A::new(rx[j], ry[j], rz[j]);
            }
            *bc = acc;
        }
        vcycle(rest, coarse, &mut level.xc, &level.bc, (true, false));
        let [x0, x1, x2] = &mut self.x;
        for (f, &i) in self.free.iter().enumerate() {
            let r = level.p.ptr[f]..level.p.ptr[f + 1];
            let mut acc = Vec3A::ZERO;
            for (&j, &v) in level.p.idx[r.clone()].iter().zip(&level.p.val32[r]) {
                acc += v * level.xc[j as usize];
            }
            let i = p + i as usize;
            x0[i] += acc.x;
            x1[i] += acc.y;
            x2[i] += acc.z;
        }
        self.residual(simd);
        self.jacobi();
    }
}

/// The multigrid hierarchy of one matrix (see the [module docs](self)).
#[derive(Debug, Default)]
pub(super) struct Multigrid {
    levels: Vec<Level>,
    /// The coarsest matrix, and its factor.
    coarsest: Csr,
    coarse: Coarse,
    /// The finest level's cycle on its stencil, when it has one (and the
    /// hierarchy has more than the dense level).
    fine: Option<Fine>,
    /// The SIMD level of the fine cycle.
    simd: Simd,
    /// The solution and right-hand side of [`run`](Self::run) without the
    /// fine stencil.
    x: Vec<Vec3A>,
    b: Vec<Vec3A>,
}

impl Multigrid {
    /// The hierarchy of the symmetric positive definite `m×m` matrix given
    /// by rows (`ptr`, `idx`, `val`; the full matrix, both triangles). A
    /// coarsest matrix that is not positive definite (only if `S` is not)
    /// is [`SolveError`].
    ///
    /// With `fine`, the finest level's cycles run on its stencil
    /// ([`FineStencil`]).
    pub(super) fn build(
        ptr: &[usize],
        idx: &[usize],
        val: &[f64],
        mut fine_stencil: Option<FineStencil>,
    ) -> Result<Self, SolveError> {
        let mut a = Csr {
            ptr: ptr.to_vec(),
            idx: idx.iter().map(|&j| j as u32).collect(),
            val: val.to_vec(),
            cols: ptr.len() - 1,
            val32: Vec::new(),
        };
        let mut levels = Vec::new();
        let mut fine = None;
        while a.rows() > COARSEST {
            let diag = diagonal(&a);
            let (aggregate_of, aggregates) = aggregate(&a, &diag);
            if aggregates * 5 > a.rows() * 4 {
                // Coarsening stalled (a graph with few strong links).
                break;
            }
            // Gershgorin: D⁻¹A's eigenvalues are at most λ.
            let lambda = (0..a.rows())
                .map(|i| a.row(i).1.iter().map(|v| v.abs()).sum::<f64>() / diag[i])
                .fold(0.0f64, f64::max);
            let omega = 4.0 / (3.0 * lambda);
            let p = prolongation(&a, &diag, &aggregate_of, aggregates, omega);
            let pt = p.transpose();
            if levels.is_empty()
                && let Some(stencil) = fine_stencil.take()
            {
                fine = Some(Fine::new(stencil, &a, omega, &pt.clone().for_cycles()));
            }
            let coarse = pt.mul(&a.mul(&p));
            let n = a.rows();
            levels.push(Level {
                smooth: diag.iter().map(|d| (omega / d) as f32).collect(),
                omega,
                a: a.for_cycles(),
                p: p.for_cycles(),
                pt: pt.for_cycles(),
                r: vec![Vec3A::ZERO; n],
                xc: vec![Vec3A::ZERO; aggregates],
                bc: vec![Vec3A::ZERO; aggregates],
            });
            a = coarse;
        }
        Ok(Self {
            levels,
            coarse: Coarse::new(&a)?,
            coarsest: a,
            x: vec![Vec3A::ZERO; if fine.is_some() { 0 } else { ptr.len() - 1 }],
            b: vec![Vec3A::ZERO; if fine.is_some() { 0 } else { ptr.len() - 1 }],
            fine,
            simd: Simd::Auto.resolve(),
        })
    }

    /// Sets diagonal entries of the finest matrix (`(row, value)`, rows
    /// increasing), as a penalty sphere's contacts change them, without a
    /// new hierarchy: the prolongations are kept and each coarser matrix
    /// takes the Galerkin image of the change, `ΔS_c = Pᵀ ΔS P`, so that it
    /// stays `Pᵀ S P` of the new `S`; the smoothing weights follow the new
    /// diagonals (their `ω` stays: a larger diagonal only lowers the
    /// Gershgorin bound it came from), and the coarsest factor is made
    /// again. (Keeping the coarser matrices as they were made the cycle
    /// diverge: per-step error 36 instead of 0.04 on the report's sphere
    /// scene at 101².) False, with the hierarchy half changed, if a change
    /// falls outside a level's pattern (not expected: the caller builds
    /// anew); a coarsest matrix that is not positive definite is
    /// [`SolveError`].
    pub(super) fn set_diagonal(&mut self, changes: &[(usize, f64)]) -> Result<bool, SolveError> {
        type Delta = std::collections::BTreeMap<(u32, u32), f64>;
        // Adds `delta` to `a`; false if an entry is not in its pattern
        // (never for a Galerkin change, but then the caller builds anew).
        fn add(a: &mut Csr, delta: &Delta) -> bool {
            for (&(i, j), &v) in delta {
                let Some(at) = a.position(i as usize, j as usize) else {
                    return false;
                };
                a.set_at(at, a.val[at] + v);
            }
            true
        }
        // The change at the finest level: the diagonal set exactly.
        let mut delta = Delta::new();
        let finest = self
            .levels
            .first_mut()
            .map_or(&mut self.coarsest, |l| &mut l.a);
        for &(f, d) in changes {
            let Some(at) = finest.position(f, f) else {
                return Ok(false);
            };
            delta.insert((f as u32, f as u32), d - finest.val[at]);
            finest.set_at(at, d);
        }
        for (at, level) in self.levels.iter_mut().enumerate() {
            if at > 0 && !add(&mut level.a, &delta) {
                return Ok(false);
            }
            for &(i, _) in delta.keys().filter(|(i, j)| i == j) {
                let Some(pos) = level.a.position(i as usize, i as usize) else {
                    return Ok(false);
                };
                let d = level.a.val[pos];
                level.smooth[i as usize] = (level.omega / d) as f32;
                if let (0, Some(fine)) = (at, &mut self.fine) {
                    let v = fine.free[i as usize] as usize;
                    fine.op.diag[v] = d as f32;
                    fine.smooth[v] = level.smooth[i as usize];
                }
            }
            // `Pᵀ Δ P`, summed in a fixed order.
            let mut next = Delta::new();
            for (&(i, j), &v) in &delta {
                let (ai, pi) = level.p.row(i as usize);
                let (aj, pj) = level.p.row(j as usize);
                for (&a, &pa) in ai.iter().zip(pi) {
                    for (&b, &pb) in aj.iter().zip(pj) {
                        *next.entry((a, b)).or_insert(0.0) += pa * v * pb;
                    }
                }
            }
            delta = next;
        }
        if !self.levels.is_empty() && !add(&mut self.coarsest, &delta) {
            return Ok(false);
        }
        self.coarse = Coarse::new(&self.coarsest)?;
        Ok(true)
    }

    /// How many levels, the dense one included.
    pub(super) fn depth(&self) -> usize {
        self.levels.len() + 1
    }

    /// Sets the fine cycle's SIMD level.
    pub(super) fn configure(&mut self, simd: Simd) {
        self.simd = simd.resolve();
    }

    /// `cycles` V-cycles on `S x = b` from zero (`x` is overwritten).
    ///
    /// From zero, not from a guess: the cycles run in `f32`, so the caller
    /// solves for the correction to its guess from the guess's residual
    /// (computed in `f64`). A guess of size `|x|` would leave an error of
    /// about `ε·|x|`; a correction's is `ε·|δ|`.
    #[cfg(test)]
    pub(super) fn solve(&mut self, x: &mut [Vec3A], b: &[Vec3A], cycles: u32) {
        let free = self.fine.as_ref().map(|f| f.free.clone());
        let vertex = |f: usize| free.as_ref().map_or(f, |free| free[f] as usize);
        for (f, b) in b.iter().enumerate() {
            self.set_rhs(f, vertex(f), *b);
        }
        self.run(cycles);
        for (f, x) in x.iter_mut().enumerate() {
            *x = self.solution(f, vertex(f));
        }
    }

    /// Sets the right-hand side of row `f` (vertex `i`, for the fine
    /// stencil) for [`run`](Self::run).
    #[inline]
    pub(super) fn set_rhs(&mut self, f: usize, i: usize, b: Vec3A) {
        match &mut self.fine {
            Some(fine) => (fine.b[0][i], fine.b[1][i], fine.b[2][i]) = (b.x, b.y, b.z),
            None => self.b[f] = b,
        }
    }

    /// Row `f`'s (vertex `i`'s) solution after [`run`](Self::run).
    #[inline]
    pub(super) fn solution(&self, f: usize, i: usize) -> Vec3A {
        match &self.fine {
            Some(fine) => {
                let i = fine.op.pad + i;
                Vec3A::new(fine.x[0][i], fine.x[1][i], fine.x[2][i])
            }
            None => self.x[f],
        }
    }

    /// `cycles` V-cycles from zero on the right-hand side set by
    /// [`set_rhs`](Self::set_rhs) (see [`solve`](Self::solve)).
    pub(super) fn run(&mut self, cycles: u32) {
        for c in 0..cycles {
            match &mut self.fine {
                Some(fine) => {
                    let (level, rest) = self.levels.split_first_mut().expect("a fine level");
                    fine.cycle(self.simd, (level, rest), &mut self.coarse, c == 0);
                }
                None => vcycle(
                    &mut self.levels,
                    &mut self.coarse,
                    &mut self.x,
                    &self.b,
                    (c == 0, true),
                ),
            }
        }
    }
}

/// One V(1,1) cycle on the first of `levels` (or the dense solve when none
/// is left). `zero`: `x` is zero on entry (its first residual is `b`);
/// `finest`: these are the finest level's vectors (which skip the
/// pre-smoothing from zero, as [`Fine::cycle`] does).
fn vcycle(
    levels: &mut [Level],
    coarse: &mut Coarse,
    x: &mut [Vec3A],
    b: &[Vec3A],
    (zero, finest): (bool, bool),
) {
    let Some((level, rest)) = levels.split_first_mut() else {
        x.copy_from_slice(b);
        coarse.solve(x);
        return;
    };
    let Level {
        a,
        smooth,
        p,
        pt,
        r,
        xc,
        bc,
        ..
    } = level;
    // The finest level from zero skips its pre-smoothing, as `Fine::cycle`.
    let from_b = zero && finest;
    // Pre-smoothing.
    if from_b {
        x.fill(Vec3A::ZERO);
    } else if zero {
        for ((x, b), w) in x.iter_mut().zip(b).zip(smooth.iter()) {
            *x = *w * *b;
        }
    } else {
        residual(a, x, b, r);
        jacobi(x, r, smooth);
    }
    // Coarse-grid correction.
    if from_b {
        product(pt, b, bc);
    } else {
        residual(a, x, b, r);
        product(pt, r, bc);
    }
    vcycle(rest, coarse, xc, bc, (true, false));
    product(p, xc, r);
    for (x, c) in x.iter_mut().zip(r.iter()) {
        *x += *c;
    }
    // Post-smoothing.
    residual(a, x, b, r);
    jacobi(x, r, smooth);
}

fn jacobi(x: &mut [Vec3A], r: &[Vec3A], smooth: &[f32]) {
    for ((x, r), w) in x.iter_mut().zip(r).zip(smooth) {
        *x += *w * *r;
    }
}

#[cfg(test)]
mod tests;
