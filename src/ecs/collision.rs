//! Sphere and plane colliders as components and plugins.

use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use super::{Cloth, ClothCorePlugin, ClothParams, ClothStats, ClothSystems};
use crate::collision::{PenaltySphere, Plane, Sphere, project_planes, project_spheres};

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
    /// Planes that project vertices out after the step, with friction
    /// (their thickness already in `point`), gathered from
    /// [`PlaneCollider`]s by [`PlaneCollisionPlugin`].
    pub planes: Vec<Plane>,
}

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
}

impl SphereCollider {
    /// A projecting sphere of this radius.
    pub const fn new(radius: f32) -> Self {
        Self {
            radius,
            response: SphereResponse::Projection,
        }
    }

    /// A penalty sphere of this radius and stiffness.
    pub const fn penalty(radius: f32, stiffness: f32) -> Self {
        Self {
            radius,
            response: SphereResponse::Penalty { stiffness },
        }
    }
}

/// Adds sphere collision: every cloth against every [`SphereCollider`] —
/// penalty spheres inside each method's step, projection spheres after it
/// in [`ClothSystems::Collide`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SphereCollisionPlugin {
    schedule: Interned<dyn ScheduleLabel>,
}

impl SphereCollisionPlugin {
    /// Runs in `schedule`.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for SphereCollisionPlugin {
    /// `FixedUpdate`.
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl Plugin for SphereCollisionPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.register_type::<SphereCollider>()
            .register_type::<SphereResponse>()
            .add_systems(
                self.schedule,
                (
                    gather_spheres.in_set(ClothSystems::SyncIn),
                    project_cloths
                        .in_set(ClothSystems::Collide)
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
    helper: TransformHelper,
    colliders: Query<(Entity, &SphereCollider)>,
    mut spheres: ResMut<ClothColliders>,
    mut warned: Local<Vec<Entity>>,
) {
    let spheres = spheres.bypass_change_detection();
    spheres.projection.clear();
    spheres.penalty.clear();
    for (entity, collider) in &colliders {
        let Ok(global) = helper.compute_global_transform(entity) else {
            continue;
        };
        let center = global.translation_vec3a();
        let radius = collider.radius;
        let valid_radius = radius.is_finite() && radius >= 0.0 && center.is_finite();
        match collider.response {
            SphereResponse::Projection if valid_radius => {
                spheres.projection.push(Sphere { center, radius });
            }
            SphereResponse::Penalty { stiffness }
                if valid_radius && stiffness.is_finite() && stiffness >= 0.0 =>
            {
                spheres.penalty.push(PenaltySphere {
                    center,
                    radius,
                    stiffness,
                });
            }
            _ => {
                if !warned.contains(&entity) {
                    warn!(
                        "sphere collider {entity} skipped: radius {radius}, centre {center} and {:?} must be finite and non-negative",
                        collider.response
                    );
                    warned.push(entity);
                }
            }
        }
    }
}

/// Projects every running cloth out of every projection sphere.
fn project_cloths(
    time: Res<Time>,
    spheres: Res<ClothColliders>,
    mut cloths: Query<(&mut Cloth, &ClothParams, &mut ClothStats)>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 || spheres.projection.is_empty() {
        return;
    }
    cloths
        .par_iter_mut()
        .for_each(|(mut cloth, params, mut stats)| {
            if !cloth.initialized || !stats.is_running() {
                return;
            }
            let cloth = &mut *cloth;
            let contacts = project_spheres(
                &cloth.model,
                &mut cloth.state,
                &spheres.projection,
                params.particle_radius,
                dt,
            );
            stats.contacts += contacts as u32;
        });
}

/// A half-space every cloth collides with: the ground, a floor, a slope. Its
/// surface passes through the entity's global translation with the normal
/// along the entity's local `+Y` (rotate the entity to tilt it); the solid
/// side is below. Vertices are kept [`thickness`](Self::thickness) plus the
/// cloth's [`ClothParams::particle_radius`] above the surface, projected
/// after the step like projection spheres, with Coulomb friction
/// ([`project_planes`]). Works with every method. Counted in
/// [`ClothStats::contacts`].
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug, PartialEq, Default)]
#[require(Transform)]
pub struct PlaneCollider {
    /// Friction coefficient `μ ≥ 0`: a cloth rests on a slope of angle `θ`
    /// while `μ ≥ tan θ` (0: frictionless).
    pub friction: f32,
    /// Extra distance above the surface at which contact happens (`≥ 0`).
    pub thickness: f32,
}

impl Default for PlaneCollider {
    /// `μ = 0.5`, no thickness.
    fn default() -> Self {
        Self {
            friction: 0.5,
            thickness: 0.0,
        }
    }
}

impl PlaneCollider {
    /// A plane with this friction coefficient and no thickness.
    pub const fn new(friction: f32) -> Self {
        Self {
            friction,
            thickness: 0.0,
        }
    }
}

/// Adds plane collision: every cloth against every [`PlaneCollider`], in
/// [`ClothSystems::Collide`] (after the projection spheres).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct PlaneCollisionPlugin {
    schedule: Interned<dyn ScheduleLabel>,
}

impl PlaneCollisionPlugin {
    /// Runs in `schedule`.
    pub fn new(schedule: impl ScheduleLabel) -> Self {
        Self {
            schedule: schedule.intern(),
        }
    }
}

impl Default for PlaneCollisionPlugin {
    /// `FixedUpdate`.
    fn default() -> Self {
        Self::new(FixedUpdate)
    }
}

impl Plugin for PlaneCollisionPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.register_type::<PlaneCollider>().add_systems(
            self.schedule,
            (
                gather_planes.in_set(ClothSystems::SyncIn),
                project_cloths_on_planes
                    .in_set(ClothSystems::Collide)
                    .after(project_cloths)
                    .run_if(any_with_component::<Cloth>),
            )
                .run_if(planes_present),
        );
    }
}

/// True while there are plane colliders, or planes left from removed ones.
fn planes_present(colliders: Query<(), With<PlaneCollider>>, spheres: Res<ClothColliders>) -> bool {
    !colliders.is_empty() || !spheres.planes.is_empty()
}

/// Gathers the plane colliders into [`ClothColliders::planes`]. A plane with
/// a negative or non-finite friction or thickness, or a non-finite
/// transform, is skipped with a warning (once per entity).
fn gather_planes(
    helper: TransformHelper,
    colliders: Query<(Entity, &PlaneCollider)>,
    mut spheres: ResMut<ClothColliders>,
    mut warned: Local<Vec<Entity>>,
) {
    let planes = &mut spheres.bypass_change_detection().planes;
    planes.clear();
    for (entity, collider) in &colliders {
        let Ok(global) = helper.compute_global_transform(entity) else {
            continue;
        };
        let (_, rotation, translation) = global.to_scale_rotation_translation();
        let normal = Vec3A::from(rotation * Vec3::Y).normalize_or_zero();
        let point = Vec3A::from(translation) + collider.thickness * normal;
        let PlaneCollider {
            friction,
            thickness,
        } = *collider;
        let valid = friction.is_finite()
            && friction >= 0.0
            && thickness.is_finite()
            && thickness >= 0.0
            && point.is_finite()
            && normal != Vec3A::ZERO;
        if valid {
            planes.push(Plane {
                point,
                normal,
                friction,
            });
        } else if !warned.contains(&entity) {
            warn!(
                "plane collider {entity} skipped: friction {friction} and thickness {thickness} must be finite and non-negative, and its transform finite"
            );
            warned.push(entity);
        }
    }
}

/// Projects every running cloth out of every plane.
fn project_cloths_on_planes(
    time: Res<Time>,
    colliders: Res<ClothColliders>,
    mut cloths: Query<(&mut Cloth, &ClothParams, &mut ClothStats)>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 || colliders.planes.is_empty() {
        return;
    }
    cloths
        .par_iter_mut()
        .for_each(|(mut cloth, params, mut stats)| {
            if !cloth.initialized || !stats.is_running() {
                return;
            }
            let cloth = &mut *cloth;
            let contacts = project_planes(
                &cloth.model,
                &mut cloth.state,
                &colliders.planes,
                params.particle_radius,
                dt,
            );
            stats.contacts += contacts as u32;
        });
}
