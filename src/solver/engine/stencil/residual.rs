//! The residual `r = b − S x` of a symmetric matrix kept on a grid cloth's
//! stencil, at the CPU's widest SIMD: the finest level of projective
//! dynamics' multigrid.

use crate::solver::engine::simd::at_level;

/// A symmetric matrix on a grid cloth's stencil: per offset family `o`, the
/// coefficient `s_{i, i+o}` at `i` (padded), and the diagonal. Projective
/// dynamics' multigrid keeps its finest level this way.
#[derive(Clone, Debug, Default)]
pub(crate) struct StencilMatrix {
    pub(crate) offsets: Vec<usize>,
    /// The vectors' and coefficients' zero padding on each side: the
    /// largest offset.
    pub(crate) pad: usize,
    /// Per family, `n + 2·pad` (padded).
    pub(crate) coeffs: Vec<Vec<f32>>,
    /// Per vertex: `s_ii` (1 where pinned).
    pub(crate) diag: Vec<f32>,
}

/// Rows per block of the fine residual: a block's vectors stay in L1
/// while each family adds its terms.
const BLOCK: usize = 256;

at_level! {
    /// [`residual_kernel`] at `level`.
    pub(crate) fn stencil_residual(fine: &StencilMatrix, x: &[f32], b: &[f32], r: &mut [f32]) => residual_kernel
}

/// `r = b − S x` on the stencil, `x` padded.
#[inline(always)]
fn residual_kernel(fine: &StencilMatrix, x: &[f32], b: &[f32], r: &mut [f32]) {
    let (n, p) = (r.len(), fine.pad);
    let mut start = 0;
    while start < n {
        let end = (start + BLOCK).min(n);
        let len = end - start;
        let rb = &mut r[start..end];
        let (bb, db, xb) = (
            &b[start..end],
            &fine.diag[start..end],
            &x[p + start..p + end],
        );
        for i in 0..len {
            rb[i] = bb[i] - db[i] * xb[i];
        }
        for (c, &o) in fine.coeffs.iter().zip(&fine.offsets) {
            let (c_up, x_up) = (&c[p + start..p + end], &x[p + start + o..p + end + o]);
            let (c_down, x_down) = (
                &c[p + start - o..p + end - o],
                &x[p + start - o..p + end - o],
            );
            for i in 0..len {
                rb[i] += c_up[i] * x_up[i] + c_down[i] * x_down[i];
            }
        }
        start = end;
    }
}
