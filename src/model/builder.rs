//! Builders: the lab's grid, any triangle list, and Bevy meshes.

use std::sync::Arc;

use bevy::math::Vec3;
use bevy::mesh::{Indices, Mesh, MeshVertexAttribute, PrimitiveTopology, VertexAttributeValues};

use super::topology::{cross_edge_springs, triangle_edges, validate_triangles};
use super::{ClothBuildError, ClothModel, ClothTopology, MeshReadError, SpringKind};

/// How mass is given to the vertices.
#[derive(Clone, Debug, PartialEq)]
pub enum Mass {
    /// Every vertex has this mass (the lab: 1).
    PerVertex(f32),
    /// The total mass, spread evenly over the vertices.
    Total(f32),
    /// One mass per vertex.
    Each(Vec<f32>),
    /// Mass per unit area (kg/m²): each triangle's mass, its area times
    /// this, goes a third to each of its corners (a lumped mass matrix), so
    /// a vertex on the edge weighs about half an inner one and the cloth
    /// weighs the same at every resolution.
    Areal(f32),
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
        weld: bool,
    },
    SpringGrid {
        rows: usize,
        cols: usize,
        corners: [Vec3; 4],
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
    shear: bool,
    bend: bool,
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
            shear: false,
            bend: false,
        }
    }

    /// Any triangle list: positions and three indices per triangle
    /// (counter-clockwise seen from the front). Mass 1 per vertex.
    pub fn from_triangles(positions: Vec<Vec3>, indices: Vec<u32>) -> Self {
        Self {
            source: Source::Triangles {
                positions,
                indices,
                weld: false,
            },
            mass: Mass::PerVertex(1.0),
            pins: Vec::new(),
            shear: false,
            bend: false,
        }
    }

    /// The assignment's particle grid: `rows×cols` particles between four
    /// corners, particle `i*cols + j` (row `i`, column `j`) at the bilinear
    /// blend `(1−v)((1−u)x00 + u·x10) + v((1−u)x01 + u·x11)` with
    /// `u = i/(rows−1)`, `v = j/(cols−1)`. Springs as the assignment builds
    /// them: stretch springs along rows ("x") and columns ("y"); with
    /// [`with_shear_springs`](Self::with_shear_springs) both diagonals of
    /// every cell; with [`with_bending_springs`](Self::with_bending_springs)
    /// skip-one springs along rows and columns. Each cell is split into two
    /// triangles for rendering only. Mass 1 per particle, no pins.
    pub fn spring_grid(
        rows: usize,
        cols: usize,
        x00: Vec3,
        x01: Vec3,
        x10: Vec3,
        x11: Vec3,
    ) -> Self {
        Self {
            source: Source::SpringGrid {
                rows,
                cols,
                corners: [x00, x01, x10, x11],
            },
            mass: Mass::PerVertex(1.0),
            pins: Vec::new(),
            shear: false,
            bend: false,
        }
    }

    /// The assignment's scene cloth: a [`spring_grid`](Self::spring_grid)
    /// over the horizontal square `x ∈ [−0.25, 0.25]`, `z ∈ [−0.5, 0]` at
    /// `y = 0.5` (`x00 = (−0.25, 0.5, 0)`, `x01 = (0.25, 0.5, 0)`,
    /// `x10 = (−0.25, 0.5, −0.5)`, `x11 = (0.25, 0.5, −0.5)`), total mass
    /// 0.1, every spring kind, and the two corners of row 0 fixed. This is
    /// the setup that reproduces the assignment's printed first-step `A` and
    /// `b` for 2×2 (derived from that matrix: see the crate docs).
    pub fn assignment(rows: usize, cols: usize) -> Self {
        Self::spring_grid(
            rows,
            cols,
            Vec3::new(-0.25, 0.5, 0.0),
            Vec3::new(0.25, 0.5, 0.0),
            Vec3::new(-0.25, 0.5, -0.5),
            Vec3::new(0.25, 0.5, -0.5),
        )
        .with_total_mass(0.1)
        .with_shear_springs()
        .with_bending_springs()
        .with_pins([0, cols.saturating_sub(1) as u32])
    }

    /// A Bevy triangle-list [`Mesh`] with `Float32x3` positions and an index
    /// buffer, **welded**: vertices at the same position (within a millionth
    /// of the mesh's size), which a UV-mapped or flat-shaded mesh splits
    /// along its seams, become one simulated vertex, so the cloth does not
    /// tear there. A mesh whose vertex order scatters its edges in memory
    /// is renumbered for locality. [`ClothModel::welded_from`] maps the
    /// mesh's vertices to the simulated ones, and the mesh write-back
    /// (`render::ClothRenderPlugin`) writes them back unwelded, with normals
    /// smooth across the seams. Pins
    /// ([`with_pins`](Self::with_pins)) are mesh vertex indices.
    ///
    /// Fails with [`ClothBuildError::Mesh`], so reading and building share one
    /// error type: `ClothBuilder::from_mesh(&mesh)?.with_pins(..).build()?`.
    pub fn from_mesh(mesh: &Mesh) -> Result<Self, ClothBuildError> {
        Self::read_mesh(mesh).map_err(ClothBuildError::Mesh)
    }

    fn read_mesh(mesh: &Mesh) -> Result<Self, MeshReadError> {
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
        Ok(Self::from_triangles(positions, indices).with_welding(true))
    }

    /// Whether vertices at the same position are merged into one and the
    /// vertices renumbered for locality where that clearly helps (see
    /// [`from_mesh`](Self::from_mesh), where it is on; off for
    /// [`from_triangles`](Self::from_triangles), whose vertices keep the
    /// numbers given). No effect on grids.
    pub fn with_welding(mut self, on: bool) -> Self {
        if let Source::Triangles { weld, .. } = &mut self.source {
            *weld = on;
        }
        self
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

    /// The masses of `material`: its areal density
    /// ([`with_areal_density`](Self::with_areal_density)). Its stiffness goes
    /// to the cloth's parameters
    /// ([`ClothMaterial::spring_stiffness`](super::ClothMaterial::spring_stiffness)),
    /// or put the material on the cloth entity, which does both.
    pub fn with_material(self, material: super::ClothMaterial) -> Self {
        self.with_areal_density(material.density)
    }

    /// Mass per unit area in kg/m² ([`Mass::Areal`]): each vertex weighs a
    /// third of its triangles' mass, so the cloth weighs the same at every
    /// resolution. A vertex in no triangle, or only in triangles without
    /// area, gets no mass: [`ClothBuildError::InvalidMass`].
    pub fn with_areal_density(mut self, density: f32) -> Self {
        self.mass = Mass::Areal(density);
        self
    }

    /// One mass per vertex. For [`from_mesh`](Self::from_mesh): per vertex
    /// after welding (the mesh's order with each seam copy dropped), and the
    /// masses follow the cloth's renumbering (see
    /// [`ClothModel::welded_from`]).
    pub fn with_masses(mut self, masses: Vec<f32>) -> Self {
        self.mass = Mass::Each(masses);
        self
    }

    /// Adds shear springs: both diagonals of every cell of a
    /// [`spring_grid`](Self::spring_grid); for the lab grid and triangle
    /// meshes, the diagonal across each edge that two triangles share as
    /// their longest edge (see [`ClothTopology`]).
    pub fn with_shear_springs(mut self) -> Self {
        self.shear = true;
        self
    }

    /// Adds bending springs: skip-one neighbours along rows and columns of a
    /// [`spring_grid`](Self::spring_grid); for the lab grid and triangle
    /// meshes, a spring across every other interior edge, joining the two
    /// vertices opposite it.
    pub fn with_bending_springs(mut self) -> Self {
        self.bend = true;
        self
    }

    /// Vertices held in place: they follow the cloth entity's transform and are
    /// never moved by a solver or a collider.
    pub fn with_pins(mut self, pins: impl IntoIterator<Item = u32>) -> Self {
        self.pins = pins.into_iter().collect();
        self
    }

    /// Validates the description and builds the model.
    pub fn build(mut self) -> Result<ClothModel, ClothBuildError> {
        let mut weld_map = None;
        let source = std::mem::replace(
            &mut self.source,
            Source::Grid {
                rows: 0,
                cols: 0,
                corners: [Vec3::ZERO; 3],
            },
        );
        let (positions, triangles, springs) = match source {
            Source::Grid {
                rows,
                cols,
                corners: [o, ai, aj],
            } => {
                if rows < 2 || cols < 2 {
                    return Err(ClothBuildError::GridTooSmall { rows, cols });
                }
                let (positions, triangles) = grid_mesh(rows, cols, o, ai - o, aj - o);
                (positions, triangles, None)
            }
            Source::Triangles {
                positions,
                indices,
                weld,
            } => {
                if indices.len() % 3 != 0 {
                    return Err(ClothBuildError::IndexCountNotMultipleOf3(indices.len()));
                }
                if weld {
                    if let Some(&index) = indices.iter().find(|&&i| i as usize >= positions.len()) {
                        return Err(ClothBuildError::IndexOutOfRange {
                            index,
                            vertex_count: positions.len(),
                        });
                    }
                    if let Some(v) = positions.iter().position(|p| !p.is_finite()) {
                        return Err(ClothBuildError::NonFinitePosition { vertex: v });
                    }
                    let welded = Weld::new(&positions);
                    let tris: Vec<[u32; 3]> = indices
                        .chunks_exact(3)
                        .map(|c| [c[0], c[1], c[2]].map(|i| welded.map[i as usize]))
                        // A triangle with two corners merged has no area.
                        .filter(|[a, b, c]| a != b && b != c && a != c)
                        .collect();
                    if welded.positions.len() < positions.len() {
                        self.pins = welded.pins(&self.pins, positions.len())?;
                        weld_map = Some(welded.map.clone());
                    }
                    let mut positions = welded.positions;
                    let mut tris = tris;
                    // A mesh from a file may come in any vertex order: number
                    // the cloth's vertices for locality when that clearly helps
                    // (see `order`); `welded_from` maps through it.
                    if let Some(new_of_old) = super::order::locality_order(positions.len(), &tris) {
                        let new = |v: u32| new_of_old[v as usize];
                        let mut reordered = vec![Vec3::ZERO; positions.len()];
                        for (v, p) in positions.iter().enumerate() {
                            reordered[new_of_old[v] as usize] = *p;
                        }
                        positions = reordered;
                        for t in &mut tris {
                            *t = t.map(new);
                        }
                        weld_map = Some(match weld_map {
                            Some(map) => map.into_iter().map(new).collect(),
                            None => new_of_old.clone(),
                        });
                        // Pins and per-vertex masses were given in the welded
                        // order; out-of-range ones are left to the checks below.
                        for p in &mut self.pins {
                            if (*p as usize) < positions.len() {
                                *p = new(*p);
                            }
                        }
                        if let Mass::Each(ms) = &mut self.mass
                            && ms.len() == positions.len()
                        {
                            let mut reordered = vec![0.0; ms.len()];
                            for (v, &m) in ms.iter().enumerate() {
                                reordered[new_of_old[v] as usize] = m;
                            }
                            *ms = reordered;
                        }
                    }
                    (positions, tris, None)
                } else {
                    let tris = indices
                        .chunks_exact(3)
                        .map(|c| [c[0], c[1], c[2]])
                        .collect();
                    (positions, tris, None)
                }
            }
            Source::SpringGrid {
                rows,
                cols,
                corners,
            } => {
                if rows < 2 || cols < 2 {
                    return Err(ClothBuildError::GridTooSmall { rows, cols });
                }
                let (positions, triangles, springs) =
                    spring_grid(rows, cols, corners, self.shear, self.bend);
                (positions, triangles, Some(springs))
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
            Mass::Areal(density) => {
                if !(density.is_finite() && density > 0.0) {
                    return Err(ClothBuildError::InvalidDensity(density));
                }
                lumped_masses(&positions, &triangles, density)
            }
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
        super::check_pins(&self.pins, n)?;
        let springs = match springs {
            Some(springs) => springs,
            None => {
                // Validate before deriving springs from the triangles.
                validate_triangles(&triangles, n)?;
                let mut springs = triangle_edges(&triangles);
                if self.shear || self.bend {
                    if let Some(v) = positions.iter().position(|p| !p.is_finite()) {
                        return Err(ClothBuildError::NonFinitePosition { vertex: v });
                    }
                    springs.extend(cross_edge_springs(
                        &positions, &triangles, self.shear, self.bend,
                    ));
                }
                springs
            }
        };
        let topology = ClothTopology::new(positions, triangles, &springs)?;
        let mut model = ClothModel::from_parts(Arc::new(topology), masses, self.pins);
        model.welded_from = weld_map.map(Arc::new);
        Ok(model)
    }
}

/// Per vertex, a third of the mass (`density` times the area) of each
/// triangle it is a corner of; a corner index out of range is left to the
/// triangle checks.
pub(crate) fn lumped_masses(positions: &[Vec3], triangles: &[[u32; 3]], density: f32) -> Vec<f32> {
    let n = positions.len();
    let mut masses = vec![0.0f64; n];
    for t in triangles {
        if t.iter().any(|&i| i as usize >= n) {
            continue;
        }
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let area = 0.5 * f64::from((b - a).cross(c - a).length());
        for &i in t {
            masses[i as usize] += area * f64::from(density) / 3.0;
        }
    }
    masses.into_iter().map(|m| m as f32).collect()
}

/// A spring to build: its two vertices and its kind.
type SpringSpec = (u32, u32, SpringKind);

/// The assignment's particles, springs (in its order: x, y, shear, x bend,
/// y bend) and two render triangles per cell.
fn spring_grid(
    rows: usize,
    cols: usize,
    [x00, x01, x10, x11]: [Vec3; 4],
    shear: bool,
    bend: bool,
) -> (Vec<Vec3>, Vec<[u32; 3]>, Vec<SpringSpec>) {
    let mut positions = Vec::with_capacity(rows * cols);
    for i in 0..rows {
        let u = i as f32 / (rows - 1) as f32;
        let x0 = (1.0 - u) * x00 + u * x10;
        let x1 = (1.0 - u) * x01 + u * x11;
        for j in 0..cols {
            let v = j as f32 / (cols - 1) as f32;
            positions.push((1.0 - v) * x0 + v * x1);
        }
    }
    let k = |i: usize, j: usize| (i * cols + j) as u32;
    let mut springs = Vec::new();
    for i in 0..rows {
        for j in 0..cols - 1 {
            springs.push((k(i, j), k(i, j + 1), SpringKind::Stretch));
        }
    }
    for j in 0..cols {
        for i in 0..rows - 1 {
            springs.push((k(i, j), k(i + 1, j), SpringKind::Stretch));
        }
    }
    if shear {
        for i in 0..rows - 1 {
            for j in 0..cols - 1 {
                springs.push((k(i, j), k(i + 1, j + 1), SpringKind::Shear));
                springs.push((k(i, j + 1), k(i + 1, j), SpringKind::Shear));
            }
        }
    }
    if bend {
        for i in 0..rows {
            for j in 0..cols.saturating_sub(2) {
                springs.push((k(i, j), k(i, j + 2), SpringKind::Bend));
            }
        }
        for j in 0..cols {
            for i in 0..rows.saturating_sub(2) {
                springs.push((k(i, j), k(i + 2, j), SpringKind::Bend));
            }
        }
    }
    let mut triangles = Vec::with_capacity((rows - 1) * (cols - 1) * 2);
    for i in 0..rows - 1 {
        for j in 0..cols - 1 {
            triangles.push([k(i, j), k(i, j + 1), k(i + 1, j + 1)]);
            triangles.push([k(i, j), k(i + 1, j + 1), k(i + 1, j)]);
        }
    }
    (positions, triangles, springs)
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

/// The vertices of `mesh` whose `attribute` satisfies `select` (given the
/// value's components: one for `Float32`, four for a `Float32x4` colour),
/// in index order: pins painted in a modelling tool, e.g. every vertex whose
/// colour is red, `mesh_vertices_where(&mesh, Mesh::ATTRIBUTE_COLOR, |c| c[0] > 0.5)`.
/// The indices are the mesh's, as [`ClothBuilder::with_pins`] takes them
/// for [`ClothBuilder::from_mesh`].
pub fn mesh_vertices_where(
    mesh: &Mesh,
    attribute: MeshVertexAttribute,
    select: impl Fn(&[f32]) -> bool,
) -> Result<Vec<u32>, MeshReadError> {
    let values = match mesh.try_attribute_option(attribute.id) {
        Ok(Some(values)) => values,
        Ok(None) => return Err(MeshReadError::MissingAttribute(attribute.name)),
        Err(_) => return Err(MeshReadError::Extracted),
    };
    fn pick<const N: usize>(v: &[[f32; N]], select: impl Fn(&[f32]) -> bool) -> Vec<u32> {
        (0..v.len() as u32)
            .filter(|&i| select(&v[i as usize]))
            .collect()
    }
    Ok(match values {
        VertexAttributeValues::Float32(v) => (0..v.len() as u32)
            .filter(|&i| select(&[v[i as usize]]))
            .collect(),
        VertexAttributeValues::Float32x2(v) => pick(v, select),
        VertexAttributeValues::Float32x3(v) => pick(v, select),
        VertexAttributeValues::Float32x4(v) => pick(v, select),
        _ => return Err(MeshReadError::AttributeFormat(attribute.name)),
    })
}

/// Vertices at the same place merged: each source vertex's new index, and
/// the merged positions (the first of each place's).
struct Weld {
    map: Vec<u32>,
    positions: Vec<Vec3>,
}

impl Weld {
    /// Merges positions that round to the same point on a grid of a
    /// millionth of the bounding box's diagonal.
    fn new(positions: &[Vec3]) -> Self {
        let (lo, hi) = positions
            .iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
                (lo.min(p), hi.max(p))
            });
        let size = if lo.x <= hi.x {
            (hi - lo).length()
        } else {
            0.0
        };
        let cell = if size > 0.0 { size * 1e-6 } else { 1.0 };
        let mut first: std::collections::HashMap<[i64; 3], u32> =
            std::collections::HashMap::with_capacity(positions.len());
        let mut map = Vec::with_capacity(positions.len());
        let mut merged = Vec::with_capacity(positions.len());
        for &p in positions {
            let key = ((p - lo) / cell).round().to_array().map(|c| c as i64);
            let index = *first.entry(key).or_insert_with(|| {
                merged.push(p);
                (merged.len() - 1) as u32
            });
            map.push(index);
        }
        Self {
            map,
            positions: merged,
        }
    }

    /// Pins given as source indices, as merged indices (each once).
    fn pins(&self, pins: &[u32], source_count: usize) -> Result<Vec<u32>, ClothBuildError> {
        super::check_pins(pins, source_count)?;
        let mut merged: Vec<u32> = pins.iter().map(|&p| self.map[p as usize]).collect();
        merged.sort_unstable();
        merged.dedup();
        Ok(merged)
    }
}
