//! Cloth topology: rest shape, triangles, springs and the vertex→spring
//! adjacency used by every gather-style solver loop.

use bevy::math::Vec3;

use super::ClothBuildError;
use super::stencil::Stencil;

/// What a spring models. Each kind has its own stiffness in
/// [`SpringStiffness`](crate::solver::SpringStiffness).
///
/// The lab's cloth has only [`Stretch`](SpringKind::Stretch) springs: the
/// unique edges of its triangles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SpringKind {
    /// An edge of the surface (triangle edges; x/y springs of a grid).
    #[default]
    Stretch,
    /// A diagonal across a quad.
    Shear,
    /// A skip-one spring that resists folding.
    Bend,
}

impl SpringKind {
    /// Every kind, in a fixed order.
    pub const ALL: [SpringKind; 3] = [SpringKind::Stretch, SpringKind::Shear, SpringKind::Bend];
}

/// A spring between vertices `a < b` with its rest length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    /// First vertex (the smaller index).
    pub a: u32,
    /// Second vertex (the larger index).
    pub b: u32,
    /// Length at rest, taken from the initial shape.
    pub rest_length: f32,
    /// What the spring models.
    pub kind: SpringKind,
}

/// One spring seen from one of its vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Incidence {
    /// Index of the spring in [`ClothTopology::springs`].
    pub spring: u32,
    /// The vertex at the other end.
    pub other: u32,
    /// `+1` if the vertex is the spring's `a`, `-1` if it is `b`: a per-spring
    /// quantity computed for `a` is gathered by `b` with this sign.
    pub sign: f32,
}

/// Vertex→spring adjacency in compressed rows: the springs of vertex `i` are
/// `incidences[offsets[i]..offsets[i + 1]]`, in increasing spring order.
///
/// Solvers compute per-spring terms once, then each vertex *gathers* its own
/// sum, so no two threads ever write the same vertex and the summation order
/// is fixed (deterministic, no atomics).
#[derive(Clone, Debug, Default)]
pub struct Adjacency {
    /// Unique per built adjacency (clones share it: same contents), so a
    /// workspace can tell that rows it copied are still these.
    id: u64,
    offsets: Vec<u32>,
    incidences: Vec<Incidence>,
    /// The same rows as bare spring indices, each row split in two: the
    /// springs whose `a` the vertex is (`offsets[i]..split[i]`), then those
    /// whose `b` it is (`split[i]..offsets[i + 1]`). The solvers' gathers
    /// read 4 bytes per incidence and add or subtract without a multiply.
    signed: Vec<u32>,
    split: Vec<u32>,
    /// When no vertex has more than 4 springs on either side (the lab's
    /// triangle grids: 3 and 3): per vertex, its start and end springs
    /// padded to 4 each with the index `springs.len()` (a gather reads a
    /// zero term there). Fixed-length gathers: no loop bounds to predict.
    padded: Vec<[[u32; 4]; 2]>,
}

/// Equal contents (the id aside).
impl PartialEq for Adjacency {
    fn eq(&self, other: &Self) -> bool {
        (
            &self.offsets,
            &self.incidences,
            &self.signed,
            &self.split,
            &self.padded,
        ) == (
            &other.offsets,
            &other.incidences,
            &other.signed,
            &other.split,
            &other.padded,
        )
    }
}

impl Adjacency {
    fn build(vertex_count: usize, springs: &[Spring]) -> Self {
        let mut counts = vec![0u32; vertex_count + 1];
        for s in springs {
            counts[s.a as usize + 1] += 1;
            counts[s.b as usize + 1] += 1;
        }
        for i in 0..vertex_count {
            counts[i + 1] += counts[i];
        }
        let offsets = counts;
        let mut fill = offsets.clone();
        let mut incidences = vec![
            Incidence {
                spring: 0,
                other: 0,
                sign: 0.0
            };
            springs.len() * 2
        ];
        for (e, s) in springs.iter().enumerate() {
            for (v, other, sign) in [(s.a, s.b, 1.0), (s.b, s.a, -1.0)] {
                let slot = &mut fill[v as usize];
                incidences[*slot as usize] = Incidence {
                    spring: e as u32,
                    other,
                    sign,
                };
                *slot += 1;
            }
        }
        let mut signed = Vec::with_capacity(incidences.len());
        let mut split = Vec::with_capacity(vertex_count);
        for i in 0..vertex_count {
            let row = &incidences[offsets[i] as usize..offsets[i + 1] as usize];
            signed.extend(
                row.iter()
                    .filter(|inc| inc.sign > 0.0)
                    .map(|inc| inc.spring),
            );
            split.push(signed.len() as u32);
            signed.extend(
                row.iter()
                    .filter(|inc| inc.sign < 0.0)
                    .map(|inc| inc.spring),
            );
        }
        let pad = springs.len() as u32;
        let mut padded = Vec::with_capacity(vertex_count);
        for i in 0..vertex_count {
            let (start, mid, end) = (
                offsets[i] as usize,
                split[i] as usize,
                offsets[i + 1] as usize,
            );
            if mid - start > 4 || end - mid > 4 {
                padded.clear();
                break;
            }
            let mut row = [[pad; 4]; 2];
            row[0][..mid - start].copy_from_slice(&signed[start..mid]);
            row[1][..end - mid].copy_from_slice(&signed[mid..end]);
            padded.push(row);
        }
        static NEXT_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        Self {
            id: NEXT_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            offsets,
            incidences,
            signed,
            split,
            padded,
        }
    }

    /// Per vertex, its start and end springs each padded to 4 with the
    /// index `springs.len()`, or `None` if some vertex has more than 4 on a
    /// side. A gather over it needs one zero term past the last spring.
    #[inline]
    pub fn padded(&self) -> Option<&[[[u32; 4]; 2]]> {
        (!self.padded.is_empty()).then_some(&self.padded[..])
    }

    /// Unique per built adjacency, shared by its clones.
    #[inline]
    pub(crate) fn id(&self) -> u64 {
        self.id
    }

    /// The springs of vertex `i` split by side: those that start at `i`
    /// (their per-spring term is added) and those that end at `i` (it is
    /// subtracted), each in increasing spring order.
    #[inline]
    pub fn by_side(&self, i: usize) -> (&[u32], &[u32]) {
        let (start, split, end) = (
            self.offsets[i] as usize,
            self.split[i] as usize,
            self.offsets[i + 1] as usize,
        );
        (&self.signed[start..split], &self.signed[split..end])
    }

    /// The springs incident to vertex `i`.
    #[inline]
    pub fn of(&self, i: usize) -> &[Incidence] {
        &self.incidences[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }

    /// Number of springs incident to vertex `i`.
    #[inline]
    pub fn degree(&self, i: usize) -> usize {
        (self.offsets[i + 1] - self.offsets[i]) as usize
    }
}

/// The immutable shape of a cloth: rest positions (in the cloth entity's local
/// space), triangles for rendering, springs and adjacency.
///
/// Shared between cloths through an `Arc` in [`ClothModel`](super::ClothModel),
/// so a hundred identical cloths store it once.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ClothTopology {
    rest_positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    springs: Vec<Spring>,
    adjacency: Adjacency,
    kind_counts: [usize; 3],
    /// Per spring kind, the stiffness per spring of one N/m of sheet
    /// modulus (see [`ClothMaterial`](super::ClothMaterial)).
    sheet: [f32; 3],
    /// Per spring kind, the mean rest length (0 for a kind it lacks).
    mean_rest: [f32; 3],
    /// The shortest triangle edge at rest (`∞` without triangles).
    shortest_edge: f32,
    /// The springs as offset families, when they form a stencil (a grid
    /// numbered row by row): what the implicit iteration's
    /// structure-of-arrays kernels run on.
    stencil: Option<Stencil>,
}

impl ClothTopology {
    /// Builds a topology from rest positions, triangles (for rendering and
    /// normals) and springs `(a, b, kind)`, kept in the order given; a spring
    /// joining a pair that an earlier spring already joins is dropped.
    pub(crate) fn new(
        rest_positions: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        spring_list: &[(u32, u32, SpringKind)],
    ) -> Result<Self, ClothBuildError> {
        let n = rest_positions.len();
        if n == 0 {
            return Err(ClothBuildError::NoVertices);
        }
        if let Some(v) = rest_positions.iter().position(|p| !p.is_finite()) {
            return Err(ClothBuildError::NonFinitePosition { vertex: v });
        }
        validate_triangles(&triangles, n)?;
        let mut keys: Vec<(u32, u32, usize)> = Vec::with_capacity(spring_list.len());
        for (order, &(p, q, _)) in spring_list.iter().enumerate() {
            for i in [p, q] {
                if i as usize >= n {
                    return Err(ClothBuildError::IndexOutOfRange {
                        index: i,
                        vertex_count: n,
                    });
                }
            }
            if p == q {
                return Err(ClothBuildError::ZeroLengthEdge { a: p, b: q });
            }
            keys.push((p.min(q), p.max(q), order));
        }
        keys.sort_unstable();
        let mut keep = vec![false; spring_list.len()];
        for (k, key) in keys.iter().enumerate() {
            if k == 0 || (keys[k - 1].0, keys[k - 1].1) != (key.0, key.1) {
                keep[key.2] = true;
            }
        }

        let mut springs = Vec::with_capacity(spring_list.len());
        for (&(p, q, kind), _) in spring_list.iter().zip(&keep).filter(|(_, k)| **k) {
            let (a, b) = (p.min(q), p.max(q));
            let rest_length = rest_positions[a as usize].distance(rest_positions[b as usize]);
            if rest_length <= 0.0 || rest_length.is_nan() {
                return Err(ClothBuildError::ZeroLengthEdge { a, b });
            }
            springs.push(Spring {
                a,
                b,
                rest_length,
                kind,
            });
        }
        let adjacency = Adjacency::build(n, &springs);
        let mut kind_counts = [0; 3];
        for s in &springs {
            kind_counts[s.kind as usize] += 1;
        }
        let stencil = Stencil::build(n, &springs);
        let area: f64 = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| rest_positions[i as usize]);
                0.5 * f64::from((b - a).cross(c - a).length())
            })
            .sum();
        let sheet = super::material::sheet_factors(area as f32, &springs);
        let mut rest_sums = [0.0f64; 3];
        for s in &springs {
            rest_sums[s.kind as usize] += f64::from(s.rest_length);
        }
        let mean_rest = [0, 1, 2].map(|k| {
            if kind_counts[k] > 0 {
                (rest_sums[k] / kind_counts[k] as f64) as f32
            } else {
                0.0
            }
        });
        let shortest_edge = triangles
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(a, b)| rest_positions[a as usize].distance(rest_positions[b as usize]))
            .filter(|&l| l > 0.0)
            .fold(f32::INFINITY, f32::min);
        Ok(Self {
            rest_positions,
            triangles,
            springs,
            adjacency,
            kind_counts,
            sheet,
            mean_rest,
            shortest_edge,
            stencil,
        })
    }

    /// Per spring kind (indexed by `SpringKind as usize`), the stiffness
    /// per spring that gives the sheet a mean modulus of 1 N/m:
    /// `A/((3/8)·Σ L²)` over the springs of that kind, `A` the rest
    /// triangles' area (1 for a kind the cloth does not have). See
    /// [`ClothMaterial`](super::ClothMaterial).
    #[inline]
    pub fn sheet_factors(&self) -> [f32; 3] {
        self.sheet
    }

    /// Number of vertices.
    #[inline]
    pub fn vertex_count(&self) -> usize {
        self.rest_positions.len()
    }

    /// Rest positions in the cloth's local space.
    #[inline]
    pub fn rest_positions(&self) -> &[Vec3] {
        &self.rest_positions
    }

    /// Triangles (counter-clockwise as given), for rendering and normals.
    #[inline]
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Springs: the unique triangle edges first, then any extra springs.
    #[inline]
    pub fn springs(&self) -> &[Spring] {
        &self.springs
    }

    /// Vertex→spring adjacency.
    #[inline]
    pub fn adjacency(&self) -> &Adjacency {
        &self.adjacency
    }

    /// The springs as offset families, if they form a stencil.
    pub(crate) fn stencil(&self) -> Option<&Stencil> {
        self.stencil.as_ref()
    }

    /// The mean rest length of each spring kind, in [`SpringKind::ALL`]
    /// order (0 for a kind the cloth lacks).
    #[inline]
    pub fn mean_rest_lengths(&self) -> [f32; 3] {
        self.mean_rest
    }

    /// The shortest triangle edge at rest, zero-length edges left out (`∞`
    /// for a cloth without triangles): what bounds a
    /// [`SelfCollision`](crate::SelfCollision)'s thickness.
    #[inline]
    pub fn shortest_edge(&self) -> f32 {
        // (A default topology has no triangles and a zero here.)
        if self.triangles.is_empty() {
            f32::INFINITY
        } else {
            self.shortest_edge
        }
    }

    /// How many springs of each kind, in [`SpringKind::ALL`] order.
    #[inline]
    pub fn spring_counts(&self) -> [usize; 3] {
        self.kind_counts
    }
}

pub(crate) fn validate_triangles(triangles: &[[u32; 3]], n: usize) -> Result<(), ClothBuildError> {
    for (t, tri) in triangles.iter().enumerate() {
        for &i in tri {
            if i as usize >= n {
                return Err(ClothBuildError::IndexOutOfRange {
                    index: i,
                    vertex_count: n,
                });
            }
        }
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            return Err(ClothBuildError::DegenerateTriangle { triangle: t });
        }
    }
    Ok(())
}

/// The unique edges of `triangles` as stretch springs, sorted by `(a, b)`
/// with `a < b` — the lab's edge list. Triangles must be valid.
pub(crate) fn triangle_edges(triangles: &[[u32; 3]]) -> Vec<(u32, u32, SpringKind)> {
    let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(triangles.len() * 3);
    for tri in triangles {
        for (p, q) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
            pairs.push((p.min(q), p.max(q)));
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
        .into_iter()
        .map(|(a, b)| (a, b, SpringKind::Stretch))
        .collect()
}

/// Shear and bending springs of a general triangle mesh, from neighbouring
/// triangles: across each interior edge shared by exactly two triangles, a
/// spring joins the two vertices opposite the edge. It is a **shear** spring
/// when the shared edge is the longest edge of both triangles (the two
/// triangles then form a quad and the edge is one of its diagonals, so the
/// new spring is the other diagonal), and a **bending** spring otherwise (it
/// spans the fold along the edge). On a triangulated grid this gives exactly
/// the second diagonal of every cell as shear, and a spring across every
/// side edge as bending. Only the kinds asked for are returned, sorted by
/// `(kind, a, b)`.
pub(crate) fn cross_edge_springs(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    shear: bool,
    bend: bool,
) -> Vec<(u32, u32, SpringKind)> {
    // (edge a, edge b, opposite vertex, edge is the triangle's longest)
    let mut sides: Vec<(u32, u32, u32, bool)> = Vec::with_capacity(triangles.len() * 3);
    for tri in triangles {
        let len = |p: u32, q: u32| positions[p as usize].distance_squared(positions[q as usize]);
        let lengths = [
            len(tri[0], tri[1]),
            len(tri[1], tri[2]),
            len(tri[2], tri[0]),
        ];
        let longest = lengths.iter().copied().fold(0.0, f32::max);
        for k in 0..3 {
            let (p, q, o) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
            sides.push((p.min(q), p.max(q), o, lengths[k] >= longest));
        }
    }
    sides.sort_unstable_by_key(|&(a, b, o, _)| (a, b, o));
    let mut out = Vec::new();
    let mut k = 0;
    while k < sides.len() {
        let mut end = k + 1;
        while end < sides.len() && (sides[end].0, sides[end].1) == (sides[k].0, sides[k].1) {
            end += 1;
        }
        if end - k == 2 {
            let (c, d) = (sides[k].2, sides[k + 1].2);
            let kind = if sides[k].3 && sides[k + 1].3 {
                SpringKind::Shear
            } else {
                SpringKind::Bend
            };
            let wanted = match kind {
                SpringKind::Shear => shear,
                _ => bend,
            };
            if wanted && c != d {
                out.push((c.min(d), c.max(d), kind));
            }
        }
        k = end;
    }
    out.sort_unstable_by_key(|&(a, b, kind)| (kind, a, b));
    out.dedup_by_key(|&mut (a, b, _)| (a, b));
    out
}
