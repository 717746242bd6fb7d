//! Cloths against each other after their steps ([`ClothLayers`]).

use bevy::math::Vec3A;

use super::{Follow, SelfCollision, SelfContacts, inverse_mass, settle};
use crate::model::ClothModel;

/// Cloths against each other after their steps: what each cloth's step
/// could not see (the other cloths move through the step too, while each
/// saw them where they were at its start). Every cloth with a
/// [`SelfCollision`] is [`add`](Self::add)ed with where its step began and
/// ended; [`resolve`](Self::resolve) then finds, in one broad phase, the
/// pairs of vertices of different cloths within the mean of their
/// thicknesses and pushes them apart by inverse mass in
/// at most [`AFTER_STEP_PASSES`](super::AFTER_STEP_PASSES) passes;
/// [`follow`](Self::follow) then pulls each cloth's rings of vertices
/// around those pushed after them.
#[derive(Clone, Debug, Default)]
pub struct ClothLayers {
    contacts: SelfContacts,
    /// Per vertex of all cloths: the step's start, its end, its end
    /// resolved, its motion over the step as a velocity, its inverse mass,
    /// its cloth, half its cloth's thickness and its cloth's friction.
    start: Vec<Vec3A>,
    stepped: Vec<Vec3A>,
    x: Vec<Vec3A>,
    v: Vec<Vec3A>,
    weight: Vec<f32>,
    cloth: Vec<u32>,
    half: Vec<f32>,
    friction: Vec<f32>,
    /// Where each cloth's vertices begin.
    offsets: Vec<usize>,
    /// The rings that follow the pushed vertices.
    follow: Follow,
}

impl ClothLayers {
    /// Empties it for a new step.
    pub fn clear(&mut self) {
        self.start.clear();
        self.stepped.clear();
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
            self.stepped.push(after[i]);
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

    /// After [`resolve`](Self::resolve): pulls the rings of cloth
    /// `index` (of `model`, as added) around the vertices the pushes
    /// moved after them, as `stiff`'s untangling does (the pushed vertices
    /// stay where they were pushed; see `Follow`). A push moves one vertex
    /// by up to the thickness, a third of an edge or more, and left alone
    /// its springs take all of it: two `stiff` sheets landing on each
    /// other over a ball stretched edges 46 % in single steps, and pushed
    /// 23 of their own edges through their triangles (32², 10 s); with
    /// the rings following (here and after the untangling), 2.4 % and
    /// none (5.4 % and none once the edge pass's last bits changed: the
    /// scene is chaotic). The plugin calls it for the cloths whose method kept them off
    /// the others inside its step (`stiff`), whose pushes here are what
    /// the step left over: for the implicit methods the pass is the
    /// answer to the other cloths, and followed too, `newton`'s and the
    /// exact method's sheets stretched more (13.6 and 6.6 % against 12.7
    /// and 4.6 %); PBD limits its springs' strain itself, and followed,
    /// its sheets tangled further (1,655 edges through against 338).
    pub fn follow(&mut self, index: usize, model: &ClothModel) {
        let range = self.range(index);
        if model.vertex_count() != range.len() {
            return;
        }
        let (x, stepped) = (&mut self.x[range.clone()], &self.stepped[range]);
        for (i, (&now, &was)) in x.iter().zip(stepped).enumerate() {
            if now != was {
                self.follow.moved(i, was, x, true);
            }
        }
        self.follow.run(model, x);
    }

    /// Cloth `index`'s resolved positions (as many as it added).
    pub fn positions(&self, index: usize) -> &[Vec3A] {
        &self.x[self.range(index)]
    }

    /// Where cloth `index`'s vertices are.
    fn range(&self, index: usize) -> core::ops::Range<usize> {
        let from = self.offsets.get(index).copied().unwrap_or(self.x.len());
        let to = self.offsets.get(index + 1).copied().unwrap_or(self.x.len());
        from..to
    }
}
