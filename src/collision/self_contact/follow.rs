//! After `stiff`'s untangling and the pass between cloths: the cloth
//! around the vertices they moved follows them ([`Follow`]).

use bevy::math::Vec3A;

use super::inverse_mass;
use crate::model::ClothModel;

/// How many rings of neighbours around the vertices an untangling moved
/// follow them.
pub(crate) const FOLLOW_RINGS: usize = 4;

/// Gauss–Seidel passes over the springs of those rings.
const FOLLOW_PASSES: usize = 8;

/// The stretch beyond its rest length the following leaves a spring
/// (shorter springs are left alone: the following only pulls).
const FOLLOW_SLACK: f32 = 0.02;

/// The cloth around the vertices [`untangle`](super::untangle) moved,
/// pulled after them (positions only, as the untangling itself); and
/// around those the pass between cloths pushed
/// ([`ClothLayers::follow`](super::ClothLayers::follow)).
///
/// The untangling moves one end of each edge through a triangle back to
/// its side, and the triangle's corners by their share, each by up to the
/// self-collision's thickness, a third of an edge or more; with their
/// neighbours where they were, their springs were stretched by that in one
/// step. Two `stiff` sheets landing on each other over a ball (32², 10 s)
/// stretched an edge 37.9 % where two edges of the lower sheet went
/// through it, 0.6 % in the step before and 1.8 % in the step after. So
/// the ends moved back are held where the untangling put them (they are
/// out of the triangle), and their neighbours, [`FOLLOW_RINGS`] rings of
/// them, the triangles' corners among them, are pulled after them: a few
/// Gauss–Seidel passes over their springs, each spring stretched more
/// than 2 % brought back to that by inverse mass, the held, pinned and
/// beyond-the-rings vertices holding. Two held vertices share the pull of
/// the spring between them (held against each other, it kept all the
/// difference of their moves). The stretch spreads over the rings
/// instead of one edge. Each spring is brought back to no less than its
/// length before the move: what the step stretched is the step's to
/// answer. With it and the pass's following, the landing's worst stretch
/// over the 10 s was 2.4 %, nothing through (5.4 % once the edge pass's
/// last bits changed: the scene is chaotic).
#[derive(Clone, Debug, Default)]
pub(crate) struct Follow {
    /// Per vertex: 0 not in the rings, 1 moved (held), 2 following;
    /// all 0 between runs.
    marks: Vec<u8>,
    /// Per marked vertex: where it was before the untangling.
    before: Vec<Vec3A>,
    /// The moved vertices, then the rings, as they were marked.
    marked: Vec<u32>,
    /// The springs of the marked vertices, sorted, and the length each
    /// is brought back to.
    springs: Vec<(u32, f32)>,
}

impl Follow {
    /// Forgets the moved vertices.
    fn clear(&mut self) {
        for &i in &self.marked {
            self.marks[i as usize] = 0;
        }
        self.marked.clear();
    }

    /// Records that the untangling moved vertex `i` of `x` from `from`:
    /// an edge's end, `held` where it was put, or a triangle's corner,
    /// which follows.
    pub(crate) fn moved(&mut self, i: usize, from: Vec3A, x: &[Vec3A], held: bool) {
        if self.marks.len() < x.len() {
            self.marks.resize(x.len(), 0);
            self.before.resize(x.len(), Vec3A::ZERO);
        }
        match self.marks[i] {
            0 => {
                self.marks[i] = if held { 1 } else { 2 };
                self.before[i] = from;
                self.marked.push(i as u32);
            }
            2 if held => self.marks[i] = 1,
            _ => {}
        }
    }

    /// Pulls the rings around the moved vertices after them; then forgets
    /// them.
    pub(crate) fn run(&mut self, model: &ClothModel, x: &mut [Vec3A]) {
        if self.marked.is_empty() {
            return;
        }
        let adjacency = model.topology().adjacency();
        let all = model.topology().springs();
        let mut ring = 0..self.marked.len();
        for _ in 0..FOLLOW_RINGS {
            let end = self.marked.len();
            for k in ring.clone() {
                let v = self.marked[k] as usize;
                for incidence in adjacency.of(v) {
                    let other = incidence.other as usize;
                    if self.marks[other] == 0 {
                        self.marks[other] = 2;
                        self.before[other] = x[other];
                        self.marked.push(other as u32);
                    }
                }
            }
            ring = end..self.marked.len();
        }
        // Each spring is brought back to 2 % over its rest length, or to
        // its length before the untangling if that was longer: the
        // following undoes what the untangling stretched, not the step.
        self.springs.clear();
        for &v in &self.marked {
            self.springs
                .extend(adjacency.of(v as usize).iter().map(|inc| (inc.spring, 0.0)));
        }
        self.springs.sort_unstable_by_key(|&(s, _)| s);
        self.springs.dedup_by_key(|&mut (s, _)| s);
        let (marks, before) = (&self.marks, &self.before);
        for (s, limit) in &mut self.springs {
            let spring = &all[*s as usize];
            let (a, b) = (spring.a as usize, spring.b as usize);
            let was = |i: usize| if marks[i] == 0 { x[i] } else { before[i] };
            *limit = was(a)
                .distance(was(b))
                .max(spring.rest_length * (1.0 + FOLLOW_SLACK));
        }
        // A moved vertex is held against its rings, but two moved by
        // different amounts share their spring's pull: held against each
        // other, the spring between them kept all of the difference.
        let weight = |i: usize, other: usize| match (marks[i], marks[other]) {
            (2, _) | (1, 1) => inverse_mass(model, i),
            _ => 0.0,
        };
        for _ in 0..FOLLOW_PASSES {
            for &(s, limit) in &self.springs {
                let spring = &all[s as usize];
                let (a, b) = (spring.a as usize, spring.b as usize);
                let (wa, wb) = (weight(a, b), weight(b, a));
                if wa + wb <= 0.0 {
                    continue;
                }
                let d = x[b] - x[a];
                let length = d.length();
                let excess = length - limit;
                if excess <= 0.0 || length <= 0.0 {
                    continue;
                }
                let pull = d * (excess / (length * (wa + wb)));
                x[a] += pull * wa;
                x[b] -= pull * wb;
            }
        }
        self.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::tests::flat_sheet;
    use crate::solver::max_stretch;

    /// A vertex in the middle of a flat 16² sheet moved a third of an
    /// edge along the sheet, as an untangling moves the end of an edge
    /// through a triangle: its springs on the far side are stretched a
    /// third. Followed, it stays where it was put, its rings come after
    /// it (the stretch spread over them: the ring beyond them is held, so
    /// some is left) and nothing beyond the rings moves.
    #[test]
    fn the_rings_around_a_moved_vertex_follow_it() {
        let n = 16;
        let (model, mut x) = flat_sheet(n);
        let h = 1.0 / (n - 1) as f32;
        let moved = 7 * n + 7;
        let start = x.clone();
        let to = x[moved] + Vec3A::new(h / 3.0, 0.0, 0.0);
        let mut follow = Follow::default();
        follow.moved(moved, x[moved], &x, true);
        x[moved] = to;
        let unfollowed = max_stretch(&model, &x);
        assert!(unfollowed > 0.3, "{unfollowed}");
        follow.run(&model, &mut x);
        assert_eq!(x[moved], to);
        let stretch = max_stretch(&model, &x);
        assert!(stretch < unfollowed / 3.0, "{stretch} from {unfollowed}");
        // The rings (each a grid step further, diagonals included).
        let reach = (FOLLOW_RINGS as f32 + 0.5) * h * core::f32::consts::SQRT_2;
        let mut followed = 0;
        for (i, (p, q)) in x.iter().zip(&start).enumerate() {
            if i != moved && p != q {
                followed += 1;
                assert!(q.distance(start[moved]) < reach, "{i} moved");
            }
        }
        assert!(followed > 8, "{followed}");
        // Forgotten: a second run moves nothing.
        let again = x.clone();
        follow.run(&model, &mut x);
        assert_eq!(x, again);
    }

    /// Springs the step left stretched are left as they were: the
    /// following only takes back what the untangling added.
    #[test]
    fn a_stretch_the_untangling_did_not_add_is_left_alone() {
        let n = 8;
        let (model, mut x) = flat_sheet(n);
        // The whole sheet stretched a tenth along x by the step.
        for p in &mut x {
            p.x *= 1.1;
        }
        let start = x.clone();
        let mut follow = Follow::default();
        // A corner of a triangle moved a little along the normal, which
        // adds almost no stretch.
        let corner = 3 * n + 3;
        follow.moved(corner, x[corner], &x, false);
        x[corner].y += 1e-3;
        follow.run(&model, &mut x);
        for (i, (p, q)) in x.iter().zip(&start).enumerate() {
            if i != corner {
                assert!(p.distance(*q) < 1e-4, "{i}: {q} to {p}");
            }
        }
    }
}
