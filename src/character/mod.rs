//! Character cloth: a cloth held near an animated shape, the way game
//! engines hold a cape or a skirt near a skinned character (Unreal's Chaos
//! Cloth "max distance", "backstop" and "anim drive"; NvCloth's motion and
//! separation constraints; Unity Cloth's max distance and surface
//! penetration).
//!
//! Each cloth vertex has a *skinned* position and normal ([`SkinPose`]):
//! where the animation puts it this step. [`SkinConstraints`] say, per
//! vertex, how the simulated vertex relates to it:
//!
//! - **max distance** `r`: the vertex stays within `r` of its skinned
//!   position (0 follows the skin, as a pin; `∞` leaves it free);
//! - **backstop** `d` (with one radius `R` per cloth): the vertex stays
//!   outside a sphere of radius `R` whose surface is `d` behind its skinned
//!   position, along the skinned normal, so a cape stays outside the back
//!   it hangs on (`∞` for none; a large `R` makes it a plane);
//! - **anim drive** `a` (per second, one per cloth): each step moves the
//!   vertex `1 − (1 − a)^dt` of the way to its skinned position, for cloth
//!   that should keep its animated shape (0: none, 1: at once);
//! - **tethers** (long-range attachments, Kim, Chentanez and Müller-Fischer
//!   2012) with a scale `s ≥ 1` (one per cloth): each free vertex stays
//!   within `s` times its rest distance of its nearest pin, whatever the
//!   method, so a cape hanging from its collar does not stretch under its
//!   own weight. The rest distance is the shortest path along the springs
//!   (or the straight line where that is at most a tenth shorter, on a flat
//!   cloth), never shorter than what the cloth can reach without stretching:
//!   a Euclidean distance would let a curved cape (a skirt round the hips)
//!   be pulled taut across its curve, and a geodesic one never does.
//!
//! [`apply_skin`] applies them after a method's step, like a collider's
//! projection: positions are moved, and velocities change by the same
//! displacement over `dt`, in the order drive, tethers, backstop, max
//! distance (the last holds whatever the others did).
//!
//! [`ClothInertia`] says how much of its anchor's motion a cloth feels and
//! moves it rigidly when the anchor is teleported ([`inertia`]).

use bevy::math::Vec3A;
use bevy::reflect::Reflect;
use thiserror::Error;

use crate::model::{ClothModel, ClothState};
use crate::solver::SkinInput;
use crate::solver::xpbd::tethers::{Tethers, hold};

/// Where the animation puts each cloth vertex this step: its skinned
/// position and unit normal, world space, one per cloth vertex.
#[derive(Reflect, Clone, Debug, Default, PartialEq)]
pub struct SkinPose {
    /// Skinned positions.
    pub positions: Vec<Vec3A>,
    /// Skinned unit normals (the side the backstop is behind).
    pub normals: Vec<Vec3A>,
}

/// Per-vertex constraints of a cloth to its [`SkinPose`] (see the
/// [module docs](self)).
#[derive(Reflect, Clone, Debug, PartialEq)]
pub struct SkinConstraints {
    /// Per cloth vertex: how far it may be from its skinned position
    /// (`f32::INFINITY`: no limit; 0: it follows the skin).
    pub max_distance: Vec<f32>,
    /// Per cloth vertex: how far behind its skinned position, along the
    /// skinned normal, the backstop sphere's surface is
    /// (`f32::INFINITY`: no backstop).
    pub backstop_distance: Vec<f32>,
    /// The backstop spheres' radius.
    pub backstop_radius: f32,
    /// Anim drive: the share of the way to its skinned position a vertex
    /// moves per second, in `[0, 1]`.
    pub drive: f32,
    /// Tethers' scale over each vertex's rest distance to its nearest pin,
    /// at least 1 (`f32::INFINITY`: no tethers).
    pub tether_scale: f32,
}

impl SkinConstraints {
    /// No constraint on any of `vertices` vertices.
    pub fn free(vertices: usize) -> Self {
        Self {
            max_distance: vec![f32::INFINITY; vertices],
            backstop_distance: vec![f32::INFINITY; vertices],
            backstop_radius: 1.0,
            drive: 0.0,
            tether_scale: f32::INFINITY,
        }
    }

    /// Each vertex's max distance from `f(vertex)` (a painted weight: 0
    /// follows the skin, `f32::INFINITY` leaves it free).
    #[must_use]
    pub fn with_max_distance(mut self, f: impl Fn(usize) -> f32) -> Self {
        for (i, r) in self.max_distance.iter_mut().enumerate() {
            *r = f(i);
        }
        self
    }

    /// Each vertex's backstop distance from `f(vertex)`, with spheres of
    /// `radius`.
    #[must_use]
    pub fn with_backstop(mut self, radius: f32, f: impl Fn(usize) -> f32) -> Self {
        self.backstop_radius = radius;
        for (i, d) in self.backstop_distance.iter_mut().enumerate() {
            *d = f(i);
        }
        self
    }

    /// An anim drive of `drive` per second.
    #[must_use]
    pub fn with_drive(mut self, drive: f32) -> Self {
        self.drive = drive;
        self
    }

    /// Tethers each free vertex to its nearest pin at `scale` (at least 1)
    /// times its rest distance.
    #[must_use]
    pub fn with_tethers(mut self, scale: f32) -> Self {
        self.tether_scale = scale;
        self
    }

    /// The constraints and `pose` as a method reads them inside its step.
    pub fn input<'a>(&'a self, pose: &'a SkinPose) -> SkinInput<'a> {
        SkinInput {
            positions: &pose.positions,
            previous: None,
            normals: &pose.normals,
            max_distance: &self.max_distance,
            backstop_distance: &self.backstop_distance,
            backstop_radius: self.backstop_radius,
            tether_scale: self.tether_scale,
        }
    }

    /// Checks the constraints against a cloth of `vertices` vertices and a
    /// pose: lengths, and values (distances not NaN nor negative, the
    /// radius positive and finite, the drive in `[0, 1]`, the tether scale
    /// at least 1).
    pub fn validate(&self, vertices: usize, pose: &SkinPose) -> Result<(), SkinError> {
        for got in [
            self.max_distance.len(),
            self.backstop_distance.len(),
            pose.positions.len(),
            pose.normals.len(),
        ] {
            if got != vertices {
                return Err(SkinError::Length {
                    expected: vertices,
                    got,
                });
            }
        }
        let distance = |d: &f32| !d.is_nan() && *d >= 0.0;
        if !(self.max_distance.iter().all(distance) && self.backstop_distance.iter().all(distance))
        {
            return Err(SkinError::Distance);
        }
        if !(self.backstop_radius.is_finite() && self.backstop_radius > 0.0) {
            return Err(SkinError::Radius(self.backstop_radius));
        }
        if !(0.0..=1.0).contains(&self.drive) {
            return Err(SkinError::Drive(self.drive));
        }
        if self.tether_scale.is_nan() || self.tether_scale < 1.0 {
            return Err(SkinError::Tether(self.tether_scale));
        }
        if !(pose.positions.iter().all(|p| p.is_finite())
            && pose.normals.iter().all(|n| n.is_finite()))
        {
            return Err(SkinError::Pose);
        }
        Ok(())
    }
}

/// Why [`SkinConstraints`] cannot act on a cloth.
#[derive(Error, Reflect, Clone, Copy, Debug, PartialEq)]
pub enum SkinError {
    /// A list has another length than the cloth's vertex count.
    #[error("a skin list has {got} entries for a cloth of {expected} vertices")]
    Length {
        /// The cloth's vertex count.
        expected: usize,
        /// The list's length.
        got: usize,
    },
    /// A max distance or backstop distance is NaN or negative.
    #[error("a max distance or backstop distance is NaN or negative")]
    Distance,
    /// The backstop radius is not positive and finite.
    #[error("the backstop radius {0} is not positive and finite")]
    Radius(f32),
    /// The drive is not in `[0, 1]`.
    #[error("the anim drive {0} is not in [0, 1]")]
    Drive(f32),
    /// The tether scale is below 1 or NaN.
    #[error("the tether scale {0} is below 1 or NaN")]
    Tether(f32),
    /// A velocity or acceleration scale of [`ClothInertia`] is not in
    /// `[0, 1]`.
    #[error("an inertia scale {0} is not in [0, 1]")]
    Scale(f32),
    /// The teleport distance of [`ClothInertia`] is not positive (or is
    /// NaN).
    #[error("the teleport distance {0} is not positive")]
    Teleport(f32),
    /// A skinned position or normal is not finite.
    #[error("a skinned position or normal is not finite")]
    Pose,
    /// The skinned mesh lacks positions, normals, joint indices
    /// (`Uint16x4`) or joint weights (`Float32x4`), its lists disagree, or
    /// it does not cover every cloth vertex.
    #[error(
        "the skinned mesh lacks positions, normals, joint indices or weights, or does not \
         match the cloth"
    )]
    Mesh,
    /// A joint weight of the skinned mesh is negative or NaN.
    #[error("a joint weight of the skinned mesh is negative or NaN")]
    Weight,
    /// A joint index past the skinned mesh's joints or inverse bind poses.
    #[error("a joint index is past the skinned mesh's joints")]
    Joint,
}

/// The tethers' rest distances of one cloth, found once per topology and
/// set of pins and kept between steps (Dijkstra from every pin at once is
/// the one costly part of [`apply_skin`]).
#[derive(Clone, Debug, Default)]
pub struct SkinTethers {
    tethers: Tethers,
    /// The pins' positions this step, by their place among the pins.
    anchors: Vec<Vec3A>,
}

/// Applies `constraints` to `state` after a step of `dt` seconds (see the
/// [module docs](self)); pinned vertices are left alone. Returns how many
/// vertices a tether, backstop or max distance moved. Call
/// [`SkinConstraints::validate`] first: lists of other lengths are cut to
/// the shortest. `tethers` keeps the tethers' rest distances between calls
/// (one per cloth).
pub fn apply_skin(
    model: &ClothModel,
    state: &mut ClothState,
    pose: &SkinPose,
    constraints: &SkinConstraints,
    tethers: &mut SkinTethers,
    dt: f32,
) -> usize {
    if dt <= 0.0 {
        return 0;
    }
    let scale = constraints.tether_scale;
    let SkinTethers { tethers, anchors } = tethers;
    anchors.clear();
    let ties: &[(u32, f32)] = if scale.is_finite() && !model.pins().is_empty() {
        tethers.update(model);
        // The pins are not moved here: read them before the loop.
        anchors.extend(model.pins().iter().map(|&p| state.positions[p as usize]));
        &tethers.ties
    } else {
        &[]
    };
    let inv_dt = 1.0 / dt;
    let pull = 1.0 - (1.0 - constraints.drive).powf(dt);
    let input = constraints.input(pose);
    let mut held = 0;
    let ClothState {
        positions,
        velocities,
    } = state;
    let vertices = (positions.iter_mut().zip(velocities.iter_mut())).zip(model.pinned());
    let n = pose.positions.len().min(pose.normals.len());
    let n = n
        .min(constraints.max_distance.len())
        .min(constraints.backstop_distance.len());
    for (i, ((x, v), &pinned)) in vertices.enumerate().take(n) {
        if pinned {
            continue;
        }
        let start = *x;
        if pull > 0.0 {
            *x += pull * (pose.positions[i] - *x);
        }
        let mut moved = false;
        if let Some(&(place, rest)) = ties.get(i)
            && rest.is_finite()
        {
            let before = *x;
            hold(x, anchors[place as usize], rest * scale);
            moved |= *x != before;
        }
        moved |= input.hold(i, x);
        held += usize::from(moved);
        *v += (*x - start) * inv_dt;
    }
    held
}

mod ecs;
pub mod inertia;
pub use ecs::{
    ATTRIBUTE_CLOTH_BACKSTOP, ATTRIBUTE_CLOTH_MAX_DISTANCE, CharacterClothPlugin, ClothSkin,
    Skinning,
};
pub use inertia::ClothInertia;
mod save;
pub use save::CharacterSnapshot;

#[cfg(test)]
mod tests;
