//! Sphere colliders as a component and a plugin.

use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use super::{Cloth, ClothCorePlugin, ClothParams, ClothStats, ClothSystems};
use crate::collision::{PenaltySphere, Sphere, project_spheres};

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
