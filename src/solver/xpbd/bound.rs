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
//!
//! In the substeps the quick tests run over the whole cloth at once
//! ([`Near`]): after the tethers and the skin have held every vertex, each
//! solid's test runs over columns of the coordinates, which the compiler
//! vectorises, and leaves a bit per vertex and solid; the pass that follows
//! runs the exact test only where a bit is set ([`project_near`]). The
//! results are [`project`]'s, bit for bit (a test compares them).

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
pub(super) fn project(x: &mut Vec3A, prev: Vec3A, solids: Solids<'_>) -> bool {
    project_near(x, prev, solids, u32::MAX)
}

/// [`project`] with the first 32 solids' vectorised quick tests taken from
/// `near`, [`Near`]'s mask for `x` where it is (bit `k` clear: solid `k`
/// turned it away; `u32::MAX` turns none away). A solid a bit keeps, and
/// every solid once another has moved `x`, takes its own quick test
/// ([`Bound::outside`]) at `x` where it then is.
pub(super) fn project_near(
    x: &mut Vec3A,
    prev: Vec3A,
    (shapes, bounds, shifts): Solids<'_>,
    near: u32,
) -> bool {
    if near == 0 && shapes.len() <= 32 {
        return false;
    }
    let mut touched = false;
    for (k, ((shape, bound), &shift)) in shapes.iter().zip(bounds).zip(shifts).enumerate() {
        let kept = touched || k >= 32 || near & (1 << k) != 0;
        if kept && !bound.outside(*x) {
            touched |= push_out(x, prev, shape, shift);
        }
    }
    touched
}

/// Moves `x` out of `shape` if it is inside, with friction (see
/// [`project`]); says whether it was.
#[inline]
fn push_out(x: &mut Vec3A, prev: Vec3A, shape: &Shape, shift: Vec3A) -> bool {
    let Some((normal, depth)) = shape.contact(*x, 0.0) else {
        return false;
    };
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
    true
}

/// The first 32 solids' quick tests over a whole cloth at once, a solid at
/// a time over arrays of the coordinates, which the compiler vectorises
/// (one vertex and one solid at a time, each test a chain of horizontal
/// sums, they were the largest part of a cape's step: see
/// `docs/measurements.md`). A capsule's is its distance to the axis alone
/// (the sphere in front of it in [`Bound::outside`] turns away nothing it
/// would not), computed as [`Bound::outside`] computes it, a cuboid's its
/// sphere, a plane's nothing.
#[derive(Clone, Debug, Default)]
pub(super) struct Near {
    /// The vertices' coordinates, a column each.
    xyz: [Vec<f32>; 3],
    /// Per vertex, bit `k` set unless solid `k` turned it away.
    masks: Vec<u32>,
}

impl Near {
    /// The masks for the cloth at `x`, against the solids of `bounds`.
    pub(super) fn update(&mut self, x: &[Vec3A], bounds: &[Bound]) {
        let [xs, ys, zs] = &mut self.xyz;
        for column in [&mut *xs, &mut *ys, &mut *zs] {
            column.resize(x.len(), 0.0);
        }
        for (p, ((x, y), z)) in x
            .iter()
            .zip(xs.iter_mut().zip(ys.iter_mut()).zip(zs.iter_mut()))
        {
            (*x, *y, *z) = (p.x, p.y, p.z);
        }
        self.masks.clear();
        self.masks.resize(x.len(), 0);
        let columns = || xs.iter().zip(ys.iter()).zip(zs.iter());
        for (k, bound) in bounds.iter().enumerate().take(32) {
            let bit = 1u32 << k;
            let masks = self.masks.iter_mut();
            match *bound {
                Bound::Always => masks.for_each(|m| *m |= bit),
                Bound::Sphere(c, r2) => {
                    for (m, ((&x, &y), &z)) in masks.zip(columns()) {
                        let (dx, dy, dz) = (x - c.x, y - c.y, z - c.z);
                        let d2 = (dx * dx + dy * dy) + dz * dz;
                        *m |= bit * (1 - u32::from(d2 > r2));
                    }
                }
                Bound::Capsule {
                    a,
                    axis,
                    inv,
                    reach2,
                    ..
                } => {
                    for (m, ((&x, &y), &z)) in masks.zip(columns()) {
                        let (dx, dy, dz) = (x - a.x, y - a.y, z - a.z);
                        let along = ((dx * axis.x + dy * axis.y) + dz * axis.z) * inv;
                        let t = along.clamp(0.0, 1.0);
                        let (ex, ey, ez) = (dx - t * axis.x, dy - t * axis.y, dz - t * axis.z);
                        let d2 = (ex * ex + ey * ey) + ez * ez;
                        *m |= bit * (1 - u32::from(d2 > reach2));
                    }
                }
            }
        }
    }

    /// Vertex `i`'s mask.
    #[inline]
    pub(super) fn mask(&self, i: usize) -> u32 {
        self.masks[i]
    }
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

    /// `project_near` with `Near`'s masks is `project`, bit for bit, over
    /// a cloud of points in and around a body of capsules, a box and the
    /// ground (some inside two solids at once, where the second's quick
    /// test is taken at the place the first moved the point to), and the
    /// masks turn away only points `Bound::outside` turns away.
    #[test]
    fn the_quick_tests_over_the_whole_cloth_project_as_one_at_a_time() {
        use crate::collision::{Cuboid, Plane};
        let capsule = |a: Vec3A, b: Vec3A, radius| {
            Shape::Capsule(Capsule {
                a,
                b,
                radius,
                friction: 0.3,
            })
        };
        let shapes = [
            capsule(Vec3A::new(0.0, 0.9, 0.0), Vec3A::new(0.0, 1.4, 0.05), 0.17),
            capsule(Vec3A::new(0.1, 0.2, 0.0), Vec3A::new(0.1, 0.9, 0.0), 0.08),
            capsule(Vec3A::new(0.0, 1.6, 0.0), Vec3A::new(0.0, 1.6, 0.0), 0.11),
            Shape::Cuboid(Cuboid {
                center: Vec3A::new(0.2, 1.0, 0.1),
                axes: [Vec3A::X, Vec3A::Y, Vec3A::Z],
                half_extents: Vec3A::new(0.1, 0.2, 0.1),
                friction: 0.5,
            }),
            Shape::Plane(Plane {
                point: Vec3A::new(0.0, 0.25, 0.0),
                normal: Vec3A::Y,
                friction: 0.0,
            }),
        ];
        let bounds: Vec<Bound> = shapes.iter().map(Bound::of).collect();
        let shifts = [Vec3A::new(0.01, 0.0, 0.0); 5];
        let solids = (&shapes[..], &bounds[..], &shifts[..]);
        // A cloud over the body, from a small linear congruential generator.
        let mut seed = 12345u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        let x: Vec<Vec3A> = (0..20_000)
            .map(|_| Vec3A::new(0.7 * next() - 0.3, 1.9 * next(), 0.6 * next() - 0.3))
            .chain([Vec3A::NAN])
            .collect();
        let mut near = Near::default();
        near.update(&x, &bounds);
        let (mut touched, mut turned_away) = (0, 0);
        for (i, &p) in x.iter().enumerate() {
            for (k, bound) in bounds.iter().enumerate() {
                if near.mask(i) & (1 << k) == 0 {
                    turned_away += 1;
                    assert!(bound.outside(p), "{p:?}, solid {k}");
                }
            }
            let prev = p - Vec3A::new(0.0, 0.02, 0.01);
            let (mut one, mut all) = (p, p);
            let t = project(&mut one, prev, solids);
            assert_eq!(project_near(&mut all, prev, solids, near.mask(i)), t);
            assert!(
                one.to_array().map(f32::to_bits) == all.to_array().map(f32::to_bits) || p.is_nan()
            );
            touched += u32::from(t);
        }
        // Both kinds occur: points pushed out, and quick tests that spare
        // most of the exact ones.
        assert!(touched > 1000, "{touched}");
        assert!(turned_away > 3 * 20_000, "{turned_away}");
    }
}
