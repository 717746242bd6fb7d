//! Inertia control and teleports: how much of its anchor's motion a cloth
//! feels (Unity Cloth's world velocity and acceleration scales), and a
//! rigid move with the anchor when it jumps.
//!
//! A cloth is simulated in world space, so a cape hanging from a running
//! character feels all of the character's motion: it trails behind at
//! speed and swings at every start, stop and turn. [`ClothInertia`] names
//! an *anchor* entity (the character's root; by default the cloth's own
//! entity) and, before every step, reads the anchor's rigid motion `Δ`
//! over the step (its global transform now times its inverse a step ago):
//!
//! - **velocity scale** `s_v`: the cloth is carried by `1 − s_v` of `Δ`,
//!   positions only (each free vertex `x` moves by `(1 − s_v)·(Δx − x)`,
//!   and the pins' last positions likewise, so their velocity over the step
//!   is what is left). At 1 the cloth feels all of the motion (world space);
//!   at 0 it moves as if simulated in the anchor's frame.
//! - **acceleration scale** `s_a`: of the anchor's change of velocity at a
//!   vertex over the step (`u(x) = (Δx − x)/dt` now minus a step ago), the
//!   cloth's free vertices take `s_v·(1 − s_a)` into their velocity at once
//!   instead of lagging behind it. At 1 they lag (world space); at 0 a start,
//!   stop or turn does not swing them.
//! - **teleport distance**: when the anchor's origin moves further than
//!   this in one step, the whole cloth moves with it rigidly (positions by
//!   `Δ`, velocities turned with it, the guard's last good state too), so it
//!   is not dragged across the jump and the guard sees nothing to catch.

use bevy::math::{Affine3A, Vec3A};
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;

use super::{ClothSkin, SkinError};
use crate::ecs::{Cloth, ClothStats};

/// How much of its anchor's motion a cloth feels, and from what jump the
/// anchor counts as teleported (see the [module docs](self)). Handled by
/// [`CharacterClothPlugin`](super::CharacterClothPlugin) for every method;
/// the default (`1`, `1`, no teleport) changes nothing.
#[derive(Component, Clone, Debug, PartialEq)]
pub struct ClothInertia {
    /// The entity whose motion the scales measure (`None`: the cloth's own).
    pub anchor: Option<Entity>,
    /// Share of the anchor's velocity the cloth feels, in `[0, 1]`.
    pub velocity_scale: f32,
    /// Share of the anchor's acceleration the cloth feels, in `[0, 1]`.
    pub acceleration_scale: f32,
    /// A jump of the anchor's origin in one step beyond which the cloth
    /// moves with it rigidly (`f32::INFINITY`: never).
    pub teleport_distance: f32,
    /// The anchor's global transform at the last step and its motion over
    /// that step.
    pub(super) last: Option<(Affine3A, Affine3A)>,
}

impl Default for ClothInertia {
    fn default() -> Self {
        Self {
            anchor: None,
            velocity_scale: 1.0,
            acceleration_scale: 1.0,
            teleport_distance: f32::INFINITY,
            last: None,
        }
    }
}

impl ClothInertia {
    /// The anchor's motion measured on `anchor` instead of the cloth's own
    /// entity.
    #[must_use]
    pub fn with_anchor(mut self, anchor: Entity) -> Self {
        self.anchor = Some(anchor);
        self
    }

    /// The velocity and acceleration scales.
    #[must_use]
    pub fn with_scales(mut self, velocity: f32, acceleration: f32) -> Self {
        self.velocity_scale = velocity;
        self.acceleration_scale = acceleration;
        self
    }

    /// The teleport distance.
    #[must_use]
    pub fn with_teleport(mut self, distance: f32) -> Self {
        self.teleport_distance = distance;
        self
    }

    /// Checks the scales (in `[0, 1]`) and the teleport distance (positive,
    /// not NaN).
    pub fn validate(&self) -> Result<(), SkinError> {
        for s in [self.velocity_scale, self.acceleration_scale] {
            if !(0.0..=1.0).contains(&s) {
                return Err(SkinError::Scale(s));
            }
        }
        if self.teleport_distance.is_nan() || self.teleport_distance <= 0.0 {
            return Err(SkinError::Teleport(self.teleport_distance));
        }
        Ok(())
    }

    /// Forgets the anchor's last transform: the next step measures no
    /// motion (after the game places the cloth anew).
    pub fn reset(&mut self) {
        self.last = None;
    }
}

/// What [`carry`] did to a cloth this step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Carried {
    /// Nothing: the first step, or no motion to scale.
    Nothing,
    /// Carried by a share of the anchor's motion.
    Scaled,
    /// Moved rigidly with a teleported anchor.
    Teleported,
}

/// Applies `inertia` to `cloth` given its anchor's global transform `now`,
/// before a step of `dt` seconds (see the [module docs](self)). `skin`, a
/// character cloth's skinned positions at the last step, moves with the
/// pins' last positions: the step moves the skin from there.
pub(super) fn carry(
    inertia: &mut ClothInertia,
    cloth: &mut Cloth,
    skin: Option<&mut [Vec3A]>,
    now: Affine3A,
    dt: f32,
) -> Carried {
    let Some((before, last_motion)) = inertia.last else {
        inertia.last = Some((now, Affine3A::IDENTITY));
        return Carried::Nothing;
    };
    // An anchor scaled to nothing (hidden) or not finite has no motion to
    // read: the cloth waits for it where it last was.
    let det = now.matrix3.determinant();
    if dt <= 0.0 || !now.is_finite() || !det.is_normal() {
        return Carried::Nothing;
    }
    let motion = now * before.inverse();
    let jump = now.translation.distance(before.translation);
    if jump > inertia.teleport_distance {
        // The last step's motion stays the reference for the next one's
        // acceleration (the jump is no velocity), carried to where the
        // anchor is now: a motion is a map of the whole space, and a turn
        // read 100 m from where it was measured would be a fling.
        inertia.last = Some((now, motion * last_motion * motion.inverse()));
        teleport(cloth, &motion);
        for p in skin.into_iter().flatten() {
            *p = motion.transform_point3a(*p);
        }
        return Carried::Teleported;
    }
    inertia.last = Some((now, motion));
    let share = 1.0 - inertia.velocity_scale;
    let take = inertia.velocity_scale * (1.0 - inertia.acceleration_scale);
    if share == 0.0 && take == 0.0 {
        return Carried::Nothing;
    }
    let inv_dt = 1.0 / dt;
    let pinned = cloth.model.pinned();
    let state = &mut cloth.state;
    let vertices = state.positions.iter_mut().zip(&mut state.velocities);
    for ((x, v), &pinned) in vertices.zip(pinned) {
        if pinned {
            continue;
        }
        let moved = motion.transform_point3a(*x) - *x;
        if take > 0.0 {
            let was = last_motion.transform_point3a(*x) - *x;
            *v += take * (moved - was) * inv_dt;
        }
        *x += share * moved;
    }
    if share > 0.0 {
        let skin = skin.into_iter().flatten();
        for p in cloth.pins_stepped.iter_mut().map(|(_, p)| p).chain(skin) {
            *p += share * (motion.transform_point3a(*p) - *p);
        }
    }
    cloth.measured = None;
    Carried::Scaled
}

/// Moves every vertex of `cloth` (its state, its pins' last positions and
/// its last good state) rigidly by `motion`, velocities turned with it.
fn teleport(cloth: &mut Cloth, motion: &Affine3A) {
    let pinned = cloth.model.pinned();
    for state in [&mut cloth.state, &mut cloth.last_good] {
        let vertices = state.positions.iter_mut().zip(&mut state.velocities);
        for ((x, v), &pinned) in vertices.zip(pinned) {
            // The pins are already where their entity or skin put them.
            if !pinned {
                *x = motion.transform_point3a(*x);
            }
            *v = motion.transform_vector3a(*v);
        }
    }
    for (_, p) in &mut cloth.pins_stepped {
        *p = motion.transform_point3a(*p);
    }
    cloth.measured = None;
}

/// Before the step (after the pins are placed): carries every cloth with a
/// [`ClothInertia`] by its share of its anchor's motion, or moves it with
/// a teleported anchor. A cloth whose inertia is refused is skipped with a
/// warning, once per entity.
pub(super) fn carry_with_anchor(
    time: Res<Time>,
    helper: TransformHelper,
    mut cloths: Query<(
        Entity,
        &mut Cloth,
        &mut ClothInertia,
        &ClothStats,
        Option<&mut ClothSkin>,
    )>,
    mut warned: Local<Vec<Entity>>,
) {
    let dt = time.delta_secs();
    for (entity, mut cloth, mut inertia, stats, skin) in &mut cloths {
        if !cloth.initialized || !stats.is_running() {
            continue;
        }
        if let Err(error) = inertia.validate() {
            if !warned.contains(&entity) {
                warn!("cloth {entity}'s inertia is ignored: {error}");
                warned.push(entity);
            }
            continue;
        }
        let anchor = inertia.anchor.unwrap_or(entity);
        let Ok(global) = helper.compute_global_transform(anchor) else {
            continue;
        };
        let skin = skin.map(|s| s.into_inner().previous.as_mut_slice());
        carry(&mut inertia, &mut cloth, skin, global.affine(), dt);
    }
}
