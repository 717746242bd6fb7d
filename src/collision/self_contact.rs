//! A cloth against itself (issue N, first part): every pair of vertices is
//! kept at least a *thickness* apart, as in Müller's "ten minute physics"
//! self-collision, with friction.
//!
//! # Why vertices, and how thick
//!
//! The thickness is validated to be below the cloth's shortest rest edge
//! (else every vertex would touch its neighbours at rest). Above about
//! 0.71 of the edges (the circumradius of the grid's right triangles), a
//! vertex kept that far from every other vertex cannot reach any point of
//! a triangle of the cloth's own resolution, and two edges cannot cross
//! without their ends coming that close: vertex–vertex separation then
//! keeps the surface from passing through itself, while the narrow phase
//! stays one distance per pair. [`SelfCollision::for_model`] picks 0.9 of
//! the shortest edge. A thinner setting keeps layers closer; vertex pairs
//! alone no longer hold it, and vertex–triangle pairs take over (below).
//!
//! # Thin cloth
//!
//! Below [`FACES_BELOW`] (0.71) of the shortest edge, the search also
//! finds vertex–triangle pairs (`faces.rs`): each vertex against every
//! triangle of its cloth that does not hold it and is not beside it
//! (across one of its edges, or joined to two of its corners by stretch
//! or shear springs), their swept boxes in a grid of cells of twice the
//! shortest edge, kept where the vertex can come within the thickness of
//! the triangle in the step. Each pair remembers the vertex's side of the
//! triangle when the step began; while the vertex is over the triangle
//! (its projection inside, within a small tolerance), it is pushed back to
//! that side, the thickness from the plane, the corners taking their share
//! by barycentric weight and inverse mass, with friction, in the same
//! passes as the vertex pairs (every substep of `stiff`, every iteration
//! of PBD, after the step of the others). A vertex that went through a
//! triangle within the step is so taken back, not held where it is.
//! `pd`, `newton` and `exact` also take them into their solve, as a
//! half-space on the vertex's height over the triangle's point under it at
//! the step's start (after their step alone, the pushes fought their stiff
//! springs: a 64² sheet folded at 0.3 of its edges stretched 127 % under
//! `pd`). The default setting (0.9) finds none and pays nothing.
//!
//! Two edges can still pass through each other with no vertex over a
//! triangle (where the cloth crumples at the scale of its triangles, or
//! two strips cross like an X). A thin setting so also finds edge–edge
//! pairs (`edges.rs`): each two triangle edges that share no vertex, in
//! the same grid, kept where they can come within half the thickness in
//! the step; each remembers the direction from the first edge's closest
//! point to the second's when the step began, and while their closest
//! points are nearer than half the thickness along it (or crossed to the
//! other side) and not slid apart across it, they are pushed back apart,
//! each end taking its share by its weight in the closest point and its
//! inverse mass, with friction, in the same passes as the vertex–triangle
//! pairs (after the step of `pd` and `pd-anderson`, not in their
//! objective: as its terms without their blocks in the global matrix,
//! `pd-anderson` diverged; `newton` and `exact` also take them into their
//! objective as half-space terms, their Hessian blocks whole, and push them
//! after the step too). Half the
//! thickness, not all of it: the
//! vertex–triangle pairs hold resting layers a thickness apart, and edges
//! crossing each other there would push in every pass. Two edges a row
//! and a column apart (two or three of their ends joined by springs) are
//! kept a tenth of that apart: only from passing through each other (held
//! further apart, a crumpled corner stretched against its springs; the
//! measurements are in `docs/measurements.md`).
//!
//! # The loop
//!
//! - [`SelfContacts::find`] once per step: the pairs that can come within
//!   the thickness during the step, from each vertex's swept box (its
//!   position and where its velocity takes it, relative to the vertices'
//!   mean velocity: a pair's closest approach is the same in that frame,
//!   and a cloth falling as a whole has small boxes) in a grid of cells of
//!   2.5 times the thickness (a hash table filled by a counting sort; each pair
//!   tested once, in the lowest cell the two boxes share, and first by
//!   the boxes themselves). A pair's
//!   minimum distance is the thickness, or its rest distance where that is
//!   shorter (a mesh folded at rest); two vertices joined by a stretch or
//!   shear spring are not a pair (the spring keeps them apart). After the
//!   step the list is kept while the cloth moves slowly ([`SKIN`]).
//! - [`SelfContacts::resolve`] in every substep of the `stiff` method (a
//!   vertex moves less than the thickness in one), after every
//!   strain-limiting iteration of PBD (with the colliders projected first:
//!   only after its step, the pairs fought its strain limiting and a 32²
//!   sheet folded in four tangled), and after the step of every other
//!   method (`pd`'s and Newton's also take them into their solve as
//!   penalty terms, `PairTerms`): Gauss–Seidel over the pairs in a fixed order,
//!   each pushed apart by inverse mass along the line between them, then
//!   position-based Coulomb friction on their relative motion since the
//!   substep began. Pinned vertices do not move. The order is the sorted
//!   pair list: the same result on any thread count.
//!
//! A pair that is already closer than its least distance when the step
//! begins (a cloth that starts interpenetrated, or layers pressed
//! together) is parted gradually, by at most [`UNTANGLE`] of the thickness
//! per step, not launched apart in one substep. In `stiff`'s substeps each
//! substep parts a vertex–triangle or edge pair by at most its share of
//! that (beyond what the pair came closer in the substep): such a pair
//! pushes only while its vertex is over its triangle (its edges beside each
//! other), and one that began to push late in the step took the whole
//! allowance in one substep (a 16² sheet at 0.3 of its edges, 80 m/s in a
//! crumpled corner, stopped by the guard).
//!
//! # Edges already through
//!
//! The pairs keep a surface from passing through itself, but they cannot
//! take back an edge that went through one of the cloth's triangles anyway
//! (a step that went wrong, two edges crossing in a thin setting): their
//! pushes hold its end on the side it is on, for the rest of the run.
//! After each `stiff` step, `untangle` finds such edges with the exact
//! check below and moves the end nearer the triangle's plane (the one that
//! went through) back to the other end's side, [`UNTANGLE_MARGIN`] of the
//! thickness past the plane, the triangle's corners taking their share by
//! inverse mass, as a point–triangle contact would; the pairs do the rest
//! in the next step. The cloth around the moved vertices is then pulled
//! after them (four rings of neighbours, each spring brought back to 2 %
//! over its rest length or its length before the move): left alone, the
//! springs of the moved end took the whole move, a third of an edge or
//! more, in one step. A cloth with `stiff`'s chains then settles after
//! the moves, positions only (the chains pulled, the pairs held, the
//! solids projected): its chains would take what the rings left back all
//! at once in the next step, as velocity. It costs the exact check, a
//! small share of a `stiff` step with self-collision but several steps of
//! the other methods, so they leave it (the CHANGELOG has the
//! measurements). Edges through
//! another cloth are taken back the same way after every method's step
//! (`untangle_between`, in the pass below, where two cloths' boxes meet):
//! a ball that pressed one sheet through the one under it within a step
//! left their edges crossed for the rest of the run.
//!
//! # Cloth against cloth
//!
//! Each cloth's step also sees the vertices of the other cloths with a
//! [`SelfCollision`] ([`OtherVertex`], [`SelfCollisionInput::others`]),
//! where they were at the step's start, and takes its share of each push;
//! after all the steps, [`ClothLayers`] pushes apart in one pass what the
//! steps could not see (every cloth moved while the others stood still in
//! its view), and then takes back the edges of one through the other's
//! triangles (above) where they can have gone through: the first step two
//! cloths meet, after fast relative motion, and while edges are found
//! (the plugin's `collide_cloths`). A `stiff` cloth that either moved ends
//! the pass with the untangling of its own edges, as its step ends: the
//! vertices pulled after a pushed one ([`ClothLayers::follow`]) can cross
//! its own folds.
//!
//! [`count_intersections`] is the exact check: how many mesh edges pass
//! through a triangle that shares no vertex with them;
//! [`count_crossings`] the same between two cloths.

use bevy::math::Vec3A;
use bevy::prelude::*;

use crate::model::{ClothModel, ClothState};
use grid::{CellBox, Entry, Linked};

mod check;
mod edges;
mod faces;
mod follow;
mod grid;
mod layers;
mod objective;
mod substeps;

pub use check::{
    IntersectionCheck, UNTANGLE_MARGIN, count_crossings, count_intersections, ray_meets,
};
pub(crate) use check::{untangle, untangle_between};
pub use faces::FACES_BELOW;
#[cfg(test)]
pub(crate) use follow::FOLLOW_RINGS;
pub(crate) use follow::Follow;
pub use layers::ClothLayers;
pub(crate) use objective::PairTerms;
pub use substeps::SUBSTEP_SKIN;

/// A cloth that collides with itself: add it to a cloth entity (any
/// method). A cloth without it pays nothing.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Debug, PartialEq)]
pub struct SelfCollision {
    /// How far apart any two vertices are kept (m), and a vertex from a
    /// triangle under it: below the cloth's shortest rest edge. Below
    /// [`FACES_BELOW`] of it, vertex–triangle and edge–edge pairs are
    /// searched too (see the [module docs](self)).
    pub thickness: f32,
    /// Coulomb friction between touching parts of the cloth (0: none).
    pub friction: f32,
}

impl SelfCollision {
    /// 0.9 of `model`'s shortest rest edge, with friction 0.3.
    pub fn for_model(model: &ClothModel) -> Self {
        Self {
            thickness: 0.9 * shortest_edge(model),
            friction: 0.3,
        }
    }

    /// Checks the setting for `model` (see [`SelfCollisionError`]).
    pub fn validate(&self, model: &ClothModel) -> Result<(), SelfCollisionError> {
        if !(self.thickness.is_finite() && self.thickness > 0.0) {
            return Err(SelfCollisionError::Thickness(self.thickness));
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err(SelfCollisionError::Friction(self.friction));
        }
        let shortest = shortest_edge(model);
        if shortest.is_finite() && self.thickness >= shortest {
            return Err(SelfCollisionError::ThickerThanEdges {
                thickness: self.thickness,
                shortest,
            });
        }
        Ok(())
    }
}

/// Vertex `i`'s inverse mass in `model` (0 for a pinned vertex): how much
/// of a push it takes.
pub(crate) fn inverse_mass(model: &ClothModel, i: usize) -> f32 {
    if model.pinned()[i] {
        0.0
    } else {
        1.0 / model.masses()[i]
    }
}

/// The shortest triangle edge of `model` at rest (`∞` without triangles;
/// the topology keeps it).
fn shortest_edge(model: &ClothModel) -> f32 {
    model.topology().shortest_edge()
}

/// Whether vertex pairs at `thickness` can miss a vertex passing through
/// one of `model`'s triangles: the thickness is below [`FACES_BELOW`] of its
/// shortest rest edge (a point of a triangle can be that far from its
/// nearest corner), where a cloth alone needs vertex–triangle pairs.
pub(crate) fn thin_for(model: &ClothModel, thickness: f32) -> bool {
    let shortest = shortest_edge(model);
    shortest.is_finite() && thickness < FACES_BELOW * shortest
}

/// Why a [`SelfCollision`] is refused.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error, Reflect)]
pub enum SelfCollisionError {
    /// The thickness is zero, negative or not finite.
    #[error("self-collision thickness {0} must be positive and finite")]
    Thickness(f32),
    /// The thickness is at least the cloth's shortest rest edge: every
    /// vertex would touch its neighbours at rest.
    #[error(
        "self-collision thickness {thickness} must be below the cloth's shortest rest edge \
         ({shortest})"
    )]
    ThickerThanEdges {
        /// The thickness given.
        thickness: f32,
        /// The shortest triangle edge at rest.
        shortest: f32,
    },
    /// The friction is negative or not finite.
    #[error("self-collision friction {0} must be non-negative and finite")]
    Friction(f32),
}

/// One pair of vertices kept apart: `a < b`, the least distance between
/// them and their friction.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Pair {
    a: u32,
    b: u32,
    min: f32,
    friction: f32,
    /// Their distance at the step's start if that was below `min` (else
    /// infinite): they are parted gradually (see [`UNTANGLE`]).
    overlap: f32,
}

/// How much of its least distance a pair found closer than that at the
/// step's start may be parted by over one step (gradually through its
/// substeps): a cloth that starts interpenetrated, or is pressed together,
/// untangles over a few steps (at a quarter of the thickness per step)
/// instead of being launched apart in one substep.
pub const UNTANGLE: f32 = 0.25;

/// The most grid cells one vertex's swept box may cover: a vertex moving
/// further in one step (a diverging cloth, which the guard will stop) is
/// left out of the step's pairs rather than filling memory.
const MAX_CELLS: i64 = 512;

/// Self-collision's scratch and the step's pairs ([`find`](Self::find),
/// [`resolve`](Self::resolve)), reused from step to step.
#[derive(Clone, Debug, Default)]
pub struct SelfContacts {
    /// Each vertex's swept box in grid cells (`lo`, `hi`, inclusive;
    /// empty, `lo > hi`, for a vertex left out).
    boxes: Vec<CellBox>,
    /// Each vertex's margin (m) and swept box, grown by it, in metres.
    margins: Vec<f32>,
    extents: Vec<[Vec3A; 2]>,
    /// The grid as a counting-sorted hash table: bucket `b`'s entries are
    /// `entries[starts[b]..starts[b + 1]]`, in increasing vertex order.
    starts: Vec<u32>,
    entries: Vec<Entry>,
    /// The step's pairs, sorted by `(a, b)`.
    pairs: Vec<Pair>,
    /// Vertices left out of the step's pairs (their swept box was too large).
    skipped: usize,
    /// The cloth's own vertices among the step's: the others' come after.
    own: usize,
    /// The other cloths' vertices of the step.
    others: Vec<OtherVertex>,
    /// Scratch: the cloth's and the other cloths' positions and velocities.
    all_x: Vec<Vec3A>,
    all_v: Vec<Vec3A>,
    /// Scratch of [`resolve_after_step`](Self::resolve_after_step).
    after_step: (Vec<Vec3A>, Vec<Vec3A>),
    /// The pair list kept from step to step, if any.
    kept: Kept,
    /// The step's pairs that can touch within the next substeps.
    active: substeps::Active,
    /// Which vertices a stretch or shear spring joins.
    linked: Linked,
    /// The step's vertex–triangle and edge–edge pairs, for a thin setting.
    faces: faces::Faces,
    edges: edges::Edges,
}

/// How far beyond the thickness, as a share of it, the pairs of a cloth
/// alone (no other cloth near) are looked for when it moves slowly, for
/// self-collision after the step ([`SelfContacts::resolve_after_step`]), so
/// that the same list serves the next steps: until some vertex has moved
/// that far from where it was when the list was made, apart from the
/// whole cloth's common motion, counting the step's own motion (a Verlet
/// list). A resting or gliding cloth then pays for the grid only now and
/// then.
pub const SKIN: f32 = 0.125;

/// What a kept pair list was made for and from.
#[derive(Clone, Debug, Default)]
struct Kept {
    /// The cloth's vertices when the list was made (empty: none kept).
    built: Vec<Vec3A>,
    /// The adjacency it was made for.
    topology: u64,
    /// Thickness, friction, slack and step, as bits.
    key: [u32; 4],
    /// The pins it was made with.
    pins: Vec<u32>,
}

impl Kept {
    /// Whether the list still holds every pair a new search of `x` moving
    /// at `v` would find (see [`SKIN`]).
    fn holds(&self, x: &[Vec3A], v: &[Vec3A], dt: f32, skin: f32) -> bool {
        let n = self.built.len();
        if n == 0 || x.len() < n || v.len() < n {
            return false;
        }
        let inv = 1.0 / n as f32;
        let drift = x[..n]
            .iter()
            .zip(&self.built)
            .fold(Vec3A::ZERO, |c, (&x, &b)| c + (x - b))
            * inv;
        let reach = Reach::of(&v[..n], dt, skin);
        x[..n]
            .iter()
            .zip(&self.built)
            .zip(&v[..n])
            .all(|((&x, &b), &v)| (x - b - drift).length_squared() + reach.motion(v) <= reach.limit)
    }

    /// Whether a list made now, at `x`, would hold for the step (the test
    /// of [`holds`](Self::holds) with every vertex where the list was made).
    fn would_hold(v: &[Vec3A], dt: f32, skin: f32) -> bool {
        if v.is_empty() {
            return false;
        }
        let reach = Reach::of(v, dt, skin);
        v.iter().all(|&v| reach.motion(v) <= reach.limit)
    }
}

/// `|x − b − drift| + (|v|/4 + |v − mean|)·dt ≤ skin`, tested by the
/// stronger `2·(p² + 2·(|v|²/16 + |v − mean|²)·dt²) ≤ skin²` (no square
/// roots: this runs every step): the velocities' mean and the constants.
struct Reach {
    mean: Vec3A,
    dt2: f32,
    limit: f32,
}

impl Reach {
    fn of(v: &[Vec3A], dt: f32, skin: f32) -> Self {
        let inv = 1.0 / v.len() as f32;
        Self {
            mean: v.iter().fold(Vec3A::ZERO, |u, &v| u + v) * inv,
            dt2: 2.0 * dt * dt,
            limit: 0.5 * skin * skin,
        }
    }

    /// A vertex's own motion's share of the test.
    #[inline]
    fn motion(&self, v: Vec3A) -> f32 {
        (0.0625 * v.length_squared() + (v - self.mean).length_squared()) * self.dt2
    }
}

/// A vertex of another cloth, as this cloth's step sees it: where it was
/// at the step's start (it stays there through the step), its inverse mass
/// (0: pinned), half its cloth's thickness and its cloth's friction.
/// Cloths with a [`SelfCollision`] each see the others' vertices so and
/// take their share of each push (by inverse mass), so that two cloths
/// keep each other apart. (Moving them along their velocity through the
/// step was tried: it ignores that the other cloth is stopped too, and a
/// sheet landing on another squeezed the lower one against the ball under
/// it, stretching it 43 %.)
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OtherVertex {
    /// Position at the step's start.
    pub position: Vec3A,
    /// Inverse mass (0 for a pinned vertex).
    pub weight: f32,
    /// Half its cloth's thickness.
    pub half_thickness: f32,
    /// Its cloth's friction.
    pub friction: f32,
}

/// A cloth's self-collision as its step reads it: its setting, and the
/// vertices of the other cloths it collides with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SelfCollisionInput<'a> {
    /// The cloth's own setting (validated).
    pub setting: SelfCollision,
    /// Vertices of the other cloths with a [`SelfCollision`] (in two
    /// lists: those gathered before this cloth's and after).
    pub others: [&'a [OtherVertex]; 2],
}

impl SelfCollisionInput<'_> {
    /// The setting alone, with no other cloths.
    pub fn alone(setting: SelfCollision) -> SelfCollisionInput<'static> {
        SelfCollisionInput {
            setting,
            others: [&[], &[]],
        }
    }
}

impl SelfContacts {
    /// The pairs of the step: vertices of `model` at `x` moving at `v` for
    /// `dt` seconds that can come within `sc`'s thickness of each other or
    /// within the mean thickness of a vertex of another cloth, with `slack`
    /// (m) added to every swept box for what the step's forces add to the
    /// straight motion (`stiff` passes the fall `|g|·dt²`; a quarter of
    /// each vertex's own motion is added on top).
    pub fn find(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        v: &[Vec3A],
        dt: f32,
        sc: SelfCollisionInput<'_>,
        slack: f32,
    ) {
        self.find_or_keep(model, x, v, dt, sc, slack, false);
    }

    /// [`find`](Self::find), or, with `reuse`, the last step's pairs while
    /// they still serve, and a list made to serve the next steps when the
    /// cloth moves slowly (see [`SKIN`]). Worth it where the pairs are
    /// resolved a few times a step (after the step); `stiff` resolves them
    /// in every substep, where the skin's extra pairs cost more than the
    /// search. PBD, which resolves them after each of its iterations, keeps
    /// the list too: there the search, not the skin's extra pairs, was the
    /// larger cost.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn find_or_keep(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        v: &[Vec3A],
        dt: f32,
        sc: SelfCollisionInput<'_>,
        slack: f32,
        reuse: bool,
    ) {
        let (thickness, friction) = (sc.setting.thickness, sc.setting.friction);
        self.active.reset(thickness);
        // A thin setting's vertex–triangle and edge–edge pairs: found anew
        // every step.
        self.linked.update(model);
        let search = faces::FaceSearch {
            model,
            linked: &self.linked,
            dt,
            thickness,
            friction,
            slack,
        };
        if self.faces.find(x, v, search) {
            let faces = &self.faces;
            let grid = (faces.frame, faces.inv);
            self.edges.find(x, v, &faces.vertex_boxes, grid, &search);
        } else {
            self.edges.pairs.clear();
        }
        let n = model.vertex_count().min(x.len()).min(v.len());
        let pinned = model.pinned();
        let topology = model.topology();
        // The kept list, if it still serves (a cloth alone only: the other
        // cloths' vertices come and go).
        let alone = reuse && sc.others.iter().all(|o| o.is_empty());
        let skin = SKIN * thickness;
        let key = [thickness, friction, slack, dt].map(f32::to_bits);
        let made_for = |k: &Kept| {
            k.topology == topology.adjacency().id()
                && k.key == key
                && k.pins == model.pins()
                && k.built.len() == n
        };
        if alone && made_for(&self.kept) && self.kept.holds(x, v, dt, skin) {
            for p in &mut self.pairs {
                let d2 = x[p.a as usize].distance_squared(x[p.b as usize]);
                p.overlap = if d2 < p.min * p.min {
                    d2.sqrt()
                } else {
                    f32::INFINITY
                };
            }
            self.own = n;
            self.others.clear();
            return;
        }
        // Keep the new list if the cloth moves slowly enough (measured as
        // the kept list is checked, from where it is).
        let keep = alone && n > 0 && Kept::would_hold(&v[..n], dt, skin);
        self.kept.built.clear();
        if keep {
            self.kept.built.extend_from_slice(&x[..n]);
        }
        let rest = topology.rest_positions();
        // Two vertices joined by a stretch or shear spring: the spring
        // keeps them apart (the thickness is below its rest length), so
        // they are not a pair. Vertices joined by a bending spring can fold
        // onto each other and are.
        let mut linked = core::mem::take(&mut self.linked);
        linked.update(model);
        let mut others = core::mem::take(&mut self.others);
        others.clear();
        others.extend(sc.others.into_iter().flatten());
        let half = 0.5 * thickness;
        let (cell, slack) = if keep {
            (thickness + 2.0 * (slack + skin), slack + skin)
        } else {
            (thickness, slack)
        };
        let half_of = |i: usize| {
            if i < n {
                half
            } else {
                others[i - n].half_thickness
            }
        };
        let pair = |a: usize, b: usize| match (a < n, b < n) {
            (true, true) => {
                let min = thickness.min(rest[a].distance(rest[b]));
                (!(pinned[a] && pinned[b]) && min > 0.0 && !linked.joins(a, b))
                    .then_some((min, friction))
            }
            (true, false) => {
                let o = &others[b - n];
                (!pinned[a]).then_some((half + o.half_thickness, 0.5 * (friction + o.friction)))
            }
            _ => None,
        };
        let (mut xs, mut vs) = (
            core::mem::take(&mut self.all_x),
            core::mem::take(&mut self.all_v),
        );
        if others.is_empty() && !keep {
            // A cloth alone, moving: its own positions and velocities, not
            // copies.
            self.find_where(&x[..n], &v[..n], dt, [cell, slack], half_of, pair);
        } else {
            xs.clear();
            vs.clear();
            xs.extend_from_slice(&x[..n]);
            if keep {
                // Where the vertices are, grown by the skin: the list then
                // covers their motion in this step and the next ones'.
                vs.resize(n, Vec3A::ZERO);
            } else {
                vs.extend_from_slice(&v[..n]);
            }
            xs.extend(others.iter().map(|o| o.position));
            vs.extend(others.iter().map(|_| Vec3A::ZERO));
            self.find_where(&xs, &vs, dt, [cell, slack], half_of, pair);
        }
        self.own = n;
        self.others = others;
        self.linked = linked;
        self.all_x = xs;
        self.all_v = vs;
        if keep {
            self.kept.topology = topology.adjacency().id();
            self.kept.key = key;
            self.kept.pins.clear();
            self.kept.pins.extend_from_slice(model.pins());
        }
    }

    /// The step's pairs as `(a, b, least distance)`, in their order.
    #[cfg(test)]
    pub(crate) fn pair_list(&self) -> Vec<(u32, u32, f32)> {
        self.pairs.iter().map(|p| (p.a, p.b, p.min)).collect()
    }

    /// Pairs found for the step.
    pub fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// Vertices left out of the step's pairs because their swept box was
    /// too large to grid (a cloth moving its own size in one step) or not
    /// finite.
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    /// One Gauss–Seidel pass over the step's pairs of `model`: each pair
    /// closer than its least distance is pushed apart by inverse mass, with
    /// Coulomb friction on the pair's relative motion since `start` (the
    /// substep's start). The other cloths' vertices do not move: each cloth
    /// takes its own share of the push. `progress` is how far through the
    /// step the substep ends (1 after the step): a pair that started closer
    /// than its least distance is parted only that far along
    /// ([`UNTANGLE`]). A thin setting's vertex–triangle and edge–edge
    /// pairs follow, in the same pass (see the [module docs](self), "Thin
    /// cloth"). Returns the pairs that were touching, of every kind.
    pub fn resolve(
        &self,
        model: &ClothModel,
        x: &mut [Vec3A],
        start: impl Fn(usize) -> Vec3A,
        progress: f32,
    ) -> u32 {
        let weight = |i| self.weight(model, i);
        self.resolve_weighted(self.pairs.iter(), x, &start, progress, weight)
            .touching
            + self.faces.resolve(x, &start, progress, &weight).touching
            + self.edges.resolve(x, &start, progress, &weight).touching
    }

    /// Vertex–triangle pairs found for the step: none unless the thickness
    /// is below [`FACES_BELOW`] of the cloth's shortest rest edge.
    pub fn face_pair_count(&self) -> usize {
        self.faces.pairs.len()
    }

    /// Edge–edge pairs found for the step: none unless the thickness is
    /// below [`FACES_BELOW`] of the cloth's shortest rest edge.
    pub fn edge_pair_count(&self) -> usize {
        self.edges.pairs.len()
    }

    /// A vertex's inverse mass: the cloth's own, or another cloth's.
    fn weight(&self, model: &ClothModel, i: usize) -> f32 {
        if i >= self.own {
            self.others[i - self.own].weight
        } else {
            inverse_mass(model, i)
        }
    }

    /// [`resolve`](Self::resolve) over `pairs` (some of the step's), with
    /// each vertex's inverse mass from `weight`.
    fn resolve_weighted<'p>(
        &self,
        pairs: impl Iterator<Item = &'p Pair>,
        x: &mut [Vec3A],
        start: impl Fn(usize) -> Vec3A,
        progress: f32,
        weight: impl Fn(usize) -> f32,
    ) -> Pass {
        Pass::over(pairs, |p| {
            self.resolve_pair(p, x, &start, progress, &weight)
        })
    }

    /// One pair of [`resolve_weighted`](Self::resolve_weighted): if it was
    /// touching (and was pushed apart), how deep, as a share of its least
    /// distance.
    #[inline]
    fn resolve_pair(
        &self,
        p: &Pair,
        x: &mut [Vec3A],
        start: &impl Fn(usize) -> Vec3A,
        progress: f32,
        weight: &impl Fn(usize) -> f32,
    ) -> Option<f32> {
        let own = self.own;
        let (a, b) = (p.a as usize, p.b as usize);
        let &xa = x.get(a)?;
        let xb = if b < own {
            *x.get(b)?
        } else {
            self.others[b - own].position
        };
        let min = p.min.min(p.overlap + UNTANGLE * p.min * progress);
        let d = xb - xa;
        let d2 = d.length_squared();
        if d2 >= min * min {
            return None;
        }
        // The other cloths' vertices stand still through the step.
        let start_b = if b < own { start(b) } else { xb };
        let (wa, wb) = (weight(a), weight(b));
        let w = wa + wb;
        if w <= 0.0 {
            return None;
        }
        let dist = d2.sqrt();
        // Two vertices on the same point: apart along where they came from.
        let normal = if dist > 1e-6 * min {
            d / dist
        } else {
            (start_b - start(a)).try_normalize()?
        };
        let depth = min - dist;
        let (sa, sb) = (wa / w, wb / w);
        let (mut xa, mut xb) = (xa - normal * (depth * sa), xb + normal * (depth * sb));
        if p.friction > 0.0 {
            let moved = (xb - start_b) - (xa - start(a));
            let tangential = moved - moved.dot(normal) * normal;
            let length = tangential.length();
            if length > 0.0 {
                let cut = tangential * ((p.friction * depth).min(length) / length);
                xa += cut * sa;
                xb -= cut * sb;
            }
        }
        x[a] = xa;
        if b < own {
            x[b] = xb;
        }
        Some(depth / p.min)
    }
}

/// The most Gauss–Seidel passes self-collision makes after the step of a
/// method that does not handle it inside: contacts found in one pass
/// disturb their neighbours, and a few more settle a fold.
pub const AFTER_STEP_PASSES: u32 = 4;

/// The passes after the step end early once one pushed no pair apart by
/// more than this share of its least distance: what the next would do is
/// smaller still. A resting fold's second pass pushes its pairs by about
/// a ten-thousandth of the thickness (a 64² sheet folded in four, 1.5 cm
/// thick: 2 µm), where its last two passes cost a third of self-collision.
pub const SETTLED: f32 = 1e-3;

/// What one pass over the pairs did.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Pass {
    /// Pairs found touching (and pushed apart).
    pub(crate) touching: u32,
    /// The deepest push, as a share of its pair's least distance.
    pub(crate) deepest: f32,
}

impl Pass {
    /// A pass over `pairs`, each resolved by `push` (how deep it was, as a
    /// share of its least distance, if it was pushed).
    #[inline]
    pub(crate) fn over<P>(
        pairs: impl Iterator<Item = P>,
        mut push: impl FnMut(P) -> Option<f32>,
    ) -> Self {
        let mut pass = Self::default();
        for p in pairs {
            if let Some(depth) = push(p) {
                pass.touching += 1;
                pass.deepest = pass.deepest.max(depth);
            }
        }
        pass
    }
}

/// Up to [`AFTER_STEP_PASSES`] passes, until one finds nothing touching or
/// pushes nothing deeper than [`SETTLED`]; the first pass's count of
/// touching pairs (what the step left too close).
pub(crate) fn settle(mut pass: impl FnMut() -> Pass) -> u32 {
    let mut first = None;
    for _ in 0..AFTER_STEP_PASSES {
        let now = pass();
        first.get_or_insert(now.touching);
        if now.touching == 0 || now.deepest < SETTLED {
            break;
        }
    }
    first.unwrap_or(0)
}

impl SelfContacts {
    /// Self-collision after a step from `before` to `state` (and against the
    /// other cloths' vertices where they were before it):
    /// the pairs found from the step's start and its motion, pushed apart in
    /// [`AFTER_STEP_PASSES`] passes, and the velocities changed by what that
    /// moved. Returns the pairs the step left too close (the first pass's).
    pub fn resolve_after_step(
        &mut self,
        model: &ClothModel,
        state: &mut ClothState,
        before: &ClothState,
        params: &crate::solver::StepParams,
        sc: SelfCollisionInput<'_>,
    ) -> u32 {
        let n = model.vertex_count();
        if before.positions.len() < n || state.positions.len() < n {
            return 0;
        }
        let dt = params.dt as f32;
        let inv_dt = 1.0 / dt;
        // The step's motion as a velocity, for the swept boxes.
        // Scratch kept from step to step: the step's motion as a velocity
        // (for the swept boxes) and where the step left the positions.
        let (mut moved, mut solved) = core::mem::take(&mut self.after_step);
        moved.clear();
        moved.extend(
            state.positions[..n]
                .iter()
                .zip(&before.positions)
                .map(|(&x, &b)| (x - b) * inv_dt),
        );
        solved.clear();
        solved.extend_from_slice(&state.positions[..n]);
        self.find_or_keep(model, &before.positions[..n], &moved, dt, sc, 0.0, true);
        // The pairs the step left too close (the first pass's count; the
        // later passes settle what it disturbed).
        let start = |i: usize| before.positions[i];
        let weight = |i| self.weight(model, i);
        let touching = settle(|| {
            let x = &mut state.positions[..n];
            let vertices = self.resolve_weighted(self.pairs.iter(), x, start, 1.0, weight);
            let faces = self.faces.resolve(x, &start, 1.0, &weight);
            let edges = self.edges.resolve(x, &start, 1.0, &weight);
            Pass {
                touching: vertices.touching + faces.touching + edges.touching,
                deepest: vertices.deepest.max(faces.deepest).max(edges.deepest),
            }
        });
        for ((v, &x), &s) in state
            .velocities
            .iter_mut()
            .zip(&state.positions)
            .zip(&solved)
        {
            *v += (x - s) * inv_dt;
        }
        self.after_step = (moved, solved);
        touching
    }
}
