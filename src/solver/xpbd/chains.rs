//! Chains of stretch springs solved whole: the line relaxation of `stiff`'s
//! substep (see [`XpbdSolver::chains`](super::XpbdSolver::chains)).
//!
//! One sweep per substep passes a spring's correction one spring on, so a
//! pull at one end of a cloth reaches the other `n` substeps later: the
//! cloth's springs answer at `ℓ/h` (an edge per substep), where cotton's
//! answer at `√(k/ρ)` ≈ 220 m/s. A 4,000-vertex cape (edges of 1.5 cm,
//! 960 substeps a second) passes a pull on at 14 m/s, and a running,
//! turning character stretches it by half.
//!
//! A *chain* is a path of at least two stretch springs that goes on
//! straight through each of its vertices (a grid's rows, columns and
//! diagonal lines; at each vertex the springs are paired with the one most
//! nearly opposite them at rest, at least [`STRAIGHT`] apart; a ring, such
//! as a skirt's row, is cut where it closes, its last spring left to the
//! sweep). Its springs' XPBD update, linearised, is one
//! tridiagonal system in their multipliers,
//! `(J W Jᵀ + α̃) Δλ = −C`, with `Aᵢᵢ = wᵢ₋₁ + wᵢ + α̃` and
//! `Aᵢ,ᵢ₊₁ = −wᵢ nᵢ·nᵢ₊₁` (`nᵢ` the unit vector of spring `i` from its
//! second end to its first, `w` the inverse masses): solved exactly
//! (Thomas' algorithm: the matrix is symmetric positive definite, so no
//! pivoting), a pull passes along the whole chain in one substep. Chains
//! are solved one after the other (block Gauss–Seidel, in the order of
//! their first springs in the model), before the substep's sweep, which
//! still passes over every spring. A chain's solve costs about what the
//! sweep costs its springs (the cape's step about doubles; the perf page).
//! The chains and their order are taken once per topology, so a step is
//! the same bits every run.

use bevy::math::{Vec3, Vec3A};

use crate::model::{ClothModel, SpringKind};

/// How far from straight on a chain may turn at a vertex: the two springs'
/// directions away from it at rest must have a cosine at most this
/// (−0.9: within about 26° of opposite).
pub(crate) const STRAIGHT: f32 = -0.9;

/// The model's chains: `vertices[starts[c]..starts[c + 1]]` are chain `c`'s
/// vertices in order, and `rest[k]` the rest length of the spring between
/// `vertices[k - 1]` and `vertices[k]` (unused at a chain's first vertex).
/// Taken once per topology.
#[derive(Clone, Debug, Default)]
pub(crate) struct Chains {
    vertices: Vec<u32>,
    rest: Vec<f32>,
    starts: Vec<usize>,
    /// Per spring: whether it is on a chain.
    pub(crate) chained: Vec<bool>,
    source: Option<u64>,
    /// Scratch per spring of a chain: its unit vector, the elimination's
    /// upper factor and right side (then the multipliers).
    n: Vec<Vec3A>,
    upper: Vec<f32>,
    rhs: Vec<f32>,
}

impl Chains {
    /// Finds `model`'s chains, unless these are already its.
    pub(crate) fn update(&mut self, model: &ClothModel) {
        let id = model.topology().adjacency().id();
        if self.source == Some(id) {
            return;
        }
        self.source = Some(id);
        let (vertices, rest, starts, chained) = find(model);
        self.chained = chained;
        self.vertices = vertices;
        self.rest = rest;
        self.starts = starts;
    }

    /// The number of chains.
    pub(crate) fn count(&self) -> usize {
        self.starts.len().saturating_sub(1)
    }

    /// One solve of every chain in turn at `x`, with inverse masses `w`
    /// and compliance `compliance` (`1/(k h²)`).
    pub(crate) fn solve(&mut self, x: &mut [Vec3A], w: &[f32], compliance: f32) {
        for c in 0..self.count() {
            let (start, end) = (self.starts[c], self.starts[c + 1]);
            self.solve_one(start, end, x, w, compliance);
        }
    }

    fn solve_one(&mut self, start: usize, end: usize, x: &mut [Vec3A], w: &[f32], alpha: f32) {
        let verts = &self.vertices[start..end];
        let rest = &self.rest[start..end];
        let m = verts.len() - 1;
        self.n.resize(m, Vec3A::ZERO);
        self.upper.resize(m, 0.0);
        self.rhs.resize(m, 0.0);
        // Spring i joins verts[i] (its first end) and verts[i + 1]; the
        // system's off-diagonal between springs i − 1 and i is
        // −w(verts[i]) nᵢ₋₁·nᵢ. Forward elimination as the springs are
        // read (Thomas' algorithm).
        let (mut pivot, mut prev) = (1.0f32, 0.0f32);
        for i in 0..m {
            let (a, b) = (verts[i] as usize, verts[i + 1] as usize);
            let d = x[a] - x[b];
            let l = d.length();
            let (n, c) = if l > 0.0 {
                (d / l, rest[i + 1] - l)
            } else {
                (Vec3A::ZERO, 0.0)
            };
            let diag = w[a] + w[b] + alpha;
            let (next_pivot, next) = if i > 0 {
                let off = -w[a] * self.n[i - 1].dot(n);
                let upper = if pivot > 0.0 { off / pivot } else { 0.0 };
                self.upper[i - 1] = upper;
                (diag - off * upper, c - off * prev)
            } else {
                (diag, c)
            };
            pivot = next_pivot;
            prev = if pivot > 0.0 { next / pivot } else { 0.0 };
            self.n[i] = n;
            self.rhs[i] = prev;
        }
        // Back substitution; each spring's multiplier moves its ends.
        for i in (0..m.saturating_sub(1)).rev() {
            let next = self.rhs[i + 1];
            self.rhs[i] -= self.upper[i] * next;
        }
        for i in 0..m {
            let (a, b) = (verts[i] as usize, verts[i + 1] as usize);
            let push = self.n[i] * self.rhs[i];
            x[a] += w[a] * push;
            x[b] -= w[b] * push;
        }
    }
}

/// The chains of `model`'s stretch springs (see the module docs).
fn find(model: &ClothModel) -> (Vec<u32>, Vec<f32>, Vec<usize>, Vec<bool>) {
    let topology = model.topology();
    let springs = topology.springs();
    let rest_x = topology.rest_positions();
    let adjacency = topology.adjacency();
    let n = model.vertex_count();
    let stretch = |s: u32| springs[s as usize].kind == SpringKind::Stretch;
    // Per vertex, per stretch spring at it: the spring it goes on into.
    let mut next: std::collections::HashMap<(u32, u32), u32> = Default::default();
    for v in 0..n {
        let at: Vec<(u32, Vec3)> = adjacency
            .of(v)
            .iter()
            .filter(|inc| stretch(inc.spring))
            .map(|inc| {
                let d = rest_x[inc.other as usize] - rest_x[v];
                (inc.spring, d.normalize_or_zero())
            })
            .collect();
        let mut pairs: Vec<(f32, u32, u32)> = Vec::new();
        for (k, &(s, d)) in at.iter().enumerate() {
            for &(t, e) in &at[k + 1..] {
                let cos = d.dot(e);
                if cos <= STRAIGHT {
                    pairs.push((cos, s, t));
                }
            }
        }
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2).cmp(&(b.1, b.2))));
        let mut taken: Vec<u32> = Vec::new();
        for (_, s, t) in pairs {
            if taken.contains(&s) || taken.contains(&t) {
                continue;
            }
            taken.extend([s, t]);
            next.insert((v as u32, s), t);
            next.insert((v as u32, t), s);
        }
    }
    let mut walk = Walk {
        used: vec![false; springs.len()],
        chained: vec![false; springs.len()],
        on_chain: vec![false; n],
        vertices: Vec::new(),
        rest: Vec::new(),
    };
    let mut starts = vec![0];
    // Chains from their ends first (a spring with no continuation at one
    // end), then what is left (rings).
    for pass in 0..2 {
        for (e, spring) in springs.iter().enumerate() {
            if walk.used[e] || spring.kind != SpringKind::Stretch {
                continue;
            }
            let (a, b) = (spring.a, spring.b);
            let open_a = !next.contains_key(&(a, e as u32));
            let open_b = !next.contains_key(&(b, e as u32));
            let from = if open_a {
                a
            } else if open_b {
                b
            } else if pass == 1 {
                a
            } else {
                continue;
            };
            if walk.trace(springs, &next, e as u32, from) {
                starts.push(walk.vertices.len());
            }
        }
    }
    (walk.vertices, walk.rest, starts, walk.chained)
}

/// The state of [`find`]'s walks along the chains.
struct Walk {
    used: Vec<bool>,
    chained: Vec<bool>,
    on_chain: Vec<bool>,
    vertices: Vec<u32>,
    rest: Vec<f32>,
}

impl Walk {
    /// Walks from vertex `from` along spring `first` and on through the
    /// springs' continuations; keeps the chain if it has two springs or
    /// more.
    fn trace(
        &mut self,
        springs: &[crate::model::Spring],
        next: &std::collections::HashMap<(u32, u32), u32>,
        first: u32,
        from: u32,
    ) -> bool {
        let mut chain = vec![from];
        let mut lengths = vec![0.0];
        let mut on = Vec::new();
        self.on_chain[from as usize] = true;
        let (mut s, mut v) = (first, from);
        loop {
            self.used[s as usize] = true;
            let spring = springs[s as usize];
            let w = if spring.a == v { spring.b } else { spring.a };
            if self.on_chain[w as usize] {
                // A ring: cut it here (its last spring is left to the sweep).
                break;
            }
            chain.push(w);
            lengths.push(spring.rest_length);
            on.push(s);
            self.on_chain[w as usize] = true;
            match next.get(&(w, s)) {
                Some(&t) if !self.used[t as usize] => (s, v) = (t, w),
                _ => break,
            }
        }
        for &c in &chain {
            self.on_chain[c as usize] = false;
        }
        if chain.len() >= 3 {
            for s in on {
                self.chained[s as usize] = true;
            }
            self.vertices.extend(chain);
            self.rest.extend(lengths);
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use bevy::math::{Affine3A, Vec3};

    use super::*;
    use crate::model::{ClothBuilder, ClothState};

    #[test]
    fn a_grids_chains_are_its_rows_columns_and_diagonals() {
        // 5 rows of 7 vertices, each quad split by one diagonal: 5 rows, 7
        // columns and the 7 diagonal lines of two springs or more; the two
        // corner diagonals, one spring each, are left to the sweep.
        let model = ClothBuilder::grid(5, 7, Vec3::ZERO, Vec3::X, Vec3::NEG_Z)
            .build()
            .unwrap();
        let mut chains = Chains::default();
        chains.update(&model);
        assert_eq!(chains.count(), 5 + 7 + 7);
        let springs = model.topology().springs();
        let stretch = springs
            .iter()
            .filter(|s| s.kind == SpringKind::Stretch)
            .count();
        assert_eq!(stretch, 5 * 6 + 4 * 7 + 4 * 6);
        let on_chains = chains.vertices.len() - chains.count();
        assert_eq!(on_chains, stretch - 2);
        assert_eq!(chains.chained.iter().filter(|&&c| c).count(), on_chains);
        // Each chain's consecutive vertices are joined by a stretch spring
        // of the rest length it carries.
        for c in 0..chains.count() {
            let (start, end) = (chains.starts[c], chains.starts[c + 1]);
            for k in start + 1..end {
                let (a, b) = (chains.vertices[k - 1], chains.vertices[k]);
                let spring = springs
                    .iter()
                    .find(|s| (s.a, s.b) == (a.min(b), a.max(b)))
                    .expect("a spring");
                assert_eq!(spring.kind, SpringKind::Stretch);
                assert_eq!(spring.rest_length, chains.rest[k]);
            }
        }
    }

    #[test]
    fn one_solve_restores_a_fallen_column() {
        // Two columns of 12 vertices hanging from their top row, every free
        // vertex moved down alike (a substep's fall): one sweep fixes only
        // the top springs, one solve of each column all of its springs (the
        // motion is along the chain, where the linearisation is exact).
        let model = ClothBuilder::grid(12, 2, Vec3::ZERO, Vec3::X, Vec3::NEG_Y)
            .with_pins([0, 1])
            .build()
            .unwrap();
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let top = state.positions[..2].to_vec();
        for p in &mut state.positions[2..] {
            p.y -= 0.01;
        }
        let w: Vec<f32> = model
            .masses()
            .iter()
            .zip(model.pinned())
            .map(|(&m, &p)| if p { 0.0 } else { 1.0 / m })
            .collect();
        let mut chains = Chains::default();
        chains.update(&model);
        assert_eq!(chains.count(), 2);
        chains.solve(&mut state.positions, &w, 0.0);
        let x = &state.positions;
        let mut vertical = 0;
        for s in model.topology().springs() {
            let (a, b) = (x[s.a as usize], x[s.b as usize]);
            if s.kind == SpringKind::Stretch && (a.x - b.x).abs() < 1e-6 {
                vertical += 1;
                let l = a.distance(b);
                assert!(
                    (l - s.rest_length).abs() < 1e-5,
                    "{l} against {}",
                    s.rest_length
                );
            }
        }
        assert_eq!(vertical, 2 * 11);
        assert_eq!(&x[..2], &top[..]);
    }

    #[test]
    fn chains_solved_whole_take_back_most_of_a_long_capes_stretch() {
        // A 64² cape of 2 m and 1 kg pinned along one edge swings down from
        // level at 60 Hz, without tethers: one sweep per substep passes a
        // pull one spring on, so its 64-vertex columns answer their pins
        // slowly and stretch; solving each chain whole before the sweep
        // passes the pull along at once. Judged from its second second.
        use crate::solver::xpbd::XpbdSolver;
        use crate::solver::{Method, SpringStiffness, StepParams, max_stretch};
        let n = 64;
        let model = ClothBuilder::grid(
            n,
            n,
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(-1.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 2.0),
        )
        .with_total_mass(1.0)
        .with_pins(0..n as u32)
        .build()
        .unwrap();
        let params = StepParams {
            dt: 1.0 / 60.0,
            stiffness: SpringStiffness::uniform(8000.0),
            ..StepParams::LAB
        };
        let worst = |method: XpbdSolver| {
            let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
            let mut ws = Default::default();
            let mut worst = 0.0f32;
            for step in 1..=150 {
                method
                    .step(&model, &mut state, &params, &[], &mut ws)
                    .expect("a valid step");
                assert!(state.positions.iter().all(|p| p.is_finite()));
                if step > 60 {
                    worst = worst.max(max_stretch(&model, &state.positions));
                }
            }
            worst
        };
        let loose = XpbdSolver::STIFF.with_tethers(false);
        let without = worst(loose);
        let with = worst(loose.with_chains(true));
        // Measured: 12.7 % without, 0.22 % with.
        assert!(without > 0.08, "without chains: {without}");
        assert!(with < 0.01, "with chains: {with} against {without}");
    }
}
