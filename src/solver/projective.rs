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
//! [`SparseCholesky::solve_factored_xyz`](super::cholesky::SparseCholesky::solve_factored_xyz);
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
//! far less: at 201², 10 iterations take 9.5 ms where the direct solve's
//! take 59 ms (`docs/perf.md`).
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

use bevy::math::{DVec3, Vec3A};
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};

use super::cholesky::SparseCholesky;
use super::implicit::{Rho, chebyshev_omega, rho_from_update_norms, validate_chebyshev};
use super::kernels::{Springs, dot, spring_scales};
use super::lanes::LaneFactor;
use super::multigrid::{FineStencil, Multigrid};
use super::simd::{Simd, spring_products};
use super::stencil::{NONE, StencilWorkspace};
use super::{ConvergenceSums, Method, ParamError, SolveError, StepError, StepParams, StepReport};
use crate::collision::PenaltySphere;
use crate::model::{Adjacency, ClothModel, ClothState};

/// The interactive iteration budget of projective dynamics: each iteration
/// costs about seven of the lab's Jacobi iterations at 21² (10 take 92 µs,
/// 32 Jacobi iterations 37.5 µs: `docs/perf.md`), and 10
/// Chebyshev-accelerated ones reach the exact step within about 1e-2 on the
/// lab's cloth (see the report). The preset stops before it at
/// [`PD_TOLERANCE`].
pub const PD_ITERATIONS: u32 = 10;

/// The preset's early stop ([`ProjectiveSolver::tolerance`]): an estimated
/// error of 1 % of the step's motion, the per-step error the budget of
/// [`PD_ITERATIONS`] aims at. On the perf page's swinging 21² cloth it
/// stops after 5 iterations (estimate 0.0096; 0.0033 after all 10), in
/// 64 µs instead of 92; where the cloth is stiff for its step, and on that
/// cloth from 101² (one multigrid V-cycle per iteration), the estimate
/// stays above it and the whole budget runs, the estimate costing about
/// 3 % more. The stability map's verdicts and flags are those of the
/// whole budget.
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
    /// local–global iterations.
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
/// Below, the direct solve is cheap (0.9 ms for 10 iterations at 51²) and
/// exact: at 21² one V-cycle per iteration is no faster now (about 91
/// against 93 µs in release probes; 1.7× faster before the direct solve's
/// lanes, `lanes` module) and would leave 2 more of the stability map's 40
/// cells wrong (k = 1e5 at dt = 0.1 and 1e6 at 0.0333, 11–12 % short of
/// the exact drop where the criterion is 10 %).
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
    track: Track,
}

/// The error estimate behind [`ProjectiveSolver::tolerance`], made each
/// iteration from what the iteration computes anyway.
///
/// The objective's gradient at an iterate `x_j` is `S x_j − b_j`, where
/// `b_j` is the right-hand side the local step at `x_j` gives (the
/// projections' and spheres' terms are the gradient's non-quadratic part,
/// pins and inertia its constant part). `S x_j` needs no product with `S`:
/// the direct solve gives `S x̂_{j+1} = b_j`, and Chebyshev's iterate is
/// `x_{j+1} = ω_j x̂_{j+1} + (1 − ω_j) x_{j−1}`, so `q_{j+1} = S x_{j+1} =
/// ω_j b_j + (1 − ω_j) q_{j−1}`. The first iterations are plain (`ω = 1`), so
/// `q` is known from the first solve on: `q_1 = b_0` (with a fixed `ρ`, whose
/// second iteration is already accelerated, only every other iterate has
/// it). The multigrid's right-hand side is that gradient itself. The
/// estimate is then [`ConvergenceSums`]' over free vertices, as the step's
/// reported [`relative_error`](StepReport::relative_error), which is still
/// computed afresh in `f64` at the final iterate.
#[derive(Debug, Default)]
struct Track {
    /// The tolerance, or 0 (off), and the step's `h`.
    tolerance: f64,
    dt: f64,
    /// Iterations estimated so far this step, and this iteration's `ω`
    /// (set before its local step).
    iteration: u32,
    omega: f64,
    /// `S x` at the last two iterates by position of the right-hand side
    /// (the lanes' order for the simplicial factor, else free order):
    /// `q1` the latest, and whether each is known.
    q1: Vec<DVec3>,
    q2: Vec<DVec3>,
    known: [bool; 2],
    /// Per free vertex `h²/m` (in `f64` and `f32`, made with the
    /// factorisation); per vertex its position at the start of the step.
    h2_over_m: Vec<f64>,
    h2_over_m32: Vec<f32>,
    x_start: Vec<Vec3A>,
    /// By position: the vertex, its `h²/m` and start (made at the first
    /// iteration, which has no estimate).
    vertex: Vec<u32>,
    weight: Vec<f64>,
    start: Vec<Vec3A>,
}

impl Track {
    /// Starts a step with `tolerance` (0: off).
    fn start(&mut self, tolerance: f64, dt: f64, vertices: usize) {
        (self.tolerance, self.dt) = (tolerance, dt);
        self.iteration = 0;
        self.omega = 1.0;
        self.known = [false; 2];
        if tolerance > 0.0 {
            self.x_start.resize(vertices, Vec3A::ZERO);
        }
    }

    fn on(&self) -> bool {
        self.tolerance > 0.0
    }

    /// Takes the right-hand side `b_j` at iterate `x` (`len` positions:
    /// `free_at(p)` is position `p`'s free index, `b_at(p)` its value). True
    /// if the estimated relative error at `x` is within the tolerance.
    #[inline(always)]
    fn converged(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        free: &[u32],
        len: usize,
        free_at: impl Fn(usize) -> usize,
        b_at: impl FnMut(usize) -> DVec3,
    ) -> bool {
        if self.iteration == 0 {
            self.q1.resize(len, DVec3::ZERO);
            self.q2.resize(len, DVec3::ZERO);
            self.vertex.clear();
            self.weight.clear();
            self.start.clear();
            for p in 0..len {
                let f = free_at(p);
                let i = free[f];
                self.vertex.push(i);
                self.weight.push(self.h2_over_m[f]);
                self.start.push(self.x_start[i as usize]);
            }
        }
        let (omega, known) = (self.omega, self.known[0]);
        // `q_{j+1}` into `q2`'s place (`q_{j−1}`); the estimate from `q_j`.
        let sums = match (known, omega == 1.0) {
            (true, true) => self.pass::<true, true>(x, len, omega, b_at),
            (true, false) => self.pass::<true, false>(x, len, omega, b_at),
            (false, true) => self.pass::<false, true>(x, len, omega, b_at),
            (false, false) => self.pass::<false, false>(x, len, omega, b_at),
        };
        core::mem::swap(&mut self.q1, &mut self.q2);
        self.known = [omega == 1.0 || self.known[1], known];
        self.iteration += 1;
        known && f64::from(sums.relative_error(model, self.dt)) <= self.tolerance
    }

    /// [`converged`](Self::converged)'s loop: with `KNOWN` the estimate,
    /// and `q_{j+1}` plainly `b_j` if `PLAIN` (`ω = 1`).
    #[inline(always)]
    fn pass<const KNOWN: bool, const PLAIN: bool>(
        &mut self,
        x: &[Vec3A],
        len: usize,
        omega: f64,
        mut b_at: impl FnMut(usize) -> DVec3,
    ) -> ConvergenceSums {
        let mut sums = Slots::default();
        let (q1, q2) = (&self.q1[..len], &mut self.q2[..len]);
        let (vertex, weight, start) =
            (&self.vertex[..len], &self.weight[..len], &self.start[..len]);
        for (p, (q2, (q1, ((&i, &w), &start)))) in q2
            .iter_mut()
            .zip(q1.iter().zip(vertex.iter().zip(weight).zip(start)))
            .enumerate()
        {
            let b = b_at(p);
            if KNOWN {
                let error = ((*q1 - b) * w).length_squared();
                sums.add(p, error, (x[i as usize] - start).length_squared());
            }
            *q2 = if PLAIN {
                b
            } else {
                omega * b + (1.0 - omega) * *q2
            };
        }
        sums.sums(len)
    }
}

/// Squared errors and motions summed in 8 interleaved slots, so that one
/// vertex's sum does not wait on the last one's; in `f64`, or in `f32` for
/// the multigrid's `f32` gradient.
#[derive(Default)]
struct Slots([[f64; 2]; 8], [[f32; 2]; 8]);

impl Slots {
    /// Adds the vertex at position `at`, in `f32`.
    #[inline(always)]
    fn add32(&mut self, at: usize, error: f32, motion: f32) {
        let slot = &mut self.1[at % 8];
        slot[0] += error;
        slot[1] += motion;
    }

    /// Adds the vertex at position `at`.
    #[inline(always)]
    fn add(&mut self, at: usize, error: f64, motion: f32) {
        let slot = &mut self.0[at % 8];
        slot[0] += error;
        slot[1] += f64::from(motion);
    }

    /// The sums over `count` free vertices.
    fn sums(&self, count: usize) -> ConvergenceSums {
        let (mut error, mut motion) = (0.0, 0.0);
        for ([e, m], [e32, m32]) in self.0.into_iter().zip(self.1) {
            error += e + f64::from(e32);
            motion += m + f64::from(m32);
        }
        ConvergenceSums::from_parts(error, motion, count)
    }
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
    fn prepare(
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
    fn factorize(&mut self) -> Result<(), SolveError> {
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
    fn place_contacts(
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
        // The multigrid takes the new diagonal into its hierarchy (a new
        // hierarchy per change cost the perf page's cloth falling onto a
        // penalty sphere 31 instead of 11 ms per step at 201²).
        if let Some((multigrid, _)) = &mut self.multigrid
            && multigrid.set_diagonal(&changes)?
        {
            self.factorizations += 1;
            return Ok(());
        }
        self.factorize()
    }

    /// One local step and one global solve from `x`, into `self.rhs`; or,
    /// with an early stop whose estimate at `x` is within its tolerance,
    /// the local step alone and `true`.
    fn local_global(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        spheres: &[PenaltySphere],
    ) -> Result<bool, SolveError> {
        let stencil = model.topology().stencil().filter(|_| self.stencil_on);
        match stencil {
            // On the stencil kernels, summed per vertex: each spring's
            // `k_e·d_e` for the direct solve's right-hand side, or its
            // `k(1 − L/l)d` for the objective's gradient, which the
            // multigrid solves from for the correction.
            Some(stencil) => {
                if self.multigrid.is_some() {
                    self.stencil.load_springs(stencil, self.kinds_k, x);
                } else {
                    self.stencil.load_projection(stencil, self.kinds_k, x);
                }
                self.sums.resize(x.len(), Vec3A::ZERO);
                self.stencil
                    .spring_sums(self.simd, self.parallel, &mut self.sums);
                let sums = std::mem::take(&mut self.sums);
                let solved = self.global(model, x, spheres, Some(&sums));
                self.sums = sums;
                solved
            }
            None => {
                let d = &mut self.d;
                spring_products(self.simd, Springs::of(model), &self.coeffs, x, d);
                self.global(model, x, spheres, None)
            }
        }
    }

    /// The local step alone, returning the spring and penalty energy at `x`
    /// (the objective less its inertia and gravity terms).
    fn local_with_energy(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        spheres: &[PenaltySphere],
    ) -> f64 {
        let springs = model.topology().springs();
        let (d, k) = (&mut self.d, &self.k);
        let mut energy = 0.0f64;
        spring_scales(springs, &self.coeffs, x, |e, dx, scale| {
            d[e] = dx * scale;
            let stretch = f64::from(dx.length() * (1.0 - scale));
            energy += 0.5 * k[e] * stretch * stretch;
        });
        if !spheres.is_empty() {
            for &i in &self.free {
                for sphere in spheres {
                    if let Some(contact) = sphere.contact(x[i as usize]) {
                        energy += 0.5 * f64::from(sphere.stiffness * contact.depth * contact.depth);
                    }
                }
            }
        }
        energy
    }

    /// The global step: the right-hand side at `x` from each vertex's
    /// `Σ ±k_e·d_e` in `sums` (the stencil kernels), or else from the
    /// projections in `self.d`, solved into `self.rhs`. With the multigrid,
    /// `sums` holds each vertex's spring gradient instead
    /// ([`global_multigrid`](Self::global_multigrid)). `true` (and no
    /// solve) if the early stop's estimate at `x` is within its tolerance.
    fn global(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        spheres: &[PenaltySphere],
        sums: Option<&[Vec3A]>,
    ) -> Result<bool, SolveError> {
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
            x,
        };
        // A simplicial factor: the right-hand side written straight into
        // its lanes, in its order, and solved there (`Solved` reads it
        // back); through `rhs` and `solve3`'s two permuted copies, `pd 10`
        // at 21² took 8 % longer.
        if let Some(lanes) = cholesky.lanes() {
            let (order, b) = lanes.rhs_mut();
            match sums.filter(|_| spheres.is_empty()) {
                // The common case on its own loop (through `parts.at`, even
                // with this case first in it, `pd 10` at 21² took 98
                // instead of 93 µs in release probes).
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
            // loops above (the value read as it is written), `pd` with
            // its preset took 68 instead of 62 µs at 21².
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
struct RhsParts<'a> {
    free: &'a [u32],
    base: &'a [DVec3],
    k: &'a [f64],
    d: &'a [Vec3A],
    near: &'a [u64],
    adjacency: &'a Adjacency,
    sums: Option<&'a [Vec3A]>,
    spheres: &'a [PenaltySphere],
    x: &'a [Vec3A],
}

impl RhsParts<'_> {
    /// Free vertex `f`'s right-hand side: its `M/h² x̃ + M g`, pinned
    /// neighbours' and springs' `Σ ±k_e·d_e` and spheres' terms. (Inlined:
    /// as a call its `DVec3` went through memory, which cost more than the
    /// sum.)
    #[inline(always)]
    fn at(&self, f: usize) -> DVec3 {
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
    fn global_multigrid(
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
        let mut estimate = Slots::default();
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
            if track {
                // In `f32`, as `r` is (in `f64`, 2.37 instead of 2.26 ms
                // for `pd ≤10` at 101², where it runs all 10).
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
    /// spring's term made once and added to both ends (per vertex over its
    /// springs, each term was made twice: about 2 µs more at 21²).
    fn spring_gradients(&mut self, model: &ClothModel, x: &[Vec3A]) {
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
enum Solved<'a> {
    /// The multigrid's correction to the iterate.
    Multigrid(&'a Multigrid),
    /// The simplicial factor's lanes.
    Lanes(&'a LaneFactor),
    /// `rhs`, column-major.
    Columns(&'a [f64]),
}

impl<'a> Solved<'a> {
    /// From the workspace's `multigrid`, `cholesky` and `rhs` (borrowed
    /// alone, so that the iteration can write the others).
    fn of(
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
    /// lanes' order for the simplicial factor): one loop reading through
    /// all three made `pd 10` at 21² about 9 µs slower.
    #[inline(always)]
    fn blend<const CHEBYSHEV: bool, const MEASURE: bool>(
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
                x[i] = omega * (x_hat - before) + before;
            } else {
                x[i] = x_hat;
            }
        };
        match self {
            // The multigrid's correction added to the iterate in `f32`.
            // (Through an `f64` round trip, the same bits, `pd 10` at 101²
            // took 2.8 instead of 2.3 ms.)
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
    fn at_f64(&self, f: usize, i: usize, x: Vec3A) -> DVec3 {
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

impl ProjectiveSolver {
    /// The inertia and gravity terms of the objective at `x`.
    fn inertia(
        model: &ClothModel,
        x: &[Vec3A],
        ws: &ProjectiveWorkspace,
        inv_h2: f64,
        gravity: DVec3,
    ) -> f64 {
        let masses = model.masses();
        ws.free
            .iter()
            .map(|&i| {
                let i = i as usize;
                let mass = f64::from(masses[i]);
                let x = x[i].as_dvec3();
                0.5 * mass * inv_h2 * x.distance_squared(ws.x_tilde[i].as_dvec3())
                    - mass * gravity.dot(x)
            })
            .sum()
    }

    /// Anderson-accelerated local–global iterations (type II, Peng et al.
    /// 2018) with their energy safeguard; leaves the last plain iterate in
    /// `x`.
    fn anderson_iterations(
        &self,
        model: &ClothModel,
        x: &mut [Vec3A],
        params: &StepParams,
        spheres: &[PenaltySphere],
        ws: &mut ProjectiveWorkspace,
    ) -> Result<(), SolveError> {
        let m = ws.free.len();
        let inv_h2 = 1.0 / (params.dt * params.dt);
        let gravity = params.gravity.as_dvec3();
        let window = self.anderson as usize;
        ws.aa_g.resize(3 * m, 0.0);
        ws.aa_f.resize(3 * m, 0.0);
        let mut history = 0usize;
        let mut next = 0usize;
        let mut accepted = f64::INFINITY;
        let mut extrapolated = false;
        // ΔFᵀΔF by ring slot (slots 0..history hold the history), kept
        // row by row as slots are rewritten, and a copy to solve in.
        ws.aa_gram.resize(window * window, 0.0);
        ws.aa_system.resize(window * window, 0.0);
        ws.aa_gamma.resize(window, 0.0);
        let (mut gram, mut system, mut rhs) = (
            std::mem::take(&mut ws.aa_gram),
            std::mem::take(&mut ws.aa_system),
            std::mem::take(&mut ws.aa_gamma),
        );
        for k in 0..self.iterations {
            let mut energy = ws.local_with_energy(model, x, spheres)
                + Self::inertia(model, x, ws, inv_h2, gravity);
            if extrapolated && energy.partial_cmp(&accepted) != Some(core::cmp::Ordering::Less) {
                // The extrapolation raised the objective: take the plain
                // iterate G(x) of the last accepted x and restart.
                for (f, &i) in ws.free.iter().enumerate() {
                    x[i as usize] = Vec3A::new(
                        ws.aa_g[f] as f32,
                        ws.aa_g[m + f] as f32,
                        ws.aa_g[2 * m + f] as f32,
                    );
                }
                history = 0;
                next = 0;
                energy = ws.local_with_energy(model, x, spheres)
                    + Self::inertia(model, x, ws, inv_h2, gravity);
            }
            accepted = energy;
            // (Anderson takes no tolerance: `validate`.)
            ws.global(model, x, spheres, None)?;
            // g = G(x) in ws.rhs, f = g − x.
            let first = k == 0;
            if ws.aa_dg.len() < window {
                ws.aa_dg.resize(window, Vec::new());
                ws.aa_df.resize(window, Vec::new());
            }
            let mut dg = std::mem::take(&mut ws.aa_dg[next]);
            let mut df = std::mem::take(&mut ws.aa_df[next]);
            dg.resize(3 * m, 0.0);
            df.resize(3 * m, 0.0);
            let solved = Solved::of(&ws.multigrid, &ws.cholesky, &ws.rhs);
            for (f, &i) in ws.free.iter().enumerate() {
                let xi = x[i as usize];
                let gi = solved.at_f64(f, i as usize, xi).to_array();
                for (c, &xc) in xi.to_array().iter().enumerate() {
                    let j = c * m + f;
                    let g = gi[c];
                    let fx = g - f64::from(xc);
                    dg[j] = g - ws.aa_g[j];
                    df[j] = fx - ws.aa_f[j];
                    ws.aa_g[j] = g;
                    ws.aa_f[j] = fx;
                }
            }
            (ws.aa_dg[next], ws.aa_df[next]) = (dg, df);
            if !first {
                let written = next;
                history = (history + 1).min(window);
                next = (next + 1) % window;
                for b in 0..history {
                    let dot = dot(&ws.aa_df[written], &ws.aa_df[b]);
                    gram[written * window + b] = dot;
                    gram[b * window + written] = dot;
                }
            }
            extrapolated = false;
            let last = k + 1 == self.iterations;
            if history > 0 && !last {
                // γ = argmin ‖f − ΔF γ‖ by its normal equations (at most
                // `window`² entries, solved in place: Gaussian elimination
                // with a small Tikhonov term for a rank-deficient history).
                system.copy_from_slice(&gram);
                for (a, r) in rhs.iter_mut().enumerate().take(history) {
                    *r = dot(&ws.aa_df[a], &ws.aa_f);
                }
                let trace: f64 = (0..history).map(|a| gram[a * window + a]).sum();
                for a in 0..history {
                    system[a * window + a] += 1e-10 * trace + f64::MIN_POSITIVE;
                }
                if solve_small(&mut system, &mut rhs, history, window) {
                    for (f, &i) in ws.free.iter().enumerate() {
                        let mut p = [ws.aa_g[f], ws.aa_g[m + f], ws.aa_g[2 * m + f]];
                        for (h, &gamma) in rhs.iter().enumerate().take(history) {
                            let s = &ws.aa_dg[h];
                            p[0] -= gamma * s[f];
                            p[1] -= gamma * s[m + f];
                            p[2] -= gamma * s[2 * m + f];
                        }
                        x[i as usize] = Vec3A::new(p[0] as f32, p[1] as f32, p[2] as f32);
                    }
                    extrapolated = x.iter().all(|p| p.is_finite());
                }
                if !extrapolated {
                    history = 0;
                    next = 0;
                }
            }
            if !extrapolated {
                for (f, &i) in ws.free.iter().enumerate() {
                    x[i as usize] = Vec3A::new(
                        ws.aa_g[f] as f32,
                        ws.aa_g[m + f] as f32,
                        ws.aa_g[2 * m + f] as f32,
                    );
                }
            }
        }
        // Kept for the next step (an early error return just drops them).
        (ws.aa_gram, ws.aa_system, ws.aa_gamma) = (gram, system, rhs);
        Ok(())
    }
}

/// Solves the `n×n` system in the top-left of the row-major `stride`-wide
/// `a` for `b` in place, by Gaussian elimination with partial pivoting
/// (hand-written: `n` is Anderson's window, a handful, where a dense
/// library's setup costs more than the solve). False if singular.
fn solve_small(a: &mut [f64], b: &mut [f64], n: usize, stride: usize) -> bool {
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&p, &q| {
                a[p * stride + col]
                    .abs()
                    .total_cmp(&a[q * stride + col].abs())
            })
            .unwrap_or(col);
        if a[pivot * stride + col].abs().partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            return false;
        }
        if pivot != col {
            for c in 0..n {
                a.swap(col * stride + c, pivot * stride + c);
            }
            b.swap(col, pivot);
        }
        for row in col + 1..n {
            let factor = a[row * stride + col] / a[col * stride + col];
            for c in col..n {
                a[row * stride + c] -= factor * a[col * stride + c];
            }
            b[row] -= factor * b[col];
        }
    }
    for row in (0..n).rev() {
        let mut v = b[row];
        for c in row + 1..n {
            v -= a[row * stride + c] * b[c];
        }
        b[row] = v / a[row * stride + row];
    }
    b[..n].iter().all(|v| v.is_finite())
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
    /// [`SolveError`] (the guard reports it as `SolveFailed`).
    fn advance(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
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
        let chebyshev = self.chebyshev;
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
            let solved = Solved::of(&ws.multigrid, &ws.cholesky, &ws.rhs);
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
        let mut residual = 0.0f64;
        let mut convergence = ConvergenceSums::default();
        let inv_h = 1.0 / params.dt as f32;
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
            for sphere in spheres {
                if let Some(contact) = sphere.contact(x[i]) {
                    g -= contact.force.as_dvec3();
                }
            }
            residual += g.length_squared();
            let motion = xi - (x_tilde - h * v[i].as_dvec3());
            convergence.add_f64(g * (h * h / mass), motion);
            // The velocity from the step's motion (after `motion` read the
            // old one).
            v[i] += (x[i] - ws.x_tilde[i]) * inv_h;
        }
        Ok(StepReport {
            iterations,
            residual: Some(residual.sqrt() as f32),
            relative_error: Some(convergence.relative_error(model, params.dt)),
        })
    }
}

#[cfg(test)]
mod tests {
    use bevy::math::{Affine3A, Vec3};

    use super::*;
    use crate::model::ClothBuilder;
    use crate::solver::exact::{ExactSolver, ExactWorkspace};
    use crate::solver::{SpringStiffness, step_error};

    fn lab() -> ClothModel {
        ClothBuilder::lab().build().unwrap()
    }

    /// Both global solves.
    const GLOBALS: [GlobalSolve; 2] = [GlobalSolve::Direct, GlobalSolve::Multigrid { cycles: 1 }];

    /// The exact trajectory after `steps` steps (a swinging, bent sheet).
    fn swinging(model: &ClothModel, params: &StepParams, steps: usize) -> ClothState {
        swinging_onto(model, params, &[], steps)
    }

    fn swinging_onto(
        model: &ClothModel,
        params: &StepParams,
        spheres: &[PenaltySphere],
        steps: usize,
    ) -> ClothState {
        let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
        let mut ws = ExactWorkspace::default();
        for _ in 0..steps {
            ExactSolver::REFERENCE
                .step(model, &mut state, params, spheres, &mut ws)
                .unwrap();
        }
        state
    }

    /// The report's sphere scene's sphere: the lab's, as a penalty sphere
    /// stiffer than the cloth's inertia (c = 1e4 against m/h² ≈ 900).
    fn lab_penalty_sphere() -> PenaltySphere {
        PenaltySphere {
            center: Vec3A::new(0.0, -4.0, 4.0),
            radius: 2.7,
            stiffness: 1e4,
            surface: Default::default(),
        }
    }

    fn error_against_exact(
        model: &ClothModel,
        params: &StepParams,
        start: &ClothState,
        pd: ProjectiveSolver,
    ) -> f64 {
        error_against_exact_onto(model, params, &[], start, pd)
    }

    fn error_against_exact_onto(
        model: &ClothModel,
        params: &StepParams,
        spheres: &[PenaltySphere],
        start: &ClothState,
        pd: ProjectiveSolver,
    ) -> f64 {
        let mut exact = start.clone();
        ExactSolver::REFERENCE
            .step(
                model,
                &mut exact,
                params,
                spheres,
                &mut ExactWorkspace::default(),
            )
            .unwrap();
        let mut state = start.clone();
        pd.step(
            model,
            &mut state,
            params,
            spheres,
            &mut ProjectiveWorkspace::default(),
        )
        .unwrap();
        step_error(&state.positions, &exact.positions, &start.positions)
    }

    #[test]
    fn converges_to_the_exact_step_on_a_penalty_sphere() {
        // The report's scene: the lab cloth falling onto the lab's sphere as
        // a penalty sphere stiffer than the cloth's inertia (c = 1e4 against
        // m/h² ≈ 900). As an explicit force at the iterate, more iterations
        // made it worse; as a projective term, it converges.
        let model = ClothBuilder::lab().with_total_mass(441.0).build().unwrap();
        let params = StepParams::LAB;
        let spheres = [lab_penalty_sphere()];
        let start = swinging_onto(&model, &params, &spheres, 20);
        let touching = start
            .positions
            .iter()
            .filter(|x| spheres[0].contact(**x).is_some())
            .count();
        assert!(touching > 10, "{touching} vertices in contact");
        for global in GLOBALS {
            let error = |pd: ProjectiveSolver| {
                error_against_exact_onto(&model, &params, &spheres, &start, pd.with_global(global))
            };
            let few = error(ProjectiveSolver::new(4));
            let many = error(ProjectiveSolver::new(400));
            let interactive = error(ProjectiveSolver::default());
            assert!(
                many < 1e-3 && many < few / 10.0,
                "{global:?}: {few} → {many}"
            );
            assert!(interactive < 2e-2, "{global:?}: {interactive}");
        }
    }

    #[test]
    fn refactorises_only_when_the_vertices_near_a_sphere_change() {
        let model = lab();
        let params = StepParams::LAB;
        let far = [PenaltySphere {
            center: Vec3A::new(0.0, -50.0, 0.0),
            radius: 1.0,
            stiffness: 1e4,
            surface: Default::default(),
        }];
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = ProjectiveWorkspace::default();
        let pd = ProjectiveSolver::default().with_global(GlobalSolve::Multigrid { cycles: 1 });
        for _ in 0..3 {
            pd.step(&model, &mut state, &params, &far, &mut ws).unwrap();
        }
        assert_eq!(ws.factorizations(), 1, "a sphere far away changes nothing");
        let near = [PenaltySphere {
            center: state.positions[220] + Vec3A::new(0.0, -0.5, 0.0),
            ..far[0]
        }];
        pd.step(&model, &mut state, &params, &near, &mut ws)
            .unwrap();
        assert_eq!(ws.factorizations(), 2);
        assert!(ws.contact_k.contains(&1e4));
        pd.step(&model, &mut state, &params, &far, &mut ws).unwrap();
        assert_eq!(ws.factorizations(), 3, "and back");
        assert!(ws.contact_k.iter().all(|&k| k == 0.0));
    }

    #[test]
    fn converges_to_the_exact_implicit_step() {
        let model = lab();
        let params = StepParams::LAB;
        let start = swinging(&model, &params, 10);
        for global in GLOBALS {
            let error = |pd: ProjectiveSolver| {
                error_against_exact(&model, &params, &start, pd.with_global(global))
            };
            let few = error(ProjectiveSolver::new(4));
            let many = error(ProjectiveSolver::new(400));
            assert!(
                many < 1e-3 && many < few / 10.0,
                "{global:?}: {few} → {many}"
            );
            let accelerated = error(ProjectiveSolver::chebyshev(40));
            let plain = error(ProjectiveSolver::new(40));
            assert!(
                accelerated < plain,
                "{global:?}: Chebyshev {accelerated} vs plain {plain}"
            );
        }
    }

    #[test]
    fn multigrid_gives_the_direct_solves_step_on_large_cloths_and_every_path() {
        use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
        ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
        // 101²: the automatic choice is multigrid; the assignment's six
        // spring families; stiff; the stencil kernels and the general ones;
        // plain, Chebyshev and Anderson.
        let lab = ClothBuilder::lab_grid(101).build().unwrap();
        let assignment = ClothBuilder::assignment(70, 70).build().unwrap();
        for (model, k) in [(&lab, 8000.0), (&lab, 1e6), (&assignment, 8000.0)] {
            let params = StepParams {
                stiffness: SpringStiffness::uniform(k),
                ..StepParams::LAB
            };
            // A bent, swinging sheet (40 lab steps), and its exact step.
            let mut start = ClothState::at_rest(model, &Affine3A::IDENTITY);
            let lab_method = crate::solver::implicit::ImplicitSolver::default();
            let mut lab_ws = Default::default();
            for _ in 0..40 {
                lab_method
                    .step(model, &mut start, &params, &[], &mut lab_ws)
                    .unwrap();
            }
            let mut exact = start.clone();
            ExactSolver::REFERENCE
                .step(
                    model,
                    &mut exact,
                    &params,
                    &[],
                    &mut ExactWorkspace::default(),
                )
                .unwrap();
            for pd in [
                ProjectiveSolver::new(20),
                ProjectiveSolver::chebyshev(20),
                ProjectiveSolver::anderson(10, PD_ANDERSON_WINDOW),
            ] {
                let step = |global: GlobalSolve, params: &StepParams| {
                    let mut state = start.clone();
                    let mut ws = ProjectiveWorkspace::default();
                    pd.with_global(global)
                        .step(model, &mut state, params, &[], &mut ws)
                        .unwrap();
                    (state, ws.multigrid.is_some())
                };
                let (direct, _) = step(GlobalSolve::Direct, &params);
                // Auto is multigrid here, but direct with Anderson.
                let (_, multigrid) = step(GlobalSolve::Auto, &params);
                assert_eq!(multigrid, pd.anderson == 0, "{pd:?}");
                let mg = GlobalSolve::Multigrid { cycles: 1 };
                let (auto, _) = step(mg, &params);
                // As close to the exact step as the direct solve's iterate
                // (one V-cycle per iteration gains a little less).
                let direct = step_error(&direct.positions, &exact.positions, &start.positions);
                let error = step_error(&auto.positions, &exact.positions, &start.positions);
                assert!(
                    error < 2.0 * direct + 1e-4,
                    "{} k {k} {pd:?}: {error} against {direct}",
                    model.vertex_count()
                );
                let general = StepParams {
                    stencil: false,
                    ..params
                };
                let (general, _) = step(mg, &general);
                let error = step_error(&general.positions, &auto.positions, &start.positions);
                assert!(error < 1e-3, "stencil against general: {error}");
                let serial = StepParams {
                    parallel: false,
                    ..params
                };
                assert_eq!(step(mg, &serial).0, auto, "same bits on 1 and 2 threads");
                for simd in [Simd::Baseline, Simd::Avx2, Simd::Avx512] {
                    let at = StepParams { simd, ..params };
                    assert_eq!(step(mg, &at).0, auto, "same bits at {simd:?}");
                }
            }
        }
    }

    #[test]
    fn is_right_on_stiff_cloth_where_it_falls_as_the_exact_method_does() {
        // k = 1e6 at the lab's step: Jacobi locks here; PD does not.
        let model = lab();
        let params = StepParams {
            stiffness: SpringStiffness::uniform(1e6),
            ..StepParams::LAB
        };
        let start = swinging(&model, &params, 5);
        for global in GLOBALS {
            let pd = ProjectiveSolver::default().with_global(global);
            let e = error_against_exact(&model, &params, &start, pd);
            assert!(e < 0.1, "{global:?}: {e}");
        }
    }

    #[test]
    fn factorises_once_and_again_only_when_k_h_or_pins_change() {
        for global in GLOBALS {
            factorises_once_and_again_only_when_k_h_or_pins_change_with(global);
        }
        // Switching between the direct solve and multigrid rebuilds.
        let model = lab();
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = ProjectiveWorkspace::default();
        // (Auto is the direct solve on the lab's 441 vertices.)
        for (global, builds) in [
            (GlobalSolve::Direct, 1),
            (GlobalSolve::Auto, 1),
            (GlobalSolve::Multigrid { cycles: 1 }, 2),
            (GlobalSolve::Multigrid { cycles: 2 }, 3),
            (GlobalSolve::Direct, 4),
        ] {
            ProjectiveSolver::default()
                .with_global(global)
                .step(&model, &mut state, &StepParams::LAB, &[], &mut ws)
                .unwrap();
            assert_eq!(ws.factorizations(), builds, "{global:?}");
        }
    }

    fn factorises_once_and_again_only_when_k_h_or_pins_change_with(global: GlobalSolve) {
        let model = lab();
        let mut params = StepParams::LAB;
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = ProjectiveWorkspace::default();
        let pd = ProjectiveSolver::default().with_global(global);
        for _ in 0..5 {
            pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
        }
        assert_eq!(ws.factorizations(), 1);
        params.stiffness = SpringStiffness::uniform(9000.0);
        pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
        assert_eq!(ws.factorizations(), 2);
        params.dt = 0.02;
        pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
        assert_eq!(ws.factorizations(), 3);
        let unpinned = ClothBuilder::lab().with_pins([0]).build().unwrap();
        let mut s = ClothState::at_rest(&unpinned, &Affine3A::IDENTITY);
        pd.step(&unpinned, &mut s, &params, &[], &mut ws).unwrap();
        assert_eq!(ws.factorizations(), 4);
        // Moving a pin is a right-hand side change only.
        state.positions[0] += Vec3A::new(0.5, 0.0, 0.0);
        pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
        assert_eq!(ws.factorizations(), 5);
        pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
        assert_eq!(ws.factorizations(), 5);
        assert_eq!(state.positions[0].x, 5.5, "pins never move");
    }

    #[test]
    fn edge_cases_are_typed_errors_or_plain_physics() {
        for global in GLOBALS {
            edge_cases_are_typed_errors_or_plain_physics_with(global);
        }
        assert_eq!(
            ProjectiveSolver::default()
                .with_global(GlobalSolve::Multigrid { cycles: 0 })
                .validate(),
            Err(ParamError::Iterations)
        );
    }

    fn edge_cases_are_typed_errors_or_plain_physics_with(global: GlobalSolve) {
        let pd = ProjectiveSolver::default().with_global(global);
        let model = lab();
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = ProjectiveWorkspace::default();
        // k = 0 is refused like every method refuses it; the state is kept.
        let zero = StepParams {
            stiffness: SpringStiffness::uniform(0.0),
            ..StepParams::LAB
        };
        let before = state.clone();
        assert_eq!(
            pd.step(&model, &mut state, &zero, &[], &mut ws),
            Err(StepError::Params(ParamError::Stiffness(0.0)))
        );
        assert_eq!(state, before);
        assert_eq!(
            ProjectiveSolver::new(0).step(&model, &mut state, &StepParams::LAB, &[], &mut ws),
            Err(StepError::Params(ParamError::Iterations))
        );
        // h → 0: the mass term dominates, nothing moves measurably.
        let tiny = StepParams {
            dt: 1e-9,
            ..StepParams::LAB
        };
        pd.step(&model, &mut state, &tiny, &[], &mut ws).unwrap();
        assert!(state.is_finite());
        assert!(state.positions[220].distance(before.positions[220]) < 1e-6);
        // No springs: a cloth without triangles cannot be built (a typed
        // error), so PD never sees an empty Laplacian.
        let loose =
            ClothBuilder::from_triangles(vec![Vec3::ZERO, Vec3::X, Vec3::Z], Vec::new()).build();
        assert!(loose.is_err(), "{loose:?}");
        // Every pin removed: the whole sheet falls, finite.
        let free = ClothBuilder::lab().with_pins([]).build().unwrap();
        let mut s = ClothState::at_rest(&free, &Affine3A::IDENTITY);
        let mut ws = ProjectiveWorkspace::default();
        for _ in 0..30 {
            pd.step(&free, &mut s, &StepParams::LAB, &[], &mut ws)
                .unwrap();
        }
        assert!(s.is_finite() && s.positions.iter().all(|p| p.y < -1.0));
    }

    #[test]
    fn is_deterministic() {
        let model = lab();
        let run = |pd: ProjectiveSolver| {
            let mut s = ClothState::at_rest(&model, &Affine3A::IDENTITY);
            let mut ws = ProjectiveWorkspace::default();
            for _ in 0..20 {
                pd.step(&model, &mut s, &StepParams::LAB, &[], &mut ws)
                    .unwrap();
            }
            s.positions
                .iter()
                .flat_map(|p| p.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        for global in GLOBALS {
            for pd in [
                ProjectiveSolver::default(),
                ProjectiveSolver::anderson(PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW),
            ] {
                let pd = pd.with_global(global);
                assert_eq!(run(pd), run(pd));
            }
        }
    }

    /// The lowest point after 1 s of falling from rest, and the exact run's.
    pub(super) fn lowest_after_one_second(params: &StepParams, pd: ProjectiveSolver) -> (f32, f32) {
        let model = lab();
        let steps = (1.0 / params.dt).ceil() as usize;
        let lowest = |s: &ClothState| s.positions.iter().map(|p| p.y).fold(f32::MAX, f32::min);
        let exact = swinging(&model, params, steps);
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = ProjectiveWorkspace::default();
        for _ in 0..steps {
            pd.step(&model, &mut state, params, &[], &mut ws).unwrap();
        }
        (lowest(&state), lowest(&exact))
    }

    #[test]
    fn anderson_falls_as_the_exact_method_on_stiff_cloth_where_chebyshev_locks() {
        // The stability map's cell k = 1e7, dt = 0.0333: 10 Chebyshev
        // iterations stay far above the exact sheet; 20 Anderson ones reach
        // it (the map's criterion: within 10 % of the drop).
        let params = StepParams {
            stiffness: SpringStiffness::uniform(1e7),
            ..StepParams::LAB
        };
        let rest = 0.0;
        let (chebyshev, exact) = lowest_after_one_second(&params, ProjectiveSolver::default());
        let (anderson, _) = lowest_after_one_second(
            &params,
            ProjectiveSolver::anderson(PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW),
        );
        let drop = rest - exact;
        assert!(drop > 1.0, "the exact sheet falls: {exact}");
        assert!(
            (anderson - exact).abs() < 0.1 * drop,
            "{anderson} vs {exact}"
        );
        assert!(
            (chebyshev - exact).abs() > 0.3 * drop,
            "{chebyshev} vs {exact}"
        );
    }

    #[test]
    fn anderson_converges_to_the_exact_step_and_never_raises_the_objective() {
        let model = lab();
        let params = StepParams::LAB;
        let start = swinging(&model, &params, 10);
        let few = error_against_exact(&model, &params, &start, ProjectiveSolver::anderson(4, 5));
        let many = error_against_exact(&model, &params, &start, ProjectiveSolver::anderson(100, 5));
        let chebyshev =
            error_against_exact(&model, &params, &start, ProjectiveSolver::chebyshev(20));
        let anderson =
            error_against_exact(&model, &params, &start, ProjectiveSolver::anderson(20, 5));
        assert!(many < 1e-4 && many < few / 10.0, "{few} → {many}");
        assert!(
            anderson < chebyshev,
            "Anderson {anderson} vs Chebyshev {chebyshev}"
        );
        // Its safeguard: the objective at the step's result is no higher
        // than plain local–global iterations' from the same start (each of
        // which lowers it).
        let objective = |pd: ProjectiveSolver| {
            let mut s = start.clone();
            pd.step(
                &model,
                &mut s,
                &params,
                &[],
                &mut ProjectiveWorkspace::default(),
            )
            .unwrap();
            let mut ws = ProjectiveWorkspace::default();
            let mut probe = start.clone();
            ProjectiveSolver::new(1)
                .step(&model, &mut probe, &params, &[], &mut ws)
                .unwrap();
            let inv_h2 = 1.0 / (params.dt * params.dt);
            ws.local_with_energy(&model, &s.positions, &[])
                + ProjectiveSolver::inertia(
                    &model,
                    &s.positions,
                    &ws,
                    inv_h2,
                    params.gravity.as_dvec3(),
                )
        };
        assert!(
            objective(ProjectiveSolver::anderson(20, 5)) <= objective(ProjectiveSolver::new(20))
        );
    }

    #[test]
    fn stops_early_at_its_tolerance_on_the_iterates_of_the_whole_budget() {
        // The lab cloth falling (by both global solves, and onto a penalty
        // sphere: the right-hand side through `RhsParts::at`), and a 201²
        // cloth by the direct solve (the supernodal factor: the
        // column-major right-hand side), to a tighter tolerance: it is
        // within 1e-4 after one iteration.
        let lab = lab();
        let big = ClothBuilder::lab_grid(201).build().unwrap();
        let params = StepParams::LAB;
        let sphere = [lab_penalty_sphere()];
        let mg = GlobalSolve::Multigrid { cycles: 1 };
        const TIGHT: f64 = 5e-5;
        let cases: [(&ClothModel, &[PenaltySphere], GlobalSolve, f64); 4] = [
            (&lab, &[], GlobalSolve::Direct, PD_TOLERANCE),
            (&lab, &[], mg, PD_TOLERANCE),
            (&lab, &sphere, GlobalSolve::Direct, PD_TOLERANCE),
            (&big, &[], GlobalSolve::Direct, TIGHT),
        ];
        // Budgets for which Chebyshev's plain iterations (`ρ` estimated
        // from them) are as many as in a shorter run (2 up to 11), so that
        // a run of the iterations the early stop took is the same run.
        let fixed_rho = ProjectiveSolver {
            chebyshev: Some(Rho::Fixed(0.9)),
            ..ProjectiveSolver::chebyshev(60)
        };
        let methods = [
            ProjectiveSolver::new(60),
            ProjectiveSolver::chebyshev(PD_ITERATIONS),
            fixed_rho,
        ];
        for (model, spheres, global, tolerance) in cases {
            let mut start = ClothState::at_rest(model, &Affine3A::IDENTITY);
            let mut start_ws = ProjectiveWorkspace::default();
            for _ in 0..20 {
                ProjectiveSolver::PRESET
                    .step(model, &mut start, &params, spheres, &mut start_ws)
                    .unwrap();
            }
            for pd in methods {
                let pd = pd.with_global(global);
                let run = |pd: ProjectiveSolver| {
                    let mut state = start.clone();
                    let mut ws = ProjectiveWorkspace::default();
                    let report = pd
                        .step(model, &mut state, &params, spheres, &mut ws)
                        .unwrap();
                    (state, report, ws.cholesky.lanes_ref().is_some())
                };
                let case = format!("{} vertices, {pd:?}", model.vertex_count());
                let (early, report, lanes) = run(pd.with_tolerance(tolerance));
                assert_eq!(lanes, model.vertex_count() < 1000 && global != mg, "{case}");
                let j = report.iterations;
                // (Chebyshev's budget of 10 may run out before an iterate
                // is within the tolerance; the others' budget does not.)
                let stopped = j < pd.iterations;
                assert!(j > 0, "{case}");
                assert!(stopped || pd.chebyshev == Some(Rho::Auto), "{case}: {j}");
                // The budget's first j iterates, bit for bit.
                let (fixed, fixed_report, _) = run(ProjectiveSolver {
                    iterations: j,
                    ..pd
                });
                assert_eq!(early, fixed, "{case}");
                assert_eq!(report, fixed_report, "{case}");
                // What it stopped on is the step's reported error (made
                // afresh in `f64`), and the iterate before was not within
                // it (with a fixed `ρ`, every other one is estimated).
                let error = report.relative_error.unwrap();
                let tolerance = tolerance as f32;
                assert!(stopped == (error <= 1.02 * tolerance), "{case}: {error}");
                let back = if pd.chebyshev == fixed_rho.chebyshev {
                    2
                } else {
                    1
                };
                if stopped && j > back {
                    let (_, before, _) = run(ProjectiveSolver {
                        iterations: j - back,
                        ..pd
                    });
                    let before = before.relative_error.unwrap();
                    assert!(before > 0.98 * tolerance, "{case}: {before}");
                }
                // A tolerance no iterate reaches: the whole budget, the
                // same bits as without one.
                let (all, all_report, _) = run(pd.with_tolerance(1e-9));
                let (plain, plain_report, _) = run(pd);
                assert_eq!((all, all_report), (plain, plain_report), "{case}");
                assert_eq!(all_report.iterations, pd.iterations, "{case}");
            }
        }
    }

    #[test]
    fn a_tolerance_is_a_number_and_not_with_anderson() {
        assert_eq!(ProjectiveSolver::PRESET.validate(), Ok(()));
        assert_eq!(ProjectiveSolver::default(), ProjectiveSolver::PRESET);
        for bad in [-1e-3, f64::NAN, f64::INFINITY] {
            let refused = ProjectiveSolver::PRESET.with_tolerance(bad).validate();
            assert!(matches!(refused, Err(ParamError::Tolerance(_))), "{bad}");
        }
        // Anderson's iterations have no estimate to stop on.
        let anderson = ProjectiveSolver::anderson(PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW);
        assert_eq!(anderson.validate(), Ok(()));
        assert_eq!(
            anderson.with_tolerance(PD_TOLERANCE).validate(),
            Err(ParamError::Tolerance(PD_TOLERANCE))
        );
    }

    #[test]
    fn two_accelerations_are_refused() {
        let both = ProjectiveSolver {
            anderson: 5,
            ..ProjectiveSolver::default()
        };
        assert_eq!(both.validate(), Err(ParamError::Acceleration));
        assert_eq!(ProjectiveSolver::anderson(20, 5).name(), "pd-anderson");
        assert_eq!(ProjectiveSolver::default().name(), "pd");
    }
}
