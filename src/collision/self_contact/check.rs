//! The exact check: mesh edges through a cloth's own triangles, or
//! through another cloth's ([`count_intersections`], [`count_crossings`]),
//! on a grid of the triangles' cells.

use bevy::math::Vec3A;

use super::MAX_CELLS;
use super::grid::{cell_of, span};
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
    /// The triangles' cells, `(cell, triangle)`, by hash bucket.
    cells: Vec<(u64, u32)>,
    /// Where each bucket starts in `cells` (and the end).
    starts: Vec<u32>,
    candidates: Vec<u32>,
    /// Per triangle, the last edge it was a candidate of (see
    /// `count_through`).
    stamps: Vec<u32>,
    edges: Vec<(u32, u32)>,
    /// The edges through a triangle found by [`untangle`]: the edge's ends
    /// and the triangle's index.
    found: Vec<(u32, u32, u32)>,
    /// The cloth pulled after the vertices [`untangle`] moved.
    follow: super::follow::Follow,
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
    count_through((model, x), (model, x), true, check, |_, _, _| {})
}

/// The exact check between two cloths: how many mesh edges of either pass
/// through a triangle of the other. 0 for two surfaces that do not pass
/// through each other.
pub fn count_crossings(
    a: (&ClothModel, &[Vec3A]),
    b: (&ClothModel, &[Vec3A]),
    check: &mut IntersectionCheck,
) -> usize {
    count_through(a, b, false, check, |_, _, _| {})
        + count_through(b, a, false, check, |_, _, _| {})
}

/// Edges of the first cloth through triangles of the second; `same` when
/// they are one cloth (an edge and a triangle sharing a vertex are then
/// not counted). Each is also shown to `found` (the edge's ends, the
/// triangle's index), in a fixed order.
fn count_through(
    (edge_model, xe): (&ClothModel, &[Vec3A]),
    (model, x): (&ClothModel, &[Vec3A]),
    same: bool,
    check: &mut IntersectionCheck,
    mut found: impl FnMut(u32, u32, u32),
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
    // The triangles' cells in a hash table filled by a counting sort
    // (bucket `b`'s entries are `cells[starts[b]..starts[b + 1]]`, in
    // increasing triangle order): a sort of the entries and a binary search
    // per cell looked up were most of the check.
    let boxes = |t: &[u32; 3]| {
        let [a, b, c] = corners(t);
        cells_of(a.min(b).min(c), a.max(b).max(c), inv)
    };
    let total: usize = triangles
        .iter()
        .filter_map(|t| boxes(t).map(Iterator::count))
        .sum();
    let bits = (2 * total).next_power_of_two().max(2).trailing_zeros();
    let bucket = |k: u64| (k.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (64 - bits)) as usize;
    check.starts.clear();
    check.starts.resize((1 << bits) + 1, 0);
    for t in triangles {
        for k in boxes(t).into_iter().flatten() {
            check.starts[bucket(k)] += 1;
        }
    }
    let mut sum = 0;
    for s in &mut check.starts {
        sum += *s;
        *s = sum;
    }
    check.cells.clear();
    check.cells.resize(total, (0, 0));
    for (i, t) in triangles.iter().enumerate().rev() {
        for k in boxes(t).into_iter().flatten() {
            let s = &mut check.starts[bucket(k)];
            *s -= 1;
            check.cells[*s as usize] = (k, i as u32);
        }
    }
    // Each edge once.
    check.edges.clear();
    for t in edge_model.topology().triangles() {
        for (u, w) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            check.edges.push((u.min(w), u.max(w)));
        }
    }
    check.edges.sort_unstable();
    check.edges.dedup();
    check.stamps.clear();
    check.stamps.resize(triangles.len(), 0);
    let mut stamp = 0u32;
    let mut count = 0;
    for &(u, w) in &check.edges {
        let (p, q) = (xe[u as usize], xe[w as usize]);
        let Some(keys) = cells_of(p.min(q), p.max(q), inv) else {
            continue;
        };
        // Each triangle once per edge: stamped with the edge's number.
        check.candidates.clear();
        stamp += 1;
        for k in keys {
            let b = bucket(k);
            let (from, to) = (check.starts[b] as usize, check.starts[b + 1] as usize);
            for &(_, t) in check.cells[from..to].iter().filter(|&&(c, _)| c == k) {
                let seen = &mut check.stamps[t as usize];
                if *seen != stamp {
                    *seen = stamp;
                    check.candidates.push(t);
                }
            }
        }
        // In increasing order, as the count's visitors are shown them.
        check.candidates.sort_unstable();
        let (lo, hi) = (p.min(q), p.max(q));
        for &other in &check.candidates {
            let tri = triangles[other as usize];
            if same && (tri.contains(&u) || tri.contains(&w)) {
                continue;
            }
            // Boxes apart: the crossing point would lie in both (most
            // triangles sharing a cell with the edge are not near it).
            let [a, b, c] = corners(&tri);
            if hi.cmplt(a.min(b).min(c)).any() || lo.cmpgt(a.max(b).max(c)).any() {
                continue;
            }
            if segment_hits_triangle(p, q, [a, b, c]) {
                count += 1;
                found(u, w, other);
            }
        }
    }
    count
}

/// How far past a triangle's plane `stiff`'s untangling takes the end of an edge
/// through it, as a share of the self-collision's thickness (the pairs'
/// pushes then take it the rest of the way).
pub const UNTANGLE_MARGIN: f32 = 0.25;

/// Takes `model`'s edges at `x` back out of its own triangles: for each
/// edge through a triangle that shares no vertex with it, the end nearer
/// the triangle's plane (the one that went through) is moved back to the
/// other end's side, [`UNTANGLE_MARGIN`] of `thickness` past the plane,
/// and the triangle's corners take their share of the move (by inverse
/// mass and where the end lies over the triangle), as a point–triangle
/// contact would. Vertex–vertex self-collision keeps a surface from
/// passing through itself but cannot take back an edge already through:
/// its pushes hold the end on the side it is on. The cloth around the
/// moved vertices is then pulled after them (`Follow`), so that their
/// springs do not take the whole move. Returns the edges found through
/// (before the moves).
pub(crate) fn untangle(
    model: &ClothModel,
    x: &mut [Vec3A],
    check: &mut IntersectionCheck,
    thickness: f32,
) -> usize {
    let mut found = core::mem::take(&mut check.found);
    found.clear();
    let count = count_through((model, x), (model, x), true, check, |u, w, t| {
        found.push((u, w, t));
    });
    let triangles = model.topology().triangles();
    let weight = |i: usize| super::inverse_mass(model, i);
    for &(u, w, t) in &found {
        let corners = triangles[t as usize].map(|i| i as usize);
        let ends = [u as usize, w as usize];
        let move_ = take_back(
            ends.map(|i| (x[i], weight(i))),
            corners.map(|i| (x[i], weight(i))),
            thickness,
        );
        if let Some((end, by, shifts)) = move_ {
            check.follow.moved(ends[end], x[ends[end]], x, true);
            x[ends[end]] += by;
            for (&k, shift) in corners.iter().zip(shifts) {
                check.follow.moved(k, x[k], x, false);
                x[k] += shift;
            }
        }
    }
    check.follow.run(model, x);
    check.found = found;
    count
}

/// As [`untangle`], between two cloths: the edges of each through a
/// triangle of the other are taken back out, the edge's end moved back to
/// its other end's side, [`UNTANGLE_MARGIN`] of `thickness` past the
/// triangle's plane, and the other cloth's corners taking their share.
/// The rings of a cloth whose `follow` is set are pulled after its moved
/// ends, as [`untangle`]'s are (the plugin sets it for `stiff`'s cloths;
/// see [`ClothLayers::follow`](super::ClothLayers::follow)).
/// Returns the edges found through (before the moves).
pub(crate) fn untangle_between(
    (model_a, a): (&ClothModel, &mut [Vec3A]),
    (model_b, b): (&ClothModel, &mut [Vec3A]),
    check: &mut IntersectionCheck,
    thickness: f32,
    follow: [bool; 2],
) -> usize {
    let mut first = None;
    for _ in 0..4 {
        let found = untangle_through(
            (model_b, &mut *b, follow[1]),
            (model_a, &mut *a),
            check,
            thickness,
        ) + untangle_through(
            (model_a, &mut *a, follow[0]),
            (model_b, &mut *b),
            check,
            thickness,
        );
        first.get_or_insert(found);
        if found == 0 {
            break;
        }
    }
    first.unwrap_or(0)
}

/// The edges of the first cloth through the second's triangles, taken back
/// out, its rings following if `follow` (see [`untangle_between`]).
fn untangle_through(
    (edge_model, xe, follow): (&ClothModel, &mut [Vec3A], bool),
    (model, x): (&ClothModel, &mut [Vec3A]),
    check: &mut IntersectionCheck,
    thickness: f32,
) -> usize {
    let mut found = core::mem::take(&mut check.found);
    found.clear();
    let count = count_through((edge_model, xe), (model, x), false, check, |u, w, t| {
        found.push((u, w, t));
    });
    let triangles = model.topology().triangles();
    for &(u, w, t) in &found {
        let corners = triangles[t as usize].map(|i| i as usize);
        let ends = [u as usize, w as usize];
        let move_ = take_back(
            ends.map(|i| (xe[i], super::inverse_mass(edge_model, i))),
            corners.map(|i| (x[i], super::inverse_mass(model, i))),
            thickness,
        );
        if let Some((end, by, shifts)) = move_ {
            if follow {
                check.follow.moved(ends[end], xe[ends[end]], xe, true);
            }
            xe[ends[end]] += by;
            for (&k, shift) in corners.iter().zip(shifts) {
                x[k] += shift;
            }
        }
    }
    check.follow.run(edge_model, xe);
    check.found = found;
    count
}

/// The move that takes an edge (its ends' positions and inverse masses)
/// back out of a triangle (its corners'): which end moves, by how much,
/// and each corner's share, or `None` where there is nothing to do (an
/// earlier move took it out already, a degenerate triangle, both ends
/// pinned with the corners).
fn take_back(
    ends: [(Vec3A, f32); 2],
    corners: [(Vec3A, f32); 3],
    thickness: f32,
) -> Option<(usize, Vec3A, [Vec3A; 3])> {
    let [(a, _), (b, _), (c, _)] = corners;
    let n = (b - a).cross(c - a).try_normalize()?;
    let (du, dw) = ((ends[0].0 - a).dot(n), (ends[1].0 - a).dot(n));
    // An earlier move may have taken this one out already.
    if du * dw >= 0.0 {
        return None;
    }
    let (end, d, other) = if du.abs() <= dw.abs() {
        (0, du, dw)
    } else {
        (1, dw, du)
    };
    let (at, weight) = ends[end];
    let target = UNTANGLE_MARGIN * thickness * other.signum();
    // Where the end lies over the triangle (barycentric, clamped).
    let p = at - n * d;
    let (e0, e1, e2) = (b - a, c - a, p - a);
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (e2.dot(e0), e2.dot(e1));
    let det = d00 * d11 - d01 * d01;
    if det.is_nan() || det <= 0.0 {
        return None;
    }
    let v = ((d11 * d20 - d01 * d21) / det).clamp(0.0, 1.0);
    let wc = ((d00 * d21 - d01 * d20) / det).clamp(0.0, 1.0 - v);
    let bary = [1.0 - v - wc, v, wc];
    let share: f32 = weight
        + corners
            .iter()
            .zip(bary)
            .map(|(&(_, w), s)| s * s * w)
            .sum::<f32>();
    if share.is_nan() || share <= 0.0 {
        return None;
    }
    let lambda = (target - d) / share;
    let shifts = [0, 1, 2].map(|k| -n * (lambda * bary[k] * corners[k].1));
    Some((end, n * (lambda * weight), shifts))
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
