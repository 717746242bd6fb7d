//! Builders: the lab's grid, any triangle list, and Bevy meshes.

use std::sync::Arc;

use bevy::math::Vec3;
use bevy::mesh::{Indices, Mesh, PrimitiveTopology, VertexAttributeValues};

use super::{ClothBuildError, ClothModel, ClothTopology, MeshReadError};

/// How mass is given to the vertices.
#[derive(Clone, Debug, PartialEq)]
pub enum Mass {
    /// Every vertex has this mass (the lab: 1).
    PerVertex(f32),
    /// The total mass, spread evenly over the vertices.
    Total(f32),
    /// One mass per vertex.
    Each(Vec<f32>),
}

#[derive(Clone, Debug, PartialEq)]
enum Source {
    Grid {
        rows: usize,
        cols: usize,
        corners: [Vec3; 3],
    },
    Triangles {
        positions: Vec<Vec3>,
        indices: Vec<u32>,
    },
}

/// Describes a cloth and builds a validated [`ClothModel`].
///
/// ```
/// use bevy::math::Vec3;
/// use bevy_cloth::prelude::*;
///
/// // The Unity lab's cloth: 21×21 vertices over 10×10 units, mass 1 per
/// // vertex, vertices 0 and 20 pinned.
/// let model = ClothBuilder::lab_grid(21).with_pins([0, 20]).build().unwrap();
/// assert_eq!(model.topology().vertex_count(), 441);
///
/// // Any triangle list works too; bad input is a typed error.
/// let err = ClothBuilder::from_triangles(vec![Vec3::ZERO; 3], vec![0, 1, 5]).build();
/// assert!(matches!(err, Err(ClothBuildError::IndexOutOfRange { index: 5, .. })));
/// ```
#[derive(Clone, Debug, PartialEq)]
pub struct ClothBuilder {
    source: Source,
    mass: Mass,
    pins: Vec<u32>,
}

impl ClothBuilder {
    /// The lab's square grid: `n×n` vertices over 10×10 units in the `y = 0`
    /// plane, vertex `j*n+i` at `(5 − 10i/(n−1), 0, 5 − 10j/(n−1))`, two
    /// triangles per cell `(j*n+i, j*n+i+1, (j+1)*n+i+1)` and
    /// `(j*n+i, (j+1)*n+i+1, (j+1)*n+i)`. Mass 1 per vertex, no pins (the lab
    /// pins 0 and `n−1`: add [`with_pins`](Self::with_pins)).
    pub fn lab_grid(n: usize) -> Self {
        Self::grid(
            n,
            n,
            Vec3::new(5.0, 0.0, 5.0),
            Vec3::new(-5.0, 0.0, 5.0),
            Vec3::new(5.0, 0.0, -5.0),
        )
    }

    /// The lab's cloth exactly: [`lab_grid(21)`](Self::lab_grid) pinned at
    /// vertices 0 and 20.
    pub fn lab() -> Self {
        Self::lab_grid(21).with_pins([0, 20])
    }

    /// A `rows×cols` parallelogram grid: vertex `j*cols+i` at
    /// `origin + (i/(cols−1))·(along_i − origin) + (j/(rows−1))·(along_j − origin)`,
    /// triangulated like the lab. Mass 1 per vertex.
    pub fn grid(rows: usize, cols: usize, origin: Vec3, along_i: Vec3, along_j: Vec3) -> Self {
        Self {
            source: Source::Grid {
                rows,
                cols,
                corners: [origin, along_i, along_j],
            },
            mass: Mass::PerVertex(1.0),
            pins: Vec::new(),
        }
    }

    /// Any triangle list: positions and three indices per triangle
    /// (counter-clockwise seen from the front). Mass 1 per vertex.
    pub fn from_triangles(positions: Vec<Vec3>, indices: Vec<u32>) -> Self {
        Self {
            source: Source::Triangles { positions, indices },
            mass: Mass::PerVertex(1.0),
            pins: Vec::new(),
        }
    }

    /// A Bevy triangle-list [`Mesh`] with `Float32x3` positions and an index
    /// buffer. Vertices are shared by index only: weld duplicated seam vertices
    /// first, or the cloth tears there.
    pub fn from_mesh(mesh: &Mesh) -> Result<Self, MeshReadError> {
        if mesh.primitive_topology() != PrimitiveTopology::TriangleList {
            return Err(MeshReadError::NotTriangleList);
        }
        let positions = match mesh.try_attribute_option(Mesh::ATTRIBUTE_POSITION) {
            Ok(Some(VertexAttributeValues::Float32x3(p))) => {
                p.iter().map(|&p| Vec3::from_array(p)).collect()
            }
            Ok(_) => return Err(MeshReadError::MissingPositions),
            Err(_) => return Err(MeshReadError::Extracted),
        };
        let indices = match mesh.try_indices_option() {
            Ok(Some(Indices::U16(i))) => i.iter().map(|&i| u32::from(i)).collect(),
            Ok(Some(Indices::U32(i))) => i.clone(),
            Ok(None) => return Err(MeshReadError::MissingIndices),
            Err(_) => return Err(MeshReadError::Extracted),
        };
        Ok(Self::from_triangles(positions, indices))
    }

    /// Mass of every vertex.
    pub fn with_mass_per_vertex(mut self, mass: f32) -> Self {
        self.mass = Mass::PerVertex(mass);
        self
    }

    /// Total mass, spread evenly over the vertices.
    pub fn with_total_mass(mut self, mass: f32) -> Self {
        self.mass = Mass::Total(mass);
        self
    }

    /// One mass per vertex.
    pub fn with_masses(mut self, masses: Vec<f32>) -> Self {
        self.mass = Mass::Each(masses);
        self
    }

    /// Vertices held in place: they follow the cloth entity's transform and are
    /// never moved by a solver or a collider.
    pub fn with_pins(mut self, pins: impl IntoIterator<Item = u32>) -> Self {
        self.pins = pins.into_iter().collect();
        self
    }

    /// Validates the description and builds the model.
    pub fn build(self) -> Result<ClothModel, ClothBuildError> {
        let (positions, triangles) = match self.source {
            Source::Grid {
                rows,
                cols,
                corners: [o, ai, aj],
            } => {
                if rows < 2 || cols < 2 {
                    return Err(ClothBuildError::GridTooSmall { rows, cols });
                }
                grid_mesh(rows, cols, o, ai - o, aj - o)
            }
            Source::Triangles { positions, indices } => {
                if indices.len() % 3 != 0 {
                    return Err(ClothBuildError::IndexCountNotMultipleOf3(indices.len()));
                }
                let tris = indices
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect();
                (positions, tris)
            }
        };
        let n = positions.len();
        if n == 0 {
            return Err(ClothBuildError::NoVertices);
        }
        if triangles.is_empty() {
            return Err(ClothBuildError::NoTriangles);
        }
        let masses = match self.mass {
            Mass::PerVertex(m) => vec![m; n],
            Mass::Total(m) => vec![m / n as f32; n],
            Mass::Each(ms) => {
                if ms.len() != n {
                    return Err(ClothBuildError::MassCountMismatch {
                        got: ms.len(),
                        vertex_count: n,
                    });
                }
                ms
            }
        };
        if let Some((vertex, &mass)) = masses
            .iter()
            .enumerate()
            .find(|&(_, &m)| !(m.is_finite() && m > 0.0))
        {
            return Err(ClothBuildError::InvalidMass { vertex, mass });
        }
        if let Some(&index) = self.pins.iter().find(|&&p| p as usize >= n) {
            return Err(ClothBuildError::PinOutOfRange {
                index,
                vertex_count: n,
            });
        }
        let topology = ClothTopology::new(positions, triangles, &[])?;
        Ok(ClothModel::from_parts(
            Arc::new(topology),
            masses,
            self.pins,
        ))
    }
}

/// Grid positions and the lab's triangulation.
fn grid_mesh(
    rows: usize,
    cols: usize,
    origin: Vec3,
    di: Vec3,
    dj: Vec3,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut positions = Vec::with_capacity(rows * cols);
    for j in 0..rows {
        for i in 0..cols {
            let u = i as f32 / (cols - 1) as f32;
            let v = j as f32 / (rows - 1) as f32;
            positions.push(origin + u * di + v * dj);
        }
    }
    let mut triangles = Vec::with_capacity((rows - 1) * (cols - 1) * 2);
    for j in 0..rows - 1 {
        for i in 0..cols - 1 {
            let p = |i: usize, j: usize| (j * cols + i) as u32;
            triangles.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            triangles.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    (positions, triangles)
}
