//! A sparse Cholesky factorisation shared by the direct methods (the
//! linearly implicit direct solve, the exact method, projective dynamics).

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::sparse::SparseColMatRef;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
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
}

impl SparseCholesky {
    /// Forgets the symbolic analysis (the pattern changed).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    fn analyse(&mut self, a: SparseColMatRef<'_, usize, f64>) -> Result<(), SolveError> {
        if self.symbolic.is_none() {
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
                sym.solve_in_place_scratch::<f64>(1, Par::Seq),
            ])));
            self.symbolic = Some(sym);
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
        self.analyse(a)?;
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
}
