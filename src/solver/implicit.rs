//! Implicit Euler by a diagonal-Hessian Newton (Jacobi) iteration, with
//! optional Chebyshev acceleration — the lab's part 1.
//!
//! One step, for every free vertex `i`:
//!
//! 1. damp: `vᵢ ← damping·vᵢ`; predict `x̃ᵢ = xᵢ + dt·vᵢ`; initial guess
//!    `xᵢ = x̃ᵢ` (lab 1.a);
//! 2. `K` times: the gradient `g = M(x − x̃)/dt² − f(x)` of the implicit-Euler
//!    objective (lab 1.b, [`gradient`]), then the
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

use super::{StepError, StepParams, StepReport, check_state, for_chunks, for_chunks2, gradient};
use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState, ParamError, SpringKind};

/// The spectral radius `ρ` that Chebyshev acceleration assumes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rho {
    /// A fixed value in `(0, 1)` (the lab: 0.995).
    Fixed(f32),
    /// Estimated each step: the first `S = clamp(K/4, 2, 8)` iterations are
    /// plain Jacobi, and `ρ` is the geometric mean decay of their update
    /// norms `‖x_{k+1} − x_k‖` over the second half of them (Wang 2015
    /// delays acceleration for the same reason); Chebyshev then runs with it.
    Auto,
}

/// Settings of the implicit solver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImplicitConfig {
    /// Jacobi iterations per step (the lab: 32).
    pub iterations: u32,
    /// Chebyshev acceleration with this `ρ`, or `None` for plain Jacobi.
    pub chebyshev: Option<Rho>,
}

impl ImplicitConfig {
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

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.iterations == 0 {
            return Err(ParamError::Iterations);
        }
        if let Some(Rho::Fixed(rho)) = self.chebyshev
            && !(rho > 0.0 && rho < 1.0)
        {
            return Err(ParamError::Rho(rho));
        }
        Ok(())
    }
}

impl Default for ImplicitConfig {
    /// The lab: 32 plain Jacobi iterations.
    fn default() -> Self {
        Self::jacobi(32)
    }
}

/// Scratch buffers of the implicit solver, sized on first use.
#[derive(Clone, Debug, Default)]
pub struct ImplicitWorkspace {
    x_tilde: Vec<Vec3A>,
    gradient: Vec<Vec3A>,
    terms: Vec<Vec3A>,
    inv_diag: Vec<f32>,
    base_diag: Vec<f32>,
    update_norms: Vec<f64>,
    /// The iterate before last, for Chebyshev; empty without it.
    x_prev: Vec<Vec3A>,
    /// Inverse diagonal including contact stiffness; empty without spheres.
    contact_diag: Vec<f32>,
    /// Per chunk of vertices: the sum of squared Chebyshev updates.
    chunk_sums: Vec<f64>,
}

impl ImplicitWorkspace {
    fn prepare(&mut self, vertices: usize, springs: usize, chebyshev: bool, contacts: bool) {
        if contacts {
            self.contact_diag.resize(vertices, 0.0);
        } else {
            self.contact_diag = Vec::new();
        }
        self.x_tilde.resize(vertices, Vec3A::ZERO);
        self.gradient.resize(vertices, Vec3A::ZERO);
        self.inv_diag.resize(vertices, 0.0);
        self.base_diag.resize(vertices, 0.0);
        self.terms.resize(springs, Vec3A::ZERO);
        if chebyshev {
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

/// Advances `state` by one implicit-Euler step (see the module docs).
///
/// Returns the iterations performed and the final gradient norm. On error
/// the state is unchanged.
pub fn step(
    model: &ClothModel,
    state: &mut ClothState,
    params: &StepParams,
    config: &ImplicitConfig,
    spheres: &[PenaltySphere],
    ws: &mut ImplicitWorkspace,
) -> Result<StepReport, StepError> {
    params.validate()?;
    config.validate()?;
    check_state(model, state)?;
    let n = model.vertex_count();
    ws.prepare(
        n,
        model.topology().springs().len(),
        config.chebyshev.is_some(),
        !spheres.is_empty(),
    );
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
    let ClothState {
        positions: x,
        velocities: v,
    } = state;

    // 1.a: damping, prediction, initial guess.
    for i in 0..n {
        if !pinned[i] {
            v[i] *= params.damping;
            x[i] += dt * v[i];
        }
        ws.x_tilde[i] = x[i];
        let spring_diag = if lab_diagonal {
            4.0 * k[SpringKind::Stretch as usize]
        } else {
            adjacency
                .of(i)
                .iter()
                .map(|inc| k[springs[inc.spring as usize].kind as usize])
                .sum()
        };
        ws.base_diag[i] = model.masses()[i] * inv_dt2 + spring_diag;
        ws.inv_diag[i] = 1.0 / ws.base_diag[i];
    }
    if config.chebyshev.is_some() {
        ws.x_prev.copy_from_slice(x);
    }

    // 1.b–1.d: K diagonal-Newton iterations, optionally Chebyshev-accelerated.
    let mut omega = 1.0f32;
    // Iterations before acceleration starts, and ρ.
    let (delay, mut rho) = match config.chebyshev {
        Some(Rho::Auto) => ((config.iterations / 4).clamp(2, 8), 0.0),
        Some(Rho::Fixed(r)) => (0, r),
        None => (0, 0.0),
    };
    ws.update_norms.clear();
    for k in 0..config.iterations {
        objective_gradient(model, x, params, spheres, ws);
        // Pinned vertices have a zero gradient, so neither update moves them.
        let inv_diag = if spheres.is_empty() {
            &ws.inv_diag
        } else {
            &ws.contact_diag
        };
        let gradient = &ws.gradient;
        match config.chebyshev {
            None => {
                for_chunks(x, |start, x| {
                    for ((xi, g), d) in x.iter_mut().zip(&gradient[start..]).zip(&inv_diag[start..])
                    {
                        *xi -= *g * *d;
                    }
                });
            }
            Some(kind) => {
                if kind == Rho::Auto && k == delay {
                    rho = rho_from_update_norms(&ws.update_norms);
                }
                omega = match k.checked_sub(delay) {
                    None | Some(0) => 1.0,
                    Some(1) => 2.0 / (2.0 - rho * rho),
                    _ => 4.0 / (4.0 - rho * rho * omega),
                };
                // Each chunk updates its vertices and the previous iterate,
                // and sums its squared update norms; the sums are added in
                // chunk order, so the total is the same on any thread count.
                for_chunks2(x, &mut ws.x_prev, &mut ws.chunk_sums, |start, x, prev| {
                    let mut update = 0.0f64;
                    let per_vertex = x
                        .iter_mut()
                        .zip(prev.iter_mut())
                        .zip(&gradient[start..])
                        .zip(&inv_diag[start..]);
                    for (((xi, prev), g), d) in per_vertex {
                        let step = *g * *d;
                        let x_hat = *xi - step;
                        let before = *prev;
                        *prev = *xi;
                        *xi = omega * (x_hat - before) + before;
                        update += f64::from(step.length_squared());
                    }
                    update
                });
                if k < delay {
                    let update: f64 = ws.chunk_sums.iter().sum();
                    ws.update_norms.push(update.sqrt());
                }
            }
        }
    }

    // Residual at the final iterate.
    objective_gradient(model, x, params, spheres, ws);
    let residual = ws
        .gradient
        .iter()
        .map(|g| g.length_squared())
        .sum::<f32>()
        .sqrt();

    // 1.c: velocities from the positions.
    let inv_dt = 1.0 / dt;
    for i in 0..n {
        if !pinned[i] {
            v[i] += (x[i] - ws.x_tilde[i]) * inv_dt;
        }
    }
    Ok(StepReport {
        iterations: config.iterations,
        residual: Some(residual),
    })
}

/// The gradient at `x` into `ws.gradient`, with penalty contacts (which
/// also refresh `ws.contact_diag`).
fn objective_gradient(
    model: &ClothModel,
    x: &[Vec3A],
    params: &StepParams,
    spheres: &[PenaltySphere],
    ws: &mut ImplicitWorkspace,
) {
    gradient(
        model,
        x,
        &ws.x_tilde,
        params,
        &mut ws.terms,
        &mut ws.gradient,
    );
    if !spheres.is_empty() {
        add_penalty(
            model,
            x,
            spheres,
            &mut ws.gradient,
            &ws.base_diag,
            &mut ws.contact_diag,
        );
    }
}

/// `ρ` from successive Jacobi update norms `‖x_{k+1} − x_k‖`: their
/// geometric mean decay over the second half, clamped to `[0.5, 0.9999]`
/// (0.9 when there are too few). Used by [`Rho::Auto`].
pub fn rho_from_update_norms(norms: &[f64]) -> f32 {
    let (lo, hi) = (norms.len() / 2, norms.len().saturating_sub(1));
    if hi <= lo || norms[lo] <= 0.0 || !norms[hi].is_finite() {
        return 0.9;
    }
    ((norms[hi] / norms[lo]).powf(1.0 / (hi - lo) as f64) as f32).clamp(0.5, 0.9999)
}

/// Adds penalty forces to the gradient (`g −= f_c`) and writes the inverse
/// diagonal with each contact's stiffness `c` added.
fn add_penalty(
    model: &ClothModel,
    x: &[Vec3A],
    spheres: &[PenaltySphere],
    gradient: &mut [Vec3A],
    base_diag: &[f32],
    inv_diag: &mut [f32],
) {
    let pinned = model.pinned();
    for i in 0..model.vertex_count() {
        let mut diag = base_diag[i];
        if !pinned[i] {
            for sphere in spheres {
                if let Some(contact) = sphere.contact(x[i]) {
                    gradient[i] -= contact.force;
                    diag += sphere.stiffness;
                }
            }
        }
        inv_diag[i] = 1.0 / diag;
    }
}
