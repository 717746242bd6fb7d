//! Typed errors for building cloths and validating simulation parameters.

use thiserror::Error;

/// Why a cloth could not be built from its description.
///
/// Returned by [`ClothBuilder::build`](super::ClothBuilder::build) and the
/// mesh conversions. Every invalid input maps to one variant; building never
/// panics.
#[derive(Error, Debug, Clone, PartialEq)]
pub enum ClothBuildError {
    /// The description has no vertices.
    #[error("the cloth has no vertices")]
    NoVertices,
    /// A grid needs at least two vertices along each side.
    #[error("a grid needs at least 2×2 vertices, got {rows}×{cols}")]
    GridTooSmall {
        /// Vertices along the first side.
        rows: usize,
        /// Vertices along the second side.
        cols: usize,
    },
    /// The index list has a length that is not a multiple of three.
    #[error("triangle index count {0} is not a multiple of 3")]
    IndexCountNotMultipleOf3(usize),
    /// A triangle refers to a vertex that does not exist.
    #[error("triangle index {index} is out of range for {vertex_count} vertices")]
    IndexOutOfRange {
        /// The offending index.
        index: u32,
        /// The number of vertices.
        vertex_count: usize,
    },
    /// A triangle uses the same vertex twice.
    #[error("triangle {triangle} repeats a vertex")]
    DegenerateTriangle {
        /// The triangle's position in the index list (index / 3).
        triangle: usize,
    },
    /// A vertex position is NaN or infinite.
    #[error("vertex {vertex} has a non-finite position")]
    NonFinitePosition {
        /// The offending vertex.
        vertex: usize,
    },
    /// An areal density ([`Mass::Areal`](super::Mass::Areal)) is zero,
    /// negative or not finite.
    #[error("areal density {0} kg/m² must be finite and positive")]
    InvalidDensity(f32),
    /// A vertex mass is zero, negative or not finite (from an areal
    /// density: the vertex is in no triangle with area).
    #[error("vertex {vertex} has mass {mass}; masses must be finite and positive")]
    InvalidMass {
        /// The offending vertex (0 for a uniform or total mass).
        vertex: usize,
        /// The rejected mass.
        mass: f32,
    },
    /// The per-vertex mass list does not have one entry per vertex.
    #[error("{got} masses given for {vertex_count} vertices")]
    MassCountMismatch {
        /// Number of masses given.
        got: usize,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// A pinned vertex index does not exist.
    #[error("pinned vertex {index} is out of range for {vertex_count} vertices")]
    PinOutOfRange {
        /// The offending pin.
        index: u32,
        /// The number of vertices.
        vertex_count: usize,
    },
    /// A vertex is pinned twice (a list of pins built from two overlapping
    /// selections, say): pins are a set, so each vertex is listed once.
    #[error("vertex {index} is pinned twice")]
    DuplicatePin {
        /// The repeated pin.
        index: u32,
    },
    /// Two vertices joined by an edge sit at the same place, so the edge has no
    /// rest length and its direction is undefined.
    #[error("edge ({a}, {b}) has zero rest length")]
    ZeroLengthEdge {
        /// First vertex of the edge.
        a: u32,
        /// Second vertex of the edge.
        b: u32,
    },
    /// The mesh has no triangles at all (only points or lines).
    #[error("the cloth has no triangles")]
    NoTriangles,
    /// A Bevy mesh could not be read (see [`MeshReadError`]).
    #[error(transparent)]
    Mesh(#[from] MeshReadError),
}

/// Why a Bevy [`Mesh`](bevy::mesh::Mesh) cannot be turned into a cloth.
#[derive(Error, Debug, Clone, Copy, PartialEq, Eq)]
pub enum MeshReadError {
    /// Only triangle lists can be simulated.
    #[error("the mesh topology is not a triangle list")]
    NotTriangleList,
    /// The mesh has no `Float32x3` position attribute.
    #[error("the mesh has no Float32x3 position attribute")]
    MissingPositions,
    /// The mesh has no index buffer.
    #[error("the mesh has no index buffer")]
    MissingIndices,
    /// The mesh data has already been moved to the render world.
    #[error("the mesh data is no longer available in the main world")]
    Extracted,
    /// The mesh has no such vertex attribute.
    #[error("the mesh has no {0} attribute")]
    MissingAttribute(&'static str),
    /// The attribute is not 1 to 4 `f32`s per vertex.
    #[error("the mesh's {0} attribute is not Float32, Float32x2, Float32x3 or Float32x4")]
    AttributeFormat(&'static str),
}
