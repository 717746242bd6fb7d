//! Long-range attachments (Kim, Chentanez, Müller-Fischer 2012): each free
//! vertex may be no further from its nearest pin than the distance between
//! them at rest, times a slack.
//!
//! One sweep per substep passes a correction one spring further, so a long
//! cloth hanging from its pins sags by what the sweeps leave undone: a 64²
//! cape of 2 m stretched by about a tenth at 960 substeps per second, and
//! halving the substep quarters it at twice the cost. A tether ties every
//! vertex to its pin directly, at one distance test per vertex and substep.
//!
//! **The rest distance** is never shorter than any path the cloth can take
//! without stretching, so a tether holds back stretch only: it is the
//! shortest path along the springs (Dijkstra from all pins at once), or,
//! for a flat cloth, the straight line to the same pin where the path is at
//! most a tenth longer (a grid's zig-zag; a longer path goes round a hole
//! or a notch, where the straight line would leave the cloth). A curved
//! rest shape keeps the path: its straight chords are shorter than the
//! cloth between.
//!
//! **The slack** lets the cloth stretch as far as its springs would under
//! the tension it can meet: a path of springs of stiffness `k` under a
//! tension at most `T` stretches by at most `T/k` of its length. A hanging
//! cloth's springs carry at most its weight `M·|g|`, a swinging one up to
//! three times that (a pendulum released level feels three times its weight
//! at the bottom), so the limit is the rest distance times
//! `1 + 3·M·|g|/k`, `M` the free vertices' mass and `k` the stretch
//! stiffness: soft cloth is never held back, stiff cloth is held to its
//! length as the stiffness says.

use bevy::math::{Vec3, Vec3A};

use crate::model::ClothModel;

/// How near a straight line must be to the path along the springs for a
/// flat cloth's tether to take it (a grid's zig-zag is at most about 8 %
/// longer).
const STRAIGHT: f32 = 1.1;

/// How much of its weight a swinging cloth's springs can carry (see the
/// module docs).
const SWING: f32 = 3.0;

/// Per free vertex, its nearest pin and the distance to it at rest; taken
/// once per topology and set of pins.
#[derive(Clone, Debug, Default)]
pub(crate) struct Tethers {
    /// Per vertex: its pin's place in [`ClothModel::pins`] and the rest
    /// distance (infinite for a pin or a vertex no pin reaches, with
    /// place 0).
    pub(crate) ties: Vec<(u32, f32)>,
    source: Option<(u64, Vec<u32>)>,
}

impl Tethers {
    /// Finds the tethers of `model`, unless these are already its.
    pub(crate) fn update(&mut self, model: &ClothModel) {
        let id = model.topology().adjacency().id();
        if let Some((source, pins)) = &self.source
            && *source == id
            && pins.as_slice() == model.pins()
        {
            return;
        }
        self.source = Some((id, model.pins().to_vec()));
        self.ties = nearest_pins(model);
    }

    /// Whether any vertex is tethered.
    pub(crate) fn any(&self) -> bool {
        self.ties.iter().any(|&(_, rest)| rest.is_finite())
    }
}

/// The limit's factor over the rest distance, `1 + 3·M·|g|/k` (see the
/// module docs).
pub(crate) fn slack(model: &ClothModel, gravity: Vec3, stretch_stiffness: f32) -> f32 {
    let free_mass: f32 = model
        .masses()
        .iter()
        .zip(model.pinned())
        .filter(|&(_, &pinned)| !pinned)
        .map(|(&m, _)| m)
        .sum();
    1.0 + SWING * free_mass * gravity.length() / stretch_stiffness
}

/// Moves `x` back onto the sphere of radius `limit` around `anchor` if it is
/// outside.
#[inline(always)]
pub(crate) fn hold(x: &mut Vec3A, anchor: Vec3A, limit: f32) {
    let d = *x - anchor;
    let d2 = d.length_squared();
    if d2 > limit * limit {
        *x = anchor + d * (limit / d2.sqrt());
    }
}

/// Per vertex, the pin nearest along the springs (its place among the
/// pins) and the tether's rest distance to it (see the module docs).
fn nearest_pins(model: &ClothModel) -> Vec<(u32, f32)> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;

    let n = model.vertex_count();
    let topology = model.topology();
    let rest = topology.rest_positions();
    let springs = topology.springs();
    let adjacency = topology.adjacency();
    let mut best = vec![(u32::MAX, f32::INFINITY); n];
    // Distances are finite and non-negative, so their bits order as they do.
    let mut heap = BinaryHeap::new();
    for (place, &p) in model.pins().iter().enumerate() {
        best[p as usize] = (place as u32, 0.0);
        heap.push(Reverse((0.0f32.to_bits(), p)));
    }
    while let Some(Reverse((bits, i))) = heap.pop() {
        let d = f32::from_bits(bits);
        if d > best[i as usize].1 {
            continue;
        }
        let pin = best[i as usize].0;
        for incidence in adjacency.of(i as usize) {
            let j = incidence.other;
            let through = d + springs[incidence.spring as usize].rest_length;
            if through < best[j as usize].1 {
                best[j as usize] = (pin, through);
                heap.push(Reverse((through.to_bits(), j)));
            }
        }
    }
    let flat = is_flat(rest, model.size());
    let pinned = model.pinned();
    let pins = model.pins();
    best.iter()
        .enumerate()
        .map(|(i, &(place, path))| {
            if pinned[i] || place == u32::MAX {
                return (0, f32::INFINITY);
            }
            let straight = rest[i].distance(rest[pins[place as usize] as usize]);
            if flat && path <= STRAIGHT * straight {
                (place, straight)
            } else {
                (place, path)
            }
        })
        .collect()
}

/// Whether every rest position lies within a thousandth of the cloth's size
/// of one plane (through three of its points spanning the most area).
fn is_flat(rest: &[Vec3], size: f32) -> bool {
    let Some(&o) = rest.first() else {
        return true;
    };
    let Some(&far) = rest
        .iter()
        .max_by(|a, b| a.distance_squared(o).total_cmp(&b.distance_squared(o)))
    else {
        return true;
    };
    let axis = far - o;
    let Some(normal) = rest
        .iter()
        .map(|&p| axis.cross(p - o))
        .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))
        .and_then(|c| c.try_normalize())
    else {
        // Every point on one line.
        return true;
    };
    let tolerance = 1e-3 * size;
    rest.iter().all(|&p| normal.dot(p - o).abs() <= tolerance)
}
