//! Reflection of core (non-Bevy) types, so the model and solver stay free of
//! Bevy traits while components that hold them can still be reflected.

use bevy::reflect::reflect_remote;

/// Reflects [`SpringStiffness`](crate::solver::SpringStiffness).
#[reflect_remote(crate::solver::SpringStiffness)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpringStiffnessReflect {
    /// Stiffness of stretch springs.
    pub stretch: f32,
    /// Stiffness of shear springs.
    pub shear: f32,
    /// Stiffness of bending springs.
    pub bend: f32,
}
