//! The global step of projective dynamics: `S` built and factorised (or its
//! multigrid hierarchy), penalty contacts placed in it, the right-hand side
//! made and solved.

use bevy::math::{DVec3, Vec3A};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};

use super::early_stop::ErrorSlots;
use super::friction::{Friction, term_at};
use super::multigrid::{FineStencil, Multigrid};
use super::{FactorKey, PINNED, ProjectiveWorkspace};
use crate::collision::PenaltySphere;
use crate::model::stencil::NONE;
use crate::model::{Adjacency, ClothModel};
use crate::solver::chebyshev::blend;
use crate::solver::engine::cholesky::SparseCholesky;
use crate::solver::engine::lane_factor::LaneFactor;
use crate::solver::{SolveError, StepParams};

impl ProjectiveWorkspace {
    /// How many times the global matrix was factorised (or its multigrid
    /// hierarchy built).
    pub fn factorizations(&self) -> u32 {
        self.factorizations
    }

    /// Builds and factorises `S` (or builds its multigrid hierarchy) unless
    /// the key still matches.
    /// `cycles`: the multigrid's V-cycles per iteration, or `None` for the
    /// direct solve.
    pub(super) fn prepare(
        &mut self,
        model: &ClothModel,
        params: &StepParams,
        cycles: Option<u32>,
    ) -> Result<(), SolveError> {
        if self
            .key
            .as_ref()
            .is_some_and(|k| k.matches(model, params, cycles))
        {
            return Ok(());
        }
        self.key = None;
        self.dof_of.clear();
        self.free.clear();
        for (i, &pinned) in model.pinned().iter().enumerate() {
            if pinned {
                self.dof_of.push(PINNED);
            } else {
                self.dof_of.push(self.free.len() as u32);
                self.free.push(i as u32);
            }
        }
        let springs = model.topology().springs();
        let stiffness = params.stiffness.as_array();
        self.k.clear();
        self.k.extend(
            springs
                .iter()
                .map(|s| f64::from(stiffness[s.kind as usize])),
        );
        self.coeffs.clear();
        self.coeffs
            .extend(springs.iter().map(|s| [0.0, -s.rest_length]));
        // The early stop's `h²/m` per free vertex.
        let h2 = params.dt * params.dt;
        let masses = model.masses();
        self.track.h2_over_m.clear();
        self.track.h2_over_m.extend(
            self.free
                .iter()
                .map(|&i| h2 / f64::from(masses[i as usize])),
        );
        self.track.h2_over_m32.clear();
        self.track
            .h2_over_m32
            .extend(self.track.h2_over_m.iter().map(|&w| w as f32));
        self.pin_links.clear();
        for (s, &k) in springs.iter().zip(&self.k) {
            let (a, b) = (self.dof_of[s.a as usize], self.dof_of[s.b as usize]);
            match (a == PINNED, b == PINNED) {
                (false, true) => self.pin_links.push((a, s.b, k)),
                (true, false) => self.pin_links.push((b, s.a, k)),
                _ => {}
            }
        }
        // Columns of S: the diagonal and one entry per free neighbour,
        // gathered per free vertex over its springs (duplicates summed).
        let inv_h2 = 1.0 / (params.dt * params.dt);
        let adjacency = model.topology().adjacency();
        self.col_ptr.clear();
        self.row_idx.clear();
        self.values.clear();
        let mut column: Vec<(usize, f64)> = Vec::new();
        for &i in &self.free {
            let i = i as usize;
            column.clear();
            let mut diag = f64::from(masses[i]) * inv_h2;
            for inc in adjacency.of(i) {
                let s = springs[inc.spring as usize];
                let k = self.k[inc.spring as usize];
                diag += k;
                let other = if s.a as usize == i { s.b } else { s.a } as usize;
                let j = self.dof_of[other];
                if j != PINNED {
                    column.push((j as usize, -k));
                }
            }
            column.push((self.dof_of[i] as usize, diag));
            column.sort_by_key(|&(r, _)| r);
            self.col_ptr.push(self.row_idx.len());
            for (r, v) in column.drain(..) {
                if self.row_idx.len() > *self.col_ptr.last().unwrap_or(&0)
                    && self.row_idx.last() == Some(&r)
                {
                    *self.values.last_mut().expect("an entry") += v;
                } else {
                    self.row_idx.push(r);
                    self.values.push(v);
                }
            }
        }
        self.col_ptr.push(self.row_idx.len());
        let m = self.free.len();
        self.diag_pos.clear();
        self.diag_base.clear();
        for f in 0..m {
            let column = self.col_ptr[f]..self.col_ptr[f + 1];
            let at = column.start + self.row_idx[column].partition_point(|&r| r < f);
            self.diag_pos.push(at);
            self.diag_base.push(self.values[at]);
        }
        self.contact_k.clear();
        self.contact_k.resize(m, 0.0);
        self.cholesky.reset();
        self.multigrid = cycles.map(|c| (Multigrid::default(), c));
        self.fine_stencil = match model.topology().stencil() {
            Some(stencil) if cycles.is_some() && params.stencil => {
                let n = model.vertex_count();
                let free = |i: usize| self.dof_of[i] != PINNED;
                let coeffs = stencil
                    .offsets
                    .iter()
                    .enumerate()
                    .map(|(f, &o)| {
                        (0..n)
                            .map(|i| match stencil.kinds[f * n + i] {
                                NONE => 0.0,
                                kind if free(i) && free(i + o) => stiffness[kind as usize],
                                _ => 0.0,
                            })
                            .collect()
                    })
                    .collect();
                Some(FineStencil {
                    offsets: stencil.offsets.clone(),
                    coeffs,
                    free: self.free.clone(),
                    n,
                })
            }
            _ => None,
        };
        self.factorize()?;
        self.key = Some(FactorKey::of(model, params, cycles));
        Ok(())
    }

    /// Factorises `S` as it is in `values` (numerically only, once the
    /// symbolic analysis exists).
    pub(super) fn factorize(&mut self) -> Result<(), SolveError> {
        let m = self.free.len();
        if let Some((multigrid, _)) = &mut self.multigrid {
            // `S` is symmetric: its columns are its rows.
            *multigrid = Multigrid::build(
                &self.col_ptr,
                &self.row_idx,
                &self.values,
                self.fine_stencil.clone(),
            )?;
        } else if m > 0 {
            let symbolic =
                SymbolicSparseColMatRef::new_checked(m, m, &self.col_ptr, None, &self.row_idx);
            let matrix = SparseColMatRef::new(symbolic, &self.values);
            self.cholesky.factorize_llt(matrix, 3)?;
        }
        self.factorizations += 1;
        Ok(())
    }

    /// Marks the free vertices near each penalty sphere this step (within a
    /// quarter radius of its surface anywhere between `start` and the
    /// prediction `x̃`) and refactorises `S` if their penalty diagonal
    /// differs from the factor's.
    pub(super) fn place_contacts(
        &mut self,
        x_tilde: &[Vec3A],
        v: &[Vec3A],
        h: f32,
        spheres: &[PenaltySphere],
    ) -> Result<(), SolveError> {
        let m = self.free.len();
        self.near.clear();
        self.near.resize(m, 0);
        self.wanted_k.clear();
        self.wanted_k.resize(m, 0.0);
        for (s, sphere) in spheres.iter().enumerate().take(64) {
            for (f, &i) in self.free.iter().enumerate() {
                let end = x_tilde[i as usize];
                let start = end - h * v[i as usize];
                if sphere.near_segment(start, end) {
                    self.near[f] |= 1 << s;
                    self.wanted_k[f] += f64::from(sphere.stiffness);
                }
            }
        }
        // Self-collision's pairs: each end's diagonal takes `c` per pair it
        // is in (the pair's off-diagonal blocks left out: the pairs change
        // from step to step and are not in `S`'s pattern).
        self.pair_k.clear();
        if !self.pairs.terms.is_empty() {
            self.pair_k.resize(m, 0.0);
        }
        for t in &self.pairs.terms {
            let ends = [Some(t.a), t.own_b()];
            for i in ends.into_iter().flatten() {
                if let Some(&f) = self.dof_of.get(i).filter(|&&f| f != PINNED) {
                    self.pair_k[f as usize] += self.pairs.c;
                }
            }
        }
        for (w, p) in self.wanted_k.iter_mut().zip(&self.pair_k) {
            *w += p;
        }
        if self.wanted_k == self.contact_k {
            return Ok(());
        }
        let mut changes = Vec::new();
        for f in 0..m {
            let d = self.diag_base[f] + self.wanted_k[f];
            if self.wanted_k[f] != self.contact_k[f] {
                changes.push((f, d));
            }
            self.values[self.diag_pos[f]] = d;
        }
        self.contact_k.clone_from(&self.wanted_k);
        // The multigrid takes the new diagonal into its hierarchy: building
        // a new one per change costs far more (`docs/measurements.md`).
        if let Some((multigrid, _)) = &mut self.multigrid
            && multigrid.set_diagonal(&changes)?
        {
            self.factorizations += 1;
            return Ok(());
        }
        self.factorize()
    }
}

impl ProjectiveWorkspace {
    /// The global step: the right-hand side at `x` from each vertex's
    /// `Σ ±k_e·d_e` in `sums` (the stencil kernels), or else from the
    /// projections in `self.d`, solved into `self.rhs`. With the multigrid,
    /// `sums` holds each vertex's spring gradient instead
    /// ([`global_multigrid`](Self::global_multigrid)). `true` (and no
    /// solve) if the early stop's estimate at `x` is within its tolerance.
    pub(super) fn global(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        spheres: &[PenaltySphere],
        sums: Option<&[Vec3A]>,
    ) -> Result<bool, SolveError> {
        self.pair_forces(x);
        if self.multigrid.is_some() {
            return Ok(self.global_multigrid(model, x, spheres, sums));
        }
        let adjacency = model.topology().adjacency();
        let (parallel, simd) = (self.parallel, self.simd);
        let Self {
            free,
            base,
            k,
            d,
            near,
            cholesky,
            rhs,
            track,
            friction,
            friction_at,
            pair_k,
            pair_force,
            ..
        } = self;
        let parts = RhsParts {
            free,
            base,
            k,
            d,
            near,
            adjacency,
            sums,
            spheres,
            friction: (friction, friction_at),
            pairs: (pair_k, pair_force),
            x,
        };
        // A simplicial factor: the right-hand side written straight into
        // its lanes, in its order, and solved there (`Solution` reads it
        // back), sparing `rhs` and `solve3`'s two permuted copies.
        if let Some(lanes) = cholesky.lanes() {
            let (order, b) = lanes.rhs_mut();
            match sums.filter(|_| spheres.is_empty() && pair_k.is_empty()) {
                // The common case on its own loop: through `parts.at` the
                // compiler keeps the general case's branches in it.
                Some(sums) => {
                    for (b, &f) in b.iter_mut().zip(order) {
                        let (base, sum) = (base[f as usize], sums[free[f as usize] as usize]);
                        *b = [
                            base.x + f64::from(sum.x),
                            base.y + f64::from(sum.y),
                            base.z + f64::from(sum.z),
                            0.0,
                        ];
                    }
                }
                None => {
                    for (b, &f) in b.iter_mut().zip(order) {
                        let acc = parts.at(f as usize);
                        *b = [acc.x, acc.y, acc.z, 0.0];
                    }
                }
            }
            // The early stop's estimate in a pass of its own: inside the
            // loops above (the value read as it is written) it was slower.
            if track.on() {
                let (order, b) = lanes.rhs_mut();
                let free_at = |p: usize| order[p] as usize;
                let b_at = |p: usize| DVec3::new(b[p][0], b[p][1], b[p][2]);
                if track.converged(model, x, free, b.len(), free_at, b_at) {
                    return Ok(true);
                }
            }
            return match lanes.solve_in_place(simd.resolve()) {
                true => Ok(false),
                false => Err(SolveError::Factorization),
            };
        }
        let m = free.len();
        for f in 0..m {
            let acc = parts.at(f);
            rhs[f] = acc.x;
            rhs[m + f] = acc.y;
            rhs[2 * m + f] = acc.z;
        }
        if track.on() {
            let b_at = |f: usize| DVec3::new(rhs[f], rhs[m + f], rhs[2 * m + f]);
            if track.converged(model, x, free, m, |f| f, b_at) {
                return Ok(true);
            }
        }
        // x, y and z in one call: it traverses the factor once (serially
        // three single-column solves were 2× slower at 21²–101²).
        cholesky.solve_factored_xyz(rhs, parallel, simd)?;
        Ok(false)
    }
}

/// What the direct global step's right-hand side at one free vertex is
/// made of (see [`ProjectiveWorkspace::global`]).
pub(super) struct RhsParts<'a> {
    free: &'a [u32],
    base: &'a [DVec3],
    k: &'a [f64],
    d: &'a [Vec3A],
    near: &'a [u64],
    adjacency: &'a Adjacency,
    sums: Option<&'a [Vec3A]>,
    spheres: &'a [PenaltySphere],
    friction: (&'a [Friction], &'a [u32]),
    /// Self-collision's pairs: each free vertex's weight, each vertex's
    /// force (empty without pairs).
    pairs: (&'a [f64], &'a [Vec3A]),
    x: &'a [Vec3A],
}

impl RhsParts<'_> {
    /// Free vertex `f`'s right-hand side: its `M/h² x̃ + M g`, pinned
    /// neighbours' and springs' `Σ ±k_e·d_e` and spheres' terms. (Inlined:
    /// as a call its `DVec3` went through memory, which cost more than the
    /// sum.)
    #[inline(always)]
    pub(super) fn at(&self, f: usize) -> DVec3 {
        let i = self.free[f] as usize;
        let mut acc = self.base[f];
        match self.sums {
            Some(sums) => acc += sums[i].as_dvec3(),
            None => {
                let (starts, ends) = self.adjacency.by_side(i);
                for &e in starts {
                    acc += self.k[e as usize] * self.d[e as usize].as_dvec3();
                }
                for &e in ends {
                    acc -= self.k[e as usize] * self.d[e as usize].as_dvec3();
                }
            }
        }
        for (s, sphere) in self.spheres.iter().enumerate() {
            let near = s < 64 && self.near[f] & (1 << s) != 0;
            if near {
                // c·p, p the vertex projected onto the sphere's outside.
                acc += f64::from(sphere.stiffness) * self.x[i].as_dvec3();
            }
            if let Some(contact) = sphere.contact(self.x[i]) {
                acc += contact.force.as_dvec3();
            }
        }
        // Friction's force rides on its contact's `c·p` (see `friction`).
        if let Some((term, c)) = term_at(self.friction, self.near, f) {
            acc += term.force(self.x[i], c).as_dvec3();
        }
        // A pair's `c·x` and its force at the iterate (`c·p` of the pair
        // projected apart, as a sphere's).
        if let (Some(&c), Some(&force)) = (self.pairs.0.get(f), self.pairs.1.get(i)) {
            acc += c * self.x[i].as_dvec3() + force.as_dvec3();
        }
        acc
    }
}

impl ProjectiveWorkspace {
    /// The global step by multigrid: `S x = b` is solved for the correction
    /// `δ = x − x₀` from the current iterate `x₀`, whose right-hand side
    /// `b − S x₀` is the objective's negative gradient at `x₀` (the pinned
    /// neighbours' and the spheres' terms included): with `S δ = −∇Φ(x₀)`
    /// the result is the same iterate as the direct solve's, and the `f32`
    /// cycles round `δ`, not `x`. The spring gradient per vertex comes from
    /// `sums` (the stencil kernels), or else from the projections in
    /// `self.d`.
    pub(super) fn global_multigrid(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        spheres: &[PenaltySphere],
        sums: Option<&[Vec3A]>,
    ) -> bool {
        let masses = model.masses();
        if sums.is_none() {
            self.spring_gradients(model, x);
        }
        // The early stop's estimate: this right-hand side is the gradient.
        let track = self.track.on();
        let mut estimate = ErrorSlots::default();
        let (inv_h2, gravity) = (self.inv_h2 as f32, self.gravity.as_vec3a());
        for (f, &i) in self.free.iter().enumerate() {
            let i = i as usize;
            // In `f32`: `x̃ − x` is exact (near values), and each term is
            // rounded once, as the spring sums are.
            let mass = masses[i];
            let mut r = mass * (inv_h2 * (self.x_tilde[i] - x[i]) + gravity);
            match sums {
                Some(sums) => r -= sums[i],
                None => r -= self.gradient[i].as_vec3a(),
            }
            // A near sphere's `c·p − c·x` is its penalty force; so is a
            // far one's explicit force.
            for sphere in spheres {
                if let Some(contact) = sphere.contact(x[i]) {
                    r += contact.force;
                }
            }
            let terms = (&self.friction[..], &self.friction_at[..]);
            if let Some((term, c)) = term_at(terms, &self.near, f) {
                r += term.force(x[i], c);
            }
            if let Some(&force) = self.pair_force.get(i) {
                r += force;
            }
            if track {
                // In `f32`, as `r` is (an `f64` sum was measurably slower
                // where the whole budget runs).
                let error = r * self.track.h2_over_m32[f];
                let motion = x[i] - self.track.x_start[i];
                estimate.add32(f, error.length_squared(), motion.length_squared());
            }
            if let Some((multigrid, _)) = &mut self.multigrid {
                multigrid.set_rhs(f, i, r);
            }
        }
        let estimate = estimate.sums(self.free.len());
        if track && f64::from(estimate.relative_error(model, self.track.dt)) <= self.track.tolerance
        {
            return true;
        }
        let Some((multigrid, cycles)) = &mut self.multigrid else {
            return false;
        };
        multigrid.configure(self.simd);
        multigrid.run(*cycles);
        false
    }

    /// Each vertex's spring gradient `Σ ±k_e((x_a − x_b) − d_e)` in `f64`,
    /// from the projections in `self.d`, into `self.gradient`: each
    /// spring's term made once and added to both ends (not per vertex over
    /// its springs, which makes each term twice).
    pub(super) fn spring_gradients(&mut self, model: &ClothModel, x: &[Vec3A]) {
        self.gradient.clear();
        self.gradient.resize(x.len(), DVec3::ZERO);
        let springs = model.topology().springs();
        for ((s, &k), d) in springs.iter().zip(&self.k).zip(&self.d) {
            let (a, b) = (s.a as usize, s.b as usize);
            let t = k * ((x[a] - x[b]).as_dvec3() - d.as_dvec3());
            self.gradient[a] += t;
            self.gradient[b] -= t;
        }
    }
}

/// Where the global step's solution is, read once per iteration (see
/// [`ProjectiveWorkspace::global`]).
pub(super) enum Solution<'a> {
    /// The multigrid's correction to the iterate.
    Multigrid(&'a Multigrid),
    /// The simplicial factor's lanes.
    Lanes(&'a LaneFactor),
    /// `rhs`, column-major.
    Columns(&'a [f64]),
}

impl<'a> Solution<'a> {
    /// From the workspace's `multigrid`, `cholesky` and `rhs` (borrowed
    /// alone, so that the iteration can write the others).
    pub(super) fn of(
        multigrid: &'a Option<(Multigrid, u32)>,
        cholesky: &'a SparseCholesky,
        rhs: &'a [f64],
    ) -> Self {
        match (multigrid, cholesky.lanes_ref()) {
            (Some((multigrid, _)), _) => Self::Multigrid(multigrid),
            (None, Some(lanes)) => Self::Lanes(lanes),
            (None, None) => Self::Columns(rhs),
        }
    }

    /// Takes the global step's solution `x̂` as the new iterate of every
    /// free vertex (`free[f]`): with `CHEBYSHEV`, `ω(x̂ − x_prev) + x_prev`,
    /// the iterate moving to `x_prev`. Returns `Σ |x̂ − x|²` if `MEASURE`.
    /// Each way of storing `x̂` has its own loop, in its own order (the
    /// lanes' order for the simplicial factor), so no loop branches on it.
    #[inline(always)]
    pub(super) fn blend<const CHEBYSHEV: bool, const MEASURE: bool>(
        &self,
        free: &[u32],
        x: &mut [Vec3A],
        x_prev: &mut [Vec3A],
        omega: f32,
    ) -> f64 {
        let mut update = 0.0f64;
        let mut take = |x: &mut [Vec3A], i: usize, x_hat: Vec3A| {
            if MEASURE {
                update += f64::from((x_hat - x[i]).length_squared());
            }
            if CHEBYSHEV {
                let before = x_prev[i];
                x_prev[i] = x[i];
                x[i] = blend(omega, x_hat, before);
            } else {
                x[i] = x_hat;
            }
        };
        match self {
            // The multigrid's correction added to the iterate in `f32` (an
            // `f64` round trip gives the same bits, slower).
            Self::Multigrid(multigrid) => {
                for (f, &i) in free.iter().enumerate() {
                    let i = i as usize;
                    let x_hat = x[i] + multigrid.solution(f, i);
                    take(x, i, x_hat);
                }
            }
            Self::Lanes(lanes) => {
                for (f, [a, b, c]) in lanes.solved() {
                    take(
                        x,
                        free[f] as usize,
                        Vec3A::new(a as f32, b as f32, c as f32),
                    );
                }
            }
            Self::Columns(rhs) => {
                let m = free.len();
                for (f, &i) in free.iter().enumerate() {
                    let x_hat = Vec3A::new(rhs[f] as f32, rhs[m + f] as f32, rhs[2 * m + f] as f32);
                    take(x, i as usize, x_hat);
                }
            }
        }
        update
    }

    /// The solution at free vertex `f` (vertex `i`), whose iterate was `x`
    /// (the multigrid's correction is added to it), in `f64`.
    #[inline(always)]
    pub(super) fn at_f64(&self, f: usize, i: usize, x: Vec3A) -> DVec3 {
        match self {
            Self::Multigrid(multigrid) => (x + multigrid.solution(f, i)).as_dvec3(),
            Self::Lanes(lanes) => DVec3::from_array(lanes.solution(f)),
            Self::Columns(rhs) => {
                let m = rhs.len() / 3;
                DVec3::new(rhs[f], rhs[m + f], rhs[2 * m + f])
            }
        }
    }
}
