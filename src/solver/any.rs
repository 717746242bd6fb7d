//! Any method by value: one enum over every solver's settings and one
//! workspace holding every solver's scratch, for code that sweeps methods
//! (the stability map, the report, tests) without the ECS.

use super::exact::{self, ExactConfig, ExactWorkspace};
use super::implicit::{self, ImplicitConfig, ImplicitWorkspace, Rho};
use super::linear::{self, LinearConfig, LinearSolver, LinearWorkspace, SpringJacobian};
use super::pbd::{self, PbdConfig, PbdWorkspace};
use super::symplectic::{self, SymplecticWorkspace};
use super::{StepError, StepParams, StepReport};
use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState};

/// One method with its settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnyMethod {
    /// Implicit Euler by Jacobi or Chebyshev iterations ([`implicit::step`]).
    Implicit(ImplicitConfig),
    /// Position-based strain limiting ([`pbd::step`]).
    Pbd(PbdConfig),
    /// Symplectic Euler ([`symplectic::step`]).
    Symplectic,
    /// Linearly implicit Euler ([`linear::step`]).
    Linear(LinearConfig),
    /// Exact implicit Euler ([`exact::step`]).
    Exact(ExactConfig),
}

impl AnyMethod {
    /// A short name of the method and its main settings, for tables:
    /// `jacobi`, `chebyshev ρ=0.995`, `chebyshev ρ auto`, `pbd`,
    /// `symplectic`, `linear-cg`, `linear-direct`, with ` (exact K)` when
    /// the linear methods use the unclamped spring Jacobian, and `exact`.
    pub fn label(&self) -> String {
        match self {
            Self::Implicit(c) => match c.chebyshev {
                None => "jacobi".into(),
                Some(Rho::Fixed(rho)) => format!("chebyshev ρ={rho}"),
                Some(Rho::Auto) => "chebyshev ρ auto".into(),
            },
            Self::Pbd(_) => "pbd".into(),
            Self::Symplectic => "symplectic".into(),
            Self::Linear(c) => {
                let solver = match c.solver {
                    LinearSolver::Cg(_) => "linear-cg",
                    LinearSolver::Direct => "linear-direct",
                };
                match c.springs {
                    SpringJacobian::ClampCompression => solver.into(),
                    SpringJacobian::Exact => format!("{solver} (exact K)"),
                }
            }
            Self::Exact(_) => "exact".into(),
        }
    }

    /// Advances `state` by one step of this method.
    pub fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
        ws: &mut AnyWorkspace,
    ) -> Result<StepReport, StepError> {
        match self {
            Self::Implicit(c) => implicit::step(model, state, params, c, spheres, &mut ws.implicit),
            Self::Pbd(c) => pbd::step(model, state, params, c, spheres, &mut ws.pbd),
            Self::Symplectic => symplectic::step(model, state, params, spheres, &mut ws.symplectic),
            Self::Linear(c) => linear::step(model, state, params, c, spheres, &mut ws.linear),
            Self::Exact(c) => exact::step(model, state, params, c, spheres, &mut ws.exact),
        }
    }
}

/// Every solver's scratch buffers, each allocated on its method's first step.
#[derive(Debug, Default)]
pub struct AnyWorkspace {
    /// For [`AnyMethod::Implicit`].
    pub implicit: ImplicitWorkspace,
    /// For [`AnyMethod::Pbd`].
    pub pbd: PbdWorkspace,
    /// For [`AnyMethod::Symplectic`].
    pub symplectic: SymplecticWorkspace,
    /// For [`AnyMethod::Linear`].
    pub linear: LinearWorkspace,
    /// For [`AnyMethod::Exact`].
    pub exact: ExactWorkspace,
}
