//! Linearly implicit Euler with sparse matrices — the assignment.
//!
//! One step solves for the new velocities `v⁺`
//!
//! `A v⁺ = b`, `A = M − h²K`, `b = M v + h f`,
//!
//! then `x ← x + h v⁺`, where `M` is the diagonal mass matrix, `f` the spring,
//! gravity and penalty forces at the current positions and `K = ∂f/∂x`.
//! Fixed (pinned) particles carry no degrees of freedom: only free particles
//! get rows and columns. For a spring between particles 0 and 1 with
//! `Δx = x₁ − x₀`, `l = ‖Δx‖`, rest length `L`, stiffness `E`:
//!
//! - force on particle 0: `f_s = E (l − L) Δx/l` (particle 1 gets `−f_s`);
//! - `K_s = E/l² ((1 − (l−L)/l) ΔxΔxᵀ + ((l−L)/l) (ΔxᵀΔx) I)` and the
//!   spring's `K = [[−K_s, K_s], [K_s, −K_s]]`, so `A` gains `h²K_s` on both
//!   diagonal blocks and `−h²K_s` on both off-diagonal blocks (the latter
//!   only when both particles are free).
//!
//! `K_s` has eigenvalue `E` along `Δx` and `E (l − L)/l` across it, which is
//! negative for a compressed spring: `A` can then lose positive
//! definiteness. [`SpringJacobian::ClampCompression`] drops that term for
//! compressed springs (the standard remedy), keeping every block positive
//! semi-definite.
//!
//! The sparsity pattern (CSC, full symmetric, 3×3 blocks) is built once per
//! cloth and rebuilt only when the topology or the pins change; each step
//! refills the values in place. The system is solved by conjugate gradients
//! (`faer::matrix_free::conjugate_gradient`, warm-started with the previous
//! velocities) or by a sparse LDLᵀ factorisation (`faer`, AMD ordering,
//! symbolic analysis done once per pattern).

mod assembly;
mod cg;

use bevy::math::Vec3A;
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;
use faer::dyn_stack::MemBuffer;

pub use assembly::LinearSystem;
pub(crate) use assembly::normalise;
use assembly::pattern_key;

use super::params::check_budget;
use super::{Method, ParamError, SolveError, StepError, StepInput, StepReport};
use crate::model::{ClothModel, ClothState};
use crate::solver::engine::cholesky::SparseCholesky;

/// Preconditioner of the conjugate gradient solve.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Debug, PartialEq, Default)]
pub enum Preconditioner {
    /// None (the assignment's Eigen default is a diagonal one; the spec
    /// does not say, so both are offered).
    #[default]
    None,
    /// Jacobi: the inverse of `A`'s diagonal.
    Jacobi,
}

/// Conjugate gradient settings (defaults: the assignment's).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
pub struct CgConfig {
    /// Iteration cap (25).
    pub max_iterations: u32,
    /// Relative residual `‖b − Av‖/‖b‖` at which to stop (1e-6).
    pub tolerance: f64,
    /// Preconditioner.
    pub preconditioner: Preconditioner,
}

impl CgConfig {
    /// The assignment's: 25 iterations, tolerance 1e-6, no preconditioner.
    pub const ASSIGNMENT: Self = Self {
        max_iterations: 25,
        tolerance: 1e-6,
        preconditioner: Preconditioner::None,
    };
}

impl Default for CgConfig {
    /// [`CgConfig::ASSIGNMENT`].
    fn default() -> Self {
        Self::ASSIGNMENT
    }
}

/// How the linear system is solved.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
pub enum LinearSolver {
    /// Conjugate gradients, warm-started with the previous velocities.
    Cg(CgConfig),
    /// Sparse LDLᵀ factorisation (exact up to round-off).
    Direct,
}

impl Default for LinearSolver {
    /// Conjugate gradients with the assignment's settings.
    fn default() -> Self {
        Self::Cg(CgConfig::ASSIGNMENT)
    }
}

/// Which spring stiffness blocks enter `A`.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Debug, PartialEq, Default)]
pub enum SpringJacobian {
    /// The assignment's `K_s` exactly (may make `A` indefinite when springs
    /// compress).
    #[default]
    Exact,
    /// `K_s` with the `(l − L)/l` term clamped at zero for compressed
    /// springs, so `A` stays positive definite.
    ClampCompression,
}

/// Which stiffness a penalty contact adds to `A`.
///
/// The true Jacobian of `f_c = c·d·n` is
/// `∂f_c/∂x = −c nnᵀ + c(d/l)(I − nnᵀ)`. With `A = M − h²K` its normal part
/// adds `h²c nnᵀ` to `A` (positive semi-definite, good) and its tangential
/// part subtracts `h²c(d/l)(I − nnᵀ)` (can make `A` indefinite). The
/// assignment writes `K_c = c·d·I`; read literally into `A = M − h²K` that
/// subtracts `h²c·d·I` and also loses definiteness, so the sign that keeps
/// `A` symmetric positive definite is the one offered as
/// [`Isotropic`](Self::Isotropic).
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
#[reflect(Debug, PartialEq, Default)]
pub enum PenaltyJacobian {
    /// `A += h²c nnᵀ`: the positive semi-definite (normal) part of the true
    /// Jacobian. Keeps `A` SPD.
    #[default]
    Normal,
    /// `A += h²c·d·I`: the assignment's `K_c = c·d·I` with the sign that keeps
    /// `A` SPD. Weak at first contact (`d → 0`), and it also stiffens
    /// tangential motion.
    Isotropic,
    /// The true Jacobian, `A −= h²∂f_c/∂x`. Not always positive definite.
    Exact,
}

/// Steps a cloth by linearly implicit Euler, `(M − h²K) v⁺ = Mv + hf`, with
/// a sparse system solved by conjugate gradients or a direct factorisation
/// (see the module docs). As a component on a cloth entity it selects this
/// method ([`LinearImplicitPlugin`](crate::LinearImplicitPlugin)).
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Default, Debug, PartialEq)]
pub struct LinearImplicitSolver {
    /// How `A v⁺ = b` is solved.
    pub solver: LinearSolver,
    /// Which spring blocks enter `A`.
    pub springs: SpringJacobian,
    /// Which penalty stiffness enters `A`.
    pub penalty: PenaltyJacobian,
}

impl LinearImplicitSolver {
    /// Conjugate gradients with these settings (the assignment's spring
    /// blocks and the normal penalty Jacobian).
    pub const fn cg(config: CgConfig) -> Self {
        Self {
            solver: LinearSolver::Cg(config),
            springs: SpringJacobian::Exact,
            penalty: PenaltyJacobian::Normal,
        }
    }

    /// The direct sparse LDLᵀ solve.
    pub const fn direct() -> Self {
        Self {
            solver: LinearSolver::Direct,
            springs: SpringJacobian::Exact,
            penalty: PenaltyJacobian::Normal,
        }
    }

    /// With another choice of spring blocks.
    pub const fn with_springs(mut self, springs: SpringJacobian) -> Self {
        self.springs = springs;
        self
    }

    /// With another choice of penalty stiffness.
    pub const fn with_penalty(mut self, penalty: PenaltyJacobian) -> Self {
        self.penalty = penalty;
        self
    }
}

impl Method for LinearImplicitSolver {
    type Workspace = LinearWorkspace;

    /// `linear-cg` or `linear-direct` (the spring blocks and penalty
    /// Jacobian are settings of either).
    fn name(&self) -> &'static str {
        match self.solver {
            LinearSolver::Cg(_) => "linear-cg",
            LinearSolver::Direct => "linear-direct",
        }
    }

    fn iterations_mut(&mut self) -> Option<&mut u32> {
        match &mut self.solver {
            LinearSolver::Cg(cg) => Some(&mut cg.max_iterations),
            LinearSolver::Direct => None,
        }
    }

    fn validate(&self) -> Result<(), ParamError> {
        match self.solver {
            LinearSolver::Cg(cg) => check_budget(cg.max_iterations, cg.tolerance),
            LinearSolver::Direct => Ok(()),
        }
    }

    /// Advances `state` by one linearly implicit Euler step (see the module
    /// docs). Reports solver iterations (0 for the direct solve) and the final
    /// relative residual `‖b − Av⁺‖/‖b‖`.
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        ws: &mut LinearWorkspace,
    ) -> Result<StepReport, StepError> {
        let StepInput {
            model,
            params,
            spheres,
            ..
        } = input;
        let config = self;
        ws.prepare(model);
        let pinned = model.pinned();
        ws.damped.clear();
        ws.damped.extend(
            state.velocities.iter().enumerate().map(
                |(i, &v)| {
                    if pinned[i] { v } else { v * params.damping }
                },
            ),
        );
        let LinearWorkspace {
            system,
            cholesky,
            solution,
            scratch,
            inv_diag,
            memory,
            damped,
            ..
        } = ws;
        let system = system.as_mut().expect("prepared");
        system.assemble(model, &state.positions, damped, params, config, spheres);
        let n = system.dimension();
        let result = if n == 0 {
            Ok((0, 0.0))
        } else {
            match config.solver {
                LinearSolver::Cg(cg) => {
                    for (i, v) in damped.iter().enumerate() {
                        if let Some(d) = system.dof(i) {
                            solution[d..d + 3].copy_from_slice(&v.as_dvec3().to_array());
                        }
                    }
                    cg::solve(system, &cg, solution, inv_diag, memory)
                }
                LinearSolver::Direct => solve_direct(system, cholesky, solution, scratch),
            }
        };
        let (iterations, residual) = result.map_err(StepError::Solve)?;
        let h = params.dt as f32;
        for i in 0..state.positions.len() {
            if let Some(d) = system.dof(i) {
                let v = Vec3A::new(
                    solution[d] as f32,
                    solution[d + 1] as f32,
                    solution[d + 2] as f32,
                );
                state.velocities[i] = v;
                state.positions[i] += h * v;
            }
        }
        Ok(StepReport {
            iterations,
            residual: Some(residual as f32),
            relative_error: None,
            contacts: 0,
            self_contacts: None,
            substeps: 1,
        })
    }
}

/// Scratch of the linearly implicit solver: the system, the symbolic
/// factorisation and solver memory, kept from step to step.
#[derive(Default)]
pub struct LinearWorkspace {
    system: Option<LinearSystem>,
    cholesky: SparseCholesky,
    solution: Vec<f64>,
    scratch: Vec<f64>,
    inv_diag: Vec<f64>,
    memory: Option<MemBuffer>,
    damped: Vec<Vec3A>,
    /// Pattern builds so far (for tests: rebuilt only when needed).
    pattern_builds: u32,
}

impl core::fmt::Debug for LinearWorkspace {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("LinearWorkspace")
            .field(
                "dimension",
                &self.system.as_ref().map(LinearSystem::dimension),
            )
            .field("pattern_builds", &self.pattern_builds)
            .finish_non_exhaustive()
    }
}

impl LinearWorkspace {
    /// The system assembled by the last step.
    pub fn system(&self) -> Option<&LinearSystem> {
        self.system.as_ref()
    }

    /// How many times the sparsity pattern was built.
    pub fn pattern_builds(&self) -> u32 {
        self.pattern_builds
    }

    fn prepare(&mut self, model: &ClothModel) {
        if self
            .system
            .as_ref()
            .is_none_or(|s| s.key != pattern_key(model))
        {
            let system = LinearSystem::new(model);
            let n = system.dimension();
            self.solution = vec![0.0; n];
            self.scratch = vec![0.0; n];
            self.inv_diag = vec![0.0; n];
            self.system = Some(system);
            self.cholesky = SparseCholesky::for_block_hessian();
            self.memory = None;
            self.pattern_builds += 1;
        }
    }
}

fn solve_direct(
    system: &LinearSystem,
    cholesky: &mut SparseCholesky,
    solution: &mut [f64],
    scratch: &mut [f64],
) -> Result<(u32, f64), SolveError> {
    solution.copy_from_slice(system.rhs());
    cholesky.solve_ldlt(system.matrix(), solution)?;
    // Relative residual ‖b − Av‖/‖b‖.
    system.multiply(solution, scratch);
    let (mut r2, mut b2) = (0.0, 0.0);
    for (ax, b) in scratch.iter().zip(system.rhs()) {
        r2 += (b - ax) * (b - ax);
        b2 += b * b;
    }
    Ok((
        0,
        if b2 > 0.0 {
            (r2 / b2).sqrt()
        } else {
            r2.sqrt()
        },
    ))
}

#[cfg(test)]
mod tests;
