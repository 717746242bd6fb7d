//! Conjugate gradients on the assembled system (faer's matrix-free CG),
//! warm-started with the previous velocities.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::matrix_free::conjugate_gradient::{
    CgError, CgParams, conjugate_gradient, conjugate_gradient_scratch,
};
use faer::matrix_free::{IdentityPrecond, InitialGuessStatus};
use faer::{MatMut, MatRef, Par};

use super::{CgConfig, LinearSystem, Preconditioner};
use crate::solver::SolveError;

pub(super) fn solve(
    system: &LinearSystem,
    cg: &CgConfig,
    solution: &mut [f64],
    inv_diag: &mut [f64],
    memory: &mut Option<MemBuffer>,
) -> Result<(u32, f64), SolveError> {
    let n = system.dimension();
    let a = system.matrix();
    let params = CgParams {
        initial_guess: InitialGuessStatus::MaybeNonZero,
        abs_tolerance: 0.0,
        rel_tolerance: cg.tolerance,
        max_iters: cg.max_iterations as usize,
        ..Default::default()
    };
    let identity = IdentityPrecond { dim: n };
    let memory = memory.get_or_insert_with(|| {
        MemBuffer::new(StackReq::any_of(&[
            conjugate_gradient_scratch(identity, a, 1, Par::Seq),
            conjugate_gradient_scratch(
                faer::diag::DiagRef::from_slice(&inv_diag[..]),
                a,
                1,
                Par::Seq,
            ),
        ]))
    });
    let stack = MemStack::new(memory);
    let out = MatMut::from_column_major_slice_mut(solution, n, 1);
    let rhs = MatRef::from_column_major_slice(system.rhs(), n, 1);
    let result = match cg.preconditioner {
        Preconditioner::None => {
            conjugate_gradient(out, identity, a, rhs, params, |_| {}, Par::Seq, stack)
        }
        Preconditioner::Jacobi => {
            system.diagonal(inv_diag);
            for d in inv_diag.iter_mut() {
                *d = 1.0 / *d;
            }
            let precond = faer::diag::DiagRef::from_slice(&inv_diag[..]);
            conjugate_gradient(out, precond, a, rhs, params, |_| {}, Par::Seq, stack)
        }
    };
    match result {
        Ok(info) => Ok((info.iter_count as u32, info.rel_residual)),
        Err(CgError::NoConvergence { rel_residual, .. }) => Ok((cg.max_iterations, rel_residual)),
        Err(CgError::NonPositiveDefiniteOperator)
        | Err(CgError::NonPositiveDefinitePreconditioner) => Err(SolveError::NotPositiveDefinite),
    }
}
