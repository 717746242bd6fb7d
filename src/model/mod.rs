//! Pure cloth data: topology, masses, pins and state. No systems, no ECS types.
//!
//! A [`ClothModel`] is what does not change while simulating (shape, springs,
//! masses, pins); a [`ClothState`] is what does (positions, velocities). Build
//! models with [`ClothBuilder`].

mod builder;
mod error;
mod state;
mod topology;

use std::sync::Arc;

use bevy::math::Vec3;

pub use builder::{ClothBuilder, Mass};
pub use error::{ClothBuildError, MeshReadError};
pub use state::ClothState;
pub use topology::{Adjacency, ClothTopology, Incidence, Spring, SpringKind};

/// A validated cloth: shared topology, per-vertex masses and pinned vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClothModel {
    topology: Arc<ClothTopology>,
    masses: Vec<f32>,
    pinned: Vec<bool>,
    pins: Vec<u32>,
    size: f32,
}

impl ClothModel {
    pub(crate) fn from_parts(
        topology: Arc<ClothTopology>,
        masses: Vec<f32>,
        pins: Vec<u32>,
    ) -> Self {
        let mut pinned = vec![false; topology.vertex_count()];
        for &p in &pins {
            pinned[p as usize] = true;
        }
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for &p in topology.rest_positions() {
            lo = lo.min(p);
            hi = hi.max(p);
        }
        let size = if lo.x <= hi.x {
            (hi - lo).length()
        } else {
            0.0
        };
        Self {
            topology,
            masses,
            pinned,
            pins,
            size,
        }
    }

    /// The diagonal of the rest shape's bounding box: the cloth's size, the
    /// length scale of its tolerances.
    #[inline]
    pub fn size(&self) -> f32 {
        self.size
    }

    /// The shared topology.
    #[inline]
    pub fn topology(&self) -> &ClothTopology {
        &self.topology
    }

    /// The shared topology as an `Arc`, to build more cloths of the same shape.
    #[inline]
    pub fn topology_arc(&self) -> &Arc<ClothTopology> {
        &self.topology
    }

    /// Mass of each vertex.
    #[inline]
    pub fn masses(&self) -> &[f32] {
        &self.masses
    }

    /// `pinned()[i]` is true if vertex `i` is held in place.
    #[inline]
    pub fn pinned(&self) -> &[bool] {
        &self.pinned
    }

    /// The pinned vertices, in the order given (each once: the builder
    /// refuses duplicates).
    #[inline]
    pub fn pins(&self) -> &[u32] {
        &self.pins
    }

    /// Number of vertices.
    #[inline]
    pub fn vertex_count(&self) -> usize {
        self.masses.len()
    }
}

#[cfg(test)]
mod tests;
