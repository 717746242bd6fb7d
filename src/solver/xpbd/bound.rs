//! The projection of a vertex out of the step's solids, in every substep,
//! and the quick `f32` test in front of each solid's exact (`f64`) one.
//!
//! A character's body is always near its garments, so the sphere around a
//! long capsule (a torso, a thigh) holds most of a cape: with the sphere
//! alone as the quick test, the exact test ran for most vertices against
//! most of the body's capsules in every substep, and was the largest part
//! of the cape's step (see `docs/measurements.md`). A capsule's quick test
//! is therefore its own distance to the axis, in `f32`, against the radius
//! grown by a margin larger than that distance's rounding: a vertex it
//! turns away is outside the capsule, where the exact test finds nothing,
//! so the projection is the same bit for bit.

use bevy::math::Vec3A;

use crate::collision::Shape;

/// A solid's quick test (see the module docs).
#[derive(Clone, Copy, Debug)]
pub(super) enum Bound {
    /// None: the exact test always runs (a plane).
    Always,
    /// A point must be inside this sphere (centre, squared radius) to touch
    /// the solid (a box).
    Sphere(Vec3A, f32),
    /// A capsule: the sphere around it, then its axis (from `a`, `axis`
    /// long, `inv` = 1/|axis|², 0 for a sphere) and the squared radius with
    /// the margin.
    Capsule {
        /// The sphere around the capsule (centre, squared radius).
        sphere: (Vec3A, f32),
        /// The axis' first end.
        a: Vec3A,
        /// The axis, `b − a`.
        axis: Vec3A,
        /// `1/|axis|²`, or 0 for a capsule of no length.
        inv: f32,
        /// The radius with the margin, squared.
        reach2: f32,
    },
}

impl Bound {
    /// The quick test of `shape`.
    pub(super) fn of(shape: &Shape) -> Self {
        match *shape {
            Shape::Plane(_) => Self::Always,
            Shape::Capsule(c) => {
                let r = 0.5 * c.a.distance(c.b) + c.radius;
                let axis = c.b - c.a;
                let len_sq = axis.length_squared();
                // The distance's rounding in `f32` is a few units in the
                // last place of the coordinates near the capsule (at most
                // the ends' plus the radius): sixteen of them, and a
                // ten-thousandth of the radius.
                let scale = c.a.abs().max_element().max(c.b.abs().max_element()) + c.radius;
                let reach = c.radius * 1.0001 + 16.0 * f32::EPSILON * scale;
                Self::Capsule {
                    sphere: (0.5 * (c.a + c.b), r * r * 1.0001),
                    a: c.a,
                    axis,
                    inv: if len_sq > 0.0 { len_sq.recip() } else { 0.0 },
                    reach2: reach * reach,
                }
            }
            Shape::Cuboid(b) => Self::Sphere(b.center, b.half_extents.length_squared() * 1.0001),
        }
    }

    /// The sphere around the solid, if it has one.
    pub(super) fn sphere(&self) -> Option<(Vec3A, f32)> {
        match *self {
            Self::Always => None,
            Self::Sphere(centre, r2)
            | Self::Capsule {
                sphere: (centre, r2),
                ..
            } => Some((centre, r2)),
        }
    }

    /// Whether `x` is surely outside the solid (a NaN is not).
    #[inline]
    fn outside(&self, x: Vec3A) -> bool {
        match *self {
            Self::Always => false,
            Self::Sphere(centre, r2) => x.distance_squared(centre) > r2,
            Self::Capsule {
                sphere: (centre, r2),
                a,
                axis,
                inv,
                reach2,
            } => {
                if x.distance_squared(centre) > r2 {
                    return true;
                }
                let d = x - a;
                let t = (d.dot(axis) * inv).clamp(0.0, 1.0);
                (d - t * axis).length_squared() > reach2
            }
        }
    }
}

/// The solids a substep projects the cloth out of: the shapes where they
/// are, their [`Bound`]s, and each one's motion over the substep.
pub(super) type Solids<'a> = (&'a [Shape], &'a [Bound], &'a [Vec3A]);

/// Moves `x` out of every solid it is inside, with position-based Coulomb
/// friction on its motion since `prev` (the substep's start) relative to
/// the solid's, and says whether it was inside one.
pub(super) fn project(x: &mut Vec3A, prev: Vec3A, (shapes, bounds, shifts): Solids<'_>) -> bool {
    let mut touched = false;
    for ((shape, bound), &shift) in shapes.iter().zip(bounds).zip(shifts) {
        if bound.outside(*x) {
            continue;
        }
        let Some((normal, depth)) = shape.contact(*x, 0.0) else {
            continue;
        };
        touched = true;
        *x += depth * normal;
        let mu = shape.friction();
        if mu > 0.0 {
            let moved = *x - prev - shift;
            let tangential = moved - moved.dot(normal) * normal;
            let length = tangential.length();
            if length > 0.0 {
                *x -= tangential * ((mu * depth).min(length) / length);
            }
        }
    }
    touched
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::Capsule;

    /// Every point the quick test turns away is one the exact test finds
    /// outside, on capsules near the origin and 100 m and 10 km away, long
    /// and of no length, at points on a fine shell just outside and inside
    /// the surface (where rounding decides) and further out.
    #[test]
    fn a_capsule_s_quick_test_turns_away_only_points_outside() {
        // Points further from the axis than twice the radius, within 100 m
        // of the origin (at 10 km an `f32` has a millimetre's steps; near
        // the surface the margin decides).
        let (mut far, mut far_turned_away) = (0, 0);
        for offset in [
            Vec3A::ZERO,
            Vec3A::new(100.0, 0.3, -7.0),
            Vec3A::splat(1.0e4),
        ] {
            for (half, radius) in [(0.3, 0.12), (0.0, 0.5), (2.0, 0.01)] {
                let capsule = Capsule {
                    a: offset + Vec3A::new(0.1, -half, 0.2),
                    b: offset + Vec3A::new(0.1 + 0.3 * half, half, 0.2),
                    radius,
                    friction: 0.0,
                };
                let shape = Shape::Capsule(capsule);
                let bound = Bound::of(&shape);
                for i in 0..4000 {
                    // Points spread over the capsule's surface by a
                    // golden-angle spiral, along its length.
                    let u = (i as f32 + 0.5) / 4000.0;
                    let (phi, z) = (i as f32 * 2.399_963, 1.0 - 2.0 * u);
                    let ring = (1.0 - z * z).max(0.0).sqrt();
                    let dir = Vec3A::new(ring * phi.cos(), z, ring * phi.sin());
                    let along = capsule.a + (capsule.b - capsule.a) * ((i % 7) as f32 / 6.0);
                    for scale in [0.999_99, 1.0, 1.000_001, 1.000_01, 1.0001, 1.01, 3.0] {
                        let x = along + dir * (radius * scale);
                        let outside = bound.outside(x);
                        if offset.x < 1000.0 && shape.contact(x, radius).is_none() {
                            far += 1;
                            far_turned_away += u32::from(outside);
                        }
                        if outside {
                            assert!(
                                shape.contact(x, 0.0).is_none(),
                                "{x:?} turned away from {capsule:?} but inside it"
                            );
                        }
                    }
                }
            }
        }
        // The test turns all of those away.
        assert_eq!(far_turned_away, far);
        assert!(far > 4 * 4000, "{far}");
        assert!(
            !Bound::of(&Shape::Capsule(Capsule {
                a: Vec3A::ZERO,
                b: Vec3A::Y,
                radius: 0.1,
                friction: 0.0,
            }))
            .outside(Vec3A::NAN)
        );
    }
}
