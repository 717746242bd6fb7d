//! The ECS glue: components, system sets, plugins and the systems that move
//! data between the ECS and the solvers.
//!
//! This layer is thin: the physics is in [`model`](crate::model),
//! [`solver`](crate::solver) and [`collision`](crate::collision), which know
//! nothing of entities, schedules or time.

/// A plugin that runs its systems in a schedule given at construction
/// (`FixedUpdate` by default): the struct, `new` and `Default`.
macro_rules! scheduled_plugin {
    ($(#[$meta:meta])* $name:ident) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        pub struct $name {
            schedule: bevy::ecs::intern::Interned<dyn bevy::ecs::schedule::ScheduleLabel>,
        }

        impl $name {
            /// Runs in `schedule`: its systems are in
            /// [`ClothSchedule`](crate::ClothSchedule), which the core plugin
            /// (added with this schedule if missing) runs there.
            pub fn new(schedule: impl bevy::ecs::schedule::ScheduleLabel) -> Self {
                Self {
                    schedule: schedule.intern(),
                }
            }
        }

        impl Default for $name {
            /// `FixedUpdate`.
            fn default() -> Self {
                Self::new(bevy::prelude::FixedUpdate)
            }
        }
    };
}
pub(crate) use scheduled_plugin;

/// Runs the closure `$f` on every item of the query `$q`: on the compute
/// pool (`par_iter_mut`) when it has two items or more, else on this
/// thread. Bevy's `par_iter_mut` hands even a single item to a pool task
/// when the pool has several threads, and that handoff (tens of µs on the
/// perf page's machine) is most of a one-cloth frame's overhead. (A macro:
/// the closure is typed once per loop.)
macro_rules! for_each_cloth {
    ($q:expr, $f:expr $(,)?) => {
        if $q.iter().nth(1).is_some() {
            $q.par_iter_mut().for_each($f)
        } else {
            $q.iter_mut().for_each($f)
        }
    };
}
pub(crate) use for_each_cloth;
pub(crate) use layers::{ClothLayerVertices, collide_cloths, gather_layers};

mod attach;
mod collision;
mod components;
mod core;
mod layers;
mod mesh_source;
mod save;
mod schedule;
mod wind;

use bevy::prelude::*;

pub use crate::solver::guard::DivergenceReason;
pub use attach::{Attachment, ClothAttachments};
pub use collision::{
    CapsuleCollider, ClothColliders, ContactResponse, CuboidCollider, PlaneCollider,
    ShapeCollisionPlugin, SphereCollider, SphereCollisionPlugin, SphereResponse,
};
#[cfg(feature = "avian")]
pub(crate) use collision::{
    ColliderMotion, gather_shapes, project_cloths_on_shapes as project_after_shapes,
    project_running_cloths,
};
pub use components::{
    Cloth, ClothGuard, ClothParams, ClothStateMut, ClothStats, ClothStatus, GuardAction,
};
pub use core::{ClothCorePlugin, ClothMethods, ClothSimulation};
pub(crate) use core::{guard_and_measure, place_and_pin};
pub use mesh_source::ClothFromMesh;
pub use save::ClothSnapshot;
pub use schedule::{ClothFollowSystems, ClothSchedule, ClothScheduleSystems, ClothSystems};
pub use wind::{ClothAerodynamics, Wind, WindPlugin};

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

impl std::fmt::Display for ClothDiverged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "cloth {} under '{}' at step {}: {}; ",
            self.entity, self.method, self.step, self.reason
        )?;
        match self.action {
            GuardAction::Recovered { substeps } => {
                write!(f, "the step was retried as {substeps} substeps and held")
            }
            GuardAction::Paused => f.write_str("restored its last good state and stopped it"),
        }
    }
}

/// Sent once per cloth when a step of its iterative method ends far from
/// converged: its [`relative_error`](crate::solver::StepReport::relative_error)
/// exceeded the guard's
/// [`convergence_tolerance`](ClothGuard::convergence_tolerance). The step is
/// kept (it is finite and inside the guard's bounds) but does not move as
/// implicit Euler would: typically a stiff cloth that "locks" in the air.
/// Sent again only after the method or the cloth's parameters change.
/// [`ClothStats::converged`] and [`ClothStats::unconverged_steps`] follow
/// every step.
///
/// Its `Display` names the remedy.
#[derive(Message, Clone, Copy, Debug, PartialEq)]
pub struct ClothNotConverged {
    /// The cloth entity.
    pub entity: Entity,
    /// The method that was stepping it.
    pub method: &'static str,
    /// Its iterations per step.
    pub iterations: u32,
    /// The step's relative error.
    pub relative_error: f32,
    /// The tolerance it exceeded.
    pub tolerance: f32,
    /// Completed steps when it happened.
    pub step: u64,
    /// What the step looked like.
    pub behaviour: Unconverged,
}

/// What an unconverged step looked like (see [`ClothNotConverged`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Reflect)]
pub enum Unconverged {
    /// It moved in the right direction but not far enough: its estimated
    /// distance from implicit Euler's step is at most its motion.
    Lagging,
    /// It moved less than the distance still left to implicit Euler's step
    /// (relative error above 1): a stiff cloth that lags like this hangs
    /// "locked" in the air, or creeps where it should fall.
    Locked,
    /// Its free vertices' velocities turned against the step before's (their
    /// dot products sum below zero): it overshoots back and forth about
    /// implicit Euler's step.
    Oscillating,
}

impl Unconverged {
    /// From a step's relative error and the free vertices' velocities
    /// before and after it.
    pub fn of(relative_error: f32, before: &[Vec3A], after: &[Vec3A], pinned: &[bool]) -> Self {
        let turned: f64 = before
            .iter()
            .zip(after)
            .zip(pinned)
            .filter(|(_, p)| !**p)
            .map(|((a, b), _)| f64::from(a.dot(*b)))
            .sum();
        if turned < 0.0 {
            Self::Oscillating
        } else if relative_error > 1.0 {
            Self::Locked
        } else {
            Self::Lagging
        }
    }

    /// One clause that says it.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Lagging => "it lags behind that step",
            Self::Locked => {
                "it moved less than the distance left to that step: stiff cloth that does this \
                 hangs locked in the air or creeps where it should fall"
            }
            Self::Oscillating => {
                "its velocities turned against the step before's: it oscillates about that step"
            }
        }
    }
}

impl std::fmt::Display for ClothNotConverged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "cloth {} did not converge under '{}' with {} iterations at step {}: its estimated \
             distance from implicit Euler's step is {:.0} % of its motion (tolerance {:.0} %), \
             and {}; {}",
            self.entity,
            self.method,
            self.iterations,
            self.step,
            100.0 * self.relative_error,
            100.0 * self.tolerance,
            self.behaviour.describe(),
            self.remedy()
        )
    }
}

impl ClothNotConverged {
    /// What to do about it, from the stability map: more iterations, a
    /// smaller stiffness or time step, or a method that stays right at
    /// higher stiffness (`stiff`, the default preset; `pd`, then
    /// `pd-anderson`; Newton on a budget, `newton`, on small cloths).
    pub fn remedy(&self) -> &'static str {
        if self.method == "pd" {
            "raise the iterations, lower the stiffness or the time step, or use 'stiff' (XPBD \
             with small steps, the default preset for stiff cloth and cloth of real mass), \
             'pd-anderson' (Anderson-accelerated) or 'newton' (Newton on a budget, for small \
             cloths)"
        } else if self.method == "newton" || self.method == "exact" {
            "raise Newton's iteration cap, or lower the stiffness or the time step ('exact' \
             iterates up to 100 times, to a relative gradient of 1e-9)"
        } else if self.method == "pd-anderson" {
            "raise the iterations, lower the stiffness or the time step, or use 'stiff' (XPBD \
             with small steps, the default preset for stiff cloth and cloth of real mass) or \
             'newton' (Newton with direct solves on a budget, for small cloths)"
        } else {
            "raise the iterations, lower the stiffness or the time step, or use 'stiff' (XPBD \
             with small steps, the default preset for stiff cloth and cloth of real mass) or \
             the 'pd' method (projective dynamics), which stays right about a decade stiffer"
        }
    }
}
