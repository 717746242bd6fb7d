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
}

impl ClothModel {
    pub(crate) fn from_parts(
        topology: Arc<ClothTopology>,
        masses: Vec<f32>,
        pins: Vec<u32>,
    ) -> Self {
        let mut pinned = vec![false; topology.vertex_count()];
        let mut unique = Vec::with_capacity(pins.len());
        for p in pins {
            if !pinned[p as usize] {
                pinned[p as usize] = true;
                unique.push(p);
            }
        }
        Self {
            topology,
            masses,
            pinned,
            pins: unique,
        }
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

    /// The pinned vertices, each once, in the order given.
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
