//! Cloths against each other (issue N, item 2): every running cloth with a
//! [`SelfCollision`] is kept off every other such cloth after their steps,
//! in one broad phase across them ([`ClothLayers`]).

use bevy::prelude::*;

use super::{Cloth, ClothStats};
use crate::collision::SelfCollision;
use crate::collision::self_contact::ClothLayers;

/// This step's cloths in [`ClothLayers`], in entity order.
#[derive(Default)]
pub(crate) struct Added(Vec<Entity>);

/// Keeps cloths with a [`SelfCollision`] off each other, in
/// [`ClothSystems::Collide`](super::ClothSystems::Collide) before the
/// colliders' projection (so a collider wins). A vertex moved by another
/// cloth counts as one of its cloth's contacts, and its velocity changes by
/// that move over the step; the guard measures the cloth again.
pub(crate) fn collide_cloths(
    time: Res<Time>,
    mut layers: Local<ClothLayers>,
    mut added: Local<Added>,
    mut cloths: Query<(Entity, &mut Cloth, &SelfCollision, &mut ClothStats)>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 {
        return;
    }
    layers.clear();
    added.0.clear();
    let mut order: Vec<Entity> = cloths.iter().map(|(e, ..)| e).collect();
    if order.len() < 2 {
        return;
    }
    order.sort_unstable();
    for e in order {
        let Ok((_, cloth, sc, stats)) = cloths.get(e) else {
            continue;
        };
        let model = cloth.model();
        let n = model.vertex_count();
        if !cloth.initialized
            || !stats.is_running()
            || sc.validate(model).is_err()
            || cloth.last_good.positions.len() != n
            || cloth.state.positions.len() != n
        {
            continue;
        }
        layers.add(
            model,
            &cloth.last_good.positions,
            &cloth.state.positions,
            dt,
            *sc,
        );
        added.0.push(e);
    }
    if added.0.len() < 2 {
        return;
    }
    layers.resolve(dt);
    let inv_dt = 1.0 / dt;
    for (index, &e) in added.0.iter().enumerate() {
        let Ok((_, mut cloth, _, mut stats)) = cloths.get_mut(e) else {
            continue;
        };
        let cloth = &mut *cloth;
        let mut moved = 0;
        for ((x, v), &resolved) in cloth
            .state
            .positions
            .iter_mut()
            .zip(cloth.state.velocities.iter_mut())
            .zip(layers.positions(index))
        {
            if resolved != *x {
                *v += (resolved - *x) * inv_dt;
                *x = resolved;
                moved += 1;
            }
        }
        if moved > 0 {
            cloth.measured = None;
            stats.contacts += moved;
        }
    }
}
