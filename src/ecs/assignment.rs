//! The assignment's methods as components — symplectic Euler and linearly
//! implicit Euler with sparse CG or direct solves — and the exact
//! implicit-Euler reference.

use bevy::prelude::*;

use super::method::{ClothMethod, MethodPlugin};
use super::reflect::{
    CgConfigReflect, LinearSolverReflect, PenaltyJacobianReflect, SpringJacobianReflect,
};
use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState};
use crate::solver::exact::{self, ExactConfig, ExactWorkspace};
use crate::solver::linear::{
    self, CgConfig, LinearConfig, LinearSolver, LinearWorkspace, PenaltyJacobian, SpringJacobian,
};
use crate::solver::symplectic::{self, SymplecticWorkspace};
use crate::solver::{StepError, StepParams, StepReport};

/// Steps a cloth by symplectic Euler (`A = M`, the assignment's first
/// stage): `v ← v + h M⁻¹f`, `x ← x + h v`. Explicit, so stable only for small
/// steps; see [`solver::symplectic`](crate::solver::symplectic).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct SymplecticSolver;

impl ClothMethod for SymplecticSolver {
    const KIND: &'static str = "symplectic";
    type Workspace = SymplecticWorkspace;

    fn name(&self) -> &'static str {
        "symplectic"
    }

    fn register_types(app: &mut App) {
        app.register_type::<SymplecticSolver>();
    }

    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
        workspace: &mut SymplecticWorkspace,
    ) -> Result<StepReport, StepError> {
        symplectic::step(model, state, params, spheres, workspace)
    }
}

/// Steps a cloth by linearly implicit Euler, `(M − h²K) v⁺ = Mv + hf`, with a
/// sparse system solved by conjugate gradients or a direct factorisation;
/// see [`solver::linear`](crate::solver::linear).
#[derive(Component, Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct LinearImplicitSolver {
    /// How the linear system is solved (default: CG, 25 iterations, 1e-6).
    #[reflect(remote = LinearSolverReflect)]
    pub solver: LinearSolver,
    /// Which spring stiffness blocks enter the matrix.
    #[reflect(remote = SpringJacobianReflect)]
    pub springs: SpringJacobian,
    /// Which penalty stiffness enters the matrix.
    #[reflect(remote = PenaltyJacobianReflect)]
    pub penalty: PenaltyJacobian,
}

impl LinearImplicitSolver {
    /// Conjugate gradients with these settings.
    pub fn cg(config: CgConfig) -> Self {
        Self {
            solver: LinearSolver::Cg(config),
            ..default()
        }
    }

    /// The direct sparse LDLᵀ solve.
    pub fn direct() -> Self {
        Self {
            solver: LinearSolver::Direct,
            ..default()
        }
    }

    /// With another choice of spring blocks.
    pub fn with_springs(mut self, springs: SpringJacobian) -> Self {
        self.springs = springs;
        self
    }

    /// With another choice of penalty stiffness.
    pub fn with_penalty(mut self, penalty: PenaltyJacobian) -> Self {
        self.penalty = penalty;
        self
    }

    /// The solver settings.
    pub fn config(&self) -> LinearConfig {
        LinearConfig {
            solver: self.solver,
            springs: self.springs,
            penalty: self.penalty,
        }
    }
}

impl ClothMethod for LinearImplicitSolver {
    const KIND: &'static str = "linear-implicit";
    type Workspace = LinearWorkspace;

    fn name(&self) -> &'static str {
        match self.solver {
            LinearSolver::Cg(_) => "linear-cg",
            LinearSolver::Direct => "linear-direct",
        }
    }

    fn register_types(app: &mut App) {
        app.register_type::<LinearImplicitSolver>()
            .register_type::<CgConfigReflect>();
    }

    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
        workspace: &mut LinearWorkspace,
    ) -> Result<StepReport, StepError> {
        linear::step(model, state, params, &self.config(), spheres, workspace)
    }
}

/// Adds symplectic Euler: cloths with a [`SymplecticSolver`] are stepped in
/// [`ClothSystems::Step`](super::ClothSystems::Step).
pub type SymplecticPlugin = MethodPlugin<SymplecticSolver>;

/// Adds linearly implicit Euler: cloths with a [`LinearImplicitSolver`] are
/// stepped in [`ClothSystems::Step`](super::ClothSystems::Step).
pub type LinearImplicitPlugin = MethodPlugin<LinearImplicitSolver>;

/// Steps a cloth by exact implicit Euler: Newton's method with sparse
/// Cholesky and a line search on the lab's objective, to a gradient
/// tolerance. The reference the other methods are measured against; see
/// [`solver::exact`](crate::solver::exact).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct ExactSolver {
    /// Relative gradient tolerance (default 1e-9).
    pub tolerance: f64,
    /// Newton iteration cap (default 100).
    pub max_iterations: u32,
    /// Use only the projected (always positive definite) Hessian.
    pub projected_only: bool,
}

impl Default for ExactSolver {
    fn default() -> Self {
        let c = ExactConfig::default();
        Self {
            tolerance: c.tolerance,
            max_iterations: c.max_iterations,
            projected_only: c.projected_only,
        }
    }
}

impl ExactSolver {
    /// The solver settings.
    pub fn config(&self) -> ExactConfig {
        ExactConfig {
            tolerance: self.tolerance,
            max_iterations: self.max_iterations,
            projected_only: self.projected_only,
            ..ExactConfig::default()
        }
    }
}

impl ClothMethod for ExactSolver {
    const KIND: &'static str = "exact";
    type Workspace = ExactWorkspace;

    fn name(&self) -> &'static str {
        "exact"
    }

    fn register_types(app: &mut App) {
        app.register_type::<ExactSolver>();
    }

    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
        workspace: &mut ExactWorkspace,
    ) -> Result<StepReport, StepError> {
        exact::step(model, state, params, &self.config(), spheres, workspace)
    }
}

/// Adds exact implicit Euler: cloths with an [`ExactSolver`] are stepped in
/// [`ClothSystems::Step`](super::ClothSystems::Step).
pub type ExactPlugin = MethodPlugin<ExactSolver>;
