//! Edge–edge pairs, for a thickness too thin for vertex pairs alone (see
//! the [parent module](super), "Thin cloth"): two edges of the cloth that
//! share no vertex are kept on their sides of each other, apart along the
//! line between their closest points, where the vertex–triangle pairs see
//! nothing (two edges crossing with no vertex over a triangle).

use bevy::math::Vec3A;

use super::faces::{FaceSearch, parting, push};
use super::grid::{CellBox, EMPTY_BOX, bucket, cell_box, fill_table, for_each_cell};
use super::{Pass, UNTANGLE};

/// How far across the pair's normal, as a share of its least distance, the
/// closest points of two edges may lie and the pair still push: beyond it
/// the edges have slid apart (an end of one past the other), as a vertex
/// off its triangle no longer pushes.
pub(super) const ASIDE: f32 = 1.0;

/// The least squared sine of the angle between two edges that makes them
/// a pair (about 10°): nearly parallel edges cannot pass through each
/// other without an end coming over a triangle, where the vertex–triangle
/// pairs hold it.
const PARALLEL: f32 = 0.03;

/// The share of [`EDGES_SHARE`] of the thickness two neighbouring edges
/// (two or three of their ends joined by stretch or shear springs, as a
/// row and a column apart) are kept apart: enough to keep them from passing
/// through each other, not so much as to fight the springs where the cloth
/// crumples (kept half the thickness apart, a crumpled corner of the
/// stability map's thin fold stretched 4.4 % under Chebyshev, 15 % under
/// PBD, against 1.9 and 9.6 % without edge pairs).
const NEIGHBOURS: f32 = 0.1;

/// The share of the thickness two edges are kept apart: layers resting on
/// each other are held a thickness apart by the vertex–triangle pairs, and
/// their edges, crossing each other at that distance, would cost a push
/// each in every pass; the edge pairs keep two edges from passing through
/// each other where no vertex is over a triangle.
const EDGES_SHARE: f32 = 0.5;

/// Two edges kept apart.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct EdgePair {
    /// The first edge's ends, then the second's.
    pub(super) ends: [u32; 4],
    /// The unit vector from the first edge's closest point to the
    /// second's when the step began (or, for edges touching then, at its
    /// end): the side each keeps.
    pub(super) normal: Vec3A,
    /// Their least distance.
    pub(super) min: f32,
    friction: f32,
    /// How far the step could bring them closer: an edge found further
    /// than that on the other side went round the other's end, not through.
    pub(super) reach: f32,
    /// Their distance when the step began if that was below `min` (else
    /// infinite): parted gradually, as vertex pairs are.
    pub(super) overlap: f32,
}

/// The step's edge–edge pairs and the scratch of their search.
#[derive(Clone, Debug, Default)]
pub(super) struct Edges {
    pub(super) pairs: Vec<EdgePair>,
    /// The adjacency `list` was made for.
    topology: u64,
    /// The cloth's triangle edges, each once, lower end first.
    list: Vec<[u32; 2]>,
    /// Each edge's swept box grown by half the thickness (m), and in cells.
    boxes: Vec<[Vec3A; 2]>,
    cells: Vec<CellBox>,
    /// The edges in the grid: bucket `b`'s entries are
    /// `entries[starts[b]..starts[b + 1]]`, in increasing edge order.
    starts: Vec<u32>,
    entries: Vec<(u32, [i32; 3])>,
}

/// The parameters `(s, t)` of the closest points of the segments `p0–p1`
/// and `q0–q1` (Ericson, "Real-Time Collision Detection", 5.1.9; parallel
/// segments take `s = 0`).
pub(super) fn closest_points(p0: Vec3A, p1: Vec3A, q0: Vec3A, q1: Vec3A) -> (f32, f32) {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    let tiny = 1e-12 * (a + e);
    if a <= tiny && e <= tiny {
        return (0.0, 0.0);
    }
    if a <= tiny {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(r);
    if e <= tiny {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(d2);
    let denom = a * e - b * b;
    let s = if denom > 1e-6 * a * e {
        ((b * f - c * e) / denom).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let t = (b * s + f) / e;
    if t < 0.0 {
        ((-c / a).clamp(0.0, 1.0), 0.0)
    } else if t > 1.0 {
        (((b - c) / a).clamp(0.0, 1.0), 1.0)
    } else {
        (s, t)
    }
}

/// The vector from the first segment's closest point to the second's, and
/// their parameters.
#[inline]
pub(super) fn between(x: [Vec3A; 4]) -> (Vec3A, [f32; 2]) {
    let (s, t) = closest_points(x[0], x[1], x[2], x[3]);
    (x[2].lerp(x[3], t) - x[0].lerp(x[1], s), [s, t])
}

/// The weights of the four ends in the difference of the closest points at
/// parameters `[s, t]`.
#[inline]
pub(super) fn weights([s, t]: [f32; 2]) -> [f32; 4] {
    [-(1.0 - s), -s, 1.0 - t, t]
}

impl Edges {
    /// The step's pairs: each two edges of the cloth that share no vertex,
    /// are not opposite sides of a quad (all four ends joined by stretch or
    /// shear springs) and are not nearly parallel ([`PARALLEL`]), whose
    /// swept boxes, grown by a quarter of the thickness each, meet, and that
    /// are within half the thickness ([`EDGES_SHARE`]) plus what the step
    /// can bring them closer (their fastest ends' motion, a quarter more,
    /// and twice `slack`). `vertex_boxes` are the vertices'
    /// swept boxes in the frame moving at `frame`, and `inv` the inverse
    /// cell size, both from the vertex–triangle search.
    pub(super) fn find(
        &mut self,
        x: &[Vec3A],
        v: &[Vec3A],
        vertex_boxes: &[[Vec3A; 2]],
        (frame, inv): (Vec3A, f32),
        s: &FaceSearch<'_>,
    ) {
        self.pairs.clear();
        let FaceSearch {
            model,
            linked,
            dt,
            thickness,
            friction,
            slack,
        } = *s;
        let topology = model.topology();
        let id = topology.adjacency().id();
        if self.topology != id || id == 0 || self.list.is_empty() {
            self.list = topology
                .triangles()
                .iter()
                .flat_map(|&[a, b, c]| [[a, b], [b, c], [c, a]])
                .map(|[a, b]| [a.min(b), a.max(b)])
                .collect();
            self.list.sort_unstable();
            self.list.dedup();
            self.topology = id;
        }
        let n = vertex_boxes.len().min(x.len()).min(v.len());
        let (rest, pinned) = (topology.rest_positions(), model.pinned());
        // Kept apart by a share of the thickness: the vertex–triangle pairs
        // hold resting layers a thickness apart.
        let apart = EDGES_SHARE * thickness;
        let half = 0.5 * apart;
        let mut total = 0usize;
        self.boxes.clear();
        self.cells.clear();
        for &[a, b] in &self.list {
            let (a, b) = (a as usize, b as usize);
            let [lo, hi] = if a < n && b < n {
                let ([la, ha], [lb, hb]) = (vertex_boxes[a], vertex_boxes[b]);
                [la.min(lb) - half, ha.max(hb) + half]
            } else {
                [Vec3A::NAN; 2]
            };
            self.boxes.push([lo, hi]);
            match cell_box(lo, hi, inv) {
                Some((b, cells)) => {
                    total += cells;
                    self.cells.push(b);
                }
                None => self.cells.push(EMPTY_BOX),
            }
        }
        let mask = fill_table(
            &self.cells,
            total,
            &mut self.starts,
            &mut self.entries,
            |e, _, cell| (e as u32, cell),
        );
        let (list, boxes, cells) = (&self.list, &self.boxes, &self.cells);
        let (starts, entries) = (&self.starts, &self.entries);
        let pairs = &mut self.pairs;
        let motion = |j: usize| (v[j] - frame).length() * dt;
        let tiny = 1e-4 * thickness;
        for (e, &[lo, hi]) in boxes.iter().enumerate() {
            let own = list[e].map(|j| j as usize);
            if own
                .iter()
                .any(|&j| j >= n || !(x[j].is_finite() && v[j].is_finite()))
            {
                continue;
            }
            let own_motion = motion(own[0]).max(motion(own[1]));
            let mine = &cells[e];
            for_each_cell(mine, |c| {
                let k = bucket(c, mask);
                for &(f, fc) in &entries[starts[k] as usize..starts[k + 1] as usize] {
                    if f as usize <= e || fc != c {
                        continue;
                    }
                    // Tested once, in the lowest cell the two boxes share.
                    let low = &cells[f as usize][0];
                    if (0..3).any(|a| c[a] != mine[0][a].max(low[a])) {
                        continue;
                    }
                    let [flo, fhi] = boxes[f as usize];
                    if lo.cmpgt(fhi).any() || flo.cmpgt(hi).any() {
                        continue;
                    }
                    let other = list[f as usize].map(|j| j as usize);
                    let ends = [own[0], own[1], other[0], other[1]];
                    if own.iter().any(|j| other.contains(j)) || ends.iter().all(|&j| pinned[j]) {
                        continue;
                    }
                    let links = own
                        .iter()
                        .flat_map(|&a| other.iter().map(move |&b| (a, b)))
                        .filter(|&(a, b)| linked.joins(a, b))
                        .count();
                    if links >= 4 {
                        continue;
                    }
                    let now = ends.map(|j| x[j]);
                    let (d, _) = between(now);
                    let reach = apart
                        + 1.25 * (own_motion + motion(other[0]).max(motion(other[1])))
                        + 2.0 * slack;
                    let distance = d.length();
                    if distance.is_nan() || distance > reach {
                        continue;
                    }
                    let (e1, e2) = (now[1] - now[0], now[3] - now[2]);
                    if e1.cross(e2).length_squared()
                        < PARALLEL * e1.length_squared() * e2.length_squared()
                    {
                        continue;
                    }
                    // The side: where the second edge's closest point lay
                    // at the step's start, or, for edges touching then, at
                    // its end.
                    let normal = if distance > tiny {
                        d / distance
                    } else {
                        let (d, _) = between(ends.map(|j| x[j] + v[j] * dt));
                        match d.try_normalize() {
                            Some(n) if d.length() > tiny => n,
                            _ => continue,
                        }
                    };
                    let r = ends.map(|j| Vec3A::from(rest[j]));
                    let min = apart.min(between(r).0.length())
                        * if links >= 2 { NEIGHBOURS } else { 1.0 };
                    if min.is_nan() || min <= 0.0 {
                        continue;
                    }
                    pairs.push(EdgePair {
                        ends: ends.map(|j| j as u32),
                        normal,
                        min,
                        friction,
                        reach,
                        overlap: if distance < min {
                            distance
                        } else {
                            f32::INFINITY
                        },
                    });
                }
            });
        }
    }

    /// One Gauss–Seidel pass over the pairs: two edges whose closest points
    /// are nearer than their least distance along the pair's normal (or
    /// crossed to the other side), and not slid apart across it, are
    /// pushed back apart along it, each end taking its share by its weight
    /// in the closest point and its inverse mass, with Coulomb friction on
    /// the closest points' relative motion since `start`.
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

    /// Appends to `list` the pairs whose edges are within their least
    /// distance plus `skin` of each other at `x`: the others cannot push
    /// while none of their ends has moved half of `skin`.
    pub(super) fn near(&self, x: &[Vec3A], skin: f32, list: &mut Vec<u32>) {
        for (k, p) in self.pairs.iter().enumerate() {
            let Some(ends) = gather(x, p.ends) else {
                continue;
            };
            let reach = p.min + skin;
            let (lo, hi) = (ends[0].min(ends[1]) - reach, ends[0].max(ends[1]) + reach);
            if ends[2].min(ends[3]).cmpgt(hi).any() || ends[2].max(ends[3]).cmplt(lo).any() {
                continue;
            }
            if between(ends).0.length_squared() <= reach * reach {
                list.push(k as u32);
            }
        }
    }
}

/// The positions of `ends` in `x`, if all are there.
#[inline]
pub(super) fn gather(x: &[Vec3A], ends: [u32; 4]) -> Option<[Vec3A; 4]> {
    let [a, b, c, d] = ends.map(|j| x.get(j as usize).copied());
    Some([a?, b?, c?, d?])
}

/// One pair of [`Edges::resolve`]: how deep it was, as a share of its
/// least distance, if it was pushed.
#[inline]
pub(super) fn resolve_pair(
    p: &EdgePair,
    x: &mut [Vec3A],
    start: &impl Fn(usize) -> Vec3A,
    progress: [f32; 2],
    weight: &impl Fn(usize) -> f32,
) -> Option<f32> {
    let now = gather(x, p.ends)?;
    let min = p.min.min(p.overlap + UNTANGLE * p.min * progress[1]);
    let (d, along) = between(now);
    let h = d.dot(p.normal);
    if h >= min || h < -p.reach || (d - h * p.normal).length_squared() > (ASIDE * min).powi(2) {
        return None;
    }
    let came = || between(p.ends.map(|j| start(j as usize))).0.dot(p.normal) - h;
    let depth = parting(min - h, (p.min, p.overlap), progress, came);
    push(
        p.ends.map(|j| j as usize),
        weights(along),
        p.normal,
        depth,
        p.friction,
        x,
        start,
        weight,
    )?;
    Some(depth / p.min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_closest_points_are_the_least_over_a_fine_sampling() {
        let cases = [
            // Crossing at an angle, apart along z.
            [
                Vec3A::new(0.0, 0.0, 0.0),
                Vec3A::new(1.0, 0.0, 0.0),
                Vec3A::new(0.5, -0.5, 0.2),
                Vec3A::new(0.4, 0.5, 0.1),
            ],
            // One past the other's end.
            [
                Vec3A::new(0.0, 0.0, 0.0),
                Vec3A::new(1.0, 0.0, 0.0),
                Vec3A::new(1.5, -0.5, 0.3),
                Vec3A::new(1.6, 0.5, 0.3),
            ],
            // Parallel.
            [
                Vec3A::new(0.0, 0.0, 0.0),
                Vec3A::new(1.0, 0.0, 0.0),
                Vec3A::new(0.3, 0.2, 0.0),
                Vec3A::new(1.3, 0.2, 0.0),
            ],
        ];
        for x in cases {
            let (d, [s, t]) = between(x);
            assert!((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&t));
            let steps = 400;
            let mut least = f32::INFINITY;
            for i in 0..=steps {
                for j in 0..=steps {
                    let (u, w) = (i as f32 / steps as f32, j as f32 / steps as f32);
                    least = least.min(x[0].lerp(x[1], u).distance(x[2].lerp(x[3], w)));
                }
            }
            assert!(
                (d.length() - least).abs() < 5e-3,
                "{x:?}: {d} against {least}"
            );
        }
    }

    #[test]
    fn an_edge_through_another_goes_back_to_its_side() {
        // The second edge came down through the first within the step.
        let start = [
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.0, 0.0),
            Vec3A::new(0.5, 0.1, -0.5),
            Vec3A::new(0.5, 0.1, 0.5),
        ];
        let mut x = start;
        x[2].y = -0.04;
        x[3].y = -0.04;
        let edges = Edges {
            pairs: vec![EdgePair {
                ends: [0, 1, 2, 3],
                normal: Vec3A::Y,
                min: 0.02,
                friction: 0.0,
                reach: 1.0,
                overlap: f32::INFINITY,
            }],
            ..Default::default()
        };
        let before: Vec3A = x.iter().sum();
        let pass = edges.resolve(&mut x, &|i| start[i], 1.0, &|_| 1.0);
        assert_eq!(pass.touching, 1);
        let (d, _) = between(x);
        assert!((d.y - 0.02).abs() < 1e-5, "{d}");
        // Momentum kept.
        assert!(x.iter().sum::<Vec3A>().distance(before) < 1e-5);
        let again = edges.resolve(&mut x, &|i| start[i], 1.0, &|_| 1.0);
        assert!(again.deepest < 1e-3, "{again:?}");
        // Slid apart across the normal: no push.
        let mut aside = x;
        aside[2].x += 2.0;
        aside[3].x += 2.0;
        aside[2].y = -0.04;
        aside[3].y = -0.04;
        let pass = edges.resolve(&mut aside, &|i| start[i], 1.0, &|_| 1.0);
        assert_eq!(pass.touching, 0);
    }
}
