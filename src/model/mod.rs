//! Pure cloth data: topology, masses, pins and state. No systems, no ECS types.
//!
//! A [`ClothModel`] is what does not change while simulating (shape, springs,
//! masses, pins); a [`ClothState`] is what does (positions, velocities). Build
//! models with [`ClothBuilder`].

mod builder;
mod error;
mod material;
mod order;
mod state;
pub(crate) mod stencil;
mod topology;

use std::sync::Arc;

use bevy::math::Vec3;

pub use builder::{ClothBuilder, Mass, mesh_vertices_where};
pub use error::{ClothBuildError, MeshReadError};
pub use material::ClothMaterial;
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
    /// The mass of the free (unpinned) vertices.
    free_mass: f32,
    /// For each vertex of the source mesh, the cloth vertex it became.
    pub(crate) welded_from: Option<Arc<Vec<u32>>>,
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
        let free_mass = free_mass(&masses, &pinned);
        Self {
            topology,
            masses,
            pinned,
            pins,
            size,
            free_mass,
            welded_from: None,
        }
    }

    /// The total mass of the vertices that are not pinned: the weight the
    /// pins carry, over `|g|`.
    #[inline]
    pub fn free_mass(&self) -> f32 {
        self.free_mass
    }

    /// For a cloth built from a mesh ([`ClothBuilder::from_mesh`]): for each
    /// vertex of that mesh, the cloth vertex it became. A mesh's seams are
    /// welded (copies of a vertex become one), and a mesh whose vertex order
    /// scatters its edges in memory is renumbered for locality (reverse
    /// Cuthill–McKee; a shuffled 101² grid mesh stepped about 3× slower
    /// before). `None` when neither happened (mesh and cloth vertices are
    /// the same). Pins and per-vertex masses given to the builder follow the
    /// renumbering; the mesh write-back reads through this map.
    #[inline]
    pub fn welded_from(&self) -> Option<&[u32]> {
        self.welded_from.as_deref().map(Vec::as_slice)
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

    /// Replaces the pinned vertices (a run-time attach or detach). Every
    /// method notices the change at its next step (the factorising ones
    /// refactorise). On error the pins are unchanged.
    pub fn set_pins(&mut self, pins: Vec<u32>) -> Result<(), ClothBuildError> {
        check_pins(&pins, self.vertex_count())?;
        self.pinned.fill(false);
        for &p in &pins {
            self.pinned[p as usize] = true;
        }
        self.pins = pins;
        self.free_mass = free_mass(&self.masses, &self.pinned);
        Ok(())
    }

    /// Replaces the vertices' masses (a material's density applied at run
    /// time, say). Every method notices at its next step (the factorising
    /// ones refactorise). On error the masses are unchanged:
    /// [`ClothBuildError::MassCountMismatch`] or
    /// [`ClothBuildError::InvalidMass`].
    pub fn set_masses(&mut self, masses: Vec<f32>) -> Result<(), ClothBuildError> {
        if masses.len() != self.vertex_count() {
            return Err(ClothBuildError::MassCountMismatch {
                got: masses.len(),
                vertex_count: self.vertex_count(),
            });
        }
        if let Some((vertex, &mass)) = masses
            .iter()
            .enumerate()
            .find(|&(_, &m)| !(m.is_finite() && m > 0.0))
        {
            return Err(ClothBuildError::InvalidMass { vertex, mass });
        }
        self.masses = masses;
        self.free_mass = free_mass(&self.masses, &self.pinned);
        Ok(())
    }

    /// The cloth vertices that the vertices `mesh_indices` of the mesh this
    /// cloth was built from became (see [`welded_from`](Self::welded_from)),
    /// in order, duplicates (welded copies) removed; an index past the mesh
    /// is skipped. For a cloth not built from a mesh, or one neither welded
    /// nor renumbered, the indices themselves. The builder's
    /// [`with_pins`](ClothBuilder::with_pins) after
    /// [`from_mesh`](ClothBuilder::from_mesh) and
    /// [`mesh_vertices_where`] speak mesh
    /// indices; everything after [`ClothBuilder::build`] ([`vertices_where`](Self::vertices_where),
    /// [`Attachment`](crate::Attachment), [`ClothState`]) speaks cloth
    /// indices: this converts.
    pub fn cloth_vertices(&self, mesh_indices: impl IntoIterator<Item = u32>) -> Vec<u32> {
        let n = self.vertex_count();
        let mut seen = vec![false; n];
        let mut out = Vec::new();
        for i in mesh_indices {
            let v = match self.welded_from() {
                Some(map) => map.get(i as usize).copied(),
                None => ((i as usize) < n).then_some(i),
            };
            if let Some(v) = v.filter(|&v| !std::mem::replace(&mut seen[v as usize], true)) {
                out.push(v);
            }
        }
        out
    }

    /// The vertices whose rest position satisfies `select`, in index order:
    /// pins by place (`|p| p.y > 0.99` for a top edge).
    pub fn vertices_where(&self, select: impl Fn(Vec3) -> bool) -> Vec<u32> {
        vertices_where(self.topology.rest_positions(), select)
    }
}

fn free_mass(masses: &[f32], pinned: &[bool]) -> f32 {
    let sum: f64 = masses
        .iter()
        .zip(pinned)
        .filter(|(_, p)| !**p)
        .map(|(&m, _)| f64::from(m))
        .sum();
    sum as f32
}

/// The indices of `positions` that satisfy `select`.
pub(crate) fn vertices_where(positions: &[Vec3], select: impl Fn(Vec3) -> bool) -> Vec<u32> {
    (0..positions.len() as u32)
        .filter(|&i| select(positions[i as usize]))
        .collect()
}

/// Every pin in range and listed once.
pub(crate) fn check_pins(pins: &[u32], vertex_count: usize) -> Result<(), ClothBuildError> {
    if let Some(&index) = pins.iter().find(|&&p| p as usize >= vertex_count) {
        return Err(ClothBuildError::PinOutOfRange {
            index,
            vertex_count,
        });
    }
    let mut seen = vec![false; vertex_count];
    for &p in pins {
        if std::mem::replace(&mut seen[p as usize], true) {
            return Err(ClothBuildError::DuplicatePin { index: p });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
