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
//! Balls, capsules, cuboids and half-spaces (avian's primitives that are
//! also the crate's shapes) are gathered before the step into
//! [`ClothColliders::avian`](crate::ClothColliders::avian), so they act
//! inside it as the crate's own colliders do: projected in `stiff`'s
//! substeps and terms of `pd`'s and `newton`'s objectives, where stiff
//! cloth keeps its length over them instead of being strained by the
//! projection after the step (in `stiff`'s substeps boxes push the cloth's
//! edges too, not only its vertices). After the step they are projected as
//! the crate's shapes are
//! ([`collision::project_swept`](crate::collision::project_swept)): swept by
//! their motion, so a fast one does not pass through the cloth; the
//! closest-point query serves every other shape.
//!
//! **One-way**: the cloth does not push rigid bodies (they are projected
//! against, not given impulses). A collider's pose is its entity's global
//! transform, computed from the `Transform` hierarchy; its scale is avian's
//! (`Collider::shape_scaled`).

use crate::ecs::scheduled_plugin;
use avian3d::prelude::{Collider, Friction, Sensor};
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use crate::collision::{Capsule, Cuboid, Plane, Shape, Sweep, project_contacts, project_swept};
use crate::ecs::{
    ClothCorePlugin, ClothSchedule, ClothSystems, ColliderMotion, gather_shapes,
    project_after_shapes,
};
use crate::{Cloth, ClothColliders, ClothParams};

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
            (
                // After the shape colliders' gathering: both write
                // ClothColliders.
                gather_avian
                    .in_set(ClothSystems::SyncIn)
                    .after(gather_shapes)
                    .run_if(
                        any_with_component::<Collider>
                            .or_else(|c: Res<ClothColliders>| !c.avian.is_empty()),
                    ),
                project_on_avian
                    .in_set(ClothSystems::Collide)
                    .after(project_after_shapes)
                    .after(crate::ecs::collide_cloths)
                    .run_if(any_with_component::<Collider>.and_then(any_with_component::<Cloth>)),
            ),
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

/// Gathers the avian colliders whose shape is one of the crate's into
/// [`ClothColliders::avian`] (see the [module](self) docs); the others, and
/// any with a non-finite pose or a negative friction, are left to
/// [`project_on_avian`] (which warns of the latter).
fn gather_avian(
    time: Res<Time>,
    helper: TransformHelper,
    colliders: Query<(Entity, &Collider, Option<&Friction>), Without<Sensor>>,
    mut gathered: ResMut<ClothColliders>,
    mut motion: Local<ColliderMotion>,
) {
    let dt = time.delta_secs();
    let gathered = gathered.bypass_change_detection();
    gathered.avian.clear();
    gathered.avian_motion.clear();
    for (entity, collider, friction) in &colliders {
        let Some(Ok((translation, rotation, friction))) = placement(&helper, entity, friction)
        else {
            continue;
        };
        // Every avian collider's motion, the ones projected after the step
        // too.
        let moved = motion.saw(entity, Vec3A::from(translation), dt);
        if let Some(shape) = primitive(collider, translation, rotation, friction) {
            gathered.avian.push(shape);
            gathered.avian_motion.push(moved);
        }
    }
    gathered.speeds[2] = motion.finish();
}

/// An avian collider as one of the crate's shapes, placed at
/// `translation`, `rotation`: a ball, capsule, cuboid or half-space with
/// finite, non-negative sizes; `None` for any other shape.
fn primitive(
    collider: &Collider,
    translation: Vec3,
    rotation: Quat,
    friction: f32,
) -> Option<Shape> {
    // parry's vectors are its own glam's: copied through arrays.
    let world = |v: [f32; 3]| Vec3A::from(translation + rotation * Vec3::from_array(v));
    let direction = |v: [f32; 3]| Vec3A::from(rotation * Vec3::from_array(v)).normalize_or_zero();
    let shape = collider.shape_scaled();
    let center = Vec3A::from(translation);
    let placed = if let Some(ball) = shape.as_ball() {
        Shape::Capsule(Capsule {
            a: center,
            b: center,
            radius: ball.radius,
            friction,
        })
    } else if let Some(capsule) = shape.as_capsule() {
        Shape::Capsule(Capsule {
            a: world(capsule.segment.a.to_array()),
            b: world(capsule.segment.b.to_array()),
            radius: capsule.radius,
            friction,
        })
    } else if let Some(cuboid) = shape.as_cuboid() {
        Shape::Cuboid(Cuboid {
            center,
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(direction),
            half_extents: Vec3A::from_array(cuboid.half_extents.to_array()),
            friction,
        })
    } else if let Some(half_space) = shape.as_halfspace() {
        Shape::Plane(Plane {
            point: center,
            normal: direction(half_space.normal.to_array()),
            friction,
        })
    } else {
        return None;
    };
    let finite = match placed {
        Shape::Capsule(c) => {
            c.a.is_finite() && c.b.is_finite() && c.radius.is_finite() && c.radius >= 0.0
        }
        Shape::Cuboid(b) => {
            b.half_extents.is_finite()
                && b.half_extents.min_element() >= 0.0
                && b.axes.iter().all(|a| *a != Vec3A::ZERO)
        }
        Shape::Plane(p) => p.point.is_finite() && p.normal != Vec3A::ZERO,
    };
    finite.then_some(placed)
}

/// An avian collider's world translation, rotation and friction (its
/// dynamic coefficient, avian's default without a [`Friction`]): `None`
/// without a global transform, `Err(friction)` if the pose is not finite or
/// the friction is negative.
fn placement(
    helper: &TransformHelper,
    entity: Entity,
    friction: Option<&Friction>,
) -> Option<Result<(Vec3, Quat, f32), f32>> {
    let global = helper.compute_global_transform(entity).ok()?;
    let (_, rotation, translation) = global.to_scale_rotation_translation();
    let friction = friction.copied().unwrap_or_default().dynamic_coefficient;
    Some(
        if translation.is_finite() && rotation.is_finite() && friction >= 0.0 {
            Ok((translation, rotation, friction))
        } else {
            Err(friction)
        },
    )
}

/// Projects every running cloth out of every avian collider: the ones
/// that are the crate's shapes ([`ClothColliders::avian`]) swept
/// ([`project_swept`]), the others by avian's closest-point query.
fn project_on_avian(
    time: Res<Time>,
    helper: TransformHelper,
    colliders: Query<(Entity, &Collider, Option<&Friction>), Without<Sensor>>,
    gathered: Res<ClothColliders>,
    mut cloths: Query<(&mut Cloth, &ClothParams, &mut crate::ClothStats)>,
    mut placed: Local<Vec<Placed>>,
    mut warned: Local<Vec<Entity>>,
) {
    placed.clear();
    for (entity, collider, friction) in &colliders {
        let (translation, rotation, friction) = match placement(&helper, entity, friction) {
            None => continue,
            Some(Ok(placed)) => placed,
            Some(Err(friction)) => {
                if !warned.contains(&entity) {
                    warn!(
                        "avian collider {entity} skipped by the cloths: its transform must be finite \
                     and its friction ≥ 0 (got {friction})"
                    );
                    warned.push(entity);
                }
                continue;
            }
        };
        if primitive(collider, translation, rotation, friction).is_some() {
            continue;
        }
        placed.push(Placed {
            collider: collider.clone(),
            translation,
            rotation,
            friction,
        });
    }
    if !gathered.avian.is_empty() {
        crate::ecs::project_running_cloths(
            &time,
            cloths.reborrow(),
            |model, state, from, thickness, dt| {
                let sweep = Sweep {
                    motion: &gathered.avian_motion,
                    start: from.start,
                    share: from.share,
                    edges: false,
                };
                project_swept(model, state, &gathered.avian, sweep, thickness, dt)
            },
        );
    }
    if placed.is_empty() {
        return;
    }
    let placed = &*placed;
    crate::ecs::project_running_cloths(&time, cloths, |model, state, _, thickness, dt| {
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

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::FRAC_PI_2;

    #[test]
    fn avian_primitives_become_the_crates_shapes_where_they_are() {
        let (at, turn) = (Vec3::new(1.0, 2.0, 3.0), Quat::from_rotation_z(FRAC_PI_2));
        let shape = |c: Collider| primitive(&c, at, turn, 0.3);
        let Some(Shape::Capsule(ball)) = shape(Collider::sphere(0.5)) else {
            panic!("a ball is a capsule of no length")
        };
        assert_eq!(
            (ball.a, ball.b, ball.radius),
            (Vec3A::from(at), Vec3A::from(at), 0.5)
        );
        // avian's capsule stands along its local y, here turned onto −x.
        let Some(Shape::Capsule(c)) = shape(Collider::capsule(0.25, 2.0)) else {
            panic!("a capsule")
        };
        let ends = [c.a, c.b].map(|e| e - Vec3A::from(at));
        assert!(ends[0].abs_diff_eq(Vec3A::X, 1e-6) || ends[0].abs_diff_eq(-Vec3A::X, 1e-6));
        assert!(ends[1].abs_diff_eq(-ends[0], 1e-6));
        assert_eq!((c.radius, c.friction), (0.25, 0.3));
        let Some(Shape::Cuboid(b)) = shape(Collider::cuboid(2.0, 4.0, 6.0)) else {
            panic!("a box")
        };
        assert_eq!(b.half_extents, Vec3A::new(1.0, 2.0, 3.0));
        assert!(b.axes[1].abs_diff_eq(-Vec3A::X, 1e-6), "{:?}", b.axes);
        let Some(Shape::Plane(p)) = shape(Collider::half_space(Vec3::Y)) else {
            panic!("a plane")
        };
        assert!(p.normal.abs_diff_eq(-Vec3A::X, 1e-6) && p.point == Vec3A::from(at));
        // Shapes the crate has not: left to the projection after the step.
        assert!(shape(Collider::cylinder(1.0, 2.0)).is_none());
    }
}
