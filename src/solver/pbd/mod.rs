//! Position-based dynamics with Jacobi strain limiting — the lab's part 2.
//!
//! One step, for every free vertex `i`:
//!
//! 1. `vᵢ ← damping·vᵢ + dt·g`, `xᵢ ← xᵢ + dt·vᵢ` (lab 2.a);
//! 2. `K` times, Jacobi strain limiting (lab equations 5–6): every spring
//!    `e = (i, j)` proposes for each end the position that restores its rest
//!    length about the spring's midpoint,
//!    `½(xᵢ + xⱼ ± L_e (xᵢ − xⱼ)/‖xᵢ − xⱼ‖)`; each vertex moves to the
//!    0.2-weighted average `x'ᵢ = (0.2 xᵢ + Σ proposals)/(0.2 + nᵢ)` of its
//!    position and its `nᵢ` proposals, and `vᵢ ← vᵢ + (x'ᵢ − xᵢ)/dt`.
//!
//! A penalty collider is projected after the strain limiting, as the lab's
//! sphere is after the step (its stiffness unused: an explicit penalty force
//! in the prediction launched the cloth where `c·dt²/m ≫ 1`). The proposals are computed once per spring and
//! gathered per vertex. A cloth whose springs form a stencil (every
//! builder's grid) runs step 2 on structure-of-arrays kernels at the CPU's
//! widest SIMD (`solver::engine::stencil::pbd`, crate-private), unless
//! [`StepParams::stencil`] is off.
//! Pinned vertices never move (but their springs still propose positions to
//! their neighbours).
//!
//! A cloth with self-collision has its pairs found once per step, from
//! where it is and where its velocities take it (as `stiff` does), and
//! resolved after the prediction and after each iteration of step 2 (the
//! colliders projected first each time), where
//! the strain limiting answers their pushes in the iterations that follow
//! (each push also moves the vertex's velocity, as the proposals do). Only
//! resolved after the step, the pushes fought the strain limiting of the
//! next step: a 32² sheet folded in four stretched 98.6 % and left 294
//! edges through (the stability map's contact cases).

use bevy::math::Vec3A;

use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use super::{LAB_ITERATIONS, Method, ParamError, StepError, StepInput, StepParams, StepReport};
use crate::collision::self_contact::SelfContacts;
use crate::collision::{PenaltySphere, Shape, project_contacts_on, project_shapes};
use crate::model::ClothState;
use crate::solver::engine::kernels::{PaddedRows, Springs, spring_scales_ends};
use crate::solver::engine::stencil::pbd::PbdStencilWorkspace;

pub use crate::solver::engine::stencil::pbd::SELF_WEIGHT;

/// Steps a cloth by position-based dynamics with the lab's Jacobi strain
/// limiting (see the module docs). Spring stiffness is not used. As a
/// component on a cloth entity it selects this method
/// ([`PbdPlugin`](crate::PbdPlugin)).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Default, Debug, PartialEq)]
pub struct PbdSolver {
    /// Strain-limiting iterations per step.
    pub iterations: u32,
}

impl PbdSolver {
    /// With `iterations` strain-limiting iterations.
    pub const fn new(iterations: u32) -> Self {
        Self { iterations }
    }
}

impl Default for PbdSolver {
    /// 32 iterations (the lab leaves the count open; this matches part 1).
    fn default() -> Self {
        Self::new(LAB_ITERATIONS)
    }
}

impl Method for PbdSolver {
    type Workspace = PbdWorkspace;

    fn name(&self) -> &'static str {
        "pbd"
    }

    fn iterations_mut(&mut self) -> Option<&mut u32> {
        Some(&mut self.iterations)
    }

    fn validate(&self) -> Result<(), ParamError> {
        if self.iterations == 0 {
            return Err(ParamError::Iterations);
        }
        Ok(())
    }

    /// Everything but the stiffness, which PBD does not read.
    fn validate_params(&self, params: &StepParams) -> Result<(), ParamError> {
        params.validate_without_stiffness()
    }

    fn uses_stiffness(&self) -> bool {
        false
    }

    /// Advances `state` by one PBD step (see the module docs). Stiffness is not
    /// used: strain limiting restores rest lengths directly.
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        ws: &mut PbdWorkspace,
    ) -> Result<StepReport, StepError> {
        let StepInput {
            model,
            params,
            spheres,
            self_collision,
            contacts,
            ..
        } = input;
        let config = self;
        let n = model.vertex_count();
        let mut report = StepReport {
            iterations: config.iterations,
            residual: None,
            relative_error: None,
            contacts: 0,
            self_contacts: self_collision.map(|_| 0),
            substeps: 1,
        };
        let springs = model.topology().springs();
        let adjacency = model.topology().adjacency();
        let pinned = model.pinned();
        let dt = params.dt as f32;
        let inv_dt = 1.0 / dt;
        let gravity = Vec3A::from(params.gravity);
        let ClothState {
            positions: x,
            velocities: v,
        } = &mut *state;

        // Self-collision's pairs, from where the cloth is and where its
        // velocities take it, each box grown by the step's fall; the last
        // step's list while it serves (a new search every step was a third
        // of the step with self-collision on a resting 64² fold).
        ws.start.clear();
        if let Some(sc) = self_collision {
            ws.self_contacts
                .find_or_keep(model, x, v, dt, sc, params.fall(), true);
            ws.start.extend_from_slice(&x[..n]);
        }
        for i in 0..n {
            if !pinned[i] {
                v[i] = v[i] * params.damping + dt * gravity;
                x[i] += dt * v[i];
            }
        }
        // Penalty colliders are projected after the strain limiting (as the
        // lab's sphere is after the step): their force, explicit in the
        // prediction, launches a cloth resting on a stiff one
        // (`c·dt²/m` ≫ 1).
        ws.solids.clear();
        ws.solids
            .extend(spheres.iter().map(PenaltySphere::as_shape));

        // The structure-of-arrays kernels where the springs form a stencil.
        // With self-collision, the pairs resolved before the first
        // iteration and after each (the kernels run one at a time).
        let run = if self_collision.is_some() {
            1
        } else {
            config.iterations
        };
        if self_collision.is_some() {
            ws.resolve_self(model, contacts, x, v, 0, config.iterations, dt);
        }
        if let Some(stencil) = model.topology().stencil().filter(|_| params.stencil) {
            let mut done = 0;
            while done < config.iterations {
                let k = run.min(config.iterations - done);
                ws.stencil.load(stencil, x, |i| adjacency.degree(i), pinned);
                ws.stencil
                    .iterate(params.simd, params.parallel, k, inv_dt, x, v);
                done += k;
                if self_collision.is_some() {
                    report.self_contacts =
                        Some(ws.resolve_self(model, contacts, x, v, done, config.iterations, dt));
                }
            }
            report.contacts = project_shapes(model, state, &ws.solids, 0.0, dt) as u32;
            return Ok(report);
        }
        ws.proposals.clear();
        ws.proposals.resize(springs.len() + 1, [Vec3A::ZERO; 2]);
        ws.coeffs.clear();
        ws.coeffs
            .extend(springs.iter().map(|s| [0.0, -0.5 * s.rest_length]));
        ws.inv_weight.clear();
        ws.inv_weight
            .extend((0..n).map(|i| 1.0 / (SELF_WEIGHT + adjacency.degree(i) as f32)));
        ws.rows.update::<[Vec3A; 2]>(adjacency, springs.len() + 1);
        for iteration in 1..=config.iterations {
            let proposals = &mut ws.proposals;
            assert_eq!(x.len(), n);
            spring_scales_ends(Springs::of(model), &ws.coeffs, x, |e, d, half, xa, xb| {
                let mid = 0.5 * (xa + xb);
                let half = d * half;
                proposals[e] = [mid + half, mid - half];
            });
            let proposals = &ws.proposals[..];
            let inv_weight = &ws.inv_weight[..n];
            let (x, v) = (&mut x[..n], &mut v[..n]);
            let update = |x: &mut Vec3A, v: &mut Vec3A, sum: Vec3A, inv_weight: f32| {
                let new = sum * inv_weight;
                *v += (new - *x) * inv_dt;
                *x = new;
            };
            match (!ws.rows.is_empty()).then(|| ws.rows.gather(0..n, proposals)) {
                // Fixed length, summed as a tree (see the implicit solver).
                Some(rows) => {
                    let rows = rows.first(n);
                    for i in 0..n {
                        if pinned[i] {
                            continue;
                        }
                        let (starts, ends) = rows.sums(i, |p| p[0], |p| p[1]);
                        let sum = SELF_WEIGHT * x[i] + (starts + ends);
                        update(&mut x[i], &mut v[i], sum, inv_weight[i]);
                    }
                }
                None => {
                    for i in 0..n {
                        if pinned[i] {
                            continue;
                        }
                        let (starts, ends) = adjacency.by_side(i);
                        let mut sum = SELF_WEIGHT * x[i];
                        for &e in starts {
                            sum += proposals[e as usize][0];
                        }
                        for &e in ends {
                            sum += proposals[e as usize][1];
                        }
                        update(&mut x[i], &mut v[i], sum, inv_weight[i]);
                    }
                }
            }
            if self_collision.is_some() {
                report.self_contacts =
                    Some(ws.resolve_self(model, contacts, x, v, iteration, config.iterations, dt));
            }
        }
        report.contacts = project_shapes(model, state, &ws.solids, 0.0, dt) as u32;
        Ok(report)
    }
}

/// Scratch buffers of the PBD solver, sized on first use.
#[derive(Clone, Debug, Default)]
pub struct PbdWorkspace {
    /// Per spring: the positions it proposes for its `a` and its `b`
    /// (midpoint ± half the rest-length vector), then a zero pair that
    /// padded gathers read.
    proposals: Vec<[Vec3A; 2]>,
    /// Per spring `[0, −L/2]` (see `spring_scales`).
    coeffs: Vec<[f32; 2]>,
    /// Per vertex: `1/(0.2 + nᵢ)`.
    inv_weight: Vec<f32>,
    /// The model's padded rows (as offsets into `proposals`), when it has
    /// them.
    rows: PaddedRows,
    /// The structure-of-arrays state of the stencil kernels.
    stencil: PbdStencilWorkspace,
    /// The step's penalty colliders as solids to project.
    solids: Vec<Shape>,
    /// Self-collision's pairs for the step.
    self_contacts: SelfContacts,
    /// With self-collision: where the vertices were at the step's start.
    start: Vec<Vec3A>,
    /// Scratch: the positions before a pass over the pairs.
    before: Vec<Vec3A>,
}

impl PbdWorkspace {
    /// After `done` of the step's `iterations`: the free vertices projected
    /// out of the `solids` (where they are, with friction), then one pass
    /// over the step's self-collision pairs (parting those that started
    /// too close as far as the step has got), each push added to the
    /// vertex's velocity over `dt`. Returns the pairs that were touching.
    #[allow(clippy::too_many_arguments)]
    fn resolve_self(
        &mut self,
        model: &crate::model::ClothModel,
        solids: &[Shape],
        x: &mut [Vec3A],
        v: &mut [Vec3A],
        done: u32,
        iterations: u32,
        dt: f32,
    ) -> u32 {
        let n = self.start.len().min(x.len()).min(v.len());
        let inv_dt = 1.0 / dt;
        // The colliders first, so the pairs push from where they hold the
        // cloth (after the step, the ground's projection lifted the bottom
        // layer into the next, and the sheet tangled).
        project_contacts_on(model, &mut x[..n], &mut v[..n], solids, dt, |s, x| {
            s.contact(x, 0.0)
                .map(|(normal, depth)| (normal, depth, s.friction()))
        });
        self.before.clear();
        self.before.extend_from_slice(&x[..n]);
        let start = &self.start;
        let touching = self.self_contacts.resolve_substep(
            model,
            &mut x[..n],
            |i| start[i],
            [0.0, done as f32 / iterations as f32],
        );
        for ((v, &x), &b) in v[..n].iter_mut().zip(&x[..n]).zip(&self.before) {
            *v += (x - b) * inv_dt;
        }
        touching
    }
}
