//! XPBD's chains of stretch springs solved whole, [`LANES`] chains at a
//! time (see `solver::xpbd`'s `chains` module for what a chain is and
//! the system each one solves).
//!
//! One chain's solve (Thomas' algorithm) is a chain of dependent
//! divisions: each spring's pivot needs the one before it, so a chain
//! solved alone waits on the divider at every spring. Chains that share
//! no vertex are independent, so a batch of [`LANES`] of them is solved
//! in lock step, one spring of each per row, each row's arithmetic written
//! lane by lane for the compiler to vectorise at the step's SIMD level
//! (through `at_level!`; no `unsafe`, no fused multiply–adds, so the same
//! bits at every level). A lane whose chain is shorter than the batch's
//! longest repeats its last vertex: a spring of length zero, whose
//! direction, violation and coupling are zero, so it neither moves the
//! cloth nor touches its chain's real springs.
//!
//! Batching is what makes the chains affordable beside the sweep; what it
//! saves, and a faster kernel measured but not kept (it moves the last
//! bits, so the map's and the perf page's chains rows must be run again
//! with it), are in the CHANGELOG and the perf page.

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
    /// and compliance `alpha` (`1/(k h²)`), at SIMD `level`.
    ///
    /// # Panics
    /// If a chain names a vertex past `x` or `w`.
    pub(crate) fn solve(&mut self, level: Simd, x: &mut [Vec3A], w: &[f32], alpha: f32) {
        solve_at(level, self, x, w, alpha);
    }
}

at_level! {
    /// [`solve_kernel`] at `level`.
    fn solve_at(lanes: &mut ChainLanes, x: &mut [Vec3A], w: &[f32], alpha: f32) => solve_kernel
}

#[inline(always)]
fn solve_kernel(lanes: &mut ChainLanes, x: &mut [Vec3A], w: &[f32], alpha: f32) {
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
        let m = rows.len().saturating_sub(1);
        // Forward elimination as the springs are read: spring i joins rows
        // i and i + 1; its coupling to spring i − 1 is −w(row i) nᵢ₋₁·nᵢ
        // (zero for the first, whose previous direction is zero).
        let mut pivot = [1.0f32; LANES];
        let mut prev = [0.0f32; LANES];
        let mut last = [[0.0f32; LANES]; 3];
        for i in 0..m {
            let (va, vb) = (&rows[i], &rows[i + 1]);
            let mut d = [[0.0f32; LANES]; 3];
            let mut wa = [0.0f32; LANES];
            let mut wb = [0.0f32; LANES];
            for j in 0..LANES {
                let (a, b) = (va[j] as usize, vb[j] as usize);
                let e = x[a] - x[b];
                (d[0][j], d[1][j], d[2][j]) = (e.x, e.y, e.z);
                (wa[j], wb[j]) = (w[a], w[b]);
            }
            let mut dir = [[0.0f32; LANES]; 3];
            for j in 0..LANES {
                let l = ((d[0][j] * d[0][j] + d[1][j] * d[1][j]) + d[2][j] * d[2][j]).sqrt();
                let live = l > 0.0;
                let c = if live { rest[i + 1][j] - l } else { 0.0 };
                for k in 0..3 {
                    dir[k][j] = if live { d[k][j] / l } else { 0.0 };
                }
                let diag = (wa[j] + wb[j]) + alpha;
                let off = -wa[j]
                    * ((last[0][j] * dir[0][j] + last[1][j] * dir[1][j]) + last[2][j] * dir[2][j]);
                let up = if pivot[j] > 0.0 { off / pivot[j] } else { 0.0 };
                upper[i][j] = up;
                pivot[j] = diag - off * up;
                let next = c - off * prev[j];
                prev[j] = if pivot[j] > 0.0 { next / pivot[j] } else { 0.0 };
                rhs[i][j] = prev[j];
            }
            n[i] = dir;
            last = dir;
        }
        // Back substitution, then each spring's multiplier moves its ends.
        for i in (1..m).rev() {
            for j in 0..LANES {
                rhs[i - 1][j] -= upper[i][j] * rhs[i][j];
            }
        }
        for i in 0..m {
            for j in 0..LANES {
                let (a, b) = (rows[i][j] as usize, rows[i + 1][j] as usize);
                let push = Vec3A::new(n[i][0][j], n[i][1][j], n[i][2][j]) * rhs[i][j];
                x[a] += w[a] * push;
                x[b] -= w[b] * push;
            }
        }
    }
}
