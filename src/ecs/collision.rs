//! Sphere colliders as a component and a plugin.

use bevy::ecs::intern::Interned;
use bevy::ecs::schedule::ScheduleLabel;
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use super::{Cloth, ClothCorePlugin, ClothStats, ClothSystems};
use crate::collision::{Sphere, project_spheres};

/// How a sphere acts on the cloth.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
pub enum SphereResponse {
    /// Impulse projection after the step (the lab's equation 4): vertices
    /// inside are moved to the surface and their velocity changed to match.
    #[default]
    Projection,
}

/// A sphere that every cloth collides with. Its centre is the entity's
/// global translation (rotation and scale are ignored; the radius is the
/// component's). Move the entity to push the cloth.
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
}

/// Adds sphere collision: after each step, every cloth is resolved against
/// every [`SphereCollider`] in [`ClothSystems::Collide`].
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
                collide_spheres.in_set(ClothSystems::Collide).run_if(
                    any_with_component::<SphereCollider>.and_then(any_with_component::<Cloth>),
                ),
            );
    }
}

/// Resolves every running cloth against every valid sphere. A sphere with a
/// negative or non-finite radius or position is skipped with a warning.
fn collide_spheres(
    time: Res<Time>,
    helper: TransformHelper,
    colliders: Query<(Entity, &SphereCollider)>,
    mut cloths: Query<(&mut Cloth, &mut ClothStats)>,
    mut spheres: Local<Vec<Sphere>>,
    mut warned: Local<Vec<Entity>>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    spheres.clear();
    for (entity, collider) in &colliders {
        let Ok(global) = helper.compute_global_transform(entity) else {
            continue;
        };
        let center = global.translation_vec3a();
        if collider.radius.is_finite() && collider.radius >= 0.0 && center.is_finite() {
            spheres.push(Sphere {
                center,
                radius: collider.radius,
            });
        } else if !warned.contains(&entity) {
            warn!(
                "sphere collider {entity} skipped: radius {} and centre {center} must be finite (radius non-negative)",
                collider.radius
            );
            warned.push(entity);
        }
    }
    cloths.par_iter_mut().for_each(|(mut cloth, mut stats)| {
        if !cloth.initialized || !stats.is_running() {
            return;
        }
        let cloth = &mut *cloth;
        let contacts = project_spheres(&cloth.model, &mut cloth.state, &spheres, dt);
        stats.contacts = contacts as u32;
    });
}
