//! The ECS glue: components, system sets, plugins and the systems that move
//! data between the ECS and the solvers.
//!
//! This layer is thin: the physics is in [`model`](crate::model),
//! [`solver`](crate::solver) and [`collision`](crate::collision), which know
//! nothing of entities, schedules or time.

mod collision;
mod components;
mod core;
mod method;
mod schedule;

use bevy::prelude::*;

pub use crate::solver::guard::DivergenceReason;
pub use collision::{ClothColliders, SphereCollider, SphereCollisionPlugin, SphereResponse};
pub use components::{Cloth, ClothGuard, ClothParams, ClothStats, ClothStatus, GuardAction};
pub use core::{ClothCorePlugin, ClothSimulation};
pub use method::{ClothMethod, ClothMethods, ClothWorkspace, MethodPlugin};
pub use schedule::ClothSystems;

/// Sent when the divergence guard rejects a cloth's step (see
/// [`ClothGuard`]): the step went non-finite, left the guard's bounds, or its
/// solve failed. `action` says whether a retry with smaller steps rescued
/// it or the cloth was stopped at its last good state
/// ([`ClothStatus::Diverged`]).
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub struct ClothDiverged {
    /// The cloth entity.
    pub entity: Entity,
    /// The method that was stepping it.
    pub method: &'static str,
    /// What the guard saw.
    pub reason: DivergenceReason,
    /// What it did.
    pub action: GuardAction,
    /// Completed steps when it happened.
    pub step: u64,
}
