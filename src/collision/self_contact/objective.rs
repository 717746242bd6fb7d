//! The step's pairs as terms of an implicit method's objective: each pair
//! closer than its least distance `min` costs `½c(min − l)²`, `l` its
//! distance along the line between them at the step's start (a half-space
//! per pair: an end that passed the other within the step is pushed back,
//! and the term's Hessian is exactly `c·nnᵀ`), so Newton's iteration
//! (`newton`, `exact`) and projective dynamics' (`pd`) keep the layers
//! apart *inside* their solve, where their stiff springs can follow,
//! instead of only in the pushes after their step (which a stiff method's
//! springs undo and fight: the stability map's folded sheet went through
//! itself, 377 edges with `newton`, stretched past 100 %). A thin
//! setting's vertex–triangle pairs are terms too, and for Newton's methods
//! its edge–edge pairs ([`SideTerm`]).

use bevy::math::{DMat3, DVec3, Vec3A};

use super::{SelfCollisionInput, SelfContacts, UNTANGLE};
use crate::model::{ClothModel, ClothState};

/// A position in `f32` (the plugin's state, projective dynamics) or `f64`
/// (Newton's iterate).
pub(crate) trait Position: Copy {
    /// In `f64`.
    fn f64(self) -> DVec3;
}

impl Position for DVec3 {
    #[inline]
    fn f64(self) -> DVec3 {
        self
    }
}

impl Position for Vec3A {
    #[inline]
    fn f64(self) -> DVec3 {
        self.as_dvec3()
    }
}

/// One pair's other end: a vertex of the cloth (an unknown of the solve),
/// or another cloth's vertex, which stands still through the step.
#[derive(Clone, Copy, Debug)]
pub(crate) enum PairEnd {
    /// The cloth's own vertex.
    Own(usize),
    /// Another cloth's vertex, where it was at the step's start.
    Fixed(DVec3),
}

/// A pair of the step as a term of the objective.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PairTerm {
    /// The cloth's vertex.
    pub a: usize,
    /// The other end.
    pub b: PairEnd,
    /// The distance below which the term pushes: the pair's least distance,
    /// or, for a pair already closer than that at the step's start, that
    /// distance plus [`UNTANGLE`] of it (parted gradually, as the
    /// position-based pass parts it).
    pub min: f64,
    /// The unit vector from `b` to `a` at the step's start, if they were
    /// apart.
    pub normal: Option<DVec3>,
}

/// A vertex–triangle or edge–edge pair of a thin setting (see the [parent
/// module](super), "Thin cloth") as a term of the objective: the
/// separation `d = Σ wₖxₖ` of its four ends (a vertex over the point under
/// it of a triangle: weights 1 and minus the barycentric ones; two edges:
/// the second's closest point less the first's), with weights and a
/// side-signed unit normal `n` frozen at the step's start, has height
/// `C = d·n`, which costs `½c(min − C)²` below `min`: a half-space in the
/// positions, convex and smooth, its Hessian exactly `c·ggᵀ`, `gₖ = wₖn`.
/// (Cut off where the vertex is more than twice `min` from that point, as a
/// vertex pair is, `exact` failed to converge on a 32² sheet folded at 0.3
/// of its edges.) An edge pair also stops pushing where the edges went
/// round each other (further below than the step could bring them, or slid
/// apart across the normal), as the pass after the step does.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SideTerm {
    /// The four ends.
    ends: [usize; 4],
    /// Their weights in the separation.
    weights: [f64; 4],
    /// The side-signed unit normal at the step's start.
    normal: DVec3,
    /// The least height, as [`PairTerm::min`].
    min: f64,
    /// The height below which the pair went round, not through (−∞ for a
    /// vertex over a triangle).
    floor: f64,
    /// The most the separation may lie across the normal (∞ for a vertex
    /// over a triangle).
    aside: f64,
}

/// The step's pair terms at stiffness `c` (a penalty's, per metre), and
/// the search that finds them.
#[derive(Clone, Debug, Default)]
pub(crate) struct PairTerms {
    /// The terms.
    pub terms: Vec<PairTerm>,
    /// A thin setting's vertex–triangle terms, and (for Newton's methods,
    /// [`update`](Self::update)'s `edges`) its edge–edge ones.
    sides: Vec<SideTerm>,
    /// Their stiffness.
    pub c: f64,
    /// The pair search, its list kept from step to step while the cloth
    /// moves slowly (the terms push only where a pair is closer than its
    /// `min`, so the list's extra pairs cost a distance each).
    search: SelfContacts,
}

impl PairTerm {
    /// The other end, if it is the cloth's own vertex.
    pub(crate) fn own_b(&self) -> Option<usize> {
        match self.b {
            PairEnd::Own(b) => Some(b),
            PairEnd::Fixed(_) => None,
        }
    }
}

impl PairTerms {
    /// The step's terms at stiffness `c` for `model` at `state`, stepped
    /// by `dt`: the pairs [`SelfContacts::find_or_keep`] finds (each swept
    /// box grown by `slack`, m, for what the step's forces add to the
    /// velocities' path), or none
    /// without self-collision, a thin setting's vertex–triangle pairs
    /// whose vertex is over its triangle at the step's start, and with
    /// `edges` its edge–edge pairs (Newton's methods, whose Hessian takes
    /// their blocks; projective dynamics' global matrix does not, and they
    /// run after its step).
    pub(crate) fn update(
        &mut self,
        model: &ClothModel,
        state: &ClothState,
        (dt, slack): (f64, f32),
        sc: Option<SelfCollisionInput<'_>>,
        c: f64,
        edges: bool,
    ) {
        self.c = c;
        self.terms.clear();
        self.sides.clear();
        let Some(sc) = sc else {
            return;
        };
        let contacts = &mut self.search;
        let (x, v) = (&state.positions, &state.velocities);
        contacts.find_or_keep(model, x, v, dt as f32, sc, slack, true);
        self.sides
            .extend(contacts.faces.pairs.iter().filter_map(|p| {
                let i = p.vertex as usize;
                let corners = p.triangle.map(|j| j as usize);
                let [a, b, c] = corners.map(|j| x.get(j).copied());
                let (xi, xa, xb, xc) = (x.get(i).copied()?, a?, b?, c?);
                let weights = super::faces::barycentric(xa, xb, xc, xi)?;
                if weights.iter().any(|&w| w < -super::faces::OVER) {
                    return None;
                }
                let (_, normal) = super::faces::plane_distance(xa, xb, xc, xi)?;
                let [a, b, c] = corners;
                let [wa, wb, wc] = weights.map(|w| -f64::from(w));
                Some(SideTerm {
                    ends: [i, a, b, c],
                    weights: [1.0, wa, wb, wc],
                    normal: (normal * p.side).as_dvec3(),
                    min: f64::from(p.min.min(p.overlap + UNTANGLE * p.min)),
                    floor: f64::NEG_INFINITY,
                    aside: f64::INFINITY,
                })
            }));
        if edges {
            self.sides
                .extend(contacts.edges.pairs.iter().filter_map(|p| {
                    let ends = p.ends.map(|j| j as usize);
                    let at = ends.map(|j| x.get(j).copied());
                    let at = [at[0]?, at[1]?, at[2]?, at[3]?];
                    let (_, params) = super::edges::between(at);
                    let min = p.min.min(p.overlap + UNTANGLE * p.min);
                    Some(SideTerm {
                        ends,
                        weights: super::edges::weights(params).map(f64::from),
                        normal: p.normal.as_dvec3(),
                        min: f64::from(min),
                        floor: -f64::from(p.reach),
                        aside: f64::from(super::edges::ASIDE * min),
                    })
                }));
        }
        let own = contacts.own;
        self.terms.extend(contacts.pairs.iter().map(|p| {
            let (a, b) = (p.a as usize, p.b as usize);
            let b = if b < own {
                PairEnd::Own(b)
            } else {
                PairEnd::Fixed(contacts.others[b - own].position.as_dvec3())
            };
            let xb = match b {
                PairEnd::Own(b) => x.get(b).map(|p| p.as_dvec3()),
                PairEnd::Fixed(p) => Some(p),
            };
            let normal = x
                .get(a)
                .zip(xb)
                .and_then(|(xa, xb)| (xa.as_dvec3() - xb).try_normalize());
            PairTerm {
                a,
                b,
                min: f64::from(p.min.min(p.overlap + UNTANGLE * p.min)),
                normal,
            }
        }));
    }

    /// Each pushing term at `x`: `(a, b, n, l, min)`, with `n` the unit
    /// vector from `b` to `a` at the step's start and `l` their distance
    /// along it; for a pair that started on one point, `n` at `x` and `l`
    /// the distance (skipped where the two coincide).
    fn pushing<'s, P: Position + 's>(
        &'s self,
        x: &'s [P],
    ) -> impl Iterator<Item = (usize, Option<usize>, DVec3, f64, f64)> + 's {
        self.terms.iter().filter_map(move |t| {
            let (b, xb) = match t.b {
                PairEnd::Own(b) => (Some(b), x.get(b)?.f64()),
                PairEnd::Fixed(p) => (None, p),
            };
            let d = x.get(t.a)?.f64() - xb;
            let l2 = d.length_squared();
            // Along the pair's direction at the step's start: an end that
            // went past the other within the step is pushed back to its
            // own side, not on through (the direction at the iterate
            // would push it on: a 64² sheet folded in four went through
            // itself on landing, 827 edges with `newton`, none this way).
            // Only pairs still within twice their least distance.
            if let Some(n) = t.normal {
                let along = d.dot(n);
                if along >= t.min || l2 >= 4.0 * t.min * t.min {
                    return None;
                }
                return Some((t.a, b, n, along, t.min));
            }
            if l2 >= t.min * t.min {
                return None;
            }
            let l = l2.sqrt();
            let n = d.try_normalize()?;
            Some((t.a, b, n, l, t.min))
        })
    }

    /// Each pushing side term at `x`: the term and its height `C`.
    fn sides_pushing<'s, P: Position + 's>(
        &'s self,
        x: &'s [P],
    ) -> impl Iterator<Item = (&'s SideTerm, f64)> + 's {
        self.sides.iter().filter_map(move |t| {
            let mut d = DVec3::ZERO;
            for (&k, &w) in t.ends.iter().zip(&t.weights) {
                d += x.get(k)?.f64() * w;
            }
            let height = d.dot(t.normal);
            let pushes = height < t.min
                && height >= t.floor
                && (d - height * t.normal).length_squared() <= t.aside * t.aside;
            pushes.then_some((t, height))
        })
    }

    /// Their energy at `x`.
    pub(crate) fn energy(&self, x: &[impl Position]) -> f64 {
        self.pushing(x)
            .map(|(.., l, min)| 0.5 * self.c * (min - l) * (min - l))
            .sum::<f64>()
            + self
                .sides_pushing(x)
                .map(|(t, h)| 0.5 * self.c * (t.min - h) * (t.min - h))
                .sum::<f64>()
    }

    /// Adds their gradient at `x` through `add(vertex, gradient)`.
    pub(crate) fn gradient(&self, x: &[impl Position], mut add: impl FnMut(usize, DVec3)) {
        for (a, b, n, l, min) in self.pushing(x) {
            let g = n * (self.c * (min - l));
            add(a, -g);
            if let Some(b) = b {
                add(b, g);
            }
        }
        for (t, h) in self.sides_pushing(x) {
            let g = t.normal * (self.c * (t.min - h));
            for (&k, &w) in t.ends.iter().zip(&t.weights) {
                add(k, -g * w);
            }
        }
    }

    /// The pairs of the cloth's own vertices their terms couple (a vertex
    /// pair's two ends; a side term's four), into `out`
    /// (cleared): the blocks beyond the springs' that their Hessian
    /// ([`hessian`](Self::hessian)) fills.
    pub(crate) fn couplings(&self, out: &mut Vec<(u32, u32)>) {
        out.clear();
        out.extend(
            self.terms
                .iter()
                .filter_map(|t| Some((t.a as u32, t.own_b()? as u32))),
        );
        for t in &self.sides {
            let [v, a, b, c] = t.ends.map(|k| k as u32);
            out.extend([(v, a), (v, b), (v, c), (a, b), (a, c), (b, c)]);
        }
    }

    /// Adds their Hessian at `x` through `add(i, j, block)`, block `(i, j)`
    /// of vertices `i` and `j` (`i == j` on the diagonal; each off-diagonal
    /// block once in each order). A term's Hessian is `c·ggᵀ`, `g` its
    /// constraint's gradient: for a vertex pair `c·nnᵀ` on both ends'
    /// diagonals and `−c·nnᵀ` across (for a pair that started on one point,
    /// its negative part across the direction dropped: positive
    /// semi-definite); for a side term `wₖwₗ·c·nnᵀ` between its ends `k`
    /// and `l`. With the blocks across, Newton's
    /// direction moves a pair's two ends together freely (with only the
    /// diagonal ones it saw each end held by the other, `2c` where the term
    /// has none, and crawled: `exact` stopped at its 100 iterations in 7 %
    /// of a two-sheet scene's steps, each taking a hundredth of what was
    /// left).
    pub(crate) fn hessian(&self, x: &[impl Position], mut add: impl FnMut(usize, usize, DMat3)) {
        for (a, b, n, ..) in self.pushing(x) {
            let block = DMat3::from_cols(n * n.x, n * n.y, n * n.z) * self.c;
            add(a, a, block);
            if let Some(b) = b {
                add(b, b, block);
                add(a, b, -block);
                add(b, a, -block);
            }
        }
        for (t, _) in self.sides_pushing(x) {
            let n = t.normal;
            let block = DMat3::from_cols(n * n.x, n * n.y, n * n.z) * self.c;
            for (&i, &wi) in t.ends.iter().zip(&t.weights) {
                for (&j, &wj) in t.ends.iter().zip(&t.weights) {
                    add(i, j, block * (wi * wj));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `g` is `t`'s energy's gradient at `x` (central differences).
    fn assert_gradient_is_energys(t: &PairTerms, x: &[DVec3], g: &[DVec3]) {
        let h = 1e-6;
        for i in 0..x.len() {
            for k in 0..3 {
                let (mut plus, mut minus) = (x.to_vec(), x.to_vec());
                plus[i][k] += h;
                minus[i][k] -= h;
                let numeric = (t.energy(&plus) - t.energy(&minus)) / (2.0 * h);
                assert!(
                    (numeric - g[i][k]).abs() < 1e-6,
                    "{i} {k}: {numeric} {}",
                    g[i][k]
                );
            }
        }
    }

    /// `t`'s Hessian at `x` as blocks `[i][j]`.
    fn hessian<const N: usize>(t: &PairTerms, x: &[DVec3; N]) -> [[DMat3; N]; N] {
        let mut blocks = [[DMat3::ZERO; N]; N];
        t.hessian(x, |i, j, b| blocks[i][j] += b);
        blocks
    }

    /// `t`'s Hessian at `x` is its gradient's derivative (central
    /// differences): for terms that are half-spaces in the positions.
    fn assert_hessian_is_gradients<const N: usize>(t: &PairTerms, x: &[DVec3; N]) {
        let blocks = hessian(t, x);
        let h = 1e-6;
        for j in 0..N {
            for k in 0..3 {
                let at = |s: f64| {
                    let mut y = *x;
                    y[j][k] += s * h;
                    let mut g = [DVec3::ZERO; N];
                    t.gradient(&y, |i, v| g[i] += v);
                    g
                };
                let (plus, minus) = (at(1.0), at(-1.0));
                for i in 0..N {
                    let numeric = (plus[i] - minus[i]) / (2.0 * h);
                    let column = blocks[i][j].col(k);
                    assert!(
                        (numeric - column).abs().max_element() < 1e-6 * t.c.max(1.0),
                        "({i}, {j}) column {k}: {numeric} {column}"
                    );
                }
            }
        }
    }

    fn terms() -> PairTerms {
        PairTerms {
            terms: vec![
                PairTerm {
                    a: 0,
                    b: PairEnd::Own(1),
                    min: 0.5,
                    normal: None,
                },
                PairTerm {
                    a: 2,
                    b: PairEnd::Fixed(DVec3::new(0.0, 0.3, 0.1)),
                    min: 0.4,
                    normal: None,
                },
                // Started with `a` above `b` (along y).
                PairTerm {
                    a: 3,
                    b: PairEnd::Own(4),
                    min: 0.3,
                    normal: Some(DVec3::Y),
                },
            ],
            c: 7.0,
            ..PairTerms::default()
        }
    }

    /// The gradient is the energy's (central differences), and a pair
    /// farther apart than its `min` costs and pushes nothing.
    #[test]
    fn the_gradient_is_the_energys_and_apart_pairs_cost_nothing() {
        let t = terms();
        // `a` = 3 went below `b` = 4 within the step.
        let x = [
            DVec3::new(0.1, 0.0, 0.0),
            DVec3::new(0.3, 0.2, -0.1),
            DVec3::new(0.0, 0.1, 0.2),
            DVec3::new(2.0, -0.05, 0.02),
            DVec3::new(2.01, 0.0, 0.0),
        ];
        assert!(t.energy(&x) > 0.0);
        let mut g = [DVec3::ZERO; 5];
        t.gradient(&x, |i, v| g[i] += v);
        // The crossed pair is pushed back to its sides: `a` up, `b` down
        // (a descent moves against the gradient).
        assert!(g[3].y < 0.0 && g[4].y > 0.0, "{g:?}");
        assert!((g[3] + g[4]).length() < 1e-12);
        assert_gradient_is_energys(&t, &x, &g);
        // The Hessian: `c·nnᵀ` on both ends of each own pair, one end of
        // the fixed one, `−c·nnᵀ` across the own pairs (and nothing else).
        let blocks = hessian(&t, &x);
        for (i, row) in blocks.iter().enumerate() {
            let b = row[i];
            assert!((b.x_axis.x + b.y_axis.y + b.z_axis.z - t.c).abs() < 1e-12);
        }
        assert_eq!(blocks[3][3].y_axis.y, t.c);
        for (a, b) in [(0, 1), (1, 0), (3, 4), (4, 3)] {
            assert!((blocks[a][b] + blocks[a][a]).abs_diff_eq(DMat3::ZERO, 1e-12));
        }
        assert_eq!(blocks[2][2 + 1], DMat3::ZERO);
        // The pair that started apart is a half-space: its blocks are the
        // gradient's derivative.
        let crossed = PairTerms {
            terms: vec![t.terms[2]],
            ..t.clone()
        };
        assert_hessian_is_gradients(&crossed, &x);
        let mut couplings = Vec::new();
        t.couplings(&mut couplings);
        assert_eq!(couplings, [(0, 1), (3, 4)]);
        let apart = [
            DVec3::ZERO,
            DVec3::X,
            DVec3::new(0.0, 0.3, 0.6),
            DVec3::new(2.0, 0.4, 0.0),
            DVec3::new(2.0, 0.0, 0.0),
        ];
        assert_eq!(t.energy(&apart), 0.0);
        t.gradient(&apart, |_, _| panic!("an apart pair pushed"));
        t.hessian(&apart, |_, _, _| panic!("an apart pair has a Hessian"));
    }

    /// An edge pair's term: two crossing edges, the second above the
    /// first at the step's start (weights at their closest points, the
    /// middles): its gradient is its energy's and its Hessian the
    /// gradient's derivative while the second is below `min` over the
    /// first; it pushes nothing where the second went further below than
    /// the step could bring it (round the first, not through) or slid off
    /// across the normal.
    #[test]
    fn an_edge_pairs_term_is_a_half_space_cut_off_where_the_edges_went_round() {
        let t = PairTerms {
            sides: vec![SideTerm {
                ends: [0, 1, 2, 3],
                weights: [-0.5, -0.5, 0.5, 0.5],
                normal: DVec3::Z,
                min: 0.1,
                floor: -0.2,
                aside: 0.1,
            }],
            c: 7.0,
            ..PairTerms::default()
        };
        let at = |h: f64, across: f64| {
            [
                DVec3::new(0.0, 0.0, 0.0),
                DVec3::new(1.0, 0.0, 0.0),
                DVec3::new(0.5 + across, -0.5, h),
                DVec3::new(0.5 + across, 0.5, h),
            ]
        };
        let x = at(0.03, 0.0);
        assert!((t.energy(&x) - 0.5 * 7.0 * 0.07 * 0.07).abs() < 1e-12);
        let mut g = [DVec3::ZERO; 4];
        t.gradient(&x, |i, v| g[i] += v);
        // A descent lifts the second edge and lowers the first.
        assert!(g[2].z < 0.0 && g[0].z > 0.0, "{g:?}");
        assert_gradient_is_energys(&t, &x, &g);
        assert_hessian_is_gradients(&t, &x);
        // Through within the step: still pushed back up.
        assert!(t.energy(&at(-0.1, 0.0)) > 0.0);
        for (h, across) in [(-0.3, 0.0), (0.03, 0.2), (0.15, 0.0)] {
            assert_eq!(t.energy(&at(h, across)), 0.0, "{h} {across}");
            t.hessian(&at(h, across), |_, _, _| panic!("pushed at {h} {across}"));
        }
    }

    /// A face term's gradient is its energy's, its diagonal blocks are
    /// `c·gₖ²·nnᵀ`, and a vertex at least `min` over its triangle costs
    /// nothing.
    #[test]
    fn a_face_terms_gradient_is_its_energys() {
        let t = PairTerms {
            sides: vec![SideTerm {
                ends: [3, 0, 1, 2],
                weights: [1.0, -0.2, -0.5, -0.3],
                normal: DVec3::Y,
                min: 0.1,
                floor: f64::NEG_INFINITY,
                aside: f64::INFINITY,
            }],
            c: 5.0,
            ..PairTerms::default()
        };
        // The vertex went below the triangle within the step.
        let x = [
            DVec3::new(0.0, 0.0, 0.0),
            DVec3::new(1.0, 0.02, 0.0),
            DVec3::new(0.0, -0.01, 1.0),
            DVec3::new(0.4, -0.03, 0.3),
        ];
        assert!(t.energy(&x) > 0.0);
        let mut g = [DVec3::ZERO; 4];
        t.gradient(&x, |i, v| g[i] += v);
        // A descent lifts the vertex and lowers the corners.
        assert!(g[3].y < 0.0 && g[0].y > 0.0, "{g:?}");
        assert_gradient_is_energys(&t, &x, &g);
        let blocks = hessian(&t, &x);
        assert_eq!(blocks[3][3].y_axis.y, 5.0);
        assert!((blocks[1][1].y_axis.y - 5.0 * 0.25).abs() < 1e-12);
        assert!((blocks[3][1].y_axis.y + 5.0 * 0.5).abs() < 1e-12);
        assert!((blocks[0][2].y_axis.y - 5.0 * 0.06).abs() < 1e-12);
        assert_hessian_is_gradients(&t, &x);
        let mut couplings = Vec::new();
        t.couplings(&mut couplings);
        crate::solver::linear::normalise(&mut couplings);
        assert_eq!(couplings, [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]);
        let mut above = x;
        above[3].y = 0.2;
        assert_eq!(t.energy(&above), 0.0);
        t.gradient(&above, |_, _| panic!("a vertex above pushed"));
    }
}
