//! The game's avian3d colliders (cargo feature `avian`): cloths collide
//! with every avian [`Collider`] already in the scene, with no extra
//! component.
//!
//! Each fixed step, after the cloth's own colliders
//! ([`ClothSystems::Collide`]), every free vertex within the cloth's
//! [`ClothParams::particle_radius`] of an avian collider's surface (or
//! inside it) is projected out along the collider's closest-point query
//! (`Collider::project_point`: spheres, capsules, cuboids, half-spaces,
//! cylinders, convex hulls, triangle meshes, compounds: whatever avian can
//! query), with Coulomb friction from the collider's avian
//! [`Friction`] (its dynamic coefficient; avian's default 0.5 without one),
//! as [`collision::project_contacts`](crate::collision::project_contacts)
//! describes. Colliders marked [`Sensor`] are skipped.
//!
//! **One-way**: the cloth does not push rigid bodies (they are projected
//! against, not given impulses). A collider's pose is its entity's global
//! transform, computed from the `Transform` hierarchy; its scale is avian's
//! (`Collider::shape_scaled`).

use crate::ecs::scheduled_plugin;
use avian3d::prelude::{Collider, Friction, Sensor};
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use crate::collision::project_contacts;
use crate::ecs::{ClothCorePlugin, ClothSchedule, ClothSystems, project_after_shapes};
use crate::{Cloth, ClothParams};

scheduled_plugin! {
    /// Cloths against every avian [`Collider`] (see the [module](self) docs).
    /// Part of [`ClothPlugins`](crate::ClothPlugins) when the `avian` feature
    /// is on. Needs no avian plugin to read colliders; add avian's
    /// `PhysicsPlugins` for them to move.
    AvianCollisionPlugin
}

impl Plugin for AvianCollisionPlugin {
    fn build(&self, app: &mut App) {
        ClothCorePlugin::new_interned(self.schedule).add_once(app);
        app.add_systems(
            ClothSchedule,
            project_on_avian
                .in_set(ClothSystems::Collide)
                .after(project_after_shapes)
                .run_if(any_with_component::<Collider>.and_then(any_with_component::<Cloth>)),
        );
    }
}

/// An avian collider placed in the world.
struct Placed {
    collider: Collider,
    translation: Vec3,
    rotation: Quat,
    friction: f32,
}

/// Projects every running cloth out of every avian collider.
fn project_on_avian(
    time: Res<Time>,
    helper: TransformHelper,
    colliders: Query<(Entity, &Collider, Option<&Friction>), Without<Sensor>>,
    cloths: Query<(&mut Cloth, &ClothParams, &mut crate::ClothStats)>,
    mut placed: Local<Vec<Placed>>,
    mut warned: Local<Vec<Entity>>,
) {
    placed.clear();
    for (entity, collider, friction) in &colliders {
        let Ok(global) = helper.compute_global_transform(entity) else {
            continue;
        };
        let (_, rotation, translation) = global.to_scale_rotation_translation();
        let friction = friction.copied().unwrap_or_default().dynamic_coefficient;
        if !(translation.is_finite() && rotation.is_finite() && friction >= 0.0) {
            if !warned.contains(&entity) {
                warn!(
                    "avian collider {entity} skipped by the cloths: its transform must be finite \
                     and its friction ≥ 0 (got {friction})"
                );
                warned.push(entity);
            }
            continue;
        }
        placed.push(Placed {
            collider: collider.clone(),
            translation,
            rotation,
            friction,
        });
    }
    if placed.is_empty() {
        return;
    }
    let placed = &*placed;
    crate::ecs::project_running_cloths(&time, cloths, |model, state, thickness, dt| {
        project_contacts(model, state, placed, dt, |c, x| {
            let (surface, inside) =
                c.collider
                    .project_point(c.translation, c.rotation, Vec3::from(x), false);
            let d = x - Vec3A::from(surface);
            let distance = d.length();
            if distance == 0.0 || !distance.is_finite() {
                return None;
            }
            if inside {
                Some((-d / distance, distance + thickness, c.friction))
            } else if distance < thickness {
                Some((d / distance, thickness - distance, c.friction))
            } else {
                None
            }
        })
    });
}
