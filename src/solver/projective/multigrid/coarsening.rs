//! The multigrid's sparse matrices (compressed rows) and its coarsening:
//! strength of connection, aggregation and the smoothed prolongation.

use bevy::math::Vec3A;

/// Strength of connection: `|s_ij| ≥ θ √(s_ii s_jj)`.
pub(super) const THETA: f64 = 0.08;

/// A sparse matrix by rows: built in `f64`, applied in `f32`.
#[derive(Clone, Debug, Default)]
pub(super) struct Csr {
    pub(super) ptr: Vec<usize>,
    pub(super) idx: Vec<u32>,
    pub(super) val: Vec<f64>,
    pub(super) cols: usize,
    /// `val` in `f32`, for the cycles (set by [`Csr::for_cycles`]).
    pub(super) val32: Vec<f32>,
}

impl Csr {
    #[inline]
    pub(super) fn rows(&self) -> usize {
        self.ptr.len() - 1
    }

    #[inline]
    pub(super) fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let r = self.ptr[i]..self.ptr[i + 1];
        (&self.idx[r.clone()], &self.val[r])
    }

    /// The transpose, rows in increasing column order.
    pub(super) fn transpose(&self) -> Csr {
        let mut count = vec![0usize; self.cols + 1];
        for &j in &self.idx {
            count[j as usize + 1] += 1;
        }
        for c in 0..self.cols {
            count[c + 1] += count[c];
        }
        let mut next = count.clone();
        let mut idx = vec![0u32; self.idx.len()];
        let mut val = vec![0.0; self.val.len()];
        for i in 0..self.rows() {
            let (cols, vals) = self.row(i);
            for (&j, &v) in cols.iter().zip(vals) {
                let at = next[j as usize];
                idx[at] = i as u32;
                val[at] = v;
                next[j as usize] += 1;
            }
        }
        Csr {
            ptr: count,
            idx,
            val,
            cols: self.rows(),
            val32: Vec::new(),
        }
    }

    /// `self · other` (Gustavson's row-by-row product; each row's columns
    /// in the order they are first reached, which is fixed).
    pub(super) fn mul(&self, other: &Csr) -> Csr {
        let mut out = Csr {
            ptr: vec![0],
            cols: other.cols,
            ..Csr::default()
        };
        let mut slot = vec![usize::MAX; other.cols];
        for i in 0..self.rows() {
            let start = out.idx.len();
            let (cols, vals) = self.row(i);
            for (&k, &a) in cols.iter().zip(vals) {
                let (ocols, ovals) = other.row(k as usize);
                for (&j, &b) in ocols.iter().zip(ovals) {
                    let s = slot[j as usize];
                    if s == usize::MAX || s < start {
                        slot[j as usize] = out.idx.len();
                        out.idx.push(j);
                        out.val.push(a * b);
                    } else {
                        out.val[s] += a * b;
                    }
                }
            }
            out.ptr.push(out.idx.len());
        }
        out
    }

    /// Where entry `(i, j)` is stored, if it is in the pattern.
    #[inline]
    pub(super) fn position(&self, i: usize, j: usize) -> Option<usize> {
        (self.ptr[i]..self.ptr[i + 1]).find(|&p| self.idx[p] as usize == j)
    }

    /// Sets the value at `at` (and its `f32` copy, if made).
    #[inline]
    pub(super) fn set_at(&mut self, at: usize, v: f64) {
        self.val[at] = v;
        if let Some(v32) = self.val32.get_mut(at) {
            *v32 = v as f32;
        }
    }

    /// The same matrix with its `f32` values set.
    pub(super) fn for_cycles(mut self) -> Self {
        self.val32 = self.val.iter().map(|&v| v as f32).collect();
        self
    }

    /// `y = self · x` over the rows `rows` (`y` holds those rows).
    pub(super) fn apply(&self, rows: std::ops::Range<usize>, x: &[Vec3A], y: &mut [Vec3A]) {
        for (i, y) in rows.zip(y) {
            let r = self.ptr[i]..self.ptr[i + 1];
            let mut acc = Vec3A::ZERO;
            for (&j, &v) in self.idx[r.clone()].iter().zip(&self.val32[r]) {
                acc += v * x[j as usize];
            }
            *y = acc;
        }
    }
}

/// `y = a · x`. Serial: the coarse levels are too small for a task-pool
/// scope per product to pay (`docs/measurements.md`).
#[inline]
pub(super) fn product(a: &Csr, x: &[Vec3A], y: &mut [Vec3A]) {
    a.apply(0..a.rows(), x, y);
}

/// `r = b − a · x`.
#[inline]
pub(super) fn residual(a: &Csr, x: &[Vec3A], b: &[Vec3A], r: &mut [Vec3A]) {
    product(a, x, r);
    for (r, b) in r.iter_mut().zip(b) {
        *r = *b - *r;
    }
}

pub(super) fn diagonal(a: &Csr) -> Vec<f64> {
    (0..a.rows())
        .map(|i| {
            let (cols, vals) = a.row(i);
            cols.iter()
                .zip(vals)
                .filter(|(j, _)| **j as usize == i)
                .map(|(_, v)| *v)
                .sum()
        })
        .collect()
}

/// Greedy aggregation: each row's aggregate, and how many.
pub(super) fn aggregate(a: &Csr, diag: &[f64]) -> (Vec<u32>, usize) {
    const NONE: u32 = u32::MAX;
    let n = a.rows();
    let strong = |i: usize| {
        let (cols, vals) = a.row(i);
        cols.iter().zip(vals).filter_map(move |(&j, &v)| {
            let j = j as usize;
            (j != i && v.abs() >= THETA * (diag[i] * diag[j]).sqrt()).then_some(j)
        })
    };
    let mut of = vec![NONE; n];
    let mut count = 0u32;
    // 1. A vertex whose strong neighbours are all free roots an aggregate.
    for i in 0..n {
        if of[i] == NONE && strong(i).all(|j| of[j] == NONE) {
            of[i] = count;
            for j in strong(i) {
                of[j] = count;
            }
            count += 1;
        }
    }
    // 2. The rest join a neighbouring aggregate from step 1.
    let first = of.clone();
    for (i, of) in of.iter_mut().enumerate() {
        if *of == NONE
            && let Some(j) = strong(i).find(|&j| first[j] != NONE)
        {
            *of = first[j];
        }
    }
    // 3. Anything left (no aggregated strong neighbour) starts its own.
    for i in 0..n {
        if of[i] == NONE {
            of[i] = count;
            for j in strong(i) {
                if of[j] == NONE {
                    of[j] = count;
                }
            }
            count += 1;
        }
    }
    (of, count as usize)
}

/// `P = (I − ω D⁻¹ A) P₀`, `P₀` the aggregates' indicator columns.
pub(super) fn prolongation(
    a: &Csr,
    diag: &[f64],
    of: &[u32],
    aggregates: usize,
    omega: f64,
) -> Csr {
    let mut p = Csr {
        ptr: vec![0],
        cols: aggregates,
        ..Csr::default()
    };
    let mut slot = vec![usize::MAX; aggregates];
    for i in 0..a.rows() {
        let start = p.idx.len();
        let mut add = |c: u32, v: f64| {
            let s = slot[c as usize];
            if s == usize::MAX || s < start {
                slot[c as usize] = p.idx.len();
                p.idx.push(c);
                p.val.push(v);
            } else {
                p.val[s] += v;
            }
        };
        add(of[i], 1.0);
        let (cols, vals) = a.row(i);
        let scale = omega / diag[i];
        for (&j, &v) in cols.iter().zip(vals) {
            add(of[j as usize], -scale * v);
        }
        p.ptr.push(p.idx.len());
    }
    p
}
