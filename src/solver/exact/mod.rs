//! Exact implicit Euler: Newton's method on the lab's objective, to a
//! gradient tolerance — the reference every other method is measured
//! against, and a method of its own for users who need accuracy.
//!
//! One step minimises, in `f64`,
//!
//! `Φ(x) = 1/(2dt²)‖x − x̃‖²_M + Σ_springs ½k(l − L)² − Σ m g·x (+ Σ_contacts ½c d²)`
//!
//! with `x̃ = x + dt·damping·v` (the lab's prediction), starting from
//! `x = x̃`. A cloth with a [`SelfCollision`](crate::SelfCollision) adds its
//! pairs' terms `½c(min − l)²`, `l` the pair's distance along its direction
//! at the step's start, at the same `c` (their Hessian blocks join the
//! springs' pattern, which is made again when a pair appears that it lacks). The contact terms are the penalty spheres and, with
//! [`ExactSolver::contacts`] (the default), the solids the plugin projects
//! after the step ([`StepInput::contacts`]) at a stiffness `c` of
//! [`ExactSolver::CONTACT_STIFFNESS`] times the heaviest vertex's `m/dt²`.
//! A contact with friction `μ` adds lagged Coulomb friction (Li et al.
//! 2020, IPC): for a vertex the last step ended in contact with normal
//! force `λ` and normal `n`, the term `μλ·f₀(‖(I − nnᵀ)(x − x₀)‖)`, where
//! `f₀` is the tangential slip `y` beyond `ε` and a smooth quadratic start
//! below it (static friction: a held vertex creeps at most `ε/dt`, a
//! thousandth of the cloth's size per second); its Hessian is taken as
//! `μλ f₁(y)/y·(I − nnᵀ)`, positive semi-definite. Each Newton iteration assembles the Hessian
//! `H = M/dt² + Σ k[nnᵀ + (1 − L/l)(I − nnᵀ)]` on the sparse pattern of
//! [`linear`](super::linear) (it is `(M − h²K)/h²`), factorises it by sparse
//! Cholesky (symbolic analysis once per pattern), solves `H d = −∇Φ`, and
//! backtracks (Armijo, halving) along `d`. The **true** Hessian converges
//! quadratically but is indefinite where springs are compressed; when its
//! factorisation fails, that iteration uses the **projected** Hessian (each
//! spring's `1 − L/l` clamped at 0, which is positive definite), which always
//! works but converges only linearly. The iteration stops when
//! `‖∇Φ‖ ≤ tolerance·‖∇Φ(x̃)‖` (default 1e-9), when the Newton step falls
//! below round-off (the gradient of a cloth near rest can have a floor just
//! above that tolerance in `f64`), or after `max_iterations`.
//! Then `v = (x − x_old)/dt`.
//!
//! The Hessian's sparse Cholesky is always supernodal
//! (`SparseCholesky::for_block_hessian`, in the engine room): its 3×3 blocks make dense
//! supernodes; on the lab's 21² cloth that halves the step against the
//! row-by-row factor faer's heuristic picks there.
//!
//! **Newton on a budget** ([`ExactSolver::BUDGET`], preset `newton`): the
//! same iteration to a relative gradient of 1e-5, at most 16 iterations.
//! Where the springs are soft for the time step it stops after one or two
//! iterations; on stiff cloth (k = 1e7–1e8 at long steps, where projective
//! dynamics locks) it spends its budget and stays with the exact run.

use bevy::math::{DMat3, DVec3, Vec3A};

use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use super::linear::{
    LinearImplicitSolver, LinearSystem, PenaltyJacobian, SpringJacobian, normalise,
};
use super::params::check_budget;
use super::{
    ConvergenceSums, Method, ParamError, SolveError, StepError, StepInput, StepParams, StepReport,
};
use crate::collision::self_contact::PairTerms;
use crate::collision::{PenaltySphere, PenaltySurface};
use crate::model::{ClothModel, ClothState};
use crate::solver::engine::cholesky::SparseCholesky;

/// Steps a cloth by exact implicit Euler: Newton's method with sparse
/// Cholesky and a line search on the lab's objective, to a gradient
/// tolerance (see the module docs). The reference the other methods are
/// measured against. As a component on a cloth entity it selects this
/// method ([`ExactPlugin`](crate::ExactPlugin)).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Default, Debug, PartialEq)]
pub struct ExactSolver {
    /// Relative gradient tolerance `‖∇Φ‖/‖∇Φ(x̃)‖` (default 1e-9).
    pub tolerance: f64,
    /// Newton iteration cap (default 100).
    pub max_iterations: u32,
    /// Use the projected Hessian from the start (always positive definite,
    /// linear convergence) instead of the true one.
    pub projected_only: bool,
    /// Where Newton starts: the lab's prediction `x̃` (default) or the
    /// current positions. From the current positions, one full Newton step
    /// with the true Hessian is exactly the linearly implicit Euler step.
    pub start_at_current: bool,
    /// Backtracking line search (default on); off takes full Newton steps.
    pub line_search: bool,
    /// The solids projected after the step ([`StepInput::contacts`]) as
    /// penalty terms of the objective too (default on), with the stiffness
    /// [`CONTACT_STIFFNESS`](Self::CONTACT_STIFFNESS)` · m_max/dt²`: the
    /// step converges to an implicit step *with* its contacts, and the
    /// projection after it has little left to move: alone, that projection
    /// moves vertices the stiff springs cannot follow within the step, and
    /// strains the cloth (the stability map's scenes on the sphere).
    pub contacts: bool,
}

impl ExactSolver {
    /// The reference: relative gradient tolerance 1e-9, at most 100 Newton
    /// iterations, the true Hessian where it factorises, line search.
    pub const REFERENCE: Self = Self {
        tolerance: 1e-9,
        max_iterations: 100,
        projected_only: false,
        start_at_current: false,
        line_search: true,
        contacts: true,
    };

    /// Newton on a budget, for stiff cloth at interactive rates: a relative
    /// gradient tolerance of 1e-5 and at most 16 Newton iterations. Named
    /// `newton`. On the lab cloth it stops after one or two iterations
    /// where the springs are soft for the time step and spends up to its
    /// budget only where they are stiff (k·dt²/m ≫ 1; its cost per step is
    /// on the perf page), where
    /// the iterative methods at their interactive settings fall short of
    /// the exact step (see the stability map).
    pub const BUDGET: Self = Self {
        tolerance: 1e-5,
        max_iterations: 16,
        ..Self::REFERENCE
    };

    /// A contact's penalty stiffness over the heaviest vertex's `m/dt²`:
    /// stiff enough that a vertex pressed by its weight and its springs'
    /// pull stays close to the surface (the projection after the step then
    /// has little to move), and soft enough beside the inertia that the
    /// Hessian stays well conditioned for the direct solve.
    pub const CONTACT_STIFFNESS: f64 = 1e3;

    /// The loosest tolerance still called `exact`: tighter settings are the
    /// reference, looser ones Newton on a budget (`newton`).
    pub const EXACT_TOLERANCE: f64 = 1e-8;
}

impl Default for ExactSolver {
    /// [`ExactSolver::REFERENCE`].
    fn default() -> Self {
        Self::REFERENCE
    }
}

impl Method for ExactSolver {
    type Workspace = ExactWorkspace;

    /// `exact` at a tolerance of [`EXACT_TOLERANCE`](Self::EXACT_TOLERANCE)
    /// or tighter (a reference), `newton` above it (Newton on a budget,
    /// [`BUDGET`](Self::BUDGET)).
    fn name(&self) -> &'static str {
        if self.tolerance <= Self::EXACT_TOLERANCE {
            "exact"
        } else {
            "newton"
        }
    }

    fn iterations_mut(&mut self) -> Option<&mut u32> {
        Some(&mut self.max_iterations)
    }

    fn validate(&self) -> Result<(), ParamError> {
        check_budget(self.max_iterations, self.tolerance)
    }

    /// Advances `state` by one exact implicit-Euler step (see the module docs).
    /// The report's residual is the final relative gradient norm.
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        ws: &mut ExactWorkspace,
    ) -> Result<StepReport, StepError> {
        let StepInput {
            model,
            params,
            spheres,
            contacts,
            skin: _,
            self_collision,
            contact_motion: _,
        } = input;
        let config = self;
        let n = model.vertex_count();
        let heaviest = model.masses().iter().copied().fold(0.0f32, f32::max);
        let contact_stiffness =
            Self::CONTACT_STIFFNESS * f64::from(heaviest) / (params.dt * params.dt);
        // Self-collision's pairs as terms of the objective (the plugin's
        // pass after the step then has little left to move), found with
        // the step's fall `|g|·dt²` (as `stiff` and PBD find theirs): from
        // the velocities' path alone, the pairs the step's forces brought
        // together were left to the pass after it, which stretched the
        // map's upper sheet 10.1 % as it landed on the lower (0.3 % left
        // by the solve; 3.5 % with them in it).
        let c = contact_stiffness;
        let path = (params.dt, params.fall());
        ws.pairs.update(model, state, path, self_collision, c, true);
        // The penalty spheres, and the contacts as penalties.
        ws.penalties.clear();
        ws.penalties.extend_from_slice(spheres);
        if config.contacts && !contacts.is_empty() {
            let stiffness = contact_stiffness.min(f64::from(f32::MAX)) as f32;
            ws.penalties.extend(
                contacts
                    .iter()
                    .map(|&shape| PenaltySphere::shape(shape, stiffness)),
            );
        }
        let penalties = core::mem::take(&mut ws.penalties);
        let spheres = &penalties[..];
        // The pairs' terms couple vertices no spring joins: the pattern
        // holds their blocks too, made again (with its symbolic analysis)
        // when a pair appears that it lacks.
        ws.pairs.couplings(&mut ws.couplings);
        normalise(&mut ws.couplings);
        if ws
            .system
            .as_ref()
            .is_none_or(|s| !s.covers(model, &ws.couplings))
        {
            ws.system = Some(LinearSystem::with_couplings(model, ws.couplings.clone()));
            ws.cholesky = SparseCholesky::for_block_hessian();
        }
        let system = ws.system.as_mut().expect("just built");
        let dims = system.dimension();
        ws.gradient.resize(dims, 0.0);
        ws.direction.resize(dims, 0.0);
        ws.zeros.resize(n, Vec3A::ZERO);
        let dt = params.dt;
        let pinned = model.pinned();
        // The lab's prediction, in f64.
        ws.x.clear();
        ws.x_tilde.clear();
        for (i, (x, v)) in state.positions.iter().zip(&state.velocities).enumerate() {
            let x = x.as_dvec3();
            let v = if pinned[i] {
                DVec3::ZERO
            } else {
                v.as_dvec3() * f64::from(params.damping)
            };
            ws.x_tilde.push(x + dt * v);
            ws.x.push(if config.start_at_current {
                x
            } else {
                x + dt * v
            });
        }
        // Pinned vertices stay where they are.
        for &p in model.pins() {
            ws.x[p as usize] = state.positions[p as usize].as_dvec3();
            ws.x_tilde[p as usize] = ws.x[p as usize];
        }
        // Friction from the contacts the last step ended in (lagged), where
        // the same colliders are still there.
        ws.friction.clear();
        let eps = STICK_SPEED * f64::from(model.size()) * dt;
        if ws.ended_in.1 == spheres.len() && eps > 0.0 {
            ws.friction.extend(
                ws.ended_in
                    .0
                    .iter()
                    .filter(|&&(i, ..)| (i as usize) < n && !pinned[i as usize])
                    .map(|&(i, _, bound, normal)| Friction {
                        vertex: i as usize,
                        start: state.positions[i as usize].as_dvec3(),
                        normal,
                        bound,
                    }),
            );
        }
        let friction = (&ws.friction[..], eps);
        let pairs = &ws.pairs;
        let mut report = ExactReport::default();
        let g0 = gradient(
            model,
            system,
            &ws.x,
            &ws.x_tilde,
            params,
            (spheres, friction, pairs),
            &mut ws.gradient,
        );
        let mut g_norm = g0;
        let threshold = config.tolerance * g0;
        let h2 = dt * dt;
        let mut iterations = 0;
        // The gradient's ratio over the last accepted step (the step itself
        // is kept in `ws.last_step`), for the error estimate.
        let mut last_ratio: Option<f64> = None;
        while g_norm > threshold && iterations < config.max_iterations {
            iterations += 1;
            // The Hessian, scaled by h²: (M − h²K) at x.
            let mut solved = false;
            for projected in [config.projected_only, true] {
                let hessian = LinearImplicitSolver {
                    springs: if projected {
                        SpringJacobian::ClampCompression
                    } else {
                        SpringJacobian::Exact
                    },
                    penalty: if projected {
                        PenaltyJacobian::Normal
                    } else {
                        PenaltyJacobian::Exact
                    },
                    ..LinearImplicitSolver::default()
                };
                system.assemble_at(model, &ws.x, &ws.zeros, params, &hessian, spheres);
                for f in friction.0 {
                    system.add_to_diagonal(f.vertex, &(f.hessian(ws.x[f.vertex], eps) * h2));
                }
                pairs.hessian(&ws.x, |i, j, block| {
                    system.add_block_at(i, j, &(block * h2));
                });
                for (d, g) in ws.direction.iter_mut().zip(&ws.gradient) {
                    *d = -h2 * g;
                }
                if ws
                    .cholesky
                    .solve_llt(system.matrix(), &mut ws.direction)
                    .is_ok()
                {
                    if projected {
                        report.projected_hessian += 1;
                    } else {
                        report.true_hessian += 1;
                    }
                    solved = true;
                    break;
                }
            }
            if !solved {
                report.stalled = Some(SolveError::Factorization);
                break;
            }
            // A Newton step below round-off: the gradient cannot get smaller in
            // f64 (its floor is ~1e-16 of the spring forces); stop, converged.
            let step_size = ws.direction.iter().fold(0.0f64, |m, d| m.max(d.abs()));
            let scale =
                ws.x.iter()
                    .fold(1.0f64, |m, x| m.max(x.abs().max_element()));
            if step_size <= 1e-11 * scale {
                report.at_round_off = true;
                break;
            }
            // Backtracking (Armijo) line search along the Newton direction.
            let phi = objective(
                model,
                &ws.x,
                &ws.x_tilde,
                params,
                (spheres, friction, pairs),
            );
            let slope: f64 = ws
                .gradient
                .iter()
                .zip(&ws.direction)
                .map(|(g, d)| g * d)
                .sum();
            let mut alpha = 1.0;
            let mut accepted = false;
            // Where the predicted decrease is below Φ's round-off, Armijo's test
            // only sees noise: take the full (quadratically convergent) step.
            let line_search = config.line_search && -slope > 1e-13 * (1.0 + phi.abs());
            for _ in 0..40 {
                ws.trial.clone_from(&ws.x);
                for i in 0..n {
                    if let Some(d) = system.dof(i) {
                        ws.trial[i] += alpha
                            * DVec3::new(ws.direction[d], ws.direction[d + 1], ws.direction[d + 2]);
                    }
                }
                if !line_search
                    || objective(
                        model,
                        &ws.trial,
                        &ws.x_tilde,
                        params,
                        (spheres, friction, pairs),
                    ) <= phi + 1e-4 * alpha * slope
                {
                    accepted = true;
                    break;
                }
                alpha *= 0.5;
            }
            if !accepted {
                report.stalled = Some(SolveError::LineSearch);
                break;
            }
            std::mem::swap(&mut ws.x, &mut ws.trial);
            ws.last_step.clear();
            ws.last_step
                .extend(ws.x.iter().zip(&ws.trial).map(|(new, old)| *new - *old));
            let before = g_norm;
            g_norm = gradient(
                model,
                system,
                &ws.x,
                &ws.x_tilde,
                params,
                (spheres, friction, pairs),
                &mut ws.gradient,
            );
            last_ratio = Some(if before > 0.0 { g_norm / before } else { 0.0 });
        }
        // The contacts this step ends in, for the next step's friction.
        ws.ended_in.0.clear();
        ws.ended_in.1 = spheres.len();
        for (k, sphere) in spheres.iter().enumerate() {
            let PenaltySurface::Shape(shape) = sphere.surface else {
                continue;
            };
            let mu = f64::from(shape.friction());
            if mu > 0.0 {
                for (i, &x) in ws.x.iter().enumerate() {
                    if let Some(c) = (!pinned[i]).then(|| sphere.contact_f64(x)).flatten() {
                        let bound = mu * f64::from(sphere.stiffness) * c.depth;
                        ws.ended_in.0.push((i as u32, k as u32, bound, c.normal));
                    }
                }
            }
        }
        report.relative_gradient = if g0 > 0.0 { g_norm / g0 } else { 0.0 };
        report.converged = g_norm <= threshold || report.at_round_off;
        ws.last = report;
        if let Some(error) = report.stalled.filter(|_| !report.converged) {
            // Stopped short with nowhere to go: a typed failure the guard
            // retries in substeps or stops the cloth on, never a silent
            // half-step (the state still holds the step's start).
            ws.penalties = penalties;
            return Err(StepError::Solve(error));
        }
        let relative_error = newton_error(model, state, ws, params, last_ratio);
        let ClothState {
            positions,
            velocities,
        } = state;
        for (i, (x, v)) in positions.iter_mut().zip(velocities.iter_mut()).enumerate() {
            if pinned[i] {
                continue;
            }
            *v = ((ws.x[i] - x.as_dvec3()) / dt).as_vec3a();
            *x = ws.x[i].as_vec3a();
        }
        ws.penalties = penalties;
        Ok(StepReport {
            iterations,
            residual: Some(report.relative_gradient as f32),
            relative_error: Some(relative_error),
            contacts: 0,
            self_contacts: None,
            substeps: 1,
        })
    }
}

/// What the last exact step did, beyond its [`StepReport`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExactReport {
    /// Newton iterations with the true Hessian.
    pub true_hessian: u32,
    /// Newton iterations that fell back to (or used only) the projected one.
    pub projected_hessian: u32,
    /// Final relative gradient norm.
    pub relative_gradient: f64,
    /// True if the tolerance was reached, or the Newton step fell below
    /// round-off first.
    pub converged: bool,
    /// True if the iteration stopped because the Newton step fell below
    /// round-off (`‖d‖∞ ≤ 1e-11·max|x|`, far below the `f32` state's
    /// precision) before the gradient tolerance.
    pub at_round_off: bool,
    /// Why the iteration stopped short, if it did: neither Hessian
    /// factorised, or the line search found no decrease along the Newton
    /// direction.
    pub stalled: Option<SolveError>,
}

/// Scratch of the exact solver.
#[derive(Default)]
pub struct ExactWorkspace {
    system: Option<LinearSystem>,
    cholesky: SparseCholesky,
    x: Vec<DVec3>,
    x_tilde: Vec<DVec3>,
    trial: Vec<DVec3>,
    last_step: Vec<DVec3>,
    gradient: Vec<f64>,
    direction: Vec<f64>,
    zeros: Vec<Vec3A>,
    last: ExactReport,
    /// The step's penalty spheres and contacts as penalties.
    penalties: Vec<PenaltySphere>,
    /// Friction of this step: from the last step's contacts (see
    /// [`Friction`]).
    friction: Vec<Friction>,
    /// The contacts the last step ended in, with friction: `(vertex,
    /// penalty, μ·λ, normal)`; and the penalty count they index.
    ended_in: (Vec<(u32, u32, f64, DVec3)>, usize),
    /// Self-collision's pairs as terms of the objective.
    pairs: PairTerms,
    /// Scratch: the vertex pairs their terms couple.
    couplings: Vec<(u32, u32)>,
}

/// The speed below which friction holds a vertex, per metre of cloth size
/// (IPC's `ε_v`, Li et al. 2020): a cloth in static contact creeps at most
/// a thousandth of its size per second.
pub(crate) const STICK_SPEED: f64 = 1e-3;

/// One vertex's lagged Coulomb friction against a collider, a term of the
/// step's objective (Li et al. 2020, "Incremental Potential Contact",
/// section 5): with `u = (I − nnᵀ)(x − x₀)` its tangential motion over the
/// step, `μλ·f₀(‖u‖)` where `f₀` is `‖u‖` beyond `ε` and a smooth quadratic
/// start below it (static friction). The normal force `λ` and the normal
/// `n` are the previous step's at its end: lagged, so the term is convex.
#[derive(Clone, Copy, Debug)]
struct Friction {
    vertex: usize,
    start: DVec3,
    normal: DVec3,
    /// `μλ`.
    bound: f64,
}

impl Friction {
    /// `(u, ‖u‖)` at `x`.
    fn slip(&self, x: DVec3) -> (DVec3, f64) {
        let d = x - self.start;
        let u = d - self.normal * self.normal.dot(d);
        (u, u.length())
    }

    /// `μλ·f₀(‖u‖)`.
    fn energy(&self, x: DVec3, eps: f64) -> f64 {
        let (_, y) = self.slip(x);
        self.bound
            * if y < eps {
                -y * y * y / (3.0 * eps * eps) + y * y / eps + eps / 3.0
            } else {
                y
            }
    }

    /// `μλ·f₁(y)/y`: the gradient is this times `u`, and the Hessian is
    /// taken as this times `I − nnᵀ` (positive semi-definite).
    fn stiffness(&self, y: f64, eps: f64) -> f64 {
        self.bound
            * if y < eps {
                (2.0 - y / eps) / eps
            } else {
                1.0 / y
            }
    }

    /// The gradient at `x`.
    fn gradient(&self, x: DVec3, eps: f64) -> DVec3 {
        let (u, y) = self.slip(x);
        u * self.stiffness(y, eps)
    }

    /// The Hessian at `x` (see [`stiffness`](Self::stiffness)).
    fn hessian(&self, x: DVec3, eps: f64) -> DMat3 {
        let (_, y) = self.slip(x);
        let n = self.normal;
        let nn = DMat3::from_cols(n * n.x, n * n.y, n * n.z);
        (DMat3::IDENTITY - nn) * self.stiffness(y, eps)
    }
}

impl core::fmt::Debug for ExactWorkspace {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ExactWorkspace")
            .field("last", &self.last)
            .finish_non_exhaustive()
    }
}

impl ExactWorkspace {
    /// What the last step did (for the report's measurements: hidden from
    /// the docs, as the engine room is).
    #[doc(hidden)]
    pub fn last_report(&self) -> ExactReport {
        self.last
    }
}

/// The step's [`relative_error`](StepReport::relative_error) (see
/// [`ConvergenceSums`]), with Newton's own estimate of the distance left to
/// the minimiser: after a last step `s` that cut the gradient by the ratio
/// `r`, a linearly converging iteration has about `r/(1 − r)·s` still to go
/// (quadratic convergence makes `r` tiny, so a converged step reports
/// almost nothing); a step that stopped short of its tolerance (its budget
/// spent), or whose last step did not lower the gradient, counts that last
/// step at least whole: on stiff cloth the gradient's ratio alone
/// underestimated the distance up to tenfold (one Newton iteration a step
/// at k = 1e7, dt = 0.1), with the whole step it stays within 0.8–3× of it.
/// Before any step (the iteration stopped at `x̃`), the iterative
/// methods' estimate `dt²/m·∇Φ`. Measured against the motion from the
/// state's positions, which still hold the start of the step.
fn newton_error(
    model: &ClothModel,
    state: &ClothState,
    ws: &ExactWorkspace,
    params: &StepParams,
    last_ratio: Option<f64>,
) -> f32 {
    let dt2 = params.dt * params.dt;
    let converged = ws.last.converged;
    let scale = last_ratio.map(|r| {
        let ahead = if r < 1.0 { r / (1.0 - r) } else { 1.0 };
        if converged { ahead } else { ahead.max(1.0) }
    });
    let Some(system) = ws.system.as_ref() else {
        return 0.0;
    };
    let mut sums = ConvergenceSums::default();
    for (i, (&m, x)) in model.masses().iter().zip(&ws.x).enumerate() {
        let Some(d) = system.dof(i) else { continue };
        let error = match scale {
            Some(scale) => ws.last_step[i] * scale,
            None => {
                DVec3::new(ws.gradient[d], ws.gradient[d + 1], ws.gradient[d + 2])
                    * (dt2 / f64::from(m))
            }
        };
        sums.add_f64(error, *x - state.positions[i].as_dvec3());
    }
    sums.relative_error(model, params.dt)
}

/// The objective's terms beyond inertia, gravity and springs: penalties,
/// friction (with its `ε`) and self-collision's pairs.
type Terms<'a> = (&'a [PenaltySphere], (&'a [Friction], f64), &'a PairTerms);

/// `Φ(x)` in `f64`.
fn objective(
    model: &ClothModel,
    x: &[DVec3],
    x_tilde: &[DVec3],
    params: &StepParams,
    (spheres, (friction, eps), pairs): Terms<'_>,
) -> f64 {
    let inv_dt2 = 1.0 / (params.dt * params.dt);
    let g = params.gravity.as_dvec3();
    let mut e: f64 = friction.iter().map(|f| f.energy(x[f.vertex], eps)).sum();
    e += pairs.energy(x);
    for (i, &m) in model.masses().iter().enumerate() {
        if model.pinned()[i] {
            continue;
        }
        let m = f64::from(m);
        e += 0.5 * m * inv_dt2 * (x[i] - x_tilde[i]).length_squared() - m * g.dot(x[i]);
        for s in spheres {
            if let Some(contact) = s.contact_f64(x[i]) {
                e += 0.5 * f64::from(s.stiffness) * contact.depth * contact.depth;
            }
        }
    }
    for s in model.topology().springs() {
        let l = (x[s.a as usize] - x[s.b as usize]).length();
        let stretch = l - f64::from(s.rest_length);
        e += 0.5 * f64::from(params.stiffness.of(s.kind)) * stretch * stretch;
    }
    e
}

/// `∇Φ(x)` over the system's unknowns into `out`; returns its norm.
fn gradient(
    model: &ClothModel,
    system: &LinearSystem,
    x: &[DVec3],
    x_tilde: &[DVec3],
    params: &StepParams,
    (spheres, (friction, eps), pairs): Terms<'_>,
    out: &mut [f64],
) -> f64 {
    out.fill(0.0);
    let inv_dt2 = 1.0 / (params.dt * params.dt);
    let g = params.gravity.as_dvec3();
    let add = |i: usize, v: DVec3, out: &mut [f64]| {
        if let Some(d) = system.dof(i) {
            out[d] += v.x;
            out[d + 1] += v.y;
            out[d + 2] += v.z;
        }
    };
    for (i, &m) in model.masses().iter().enumerate() {
        let m = f64::from(m);
        let mut v = (x[i] - x_tilde[i]) * (m * inv_dt2) - g * m;
        for s in spheres {
            if let Some(contact) = s.contact_f64(x[i]) {
                v -= contact.force;
            }
        }
        add(i, v, out);
    }
    for f in friction {
        add(f.vertex, f.gradient(x[f.vertex], eps), out);
    }
    pairs.gradient(x, |i, g| add(i, g, out));
    for s in model.topology().springs() {
        let (a, b) = (s.a as usize, s.b as usize);
        let d = x[a] - x[b];
        let l = d.length();
        if l == 0.0 {
            continue;
        }
        let t = d * (f64::from(params.stiffness.of(s.kind)) * (1.0 - f64::from(s.rest_length) / l));
        add(a, t, out);
        add(b, -t, out);
    }
    out.iter().map(|v| v * v).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests;
