//! The position-based pipeline (the lab's part 2) as a component and a plugin.

use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;

use super::ClothCorePlugin;
use super::method::{ClothMethod, add_method};
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
    const NAME: &'static str = "pbd";
    type Workspace = PbdWorkspace;

    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        workspace: &mut PbdWorkspace,
    ) -> Result<StepReport, StepError> {
        pbd::step(
            model,
            state,
            params,
            &PbdConfig {
                iterations: self.iterations,
            },
            workspace,
        )
    }
}

/// Adds the position-based pipeline: cloths with a [`PbdSolver`] are stepped
/// in [`ClothSystems::Step`](super::ClothSystems::Step).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PbdPlugin {
    schedule: Interned<dyn ScheduleLabel>,
}

impl PbdPlugin {
    /// Runs in `schedule`.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for PbdPlugin {
    /// `FixedUpdate`.
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl Plugin for PbdPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.register_type::<PbdSolver>();
        add_method::<PbdSolver>(app, self.schedule);
    }
}
