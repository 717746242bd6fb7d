//! The implicit pipeline (the lab's part 1) as a component and a plugin.

use bevy::prelude::*;

use super::method::{ClothMethod, MethodPlugin};
use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState};
use crate::solver::implicit::{self, ImplicitConfig, ImplicitWorkspace, Rho};
use crate::solver::{StepError, StepParams, StepReport};

/// Chebyshev acceleration of the implicit solver (Wang 2015).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
pub struct Chebyshev {
    /// Estimated spectral radius of the Jacobi iteration, in `(0, 1)`.
    pub rho: f32,
    /// Estimate `ρ` each step from the first Jacobi iterations instead
    /// ([`Rho::Auto`](crate::solver::implicit::Rho::Auto)).
    pub auto_rho: bool,
}

impl Default for Chebyshev {
    /// The lab's fixed `ρ = 0.995`.
    fn default() -> Self {
        Self {
            rho: 0.995,
            auto_rho: false,
        }
    }
}

/// Steps a cloth by implicit Euler with the lab's diagonal-Hessian Newton
/// (Jacobi) iteration, optionally Chebyshev-accelerated. See
/// [`solver::implicit`](crate::solver::implicit) for the equations.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct ImplicitSolver {
    /// Iterations per step (the lab: 32).
    pub iterations: u32,
    /// Chebyshev acceleration, or `None` for plain Jacobi.
    pub chebyshev: Option<Chebyshev>,
}

impl ImplicitSolver {
    /// Plain Jacobi (the lab's 1.c).
    pub const fn jacobi(iterations: u32) -> Self {
        Self {
            iterations,
            chebyshev: None,
        }
    }

    /// Chebyshev-accelerated Jacobi (the lab's 1.d).
    pub const fn chebyshev(iterations: u32, rho: f32) -> Self {
        Self {
            iterations,
            chebyshev: Some(Chebyshev {
                rho,
                auto_rho: false,
            }),
        }
    }

    /// Chebyshev-accelerated Jacobi with `ρ` estimated each step.
    pub const fn chebyshev_auto(iterations: u32) -> Self {
        Self {
            iterations,
            chebyshev: Some(Chebyshev {
                rho: 0.995,
                auto_rho: true,
            }),
        }
    }

    /// The solver settings.
    pub fn config(&self) -> ImplicitConfig {
        ImplicitConfig {
            iterations: self.iterations,
            chebyshev: self.chebyshev.map(|c| {
                if c.auto_rho {
                    Rho::Auto
                } else {
                    Rho::Fixed(c.rho)
                }
            }),
        }
    }
}

impl Default for ImplicitSolver {
    /// The lab: 32 plain Jacobi iterations.
    fn default() -> Self {
        Self::jacobi(32)
    }
}

impl ClothMethod for ImplicitSolver {
    const KIND: &'static str = "implicit";
    type Workspace = ImplicitWorkspace;

    fn name(&self) -> &'static str {
        if self.chebyshev.is_some() {
            "chebyshev"
        } else {
            "jacobi"
        }
    }

    fn register_types(app: &mut App) {
        app.register_type::<ImplicitSolver>()
            .register_type::<Chebyshev>();
    }

    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
        workspace: &mut ImplicitWorkspace,
    ) -> Result<StepReport, StepError> {
        implicit::step(model, state, params, &self.config(), spheres, workspace)
    }
}

/// Adds the implicit pipeline: cloths with an [`ImplicitSolver`] are stepped
/// in [`ClothSystems::Step`](super::ClothSystems::Step).
pub type ImplicitPlugin = MethodPlugin<ImplicitSolver>;
