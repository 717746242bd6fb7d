//! The core plugin: sets, registration, placing and pinning cloths, and the
//! divergence guard.

use core::any::TypeId;

use bevy::ecs::component::ComponentId;
use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::{ScheduleLabel, SingleThreadedExecutor};
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;
use bevy::utils::Parallel;

use super::{
    Cloth, ClothColliders, ClothDiverged, ClothFollowSystems, ClothGuard, ClothNotConverged,
    ClothParams, ClothSchedule, ClothScheduleSystems, ClothStats, ClothStatus, ClothSystems,
    GuardAction,
};
use crate::model::ClothMaterial;
use crate::solver;

/// Registers the cloth components and messages, adds [`ClothSchedule`]
/// (with [`ClothSystems`]) and runs it from the schedule given here, places
/// new cloths, moves pinned vertices and sends the divergence guard's
/// messages. Every method plugin adds it if missing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ClothCorePlugin {
    schedule: Interned<dyn ScheduleLabel>,
}

impl ClothCorePlugin {
    /// Runs [`ClothSchedule`], and so every cloth system, in `schedule`.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for ClothCorePlugin {
    /// `FixedUpdate`.
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl Plugin for ClothCorePlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<Cloth>()
            .register_type::<super::ClothAttachments>()
            .register_type::<ClothParams>()
            .register_type::<ClothStats>()
            .register_type::<ClothGuard>()
            .register_type::<ClothMaterial>()
            .register_type::<crate::collision::SelfCollision>()
            .init_resource::<ClothMethods>()
            .init_resource::<ClothSimulation>()
            .init_resource::<ClothColliders>()
            .init_resource::<super::ClothLayerVertices>()
            .add_message::<ClothDiverged>()
            .add_message::<ClothNotConverged>()
            .add_schedule(cloth_schedule())
            .add_systems(
                self.schedule,
                run_cloth_schedule.in_set(ClothScheduleSystems),
            )
            // The two hooks also order systems of the outer schedule around
            // the whole cloth step (as before the cloth schedule existed).
            .configure_sets(
                self.schedule,
                (
                    ClothSystems::First.before(ClothScheduleSystems),
                    ClothSystems::Last.after(ClothScheduleSystems),
                ),
            )
            .configure_sets(
                ClothSchedule,
                (
                    ClothSystems::First,
                    ClothSystems::SyncIn,
                    ClothSystems::Forces,
                    ClothSystems::Step,
                    ClothSystems::Collide,
                    ClothSystems::SyncOut,
                    ClothSystems::Last,
                )
                    .chain(),
            )
            .configure_sets(
                ClothSchedule,
                (
                    ClothSystems::SyncIn,
                    ClothSystems::Forces,
                    ClothSystems::Step,
                    ClothSystems::Collide,
                    ClothSystems::SyncOut,
                )
                    .run_if(simulation_running),
            )
            .add_systems(
                ClothSchedule,
                count_requested_step.in_set(ClothSystems::Last),
            )
            .add_systems(
                ClothSchedule,
                (
                    apply_materials
                        .in_set(ClothSystems::SyncIn)
                        .before(place_and_pin)
                        .run_if(any_with_component::<ClothMaterial>),
                    place_and_pin.in_set(ClothSystems::SyncIn),
                    super::attach::hold_attached
                        .in_set(ClothSystems::SyncIn)
                        .after(place_and_pin)
                        .run_if(any_with_component::<super::ClothAttachments>),
                    guard_and_measure.in_set(ClothSystems::SyncOut),
                    super::gather_layers
                        .in_set(ClothSystems::Forces)
                        .run_if(any_with_component::<crate::collision::SelfCollision>),
                    super::collide_cloths
                        .in_set(ClothSystems::Collide)
                        .run_if(any_with_component::<crate::collision::SelfCollision>),
                )
                    .run_if(any_with_component::<Cloth>),
            )
            .add_systems(
                PreUpdate,
                super::mesh_source::build_cloths_from_meshes
                    .run_if(any_with_component::<super::ClothFromMesh>),
            )
            .configure_sets(
                PostUpdate,
                ClothFollowSystems.after(TransformSystems::Propagate),
            )
            .add_systems(
                PostUpdate,
                (
                    // Skipped unless a cloth's entity moved: under Bevy's
                    // multi-threaded executor a system that runs costs a
                    // thread handoff, a condition that fails costs none
                    // (`docs/measurements.md`).
                    follow_anchors.run_if(any_match_filter::<(With<Cloth>, Moved)>),
                    super::attach::follow_attached
                        .run_if(any_with_component::<super::ClothAttachments>),
                )
                    .chain()
                    .in_set(ClothFollowSystems)
                    .run_if(any_with_component::<Cloth>),
            );
    }
}

/// Pauses and single-steps every cloth (the assignment's space and `h`
/// keys). While paused, the cloth sets of [`ClothSystems`] do not run, except
/// for steps requested with [`step_once`](Self::step_once).
#[derive(Resource, Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct ClothSimulation {
    /// True while paused.
    pub paused: bool,
    requested: u32,
}

impl ClothSimulation {
    /// Runs one step while paused (no effect while running).
    pub fn step_once(&mut self) {
        if self.paused {
            self.requested += 1;
        }
    }

    /// Steps still requested.
    pub fn requested_steps(&self) -> u32 {
        self.requested
    }
}

/// [`ClothSchedule`] with its single-threaded executor (see its docs).
fn cloth_schedule() -> Schedule {
    let mut schedule = Schedule::new(ClothSchedule);
    schedule.set_executor(SingleThreadedExecutor::new());
    schedule
}

/// Runs [`ClothSchedule`] (added by the plugin, so it exists).
fn run_cloth_schedule(world: &mut World) {
    // `try_`: a schedule removed by the app is skipped, never a panic.
    let _ = world.try_run_schedule(ClothSchedule);
}

fn simulation_running(simulation: Res<ClothSimulation>) -> bool {
    !simulation.paused || simulation.requested > 0
}

fn count_requested_step(mut simulation: ResMut<ClothSimulation>) {
    if simulation.paused && simulation.requested > 0 {
        simulation.requested -= 1;
    }
}

/// Gives each cloth with a [`ClothMaterial`] its springs' stiffness (every
/// step: a changed material or model acts at once) and, when its density or
/// model is new, its vertices' masses. An invalid density is reported once
/// and leaves the masses as they were; invalid moduli reach the parameters,
/// where the step refuses them with a typed error.
fn apply_materials(mut cloths: Query<(Entity, &ClothMaterial, &mut Cloth, &mut ClothParams)>) {
    for (entity, material, mut cloth, mut params) in &mut cloths {
        let stiffness = material.spring_stiffness(&cloth.model);
        if params.stiffness != stiffness {
            params.stiffness = stiffness;
        }
        if cloth.density_applied == Some(material.density) {
            continue;
        }
        let cloth = &mut *cloth;
        cloth.density_applied = Some(material.density);
        if !(material.density.is_finite() && material.density > 0.0) {
            warn!(
                "cloth {entity}: {}; its masses are unchanged",
                crate::solver::ParamError::Density(material.density)
            );
            continue;
        }
        let masses = material.masses(cloth.model.topology());
        if let Err(error) = cloth.model.set_masses(masses) {
            warn!("cloth {entity}: its material gives {error}; its masses are unchanged");
        }
    }
}

/// Moves reset cloths to their rest shape at their entity's transform, places
/// a cloth again whose entity moved between its insertion and its first
/// step, and moves pinned vertices to where the transform puts them now
/// (their velocity is the displacement over the step). Also clears each
/// cloth's `claimed` flag, which the method's step system sets.
///
/// The global transform is computed here from the `Transform` hierarchy, not
/// read from `GlobalTransform`, so a cloth spawned or moved since the last
/// transform propagation is placed where it is now.
pub(crate) fn place_and_pin(
    time: Res<Time>,
    helper: TransformHelper,
    mut cloths: Query<(Entity, &mut Cloth)>,
) {
    let dt = time.delta_secs();
    for_each_cloth!(cloths, |(entity, mut cloth)| {
        let cloth = &mut *cloth;
        cloth.claimed = false;
        let Ok(global) = helper.compute_global_transform(entity) else {
            return;
        };
        let affine = global.affine();
        let placed_at = cloth.placed_at.take();
        if !cloth.initialized || placed_at.is_some_and(|p| p != affine) {
            cloth.place(&affine);
            return;
        }
        pin(cloth, &affine, dt);
    });
}

/// Moves the pinned vertices of `cloth` to `affine` applied to their rest
/// positions; with `dt > 0`, their velocity becomes the displacement over
/// `dt`.
fn pin(cloth: &mut Cloth, affine: &bevy::math::Affine3A, dt: f32) {
    let rest = cloth.model.topology().rest_positions();
    for &p in &cloth.own_pins {
        // A vertex another entity holds follows that entity instead.
        if cloth.attached.binary_search(&p).is_ok() {
            continue;
        }
        let p = p as usize;
        let target = affine.transform_point3a(rest[p].into());
        let old = cloth.state.positions[p];
        if dt > 0.0 {
            cloth.state.velocities[p] = (target - old) / dt;
        }
        cloth.state.positions[p] = target;
    }
}

/// Entities whose transform changed this frame (their own, or a parent's
/// once propagated).
type Moved = Or<(Changed<Transform>, Changed<GlobalTransform>)>;

/// After `Update` (in `PostUpdate`, after transform propagation): pinned
/// vertices of running cloths move to where their entity is now, so an
/// anchor moved in `Update` is followed in the same frame rather than at the
/// next fixed step. Positions only: the next fixed step gives them the
/// velocity of any further motion. A cloth with a
/// [`ClothSkin`](crate::ClothSkin) has its pins on its skin instead.
fn follow_anchors(
    helper: TransformHelper,
    mut cloths: Query<
        (Entity, &mut Cloth, &ClothStats),
        (Moved, Without<crate::character::ClothSkin>),
    >,
) {
    for (entity, mut cloth, stats) in &mut cloths {
        if !cloth.initialized || !stats.is_running() || cloth.own_pins.is_empty() {
            continue;
        }
        if let Ok(global) = helper.compute_global_transform(entity) {
            pin(&mut cloth, &global.affine(), 0.0);
        }
    }
}

/// The divergence guard's second half and the after-step statistics.
///
/// The step systems check each step (see [`ClothGuard`]); this checks the
/// state again after collision, which can move vertices too (a failure here
/// restores the state from before the step and stops the cloth), records
/// stretch and energy, and sends the [`ClothDiverged`] messages.
pub(crate) fn guard_and_measure(
    (time, colliders): (Res<Time>, Res<super::ClothColliders>),
    mut cloths: Query<(
        Entity,
        &mut Cloth,
        &ClothParams,
        &ClothGuard,
        &mut ClothStats,
    )>,
    mut diverged: Local<Parallel<Vec<ClothDiverged>>>,
    mut unconverged: Local<Parallel<Vec<ClothNotConverged>>>,
    mut convergence_log: Local<WarningLog>,
    mut messages: MessageWriter<ClothDiverged>,
    mut convergence: MessageWriter<ClothNotConverged>,
) {
    let dt = time.delta_secs_f64();
    if dt <= 0.0 {
        return;
    }
    for_each_cloth!(cloths, |(entity, mut cloth, params, guard, mut stats)| {
        let cloth = &mut *cloth;
        // A cloth no method stepped: `methods::report_unclaimed` tells.
        if !cloth.claimed {
            return;
        }
        if let Some(message) = settle_convergence(entity, cloth, params, guard, &mut stats, dt) {
            unconverged.borrow_local_mut().push(message);
        }
        if let Some((reason, action)) = cloth.event.take() {
            diverged.borrow_local_mut().push(ClothDiverged {
                entity,
                method: stats.method,
                reason,
                action,
                step: stats.steps,
            });
        }
        if !cloth.initialized || !stats.is_running() {
            return;
        }
        let mut params = params.step_params(dt);
        params.collider_speed = colliders.max_speed();
        // What the step's own guard check measured, if nothing has
        // touched the state since (collision and `Cloth::state_mut` drop
        // it): the same check on the same state, so it is not done twice.
        let stiffness_ok = params.stiffness.validate().is_ok();
        let result = match cloth.measured.take() {
            Some(measured) if stiffness_ok => Ok(measured),
            _ => {
                if !stiffness_ok {
                    // A method that ignores stiffness (PBD) runs with any;
                    // its energy then has no spring term rather than a NaN.
                    params.stiffness = solver::SpringStiffness::uniform(0.0);
                }
                guard.bounds.for_method(!cloth.stiffness_free).check(
                    &cloth.model,
                    &cloth.state,
                    &cloth.last_good,
                    &params,
                )
            }
        };
        match result {
            Ok(measured) => {
                stats.max_stretch = measured.max_stretch;
                stats.energy = measured.energy;
            }
            Err(reason) => {
                cloth.state.copy_from(&cloth.last_good);
                stats.status = ClothStatus::Diverged(reason);
                warn!(
                    "cloth {entity} diverged after collision under method '{}' at step {}: \
                     {reason}; restored its last good state and stopped it",
                    stats.method, stats.steps
                );
                diverged.borrow_local_mut().push(ClothDiverged {
                    entity,
                    method: stats.method,
                    reason,
                    action: GuardAction::Paused,
                    step: stats.steps,
                });
            }
        }
    });
    let mut found: Vec<ClothDiverged> = diverged.drain().collect();
    found.sort_by_key(|d| d.entity);
    messages.write_batch(found);
    let mut found: Vec<ClothNotConverged> = unconverged.drain().collect();
    found.sort_by_key(|d| d.entity);
    let now = time.elapsed_secs_f64();
    for line in convergence_log.note(found.iter().map(ToString::to_string), now) {
        warn!("{line}");
    }
    convergence.write_batch(found);
}

/// Judges the last step's convergence (see `ProjectedConvergence`): measured
/// again after the projection if that moved vertices, then
/// [`ClothStats::converged`] and the count of unconverged steps, and the
/// [`ClothNotConverged`] message the first time.
fn settle_convergence(
    entity: Entity,
    cloth: &mut Cloth,
    params: &ClothParams,
    guard: &ClothGuard,
    stats: &mut ClothStats,
    dt: f64,
) -> Option<ClothNotConverged> {
    let error = cloth.convergence.settle(
        &cloth.model,
        &cloth.last_good,
        &cloth.state.positions,
        &params.step_params(dt),
    )?;
    stats.relative_error = error;
    stats.converged = error.is_none_or(|e| e <= guard.convergence_tolerance);
    if stats.converged {
        return None;
    }
    stats.unconverged_steps += 1;
    if cloth.convergence_reported {
        return None;
    }
    cloth.convergence_reported = true;
    let relative_error = error?;
    Some(ClothNotConverged {
        entity,
        method: stats.method,
        iterations: stats.iterations,
        relative_error,
        tolerance: guard.convergence_tolerance,
        step: stats.steps,
        behaviour: crate::ecs::Unconverged::of(
            relative_error,
            &cloth.last_good.velocities,
            &cloth.state.velocities,
            cloth.model.pinned(),
        ),
    })
}

/// One kind of warning, at most one line a second: the first at once, the
/// ones after it within the second counted and told with one example when
/// the second is over, so that many cloths do not flood the log with a
/// line each. The messages themselves are all sent.
#[derive(Debug, Default)]
pub(crate) struct WarningLog {
    /// When the last line was printed.
    last: Option<f64>,
    /// Warnings since then, and the first of them.
    pending: usize,
    example: Option<String>,
}

impl WarningLog {
    /// Notes `warnings` at time `now` (seconds) and returns the lines to
    /// print now.
    pub(crate) fn note(
        &mut self,
        warnings: impl IntoIterator<Item = String>,
        now: f64,
    ) -> Vec<String> {
        for warning in warnings {
            self.pending += 1;
            self.example.get_or_insert(warning);
        }
        let due = self.last.is_none_or(|last| now - last >= 1.0);
        if self.pending == 0 || !due {
            return Vec::new();
        }
        self.last = Some(now);
        let count = core::mem::take(&mut self.pending);
        let example = self.example.take().unwrap_or_default();
        vec![if count == 1 {
            example
        } else {
            format!("{count} such warnings in the last second, the first: {example}")
        }]
    }
}

impl ClothCorePlugin {
    pub(crate) fn new_interned(schedule: Interned<dyn ScheduleLabel>) -> Self {
        Self { schedule }
    }

    /// Adds the core plugin unless it is already there (method plugins call
    /// this so each can be used on its own).
    pub(crate) fn add_once(self, app: &mut App) {
        if !app.is_plugin_added::<Self>() {
            app.add_plugins(self);
        }
    }
}

/// The method components registered by method plugins, for the
/// one-method-per-cloth rule.
#[derive(Resource, Default, Debug)]
pub struct ClothMethods {
    pub(crate) ids: Vec<(ComponentId, TypeId, &'static str)>,
}

impl ClothMethods {
    /// The registered methods, in registration order, each by the
    /// [`Method::name`](crate::solver::Method::name) of its default settings (`"jacobi"` for
    /// [`ImplicitPlugin`](crate::ImplicitPlugin)).
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.ids.iter().map(|&(_, _, name)| name)
    }

    /// True if the plugin of the method whose settings type has this
    /// [`TypeId`] was added (see [`AnyMethod::type_id`](crate::methods::AnyMethod::type_id)).
    pub fn contains(&self, type_id: TypeId) -> bool {
        self.ids.iter().any(|&(_, t, _)| t == type_id)
    }
}

#[cfg(test)]
mod tests {
    use super::WarningLog;

    #[test]
    fn warnings_of_one_kind_make_at_most_one_line_a_second() {
        let mut log = WarningLog::default();
        let warn = |i: usize| format!("cloth {i} did not converge");
        // The first at once.
        assert_eq!(log.note([warn(0)], 0.0), ["cloth 0 did not converge"]);
        // A hundred more within the second: nothing yet.
        for i in 1..=100 {
            assert!(log.note([warn(i)], 0.01 * i as f64 - 0.005).is_empty());
        }
        // Then one line with their count and the first of them.
        let lines = log.note([], 1.0);
        assert_eq!(lines.len(), 1);
        assert!(
            lines[0].starts_with("100 such warnings")
                && lines[0].ends_with("cloth 1 did not converge"),
            "{}",
            lines[0]
        );
        // Quiet afterwards.
        assert!(log.note([], 5.0).is_empty());
        assert_eq!(log.note([warn(7)], 5.5), ["cloth 7 did not converge"]);
    }
}
