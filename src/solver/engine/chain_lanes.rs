//! XPBD's chains of stretch springs solved whole, [`LANES`] chains at a
//! time (see `solver::xpbd`'s `chains` module for what a chain is and
//! the system each one solves).
//!
//! One chain's solve (Thomas' algorithm) is a chain of dependent
//! divisions: each spring's pivot needs the one before it, so a chain
//! solved alone waits on the divider at every spring. Chains that share
//! no vertex are independent, so a batch of [`LANES`] of them is solved
//! in lock step, one spring of each per row, each row's lengths, square
//! roots and divisions as one vector operation (the compiler's, at the
//! step's SIMD level through `at_level!`; no `unsafe`, no fused
//! multiply–adds, so the same bits at every level). A lane whose chain is
//! shorter than the batch's longest repeats its last vertex: a spring of
//! length zero, whose direction, violation and coupling are zero, so it
//! neither moves the cloth nor touches its chain's real springs.

use bevy::math::Vec3A;

use super::simd::{Simd, at_level};

/// Chains per batch: one AVX2 register of lengths.
pub(crate) const LANES: usize = 8;

/// Chains in batches of [`LANES`], by row: `vertices[r][j]` is the `r`-th
/// vertex of lane `j`'s chain within its batch, and `rest[r][j]` the rest
/// length of the spring between rows `r − 1` and `r` (unused at a batch's
/// first row). `batches` are where each batch's rows start, and the end.
#[derive(Clone, Debug, Default)]
pub(crate) struct ChainLanes {
    vertices: Vec<[u32; LANES]>,
    rest: Vec<[f32; LANES]>,
    batches: Vec<usize>,
    /// Scratch per spring row of a batch: the springs' unit vectors (by
    /// axis), the elimination's upper factors and right sides (then the
    /// multipliers).
    n: Vec<[[f32; LANES]; 3]>,
    upper: Vec<[f32; LANES]>,
    rhs: Vec<[f32; LANES]>,
}

impl ChainLanes {
    /// No chains.
    pub(crate) fn clear(&mut self) {
        self.vertices.clear();
        self.rest.clear();
        self.batches.clear();
    }

    /// Adds one batch of at most [`LANES`] chains, which must share no
    /// vertex, each its vertices and the rest lengths of the springs
    /// before them (the first unused), as long as each other. Empty lanes
    /// repeat the first chain's first vertex (they move nothing).
    pub(crate) fn push_batch(&mut self, chains: &[(&[u32], &[f32])]) {
        assert!(chains.len() <= LANES && !chains.is_empty());
        let rows = chains.iter().map(|c| c.0.len()).max().unwrap_or(0);
        let spare = chains[0].0[0];
        if self.batches.is_empty() {
            self.batches.push(self.vertices.len());
        }
        for r in 0..rows {
            let mut vertices = [spare; LANES];
            let mut rest = [0.0; LANES];
            for (j, (v, l)) in chains.iter().enumerate() {
                assert_eq!(v.len(), l.len());
                vertices[j] = v.get(r).or(v.last()).copied().unwrap_or(spare);
                rest[j] = l.get(r).copied().unwrap_or(0.0);
            }
            self.vertices.push(vertices);
            self.rest.push(rest);
        }
        self.batches.push(self.vertices.len());
        let springs = rows.saturating_sub(1);
        if self.n.len() < springs {
            self.n.resize(springs, [[0.0; LANES]; 3]);
            self.upper.resize(springs, [0.0; LANES]);
            self.rhs.resize(springs, [0.0; LANES]);
        }
    }

    /// One solve of every batch in turn at `x`, with inverse masses `w`
    /// and compliance `alpha` (`1/(k h²)`), at SIMD `level`; with
    /// `pull_only`, a compressed spring's violation is taken as zero (it
    /// still couples its neighbours).
    ///
    /// # Panics
    /// If a chain names a vertex past `x` or `w`.
    pub(crate) fn solve(
        &mut self,
        level: Simd,
        x: &mut [Vec3A],
        w: &[f32],
        alpha: f32,
        pull_only: bool,
    ) {
        // The violation is `rest − length`, at most this.
        let cap = if pull_only { 0.0 } else { f32::INFINITY };
        solve_at(level, self, x, w, [alpha, cap]);
    }
}

at_level! {
    /// [`solve_kernel`] at `level`.
    fn solve_at(lanes: &mut ChainLanes, x: &mut [Vec3A], w: &[f32], alpha_cap: [f32; 2]) => solve_kernel
}

/// The positions (by axis) and inverse masses of one row's vertices.
#[inline(always)]
fn gather(row: &[u32; LANES], x: &[Vec3A], w: &[f32]) -> ([[f32; LANES]; 3], [f32; LANES]) {
    let mut p = [[0.0f32; LANES]; 3];
    let mut wv = [0.0f32; LANES];
    for (j, &v) in row.iter().enumerate() {
        let at = x[v as usize];
        (p[0][j], p[1][j], p[2][j]) = (at.x, at.y, at.z);
        wv[j] = w[v as usize];
    }
    (p, wv)
}

#[inline(always)]
fn solve_kernel(lanes: &mut ChainLanes, x: &mut [Vec3A], w: &[f32], [alpha, cap]: [f32; 2]) {
    let ChainLanes {
        vertices,
        rest,
        batches,
        n,
        upper,
        rhs,
    } = lanes;
    for batch in batches.windows(2) {
        let rows = &vertices[batch[0]..batch[1]];
        let rest = &rest[batch[0]..batch[1]];
        let Some(first) = rows.first() else {
            continue;
        };
        let m = rows.len() - 1;
        // Forward elimination as the springs are read: spring i joins rows
        // i and i + 1; its coupling to spring i − 1 is −w(row i) nᵢ₋₁·nᵢ
        // (zero for the first, whose previous direction is zero).
        // `recip` is 1/pivot (0 where the pivot is not positive: a chain
        // of pins), carried to the next spring's coupling; `pa`, `wa` the
        // positions and inverse masses of the row the spring starts at,
        // read once (a spring's second end is the next one's first).
        let mut recip = [1.0f32; LANES];
        let mut prev = [0.0f32; LANES];
        let mut last = [[0.0f32; LANES]; 3];
        let (mut pa, mut wa) = gather(first, x, w);
        for i in 0..m {
            let (pb, wb) = gather(&rows[i + 1], x, w);
            let r = &rest[i + 1];
            // The lanes' arithmetic, one vector operation per line.
            let mut dir = [[0.0f32; LANES]; 3];
            let mut up = [0.0f32; LANES];
            for j in 0..LANES {
                let d = [
                    pa[0][j] - pb[0][j],
                    pa[1][j] - pb[1][j],
                    pa[2][j] - pb[2][j],
                ];
                let l = ((d[0] * d[0] + d[1] * d[1]) + d[2] * d[2]).sqrt();
                let inv = if l > 0.0 { 1.0 / l } else { 0.0 };
                let c = if l > 0.0 { (r[j] - l).min(cap) } else { 0.0 };
                dir[0][j] = d[0] * inv;
                dir[1][j] = d[1] * inv;
                dir[2][j] = d[2] * inv;
                let diag = (wa[j] + wb[j]) + alpha;
                let off = -wa[j]
                    * ((last[0][j] * dir[0][j] + last[1][j] * dir[1][j]) + last[2][j] * dir[2][j]);
                up[j] = off * recip[j];
                let pivot = diag - off * up[j];
                recip[j] = if pivot > 0.0 { 1.0 / pivot } else { 0.0 };
                prev[j] = (c - off * prev[j]) * recip[j];
            }
            upper[i] = up;
            rhs[i] = prev;
            n[i] = dir;
            last = dir;
            (pa, wa) = (pb, wb);
        }
        // Back substitution.
        for i in (1..m).rev() {
            for j in 0..LANES {
                rhs[i - 1][j] -= upper[i][j] * rhs[i][j];
            }
        }
        // Each spring's multiplier pushes its ends apart along it: a row's
        // vertex moves by its inverse mass times the push of the spring it
        // starts less that of the spring it ends (one write per vertex).
        // The pushes and their differences are taken by axis, all lanes at
        // once; only the last multiply and the write are per vertex.
        let mut before = [[0.0f32; LANES]; 3];
        for (r, row) in rows.iter().enumerate() {
            let mut now = [[0.0f32; LANES]; 3];
            if r < m {
                for (now, n) in now.iter_mut().zip(&n[r]) {
                    for j in 0..LANES {
                        now[j] = n[j] * rhs[r][j];
                    }
                }
            }
            let mut step = [[0.0f32; LANES]; 3];
            for ((step, now), before) in step.iter_mut().zip(&now).zip(&before) {
                for j in 0..LANES {
                    step[j] = now[j] - before[j];
                }
            }
            for (j, &v) in row.iter().enumerate() {
                let v = v as usize;
                x[v] += w[v] * Vec3A::new(step[0][j], step[1][j], step[2][j]);
            }
            before = now;
        }
    }
}
