//! Sphere colliders: impulse projection (the lab's equation 4).
//!
//! A vertex found inside a sphere of centre `c` and radius `r` is moved to
//! the closest point of its surface, and its velocity changes by the same
//! displacement over `dt`:
//!
//! `vᵢ ← vᵢ + (c + r(xᵢ − c)/‖xᵢ − c‖ − xᵢ)/dt`, `xᵢ ← c + r(xᵢ − c)/‖xᵢ − c‖`.
//!
//! No friction. A vertex exactly at the centre is pushed along `+y`.

use bevy::math::Vec3A;

use crate::model::{ClothModel, ClothState};

/// A sphere in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3A,
    /// Radius (the lab: 2.7).
    pub radius: f32,
}

/// Projects every free vertex out of every sphere (lab equation 4) and
/// returns how many projections were made. `dt` must be positive.
pub fn project_spheres(
    model: &ClothModel,
    state: &mut ClothState,
    spheres: &[Sphere],
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
            let d = *x - s.center;
            let dist_sq = d.length_squared();
            if dist_sq < s.radius * s.radius {
                let dist = dist_sq.sqrt();
                let dir = if dist > 0.0 { d / dist } else { Vec3A::Y };
                let target = s.center + s.radius * dir;
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
