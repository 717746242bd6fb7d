//! The three-column forward and back substitution on faer's simplicial
//! Cholesky factor, with `x`, `y` and `z` as three lanes of one 4-lane
//! vector: each factor entry is read once for the three columns, as one
//! 256-bit product (AVX2) or two 128-bit ones (SSE2/NEON).
//!
//! Projective dynamics solves its global step this way on small cloths
//! (faer chooses the simplicial factor for its scalar Laplacian there),
//! ten or more times a step. faer's simplicial solve runs one column after
//! the other, each entry a scalar product with its index loaded again per
//! column; here each entry and index is loaded once for all three (the
//! gain is measured in `docs/measurements.md`).
//! Projective dynamics writes its
//! right-hand side straight into the lanes, in the factor's order
//! (`LaneFactor::rhs_mut`), and reads the solution there.
//!
//! Both substitutions are dot products over gathered entries (no scattered
//! writes): the forward one over the rows of `L`, the back one over its
//! columns. The layout is made once per symbolic analysis; a numeric
//! factorisation only copies its values in.
//! Each sums in four accumulators taken in a fixed order, and divides by the
//! diagonal as a product with its reciprocal, so the result is the same on
//! every SIMD level (products and sums are never fused), though not bitwise
//! faer's (tested against it to 1e-12).

use super::simd::Simd;
use crate::solver::engine::simd::at_level;

/// One unknown's three columns and a padding lane.
pub(crate) type Lanes = [f64; 4];

/// [`Lanes`] aligned to their size, so that no load or store of one
/// straddles two cache lines (with `Vec`'s 16-byte alignment, how many did
/// would depend on where the allocator put the buffer, and so would the
/// solve's speed).
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(32))]
struct Aligned(Lanes);

const _: () = assert!(size_of::<Aligned>() == size_of::<Lanes>());

/// `x` as plain lanes.
fn lanes(x: &mut [Aligned]) -> &mut [Lanes] {
    // SAFETY: `Aligned` is `Lanes` alone (`repr(C)`, the same size, checked
    // above) with a larger alignment, so its slice is one of `Lanes`.
    unsafe { core::slice::from_raw_parts_mut(x.as_mut_ptr().cast::<Lanes>(), x.len()) }
}

/// faer's simplicial `L` laid out for the 4-lane substitutions, in the
/// factor's own (permuted) numbering. The layout is made once per symbolic
/// analysis; each numeric factorisation only refills its values
/// ([`fill`](Self::fill)).
#[derive(Debug, Default)]
pub(crate) struct LaneFactor {
    /// `x[new] = rhs[gather[new]]` (faer's fill-reducing permutation),
    /// and its inverse: `slot[old] = new`.
    gather: Vec<u32>,
    slot: Vec<u32>,
    /// Strictly lower `L` by rows (forward) and by columns (back).
    rows: Entries,
    cols: Entries,
    /// The permuted right-hand side, solved in place.
    x: Vec<Aligned>,
    /// True once [`fill`](Self::fill) has given it a factor's values.
    filled: bool,
}

/// A sparse triangle without its diagonal, compressed by row or by column,
/// in the order the substitution takes them: by level (a row or column
/// depends only on those of lower levels), so that the independent ones
/// of a level follow each other and the processor overlaps them, instead of
/// waiting on each result in turn as in the factor's own order. The order
/// changes no result: each is the same sum in the same order.
#[derive(Debug, Default)]
struct Entries {
    /// Per position in the order: the unknown it solves, `1 / L_ii`, and
    /// where `L_ii` is in faer's values.
    target: Vec<u32>,
    inv_diag: Vec<f64>,
    diag_src: Vec<u32>,
    /// Per line (position in the order), its entries
    /// (`ptr[at]..ptr[at + 1]`): the byte offsets in `x` of the unknowns
    /// they read, their values, and where those are in faer's values.
    /// (Not as runs of consecutive unknowns: the runs are short, 3 to 5
    /// entries at 21², and that layout measured slower.)
    ptr: Vec<u32>,
    idx: Vec<u32>,
    /// The unknowns: every line and entry is one of `0..n`.
    n: usize,
    val: Vec<f64>,
    src: Vec<u32>,
}

impl Entries {
    /// Lines `lines[i]` (each a list of `(unknown read, index in faer's
    /// values)`, unknowns ordered) taken by level, each line after every
    /// line it reads; `diag[i]` is where line `i`'s diagonal is.
    fn by_level(lines: &[Vec<(u16, u32)>], diag: &[u32]) -> Self {
        let n = lines.len();
        // A line's level is one above the highest level it reads. Rows
        // read lower unknowns and columns higher ones: take them so.
        let forward = lines
            .iter()
            .enumerate()
            .all(|(i, l)| l.iter().all(|&(j, _)| usize::from(j) < i));
        let order: Vec<usize> = if forward {
            (0..n).collect()
        } else {
            (0..n).rev().collect()
        };
        let mut level = vec![0u32; n];
        for &i in &order {
            level[i] = lines[i]
                .iter()
                .map(|&(j, _)| level[usize::from(j)] + 1)
                .max()
                .unwrap_or(0);
        }
        let mut by_level = order;
        by_level.sort_by_key(|&i| level[i]);
        // Within a level, the lines whose last input comes earliest first,
        // so that the first lines of a level do not wait on the last of the
        // level before.
        let mut position = vec![0usize; n];
        for (at, &i) in by_level.iter().enumerate() {
            position[i] = at;
        }
        by_level.sort_by_key(|&i| {
            let ready = lines[i]
                .iter()
                .map(|&(j, _)| position[usize::from(j)])
                .max();
            (level[i], ready, i)
        });
        let mut entries = Self {
            ptr: vec![0],
            n,
            ..Self::default()
        };
        for i in by_level {
            entries.target.push(i as u32);
            entries.diag_src.push(diag[i]);
            for &(j, at) in &lines[i] {
                entries.idx.push(u32::from(j) * size_of::<Lanes>() as u32);
                entries.src.push(at);
            }
            entries.ptr.push(entries.idx.len() as u32);
        }
        entries.inv_diag = vec![0.0; n];
        entries.val = vec![0.0; entries.src.len()];
        entries
    }

    /// Takes the values of a numeric factor.
    fn fill(&mut self, values: &[f64]) {
        for (v, &at) in self.val.iter_mut().zip(&self.src) {
            *v = values[at as usize];
        }
        for (d, &at) in self.inv_diag.iter_mut().zip(&self.diag_src) {
            *d = 1.0 / values[at as usize];
        }
    }
}

impl LaneFactor {
    /// The layout of faer's simplicial factor with structure `col_ptr`,
    /// `row_idx` (`L` column by column, each column's diagonal entry first)
    /// and the fill-reducing permutation's forward array (`new → old`), if
    /// any. `None` if the factor is not laid out that way, or has more than
    /// 2¹⁶ unknowns.
    pub(crate) fn new(
        col_ptr: &[usize],
        row_idx: &[usize],
        forward: Option<&[usize]>,
    ) -> Option<Self> {
        let n = col_ptr.len().checked_sub(1)?;
        if n > usize::from(u16::MAX) + 1 || col_ptr[n] > u32::MAX as usize {
            return None;
        }
        let mut diag = Vec::with_capacity(n);
        let mut rows = vec![Vec::new(); n];
        let mut cols = vec![Vec::new(); n];
        for j in 0..n {
            let column = col_ptr[j]..col_ptr[j + 1];
            let (&first, below) = row_idx.get(column.clone())?.split_first()?;
            if first != j || below.iter().any(|&i| i <= j || i >= n) {
                return None;
            }
            diag.push(column.start as u32);
            for (at, &i) in (column.start + 1..).zip(below) {
                // Columns in order: each row's entries by increasing column.
                rows[i].push((j as u16, at as u32));
                cols[j].push((i as u16, at as u32));
            }
        }
        let gather: Vec<u32> = match forward {
            Some(f) => f.iter().map(|&o| o as u32).collect(),
            None => (0..n as u32).collect(),
        };
        if gather.len() != n || gather.iter().any(|&o| o as usize >= n) {
            return None;
        }
        let mut slot = vec![u32::MAX; n];
        for (new, &old) in gather.iter().enumerate() {
            slot[old as usize] = new as u32;
        }
        if slot.contains(&u32::MAX) {
            return None;
        }
        Some(Self {
            gather,
            slot,
            rows: Entries::by_level(&rows, &diag),
            cols: Entries::by_level(&cols, &diag),
            x: vec![Aligned::default(); n],
            filled: false,
        })
    }

    /// Takes the values of a numeric factorisation (faer's values, laid out
    /// as the structure this was made from).
    pub(crate) fn fill(&mut self, values: &[f64]) {
        self.rows.fill(values);
        self.cols.fill(values);
        self.filled = true;
    }

    /// Forgets the values (the factorisation failed or was replaced).
    pub(crate) fn clear(&mut self) {
        self.filled = false;
    }

    /// Whether it holds a factor's values.
    pub(crate) fn is_filled(&self) -> bool {
        self.filled
    }

    /// Solves `L Lᵀ X = rhs` in place for `rhs` column-major `n×3`;
    /// false if the solution is not finite.
    pub(crate) fn solve3(&mut self, rhs: &mut [f64], level: Simd) -> bool {
        let n = self.x.len();
        debug_assert_eq!(rhs.len(), 3 * n);
        for (x, &g) in lanes(&mut self.x).iter_mut().zip(&self.gather) {
            let g = g as usize;
            *x = [rhs[g], rhs[n + g], rhs[2 * n + g], 0.0];
        }
        let finite = self.solve_in_place(level);
        for (Aligned(x), &g) in self.x.iter().zip(&self.gather) {
            let g = g as usize;
            (rhs[g], rhs[n + g], rhs[2 * n + g]) = (x[0], x[1], x[2]);
        }
        finite
    }

    /// The right-hand side to write in place, in the factor's order:
    /// position `new` is unknown `order[new]` (padding lanes zero). Then
    /// [`solve_in_place`](Self::solve_in_place), and read the solution with
    /// [`solution`](Self::solution). This saves [`solve3`](Self::solve3)'s
    /// two permuted copies.
    pub(crate) fn rhs_mut(&mut self) -> (&[u32], &mut [Lanes]) {
        (&self.gather, lanes(&mut self.x))
    }

    /// Unknown `old`'s three columns after
    /// [`solve_in_place`](Self::solve_in_place).
    #[inline]
    pub(crate) fn solution(&self, old: usize) -> [f64; 3] {
        let Aligned(x) = self.x[self.slot[old] as usize];
        [x[0], x[1], x[2]]
    }

    /// Every unknown (`old`) with its three columns after
    /// [`solve_in_place`](Self::solve_in_place), in the factor's order.
    #[inline]
    pub(crate) fn solved(&self) -> impl Iterator<Item = (usize, [f64; 3])> + '_ {
        self.gather
            .iter()
            .zip(&self.x)
            .map(|(&old, Aligned(x))| (old as usize, [x[0], x[1], x[2]]))
    }

    /// Solves `L Lᵀ X = B` in place for the right-hand side in `self.x`
    /// (permuted, the padding lanes zero); false if the solution is not
    /// finite.
    pub(crate) fn solve_in_place(&mut self, level: Simd) -> bool {
        let x = lanes(&mut self.x);
        substitute(level, &self.rows, x);
        substitute(level, &self.cols, x);
        all_finite(level, x)
    }
}

at_level! {
    /// No lane is NaN or infinite, at `level` (without stopping early, so
    /// that it vectorises, and at the run-time SIMD level: a short-circuit
    /// check at the baseline was a visible part of pd's step).
    fn all_finite(x: &[Lanes]) -> bool => all_finite_kernel
}

#[inline(always)]
fn all_finite_kernel(x: &[Lanes]) -> bool {
    x.iter()
        .flatten()
        .fold(true, |finite, v| finite & v.is_finite())
}

at_level! {
    /// One triangular substitution at `level`.
    fn substitute(entries: &Entries, x: &mut [Lanes]) => substitute_kernel
}

/// `x_i ← (x_i − Σ_p val_p · x_{idx_p}) / L_ii` for each line `i` of
/// `entries` (rows of `L`: forward; columns: back), in its order, the
/// entries summed in four accumulators.
#[inline(always)]
fn substitute_kernel(entries: &Entries, x: &mut [Lanes]) {
    // Every index `entries` holds is below its `n` (checked when it was
    // made), so with `x` that long the reads below stay in bounds.
    assert_eq!(x.len(), entries.n, "the factor's size");
    let x = x.as_mut_ptr();
    let lines = entries.target.iter().zip(&entries.inv_diag);
    for ((&i, &d), span) in lines.zip(entries.ptr.windows(2)) {
        let range = span[0] as usize..span[1] as usize;
        let (idx, val) = (&entries.idx[range.clone()], &entries.val[range]);
        // SAFETY: `j` is the byte offset of an unknown below `entries.n`
        // (see above). Unchecked and by byte offset, each entry costs two
        // instructions fewer (its bounds check, the index's scaling).
        let load = |j: u32| unsafe { *x.byte_add(j as usize) };
        let mut acc = [[0.0f64; 4]; 4];
        let whole = idx.len() / 4 * 4;
        for (ids, vals) in idx[..whole].chunks_exact(4).zip(val.chunks_exact(4)) {
            for a in 0..4 {
                let xj = load(ids[a]);
                for c in 0..4 {
                    acc[a][c] += vals[a] * xj[c];
                }
            }
        }
        for (a, (&j, &v)) in idx[whole..].iter().zip(&val[whole..]).enumerate() {
            let xj = load(j);
            for c in 0..4 {
                acc[a][c] += v * xj[c];
            }
        }
        // SAFETY: `i` is an unknown below `entries.n` (see above).
        let xi = unsafe { &mut *x.add(i as usize) };
        for c in 0..4 {
            let sum = (acc[0][c] + acc[1][c]) + (acc[2][c] + acc[3][c]);
            xi[c] = (xi[c] - sum) * d;
        }
    }
}
