//! Cloths against each other after their steps ([`ClothLayers`]).

use bevy::math::Vec3A;

use super::{SelfCollision, SelfContacts, inverse_mass, settle};
use crate::model::ClothModel;

/// Cloths against each other after their steps: what each cloth's step
/// could not see (the other cloths move through the step too, while each
/// saw them where they were at its start). Every cloth with a
/// [`SelfCollision`] is [`add`](Self::add)ed with where its step began and
/// ended; [`resolve`](Self::resolve) then finds, in one broad phase, the
/// pairs of vertices of different cloths within the mean of their
/// thicknesses and pushes them apart by inverse mass in
/// at most [`AFTER_STEP_PASSES`](super::AFTER_STEP_PASSES) passes.
#[derive(Clone, Debug, Default)]
pub struct ClothLayers {
    contacts: SelfContacts,
    /// Per vertex of all cloths: the step's start, its end (resolved in
    /// place), its motion over the step as a velocity, its inverse mass,
    /// its cloth, half its cloth's thickness and its cloth's friction.
    start: Vec<Vec3A>,
    x: Vec<Vec3A>,
    v: Vec<Vec3A>,
    weight: Vec<f32>,
    cloth: Vec<u32>,
    half: Vec<f32>,
    friction: Vec<f32>,
    /// Where each cloth's vertices begin.
    offsets: Vec<usize>,
}

impl ClothLayers {
    /// Empties it for a new step.
    pub fn clear(&mut self) {
        self.start.clear();
        self.x.clear();
        self.v.clear();
        self.weight.clear();
        self.cloth.clear();
        self.half.clear();
        self.friction.clear();
        self.offsets.clear();
    }

    /// Adds a cloth whose step of `dt` went from `before` to `after`;
    /// returns its index among those added.
    pub fn add(
        &mut self,
        model: &ClothModel,
        before: &[Vec3A],
        after: &[Vec3A],
        dt: f32,
        sc: SelfCollision,
    ) -> usize {
        let index = self.offsets.len();
        self.offsets.push(self.x.len());
        let n = model.vertex_count().min(before.len()).min(after.len());
        let inv_dt = 1.0 / dt;
        for i in 0..n {
            self.start.push(before[i]);
            self.x.push(after[i]);
            self.v.push((after[i] - before[i]) * inv_dt);
            self.weight.push(inverse_mass(model, i));
            self.cloth.push(index as u32);
            self.half.push(0.5 * sc.thickness);
            self.friction.push(sc.friction);
        }
        index
    }

    /// Finds the pairs across cloths over the step of `dt` and pushes them
    /// apart; returns the pairs the steps left too close (the first pass's).
    pub fn resolve(&mut self, dt: f32) -> u32 {
        if self.offsets.len() < 2 {
            return 0;
        }
        let Self {
            contacts,
            start,
            x,
            v,
            weight,
            cloth,
            half,
            friction,
            ..
        } = self;
        let cell = 2.0 * half.iter().copied().fold(0.0, f32::max);
        contacts.find_where(
            start,
            v,
            dt,
            [cell, 0.0],
            |i| half[i],
            |a, b| {
                (cloth[a] != cloth[b] && weight[a] + weight[b] > 0.0)
                    .then(|| (half[a] + half[b], 0.5 * (friction[a] + friction[b])))
            },
        );
        contacts.own = x.len();
        contacts.others.clear();
        settle(|| {
            contacts.resolve_weighted(contacts.pairs.iter(), x, |i| start[i], 1.0, |i| weight[i])
        })
    }

    /// Cloth `index`'s resolved positions (as many as it added).
    pub fn positions(&self, index: usize) -> &[Vec3A] {
        let from = self.offsets.get(index).copied().unwrap_or(self.x.len());
        let to = self.offsets.get(index + 1).copied().unwrap_or(self.x.len());
        &self.x[from..to]
    }
}
