//! Sphere colliders: impulse projection (the lab's equation 4) after a step,
//! and penalty forces (the assignment's) inside a step; planes (half-spaces,
//! the ground), capsules and boxes by projection with Coulomb friction.
//!
//! # Projection
//!
//! A vertex found inside a sphere of centre `c` and radius `r` is moved to
//! the closest point of its surface, and its velocity changes by the same
//! displacement over `dt`:
//!
//! `vᵢ ← vᵢ + (c + r(xᵢ − c)/‖xᵢ − c‖ − xᵢ)/dt`, `xᵢ ← c + r(xᵢ − c)/‖xᵢ − c‖`.
//!
//! Spheres have no friction by default (the lab's); give one a coefficient
//! and Coulomb friction follows, as for the other shapes. A vertex exactly
//! at the centre is pushed along `+y`. Planes, capsules and boxes project the same way and add Coulomb
//! friction ([`project_shapes`]).

use bevy::math::{DVec3, Vec3A};

use crate::model::{ClothModel, ClothState};

pub mod self_contact;
pub mod swept;

pub use self_contact::{SelfCollision, SelfCollisionError};
pub use swept::{Sweep, project_swept};

/// # Penalty
///
/// A vertex at `x` within contact distance `r` (sphere radius plus particle
/// radius) of the centre `c` feels `f_c = c_pen · d · Δx/l` with `Δx = x − c`,
/// `l = ‖Δx‖`, depth `d = r − l > 0` (the assignment's formula). Its
/// Jacobian is `∂f_c/∂x = −c_pen n nᵀ + c_pen (d/l)(I − n nᵀ)` with `n = Δx/l`:
/// a restoring normal stiffness and a tangential term of the opposite sign.
/// See [`PenaltyJacobian`](crate::solver::linear::PenaltyJacobian) for how
/// the implicit solvers use it.
///
/// # Other shapes
///
/// With [`surface`](Self::surface) set to [`PenaltySurface::Shape`], the
/// same penalty acts against a plane, capsule or box (its contact distance
/// already in its size): depth and normal from [`Shape::contact`]; the
/// tangential term's `l` is the distance from a capsule's axis, and
/// infinite (no term) on flat faces. `center` and `radius` are then unused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PenaltySphere {
    /// Centre.
    pub center: Vec3A,
    /// Contact distance: the sphere's radius plus the cloth particles' radius.
    pub radius: f32,
    /// Penalty stiffness `c_pen`.
    pub stiffness: f32,
    /// The sphere above, or another shape.
    pub surface: PenaltySurface,
}

/// What a [`PenaltySphere`] pushes out of.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum PenaltySurface {
    /// The sphere of its `center` and `radius`.
    #[default]
    Sphere,
    /// A plane, capsule or box, grown by the contact distance.
    Shape(Shape),
}

impl PenaltySphere {
    /// A penalty sphere.
    pub const fn sphere(center: Vec3A, radius: f32, stiffness: f32) -> Self {
        Self {
            center,
            radius,
            stiffness,
            surface: PenaltySurface::Sphere,
        }
    }

    /// A penalty plane, capsule or box (grown by the contact distance).
    pub const fn shape(shape: Shape, stiffness: f32) -> Self {
        Self {
            center: Vec3A::ZERO,
            radius: 0.0,
            stiffness,
            surface: PenaltySurface::Shape(shape),
        }
    }

    /// The same collider grown by `by` (the cloth's particle radius).
    #[must_use]
    pub fn grown(mut self, by: f32) -> Self {
        match &mut self.surface {
            PenaltySurface::Sphere => self.radius += by,
            PenaltySurface::Shape(shape) => *shape = shape.grown(by),
        }
        self
    }

    /// The solid this penalty acts against, as a frictionless [`Shape`]
    /// (a sphere as a capsule of zero length), for the position-based
    /// methods, which project it instead of applying its force.
    pub fn as_shape(&self) -> Shape {
        match self.surface {
            PenaltySurface::Sphere => Shape::Capsule(Capsule {
                a: self.center,
                b: self.center,
                radius: self.radius,
                friction: 0.0,
            }),
            PenaltySurface::Shape(shape) => shape,
        }
    }

    /// Whether the segment `a`–`b` (a vertex's motion over a step) comes
    /// within a quarter of the contact distance of the surface (a sphere),
    /// or touches the shape (any other): the vertices whose penalty may act
    /// during the step.
    pub fn near_segment(&self, a: Vec3A, b: Vec3A) -> bool {
        match self.surface {
            PenaltySurface::Sphere => {
                let ab = b - a;
                let len_sq = ab.length_squared();
                let t = if len_sq > 0.0 {
                    ((self.center - a).dot(ab) / len_sq).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let reach = 1.25 * self.radius;
                (a + t * ab).distance_squared(self.center) < reach * reach
            }
            // Every point of the segment is within half its length of its
            // middle, so this finds every segment that enters the shape.
            PenaltySurface::Shape(shape) => {
                let half = 0.5 * (b - a).length();
                shape.contact(0.5 * (a + b), 1.25 * half + 1e-4).is_some()
            }
        }
    }
}

/// One vertex's penalty contact.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PenaltyContact {
    /// The force `c_pen · d · n`.
    pub force: Vec3A,
    /// Unit normal `n` from the centre to the vertex.
    pub normal: Vec3A,
    /// Penetration depth `d > 0`.
    pub depth: f32,
    /// Distance `l` from the centre.
    pub distance: f32,
}

impl PenaltySphere {
    /// The contact of a vertex at `x`, if it is within contact distance. A
    /// vertex exactly at the centre is pushed along `+y`.
    #[inline]
    pub fn contact(&self, x: Vec3A) -> Option<PenaltyContact> {
        if let PenaltySurface::Shape(shape) = &self.surface {
            let (normal, depth) = shape.contact(x, 0.0)?;
            return Some(PenaltyContact {
                force: normal * (self.stiffness * depth),
                normal,
                depth,
                distance: shape.curvature_radius(depth),
            });
        }
        let d = x - self.center;
        let dist_sq = d.length_squared();
        if dist_sq >= self.radius * self.radius {
            return None;
        }
        let distance = dist_sq.sqrt();
        let normal = if distance > 0.0 {
            d / distance
        } else {
            Vec3A::Y
        };
        let depth = self.radius - distance;
        Some(PenaltyContact {
            force: normal * (self.stiffness * depth),
            normal,
            depth,
            distance,
        })
    }
}

/// One vertex's penalty contact, in `f64` (for the assembled systems).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PenaltyContact64 {
    /// The force `c_pen · d · n`.
    pub force: DVec3,
    /// Unit normal `n` from the centre to the vertex.
    pub normal: DVec3,
    /// Penetration depth `d > 0`.
    pub depth: f64,
    /// Distance `l` from the centre.
    pub distance: f64,
}

impl PenaltySphere {
    /// [`contact`](Self::contact) in `f64`.
    pub fn contact_f64(&self, x: DVec3) -> Option<PenaltyContact64> {
        if let PenaltySurface::Shape(shape) = &self.surface {
            let (normal, depth) = shape.contact_f64(x, 0.0)?;
            return Some(PenaltyContact64 {
                force: normal * (f64::from(self.stiffness) * depth),
                normal,
                depth,
                distance: f64::from(shape.curvature_radius(depth as f32)),
            });
        }
        let d = x - self.center.as_dvec3();
        let distance = d.length();
        let radius = f64::from(self.radius);
        if distance >= radius {
            return None;
        }
        let normal = if distance > 0.0 {
            d / distance
        } else {
            DVec3::Y
        };
        let depth = radius - distance;
        Some(PenaltyContact64 {
            force: normal * (f64::from(self.stiffness) * depth),
            normal,
            depth,
            distance,
        })
    }
}

/// A sphere in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3A,
    /// Radius (the lab: 2.7).
    pub radius: f32,
    /// Coulomb friction coefficient `μ ≥ 0` (the lab's sphere: 0).
    pub friction: f32,
}

/// Projects every free vertex out of every sphere grown by `thickness` (the
/// cloth's particle radius; the lab uses 0) per the lab's equation 4, and
/// returns how many projections were made: equation 4 as
/// [`project_contacts`] applies it (the vertex moved by its depth along the
/// normal, the velocity by the same over `dt`), then Coulomb friction for a
/// sphere with `friction > 0` (0, the lab's, is none). `dt` must be
/// positive.
pub fn project_spheres(
    model: &ClothModel,
    state: &mut ClothState,
    spheres: &[Sphere],
    thickness: f32,
    dt: f32,
) -> usize {
    project_contacts(model, state, spheres, dt, |s, x| {
        let radius = s.radius + thickness;
        let d = x - s.center;
        let dist_sq = d.length_squared();
        (dist_sq < radius * radius).then(|| {
            let dist = dist_sq.sqrt();
            let dir = if dist > 0.0 { d / dist } else { Vec3A::Y };
            (dir, radius - dist, s.friction)
        })
    })
}

/// A half-space `{x : n·(x − p) ≥ 0}` (the ground, a floor, a slope) with
/// Coulomb friction, in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    /// A point on the surface.
    pub point: Vec3A,
    /// The unit normal, pointing out of the solid side.
    pub normal: Vec3A,
    /// Friction coefficient `μ ≥ 0`.
    pub friction: f32,
}

/// A capsule (the segment `a`–`b` grown by `radius`: a limb) with Coulomb
/// friction, in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    /// One end of the axis.
    pub a: Vec3A,
    /// The other end (equal to `a` for a sphere).
    pub b: Vec3A,
    /// Radius around the axis.
    pub radius: f32,
    /// Friction coefficient `μ ≥ 0`.
    pub friction: f32,
}

/// An oriented box with Coulomb friction, in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cuboid {
    /// Centre.
    pub center: Vec3A,
    /// Unit local axes.
    pub axes: [Vec3A; 3],
    /// Half the side lengths along `axes`.
    pub half_extents: Vec3A,
    /// Friction coefficient `μ ≥ 0`.
    pub friction: f32,
}

/// A solid a cloth is projected out of, with friction (see [`project_shapes`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Shape {
    /// A half-space.
    Plane(Plane),
    /// A capsule.
    Capsule(Capsule),
    /// An oriented box.
    Cuboid(Cuboid),
}

impl Shape {
    /// For a point within `thickness` of the solid: the unit direction to
    /// push it along and how far (`depth > 0`) to reach `thickness` outside.
    /// Computed in `f64` ([`contact_f64`](Self::contact_f64)), one code
    /// path for the projection and the penalty.
    #[inline]
    pub fn contact(&self, x: Vec3A, thickness: f32) -> Option<(Vec3A, f32)> {
        self.contact_f64(x.as_dvec3(), f64::from(thickness))
            .map(|(normal, depth)| (normal.as_vec3a(), depth as f32))
    }

    /// [`contact`](Self::contact) in `f64` (the exact method's penalty
    /// needs more than `f32` to converge).
    pub fn contact_f64(&self, x: DVec3, thickness: f64) -> Option<(DVec3, f64)> {
        let (normal, depth) = match self {
            Shape::Plane(p) => {
                let n = p.normal.as_dvec3();
                (n, thickness - n.dot(x - p.point.as_dvec3()))
            }
            Shape::Capsule(c) => {
                let (a, b) = (c.a.as_dvec3(), c.b.as_dvec3());
                let axis = b - a;
                let len_sq = axis.length_squared();
                let t = if len_sq > 0.0 {
                    ((x - a).dot(axis) / len_sq).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let d = x - (a + t * axis);
                let distance = d.length();
                // On the axis: out along any direction across it (+y for a
                // capsule of zero length, a sphere, as `project_spheres`).
                let normal = if distance > 0.0 {
                    d / distance
                } else if len_sq > 0.0 {
                    (axis / len_sq.sqrt()).any_orthonormal_vector()
                } else {
                    DVec3::Y
                };
                (normal, f64::from(c.radius) + thickness - distance)
            }
            Shape::Cuboid(b) => {
                let d = x - b.center.as_dvec3();
                let axes = b.axes.map(Vec3A::as_dvec3);
                let local = DVec3::new(d.dot(axes[0]), d.dot(axes[1]), d.dot(axes[2]));
                let gap = b.half_extents.as_dvec3() + DVec3::splat(thickness) - local.abs();
                if gap.min_element() <= 0.0 {
                    return None;
                }
                // Inside: out through the nearest face.
                let k = if gap.x <= gap.y && gap.x <= gap.z {
                    0
                } else if gap.y <= gap.z {
                    1
                } else {
                    2
                };
                let sign = if local[k] < 0.0 { -1.0 } else { 1.0 };
                (axes[k] * sign, gap[k])
            }
        };
        (depth > 0.0).then_some((normal, depth))
    }

    /// The radius of curvature at a contact of this depth, for the
    /// penalty's tangential term: the distance from a capsule's axis,
    /// infinite on flat faces.
    pub fn curvature_radius(&self, depth: f32) -> f32 {
        match self {
            Shape::Capsule(c) => (c.radius - depth).max(0.0),
            Shape::Plane(_) | Shape::Cuboid(_) => f32::INFINITY,
        }
    }

    /// The same shape grown by `by` all round.
    #[must_use]
    pub fn grown(self, by: f32) -> Self {
        match self {
            Shape::Plane(p) => Shape::Plane(Plane {
                point: p.point + by * p.normal,
                ..p
            }),
            Shape::Capsule(c) => Shape::Capsule(Capsule {
                radius: c.radius + by,
                ..c
            }),
            Shape::Cuboid(b) => Shape::Cuboid(Cuboid {
                half_extents: b.half_extents + Vec3A::splat(by),
                ..b
            }),
        }
    }

    /// The same shape moved by `by`.
    #[must_use]
    pub fn translated(self, by: Vec3A) -> Self {
        match self {
            Shape::Plane(p) => Shape::Plane(Plane {
                point: p.point + by,
                ..p
            }),
            Shape::Capsule(c) => Shape::Capsule(Capsule {
                a: c.a + by,
                b: c.b + by,
                ..c
            }),
            Shape::Cuboid(b) => Shape::Cuboid(Cuboid {
                center: b.center + by,
                ..b
            }),
        }
    }

    /// The friction coefficient.
    pub fn friction(&self) -> f32 {
        match self {
            Shape::Plane(p) => p.friction,
            Shape::Capsule(c) => c.friction,
            Shape::Cuboid(b) => b.friction,
        }
    }
}

/// Projects every free vertex out of every shape, `thickness` outside its
/// surface, after a step, and returns how many projections were made.
///
/// As for spheres (the lab's equation 4), a vertex inside is moved out along
/// the contact normal and its velocity changes by the same displacement over
/// `dt`; that normal impulse per unit mass is `j = depth/dt`. **Coulomb
/// friction** then takes up to `μ·j` from the vertex's tangential velocity,
/// and the matching tangential displacement (`Δv·dt`) from its position: a
/// vertex whose tangential speed is below `μ·j` sticks (static friction,
/// which holds a cloth on a slope of angle `θ` while `μ ≥ tan θ`), a faster
/// one slides slower (kinetic). The shapes are static within the step: a
/// moving shape pushes by where it is. `dt` must be positive.
pub fn project_shapes(
    model: &ClothModel,
    state: &mut ClothState,
    shapes: &[Shape],
    thickness: f32,
    dt: f32,
) -> usize {
    project_contacts(model, state, shapes, dt, |shape, x| {
        shape
            .contact(x, thickness)
            .map(|(normal, depth)| (normal, depth, shape.friction()))
    })
}

/// [`project_shapes`] for any solids: `contact(solid, x)` gives, for a point
/// `x` within contact distance, the unit direction to push it along, how far
/// (`depth > 0`), and the friction coefficient. Used for the game's own
/// colliders (feature `avian`: any avian collider by its closest-point
/// query).
pub fn project_contacts<S>(
    model: &ClothModel,
    state: &mut ClothState,
    solids: &[S],
    dt: f32,
    contact: impl Fn(&S, Vec3A) -> Option<(Vec3A, f32, f32)>,
) -> usize {
    let ClothState {
        positions,
        velocities,
    } = state;
    project_contacts_on(model, positions, velocities, solids, dt, contact)
}

/// [`project_contacts`] on positions `x` and velocities `v` (the first
/// `model`'s vertex count of them), for a method that projects inside its
/// step.
pub(crate) fn project_contacts_on<S>(
    model: &ClothModel,
    x: &mut [Vec3A],
    v: &mut [Vec3A],
    solids: &[S],
    dt: f32,
    contact: impl Fn(&S, Vec3A) -> Option<(Vec3A, f32, f32)>,
) -> usize {
    let pinned = model.pinned();
    let inv_dt = 1.0 / dt;
    let mut count = 0;
    for (i, (x, v)) in x.iter_mut().zip(v.iter_mut()).enumerate() {
        if pinned[i] {
            continue;
        }
        for solid in solids {
            let Some((normal, depth, friction)) = contact(solid, *x) else {
                continue;
            };
            *x += depth * normal;
            *v += depth * inv_dt * normal;
            count += 1;
            self::friction(x, v, normal, depth * inv_dt, friction, dt);
        }
    }
    count
}

/// How far to move each of `vertices` along a contact normal so that the
/// point with barycentric `weights` on them moves out by `depth`: the
/// position-based share `wₖ·m⁻¹ₖ·depth/Σ wₖ²m⁻¹ₖ` (pinned vertices take
/// none). `None` if no vertex can move.
pub(crate) fn inverse_pushes<const N: usize>(
    model: &ClothModel,
    vertices: [usize; N],
    weights: [f32; N],
    depth: f32,
) -> Option<[f32; N]> {
    let inverse = vertices.map(|i| self_contact::inverse_mass(model, i));
    pushes(weights, inverse, depth)
}

/// [`inverse_pushes`] for vertices of inverse masses `inverse`.
#[inline]
pub(crate) fn pushes<const N: usize>(
    weights: [f32; N],
    inverse: [f32; N],
    depth: f32,
) -> Option<[f32; N]> {
    let sum: f32 = (0..N).map(|k| weights[k] * weights[k] * inverse[k]).sum();
    (sum > 0.0).then(|| std::array::from_fn(|k| weights[k] * inverse[k] * depth / sum))
}

/// Coulomb friction after a projection along `normal` with normal impulse
/// (per unit mass) `impulse`: takes up to `μ·impulse` from the tangential
/// velocity, and the matching displacement from the position.
#[inline]
fn friction(x: &mut Vec3A, v: &mut Vec3A, normal: Vec3A, impulse: f32, mu: f32, dt: f32) {
    let tangential = *v - v.dot(normal) * normal;
    let speed = tangential.length();
    if speed > 0.0 && mu > 0.0 {
        let taken = (mu * impulse).min(speed);
        let dv = tangential * (-taken / speed);
        *v += dv;
        *x += dv * dt;
    }
}

#[cfg(test)]
mod tests;
