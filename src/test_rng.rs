//! The tests' deterministic pseudo-random numbers (Knuth's MMIX linear
//! congruential generator): the same sequence on every machine and run.

use bevy::math::Vec3A;

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
