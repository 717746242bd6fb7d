//! Sphere, plane, capsule and box colliders as components and plugins.

use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use super::{Cloth, ClothCorePlugin, ClothParams, ClothSchedule, ClothStats, ClothSystems};
use crate::collision::swept::sphere_solids;
use crate::collision::{
    Capsule, Cuboid, PenaltySphere, Plane, Shape, Sphere, Sweep, project_swept,
};
use crate::model::{ClothModel, ClothState};

/// How a sphere acts on the cloth.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
pub enum SphereResponse {
    /// Impulse projection after the step (the lab's equation 4): vertices
    /// inside are moved to the surface and their velocity changed to match.
    #[default]
    Projection,
    /// A penalty force `c·d·n` inside the step (the assignment's), with its
    /// stiffness in the linear system of the implicit methods.
    Penalty {
        /// Penalty stiffness `c`.
        stiffness: f32,
    },
}

/// The spheres every cloth collides with this step, in world space,
/// gathered from [`SphereCollider`]s in [`ClothSystems::SyncIn`]. Penalty
/// spheres are read by the method step; projection spheres by
/// [`ClothSystems::Collide`]. Empty without [`SphereCollisionPlugin`].
#[derive(Resource, Clone, Debug, Default, PartialEq)]
pub struct ClothColliders {
    /// Spheres that project vertices out after the step.
    pub projection: Vec<Sphere>,
    /// Spheres that push with a penalty force during the step (radius
    /// without the cloth's particle radius).
    pub penalty: Vec<PenaltySphere>,
    /// Planes, capsules and boxes that project vertices out after the step,
    /// with friction (their thickness already in their size), gathered from
    /// [`PlaneCollider`]s, [`CapsuleCollider`]s and [`CuboidCollider`]s by
    /// [`ShapeCollisionPlugin`].
    pub shapes: Vec<Shape>,
    /// Planes, capsules and boxes with a [`ContactResponse::Penalty`]
    /// response: penalty forces inside the step, as [`PenaltySphere`]s with
    /// a [`PenaltySurface::Shape`](crate::collision::PenaltySurface::Shape).
    pub penalty_shapes: Vec<PenaltySphere>,
    /// The game's avian colliders whose shape is one of the crate's (balls,
    /// capsules, cuboids and half-spaces), gathered by
    /// `AvianCollisionPlugin` (cargo feature `avian`) with avian's friction:
    /// in the step like [`shapes`](Self::shapes) (inside `stiff`'s
    /// substeps, terms of `pd`'s and `newton`'s objectives), and projected
    /// after it with every other avian collider. Empty without that plugin.
    pub avian: Vec<Shape>,
    /// How fast the fastest collider of each kind moved over the last step
    /// (sphere colliders, the shape colliders, avian's; its translation
    /// since the step before over `dt`, 0 for one first seen): what the
    /// guard's speed bound allows the cloth beyond its own fall (see
    /// [`max_speed`](Self::max_speed)).
    pub speeds: [f32; 3],
    /// How far each of [`projection`](Self::projection)'s spheres moved
    /// over the last step (zero for one first seen), parallel to it: the
    /// projection sweeps the cloth relative to them, so a fast sphere
    /// cannot pass through ([`project_swept`]).
    pub projection_motion: Vec<Vec3A>,
    /// How far each of [`shapes`](Self::shapes) moved over the last step,
    /// parallel to it, as [`projection_motion`](Self::projection_motion).
    pub shape_motion: Vec<Vec3A>,
    /// How far each of [`avian`](Self::avian)'s colliders moved over the
    /// last step, parallel to it.
    pub avian_motion: Vec<Vec3A>,
}

impl ClothColliders {
    /// How fast the fastest collider moved over the last step
    /// ([`speeds`](Self::speeds)' largest); the step's
    /// [`StepParams::collider_speed`](crate::solver::StepParams::collider_speed).
    pub fn max_speed(&self) -> f32 {
        self.speeds.into_iter().fold(0.0, f32::max)
    }
}

/// Where each collider of one kind was at the last gather, to measure how
/// fast the colliders move ([`ClothColliders::speeds`]). Two maps swapped
/// each step, so it allocates only as colliders are added, and forgets a
/// despawned one.
#[derive(Default)]
pub(crate) struct ColliderMotion {
    last: bevy::ecs::entity::EntityHashMap<Vec3A>,
    now: bevy::ecs::entity::EntityHashMap<Vec3A>,
    fastest: f32,
}

impl ColliderMotion {
    /// Notes that `entity` is at `at` this step, `dt` after the last, and
    /// returns how far it moved since (zero for one first seen, or a
    /// non-finite move).
    pub(crate) fn saw(&mut self, entity: Entity, at: Vec3A, dt: f32) -> Vec3A {
        let mut moved = Vec3A::ZERO;
        if let Some(&was) = self.last.get(&entity) {
            let speed = (at - was).length() / dt;
            if speed.is_finite() {
                self.fastest = self.fastest.max(speed);
                moved = at - was;
            }
        }
        self.now.insert(entity, at);
        moved
    }

    /// The fastest speed noted since the last call; starts the next step.
    pub(crate) fn finish(&mut self) -> f32 {
        std::mem::swap(&mut self.last, &mut self.now);
        self.now.clear();
        std::mem::take(&mut self.fastest)
    }
}

/// How a plane, capsule or box acts on the cloth: the same two responses
/// as a sphere's.
pub type ContactResponse = SphereResponse;

/// A sphere that every cloth collides with. Its centre is the entity's
/// global translation (rotation and scale are ignored; the radius is the
/// component's). Move the entity to push the cloth. Contacts happen at the
/// radius plus the cloth's [`ClothParams::particle_radius`];
/// [`ClothStats::contacts`] counts its contacts (projections, or vertices
/// inside a penalty sphere).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug, PartialEq)]
#[require(Transform)]
pub struct SphereCollider {
    /// Radius (the lab: 2.7).
    pub radius: f32,
    /// How the sphere acts on the cloth.
    pub response: SphereResponse,
    /// Coulomb friction coefficient `μ ≥ 0` of the projection (the lab's
    /// sphere: 0, frictionless); see [`project_shapes`](crate::collision::project_shapes).
    pub friction: f32,
}

impl SphereCollider {
    /// A projecting sphere of this radius.
    pub const fn new(radius: f32) -> Self {
        Self {
            radius,
            response: SphereResponse::Projection,
            friction: 0.0,
        }
    }

    /// The same sphere with Coulomb friction `μ` (projection response).
    #[must_use]
    pub const fn with_friction(mut self, friction: f32) -> Self {
        self.friction = friction;
        self
    }

    /// A penalty sphere of this radius and stiffness.
    pub const fn penalty(radius: f32, stiffness: f32) -> Self {
        Self {
            radius,
            response: SphereResponse::Penalty { stiffness },
            friction: 0.0,
        }
    }
}

scheduled_plugin! {
    /// Adds sphere collision: every cloth against every [`SphereCollider`] —
    /// penalty spheres inside each method's step, projection spheres after it
    /// in [`ClothSystems::Collide`].
    SphereCollisionPlugin
}

impl Plugin for SphereCollisionPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.register_type::<SphereCollider>()
            .register_type::<SphereResponse>()
            .add_systems(
                ClothSchedule,
                (
                    gather_spheres.in_set(ClothSystems::SyncIn),
                    project_cloths
                        .in_set(ClothSystems::Collide)
                        .after(super::collide_cloths)
                        .run_if(any_with_component::<Cloth>),
                )
                    .run_if(spheres_present),
            );
    }
}

/// True while there are colliders, or spheres left from removed ones to clear.
fn spheres_present(
    colliders: Query<(), With<SphereCollider>>,
    spheres: Res<ClothColliders>,
) -> bool {
    !colliders.is_empty() || !spheres.projection.is_empty() || !spheres.penalty.is_empty()
}

/// Gathers the colliders' world spheres into [`ClothColliders`]. A sphere
/// with a negative or non-finite radius, stiffness or position is skipped
/// with a warning (once per entity).
fn gather_spheres(
    time: Res<Time>,
    helper: TransformHelper,
    colliders: Query<(Entity, &SphereCollider)>,
    mut spheres: ResMut<ClothColliders>,
    mut warned: Local<Vec<Entity>>,
    mut motion: Local<ColliderMotion>,
) {
    let dt = time.delta_secs();
    let spheres = spheres.bypass_change_detection();
    spheres.projection.clear();
    spheres.projection_motion.clear();
    spheres.penalty.clear();
    for (entity, collider) in &colliders {
        let Ok(global) = helper.compute_global_transform(entity) else {
            continue;
        };
        let center = global.translation_vec3a();
        let moved = motion.saw(entity, center, dt);
        let radius = collider.radius;
        let valid_radius = radius.is_finite()
            && radius >= 0.0
            && center.is_finite()
            && collider.friction.is_finite()
            && collider.friction >= 0.0;
        match collider.response {
            SphereResponse::Projection if valid_radius => {
                spheres.projection.push(Sphere {
                    center,
                    radius,
                    friction: collider.friction,
                });
                spheres.projection_motion.push(moved);
            }
            SphereResponse::Penalty { stiffness }
                if valid_radius && stiffness.is_finite() && stiffness >= 0.0 =>
            {
                spheres.penalty.push(PenaltySphere {
                    center,
                    radius,
                    stiffness,
                    surface: Default::default(),
                });
            }
            _ => {
                if !warned.contains(&entity) {
                    warn!(
                        "sphere collider {entity} skipped: radius {radius}, centre {center}, friction {} and {:?} must be finite and non-negative",
                        collider.friction, collider.response
                    );
                    warned.push(entity);
                }
            }
        }
    }
    spheres.speeds[0] = motion.finish();
}

/// Projects every running cloth out of every projection sphere.
fn project_cloths(
    time: Res<Time>,
    spheres: Res<ClothColliders>,
    cloths: Query<(&mut Cloth, &ClothParams, &mut ClothStats)>,
    mut solids: Local<Vec<Shape>>,
) {
    if !spheres.projection.is_empty() {
        solids.clear();
        solids.extend(sphere_solids(&spheres.projection));
        let solids = &*solids;
        project_running_cloths(&time, cloths, |model, state, from, thickness, dt| {
            let sweep = Sweep {
                motion: &spheres.projection_motion,
                start: from.start,
                share: from.share,
                edges: false,
            };
            project_swept(model, state, solids, sweep, thickness, dt)
        });
    }
}

/// Where [`project_running_cloths`] sweeps a cloth's vertices from: its
/// [`Sweep::start`] and [`Sweep::share`].
#[derive(Clone, Copy)]
pub(crate) struct SweepFrom<'a> {
    pub(crate) start: &'a [Vec3A],
    pub(crate) share: f32,
}

/// Runs `project` (model, state, the sweep's start and share of the step,
/// the cloth's particle radius, `dt`; returns the contacts) on every
/// running cloth, in parallel, and counts its contacts in the cloth's
/// stats. The sweep starts where the vertices were at the step's start, or
/// covers its method's last substep ([`Sweep::share`]).
pub(crate) fn project_running_cloths(
    time: &Time,
    mut cloths: Query<(&mut Cloth, &ClothParams, &mut ClothStats)>,
    project: impl Fn(&ClothModel, &mut ClothState, SweepFrom<'_>, f32, f32) -> usize + Sync,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    for_each_cloth!(cloths, |(mut cloth, params, mut stats)| {
        if !cloth.initialized || !stats.is_running() {
            return;
        }
        let cloth = &mut *cloth;
        // The guard checks the projected state again in `SyncOut`.
        cloth.measured = None;
        // The guard's copy of the state before the step.
        let start = &cloth.last_good.positions;
        let start = if start.len() == cloth.state.len() {
            &start[..]
        } else {
            &[]
        };
        let from = SweepFrom {
            start,
            share: cloth.last_substep.unwrap_or(1.0),
        };
        cloth.convergence.before_projection(&cloth.state.positions);
        let contacts = project(
            &cloth.model,
            &mut cloth.state,
            from,
            params.particle_radius,
            dt,
        );
        stats.contacts += contacts as u32;
    });
}

/// A half-space every cloth collides with: the ground, a floor, a slope. Its
/// surface passes through the entity's global translation with the normal
/// along the entity's local `+Y` (rotate the entity to tilt it); the solid
/// side is below. Projected after the step with Coulomb friction
/// ([`project_swept`](crate::collision::project_swept), which also sweeps
/// a moving collider so that a fast one does not pass through), for every
/// method; counted in [`ClothStats::contacts`]. `stiff` also projects it in
/// its substeps. Vertices are kept `thickness` plus the cloth's
/// [`ClothParams::particle_radius`] above the surface.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug, PartialEq, Default)]
#[require(Transform)]
pub struct PlaneCollider {
    /// Friction coefficient `μ ≥ 0`: a cloth rests on a slope of angle `θ`
    /// while `μ ≥ tan θ` (0: frictionless).
    pub friction: f32,
    /// Extra distance above the surface at which contact happens (`≥ 0`).
    pub thickness: f32,
    /// Projection after the step (with friction), or a penalty force inside
    /// it (friction unused).
    pub response: ContactResponse,
}

impl Default for PlaneCollider {
    /// `μ = 0.5`, no thickness.
    fn default() -> Self {
        Self::new(0.5)
    }
}

impl PlaneCollider {
    /// A plane with this friction coefficient and no thickness.
    pub const fn new(friction: f32) -> Self {
        Self {
            friction,
            thickness: 0.0,
            response: ContactResponse::Projection,
        }
    }

    /// A frictionless plane pushing with a penalty force of this stiffness
    /// inside the step.
    pub const fn penalty(stiffness: f32) -> Self {
        Self {
            friction: 0.0,
            thickness: 0.0,
            response: ContactResponse::Penalty { stiffness },
        }
    }
}

/// A capsule every cloth collides with (a character's limb): its axis runs
/// along the entity's local `Y` through its translation, `half_length` each
/// way (as Bevy's `Capsule3d`); rotation is followed, scale ignored.
/// Projected after the step with Coulomb friction, like [`PlaneCollider`].
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug, PartialEq)]
#[require(Transform)]
pub struct CapsuleCollider {
    /// Radius around the axis (`≥ 0`).
    pub radius: f32,
    /// Half the axis length (`≥ 0`; 0 is a sphere).
    pub half_length: f32,
    /// Friction coefficient `μ ≥ 0`.
    pub friction: f32,
    /// Extra contact distance (`≥ 0`).
    pub thickness: f32,
    /// Projection after the step, or a penalty force inside it.
    pub response: ContactResponse,
}

impl CapsuleCollider {
    /// A capsule of this radius and half length, `μ = 0.5`, no thickness.
    pub const fn new(radius: f32, half_length: f32) -> Self {
        Self {
            radius,
            half_length,
            friction: 0.5,
            thickness: 0.0,
            response: ContactResponse::Projection,
        }
    }

    /// The same capsule pushing with a penalty force inside the step.
    #[must_use]
    pub const fn with_penalty(mut self, stiffness: f32) -> Self {
        self.response = ContactResponse::Penalty { stiffness };
        self
    }
}

/// A box every cloth collides with (a crate, a table): centred on the
/// entity, oriented by its rotation (scale ignored), with these half
/// extents along its local axes. Projected after the step with Coulomb
/// friction, like [`PlaneCollider`].
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug, PartialEq)]
#[require(Transform)]
pub struct CuboidCollider {
    /// Half the side lengths along local `x`, `y`, `z` (each `≥ 0`).
    pub half_extents: Vec3,
    /// Friction coefficient `μ ≥ 0`.
    pub friction: f32,
    /// Extra contact distance (`≥ 0`).
    pub thickness: f32,
    /// Projection after the step, or a penalty force inside it.
    pub response: ContactResponse,
}

impl CuboidCollider {
    /// A box of these half extents, `μ = 0.5`, no thickness.
    pub const fn new(half_extents: Vec3) -> Self {
        Self {
            half_extents,
            friction: 0.5,
            thickness: 0.0,
            response: ContactResponse::Projection,
        }
    }

    /// The same box pushing with a penalty force inside the step.
    #[must_use]
    pub const fn with_penalty(mut self, stiffness: f32) -> Self {
        self.response = ContactResponse::Penalty { stiffness };
        self
    }
}

scheduled_plugin! {
    /// Adds plane, capsule and box collision: every cloth against every
    /// [`PlaneCollider`], [`CapsuleCollider`] and [`CuboidCollider`], in
    /// [`ClothSystems::Collide`] (after the projection spheres).
    ShapeCollisionPlugin
}

impl Plugin for ShapeCollisionPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.register_type::<PlaneCollider>()
            .register_type::<CapsuleCollider>()
            .register_type::<CuboidCollider>()
            .add_systems(
                ClothSchedule,
                (
                    // After the spheres' gathering: both write ClothColliders.
                    gather_shapes
                        .in_set(ClothSystems::SyncIn)
                        .after(gather_spheres),
                    project_cloths_on_shapes
                        .in_set(ClothSystems::Collide)
                        .after(project_cloths)
                        .after(super::collide_cloths)
                        .run_if(any_with_component::<Cloth>),
                )
                    .run_if(shapes_present),
            );
    }
}

type AnyShape = Or<(
    With<PlaneCollider>,
    With<CapsuleCollider>,
    With<CuboidCollider>,
)>;

/// An entity's shape colliders (any of them).
type ShapeColliders = (
    Entity,
    Option<&'static PlaneCollider>,
    Option<&'static CapsuleCollider>,
    Option<&'static CuboidCollider>,
);

/// True while there are shape colliders, or shapes left from removed ones.
fn shapes_present(colliders: Query<(), AnyShape>, gathered: Res<ClothColliders>) -> bool {
    !colliders.is_empty() || !gathered.shapes.is_empty() || !gathered.penalty_shapes.is_empty()
}

/// Whether every value is finite and non-negative.
fn non_negative(values: &[f32]) -> bool {
    values.iter().all(|v| v.is_finite() && *v >= 0.0)
}

/// Gathers the shape colliders into [`ClothColliders::shapes`]. A collider
/// with a negative or non-finite size, friction or thickness, or a
/// non-finite transform, is skipped with a warning (once per entity).
pub(crate) fn gather_shapes(
    time: Res<Time>,
    helper: TransformHelper,
    colliders: Query<ShapeColliders, AnyShape>,
    mut gathered: ResMut<ClothColliders>,
    mut warned: Local<Vec<Entity>>,
    mut motion: Local<ColliderMotion>,
) {
    let dt = time.delta_secs();
    let ClothColliders {
        shapes,
        shape_motion,
        penalty_shapes,
        speeds,
        ..
    } = gathered.bypass_change_detection();
    shapes.clear();
    shape_motion.clear();
    penalty_shapes.clear();
    for (entity, plane, capsule, cuboid) in &colliders {
        let Ok(global) = helper.compute_global_transform(entity) else {
            continue;
        };
        let (_, rotation, translation) = global.to_scale_rotation_translation();
        let center = Vec3A::from(translation);
        let moved = motion.saw(entity, center, dt);
        let axes =
            [Vec3::X, Vec3::Y, Vec3::Z].map(|a| Vec3A::from(rotation * a).normalize_or_zero());
        let placed = center.is_finite() && axes.iter().all(|a| *a != Vec3A::ZERO);
        let mut push =
            |shape: Option<Shape>, response: ContactResponse, what: &str, values: &[f32]| {
                let stiffness = match response {
                    ContactResponse::Projection => None,
                    ContactResponse::Penalty { stiffness } => Some(stiffness),
                };
                let valid = non_negative(stiffness.as_slice());
                match (shape, stiffness) {
                    (Some(shape), None) if placed && non_negative(values) => {
                        shapes.push(shape);
                        shape_motion.push(moved);
                    }
                    (Some(shape), Some(c)) if placed && valid && non_negative(values) => {
                        penalty_shapes.push(PenaltySphere::shape(shape, c));
                    }
                    _ if !warned.contains(&entity) => {
                        warn!(
                            "{what} collider {entity} skipped: sizes, friction, thickness \
                         {values:?} and {response:?} must be finite and non-negative, and its \
                         transform finite"
                        );
                        warned.push(entity);
                    }
                    _ => {}
                }
            };
        if let Some(p) = plane {
            push(
                Some(Shape::Plane(Plane {
                    point: center + p.thickness * axes[1],
                    normal: axes[1],
                    friction: p.friction,
                })),
                p.response,
                "plane",
                &[p.friction, p.thickness],
            );
        }
        if let Some(c) = capsule {
            push(
                Some(Shape::Capsule(Capsule {
                    a: center - c.half_length * axes[1],
                    b: center + c.half_length * axes[1],
                    radius: c.radius + c.thickness,
                    friction: c.friction,
                })),
                c.response,
                "capsule",
                &[c.radius, c.half_length, c.friction, c.thickness],
            );
        }
        if let Some(b) = cuboid {
            push(
                Some(Shape::Cuboid(Cuboid {
                    center,
                    axes,
                    half_extents: Vec3A::from(b.half_extents) + Vec3A::splat(b.thickness),
                    friction: b.friction,
                })),
                b.response,
                "box",
                &[
                    b.half_extents.x,
                    b.half_extents.y,
                    b.half_extents.z,
                    b.friction,
                    b.thickness,
                ],
            );
        }
    }
    speeds[1] = motion.finish();
}

/// Projects every running cloth out of every shape.
pub(crate) fn project_cloths_on_shapes(
    time: Res<Time>,
    colliders: Res<ClothColliders>,
    cloths: Query<(&mut Cloth, &ClothParams, &mut ClothStats)>,
) {
    if !colliders.shapes.is_empty() {
        project_running_cloths(&time, cloths, |model, state, from, thickness, dt| {
            let sweep = Sweep {
                motion: &colliders.shape_motion,
                start: from.start,
                share: from.share,
                // The edges are pushed inside `stiff`'s substeps, not here:
                // after the step, a push on a taut edge over a box's edge
                // fights the springs every step.
                edges: false,
            };
            project_swept(model, state, &colliders.shapes, sweep, thickness, dt)
        });
    }
}
