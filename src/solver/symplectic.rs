//! Symplectic Euler — the assignment's first stage (`A = M`).
//!
//! With `A = M` the linear system `M v⁺ = M v + h f` has a diagonal matrix,
//! so it is solved exactly, row by row, by dividing by the particle's mass:
//! `v⁺ = v + h M⁻¹ f(x)`, then `x ← x + h v⁺`. No factorisation or iteration
//! is needed. `f` holds spring, gravity and penalty forces; fixed particles
//! are skipped. A cloth whose springs form a stencil (every builder's
//! grid) sums its spring terms on the structure-of-arrays kernels
//! (`stencil`), unless `StepParams::stencil` is off. The step is explicit in the forces, so it is stable only
//! for `h` below about `2/ω_max` (`ω_max²` the largest eigenvalue of
//! `M⁻¹K`); past that it diverges, and the divergence guard catches it.
//!
//! A penalty collider is an undamped spring `c` on each vertex in contact,
//! which this step integrates stably only for `c·h²/m <` [`EXPLICIT_CONTACT_LIMIT`]
//! (`ω h < 2`). A stiffer one would
//! launch the cloth that rests on it, so it is projected after the step
//! instead (as PBD does): the vertex is put back on its surface and its
//! velocity into it removed.

use bevy::math::Vec3A;

use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use super::{Method, ParamError, StepError, StepInput, StepReport};
use crate::collision::{PenaltySphere, Shape, project_shapes};
use crate::model::ClothState;
use crate::solver::engine::stencil::StencilWorkspace;
use crate::solver::springs::{spring_terms, stiffness_coeffs};

/// Steps a cloth by symplectic Euler (`A = M`, the assignment's first
/// stage): `v ← v + h M⁻¹f`, `x ← x + h v` (see the module docs). Explicit,
/// so stable only for small steps. No settings. As a component on a cloth
/// entity it selects this method ([`SymplecticPlugin`](crate::SymplecticPlugin)).
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Default, Debug, PartialEq)]
pub struct SymplecticSolver;

impl Method for SymplecticSolver {
    type Workspace = SymplecticWorkspace;

    fn name(&self) -> &'static str {
        "symplectic"
    }

    fn validate(&self) -> Result<(), ParamError> {
        Ok(())
    }

    /// Advances `state` by one symplectic Euler step (see the module docs).
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        ws: &mut SymplecticWorkspace,
    ) -> Result<StepReport, StepError> {
        let StepInput {
            model,
            params,
            spheres,
            ..
        } = input;
        let h = params.dt as f32;
        // Penalty colliders stiffer than the step can integrate for the
        // lightest free vertex are projected after it (module docs); a step
        // without them does not look for it.
        let lightest = if spheres.is_empty() {
            f32::INFINITY
        } else {
            model
                .masses()
                .iter()
                .zip(model.pinned())
                .filter(|(_, p)| !**p)
                .map(|(&m, _)| m)
                .fold(f32::INFINITY, f32::min)
        };
        let explicit = |s: &PenaltySphere| s.stiffness * h * h < EXPLICIT_CONTACT_LIMIT * lightest;
        ws.projected.clear();
        ws.projected.extend(
            spheres
                .iter()
                .filter(|s| !explicit(s))
                .map(PenaltySphere::as_shape),
        );
        let gravity = Vec3A::from(params.gravity);
        let adjacency = model.topology().adjacency();
        let pinned = model.pinned();
        let n = model.vertex_count();
        // The structure-of-arrays kernels where the springs form a stencil:
        // per vertex, the sum of its springs' terms.
        let stencil = model.topology().stencil().filter(|_| params.stencil);
        if let Some(stencil) = stencil {
            let k = params.stiffness.as_array();
            ws.stencil.load_springs(stencil, k, &state.positions);
            ws.sums.resize(n, Vec3A::ZERO);
            ws.stencil
                .spring_sums(params.simd, params.parallel, &mut ws.sums);
        } else {
            ws.terms
                .resize(model.topology().springs().len(), Vec3A::ZERO);
            // terms[e] = k(1 − L/l)(x_a − x_b) = −(spring force on a).
            stiffness_coeffs(model, &params.stiffness, &mut ws.coeffs);
            spring_terms(params, model, &state.positions, &ws.coeffs, &mut ws.terms);
        }
        for (i, &m) in model.masses().iter().enumerate() {
            if pinned[i] {
                continue;
            }
            let x = state.positions[i];
            let mut f = gravity * m;
            if stencil.is_some() {
                f -= ws.sums[i];
            } else {
                let (starts, ends) = adjacency.by_side(i);
                for &e in starts {
                    f -= ws.terms[e as usize];
                }
                for &e in ends {
                    f += ws.terms[e as usize];
                }
            }
            for sphere in spheres.iter().filter(|s| explicit(s)) {
                if let Some(contact) = sphere.contact(x) {
                    f += contact.force;
                }
            }
            let v = state.velocities[i] * params.damping + f * (h / m);
            state.velocities[i] = v;
            state.positions[i] = x + h * v;
        }
        let contacts = if ws.projected.is_empty() {
            0
        } else {
            project_shapes(model, state, &ws.projected, 0.0, h) as u32
        };
        Ok(StepReport {
            iterations: 0,
            residual: None,
            relative_error: None,
            contacts,
            self_contacts: None,
            substeps: 1,
        })
    }
}

/// Scratch of the symplectic solver: one term per spring.
#[derive(Clone, Debug, Default)]
pub struct SymplecticWorkspace {
    terms: Vec<Vec3A>,
    coeffs: Vec<[f32; 2]>,
    /// Per vertex, its springs' terms summed (the stencil kernels).
    sums: Vec<Vec3A>,
    /// The structure-of-arrays state of the stencil kernels.
    stencil: StencilWorkspace,
    /// The penalty colliders too stiff for the step, as projected shapes.
    projected: Vec<Shape>,
}

/// The largest `c·h²/m` at which symplectic Euler integrates a penalty
/// contact stably (`ω h < 2` for an undamped spring); stiffer contacts are
/// projected (see the [module docs](self)).
pub const EXPLICIT_CONTACT_LIMIT: f32 = 4.0;
