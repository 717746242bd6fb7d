//! The spring pass as the methods call it: each spring's gradient term from
//! the step's stiffness, over chunks and at the step's SIMD level (the
//! engine's kernels underneath; hidden from the docs, the report times it).

use bevy::math::Vec3A;

use super::params::{SpringStiffness, StepParams};
use crate::model::ClothModel;
use crate::solver::engine::kernels::{Springs, for_chunks};
use crate::solver::engine::simd::spring_products;

/// Per spring `[k, kL]`, the coefficients of the implicit gradient term
/// `d·k(1 − L/l)` for the spring pass.
pub fn stiffness_coeffs(model: &ClothModel, stiffness: &SpringStiffness, out: &mut Vec<[f32; 2]>) {
    let k = stiffness.as_array();
    out.clear();
    out.extend(model.topology().springs().iter().map(|s| {
        let k = k[s.kind as usize];
        [k, k * s.rest_length]
    }));
}

/// Fills `terms[e]` with each spring's gradient term `k(1 − L/l)(x_a − x_b)`
/// at positions `x`, in parallel chunks for large cloths
/// ([`StepParams::parallel`](crate::solver::StepParams::parallel)), at the SIMD
/// level [`StepParams::simd`](crate::solver::StepParams::simd) chooses (the same
/// bits at every level). `coeffs` is from [`stiffness_coeffs`].
pub fn spring_terms(
    params: &StepParams,
    model: &ClothModel,
    x: &[Vec3A],
    coeffs: &[[f32; 2]],
    terms: &mut [Vec3A],
) {
    let springs = Springs::of(model);
    for_chunks(params.parallel, terms, |start, terms| {
        let end = start + terms.len();
        spring_products(
            params.simd,
            springs.range(start..end),
            &coeffs[start..end],
            x,
            terms,
        );
    });
}
