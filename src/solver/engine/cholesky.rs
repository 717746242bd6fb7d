//! A sparse Cholesky factorisation shared by the direct methods (the
//! linearly implicit direct solve, the exact method, projective dynamics).

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::SparseColMatRef;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::{Conj, MatMut, Par, Side};

use super::simd::Simd;
use crate::solver::engine::kernels::parallel_pool;
use crate::solver::engine::lane_factor::LaneFactor;
use crate::solver::engine::supernodal::{PartScratch, Plan, Structure, solve3};
use bevy::reflect::Reflect;
use thiserror::Error;

/// Why a linear solve failed. The state is left untouched.
#[derive(Error, Reflect, Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveError {
    /// Conjugate gradients met a direction of non-positive curvature: `A` is
    /// not positive definite (compressed springs under the exact spring
    /// Jacobian, or an exact penalty Jacobian).
    #[error("the system matrix is not positive definite")]
    NotPositiveDefinite,
    /// The sparse factorisation failed or produced a non-finite solution.
    #[error("the sparse factorisation failed")]
    Factorization,
    /// Newton's backtracking line search found no decrease of the objective
    /// along its direction.
    #[error("the line search found no decrease along the Newton direction")]
    LineSearch,
}

/// A sparse Cholesky factorisation (faer, AMD ordering) whose symbolic
/// analysis is done once for a sparsity pattern and reused by every
/// numeric factorisation.
#[derive(Default)]
pub struct SparseCholesky {
    symbolic: Option<SymbolicCholesky<usize>>,
    factor: Vec<f64>,
    memory: Option<MemBuffer>,
    /// Right-hand sides the memory is sized for.
    columns: usize,
    /// True once `factor` holds a numeric LLᵀ factorisation.
    factored: bool,
    /// [`solve_factored_xyz`](Self::solve_factored_xyz)'s permuted
    /// right-hand side and its per-supernode scratch.
    xyz: Vec<f64>,
    /// Its split of a supernodal factor, made with the symbolic analysis,
    /// and the scratch of each part.
    plan: Option<Plan>,
    scratch: [PartScratch; 3],
    /// A simplicial factor's layout for
    /// [`solve_factored_xyz`](Self::solve_factored_xyz)'s 4-lane
    /// substitutions, made with the symbolic analysis and given the values
    /// of each numeric factorisation.
    lanes: Option<LaneFactor>,
    /// Forces a simplicial (`Some(false)`) or supernodal (`Some(true)`)
    /// factor; faer chooses by the factorisation's flop count otherwise.
    supernodal: Option<bool>,
}

impl SparseCholesky {
    /// Forgets the symbolic analysis (the pattern changed).
    pub fn reset(&mut self) {
        *self = Self {
            supernodal: self.supernodal,
            ..Self::default()
        };
    }

    /// A factorisation that is always supernodal (`true`) or always
    /// simplicial (`false`), whatever faer's heuristic would choose.
    pub fn forced(supernodal: bool) -> Self {
        Self {
            supernodal: Some(supernodal),
            ..Self::default()
        }
    }

    /// The factorisation for the `3n×3n` spring Hessians of the linearly
    /// implicit direct solve and the exact method: always supernodal. Their
    /// 3×3 blocks make dense supernodes, yet on small cloths faer's
    /// flop-count heuristic picks the simplicial (row-by-row) factor for
    /// them, and the supernodal factor measured faster for these blocks at
    /// every size (`docs/measurements.md`). The
    /// scalar Laplacian of projective dynamics keeps faer's choice
    /// (simplicial is faster there up to about 101²).
    pub fn for_block_hessian() -> Self {
        Self::forced(true)
    }

    fn analyse(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        columns: usize,
    ) -> Result<(), SolveError> {
        let columns = columns.max(1);
        if self.symbolic.is_none() || self.columns < columns {
            let sym = factorize_symbolic_cholesky(
                a.symbolic(),
                Side::Lower,
                SymmetricOrdering::Amd,
                CholeskySymbolicParams {
                    supernodal_flop_ratio_threshold: match self.supernodal {
                        None => SupernodalThreshold::AUTO,
                        Some(true) => SupernodalThreshold::FORCE_SUPERNODAL,
                        Some(false) => SupernodalThreshold::FORCE_SIMPLICIAL,
                    },
                    ..Default::default()
                },
            )
            .map_err(|_| SolveError::Factorization)?;
            self.factor.resize(sym.len_val(), 0.0);
            self.memory = Some(MemBuffer::new(StackReq::any_of(&[
                sym.factorize_numeric_ldlt_scratch::<f64>(Par::Seq, Default::default()),
                sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
                sym.solve_in_place_scratch::<f64>(columns, Par::Seq),
            ])));
            (self.plan, self.lanes) = match sym.raw() {
                SymbolicCholeskyRaw::Supernodal(s) => (
                    Some(Plan::new(&Structure::of(s), sym.perm().map(|p| p.arrays()))),
                    None,
                ),
                SymbolicCholeskyRaw::Simplicial(s) => (
                    None,
                    LaneFactor::new(s.col_ptr(), s.row_idx(), sym.perm().map(|p| p.arrays().0)),
                ),
            };
            self.symbolic = Some(sym);
            self.columns = columns;
        }
        Ok(())
    }

    /// Solves `A x = rhs` in place by LDLᵀ (any symmetric `A` without a zero
    /// pivot; like the assignment's `A.ldlt().solve(b)`).
    pub fn solve_ldlt(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        rhs: &mut [f64],
    ) -> Result<(), SolveError> {
        self.solve(a, rhs, false)
    }

    /// Solves `A x = rhs` in place by LLᵀ; fails with
    /// [`SolveError::NotPositiveDefinite`] when `A` is not positive definite.
    pub fn solve_llt(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        rhs: &mut [f64],
    ) -> Result<(), SolveError> {
        self.solve(a, rhs, true)
    }

    fn solve(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        rhs: &mut [f64],
        llt: bool,
    ) -> Result<(), SolveError> {
        self.analyse(a, 1)?;
        self.factored = false;
        if let Some(lanes) = &mut self.lanes {
            lanes.clear();
        }
        let n = rhs.len();
        let (Some(sym), Some(memory)) = (self.symbolic.as_ref(), self.memory.as_mut()) else {
            return Err(SolveError::Factorization);
        };
        let rhs_mat = MatMut::from_column_major_slice_mut(rhs, n, 1);
        let (lower, par) = (Side::Lower, Par::Seq);
        if llt {
            sym.factorize_numeric_llt(
                &mut self.factor,
                a,
                lower,
                Default::default(),
                par,
                MemStack::new(memory),
                Default::default(),
            )
            .map_err(|_| SolveError::NotPositiveDefinite)?
            .solve_in_place_with_conj(Conj::No, rhs_mat, par, MemStack::new(memory));
        } else {
            sym.factorize_numeric_ldlt(
                &mut self.factor,
                a,
                lower,
                Default::default(),
                par,
                MemStack::new(memory),
                Default::default(),
            )
            .map_err(|_| SolveError::Factorization)?
            .solve_in_place_with_conj(Conj::No, rhs_mat, par, MemStack::new(memory));
        }
        finite(rhs)
    }

    /// Factorises `A = LLᵀ` and keeps the factor for
    /// [`solve_factored`](Self::solve_factored), with workspace for
    /// `columns` right-hand sides. Fails with
    /// [`SolveError::NotPositiveDefinite`] when `A` is not positive definite.
    pub fn factorize_llt(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        columns: usize,
    ) -> Result<(), SolveError> {
        self.factored = false;
        if let Some(lanes) = &mut self.lanes {
            lanes.clear();
        }
        self.analyse(a, columns)?;
        let (Some(sym), Some(memory)) = (self.symbolic.as_ref(), self.memory.as_mut()) else {
            return Err(SolveError::Factorization);
        };
        sym.factorize_numeric_llt(
            &mut self.factor,
            a,
            Side::Lower,
            Default::default(),
            Par::Seq,
            MemStack::new(memory),
            Default::default(),
        )
        .map_err(|_| SolveError::NotPositiveDefinite)?;
        if let Some(lanes) = &mut self.lanes {
            lanes.fill(&self.factor);
        }
        self.factored = true;
        Ok(())
    }

    /// Solves `A X = rhs` in place with the factor of the last
    /// [`factorize_llt`](Self::factorize_llt), for `rhs` holding `columns`
    /// right-hand sides column after column (at most the number it was
    /// factorised for). One forward and one back substitution.
    pub fn solve_factored(&mut self, rhs: &mut [f64], columns: usize) -> Result<(), SolveError> {
        let (Some(sym), Some(memory), true) =
            (self.symbolic.as_ref(), self.memory.as_mut(), self.factored)
        else {
            return Err(SolveError::Factorization);
        };
        if columns == 0 || columns > self.columns || !rhs.len().is_multiple_of(columns) {
            return Err(SolveError::Factorization);
        }
        let rows = rhs.len() / columns;
        LltRef::new(sym, &self.factor).solve_in_place_with_conj(
            Conj::No,
            MatMut::from_column_major_slice_mut(rhs, rows, columns),
            Par::Seq,
            MemStack::new(memory),
        );
        finite(rhs)
    }

    /// The simplicial factor's lane layout, holding the values of the last
    /// successful [`factorize_llt`](Self::factorize_llt), to write a
    /// three-column right-hand side into and solve in place (module
    /// `lanes`); `None` for a supernodal factor or none.
    pub(crate) fn lanes(&mut self) -> Option<&mut LaneFactor> {
        self.lanes
            .as_mut()
            .filter(|lanes| self.factored && lanes.is_filled())
    }

    /// [`lanes`](Self::lanes), to read the solution.
    pub(crate) fn lanes_ref(&self) -> Option<&LaneFactor> {
        self.lanes
            .as_ref()
            .filter(|lanes| self.factored && lanes.is_filled())
    }

    /// Solves `A X = rhs` for three right-hand sides (`rhs` column-major,
    /// `n×3`) with the factor of the last
    /// [`factorize_llt`](Self::factorize_llt): the same result as
    /// [`solve_factored`](Self::solve_factored) with three columns.
    ///
    /// Hand-written on faer's factor. A supernodal factor (module
    /// `supernodal`): faer's general solve runs one small dense product per
    /// supernode through its matrix-multiply dispatch, which for three
    /// columns costs more than the arithmetic. With `parallel` and a compute
    /// pool of two or more threads, two independent subtrees of the
    /// elimination tree are solved at once, with the same result to the bit
    /// (the CHANGELOG has the perf page's pd rows before and after). A
    /// simplicial factor (module `lanes`): the three columns as lanes of
    /// one vector at `simd`'s level, each factor entry read once (the same
    /// bits at every level).
    pub fn solve_factored_xyz(
        &mut self,
        rhs: &mut [f64],
        parallel: bool,
        simd: Simd,
    ) -> Result<(), SolveError> {
        let (Some(sym), true) = (self.symbolic.as_ref(), self.factored) else {
            return Err(SolveError::Factorization);
        };
        let n = sym.nrows();
        if rhs.len() != 3 * n {
            return Err(SolveError::Factorization);
        }
        let SymbolicCholeskyRaw::Supernodal(s) = sym.raw() else {
            return match &mut self.lanes {
                Some(lanes) if lanes.is_filled() => match lanes.solve3(rhs, simd.resolve()) {
                    true => Ok(()),
                    false => Err(SolveError::Factorization),
                },
                _ => self.solve_factored(rhs, 3),
            };
        };
        let Some(plan) = self.plan.as_ref() else {
            return Err(SolveError::Factorization);
        };
        let structure = Structure::of(s);
        let pool = parallel_pool(parallel && plan.splits(), self.factor.len());
        solve3(
            &structure,
            &self.factor,
            plan,
            rhs,
            &mut self.xyz,
            &mut self.scratch,
            pool,
        );
        finite(rhs)
    }
}

/// A solution is finite, or the factorisation failed.
fn finite(x: &[f64]) -> Result<(), SolveError> {
    // Without stopping early, so that it vectorises.
    if x.iter().fold(true, |finite, v| finite & v.is_finite()) {
        Ok(())
    } else {
        Err(SolveError::Factorization)
    }
}

/// Cholesky `A = L Lᵀ` of the row-major `n×n` `a`, `L` written over its
/// lower triangle. False if `a` is not positive definite.
pub(crate) fn cholesky_in_place(a: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let mut d = a[j * n + j];
        for k in 0..j {
            d -= a[j * n + k] * a[j * n + k];
        }
        if d.partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            return false;
        }
        let d = d.sqrt();
        a[j * n + j] = d;
        for i in j + 1..n {
            let mut v = a[i * n + j];
            for k in 0..j {
                v -= a[i * n + k] * a[j * n + k];
            }
            a[i * n + j] = v / d;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::SymbolicSparseColMatRef;

    /// A `side²` grid's weighted Laplacian plus a mass diagonal, full
    /// symmetric CSC, with uneven weights.
    fn grid(side: usize) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
        let n = side * side;
        let (mut col_ptr, mut row_idx, mut values) = (vec![0], Vec::new(), Vec::new());
        for j in 0..n {
            let (r, c) = (j / side, j % side);
            let mut column = Vec::new();
            let mut diag = 1.0 + (j % 7) as f64;
            let mut link = |i: usize| {
                let (lo, hi) = (i.min(j), i.max(j));
                let w = 50.0 + ((lo * 31 + hi * 17) % 13) as f64;
                diag += w;
                column.push((i, -w));
            };
            if r > 0 {
                link(j - side);
            }
            if c > 0 {
                link(j - 1);
            }
            if c + 1 < side {
                link(j + 1);
            }
            if r + 1 < side {
                link(j + side);
            }
            column.push((j, diag));
            column.sort_by_key(|&(i, _)| i);
            for (i, v) in column {
                row_idx.push(i);
                values.push(v);
            }
            col_ptr.push(row_idx.len());
        }
        (col_ptr, row_idx, values)
    }

    #[test]
    fn the_three_column_solve_matches_faers_serially_and_on_two_threads() {
        use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
        ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
        let mut kinds = (false, false);
        // 200² is large enough for the parallel path (PARALLEL_MIN factor
        // entries); 3² and 40² are simplicial, so faer's own solve.
        for (side, supernodal) in [(3, None), (6, Some(true)), (40, None), (200, Some(true))] {
            let (col_ptr, row_idx, values) = grid(side);
            let n = side * side;
            let symbolic = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
            let a = SparseColMatRef::new(symbolic, &values);
            let mut chol = supernodal.map_or_else(SparseCholesky::default, SparseCholesky::forced);
            chol.factorize_llt(a, 3).expect("SPD");
            match chol.symbolic.as_ref().expect("analysed").raw() {
                SymbolicCholeskyRaw::Simplicial(_) => kinds.0 = true,
                SymbolicCholeskyRaw::Supernodal(_) => kinds.1 = true,
            }
            let b: Vec<f64> = (0..3 * n)
                .map(|i| ((i * 7919) % 101) as f64 - 50.0)
                .collect();
            let (mut expected, mut serial, mut parallel) = (b.clone(), b.clone(), b.clone());
            chol.solve_factored(&mut expected, 3).expect("solved");
            chol.solve_factored_xyz(&mut serial, false, Simd::Auto)
                .expect("solved");
            chol.solve_factored_xyz(&mut parallel, true, Simd::Auto)
                .expect("solved");
            assert_eq!(serial, parallel, "{side}²: the same bits on two threads");
            if side == 200 {
                let plan = chol.plan.as_ref().expect("supernodal");
                assert!(plan.splits(), "a grid's tree has two subtrees to split");
            }
            let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(scale > 0.0);
            for (e, g) in expected.iter().zip(&serial) {
                assert!((e - g).abs() <= 1e-12 * scale, "{side}²: {e} vs {g}");
            }
            // And it is a solution: A x = b.
            let mut ax = vec![0.0; 3 * n];
            for c in 0..3 {
                for j in 0..n {
                    for p in col_ptr[j]..col_ptr[j + 1] {
                        ax[c * n + row_idx[p]] += values[p] * serial[c * n + j];
                    }
                }
            }
            for (r, bb) in ax.iter().zip(&b) {
                assert!(
                    (r - bb).abs() <= 1e-9 * (1.0 + bb.abs()),
                    "{side}²: {r} vs {bb}"
                );
            }
        }
        assert!(
            kinds.0 && kinds.1,
            "both factor kinds were exercised: {kinds:?}"
        );
    }

    #[test]
    fn the_lane_solve_is_faers_at_every_simd_level_and_follows_refactorisations() {
        let side = 21;
        let n = side * side;
        let (col_ptr, row_idx, mut values) = grid(side);
        let symbolic = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let mut chol = SparseCholesky::forced(false);
        let b: Vec<f64> = (0..3 * n)
            .map(|i| ((i * 7919) % 101) as f64 - 50.0)
            .collect();
        let mut first_bits = Vec::new();
        for round in 0..2 {
            if round == 1 {
                // New values on the same pattern: a heavier, uneven diagonal.
                for j in 0..n {
                    for p in col_ptr[j]..col_ptr[j + 1] {
                        if row_idx[p] == j {
                            values[p] += 40.0 * (j % 5) as f64;
                        }
                    }
                }
            }
            chol.factorize_llt(SparseColMatRef::new(symbolic, &values), 3)
                .expect("SPD");
            assert!(
                chol.lanes.as_ref().is_some_and(LaneFactor::is_filled),
                "a simplicial factor is solved in lanes"
            );
            let mut expected = b.clone();
            chol.solve_factored(&mut expected, 3).expect("solved");
            let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let mut bits: Option<Vec<f64>> = None;
            for level in Simd::supported() {
                let mut got = b.clone();
                chol.solve_factored_xyz(&mut got, false, level)
                    .expect("solved");
                for (e, g) in expected.iter().zip(&got) {
                    assert!((e - g).abs() <= 1e-12 * scale, "{level:?}: {e} vs {g}");
                }
                match &bits {
                    Some(bits) => assert_eq!(bits, &got, "{level:?}: the same bits"),
                    None => bits = Some(got),
                }
            }
            let bits = bits.expect("the baseline level runs");
            // Written in place in the factor's order and read back by
            // unknown: the same bits as through `rhs`.
            let lanes = chol.lanes().expect("a filled lane factor");
            let (order, rhs) = lanes.rhs_mut();
            for (x, &old) in rhs.iter_mut().zip(order) {
                let old = old as usize;
                *x = [b[old], b[n + old], b[2 * n + old], 0.0];
            }
            assert!(lanes.solve_in_place(Simd::Auto.resolve()));
            for j in 0..n {
                let [x, y, z] = lanes.solution(j);
                assert_eq!([x, y, z], [bits[j], bits[n + j], bits[2 * n + j]]);
            }
            if round == 0 {
                first_bits = bits;
            } else {
                assert_ne!(first_bits, bits, "the refactorised values are used");
            }
        }
        // A failed factorisation leaves no stale values to solve with.
        let mut indefinite = values.clone();
        for v in &mut indefinite {
            *v = -*v;
        }
        assert!(
            chol.factorize_llt(SparseColMatRef::new(symbolic, &indefinite), 3)
                .is_err()
        );
        assert!(
            chol.solve_factored_xyz(&mut b.clone(), false, Simd::Auto)
                .is_err()
        );
        assert!(chol.lanes().is_none() && chol.lanes_ref().is_none());
    }

    #[test]
    fn the_three_column_solve_needs_a_factor_of_the_right_size() {
        let mut chol = SparseCholesky::default();
        assert!(
            chol.solve_factored_xyz(&mut [0.0; 3], false, Simd::Auto)
                .is_err()
        );
        let (col_ptr, row_idx, values) = grid(3);
        let symbolic = SymbolicSparseColMatRef::new_checked(9, 9, &col_ptr, None, &row_idx);
        let mut chol = SparseCholesky::forced(true);
        chol.factorize_llt(SparseColMatRef::new(symbolic, &values), 3)
            .expect("SPD");
        assert!(
            chol.solve_factored_xyz(&mut [0.0; 12], false, Simd::Auto)
                .is_err()
        );
        assert!(
            chol.solve_factored_xyz(&mut [0.0; 27], false, Simd::Auto)
                .is_ok()
        );
    }
}
