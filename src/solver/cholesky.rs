//! A sparse Cholesky factorisation shared by the direct methods (the
//! linearly implicit direct solve, the exact method, projective dynamics).

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::SparseColMatRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
    factorize_symbolic_cholesky,
};
use faer::{Conj, MatMut, Par, Side};

use super::SolveError;

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
}

impl SparseCholesky {
    /// Forgets the symbolic analysis (the pattern changed).
    pub fn reset(&mut self) {
        *self = Self::default();
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
                CholeskySymbolicParams::default(),
            )
            .map_err(|_| SolveError::Factorization)?;
            self.factor.resize(sym.len_val(), 0.0);
            self.memory = Some(MemBuffer::new(StackReq::any_of(&[
                sym.factorize_numeric_ldlt_scratch::<f64>(Par::Seq, Default::default()),
                sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
                sym.solve_in_place_scratch::<f64>(columns, Par::Seq),
            ])));
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
        if rhs.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(SolveError::Factorization)
        }
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
        if rhs.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(SolveError::Factorization)
        }
    }
}
