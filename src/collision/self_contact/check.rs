//! The exact check: mesh edges through a cloth's own triangles, or
//! through another cloth's ([`count_intersections`], [`count_crossings`]),
//! on a grid of the triangles' cells.

use bevy::math::Vec3A;

use super::{MAX_CELLS, cell_of, span};
use crate::model::ClothModel;

/// A cell's key: its integer coordinates packed 21 bits each.
fn key(c: [i64; 3]) -> u64 {
    let m = (1u64 << 21) - 1;
    ((c[0] as u64) & m) | (((c[1] as u64) & m) << 21) | (((c[2] as u64) & m) << 42)
}

/// The keys of the cells (of size `1/inv`) that the box `lo..hi` overlaps,
/// or `None` if it overlaps more than [`MAX_CELLS`] (or none).
fn cells_of(lo: Vec3A, hi: Vec3A, inv: f32) -> Option<impl Iterator<Item = u64>> {
    let (lo, hi) = (cell_of(lo, inv), cell_of(hi, inv));
    (1..=MAX_CELLS).contains(&span(lo, hi)).then(|| {
        (lo[0]..=hi[0]).flat_map(move |cx| {
            (lo[1]..=hi[1]).flat_map(move |cy| (lo[2]..=hi[2]).map(move |cz| key([cx, cy, cz])))
        })
    })
}

/// Scratch of [`count_intersections`]: the triangles' cells.
#[derive(Clone, Debug, Default)]
pub struct IntersectionCheck {
    cells: Vec<(u64, u32)>,
    candidates: Vec<u32>,
    edges: Vec<(u32, u32)>,
}

/// Whether the segment `p`–`q` passes through the triangle `a, b, c`: its
/// ends strictly on opposite sides of the triangle's plane (by more than a
/// millionth of the segment's length: a segment lying in the plane, as in
/// a flat sheet, touches rather than passes) and the crossing point inside
/// the triangle or on its border.
fn segment_hits_triangle(p: Vec3A, q: Vec3A, [a, b, c]: [Vec3A; 3]) -> bool {
    let Some(n) = (b - a).cross(c - a).try_normalize() else {
        return false;
    };
    let (dp, dq) = ((p - a).dot(n), (q - a).dot(n));
    let eps = 1e-6 * p.distance(q);
    if !((dp > eps && dq < -eps) || (dp < -eps && dq > eps)) {
        return false;
    }
    let x = p + (q - p) * (dp / (dp - dq));
    let side = |u: Vec3A, w: Vec3A| (w - u).cross(x - u).dot(n) >= 0.0;
    side(a, b) && side(b, c) && side(c, a)
}

/// The exact check: how many of `model`'s mesh edges at `x` pass through
/// one of its triangles that shares no vertex with the edge (each edge
/// counted once per triangle it passes through). 0 for a surface that does
/// not pass through itself.
pub fn count_intersections(
    model: &ClothModel,
    x: &[Vec3A],
    check: &mut IntersectionCheck,
) -> usize {
    count_through((model, x), (model, x), true, check)
}

/// The exact check between two cloths: how many mesh edges of either pass
/// through a triangle of the other. 0 for two surfaces that do not pass
/// through each other.
pub fn count_crossings(
    a: (&ClothModel, &[Vec3A]),
    b: (&ClothModel, &[Vec3A]),
    check: &mut IntersectionCheck,
) -> usize {
    count_through(a, b, false, check) + count_through(b, a, false, check)
}

/// Edges of the first cloth through triangles of the second; `same` when
/// they are one cloth (an edge and a triangle sharing a vertex are then
/// not counted).
fn count_through(
    (edge_model, xe): (&ClothModel, &[Vec3A]),
    (model, x): (&ClothModel, &[Vec3A]),
    same: bool,
    check: &mut IntersectionCheck,
) -> usize {
    let triangles = model.topology().triangles();
    if triangles.is_empty()
        || x.len() < model.vertex_count()
        || xe.len() < edge_model.vertex_count()
    {
        return 0;
    }
    let corners = |t: &[u32; 3]| t.map(|v| x[v as usize]);
    // Cells of the mean edge's size.
    let mut length = 0.0f32;
    for t in triangles {
        let [a, b, c] = corners(t);
        length += a.distance(b) + b.distance(c) + c.distance(a);
    }
    let size = length / (3 * triangles.len()) as f32;
    if !(size > 0.0 && size.is_finite()) {
        return 0;
    }
    let inv = 1.0 / size;
    check.cells.clear();
    for (i, t) in triangles.iter().enumerate() {
        let [a, b, c] = corners(t);
        if let Some(keys) = cells_of(a.min(b).min(c), a.max(b).max(c), inv) {
            check.cells.extend(keys.map(|k| (k, i as u32)));
        }
    }
    check.cells.sort_unstable();
    // Each edge once.
    check.edges.clear();
    for t in edge_model.topology().triangles() {
        for (u, w) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            check.edges.push((u.min(w), u.max(w)));
        }
    }
    check.edges.sort_unstable();
    check.edges.dedup();
    let mut count = 0;
    for &(u, w) in &check.edges {
        let (p, q) = (xe[u as usize], xe[w as usize]);
        let Some(keys) = cells_of(p.min(q), p.max(q), inv) else {
            continue;
        };
        check.candidates.clear();
        for k in keys {
            let from = check.cells.partition_point(|&(c, _)| c < k);
            check.candidates.extend(
                check.cells[from..]
                    .iter()
                    .take_while(|&&(c, _)| c == k)
                    .map(|&(_, t)| t),
            );
        }
        check.candidates.sort_unstable();
        check.candidates.dedup();
        for &other in &check.candidates {
            let tri = triangles[other as usize];
            if same && (tri.contains(&u) || tri.contains(&w)) {
                continue;
            }
            if segment_hits_triangle(p, q, corners(&tri)) {
                count += 1;
            }
        }
    }
    count
}

/// Whether the ray from `from` along `direction` meets one of `model`'s
/// triangles at `x`, ahead of `from` (Möller–Trumbore; a ray in a
/// triangle's plane does not): a check that a solid thrown along `direction` has the cloth still
/// ahead of it, not passed through it.
pub fn ray_meets(model: &ClothModel, x: &[Vec3A], from: Vec3A, direction: Vec3A) -> bool {
    model.topology().triangles().iter().any(|t| {
        let [a, b, c] = t.map(|i| x[i as usize]);
        let (e1, e2) = (b - a, c - a);
        let p = direction.cross(e2);
        let det = e1.dot(p);
        if det.abs() < 1e-12 {
            return false;
        }
        let s = (from - a) / det;
        let u = s.dot(p);
        let q = s.cross(e1);
        let v = direction.dot(q);
        u >= 0.0 && v >= 0.0 && u + v <= 1.0 && e2.dot(q) > 0.0
    })
}
