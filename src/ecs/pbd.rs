//! The position-based pipeline (the lab's part 2) as a component and a plugin.

use bevy::prelude::*;

use super::method::{ClothMethod, MethodPlugin};
use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState};
use crate::solver::pbd::{self, PbdConfig, PbdWorkspace};
use crate::solver::{StepError, StepParams, StepReport};

/// Steps a cloth by position-based dynamics with the lab's Jacobi strain
/// limiting. Spring stiffness is not used. See
/// [`solver::pbd`](crate::solver::pbd).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct PbdSolver {
    /// Strain-limiting iterations per step (default 32).
    pub iterations: u32,
}

impl PbdSolver {
    /// With `iterations` strain-limiting iterations.
    pub const fn new(iterations: u32) -> Self {
        Self { iterations }
    }
}

impl Default for PbdSolver {
    fn default() -> Self {
        Self::new(32)
    }
}

impl ClothMethod for PbdSolver {
    const KIND: &'static str = "pbd";
    type Workspace = PbdWorkspace;

    fn name(&self) -> &'static str {
        "pbd"
    }

    fn register_types(app: &mut App) {
        app.register_type::<PbdSolver>();
    }

    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
        workspace: &mut PbdWorkspace,
    ) -> Result<StepReport, StepError> {
        let config = PbdConfig {
            iterations: self.iterations,
        };
        pbd::step(model, state, params, &config, spheres, workspace)
    }
}

/// Adds the position-based pipeline: cloths with a [`PbdSolver`] are stepped
/// in [`ClothSystems::Step`](super::ClothSystems::Step).
pub type PbdPlugin = MethodPlugin<PbdSolver>;
