//! Cloths against each other (issue N, item 2): before the step, the
//! vertices of every running cloth with a valid [`SelfCollision`] are
//! gathered into one list ([`ClothLayerVertices`]); each such cloth's step
//! then sees the others' vertices where they were at the step's start, and
//! keeps its own off them by its share of each push
//! ([`OtherVertex`]): inside `stiff`'s substeps, after the step for the
//! other methods. After every cloth's step, one pass over all of them
//! ([`ClothLayers`]) pushes apart what the steps could not see: each moved
//! while the others stood still in its view; then, for each two cloths
//! whose boxes meet, the edges of one already through the other's
//! triangles are taken back out (`untangle_between`).
//!
//! That take-back costs two exact checks between the cloths, many times
//! a cloth's step (the CHANGELOG has the numbers), so it runs only when
//! edges can have gone through: the first step two cloths are seen
//! together (they may start crossed),
//! after a step in which a vertex of either moved, relative to the two
//! cloths' mean motion, by more than half their mean thickness (the pushes
//! keep slower motion from passing through: a vertex passing through a
//! triangle comes within the thickness of one of its corners), and while
//! its last check found edges through. Two cloths whose mean thickness is
//! thin for either (below `FACES_BELOW` of its shortest rest edge, where a
//! point of a triangle can be further than that from its corners) are
//! checked every step: their vertex pairs alone can let a slow vertex
//! through.

use core::ops::Range;

use bevy::math::Vec3A;
use bevy::prelude::*;

use super::{Cloth, ClothStats};
use crate::collision::SelfCollision;
use crate::collision::self_contact::{
    ClothLayers, IntersectionCheck, OtherVertex, inverse_mass, thin_for, untangle, untangle_between,
};

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
            let weight = inverse_mass(model, i);
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

/// This step's cloths in [`ClothLayers`], in entity order, and whether the
/// pass or the take-back moved each.
#[derive(Default)]
pub(crate) struct Added(Vec<Entity>, Vec<bool>);

/// The take-back's memory: each two cloths it has seen together in the
/// last step, in order, and whether its check found edges through.
#[derive(Default)]
pub(crate) struct TakeBack {
    last: Vec<((Entity, Entity), bool)>,
    now: Vec<((Entity, Entity), bool)>,
}

impl TakeBack {
    /// Whether the pair `key` was seen in the last step with nothing
    /// through (else it is checked).
    fn was_clear(&self, key: (Entity, Entity)) -> bool {
        self.last
            .binary_search_by_key(&key, |&(k, _)| k)
            .is_ok_and(|i| !self.last[i].1)
    }
}

/// Whether a vertex of either cloth moved from `before` to `now` by more
/// than `reach` relative to the two cloths' mean motion (a pair of cloths
/// falling together moves little relative to itself).
fn moved_apart(a: [&[Vec3A]; 2], b: [&[Vec3A]; 2], reach: f32) -> bool {
    fn motion<'a>([before, now]: [&'a [Vec3A]; 2]) -> impl Iterator<Item = Vec3A> + 'a {
        now.iter().zip(before).map(|(&x, &y)| x - y)
    }
    let count = a[1].len().min(a[0].len()) + b[1].len().min(b[0].len());
    if count == 0 {
        return false;
    }
    let mean = motion(a).chain(motion(b)).sum::<Vec3A>() / count as f32;
    let reach2 = reach * reach;
    motion(a)
        .chain(motion(b))
        .any(|d| (d - mean).length_squared() > reach2)
}

/// After the steps, in [`ClothSystems::Collide`](super::ClothSystems::Collide)
/// before the colliders' projection: the cloths gathered before the step
/// pushed apart where they came within their thickness of each other (for
/// a cloth whose method kept it off the others inside its step, `stiff`,
/// the rings around each pushed vertex pulled after it). A vertex moved
/// counts as one of its cloth's contacts, its velocity changes
/// by that move over the step, and the guard measures the cloth again.
/// Then the edges of each two cloths whose boxes meet that are already
/// through the other's triangles are taken back out (positions only, as
/// `stiff`'s own untangling does). Last, a followed cloth that either
/// moved has its own edges through its own triangles taken back out, as
/// its step ends with: the rings pulled after a pushed vertex are pulled
/// with no eye on the cloth's own folds (two `stiff` sheets landing on
/// each other over a ball, the upper turned 5°: 74 of the lower's own
/// edges through in the landing's steps; with this, 4).
pub(crate) fn collide_cloths(
    time: Res<Time>,
    gathered: Res<ClothLayerVertices>,
    mut layers: Local<ClothLayers>,
    mut added: Local<Added>,
    mut memory: Local<TakeBack>,
    mut check: Local<IntersectionCheck>,
    mut cloths: Query<(&mut Cloth, &SelfCollision, &mut ClothStats)>,
) {
    let dt = time.delta_secs();
    if dt <= 0.0 || gathered.cloths.len() < 2 {
        return;
    }
    layers.clear();
    added.0.clear();
    added.1.clear();
    for &(e, _) in &gathered.cloths {
        let Ok((cloth, sc, stats)) = cloths.get(e) else {
            continue;
        };
        let model = cloth.model();
        let n = model.vertex_count();
        if !stats.is_running()
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
        added.1.push(false);
    }
    if added.0.len() < 2 {
        return;
    }
    layers.resolve(dt);
    let inv_dt = 1.0 / dt;
    let Added(entities, moved_by) = &mut *added;
    for (index, &e) in entities.iter().enumerate() {
        let Ok((mut cloth, _, mut stats)) = cloths.get_mut(e) else {
            continue;
        };
        let cloth = &mut *cloth;
        if cloth.held_others {
            layers.follow(index, &cloth.model);
        }
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
            moved_by[index] = true;
        }
    }
    // Edges already through another cloth (a ball that pressed one sheet
    // through the one under it within a step) are taken back out, as
    // `stiff` takes back a cloth's own: the pushes would hold them there.
    // Only where the two cloths' boxes meet, and when edges can have gone
    // through (see the module's docs).
    let memory = &mut *memory;
    memory.now.clear();
    for (k, &a) in entities.iter().enumerate() {
        for (l, &b) in entities.iter().enumerate().skip(k + 1) {
            let Ok([(mut ca, sa, _), (mut cb, sb, _)]) = cloths.get_many_mut([a, b]) else {
                continue;
            };
            if !boxes_meet(ca.positions(), cb.positions()) {
                continue;
            }
            let (ca, cb) = (&mut *ca, &mut *cb);
            let thickness = 0.5 * (sa.thickness + sb.thickness);
            let thin = thin_for(&ca.model, thickness) || thin_for(&cb.model, thickness);
            let quiet = || {
                !moved_apart(
                    [&ca.last_good.positions, &ca.state.positions],
                    [&cb.last_good.positions, &cb.state.positions],
                    0.5 * thickness,
                )
            };
            if !thin && memory.was_clear((a, b)) && quiet() {
                memory.now.push(((a, b), false));
                continue;
            }
            let through = untangle_between(
                (&ca.model, &mut ca.state.positions),
                (&cb.model, &mut cb.state.positions),
                &mut check,
                thickness,
                [ca.held_others, cb.held_others],
            );
            memory.now.push(((a, b), through > 0));
            if through > 0 {
                ca.measured = None;
                cb.measured = None;
                moved_by[k] = true;
                moved_by[l] = true;
            }
        }
    }
    core::mem::swap(&mut memory.last, &mut memory.now);
    // The rings pulled after the moved vertices of a followed cloth may
    // have crossed its own folds (they are pulled with no eye on its
    // triangles): its own edges through are taken back out, as its step
    // ends with.
    for (&e, _) in entities.iter().zip(&*moved_by).filter(|(_, moved)| **moved) {
        let Ok((mut cloth, sc, _)) = cloths.get_mut(e) else {
            continue;
        };
        if cloth.held_others {
            let cloth = &mut *cloth;
            untangle(
                &cloth.model,
                &mut cloth.state.positions,
                &mut check,
                sc.thickness,
            );
        }
    }
}

/// Whether the boxes around two point sets overlap.
fn boxes_meet(a: &[Vec3A], b: &[Vec3A]) -> bool {
    let bounds = |x: &[Vec3A]| {
        x.iter().fold(
            (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
    };
    let ((lo_a, hi_a), (lo_b, hi_b)) = (bounds(a), bounds(b));
    lo_a.cmple(hi_b).all() && lo_b.cmple(hi_a).all()
}
