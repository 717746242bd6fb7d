//! Projective dynamics for mass-spring cloth: the local–global solver of
//! Liu, Bargteil, O'Brien and Kavan (2013, "Fast simulation of mass-spring
//! systems"), with Chebyshev acceleration (Wang 2015, which was first shown
//! on exactly this solver).
//!
//! It minimises the same implicit-Euler objective as the lab's implicit
//! solver and the exact method,
//!
//! `Φ(x) = Σ m/(2h²)‖x − x̃‖² + Σ_e k_e/2 (‖x_a − x_b‖ − L_e)² − Σ m g·x`,
//!
//! with `x̃ = x + h·damping·v`, by writing each spring's energy as
//! `k_e/2 min_{‖d‖ = L_e} ‖(x_a − x_b) − d‖²` and alternating:
//!
//! 1. **local**: each spring's projection `d_e = L_e (x_a − x_b)/‖x_a − x_b‖`
//!    (the packed-SIMD spring pass the other methods share; on a cloth whose
//!    springs form a stencil, the stencil kernels' spring pass gives each
//!    `k_e·d_e` and sums them per vertex for the right-hand side, unless
//!    [`StepParams::stencil`] is off);
//! 2. **global**: `(M/h² + Σ k_e A_eᵀA_e) x = M/h² x̃ + M g + Σ k_e A_eᵀ d_e`.
//!
//! The global matrix `S` is a weighted graph Laplacian plus the mass
//! diagonal over the free vertices: one scalar `n×n` matrix for the three
//! coordinates, symmetric positive definite because every mass is positive
//! (`xᵀSx ≥ Σ m/h² x² > 0`). It is constant while the topology, the pins, the
//! masses, the stiffness and `h` stay the same, so it is factorised once
//! (faer's sparse Cholesky, AMD ordering, symbolic analysis kept) and only
//! refactorised when one of them changes; each iteration is one forward and
//! one back substitution with the three coordinates as an `n×3` block
//! (hand-written for three columns:
//! `SparseCholesky::solve_factored_xyz` in the engine room;
//! on faer's simplicial factor, which it picks for small cloths, the
//! coordinates are lanes of one vector and the rows and columns are taken
//! by level of the elimination tree; on the supernodal one, the solve is
//! split over two threads along the elimination tree).
//! Pinned vertices carry no unknowns: their positions enter the right-hand
//! side, so pins that follow their entity need no refactorisation.
//!
//! **On larger cloths the global step is one multigrid V-cycle** instead
//! ([`GlobalSolve`]; by default from [`MULTIGRID_FROM`] free vertices, and
//! never with Anderson acceleration): smoothed-aggregation algebraic
//! multigrid built from `S` once per factorisation (the `multigrid`
//! module), whose finest level runs on the cloth's stencil at the CPU's
//! widest SIMD. The cycle solves `S δ = b − S x₀` for the correction from
//! the current iterate `x₀`, and `b − S x₀` is the objective's negative
//! gradient `−∇Φ(x₀)` (the stencil kernels' spring pass with the implicit
//! iteration's coefficients), so the iteration's fixed point is the same
//! and the `f32` cycle rounds the small `δ`, not `x`. Each iteration
//! gains a little less than with the exact solve on stiff cloth, and costs
//! far less on large cloths (`docs/perf.md`).
//!
//! Every iteration decreases `Φ` (it is block coordinate descent on `x` and
//! the `d_e`), so the iteration is stable at any stiffness and time step;
//! it converges linearly, slower for strongly bent or compressed cloth and
//! much slower for stiff springs (`k h²/m` ≫ 1), where the sheet "locks".
//!
//! **The early stop** ([`ProjectiveSolver::tolerance`]; the preset
//! [`ProjectiveSolver::PRESET`] stops at [`PD_TOLERANCE`] within its
//! budget of [`PD_ITERATIONS`]): before each global solve the iteration
//! estimates the step's error at the current iterate with the measure of
//! [`StepReport::relative_error`] (`dt²/m` times the objective's gradient,
//! against the step's motion) and stops once it is within the tolerance.
//! The gradient costs no extra spring pass: it is `S x_j − b_j`, the
//! right-hand side just made, and `S x_j` follows from the earlier
//! right-hand sides (the solve gave `S x̂ = b`; Chebyshev's iterate is a
//! blend of two such). The multigrid's right-hand side is the gradient
//! itself. So a soft, swinging cloth stops after a few iterations (5 of 10
//! on the perf page's 21² cloth) and a stiff one, whose estimate stays
//! above the tolerance, runs the whole budget; the iterates are the same as
//! without the stop, only fewer.
//!
//! **Anderson acceleration** (Peng, Deng, Zhang, Liu 2018) extrapolates
//! from the last few iterates and their residuals `G(x) − x` by a small
//! least-squares problem, and keeps the extrapolated point only if the
//! local step finds it lowers `Φ` (else it takes the plain iterate and
//! restarts the history), so it keeps the descent. On stiff cloth it needs
//! about a quarter of Chebyshev's iterations for the same error.
//! With Chebyshev acceleration the first `clamp(K/4, 2, 8)` iterations are
//! plain and `ρ` is estimated from their update norms (the estimator of
//! [`Rho::Auto`]), or `ρ` is fixed.
//!
//! **Penalty spheres** are projective terms too. A vertex's penalty energy
//! `c/2 (r − ‖x − c‖)²` inside the sphere is `c/2 ‖x − p‖²` with `p` the
//! vertex projected onto the sphere's outside (`p = x` outside), so each
//! vertex near a sphere at the start of the step (within `r/4` of its
//! surface along its predicted motion) gets `c` on its diagonal of `S` and
//! `c·p` in the local step. Outside the sphere the term is zero at the fixed
//! point, so the solution is the same implicit-Euler step; the contact is
//! implicit, which keeps the iteration a descent (as an explicit force at
//! the iterate, a penalty stiffer than the cloth's inertia made it overshoot
//! and grow with the iteration count: the report's sphere scene, before this,
//! had pd's 300-step error rise from 0.39 at 4 iterations to 3.0 at 256).
//! When that set of vertices changes, `S` is refactorised numerically (the
//! symbolic analysis is kept: only diagonal values change); the multigrid
//! keeps its hierarchy and takes the change into each coarse matrix
//! (`Pᵀ ΔS P`: see the `multigrid` module). A vertex that
//! reaches a sphere it was not near gets its penalty as an explicit force.
//!
//! **Self-collision**: a cloth with a [`SelfCollision`](crate::SelfCollision)
//! makes its step's pairs terms too: `c/2 (min − (x_a − x_b)·n)²` while
//! the pair is closer than its least distance `min` along `n`, its
//! direction at the step's start (so an end that passed the other within
//! the step is pushed back), at a stiffness `c` of [`PD_PAIR_STIFFNESS`]
//! times the heaviest vertex's `m/dt²`: each end gets `c` per pair on its diagonal
//! (the pair's off-diagonal blocks are left out: the pairs change every
//! step and are not in `S`'s pattern, so the other end is taken from the
//! iterate, a Jacobi split) and `c·x + f` on its right-hand side. While
//! there are pairs, Chebyshev's acceleration is off: its `ρ` is the
//! springs', and with 30 iterations the accelerated iteration diverged
//! where a sheet landed on another. A Chebyshev-accelerated solver (the
//! `pd` preset) takes Anderson's acceleration instead while there are pairs
//! ([`PD_ANDERSON_WINDOW`], its extrapolations kept only where they lower
//! the objective; no early stop), with its own iteration budget and global
//! solve (the multigrid from [`MULTIGRID_FROM`]): plain iterations left the
//! pairs of a 64² sheet folded in four pressed, and the pass after the step
//! pushed them apart against the springs (23 edges through the sheet, 46 %
//! stretch over 10 s; with Anderson's 10 iterations none, 2.7 %).
//!
//! **Friction** (the `friction` module): a vertex that ended the last step
//! in contact with a collider of friction `μ` gets lagged Coulomb friction,
//! a Huber term of its tangential slip (capped at `μλ`, reached at the
//! exact method's stick slip), whose force rides on the contact's own
//! weight `c` on the diagonal: no refactorisation, and still a descent. The lab's penalty spheres are
//! frictionless. The contact's weight holds each iteration's tangential
//! motion as well as its normal one, so where the budget runs out a
//! frictionless cloth slides too little (a cloth on a 20° slope: Chebyshev's
//! 10 iterations slide a fifth of the exact step's 1.7 m in a second,
//! Anderson's 20 all of it); such steps' estimated error says so.

use bevy::math::{DVec3, Vec3A};
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use super::chebyshev::{Rho, chebyshev_omega, rho_from_update_norms, validate_chebyshev};
use super::{ConvergenceSums, Method, ParamError, StepError, StepInput, StepParams, StepReport};
use crate::collision::PenaltySphere;
use crate::collision::self_contact::PairTerms;
use crate::model::{ClothModel, ClothState};
use crate::solver::engine::cholesky::SparseCholesky;
use crate::solver::engine::kernels::Springs;
use crate::solver::engine::simd::{Simd, spring_products};
use crate::solver::engine::stencil::StencilWorkspace;
use crate::solver::exact::STICK_SPEED;

mod anderson;
mod early_stop;
mod friction;
mod global;
mod local;
mod multigrid;

use global::Solution;
use multigrid::{FineStencil, Multigrid};

use early_stop::EarlyStop;

/// The stiffness of a self-collision pair in projective dynamics'
/// objective, in units of the heaviest vertex's `m/dt²`: ten times a
/// contact's ([`PD_CONTACT_STIFFNESS`]), Newton's. At a contact's, the 10
/// iterations left pairs pressed together that the pass after the step then
/// pushed apart against the springs (the drape's second sheet landing:
/// 49 % stretch; 23 % at this stiffness, 25 % and 37 % at 30 and 100
/// times a contact's; `pd-anderson` 32 % → 6.2 %; measured while the pairs
/// were measured along their line at the iterate, before the line at the
/// step's start).
pub const PD_PAIR_STIFFNESS: f64 = 1e3;

/// The interactive iteration budget of projective dynamics: each iteration
/// costs several of the lab's Jacobi iterations (`docs/perf.md`), and 10
/// Chebyshev-accelerated ones reach the exact step within about 1e-2 on the
/// lab's cloth (see the report). The preset stops before it at
/// [`PD_TOLERANCE`].
pub const PD_ITERATIONS: u32 = 10;

/// The stiffness of a contact in projective dynamics' objective
/// ([`ProjectiveSolver::contacts`]), in units of the heaviest vertex's
/// `m/dt²`: a tenth of `newton`'s. At `newton`'s, the lab cloth falling
/// onto the sphere had most of its steps flagged not converged and
/// stretched more: a contact's weight on the diagonal holds the vertex's
/// motion along the collider as well as into it (it is on all three axes),
/// so the 10 iterations slide the cloth too little. (It was put down to
/// the explicit force of a vertex that reaches a collider it was not near
/// at the step's start; with that force at this stiffness and the rest at
/// `newton`'s, 244 of 300 steps were still flagged: `docs/measurements.md`.)
pub const PD_CONTACT_STIFFNESS: f64 = 1e2;

/// The preset's early stop ([`ProjectiveSolver::tolerance`]): an estimated
/// error of 1 % of the step's motion, the per-step error the budget of
/// [`PD_ITERATIONS`] aims at. A swinging lab cloth stops about halfway
/// through the budget; where the cloth is stiff for its step, and on large
/// cloths (one multigrid V-cycle per iteration), the estimate stays above
/// it and the whole budget runs (the numbers: `docs/perf.md`). The
/// stability map's verdicts and flags are those of the whole budget.
pub const PD_TOLERANCE: f64 = 1e-2;

/// The stiff-cloth setting of projective dynamics: 20 Anderson-accelerated
/// iterations over a window of [`PD_ANDERSON_WINDOW`]. On the lab cloth at
/// k = 1e6–1e8, where 10 Chebyshev iterations leave the sheet 68–74 % short
/// of the exact drop, these reach it within 1–7 % (the stability map), at
/// about 3× the cost of 10 Chebyshev iterations.
pub const PD_ANDERSON_ITERATIONS: u32 = 20;

/// Anderson's window in [`PD_ANDERSON_ITERATIONS`]' setting: 5 past
/// iterates (10 was no better on the lab's stiff cells, and costs more).
pub const PD_ANDERSON_WINDOW: u32 = 5;

/// Steps a cloth by projective dynamics (local–global) on the implicit-Euler
/// objective, optionally Chebyshev-accelerated (see the module docs). As a
/// component on a cloth entity it selects this method
/// ([`ProjectivePlugin`](crate::ProjectivePlugin)).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Default, Debug, PartialEq)]
pub struct ProjectiveSolver {
    /// Local–global iterations per step.
    pub iterations: u32,
    /// Chebyshev acceleration with this `ρ`, or `None` for plain
    /// local–global iterations. While self-collision's pairs are terms of
    /// the objective, a Chebyshev-accelerated solver is Anderson-accelerated
    /// instead (see the module docs).
    pub chebyshev: Option<Rho>,
    /// Anderson acceleration (Peng, Deng, Zhang, Liu 2018, "Anderson
    /// acceleration for geometry optimization and physics simulation") over
    /// this many past iterates, or 0 for none. Each extrapolated iterate is
    /// kept only if it lowers the objective, else the plain local–global
    /// iterate is taken and the history restarts. Not together with
    /// `chebyshev` ([`ParamError::Acceleration`]).
    pub anderson: u32,
    /// How each iteration solves the global system.
    pub global: GlobalSolve,
    /// Stop before `iterations` once the step's estimated relative error
    /// (the measure of [`StepReport::relative_error`]) at the iterate is at
    /// most this; 0 runs every iteration. Plain and Chebyshev iterations
    /// only (see [`ProjectiveWorkspace`]'s estimate): with Anderson
    /// acceleration it is [`ParamError::Tolerance`].
    pub tolerance: f64,
    /// The solids projected after the step ([`StepInput::contacts`]) as
    /// penalty terms of the objective too, like the penalty spheres, at
    /// [`PD_CONTACT_STIFFNESS`] times the heaviest vertex's `m/dt²`: the iteration
    /// converges to an implicit step with its contacts, so a stiff cloth
    /// resting on a collider is not strained by the projection after the
    /// step, nor its step measured against a fall the collider stops. A
    /// collider's friction is a term of the objective too (see the module
    /// docs).
    pub contacts: bool,
}

/// How projective dynamics solves its global system `S x = b` each
/// iteration.
#[derive(Reflect, Clone, Copy, Debug, PartialEq, Default)]
#[reflect(Debug, PartialEq, Default)]
pub enum GlobalSolve {
    /// [`Direct`](Self::Direct) below [`MULTIGRID_FROM`] free vertices,
    /// [`Multigrid`](Self::Multigrid) with [`MULTIGRID_CYCLES`] from there;
    /// always direct with Anderson acceleration, whose extrapolation gains
    /// less from an inexact global solve (the stability map's cell k = 1e7,
    /// dt = 0.0333: 12 % short of the exact drop with one V-cycle per
    /// iteration, 3 % with the direct solve).
    #[default]
    Auto,
    /// Exactly, by the sparse Cholesky factor.
    Direct,
    /// Approximately, by this many algebraic-multigrid V-cycles from the
    /// current iterate (see the [module docs](self)). The iteration's fixed
    /// point is the same; each iteration gains a little less.
    Multigrid {
        /// V-cycles per iteration (at least 1).
        cycles: u32,
    },
}

/// [`GlobalSolve::Auto`] uses multigrid from this many free vertices (64²).
/// Below, the direct solve is cheap and exact, a V-cycle per iteration is
/// no faster, and it would leave 2 more of the stability map's cells wrong
/// (`docs/measurements.md`).
pub const MULTIGRID_FROM: usize = 4096;

/// [`GlobalSolve::Auto`]'s V-cycles per iteration.
pub const MULTIGRID_CYCLES: u32 = 1;

impl GlobalSolve {
    /// The V-cycles per iteration for `free` free vertices (and Anderson
    /// acceleration or not), or `None` for the direct solve.
    fn cycles(self, free: usize, anderson: bool) -> Option<u32> {
        match self {
            Self::Auto => (free >= MULTIGRID_FROM && !anderson).then_some(MULTIGRID_CYCLES),
            Self::Direct => None,
            Self::Multigrid { cycles } => Some(cycles),
        }
    }
}

impl ProjectiveSolver {
    /// Plain local–global iterations.
    pub const fn new(iterations: u32) -> Self {
        Self {
            iterations,
            chebyshev: None,
            anderson: 0,
            global: GlobalSolve::Auto,
            tolerance: 0.0,
            contacts: true,
        }
    }

    /// Chebyshev-accelerated, with `ρ` estimated each step.
    pub const fn chebyshev(iterations: u32) -> Self {
        Self {
            iterations,
            chebyshev: Some(Rho::Auto),
            anderson: 0,
            global: GlobalSolve::Auto,
            tolerance: 0.0,
            contacts: true,
        }
    }

    /// Anderson-accelerated over `window` past iterates.
    pub const fn anderson(iterations: u32, window: u32) -> Self {
        Self {
            iterations,
            chebyshev: None,
            anderson: window,
            global: GlobalSolve::Auto,
            tolerance: 0.0,
            contacts: true,
        }
    }
}

impl ProjectiveSolver {
    /// The same, with this global solve.
    pub const fn with_global(mut self, global: GlobalSolve) -> Self {
        self.global = global;
        self
    }

    /// The same, stopping early at this estimated relative error
    /// ([`tolerance`](Self::tolerance)).
    pub const fn with_tolerance(mut self, tolerance: f64) -> Self {
        self.tolerance = tolerance;
        self
    }
}

impl ProjectiveSolver {
    /// The interactive preset: at most [`PD_ITERATIONS`]
    /// Chebyshev-accelerated iterations (`ρ` estimated), stopping early at
    /// [`PD_TOLERANCE`].
    pub const PRESET: Self = Self::chebyshev(PD_ITERATIONS).with_tolerance(PD_TOLERANCE);
}

impl Default for ProjectiveSolver {
    /// [`PRESET`](Self::PRESET).
    fn default() -> Self {
        Self::PRESET
    }
}

/// What the factorisation depends on: refactorise when any of it changes.
#[derive(Clone, Debug, Default, PartialEq)]
struct FactorKey {
    topology: usize,
    pins: Vec<u32>,
    masses: Vec<f32>,
    stiffness: [u32; 3],
    dt: u64,
    /// The multigrid's cycles, or `None` for the factor.
    cycles: Option<u32>,
    /// [`StepParams::stencil`] (the multigrid's finest level).
    stencil: bool,
}

impl FactorKey {
    fn of(model: &ClothModel, params: &StepParams, cycles: Option<u32>) -> Self {
        Self {
            cycles,
            stencil: params.stencil,
            topology: std::sync::Arc::as_ptr(model.topology_arc()) as usize,
            pins: model.pins().to_vec(),
            masses: model.masses().to_vec(),
            stiffness: params.stiffness.as_array().map(f32::to_bits),
            dt: params.dt.to_bits(),
        }
    }

    fn matches(&self, model: &ClothModel, params: &StepParams, cycles: Option<u32>) -> bool {
        self.cycles == cycles
            && self.stencil == params.stencil
            && self.topology == std::sync::Arc::as_ptr(model.topology_arc()) as usize
            && self.pins == model.pins()
            && self.masses == model.masses()
            && self.stiffness == params.stiffness.as_array().map(f32::to_bits)
            && self.dt == params.dt.to_bits()
    }
}

const PINNED: u32 = u32::MAX;

/// Scratch of the projective-dynamics solver: the factorised global matrix
/// and the per-step buffers, kept from step to step.
#[derive(Default)]
pub struct ProjectiveWorkspace {
    key: Option<FactorKey>,
    /// The step's penalty spheres and contacts as penalties.
    penalties: Vec<PenaltySphere>,
    /// Free index of each vertex, or `PINNED`.
    dof_of: Vec<u32>,
    /// The vertex of each free index.
    free: Vec<u32>,
    /// `S` in CSC (full symmetric), over free vertices.
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<f64>,
    cholesky: SparseCholesky,
    /// The multigrid hierarchy of `S` and its V-cycles per iteration, when
    /// the global solve is multigrid.
    multigrid: Option<(Multigrid, u32)>,
    /// The global matrix as a stencil, for the multigrid's finest level on
    /// a grid cloth.
    fine_stencil: Option<FineStencil>,
    /// Per spring `[0, −L]`: `spring_products` gives `L/l·d`.
    coeffs: Vec<[f32; 2]>,
    /// Per spring `k` (in `f64`).
    k: Vec<f64>,
    /// Per spring: its projection `d_e`, then a zero.
    d: Vec<Vec3A>,
    x_tilde: Vec<Vec3A>,
    /// The iterate before last, for Chebyshev.
    x_prev: Vec<Vec3A>,
    /// Each spring between a free and a pinned vertex, in spring order: the
    /// free index, the pinned vertex and `k`.
    pin_links: Vec<(u32, u32, f64)>,
    /// `M/h² x̃ + M g` and the pinned neighbours' `k x_p`, per free vertex.
    base: Vec<DVec3>,
    /// The `n×3` right-hand side / solution, column-major.
    rhs: Vec<f64>,
    update_norms: Vec<f64>,
    /// Anderson: the last plain iterate `G(x)` and residual `G(x) − x`
    /// (free coordinates, `3m`), and the history of their differences.
    aa_g: Vec<f64>,
    aa_f: Vec<f64>,
    aa_dg: Vec<Vec<f64>>,
    aa_df: Vec<Vec<f64>>,
    /// Anderson's `ΔFᵀΔF` by slot, its copy to solve in, and `γ`.
    aa_gram: Vec<f64>,
    aa_system: Vec<f64>,
    aa_gamma: Vec<f64>,
    /// Index in `values` of each free vertex's diagonal entry, and that
    /// entry without contacts.
    diag_pos: Vec<usize>,
    diag_base: Vec<f64>,
    /// Per free vertex: the penalty stiffness on its diagonal in the current
    /// factor, the one this step wants, and which spheres (bit per sphere,
    /// the first 64) it is near this step.
    contact_k: Vec<f64>,
    wanted_k: Vec<f64>,
    near: Vec<u64>,
    /// This step's [`StepParams::parallel`].
    parallel: bool,
    /// This step's [`StepParams::simd`].
    simd: Simd,
    /// This step's [`StepParams::stencil`] and stiffness per kind.
    stencil_on: bool,
    kinds_k: [f32; 3],
    /// The stencil kernels' state, and each vertex's `Σ ±k_e·d_e`.
    stencil: StencilWorkspace,
    sums: Vec<Vec3A>,
    /// Each vertex's spring gradient in `f64`, for the step's residual.
    gradient: Vec<DVec3>,
    /// This step's `1/h²` and gravity.
    inv_h2: f64,
    gravity: DVec3,
    /// Factorisations so far (for tests: refactorised only when needed).
    factorizations: u32,
    /// The early stop's estimate ([`ProjectiveSolver::tolerance`]).
    track: EarlyStop,
    /// This step's friction terms, each free vertex's (or
    /// [`friction::NONE`]), and the contacts the last step ended in.
    friction: Vec<friction::Friction>,
    friction_at: Vec<u32>,
    ended_in: friction::EndedIn,
    /// Self-collision's pairs as terms of the objective; per free vertex
    /// the pairs' weight on its diagonal, and per vertex the pairs' force
    /// at the iterate.
    pairs: PairTerms,
    pair_k: Vec<f64>,
    pair_force: Vec<Vec3A>,
}

impl core::fmt::Debug for ProjectiveWorkspace {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("ProjectiveWorkspace")
            .field("free_vertices", &self.free.len())
            .field("factorizations", &self.factorizations)
            .field(
                "multigrid_levels",
                &self.multigrid.as_ref().map(|(m, _)| m.depth()),
            )
            .finish_non_exhaustive()
    }
}

impl Method for ProjectiveSolver {
    type Workspace = ProjectiveWorkspace;

    fn name(&self) -> &'static str {
        if self.anderson > 0 {
            "pd-anderson"
        } else {
            "pd"
        }
    }

    fn iterations_mut(&mut self) -> Option<&mut u32> {
        Some(&mut self.iterations)
    }

    fn validate(&self) -> Result<(), ParamError> {
        if self.anderson > 0 && self.chebyshev.is_some() {
            return Err(ParamError::Acceleration);
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0)
            || (self.anderson > 0 && self.tolerance > 0.0)
        {
            return Err(ParamError::Tolerance(self.tolerance));
        }
        if self.global == (GlobalSolve::Multigrid { cycles: 0 }) {
            return Err(ParamError::Iterations);
        }
        validate_chebyshev(self.iterations, self.chebyshev)
    }

    /// Advances `state` by one projective-dynamics step (see the module
    /// docs). Reports the iterations and the final gradient norm of the
    /// objective over free vertices; a failed factorisation is
    /// [`SolveError`](crate::solver::SolveError) (the guard reports it as
    /// `SolveFailed`).
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        ws: &mut ProjectiveWorkspace,
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
        let heaviest = model.masses().iter().copied().fold(0.0f32, f32::max);
        let stiffness = PD_CONTACT_STIFFNESS * f64::from(heaviest) / (params.dt * params.dt);
        // Self-collision's pairs as terms of the objective (the plugin's
        // pass after the step then has less left to move), found from the
        // velocities' path alone: with the step's fall added, as `newton`'s
        // are, the drape (600 steps) left 54 edges through with `pd` and
        // 550 with `pd-anderson` (none without), its global matrix taking
        // only the pairs' diagonal blocks.
        let c = PD_PAIR_STIFFNESS * f64::from(heaviest) / (params.dt * params.dt);
        ws.pairs
            .update(model, state, (params.dt, 0.0), self_collision, c, false);
        // The penalty spheres, and the contacts as penalties.
        let mut penalties = core::mem::take(&mut ws.penalties);
        penalties.clear();
        penalties.extend_from_slice(spheres);
        if self.contacts && !contacts.is_empty() {
            let stiffness = stiffness.min(f64::from(f32::MAX)) as f32;
            penalties.extend(
                contacts
                    .iter()
                    .map(|&shape| PenaltySphere::shape(shape, stiffness)),
            );
        }
        let solver = self.with_pairs(
            !ws.pairs.terms.is_empty(),
            model.vertex_count() - model.pins().len(),
        );
        let result = solver.advance_with(model, params, &penalties, state, ws);
        ws.penalties = penalties;
        result
    }
}

impl ProjectiveSolver {
    /// The solver a step runs: with self-collision's `pairs` in its
    /// objective, a Chebyshev-accelerated one is Anderson-accelerated
    /// instead (see the module docs); otherwise itself.
    fn with_pairs(&self, pairs: bool, free: usize) -> Self {
        if pairs && self.chebyshev.is_some() && self.anderson == 0 {
            // The global solve it has without pairs (Anderson's own
            // choice, `Auto`, is always direct).
            let global = match self.global.cycles(free, false) {
                Some(cycles) => GlobalSolve::Multigrid { cycles },
                None => GlobalSolve::Direct,
            };
            Self {
                chebyshev: None,
                anderson: PD_ANDERSON_WINDOW,
                tolerance: 0.0,
                global,
                ..*self
            }
        } else {
            *self
        }
    }

    /// [`advance`](Method::advance) with the step's penalty terms.
    fn advance_with(
        &self,
        model: &ClothModel,
        params: &StepParams,
        spheres: &[PenaltySphere],
        state: &mut ClothState,
        ws: &mut ProjectiveWorkspace,
    ) -> Result<StepReport, StepError> {
        let free = model.vertex_count() - model.pins().len();
        ws.prepare(model, params, self.global.cycles(free, self.anderson > 0))?;
        let n = model.vertex_count();
        let m = ws.free.len();
        let springs = model.topology().springs();
        let h = params.dt;
        let inv_h2 = 1.0 / (h * h);
        let masses = model.masses();
        ws.d.resize(springs.len(), Vec3A::ZERO);
        ws.rhs.resize(3 * m, 0.0);
        ws.parallel = params.parallel;
        ws.simd = params.simd;
        ws.stencil_on = params.stencil;
        ws.kinds_k = params.stiffness.as_array();
        ws.base.resize(m, DVec3::ZERO);
        ws.x_tilde.resize(n, Vec3A::ZERO);
        let ClothState {
            positions: x,
            velocities: v,
        } = state;
        // Damping, prediction, initial guess x = x̃ (as the lab's 1.a).
        let gravity = params.gravity.as_dvec3();
        (ws.inv_h2, ws.gravity) = (inv_h2, gravity);
        ws.track.start(self.tolerance, h, n);
        if ws.track.on() {
            ws.track.x_start.copy_from_slice(x);
        }
        // Friction on the contacts the last step ended in (lagged), from
        // where each vertex starts.
        let eps = (STICK_SPEED * f64::from(model.size()) * h) as f32;
        ws.ended_in.terms(
            (spheres, eps),
            (&ws.dof_of, x),
            &mut ws.friction,
            &mut ws.friction_at,
            m,
        );
        for (f, &i) in ws.free.iter().enumerate() {
            let i = i as usize;
            v[i] *= params.damping;
            x[i] += params.dt as f32 * v[i];
            let mass = f64::from(masses[i]);
            ws.base[f] = mass * (inv_h2 * x[i].as_dvec3() + gravity);
        }
        ws.x_tilde.copy_from_slice(x);
        ws.place_contacts(x, v, h as f32, spheres)?;
        // Pinned neighbours: their k·x_p is constant over the step (the
        // direct solve's right-hand side; the multigrid's is a gradient).
        if ws.multigrid.is_none() {
            for &(f, p, k) in &ws.pin_links {
                ws.base[f as usize] += k * x[p as usize].as_dvec3();
            }
        }
        let chebyshev = self.chebyshev.filter(|_| ws.pairs.terms.is_empty());
        if chebyshev.is_some() {
            ws.x_prev.clear();
            ws.x_prev.extend_from_slice(x);
        }
        let (delay, mut rho) = match chebyshev {
            Some(Rho::Auto) => ((self.iterations / 4).clamp(2, 8), 0.0),
            Some(Rho::Fixed(r)) => (0, r),
            None => (0, 0.0),
        };
        ws.update_norms.clear();
        let mut omega = 1.0f32;
        let mut iterations = self.iterations;
        if self.anderson > 0 {
            self.anderson_iterations(model, x, params, spheres, ws)?;
        }
        for k in 0..if self.anderson > 0 {
            0
        } else {
            self.iterations
        } {
            // (`ω` does not depend on this iteration's local step; the
            // early stop's estimate needs it first.)
            if k == delay && chebyshev == Some(Rho::Auto) {
                rho = rho_from_update_norms(&ws.update_norms);
            }
            omega = chebyshev_omega(k, delay, rho, omega);
            ws.track.omega = f64::from(omega);
            if ws.local_global(model, x, spheres)? {
                iterations = k;
                break;
            }
            let measure = chebyshev == Some(Rho::Auto) && k < delay;
            let solved = Solution::of(&ws.multigrid, &ws.cholesky, &ws.rhs);
            let update = match (chebyshev.is_some(), measure) {
                (true, true) => solved.blend::<true, true>(&ws.free, x, &mut ws.x_prev, omega),
                (true, false) => solved.blend::<true, false>(&ws.free, x, &mut ws.x_prev, omega),
                (false, _) => solved.blend::<false, false>(&ws.free, x, &mut ws.x_prev, omega),
            };
            if measure {
                ws.update_norms.push(update.sqrt());
            }
        }
        // Residual: the objective's gradient over free vertices (the
        // spring terms k(1 − L/l)(x_a − x_b) = k(x_a − x_b) − k·d_e). With
        // the multigrid on a stencil, the spring terms are its iterations'
        // own: the stencil kernels' sums in `f32`. The direct solve's are
        // summed in `f64`: from the stencil kernels' `f32` sums they would
        // save a few µs at 21², but at k = 1e8 and
        // dt = 0.001 their rounding alone put the step's estimated error
        // above the convergence tolerance (0.251 for 0.25: a false flag on
        // the stability map).
        let stencil = model.topology().stencil();
        let sums = match stencil.filter(|_| ws.stencil_on && ws.multigrid.is_some()) {
            Some(stencil) => {
                ws.stencil.load_springs(stencil, ws.kinds_k, x);
                ws.sums.resize(n, Vec3A::ZERO);
                ws.stencil.spring_sums(ws.simd, ws.parallel, &mut ws.sums);
                true
            }
            None => {
                let d = &mut ws.d;
                spring_products(ws.simd, Springs::of(model), &ws.coeffs, x, d);
                ws.spring_gradients(model, x);
                false
            }
        };
        ws.pair_forces(x);
        let mut residual = 0.0f64;
        let mut convergence = ConvergenceSums::default();
        let inv_h = 1.0 / params.dt as f32;
        ws.ended_in.clear(spheres.len());
        for &i in &ws.free {
            let i = i as usize;
            let mass = f64::from(masses[i]);
            let (xi, x_tilde) = (x[i].as_dvec3(), ws.x_tilde[i].as_dvec3());
            let mut g = mass * inv_h2 * (xi - x_tilde) - mass * gravity;
            g += if sums {
                ws.sums[i].as_dvec3()
            } else {
                ws.gradient[i]
            };
            // Along a contact's normal the Hessian is at least `m/h² + c`,
            // not `m/h²`: the error estimate divides that part of the
            // gradient by it (else a millimetre's penetration of a stiff
            // penalty read as metres of error on a cloth at rest on it).
            // The contacts the step ended in are also kept for the next
            // step's friction (the one pressed hardest per vertex).
            let mut along = None;
            let mut pressed = None;
            for (k, sphere) in spheres.iter().enumerate() {
                if let Some(contact) = sphere.contact(x[i]) {
                    g -= contact.force.as_dvec3();
                    along = Some((contact.normal.as_dvec3(), f64::from(sphere.stiffness)));
                    friction::EndedIn::offer(&mut pressed, i as u32, k, sphere, &contact);
                }
            }
            ws.ended_in.keep(pressed);
            let f = ws.dof_of[i] as usize;
            // A self-collision pair's push likewise (its weight `c` on the
            // diagonal), along the push.
            if let Some(&force) = ws.pair_force.get(i).filter(|p| **p != Vec3A::ZERO) {
                g -= force.as_dvec3();
                if let Some(n) = force.try_normalize() {
                    let c = ws.pair_k.get(f).copied().unwrap_or(0.0);
                    along = Some((n.as_dvec3(), c));
                }
            }
            let terms = (&ws.friction[..], &ws.friction_at[..]);
            let friction = friction::term_at(terms, &ws.near, f);
            if let Some((term, c)) = friction {
                g -= term.force(x[i], c).as_dvec3();
            }
            let mut error = g * (h * h / mass);
            if let Some((n, stiffness)) = along {
                error -= n * (g.dot(n) * (h * h / mass - 1.0 / (mass * inv_h2 + stiffness)));
            }
            // Friction likewise: across the normal, a vertex that sticks
            // has `m/h² + c`.
            if let Some((term, c)) = friction.filter(|(term, c)| term.sticks(x[i], *c)) {
                let c = f64::from(c);
                error -= term.tangential(g) * (h * h / mass - 1.0 / (mass * inv_h2 + c));
            }
            residual += g.length_squared();
            let motion = xi - (x_tilde - h * v[i].as_dvec3());
            convergence.add_f64(error, motion);
            // The velocity from the step's motion (after `motion` read the
            // old one).
            v[i] += (x[i] - ws.x_tilde[i]) * inv_h;
        }
        Ok(StepReport {
            iterations,
            residual: Some(residual.sqrt() as f32),
            relative_error: Some(convergence.relative_error(model, params.dt)),
            contacts: 0,
            self_contacts: None,
            substeps: 1,
        })
    }
}

#[cfg(test)]
mod tests;
