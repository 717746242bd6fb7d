//! What the unit tests share: deterministic pseudo-random numbers (Knuth's
//! MMIX linear congruential generator: the same sequence on every machine
//! and run) and a cloth run for some steps of a method.

use bevy::math::{Affine3A, Vec3A};

use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState};
use crate::solver::{Method, StepParams};

/// Advances `seed` and returns it.
pub(crate) fn next_u64(seed: &mut u64) -> u64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    *seed
}

/// A pseudo-random vector in [-1, 1]³.
pub(crate) fn noise(seed: &mut u64) -> Vec3A {
    let mut next = || ((next_u64(seed) >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0;
    Vec3A::new(next(), next(), next())
}

/// `model` from rest after `steps` steps of `method` (a fresh workspace),
/// with `spheres` acting inside each step.
pub(crate) fn run_from_rest<M: Method>(
    method: &M,
    model: &ClothModel,
    params: &StepParams,
    spheres: &[PenaltySphere],
    steps: usize,
) -> ClothState {
    let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
    let mut ws = M::Workspace::default();
    for _ in 0..steps {
        method
            .step(model, &mut state, params, spheres, &mut ws)
            .expect("a valid step");
    }
    state
}
