//! Implicit Euler by a diagonal-Hessian Newton (Jacobi) iteration, with
//! optional Chebyshev acceleration — the lab's part 1.
//!
//! One step, for every free vertex `i`:
//!
//! 1. damp: `vᵢ ← damping·vᵢ`; predict `x̃ᵢ = xᵢ + dt·vᵢ`; initial guess
//!    `xᵢ = x̃ᵢ` (lab 1.a);
//! 2. `K` times: the gradient `g = M(x − x̃)/dt² − f(x)` of the implicit-Euler
//!    objective (lab 1.b, [`gradient`](super::gradient)), then the
//!    diagonal-Hessian update `xᵢ ← xᵢ − gᵢ / (mᵢ/dt² + 4k)` (lab 1.c).
//!    With Chebyshev acceleration (lab 1.d; Wang 2015, "A Chebyshev
//!    semi-iterative approach for accelerating projective and position-based
//!    dynamics") the update `x̂` is blended with the iterate before last:
//!    `x⁽ᵏ⁺¹⁾ = ω_{k+1}(x̂ − x⁽ᵏ⁻¹⁾) + x⁽ᵏ⁻¹⁾`, `ω₁ = 1`,
//!    `ω₂ = 2/(2 − ρ²)`, `ω_{k+1} = 4/(4 − ρ²ω_k)`;
//! 3. `vᵢ ← vᵢ + (xᵢ − x̃ᵢ)/dt` (lab 1.c).
//!
//! `4k` is the lab's diagonal for its triangle-edge (stretch) springs. A
//! cloth with shear or bending springs uses, per vertex, the sum of its
//! springs' stiffnesses instead (4k does not bound the Hessian there and the
//! iteration diverges). `ρ` is fixed or estimated per step ([`Rho`]). Pinned
//! vertices never move. A penalty sphere adds its
//! force to `f` and its stiffness `c` to the diagonal of a vertex in contact.

use bevy::math::Vec3A;

use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

pub use super::chebyshev::{Rho, rho_from_update_norms};
use super::chebyshev::{blend, chebyshev_omega, validate_chebyshev};
use super::engine::kernels::{PaddedRows, RowGather, for_chunks, for_chunks2};
use super::engine::stencil::{StencilWorkspace, Update, VertexData};
use super::springs::{spring_terms, stiffness_coeffs};
use super::{
    ConvergenceSums, LAB_ITERATIONS, Method, ParamError, StepError, StepInput, StepReport,
};
use crate::collision::PenaltySphere;
use crate::model::{Adjacency, ClothModel, ClothState, SpringKind};

/// Steps a cloth by implicit Euler with the lab's diagonal-Hessian Newton
/// (Jacobi) iteration, optionally Chebyshev-accelerated (see the module
/// docs). As a component on a cloth entity it selects this method
/// ([`ImplicitPlugin`](crate::ImplicitPlugin)).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Default, Debug, PartialEq)]
pub struct ImplicitSolver {
    /// Jacobi iterations per step (the lab: 32).
    pub iterations: u32,
    /// Chebyshev acceleration with this `ρ`, or `None` for plain Jacobi.
    pub chebyshev: Option<Rho>,
}

impl ImplicitSolver {
    /// Plain Jacobi with `iterations` iterations.
    pub const fn jacobi(iterations: u32) -> Self {
        Self {
            iterations,
            chebyshev: None,
        }
    }

    /// Chebyshev-accelerated Jacobi.
    pub const fn chebyshev(iterations: u32, rho: f32) -> Self {
        Self {
            iterations,
            chebyshev: Some(Rho::Fixed(rho)),
        }
    }

    /// Chebyshev-accelerated Jacobi with `ρ` estimated each step.
    pub const fn chebyshev_auto(iterations: u32) -> Self {
        Self {
            iterations,
            chebyshev: Some(Rho::Auto),
        }
    }
}

impl Default for ImplicitSolver {
    /// The lab: 32 plain Jacobi iterations.
    fn default() -> Self {
        Self::jacobi(LAB_ITERATIONS)
    }
}

impl Method for ImplicitSolver {
    type Workspace = ImplicitWorkspace;

    fn name(&self) -> &'static str {
        match self.chebyshev {
            None => "jacobi",
            Some(Rho::Fixed(_)) => "chebyshev",
            Some(Rho::Auto) => "chebyshev-auto",
        }
    }

    fn iterations_mut(&mut self) -> Option<&mut u32> {
        Some(&mut self.iterations)
    }

    fn validate(&self) -> Result<(), ParamError> {
        validate_chebyshev(self.iterations, self.chebyshev)
    }

    /// Advances `state` by one implicit-Euler step (see the module docs).
    ///
    /// Returns the iterations performed and the final gradient norm. On error
    /// the state is unchanged.
    ///
    /// A cloth whose springs form a stencil runs both passes on the
    /// structure-of-arrays kernels of `solver::engine::stencil` (unless
    /// `StepParams::stencil` is off); the rest of this describes the
    /// general kernels.
    ///
    /// Each iteration is two passes: one over springs, which computes every
    /// spring's gradient term once (square roots and divisions in packed SIMD
    /// blocks), and one over vertices, which gathers each vertex's terms over
    /// its adjacency and updates its position in the same loop. Both passes are
    /// split in fixed chunks, run in parallel for large cloths.
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        ws: &mut ImplicitWorkspace,
    ) -> Result<StepReport, StepError> {
        let StepInput {
            model,
            params,
            spheres,
            ..
        } = input;
        let config = self;
        let n = model.vertex_count();
        let dt = params.dt as f32;
        let inv_dt2 = 1.0 / (dt * dt);
        let pinned = model.pinned();
        // The diagonal Hessian: the lab's 4k for a cloth of triangle-edge
        // (stretch) springs only; with shear or bending springs a vertex has up
        // to 12 springs and 4k no longer bounds the Hessian (the iteration
        // diverges), so the sum of the vertex's spring stiffnesses is used.
        let counts = model.topology().spring_counts();
        let lab_diagonal =
            counts[SpringKind::Shear as usize] == 0 && counts[SpringKind::Bend as usize] == 0;
        let k = params.stiffness.as_array();
        let springs = model.topology().springs();
        let adjacency = model.topology().adjacency();
        let gravity_step = Vec3A::from(params.gravity) * (dt * dt);
        // The structure-of-arrays kernels where the springs form a stencil.
        let stencil = model.topology().stencil().filter(|_| params.stencil);
        // The general kernels' targets and previous iterate (the stencil
        // kernels keep their own).
        ws.prepare(n, stencil.is_none(), config.chebyshev.is_some());
        if stencil.is_none() {
            stiffness_coeffs(model, &params.stiffness, &mut ws.coeffs);
            // One term per spring and a zero past them, which padded gathers
            // read.
            ws.gather.terms.clear();
            ws.gather.terms.resize(springs.len() + 1, Vec3A::ZERO);
            ws.gather.rows.update::<Vec3A>(adjacency, springs.len() + 1);
        }
        let ClothState {
            positions: x,
            velocities: v,
        } = state;

        // 1.a: damping, prediction, initial guess (loops over zipped slices:
        // no bounds checks, and the per-vertex constants vectorise).
        for ((x, v), &pinned) in x.iter_mut().zip(v.iter_mut()).zip(pinned) {
            if !pinned {
                *v *= params.damping;
                *x += dt * *v;
            }
        }
        ws.x_tilde[..n].copy_from_slice(x);
        // The stencil kernels make their targets from x themselves.
        if stencil.is_none() {
            for (t, &x) in ws.gather.target.iter_mut().zip(x.iter()) {
                *t = x + gravity_step;
            }
        }
        for (t, &m) in ws.gather.mass_term.iter_mut().zip(model.masses()) {
            *t = m * inv_dt2;
        }
        if lab_diagonal {
            let spring_diag = 4.0 * k[SpringKind::Stretch as usize];
            for (d, &m) in ws.gather.base_diag.iter_mut().zip(&ws.gather.mass_term) {
                *d = m + spring_diag;
            }
        } else {
            for (i, (d, &m)) in ws
                .gather
                .base_diag
                .iter_mut()
                .zip(&ws.gather.mass_term)
                .enumerate()
            {
                let spring_diag: f32 = adjacency
                    .of(i)
                    .iter()
                    .map(|inc| k[springs[inc.spring as usize].kind as usize])
                    .sum();
                *d = m + spring_diag;
            }
        }
        for ((inv, &d), &pinned) in ws
            .gather
            .inv_diag
            .iter_mut()
            .zip(&ws.gather.base_diag)
            .zip(pinned)
        {
            *inv = if pinned { 0.0 } else { 1.0 / d };
        }
        let data = VertexData {
            mass_term: &ws.gather.mass_term,
            inv_diag: &ws.gather.inv_diag,
            base_diag: &ws.gather.base_diag,
            pinned,
            spheres,
        };
        match stencil {
            Some(stencil) => {
                ws.stencil
                    .load(stencil, k, x, gravity_step, config.chebyshev.is_some())
            }
            None if config.chebyshev.is_some() => ws.x_prev.copy_from_slice(x),
            None => {}
        }

        // 1.b–1.d: K diagonal-Newton iterations, optionally Chebyshev-accelerated.
        ws.update_norms.clear();
        let mut updates = Updates::new(config, &mut ws.update_norms);
        ws.grad.resize(n, Vec3A::ZERO);
        match stencil {
            Some(_) => ws.stencil.iterate(
                params.simd,
                params.parallel,
                &data,
                config.iterations,
                config.chebyshev.is_some(),
                |k, squares| updates.next(k, squares),
                &mut ws.grad,
                x,
            ),
            None => {
                let mut squares = 0.0;
                for k in 0..config.iterations {
                    let update = updates.next(k, squares);
                    spring_terms(
                        params,
                        model,
                        x,
                        &ws.coeffs,
                        &mut ws.gather.terms[..springs.len()],
                    );
                    let pass = VertexPass::new(&ws.gather, model, spheres);
                    squares = general_vertex_pass(
                        &pass,
                        params.parallel,
                        x,
                        &mut ws.x_prev,
                        &mut ws.chunk_sums,
                        update,
                    );
                }
                // Residual at the final iterate: the gradient over free
                // vertices.
                spring_terms(
                    params,
                    model,
                    x,
                    &ws.coeffs,
                    &mut ws.gather.terms[..springs.len()],
                );
                let pass = VertexPass::new(&ws.gather, model, spheres);
                for (i, g) in ws.grad.iter_mut().enumerate() {
                    *g = pass.gradient(i, x[i]).0;
                }
            }
        }
        // 1.c with the residual: velocities from the positions, and the
        // gradient's norm and convergence sums over free vertices.
        let mut residual = 0.0f32;
        let mut convergence = ConvergenceSums::default();
        let inv_dt = 1.0 / dt;
        let free = (v.iter_mut().zip(x.iter()))
            .zip(ws.x_tilde.iter().zip(ws.grad.iter()))
            .zip(model.masses().iter().zip(pinned))
            .filter(|(_, (_, pinned))| !**pinned);
        for (((v, &x), (&x_tilde, &g)), (&m, _)) in free {
            residual += g.length_squared();
            // x̃ = x_start + dt·v (v damped): the step's motion is x − x_start.
            let motion = x - (x_tilde - dt * *v);
            convergence.add(g * (dt * dt / m), motion);
            *v += (x - x_tilde) * inv_dt;
        }
        let residual = residual.sqrt();
        Ok(StepReport {
            iterations: config.iterations,
            residual: Some(residual),
            relative_error: Some(convergence.relative_error(model, params.dt)),
            contacts: 0,
            self_contacts: None,
            substeps: 1,
        })
    }
}

/// Each iteration's update: Jacobi, or Chebyshev with its `ω` (after
/// `Rho::Auto`'s measured iterations, from the `ρ` they give).
struct Updates<'a> {
    chebyshev: Option<Rho>,
    /// Iterations before acceleration starts.
    delay: u32,
    rho: f32,
    omega: f32,
    /// The measured iterations' update norms.
    norms: &'a mut Vec<f64>,
    /// The last update measured its steps.
    measured: bool,
}

impl<'a> Updates<'a> {
    fn new(config: &ImplicitSolver, norms: &'a mut Vec<f64>) -> Self {
        let (delay, rho) = match config.chebyshev {
            Some(Rho::Auto) => ((config.iterations / 4).clamp(2, 8), 0.0),
            Some(Rho::Fixed(r)) => (0, r),
            None => (0, 0.0),
        };
        Self {
            chebyshev: config.chebyshev,
            delay,
            rho,
            omega: 1.0,
            norms,
            measured: false,
        }
    }

    /// Iteration `k`'s update; `squares` is the sum of squared steps of
    /// iteration `k − 1` (read if it measured them). A pinned vertex has a
    /// zero inverse diagonal, so no update moves it (Chebyshev: its iterate
    /// and the one before are equal).
    fn next(&mut self, k: u32, squares: f64) -> Update {
        if self.measured {
            self.norms.push(squares.sqrt());
        }
        let update = match self.chebyshev {
            None => Update::Jacobi,
            Some(kind) => {
                if kind == Rho::Auto && k == self.delay {
                    self.rho = rho_from_update_norms(self.norms);
                }
                self.omega = chebyshev_omega(k, self.delay, self.rho, self.omega);
                Update::Chebyshev {
                    omega: self.omega,
                    measure: k < self.delay,
                }
            }
        };
        self.measured = matches!(update, Update::Chebyshev { measure: true, .. });
        update
    }
}

/// One iteration's vertex pass of the general kernels over the spring terms
/// `pass` reads, in chunks; returns the sum of squared steps when `update`
/// measures them (added in chunk order: the same on any thread count).
fn general_vertex_pass(
    pass: &VertexPass<'_>,
    parallel: bool,
    x: &mut [Vec3A],
    x_prev: &mut [Vec3A],
    chunk_sums: &mut Vec<f64>,
    update: Update,
) -> f64 {
    match update {
        Update::Jacobi => {
            for_chunks(parallel, x, move |start, x| {
                pass.chunk(start, x.len())
                    .each(x, |_, xi, step| *xi -= step);
            });
            0.0
        }
        Update::Chebyshev { omega, measure } => {
            // Each chunk updates its vertices and the previous iterate, and
            // sums its squared update norms.
            for_chunks2(parallel, x, x_prev, chunk_sums, move |start, x, prev| {
                let prev = &mut prev[..x.len()];
                let mut update = 0.0f64;
                pass.chunk(start, x.len()).each(x, |j, xi, step| {
                    let x_hat = *xi - step;
                    let before = prev[j];
                    prev[j] = *xi;
                    *xi = blend(omega, x_hat, before);
                    if measure {
                        update += f64::from(step.length_squared());
                    }
                });
                update
            });
            chunk_sums.iter().sum()
        }
    }
}

/// Scratch buffers of the implicit solver, sized on first use.
#[derive(Clone, Debug, Default)]
pub struct ImplicitWorkspace {
    x_tilde: Vec<Vec3A>,
    /// Per spring `[k, kL]` (see `spring_scales`).
    coeffs: Vec<[f32; 2]>,
    /// What the vertex pass reads.
    gather: Gather,
    update_norms: Vec<f64>,
    /// The iterate before last, for Chebyshev; empty without it.
    x_prev: Vec<Vec3A>,
    /// Per chunk of vertices: the sum of squared updates.
    chunk_sums: Vec<f64>,
    /// The gradient at the final iterate.
    grad: Vec<Vec3A>,
    /// The structure-of-arrays state of the stencil kernels.
    stencil: StencilWorkspace,
}

/// The per-step vertex data and per-iteration spring terms the vertex pass
/// reads.
#[derive(Clone, Debug, Default)]
struct Gather {
    /// `x̃ + dt²·g`: the gradient's mass term is `m/dt²·(x − target)`.
    target: Vec<Vec3A>,
    /// `m/dt²` per vertex.
    mass_term: Vec<f32>,
    /// Per spring: its gradient term `k(1 − L/l)(x_a − x_b)`, then a zero
    /// (the padded gathers' target).
    terms: Vec<Vec3A>,
    /// `1/(m/dt² + Σk)` per free vertex, `0` for a pinned one (so no update
    /// moves it).
    inv_diag: Vec<f32>,
    /// `m/dt² + Σk`, to which penalty contacts add their stiffness.
    base_diag: Vec<f32>,
    /// The padded rows as byte offsets into `terms`, filled per step from
    /// the model's: the gathers' addresses without a shift each. Empty
    /// without padded rows.
    rows: PaddedRows,
}

impl ImplicitWorkspace {
    /// Sizes the buffers for `vertices`; the general kernels' targets and
    /// previous iterate (Chebyshev's) only if `general`.
    fn prepare(&mut self, vertices: usize, general: bool, chebyshev: bool) {
        let g = &mut self.gather;
        self.x_tilde.resize(vertices, Vec3A::ZERO);
        if general {
            g.target.resize(vertices, Vec3A::ZERO);
        } else {
            g.target = Vec::new();
        }
        for v in [&mut g.mass_term, &mut g.inv_diag, &mut g.base_diag] {
            v.resize(vertices, 0.0);
        }
        if general && chebyshev {
            self.x_prev.resize(vertices, Vec3A::ZERO);
        } else {
            self.x_prev = Vec::new();
        }
    }

    /// The predicted positions `x̃` of the last step.
    pub fn x_tilde(&self) -> &[Vec3A] {
        &self.x_tilde
    }
}

/// What one iteration's vertex pass needs, shared by every chunk.
struct VertexPass<'a> {
    data: &'a Gather,
    /// The padded gathers over `data.terms`, when the model has padded rows.
    rows: Option<RowGather<'a, Vec3A>>,
    adjacency: &'a Adjacency,
    pinned: &'a [bool],
    spheres: &'a [PenaltySphere],
}

impl<'a> VertexPass<'a> {
    fn new(data: &'a Gather, model: &'a ClothModel, spheres: &'a [PenaltySphere]) -> Self {
        let adjacency = model.topology().adjacency();
        Self {
            rows: (!data.rows.is_empty())
                .then(|| data.rows.gather(0..data.rows.len(), &data.terms)),
            data,
            adjacency,
            pinned: model.pinned(),
            spheres,
        }
    }

    /// The pass over vertices `start .. start + len` (one chunk).
    fn chunk(&'a self, start: usize, len: usize) -> ChunkPass<'a> {
        let range = start..start + len;
        let d = self.data;
        ChunkPass {
            pass: self,
            start,
            target: &d.target[range.clone()],
            mass_term: &d.mass_term[range.clone()],
            inv_diag: &d.inv_diag[range.clone()],
            rows: (!d.rows.is_empty()).then(|| d.rows.gather(range, &d.terms)),
        }
    }

    /// The objective's gradient at vertex `i` and the inverse of its
    /// diagonal, penalty contacts included (for a pinned vertex the gradient
    /// is not zeroed, but its inverse diagonal is 0).
    #[inline(always)]
    fn gradient(&self, i: usize, xi: Vec3A) -> (Vec3A, f32) {
        let springs = match &self.rows {
            // Fixed length, summed as a tree: short chains of additions.
            Some(rows) => {
                let (plus, minus) = rows.sums(i, |t| *t, |t| *t);
                plus - minus
            }
            None => {
                let (starts, ends) = self.adjacency.by_side(i);
                let mut plus = Vec3A::ZERO;
                for &e in starts {
                    plus += self.data.terms[e as usize];
                }
                let mut minus = Vec3A::ZERO;
                for &e in ends {
                    minus += self.data.terms[e as usize];
                }
                plus - minus
            }
        };
        let d = self.data;
        let mut g = (xi - d.target[i]) * d.mass_term[i] + springs;
        let mut inv_diag = d.inv_diag[i];
        if !self.spheres.is_empty() && !self.pinned[i] {
            let mut diag = d.base_diag[i];
            for sphere in self.spheres {
                if let Some(contact) = sphere.contact(xi) {
                    g -= contact.force;
                    diag += sphere.stiffness;
                }
            }
            inv_diag = 1.0 / diag;
        }
        (g, inv_diag)
    }
}

/// A [`VertexPass`] over one chunk of vertices, its per-vertex data sliced
/// to the chunk.
struct ChunkPass<'a> {
    pass: &'a VertexPass<'a>,
    start: usize,
    target: &'a [Vec3A],
    mass_term: &'a [f32],
    inv_diag: &'a [f32],
    /// The chunk's padded gathers (`Gather::rows`).
    rows: Option<RowGather<'a, Vec3A>>,
}

impl ChunkPass<'_> {
    /// Calls `update(j, x_j, step_j)` for each vertex `j` of the chunk
    /// (`x` is the chunk's positions) with its diagonal-Newton step
    /// `g_j / diag_j`. A padded adjacency without penalty spheres (the lab)
    /// runs a loop of its own: fixed-length gathers, the chunk's data read
    /// in order, nothing to branch on.
    #[inline(always)]
    fn each(&self, x: &mut [Vec3A], mut update: impl FnMut(usize, &mut Vec3A, Vec3A)) {
        match self.rows {
            Some(rows) if self.pass.spheres.is_empty() => {
                let n = x.len();
                let (rows, target, mass, inv) = (
                    rows.first(n),
                    &self.target[..n],
                    &self.mass_term[..n],
                    &self.inv_diag[..n],
                );
                for j in 0..n {
                    let (plus, minus) = rows.sums(j, |t| *t, |t| *t);
                    let springs = plus - minus;
                    let g = (x[j] - target[j]) * mass[j] + springs;
                    update(j, &mut x[j], g * inv[j]);
                }
            }
            _ => {
                for (j, xi) in x.iter_mut().enumerate() {
                    let (g, d) = self.pass.gradient(self.start + j, *xi);
                    update(j, xi, g * d);
                }
            }
        }
    }
}
