//! Chebyshev semi-iterative acceleration (Wang 2015, "A Chebyshev
//! semi-iterative approach for accelerating projective and position-based
//! dynamics"), shared by the implicit Jacobi iteration and projective
//! dynamics: the setting ([`Rho`]), the weights, the estimate of `ρ` and the
//! blend of an update with the iterate before last.

use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

pub(crate) use super::engine::kernels::blend;
use super::{LAB_RHO, ParamError};

/// The spectral radius `ρ` that Chebyshev acceleration assumes.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
pub enum Rho {
    /// A fixed value in `(0, 1)` (the lab: 0.995).
    Fixed(f32),
    /// Estimated each step: the first `S = clamp(K/4, 2, 8)` iterations are
    /// plain Jacobi, and `ρ` is the geometric mean decay of their update
    /// norms `‖x_{k+1} − x_k‖` over the second half of them (Wang 2015
    /// delays acceleration for the same reason); Chebyshev then runs with it.
    Auto,
}

impl Default for Rho {
    /// The lab's fixed `ρ = 0.995`.
    fn default() -> Self {
        Self::Fixed(LAB_RHO)
    }
}

/// Checks an iteration count and a Chebyshev setting (shared by every
/// Chebyshev-accelerated method).
pub(crate) fn validate_chebyshev(
    iterations: u32,
    chebyshev: Option<Rho>,
) -> Result<(), ParamError> {
    if iterations == 0 {
        return Err(ParamError::Iterations);
    }
    if let Some(Rho::Fixed(rho)) = chebyshev
        && !(rho > 0.0 && rho < 1.0)
    {
        return Err(ParamError::Rho(rho));
    }
    Ok(())
}

/// Chebyshev's weight for iteration `k` when acceleration starts after
/// `delay` plain iterations: `ω₁ = 1`, `ω₂ = 2/(2 − ρ²)`,
/// `ω_{k+1} = 4/(4 − ρ²ω_k)` (Wang 2015), from the previous `omega`.
pub(crate) fn chebyshev_omega(k: u32, delay: u32, rho: f32, omega: f32) -> f32 {
    match k.checked_sub(delay) {
        None | Some(0) => 1.0,
        Some(1) => 2.0 / (2.0 - rho * rho),
        _ => 4.0 / (4.0 - rho * rho * omega),
    }
}

/// `ρ` from successive Jacobi update norms `‖x_{k+1} − x_k‖`: their
/// geometric mean decay over the second half, clamped to `[0.5, 0.9999]`
/// (0.9 when there are too few). Used by [`Rho::Auto`].
pub fn rho_from_update_norms(norms: &[f64]) -> f32 {
    let (lo, hi) = (norms.len() / 2, norms.len().saturating_sub(1));
    if hi <= lo || norms[lo] <= 0.0 || !norms[hi].is_finite() {
        return 0.9;
    }
    ((norms[hi] / norms[lo]).powf(1.0 / (hi - lo) as f64) as f32).clamp(0.5, 0.9999)
}
