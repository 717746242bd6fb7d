//! The glue every method plugin shares: one generic step system, the rule
//! that a cloth has at most one method component at a time, and the
//! diagnostic for a cloth that no method stepped.

use core::any::TypeId;
use core::marker::PhantomData;
use std::time::Instant;

use bevy::ecs::component::Mutable;
use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::ecs::schedule::common_conditions::any_with_component;
use bevy::prelude::*;
use bevy::reflect::GetTypeRegistration;

use crate::character::ClothSkin;
use crate::collision::SelfCollision;
use crate::collision::self_contact::{SelfCollisionInput, SelfContacts};
use crate::collision::{Capsule, PenaltySphere, Shape};
use crate::ecs::{
    Cloth, ClothColliders, ClothCorePlugin, ClothGuard, ClothLayerVertices, ClothMethods,
    ClothParams, ClothSchedule, ClothStats, ClothStatus, ClothSystems, GuardAction, for_each_cloth,
};
use crate::solver::SkinInput;
use crate::solver::guard::{GuardError, GuardedStep, guarded_step};
use crate::solver::{Method, StepError, StepInput};

/// A method as the ECS sees it: a [`Method`] settings type that is also a
/// reflected component. Every method of the crate's table
/// ([`methods`](crate::methods)) is one; nothing to implement by hand.
///
/// A cloth has at most one method: inserting one removes any other, so
/// swapping the component switches the method at run time. Each method's
/// scratch buffers live in a [`ClothWorkspace`] that is added with the
/// method and removed with it.
pub trait ClothMethod:
    Method + Default + Component<Mutability = Mutable> + Reflect + TypePath + GetTypeRegistration
{
}

impl<M> ClothMethod for M where
    M: Method
        + Default
        + Component<Mutability = Mutable>
        + Reflect
        + TypePath
        + GetTypeRegistration
{
}

/// A method's scratch buffers on a cloth entity (not reflected: it holds no
/// state worth inspecting and is rebuilt on demand).
#[derive(Component, Default, Debug)]
pub struct ClothWorkspace<W: Default + Send + Sync + 'static> {
    /// The solver's own buffers.
    pub solver: W,
    /// This cloth's penalty spheres (contact distance includes its particle
    /// radius), refilled each step.
    penalty: Vec<PenaltySphere>,
    /// The solids projected after the step, grown by this cloth's particle
    /// radius, refilled each step for a method that projects them inside
    /// it ([`StepInput::contacts`]).
    contacts: Vec<Shape>,
    /// How far each of `contacts` moved over the step (parallel to it).
    contact_motion: Vec<Vec3A>,
    /// Self-collision's pairs, for a method that leaves it to after the step.
    self_contacts: SelfContacts,
}

/// The step systems of all methods.
#[derive(SystemSet, Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct MethodSteps;

/// Registers method `M`: its step system in [`ClothSystems::Step`] (running
/// only while some entity has `M`), and the observers that keep one method
/// per cloth and manage `M`'s workspace.
pub(crate) fn add_method<M: ClothMethod>(app: &mut App) {
    let id = app.world_mut().register_component::<M>();
    let mut methods = app.world_mut().get_resource_or_init::<ClothMethods>();
    if methods.ids.iter().any(|&(i, _, _)| i == id) {
        return;
    }
    let first = methods.ids.is_empty();
    methods
        .ids
        .push((id, TypeId::of::<M>(), M::default().name()));
    app.add_systems(
        ClothSchedule,
        step_cloths::<M>
            .in_set(ClothSystems::Step)
            .in_set(MethodSteps)
            // Method step systems all write `Cloth`, but never the same cloth:
            // a cloth has one method (enforced by the observers below).
            .ambiguous_with(MethodSteps)
            .run_if(any_with_component::<M>),
    )
    .add_observer(on_method_inserted::<M>)
    .add_observer(on_method_removed::<M>);
    if first {
        app.add_systems(
            ClothSchedule,
            super::report_unclaimed.in_set(ClothSystems::SyncOut),
        );
    }
}

fn on_method_inserted<M: ClothMethod>(
    insert: On<Insert, M>,
    methods: Res<ClothMethods>,
    entities: Query<EntityRef>,
    mut commands: Commands,
) {
    let entity = insert.entity;
    let Ok(entity_ref) = entities.get(entity) else {
        return;
    };
    let mut cmds = commands.entity(entity);
    for &(id, type_id, _) in &methods.ids {
        if type_id != TypeId::of::<M>() && entity_ref.contains_id(id) {
            cmds.remove_by_id(id);
        }
    }
    if !entity_ref.contains::<ClothWorkspace<M::Workspace>>() {
        cmds.insert(ClothWorkspace::<M::Workspace>::default());
    }
}

fn on_method_removed<M: ClothMethod>(remove: On<Remove, M>, mut commands: Commands) {
    if let Ok(mut e) = commands.get_entity(remove.entity) {
        e.try_remove::<ClothWorkspace<M::Workspace>>();
    }
}

/// The plugin of method `M`: it steps the cloths that carry `M` in
/// [`ClothSystems::Step`], and adds [`ClothCorePlugin`](crate::ClothCorePlugin)
/// if it is missing, so each method plugin can be added on its own.
pub struct MethodPlugin<M> {
    schedule: Interned<dyn ScheduleLabel>,
    _method: PhantomData<fn() -> M>,
}

impl<M> MethodPlugin<M> {
    /// Runs in `schedule`: its step system is in
    /// [`ClothSchedule`](ClothSchedule), which the core plugin (added
    /// with this schedule if missing) runs there.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
            _method: PhantomData,
        }
    }
}

impl<M> Default for MethodPlugin<M> {
    /// `FixedUpdate`.
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl<M> Clone for MethodPlugin<M> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<M> Copy for MethodPlugin<M> {}

impl<M> core::fmt::Debug for MethodPlugin<M> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct(core::any::type_name::<Self>())
            .field("schedule", &self.schedule)
            .finish()
    }
}

impl<M: ClothMethod> Plugin for MethodPlugin<M> {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.register_type::<M>()
            .register_type_data::<M, ReflectComponent>();
        add_method::<M>(app);
    }
}

/// What the step system of method `M` reads and writes per cloth.
type StepData<M> = (
    Entity,
    &'static mut Cloth,
    Ref<'static, ClothParams>,
    &'static ClothGuard,
    Ref<'static, M>,
    &'static mut ClothWorkspace<<M as Method>::Workspace>,
    &'static mut ClothStats,
    Option<&'static ClothSkin>,
    Option<Ref<'static, SelfCollision>>,
);

/// Sets `status` to `Invalid(error)`, warning when it changes (compared by
/// text, so a NaN parameter warns once too).
fn refuse(entity: Entity, name: &str, stats: &mut ClothStats, error: StepError) {
    let same =
        matches!(&stats.status, ClothStatus::Invalid(e) if e.to_string() == error.to_string());
    if !same {
        warn!("cloth {entity} ('{name}') skipped: {error}");
        stats.status = ClothStatus::Invalid(error);
    }
}

/// Steps every running cloth that has method `M`, in parallel across cloths.
fn step_cloths<M: ClothMethod>(
    time: Res<Time>,
    colliders: Res<ClothColliders>,
    layers: Res<ClothLayerVertices>,
    mut cloths: Query<StepData<M>>,
) {
    let dt = time.delta_secs_f64();
    if dt <= 0.0 {
        return;
    }
    for_each_cloth!(cloths, |(
        entity,
        mut cloth,
        params,
        guard,
        method,
        mut ws,
        mut stats,
        skin,
        self_collision,
    )| {
        cloth.claimed = true;
        stats.contacts = 0;
        stats.self_contacts = 0;
        if method.is_changed() || params.is_changed() {
            cloth.convergence_reported = false;
        }
        if !stats.method.is_empty() && stats.method != method.name() {
            // Another method: what the guard and the stats said of the old
            // one does not carry over.
            stats.clear();
            cloth.guard_memory = Default::default();
        }
        if let ClothStatus::NoMethod { .. } = stats.status {
            stats.status = ClothStatus::Running;
        }
        if !cloth.initialized || matches!(stats.status, ClothStatus::Diverged(_)) {
            return;
        }
        if let Err(error) = params.validate().and_then(|()| guard.validate()) {
            refuse(entity, method.name(), &mut stats, error.into());
            return;
        }
        let cloth = &mut *cloth;
        let particle_radius = params.particle_radius;
        let params = crate::solver::StepParams {
            collider_speed: colliders.max_speed(),
            ..params.step_params(dt)
        };
        let ws = &mut *ws;
        ws.penalty.clear();
        ws.penalty.extend(
            colliders
                .penalty
                .iter()
                .chain(&colliders.penalty_shapes)
                .map(|s| s.grown(particle_radius)),
        );
        ws.contacts.clear();
        ws.contacts.extend(
            colliders
                .projection
                .iter()
                .map(|s| {
                    Shape::Capsule(Capsule {
                        a: s.center,
                        b: s.center,
                        radius: s.radius,
                        friction: s.friction,
                    })
                })
                .chain(colliders.shapes.iter().copied())
                .chain(colliders.avian.iter().copied())
                .map(|s| s.grown(particle_radius)),
        );
        ws.contact_motion.clear();
        // Spheres move through `stiff`'s substeps, from where they were to
        // where they are; capsules, boxes and planes are taken where they
        // are through the step. Their motion is their centre's translation,
        // and shifting a turned one back by it puts it where it never was:
        // a character's bone capsules, so moved, doubled its cape's
        // stretch. The projection after the step sweeps them all.
        ws.contact_motion.extend(
            [
                (colliders.projection.len(), &colliders.projection_motion),
                (colliders.shapes.len(), &colliders.shape_motion),
                (colliders.avian.len(), &colliders.avian_motion),
            ]
            .into_iter()
            .flat_map(|(n, motion)| (0..n).map(|k| motion.get(k).copied().unwrap_or(Vec3A::ZERO))),
        );
        for (m, shape) in ws.contact_motion.iter_mut().zip(&ws.contacts) {
            if !matches!(shape, Shape::Capsule(c) if c.a == c.b) {
                *m = Vec3A::ZERO;
            }
        }
        cloth.pin_velocities(dt as f32);
        let (penalty, contacts, contact_motion, solver_ws) = (
            &ws.penalty,
            &ws.contacts,
            &ws.contact_motion,
            &mut ws.solver,
        );
        let model = &cloth.model;
        // A skin that does not fit the cloth is left to `hold_to_skin`,
        // which warns.
        let skin = skin
            .filter(|s| {
                s.constraints
                    .validate(model.vertex_count(), &s.pose)
                    .is_ok()
            })
            .map(|s| SkinInput {
                previous: Some(&s.previous[..]),
                ..s.constraints.input(&s.pose)
            });
        // A self-collision that does not fit the cloth is left out, with one
        // warning each time it is set.
        let self_collision = self_collision.and_then(|sc| match sc.validate(model) {
            Ok(()) => Some(SelfCollisionInput {
                setting: *sc,
                others: layers.others(entity),
            }),
            Err(error) => {
                if sc.is_changed() {
                    warn!(
                        "cloth {entity} ('{}'): self-collision refused: {error}",
                        method.name()
                    );
                }
                None
            }
        });
        let method = &*method;
        let start = Instant::now();
        cloth.measured = None;
        cloth.stiffness_free = !method.uses_stiffness();
        let result = guarded_step(
            &guard.bounds.for_method(!cloth.stiffness_free),
            guard.policy,
            &mut cloth.guard_memory,
            model,
            &mut cloth.state,
            &mut cloth.last_good,
            &params,
            |state, p| {
                let input = StepInput {
                    model,
                    params: p,
                    spheres: penalty,
                    contacts,
                    contact_motion,
                    skin,
                    self_collision,
                };
                method.step_with(input, state, solver_ws)
            },
        );
        let elapsed = start.elapsed();
        stats.method = method.name();
        // Where the step left the pins (see `Cloth::pin_velocities`).
        cloth.pins_stepped.clear();
        cloth.pins_stepped.extend(
            model
                .pins()
                .iter()
                .map(|&p| (p, cloth.state.positions[p as usize])),
        );
        cloth.last_substep = result.as_ref().ok().and_then(GuardedStep::last_substep);
        // PBD limits its springs' strain itself, to its own bound: the
        // following would be a second limit (with it, PBD's two sheets on
        // the map tangled further, 1,655 edges through against 338).
        cloth.held_others = self_collision.is_some()
            && !cloth.stiffness_free
            && result
                .as_ref()
                .is_ok_and(|done| done.report.self_contacts.is_some());
        match result {
            Ok(done) => {
                if let Some(sc) = self_collision {
                    stats.self_contacts = match done.report.self_contacts {
                        Some(held) => held,
                        None => {
                            // After the step, for a method that does not
                            // handle it inside.
                            cloth.measured = None;
                            ws.self_contacts.resolve_after_step(
                                model,
                                &mut cloth.state,
                                &cloth.last_good,
                                &params,
                                sc,
                            )
                        }
                    };
                }
                // Penalty contacts (projection contacts are counted by the
                // collision system, which adds to these).
                stats.contacts += penalty
                    .iter()
                    .map(|s| {
                        cloth
                            .state
                            .positions
                            .iter()
                            .zip(model.pinned())
                            .filter(|&(&x, &pinned)| !pinned && s.contact(x).is_some())
                            .count() as u32
                    })
                    .sum::<u32>();
                stats.contacts += done.report.contacts;
                stats.steps += 1;
                stats.step_time = elapsed;
                stats.iterations = done.report.iterations;
                stats.residual = done.report.residual;
                // Judged in `SyncOut`, after the colliders' projection.
                cloth.convergence.stepped(
                    done.report.relative_error,
                    done.substeps == 1,
                    guard.convergence_tolerance,
                );
                stats.substeps = done.substeps;
                cloth.measured = Some(done.measured);
                if let Some(reason) = done.retried_because {
                    stats.retried_steps += 1;
                    cloth.event = Some((
                        reason,
                        GuardAction::Recovered {
                            substeps: done.substeps,
                        },
                    ));
                }
                if !stats.is_running() {
                    stats.status = ClothStatus::Running;
                }
            }
            Err(GuardError::Diverged { reason, halvings }) => {
                warn!(
                    "cloth {entity} stopped under '{}' at step {}: {reason} ({halvings} halvings \
                     tried); restored its last good state",
                    method.name(),
                    stats.steps
                );
                stats.status = ClothStatus::Diverged(reason);
                cloth.event = Some((reason, GuardAction::Paused));
            }
            Err(GuardError::Refused(error)) => refuse(entity, method.name(), &mut stats, error),
        }
    },);
}
