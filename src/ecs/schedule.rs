//! The cloth schedule and its system sets: the order of a cloth step.

use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;

/// The schedule in which every cloth system runs, in [`ClothSystems`] order.
///
/// It runs once per run of the schedule given to
/// [`ClothPlugins`](crate::ClothPlugins) (`FixedUpdate` by default, so once
/// per fixed step), from one exclusive system in [`ClothScheduleSystems`].
/// Add systems that must run just before or after the cloth step here, in
/// [`ClothSystems::First`] or [`ClothSystems::Last`].
///
/// Its executor is single-threaded (as avian runs its `PhysicsSchedule`):
/// the systems run one after another on one thread, and the heavy ones
/// spread the cloths over Bevy's compute task pool themselves. Bevy's
/// multi-threaded executor hands every system to another thread, which
/// costs more than most of these systems' work. What that costs, and what
/// one lab cloth adds to a frame, is in `docs/measurements.md` and
/// `docs/perf.md`.
#[derive(ScheduleLabel, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ClothSchedule;

/// The set, in the schedule given to [`ClothPlugins`](crate::ClothPlugins)
/// (`FixedUpdate` by default), of the one system that runs
/// [`ClothSchedule`]: order systems of that schedule before or after the
/// whole cloth step with it.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ClothScheduleSystems;

/// The system sets of the cloth simulation, run in this order (chained)
/// in [`ClothSchedule`], which runs once per run of the schedule given to
/// [`ClothPlugins`](crate::ClothPlugins) (`FixedUpdate` by default, so once
/// per fixed step):
///
/// 1. [`First`](Self::First): empty, for user systems that must run before
///    the cloth step (for example moving a collider).
/// 2. [`SyncIn`](Self::SyncIn): new cloths are placed at their entity's
///    transform; pinned vertices move to where their entity puts them.
/// 3. [`Forces`](Self::Forces): external forces other than gravity change
///    the cloths' velocities (wind and air, [`WindPlugin`](crate::WindPlugin)),
///    as explicit forces of the coming step.
/// 4. [`Step`](Self::Step): each method plugin advances the cloths that carry
///    its solver component under the divergence guard
///    ([`ClothGuard`](crate::ecs::ClothGuard)): the state before the step is
///    kept, and a step that fails is undone and retried with halved time
///    steps, or the cloth is stopped.
/// 5. [`Collide`](Self::Collide): colliders act on the stepped cloths.
/// 6. [`SyncOut`](Self::SyncOut): the guard checks every cloth again after
///    collision (restoring and pausing one that failed), sends
///    [`ClothDiverged`](crate::ecs::ClothDiverged) for every rejected step,
///    and [`ClothStats`](crate::ecs::ClothStats) gets max stretch and energy.
/// 7. [`Last`](Self::Last): empty, for user systems that read the result.
///
/// The two hooks are ordered in the outer schedule too: a system added to
/// `FixedUpdate` (or the schedule given to the plugins) in `First` runs
/// before the whole cloth step, one in `Last` after it. The other sets exist
/// only in [`ClothSchedule`].
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ClothSystems {
    /// Empty hook before the step.
    First,
    /// Place new cloths, move pinned vertices.
    SyncIn,
    /// External forces (wind, air) act on velocities.
    Forces,
    /// Advance each cloth with its method.
    Step,
    /// Resolve collisions.
    Collide,
    /// Divergence guard and statistics.
    SyncOut,
    /// Empty hook after the step.
    Last,
}

/// The set in `PostUpdate` (after transform propagation, before the mesh
/// write-back) in which pinned vertices follow their entity's transform as
/// it is at the end of the frame, so an anchor moved in `Update` is followed
/// in the same frame. See [`ClothSystems::SyncIn`] for the fixed-step side.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ClothFollowSystems;
