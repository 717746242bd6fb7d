//! The mutable state of a cloth: positions and velocities.

use bevy::math::{Affine3A, Vec3A};

use super::ClothModel;

/// Positions and velocities of every vertex, in world space, `f32`.
///
/// `Vec3A` (16-byte aligned) lets the solvers' loops use SIMD.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClothState {
    /// Vertex positions.
    pub positions: Vec<Vec3A>,
    /// Vertex velocities.
    pub velocities: Vec<Vec3A>,
}

impl ClothState {
    /// The model's rest shape placed by `transform`, at rest.
    pub fn at_rest(model: &ClothModel, transform: &Affine3A) -> Self {
        let positions = model
            .topology()
            .rest_positions()
            .iter()
            .map(|&p| transform.transform_point3a(p.into()))
            .collect();
        Self {
            positions,
            velocities: vec![Vec3A::ZERO; model.topology().vertex_count()],
        }
    }

    /// Number of vertices.
    #[inline]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True if there are no vertices.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// Copies `other` into `self`, reusing the allocation.
    pub fn copy_from(&mut self, other: &ClothState) {
        self.positions.clone_from(&other.positions);
        self.velocities.clone_from(&other.velocities);
    }

    /// True if every position and velocity is finite.
    pub fn is_finite(&self) -> bool {
        self.positions.iter().all(|p| p.is_finite())
            && self.velocities.iter().all(|v| v.is_finite())
    }
}
