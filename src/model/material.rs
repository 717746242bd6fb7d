//! Cloth as a material: sheet stiffness and areal density, from which each
//! spring's stiffness and each vertex's mass follow at any resolution.
//!
//! **Masses.** Each triangle's mass, its area times the density, goes a
//! third to each of its corners (a lumped mass matrix).
//!
//! **Stiffness.** A sheet's stretch stiffness `E` (N/m: the force per metre
//! of width that strains it by 1, Young's modulus times thickness) is made
//! of springs of one kind with stiffness `k` each. A uniform strain `ε` in
//! direction `n` stretches a spring of rest length `L` along `d` by
//! `L·(d·n)²·ε`, storing `½k·L²·(d·n)⁴·ε²`; over the directions `n` the
//! mean of `(d·n)⁴` is 3/8, so springs of total `Σ L²` over an area `A`
//! give the sheet a mean modulus `k·(3/8)·Σ L²/A`, and
//!
//! `k = E·A / ((3/8)·Σ L²)`,
//!
//! the same at every resolution of a mesh (`Σ L²` grows as the area over
//! the edge length squared times the edge length squared). On the lab's
//! square grid (edges and one diagonal per cell) that is `k = E/1.5` in its
//! interior, where a strain along the grid meets `1.5·k`: the lab's
//! `k = 8000` is a sheet of about 12 kN/m. Shear and bending springs, where
//! the cloth has them, take their kind's modulus the same way.
//!
//! A spring network is not an isotropic sheet (the lab's grid is stiffer
//! along its diagonals than across them): the modulus is the mean over
//! directions, and the masses are exact.

use bevy::ecs::component::Component;
use bevy::ecs::reflect::ReflectComponent;
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use super::{ClothModel, ClothTopology, SpringKind};
use crate::solver::{ParamError, SpringStiffness};

/// What a cloth is made of: its sheet stiffness per spring kind (N/m) and
/// its areal density (kg/m²). The per-spring stiffness and per-vertex mass
/// follow from the mesh (see the module docs), so the same material behaves
/// the same at 16² and at 64².
///
/// Two uses:
/// - [`ClothBuilder::with_material`](super::ClothBuilder::with_material)
///   gives the model its masses, and
///   [`ClothMaterial::spring_stiffness`] gives
///   [`ClothParams::stiffness`](crate::ClothParams::stiffness);
/// - as a component on a cloth entity it does both for the cloth, at every
///   fixed step (the stiffness) and whenever the density or the model
///   changes (the masses), in place of the cloth's `ClothParams::stiffness`
///   and the builder's masses.
///
/// ```
/// use bevy_cloth::prelude::*;
/// use bevy::math::Vec3;
///
/// // A 2 m square cape of cotton, 32×32 vertices, hung by its top edge.
/// let material = ClothMaterial::COTTON;
/// let model = ClothBuilder::grid(32, 32, Vec3::ZERO, Vec3::X * 2.0, Vec3::NEG_Y * 2.0)
///     .with_material(material)
///     .with_pins(0..32)
///     .build()
///     .unwrap();
/// let mass: f32 = model.masses().iter().sum();
/// assert!((mass - 4.0 * material.density).abs() < 1e-4);
/// let k = material.spring_stiffness(&model);
/// assert!(k.stretch > 0.6 * material.stretch && k.stretch < 0.7 * material.stretch);
/// ```
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct ClothMaterial {
    /// Stretch stiffness of the sheet, N/m (Young's modulus times
    /// thickness), carried by the stretch springs (the triangle edges).
    pub stretch: f32,
    /// The modulus the shear springs add, N/m (if the cloth has them).
    pub shear: f32,
    /// The modulus the bending springs add, N/m (if the cloth has them):
    /// they resist folding as they are stretched across it.
    pub bend: f32,
    /// Mass per unit area, kg/m².
    pub density: f32,
}

impl ClothMaterial {
    /// A woven cotton (shirting to light twill): 12 kN/m in stretch (the
    /// lab's `k = 8000` on its grid), shear springs as stiff, bending
    /// springs a hundredth of that, 0.25 kg/m² (a 2 m square cape weighs
    /// 1 kg).
    pub const COTTON: Self = Self {
        stretch: 1.2e4,
        shear: 1.2e4,
        bend: 1.2e2,
        density: 0.25,
    };

    /// This material with another stretch stiffness (N/m).
    #[must_use]
    pub const fn with_stretch(mut self, stretch: f32) -> Self {
        self.stretch = stretch;
        self
    }

    /// This material with another areal density (kg/m²).
    #[must_use]
    pub const fn with_density(mut self, density: f32) -> Self {
        self.density = density;
        self
    }

    /// Checks that every modulus and the density are finite and positive.
    pub fn validate(&self) -> Result<(), ParamError> {
        SpringStiffness {
            stretch: self.stretch,
            shear: self.shear,
            bend: self.bend,
        }
        .validate()?;
        if !(self.density.is_finite() && self.density > 0.0) {
            return Err(ParamError::Density(self.density));
        }
        Ok(())
    }

    /// Each spring kind's stiffness (N/m per spring) on `model`'s mesh:
    /// `k = E·A/((3/8)·Σ L²)` (see the module docs).
    pub fn spring_stiffness(&self, model: &ClothModel) -> SpringStiffness {
        let [stretch, shear, bend] = model.topology().sheet_factors();
        SpringStiffness {
            stretch: self.stretch * stretch,
            shear: self.shear * shear,
            bend: self.bend * bend,
        }
    }

    /// Each vertex's mass on `topology`'s rest mesh: a third of the mass of
    /// each triangle it is a corner of.
    pub fn masses(&self, topology: &ClothTopology) -> Vec<f32> {
        super::builder::lumped_masses(
            topology.rest_positions(),
            topology.triangles(),
            self.density,
        )
    }
}

impl Default for ClothMaterial {
    /// [`ClothMaterial::COTTON`].
    fn default() -> Self {
        Self::COTTON
    }
}

/// Per spring kind, the stiffness per spring of one N/m of sheet modulus:
/// `A/((3/8)·Σ L²)` over the springs of that kind (1 for a kind the mesh
/// does not have, or a mesh without area).
pub(crate) fn sheet_factors(topology_area: f32, springs: &[super::Spring]) -> [f32; 3] {
    let mut sums = [0.0f64; 3];
    for s in springs {
        sums[s.kind as usize] += f64::from(s.rest_length) * f64::from(s.rest_length);
    }
    [SpringKind::Stretch, SpringKind::Shear, SpringKind::Bend].map(|kind| {
        let sum = sums[kind as usize];
        if sum > 0.0 && topology_area > 0.0 {
            (f64::from(topology_area) / (0.375 * sum)) as f32
        } else {
            1.0
        }
    })
}
