//! Cloths against each other (issue N, item 2): before the step, the
//! vertices of every running cloth with a valid [`SelfCollision`] are
//! gathered into one list ([`ClothLayerVertices`]); each such cloth's step
//! then sees the others' vertices where they were at the step's start, and
//! keeps its own off them by its share of each push
//! ([`OtherVertex`]): inside `stiff`'s substeps, after the step for the
//! other methods.

use core::ops::Range;

use bevy::prelude::*;

use super::{Cloth, ClothStats};
use crate::collision::SelfCollision;
use crate::collision::self_contact::OtherVertex;

/// The vertices of the cloths with a [`SelfCollision`], gathered before the
/// step, cloth by cloth in entity order.
#[derive(Resource, Default, Debug)]
pub(crate) struct ClothLayerVertices {
    cloths: Vec<(Entity, Range<usize>)>,
    vertices: Vec<OtherVertex>,
}

impl ClothLayerVertices {
    /// The vertices of every gathered cloth but `entity`: those before its
    /// own and those after (all of them if it was not gathered).
    pub(crate) fn others(&self, entity: Entity) -> [&[OtherVertex]; 2] {
        match self.cloths.binary_search_by_key(&entity, |(e, _)| *e) {
            Ok(k) => {
                let own = self.cloths[k].1.clone();
                [&self.vertices[..own.start], &self.vertices[own.end..]]
            }
            Err(_) => [&self.vertices[..], &[]],
        }
    }
}

/// Gathers [`ClothLayerVertices`] (empty with fewer than two such cloths:
/// a lone cloth has only itself to meet).
pub(crate) fn gather_layers(
    mut layers: ResMut<ClothLayerVertices>,
    cloths: Query<(Entity, &Cloth, &SelfCollision, &ClothStats)>,
) {
    layers.cloths.clear();
    layers.vertices.clear();
    let mut order: Vec<(Entity, &Cloth, &SelfCollision)> = cloths
        .iter()
        .filter(|(_, cloth, sc, stats)| {
            cloth.initialized && stats.is_running() && sc.validate(cloth.model()).is_ok()
        })
        .map(|(e, cloth, sc, _)| (e, cloth, sc))
        .collect();
    if order.len() < 2 {
        return;
    }
    order.sort_unstable_by_key(|(e, ..)| *e);
    for (e, cloth, sc) in order {
        let model = cloth.model();
        let start = layers.vertices.len();
        let state = &cloth.state;
        for (i, &position) in state.positions.iter().enumerate() {
            let weight = if model.pinned()[i] {
                0.0
            } else {
                1.0 / model.masses()[i]
            };
            layers.vertices.push(OtherVertex {
                position,
                weight,
                half_thickness: 0.5 * sc.thickness,
                friction: sc.friction,
            });
        }
        let end = layers.vertices.len();
        layers.cloths.push((e, start..end));
    }
}
