//! Sphere colliders: impulse projection (the lab's equation 4) after a step,
//! and penalty forces (the assignment's) inside a step.
//!
//! # Projection
//!
//! A vertex found inside a sphere of centre `c` and radius `r` is moved to
//! the closest point of its surface, and its velocity changes by the same
//! displacement over `dt`:
//!
//! `vᵢ ← vᵢ + (c + r(xᵢ − c)/‖xᵢ − c‖ − xᵢ)/dt`, `xᵢ ← c + r(xᵢ − c)/‖xᵢ − c‖`.
//!
//! No friction. A vertex exactly at the centre is pushed along `+y`.

use bevy::math::{DVec3, Vec3A};

use crate::model::{ClothModel, ClothState};

/// # Penalty
///
/// A vertex at `x` within contact distance `r` (sphere radius plus particle
/// radius) of the centre `c` feels `f_c = c_pen · d · Δx/l` with `Δx = x − c`,
/// `l = ‖Δx‖`, depth `d = r − l > 0` (the assignment's formula). Its
/// Jacobian is `∂f_c/∂x = −c_pen n nᵀ + c_pen (d/l)(I − n nᵀ)` with `n = Δx/l`:
/// a restoring normal stiffness and a tangential term of the opposite sign.
/// See [`PenaltyJacobian`](crate::solver::linear::PenaltyJacobian) for how
/// the implicit solvers use it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PenaltySphere {
    /// Centre.
    pub center: Vec3A,
    /// Contact distance: the sphere's radius plus the cloth particles' radius.
    pub radius: f32,
    /// Penalty stiffness `c_pen`.
    pub stiffness: f32,
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
}

/// Projects every free vertex out of every sphere grown by `thickness` (the
/// cloth's particle radius; the lab uses 0) per the lab's equation 4, and
/// returns how many projections were made. `dt` must be positive.
pub fn project_spheres(
    model: &ClothModel,
    state: &mut ClothState,
    spheres: &[Sphere],
    thickness: f32,
    dt: f32,
) -> usize {
    let pinned = model.pinned();
    let inv_dt = 1.0 / dt;
    let mut count = 0;
    let ClothState {
        positions,
        velocities,
    } = state;
    for (i, (x, v)) in positions.iter_mut().zip(velocities.iter_mut()).enumerate() {
        if pinned[i] {
            continue;
        }
        for s in spheres {
            let radius = s.radius + thickness;
            let d = *x - s.center;
            let dist_sq = d.length_squared();
            if dist_sq < radius * radius {
                let dist = dist_sq.sqrt();
                let dir = if dist > 0.0 { d / dist } else { Vec3A::Y };
                let target = s.center + radius * dir;
                *v += (target - *x) * inv_dt;
                *x = target;
                count += 1;
            }
        }
    }
    count
}

#[cfg(test)]
mod tests;
