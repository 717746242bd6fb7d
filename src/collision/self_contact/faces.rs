//! Vertex–triangle pairs, for a thickness too thin for vertex pairs alone
//! (see the [parent module](super), "Thin cloth"): each vertex is kept on
//! its side of every nearby triangle of its own cloth that does not hold
//! it, at least the thickness from the triangle's plane wherever it lies
//! over the triangle.

use bevy::math::Vec3A;

use super::grid::{
    CellBox, EMPTY_BOX, Linked, bucket, cell_box, fill_table, for_each_cell, mean_velocity,
};
use super::{Pass, UNTANGLE, shortest_edge};
use crate::model::ClothModel;

/// Below this share of the cloth's shortest rest edge, a thickness gets
/// vertex–triangle pairs as well as vertex pairs: about the circumradius
/// of a grid's right triangles, under which a vertex can reach a triangle's
/// middle without coming within the thickness of its corners.
pub const FACES_BELOW: f32 = 0.71;

/// How far outside a triangle, in barycentric terms, a vertex over its
/// plane still counts as over it: the cloth's triangles meet at an angle,
/// and a vertex over their shared edge is then just outside both.
pub(super) const OVER: f32 = 0.02;

/// One vertex kept off one triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct FacePair {
    pub(super) vertex: u32,
    pub(super) triangle: [u32; 3],
    /// The vertex's side of the triangle when the step began: 1 along
    /// `(b − a) × (c − a)`, −1 against.
    pub(super) side: f32,
    /// Its least distance from the triangle's plane.
    pub(super) min: f32,
    friction: f32,
    /// Its distance from the plane when the step began if that was below
    /// `min` (else infinite): parted gradually, as vertex pairs are.
    pub(super) overlap: f32,
}

/// The step's vertex–triangle pairs and the scratch of their search.
#[derive(Clone, Debug, Default)]
pub(super) struct Faces {
    pub(super) pairs: Vec<FacePair>,
    /// The adjacency `across` was made for.
    adjacency: u64,
    /// Per triangle, the vertices across its three edges (the third
    /// corners of the triangles that share an edge with it; `u32::MAX`
    /// where none).
    across: Vec<[u32; 3]>,
    /// Each vertex's swept box (m), in the frame moving at `frame`, and
    /// the grid's inverse cell size (the edge–edge search reads them).
    pub(super) vertex_boxes: Vec<[Vec3A; 2]>,
    pub(super) frame: Vec3A,
    pub(super) inv: f32,
    /// Each triangle's swept box grown by the thickness (m), and in cells.
    triangle_boxes: Vec<[Vec3A; 2]>,
    triangle_cells: Vec<CellBox>,
    /// The triangles in the grid, as in the vertex pairs' search: bucket
    /// `b`'s entries are `entries[starts[b]..starts[b + 1]]`.
    starts: Vec<u32>,
    entries: Vec<(u32, [i32; 3])>,
}

/// The signed distance of `p` from the plane of `a`, `b`, `c` (along
/// `(b − a) × (c − a)`), and that unit normal.
#[inline]
pub(super) fn plane_distance(a: Vec3A, b: Vec3A, c: Vec3A, p: Vec3A) -> Option<(f32, Vec3A)> {
    let normal = (b - a).cross(c - a).try_normalize()?;
    Some(((p - a).dot(normal), normal))
}

/// The barycentric coordinates of `p`'s projection on the plane of `a`,
/// `b`, `c` (`None` for a triangle with no area).
#[inline]
pub(super) fn barycentric(a: Vec3A, b: Vec3A, c: Vec3A, p: Vec3A) -> Option<[f32; 3]> {
    let (e0, e1, d) = (b - a, c - a, p - a);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (d.dot(e0), d.dot(e1));
    let denom = d00 * d11 - d01 * d01;
    if denom.is_nan() || denom <= 0.0 {
        return None;
    }
    let v = (d11 * d20 - d01 * d21) / denom;
    let w = (d00 * d21 - d01 * d20) / denom;
    Some([1.0 - v - w, v, w])
}

/// The distance from `p` to the closest point of the triangle `a`, `b`,
/// `c` (Ericson, "Real-Time Collision Detection", 5.1.5).
fn triangle_distance(a: Vec3A, b: Vec3A, c: Vec3A, p: Vec3A) -> f32 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return ap.length();
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return bp.length();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return (p - (a + ab * (d1 / (d1 - d3)))).length();
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return cp.length();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return (p - (a + ac * (d2 / (d2 - d6)))).length();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        let t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (p - (b + (c - b) * t)).length();
    }
    let denom = 1.0 / (va + vb + vc);
    (p - (a + ab * (vb * denom) + ac * (vc * denom))).length()
}

/// Per triangle of `triangles`, the vertices across its edges `ab`, `bc`,
/// `ca` (`u32::MAX` where no other triangle has the edge; one of them where
/// several do).
fn across(triangles: &[[u32; 3]]) -> Vec<[u32; 3]> {
    let mut edges: Vec<(u64, u32, u32)> = Vec::with_capacity(3 * triangles.len());
    for (t, &[a, b, c]) in triangles.iter().enumerate() {
        for (k, (u, w)) in [(a, b), (b, c), (c, a)].into_iter().enumerate() {
            let key = (u64::from(u.min(w)) << 32) | u64::from(u.max(w));
            edges.push((key, t as u32, k as u32));
        }
    }
    edges.sort_unstable();
    let mut out = vec![[u32::MAX; 3]; triangles.len()];
    for group in edges.chunk_by(|x, y| x.0 == y.0) {
        for &(_, t, k) in group {
            if let Some(&(_, other, j)) = group.iter().find(|e| e.1 != t) {
                // The other triangle's corner off the shared edge.
                out[t as usize][k as usize] = triangles[other as usize][(j as usize + 2) % 3];
            }
        }
    }
    out
}

/// What [`Faces::find`] reads besides the positions and velocities.
#[derive(Clone, Copy)]
pub(super) struct FaceSearch<'a> {
    pub(super) model: &'a ClothModel,
    pub(super) linked: &'a Linked,
    pub(super) dt: f32,
    pub(super) thickness: f32,
    pub(super) friction: f32,
    pub(super) slack: f32,
}

impl Faces {
    /// Whether a thickness of `thickness` needs vertex–triangle pairs on
    /// `model` ([`FACES_BELOW`]).
    pub(super) fn needed(&mut self, model: &ClothModel, thickness: f32) -> bool {
        let id = model.topology().adjacency().id();
        if self.adjacency != id || id == 0 {
            self.adjacency = id;
            self.across = across(model.topology().triangles());
        }
        super::thin_for(model, thickness)
    }

    /// The step's pairs: each vertex at `x` moving at `v` and each
    /// triangle that does not hold it and is not beside it (across one of
    /// its edges, or two of its corners joined to the vertex by a stretch
    /// or shear spring: a crease folds them onto each other) whose
    /// swept boxes meet, grown by the thickness, and that are within the
    /// thickness of each other plus what the step can bring them closer
    /// (the vertex's motion and its fastest corner's, a quarter more, and
    /// twice `slack`). None where the thickness does not need them.
    /// Returns whether it searched (and made the vertices' boxes).
    pub(super) fn find(&mut self, x: &[Vec3A], v: &[Vec3A], s: FaceSearch<'_>) -> bool {
        self.pairs.clear();
        let FaceSearch {
            model,
            linked,
            dt,
            thickness,
            friction,
            slack,
        } = s;
        if !self.needed(model, thickness) {
            return false;
        }
        let topology = model.topology();
        let (triangles, rest, pinned) = (
            topology.triangles(),
            topology.rest_positions(),
            model.pinned(),
        );
        let n = model.vertex_count().min(x.len()).min(v.len());
        if triangles.is_empty() || n < 4 {
            return false;
        }
        // Swept in the frame of the vertices' mean velocity, as the vertex
        // pairs are.
        let frame = mean_velocity(&v[..n]);
        self.vertex_boxes.clear();
        self.vertex_boxes
            .extend(x[..n].iter().zip(&v[..n]).map(|(&x, &v)| {
                let to = x + (v - frame) * dt;
                let m = slack + 0.25 * v.length() * dt;
                [x.min(to) - m, x.max(to) + m]
            }));
        // Cells of twice the shortest edge: a triangle covers a few.
        let inv = 0.5 / shortest_edge(model);
        (self.frame, self.inv) = (frame, inv);
        let mut total = 0usize;
        self.triangle_boxes.clear();
        self.triangle_cells.clear();
        for t in triangles {
            let corners = t.map(|j| j as usize);
            let (lo, hi) = if corners.iter().all(|&j| j < n) {
                corners.iter().fold(
                    (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)),
                    |(lo, hi), &j| {
                        let [l, h] = self.vertex_boxes[j];
                        (lo.min(l), hi.max(h))
                    },
                )
            } else {
                (Vec3A::NAN, Vec3A::NAN)
            };
            let (lo, hi) = (lo - thickness, hi + thickness);
            self.triangle_boxes.push([lo, hi]);
            match cell_box(lo, hi, inv) {
                Some((b, cells)) => {
                    total += cells;
                    self.triangle_cells.push(b);
                }
                None => self.triangle_cells.push(EMPTY_BOX),
            }
        }
        // The triangles' entries, counting-sorted as the vertex pairs' are.
        let mask = fill_table(
            &self.triangle_cells,
            total,
            &mut self.starts,
            &mut self.entries,
            |t, _, cell| (t as u32, cell),
        );
        let (starts, entries, across) = (&self.starts, &self.entries, &self.across);
        let (triangle_boxes, triangle_cells) = (&self.triangle_boxes, &self.triangle_cells);
        let pairs = &mut self.pairs;
        let tiny = 1e-4 * thickness;
        for (i, &[lo, hi]) in self.vertex_boxes.iter().enumerate() {
            if !(x[i].is_finite() && v[i].is_finite()) {
                continue;
            }
            let Some((cells, _)) = cell_box(lo, hi, inv) else {
                continue;
            };
            // How far the vertex and a triangle's points can move towards
            // each other in the step: each moves at most as far as its
            // corners do, plus the slack.
            let own = (v[i] - frame).length() * dt;
            for_each_cell(&cells, |c| {
                let k = bucket(c, mask);
                for &(t, tc) in &entries[starts[k] as usize..starts[k + 1] as usize] {
                    if tc != c {
                        continue;
                    }
                    // Tested once, in the lowest cell the two boxes share.
                    let low = &triangle_cells[t as usize][0];
                    if (0..3).any(|a| c[a] != cells[0][a].max(low[a])) {
                        continue;
                    }
                    let [tlo, thi] = triangle_boxes[t as usize];
                    if lo.cmpgt(thi).any() || tlo.cmpgt(hi).any() {
                        continue;
                    }
                    let triangle = triangles[t as usize];
                    let [a, b, c3] = triangle.map(|j| j as usize);
                    if triangle.contains(&(i as u32))
                        || across[t as usize].contains(&(i as u32))
                        || (pinned[i] && pinned[a] && pinned[b] && pinned[c3])
                        || [a, b, c3].iter().filter(|&&j| linked.joins(i, j)).count() >= 2
                    {
                        continue;
                    }
                    let corners = [a, b, c3]
                        .iter()
                        .map(|&j| (v[j] - frame).length())
                        .fold(0.0, f32::max)
                        * dt;
                    let reach = thickness + 1.25 * (own + corners) + 2.0 * slack;
                    if triangle_distance(x[a], x[b], x[c3], x[i]) > reach {
                        continue;
                    }
                    let end = |j: usize| x[j] + v[j] * dt;
                    let Some((h0, _)) = plane_distance(x[a], x[b], x[c3], x[i]) else {
                        continue;
                    };
                    let h1 = plane_distance(end(a), end(b), end(c3), end(i)).map_or(h0, |(h, _)| h);
                    let side = if h0.abs() > tiny {
                        h0.signum()
                    } else if h1.abs() > tiny {
                        h1.signum()
                    } else {
                        continue;
                    };
                    let r = |j: usize| Vec3A::from(rest[j]);
                    let min = thickness.min(triangle_distance(r(a), r(b), r(c3), r(i)));
                    if min.is_nan() || min <= 0.0 {
                        continue;
                    }
                    let start = h0 * side;
                    pairs.push(FacePair {
                        vertex: i as u32,
                        triangle,
                        side,
                        min,
                        friction,
                        overlap: if start < min {
                            start.max(0.0)
                        } else {
                            f32::INFINITY
                        },
                    });
                }
            });
        }
        true
    }

    /// One Gauss–Seidel pass over the pairs: a vertex over its triangle
    /// and closer to its plane than its least distance (or on the other
    /// side) is pushed back out along the triangle's normal, the triangle's
    /// corners taking their share by their barycentric weights and inverse
    /// masses, with Coulomb friction on the vertex's motion relative to the
    /// triangle's point under it since `start`.
    pub(super) fn resolve(
        &self,
        x: &mut [Vec3A],
        start: &impl Fn(usize) -> Vec3A,
        progress: f32,
        weight: &impl Fn(usize) -> f32,
    ) -> Pass {
        Pass::over(self.pairs.iter(), |p| {
            resolve_pair(p, x, start, [0.0, progress], weight)
        })
    }

    /// Appends to `list` the pairs whose vertex is within its least
    /// distance plus `skin` of its triangle at `x`: the others cannot push
    /// while none of their four vertices has moved half of `skin` (a point
    /// of the triangle moves at most as far as its corners).
    pub(super) fn near(&self, x: &[Vec3A], skin: f32, list: &mut Vec<u32>) {
        for (k, p) in self.pairs.iter().enumerate() {
            let [a, b, c] = p.triangle.map(|j| j as usize);
            let i = p.vertex as usize;
            let (Some(&xi), Some(&xa), Some(&xb), Some(&xc)) =
                (x.get(i), x.get(a), x.get(b), x.get(c))
            else {
                continue;
            };
            let reach = p.min + skin;
            // The boxes first: most pairs are far apart.
            let (lo, hi) = (xa.min(xb).min(xc) - reach, xa.max(xb).max(xc) + reach);
            if xi.cmplt(lo).any() || xi.cmpgt(hi).any() {
                continue;
            }
            if triangle_distance(xa, xb, xc, xi) <= reach {
                list.push(k as u32);
            }
        }
    }
}

/// One pair of [`Faces::resolve`]: how deep it was, as a share of its
/// least distance, if it was pushed.
#[inline]
pub(super) fn resolve_pair(
    p: &FacePair,
    x: &mut [Vec3A],
    start: &impl Fn(usize) -> Vec3A,
    progress: [f32; 2],
    weight: &impl Fn(usize) -> f32,
) -> Option<f32> {
    let i = p.vertex as usize;
    let [a, b, c] = p.triangle.map(|j| j as usize);
    let (&xi, &xa, &xb, &xc) = (x.get(i)?, x.get(a)?, x.get(b)?, x.get(c)?);
    let min = p.min.min(p.overlap + UNTANGLE * p.min * progress[1]);
    // Far enough along the unnormalised normal: no square root.
    let across = (xb - xa).cross(xc - xa) * p.side;
    let along = (xi - xa).dot(across);
    if along >= 0.0 && along * along >= min * min * across.length_squared() {
        return None;
    }
    let (h, normal) = plane_distance(xa, xb, xc, xi)?;
    let (h, normal) = (h * p.side, normal * p.side);
    if h >= min {
        return None;
    }
    let bary = barycentric(xa, xb, xc, xi)?;
    if bary.iter().any(|&u| u < -OVER) {
        return None;
    }
    let parted = || {
        let [si, sa, sb, sc] = [i, a, b, c].map(start);
        plane_distance(sa, sb, sc, si).map_or(h, |(h, _)| h * p.side)
    };
    let depth = parting(min - h, (p.min, p.overlap), progress, || parted() - h);
    let grad = [1.0, -bary[0], -bary[1], -bary[2]];
    push(
        [i, a, b, c],
        grad,
        normal,
        depth,
        p.friction,
        x,
        start,
        weight,
    )?;
    Some(depth / p.min)
}

/// How far a pair `depth` within its least distance (its full least
/// distance and its `overlap`, see [`FacePair`]) is pushed in a pass over
/// the step from `progress[0]` to `progress[1]`: all of it, but for a pair
/// that began the step overlapping, in a pass that does not begin with the
/// step (a substep of `stiff`), at most what it came closer in the pass
/// (`came()`, from the pass's start) plus its share of the step's parting
/// ([`UNTANGLE`] of its least distance, spread over the step). A pair that
/// begins to push late in the step (its vertex slid over its triangle)
/// would otherwise be pushed the whole allowance of the substeps before in
/// one: in a crumpled corner of a thin setting, 5 mm in a 1/15,360 s
/// substep, 80 m/s, and the sheet blew up.
#[inline]
pub(super) fn parting(
    depth: f32,
    (min, overlap): (f32, f32),
    [from, to]: [f32; 2],
    came: impl FnOnce() -> f32,
) -> f32 {
    if from <= 0.0 || !overlap.is_finite() {
        return depth;
    }
    depth.min(came().max(0.0) + UNTANGLE * min * (to - from))
}

/// Moves `vertices` along `normal` so that the point `Σ grad[k]·x[k]`
/// moves out by `depth`, each taking its share by its weight in that point
/// and its inverse mass (from `weight`), then Coulomb friction (`friction`)
/// on that point's motion since `start` across `normal`, up to `friction`
/// times `depth`: the position-based response of a vertex–triangle or
/// edge–edge pair. `None` (nothing moved) if none of them can move.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn push(
    vertices: [usize; 4],
    grad: [f32; 4],
    normal: Vec3A,
    depth: f32,
    friction: f32,
    x: &mut [Vec3A],
    start: &impl Fn(usize) -> Vec3A,
    weight: &impl Fn(usize) -> f32,
) -> Option<()> {
    let share = crate::collision::pushes(grad, vertices.map(weight), 1.0)?;
    let mut moved = vertices.map(|k| x[k]);
    for k in 0..4 {
        moved[k] += normal * (share[k] * depth);
    }
    if friction > 0.0 {
        // The point's motion since `start`, across the normal.
        let relative: Vec3A = (0..4)
            .map(|k| (moved[k] - start(vertices[k])) * grad[k])
            .sum();
        let tangential = relative - relative.dot(normal) * normal;
        let length = tangential.length();
        if length > 0.0 {
            let cut = (friction * depth).min(length);
            let direction = tangential / length;
            for k in 0..4 {
                moved[k] -= direction * (share[k] * cut);
            }
        }
    }
    for k in 0..4 {
        x[vertices[k]] = moved[k];
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_triangle_distance_is_the_least_over_a_fine_sampling() {
        let (a, b, c) = (
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.1, 0.0),
            Vec3A::new(0.2, 0.9, 0.3),
        );
        for p in [
            Vec3A::new(0.3, 0.3, 0.5),
            Vec3A::new(-1.0, -1.0, 0.0),
            Vec3A::new(2.0, 0.0, 0.0),
            Vec3A::new(0.1, 2.0, 0.0),
            Vec3A::new(0.7, 0.7, -0.4),
            Vec3A::new(0.5, -0.5, 0.2),
        ] {
            let mut least = f32::INFINITY;
            let steps = 400;
            for s in 0..=steps {
                for t in 0..=(steps - s) {
                    let (u, w) = (s as f32 / steps as f32, t as f32 / steps as f32);
                    least = least.min(p.distance(a + (b - a) * u + (c - a) * w));
                }
            }
            let d = triangle_distance(a, b, c, p);
            assert!((d - least).abs() < 5e-3, "{p}: {d} against {least}");
        }
    }

    #[test]
    fn a_vertex_through_its_triangle_goes_back_to_its_side() {
        let mut x = vec![
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.0, 0.0),
            Vec3A::new(0.0, 0.0, 1.0),
            // Below the triangle, having come from above.
            Vec3A::new(0.25, -0.05, 0.25),
        ];
        let start = [x[0], x[1], x[2], Vec3A::new(0.25, 0.1, 0.25)];
        let (_, normal) = plane_distance(x[0], x[1], x[2], start[3]).unwrap();
        let side = (start[3] - x[0]).dot(normal).signum();
        let faces = Faces {
            pairs: vec![FacePair {
                vertex: 3,
                triangle: [0, 1, 2],
                side,
                min: 0.02,
                friction: 0.0,
                overlap: f32::INFINITY,
            }],
            ..Default::default()
        };
        let pass = faces.resolve(&mut x, &|i| start[i], 1.0, &|_| 1.0);
        assert_eq!(pass.touching, 1);
        // Back above the plane by the least distance.
        let (h, _) = plane_distance(x[0], x[1], x[2], x[3]).unwrap();
        assert!((h * side - 0.02).abs() < 1e-5, "{h}");
        // Momentum kept: the corners moved down as the vertex moved up.
        let total: Vec3A = x.iter().sum();
        let before: Vec3A = [
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.0, 0.0),
            Vec3A::new(0.0, 0.0, 1.0),
            Vec3A::new(0.25, -0.05, 0.25),
        ]
        .iter()
        .sum();
        assert!(total.distance(before) < 1e-5);
        // A second pass finds it apart (or as near as rounding leaves it).
        let again = faces.resolve(&mut x, &|i| start[i], 1.0, &|_| 1.0);
        assert!(again.deepest < 1e-3, "{again:?}");
    }
}
