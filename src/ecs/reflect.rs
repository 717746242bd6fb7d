//! Reflection of core (non-Bevy) types, so the model and solver stay free of
//! Bevy traits while components that hold them can still be reflected.

use bevy::reflect::reflect_remote;

/// Reflects [`SpringStiffness`](crate::solver::SpringStiffness).
#[reflect_remote(crate::solver::SpringStiffness)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpringStiffnessReflect {
    /// Stiffness of stretch springs.
    pub stretch: f32,
    /// Stiffness of shear springs.
    pub shear: f32,
    /// Stiffness of bending springs.
    pub bend: f32,
}

/// Reflects [`Preconditioner`](crate::solver::linear::Preconditioner).
#[reflect_remote(crate::solver::linear::Preconditioner)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PreconditionerReflect {
    /// None.
    None,
    /// Inverse diagonal.
    Jacobi,
}

/// Reflects [`CgConfig`](crate::solver::linear::CgConfig).
#[reflect_remote(crate::solver::linear::CgConfig)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CgConfigReflect {
    /// Iteration cap.
    pub max_iterations: u32,
    /// Relative residual tolerance.
    pub tolerance: f64,
    /// Preconditioner.
    #[reflect(remote = PreconditionerReflect)]
    pub preconditioner: crate::solver::linear::Preconditioner,
}

/// Reflects [`LinearSolver`](crate::solver::linear::LinearSolver).
#[reflect_remote(crate::solver::linear::LinearSolver)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LinearSolverReflect {
    /// Conjugate gradients.
    Cg(#[reflect(remote = CgConfigReflect)] crate::solver::linear::CgConfig),
    /// Direct LDLᵀ.
    Direct,
}

/// Reflects [`SpringJacobian`](crate::solver::linear::SpringJacobian).
#[reflect_remote(crate::solver::linear::SpringJacobian)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpringJacobianReflect {
    /// The assignment's blocks.
    Exact,
    /// Compressive term dropped.
    ClampCompression,
}

/// Reflects [`PenaltyJacobian`](crate::solver::linear::PenaltyJacobian).
#[reflect_remote(crate::solver::linear::PenaltyJacobian)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PenaltyJacobianReflect {
    /// Normal part of the true Jacobian.
    Normal,
    /// The assignment's `c·d·I`.
    Isotropic,
    /// The true Jacobian.
    Exact,
}
