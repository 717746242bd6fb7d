//! Projection that does not tunnel: solids that move, vertices that move
//! fast, and the cloth's edges against a solid's edges and corners.
//!
//! [`project_shapes`](super::project_shapes) pushes a vertex found inside a
//! solid out the nearest way. That is right for a vertex that sank in a
//! little, and wrong in two cases a game meets:
//!
//! - **Tunnelling.** A vertex that passed the middle of a thin box in one
//!   step, or a ball thrown through the cloth faster than its radius per
//!   step, leaves the vertex nearer the far side: the nearest way out
//!   carries it on, through the solid. [`project_swept`] follows each vertex
//!   *relative to the solid* over the step, from where it was at the step's
//!   start ([`Sweep::start`], or `x − v·dt`, where its velocity says it
//!   was) shifted by the solid's own motion, to `x` (after a method's
//!   substeps, over the last one only, [`Sweep::share`]: the earlier ones
//!   kept the vertex out along a path that is no straight line). Where
//!   the nearest way out would continue that relative motion (or the vertex
//!   crossed the solid entirely and is outside again), it is put back out
//!   on the side where it entered: moved along the surface normal at its
//!   entry point until it is outside. Otherwise (it sank in, or started
//!   inside) it goes out the nearest way, exactly as before, so slow
//!   contact, and the lab's sphere, are unchanged.
//! - **Edges.** A vertex-only test lets a box's edge or corner cut between
//!   two vertices: cloth laid over a box has springs passing through it.
//!   With `edges` set, each surface edge of the cloth (stretch and shear
//!   springs) is tested after its vertices: the signed distance to a convex
//!   solid is convex along a segment, so its deepest point is found by a
//!   golden-section search, and the two ends are pushed out along the
//!   normal there (blended between a box's faces near its edges), in
//!   proportion to their share of that point (barycentric weights over
//!   inverse masses, as position-based dynamics moves a point–edge
//!   contact), in a few passes. The push is inelastic: the ends stop moving
//!   into the solid but are not given the push as a velocity (a taut edge
//!   over a box's edge is pushed out every step). Only boxes have edges
//!   to test: a plane's segment is deepest at an end, and a smooth solid
//!   (sphere, capsule) is cut by a segment whose ends are outside no
//!   deeper than by a chord of its own length (`L²/8r` for `L` ≪ `r`),
//!   which is how a cloth of that spacing wraps it, vertex on the
//!   surface, and how the reference lets it (pushing those chords out held
//!   the lab's coarse cloth off the sphere and strained it); `stiff`
//!   pushes them for a cloth with self-collision
//!   ([`XpbdSolver::collider_edges`](crate::solver::xpbd::XpbdSolver::collider_edges)).
//!
//! Sweeps follow a solid's translation only (a spinning box or a swinging
//! capsule sweeps by its centre's motion), and a solid that moved further
//! than [`TELEPORT`] in one step is taken as teleported: it is not swept.

use bevy::math::Vec3A;

use super::{Capsule, Shape, Sphere, inverse_pushes};
use crate::model::{ClothModel, ClothState, SpringKind};

/// A solid that moved further than this in one step (metres) was
/// teleported, not swept through the cloth: its motion is ignored.
pub const TELEPORT: f32 = 5.0;

/// How [`project_swept`] treats the solids.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sweep<'a> {
    /// How far each solid moved over the step (parallel to the solids;
    /// empty for solids that did not move).
    pub motion: &'a [Vec3A],
    /// Where each vertex was at the step's start (empty: `x − v·dt`, where
    /// its velocity says it was, right for a method whose velocity is the
    /// step's displacement over `dt`, not for one with substeps).
    pub start: &'a [Vec3A],
    /// The part of the step, from its end, that the vertices are swept
    /// over: 1 (or 0, the default), all of it; `1/n` after a method's `n` substeps
    /// ([`GuardedStep::last_substep`](crate::solver::guard::GuardedStep::last_substep)),
    /// whose earlier substeps kept the cloth out of the solids along a
    /// path that is no straight line from the step's start (swept so, a
    /// vertex carried round a solid was taken for one that passed through
    /// it and put back where it entered). Each solid's motion is scaled by
    /// it, and below 1 `start` is not read: each vertex was at
    /// `x − v·share·dt`.
    pub share: f32,
    /// Whether the cloth's edges are tested too (not only its vertices).
    pub edges: bool,
}

/// A vertex this close inside a solid at the step's start (metres) was
/// touching it, not inside: it was left on the surface by the last step's
/// projection, up to rounding, and is still swept.
const TOUCH: f32 = 1e-4;

/// Iterations of the line searches: golden section shrinks its interval by
/// 0.618 each, so 28 reach 1e-6 of the segment.
const SEARCH: usize = 28;

impl Shape {
    /// The signed distance from `x` to the solid's surface (negative
    /// inside) and the outward unit normal at the nearest surface point
    /// (its gradient).
    // `#[inline]` here and on `swept_contact`: without it, whether they
    // were inlined into `project_swept`'s vertex loop hung on how the
    // crate's codegen units were cut, and an unrelated call added to
    // `XpbdSolver::advance` left them out of line, the loop spilling to the
    // stack (the CHANGELOG has the measurement).
    #[inline]
    pub fn signed_distance(&self, x: Vec3A) -> (f32, Vec3A) {
        match self {
            Shape::Plane(p) => (p.normal.dot(x - p.point), p.normal),
            Shape::Capsule(c) => {
                let axis = c.b - c.a;
                let len_sq = axis.length_squared();
                let t = if len_sq > 0.0 {
                    ((x - c.a).dot(axis) / len_sq).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let d = x - (c.a + t * axis);
                let distance = d.length();
                let normal = if distance > 0.0 {
                    d / distance
                } else if len_sq > 0.0 {
                    axis.any_orthonormal_vector()
                } else {
                    Vec3A::Y
                };
                (distance - c.radius, normal)
            }
            Shape::Cuboid(b) => {
                let d = x - b.center;
                let local = Vec3A::new(d.dot(b.axes[0]), d.dot(b.axes[1]), d.dot(b.axes[2]));
                let q = local.abs() - b.half_extents;
                let sign = Vec3A::select(local.cmplt(Vec3A::ZERO), -Vec3A::ONE, Vec3A::ONE);
                let to_world = |l: Vec3A| l.x * b.axes[0] + l.y * b.axes[1] + l.z * b.axes[2];
                let outside = q.max(Vec3A::ZERO);
                let distance = outside.length();
                if distance > 0.0 {
                    (distance, to_world(outside * sign / distance))
                } else {
                    // Inside: out through the nearest face.
                    let k = if q.x >= q.y && q.x >= q.z {
                        0
                    } else if q.y >= q.z {
                        1
                    } else {
                        2
                    };
                    (q[k], b.axes[k] * sign[k])
                }
            }
        }
    }
}

/// The point of segment `a`–`b` deepest in (or nearest to) the convex
/// `shape`: its parameter `t ∈ [0, 1]` and signed distance. Golden-section
/// search on the convex signed distance.
fn deepest_on_segment(shape: &Shape, a: Vec3A, b: Vec3A) -> (f32, f32) {
    deepest_within(shape, a, b, SEARCH)
}

/// [`deepest_on_segment`] in `iterations` golden-section steps.
fn deepest_within(shape: &Shape, a: Vec3A, b: Vec3A, iterations: usize) -> (f32, f32) {
    const INV_PHI: f32 = 0.618_034;
    let f = |t: f32| shape.signed_distance(a + t * (b - a)).0;
    let (mut lo, mut hi) = (0.0_f32, 1.0_f32);
    let mut c = hi - INV_PHI * (hi - lo);
    let mut d = lo + INV_PHI * (hi - lo);
    let (mut fc, mut fd) = (f(c), f(d));
    for _ in 0..iterations {
        if fc < fd {
            hi = d;
            (d, fd) = (c, fc);
            c = hi - INV_PHI * (hi - lo);
            fc = f(c);
        } else {
            lo = c;
            (c, fc) = (d, fd);
            d = lo + INV_PHI * (hi - lo);
            fd = f(d);
        }
    }
    deeper_than_ends(f, 0.5 * (lo + hi))
}

/// `(t, f(t))`, or an end of the segment where `f` is at least as low
/// there (the lower end first).
#[inline]
fn deeper_than_ends(f: impl Fn(f32) -> f32, t: f32) -> (f32, f32) {
    let (fa, fb, ft) = (f(0.0), f(1.0), f(t));
    if fa <= ft && fa <= fb {
        (0.0, fa)
    } else if fb <= ft {
        (1.0, fb)
    } else {
        (t, ft)
    }
}

/// [`deepest_within`] where the deepest point has a closed form: on a
/// half-space, the lower end; on a capsule (or sphere), the segment's
/// point nearest the axis (the closest points of two segments), checked
/// against the ends; a box keeps the search. The edge pass below calls it
/// about 300 times per edge on a solid (its push found by bisection), in
/// every substep of `stiff`: with the search there, it was a quarter of the
/// drape's step.
fn deepest_fast(shape: &Shape, a: Vec3A, b: Vec3A, iterations: usize) -> (f32, f32) {
    let f = |t: f32| shape.signed_distance(a + t * (b - a)).0;
    let t = match shape {
        Shape::Cuboid(_) => return deepest_within(shape, a, b, iterations),
        Shape::Plane(_) => 0.0,
        Shape::Capsule(c) => nearest_to_axis(a, b, c.a, c.b),
    };
    deeper_than_ends(f, t)
}

/// The parameter `s ∈ [0, 1]` of the point of segment `a`–`b` nearest to
/// segment `p`–`q` (the closest points of two segments, as in Ericson's
/// *Real-Time Collision Detection*, 5.1.9; either may be a point).
fn nearest_to_axis(a: Vec3A, b: Vec3A, p: Vec3A, q: Vec3A) -> f32 {
    let (d1, d2, r) = (b - a, q - p, a - p);
    let (aa, ee, ff) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    let tiny = f32::EPSILON;
    if aa <= tiny {
        return 0.0;
    }
    let c = d1.dot(r);
    if ee <= tiny {
        return (-c / aa).clamp(0.0, 1.0);
    }
    let bb = d1.dot(d2);
    let denom = aa * ee - bb * bb;
    let s = if denom > 0.0 {
        ((bb * ff - c * ee) / denom).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let t = (bb * s + ff) / ee;
    if t < 0.0 {
        (-c / aa).clamp(0.0, 1.0)
    } else if t > 1.0 {
        ((bb - c) / aa).clamp(0.0, 1.0)
    } else {
        s
    }
}

/// The first `t ∈ [lo, hi]` where `f` crosses zero, for `f(lo) > 0 ≥
/// f(hi)` (bisection).
fn first_root(f: impl Fn(f32) -> f32, mut lo: f32, mut hi: f32) -> f32 {
    for _ in 0..SEARCH {
        let mid = 0.5 * (lo + hi);
        if f(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Whether a path that entered `shape` where its normal is `entry`, went
/// `deepest` in, and ends where the normal is `end` (the nearest way out
/// if it ends inside, where it came out if outside) went *through* the
/// solid rather than round it: into a box and out of (or towards) the
/// opposite face, or into a capsule or sphere further than a tenth of its
/// radius. A vertex sliding over a box's edge or along a ball cuts a
/// corner or a shallow chord in one step; that is not tunnelling.
fn went_through(shape: &Shape, entry: Vec3A, end: Vec3A, deepest: f32) -> bool {
    match shape {
        Shape::Plane(_) => false,
        Shape::Cuboid(_) => entry.dot(end) < -0.5,
        Shape::Capsule(c) => deepest < -0.1 * c.radius,
    }
}

/// Where a vertex now at `x` that came from `from` (both relative to the
/// solid's current place) must go out of `shape`, if it is inside or passed
/// through it: the unit direction and how far. `None` if it is outside and
/// did not pass through.
#[inline]
fn swept_contact(shape: &Shape, from: Vec3A, x: Vec3A) -> Option<(Vec3A, f32)> {
    let (fx, nearest) = shape.signed_distance(x);
    let (f_from, _) = shape.signed_distance(from);
    let travel = x - from;
    // Where the segment first enters the solid before `until`, and the
    // outward normal there.
    let entry = |until: f32| {
        let t = first_root(|t| shape.signed_distance(from + t * travel).0, 0.0, until);
        let at = from + t * travel;
        (at, shape.signed_distance(at).1.normalize_or_zero())
    };
    if fx < 0.0 {
        // Inside: the nearest way out, unless that carries the vertex on
        // through a solid it came into from outside.
        if f_from <= -TOUCH || nearest.dot(travel) <= 0.0 {
            return Some((nearest, -fx));
        }
        let (at, normal) = entry(1.0);
        let (_, deepest) = deepest_on_segment(shape, from, x);
        if normal == Vec3A::ZERO || !went_through(shape, normal, nearest, deepest) {
            return Some((nearest, -fx));
        }
        return back_to(at, x);
    }
    // Outside now: did it pass through in this step? (The distance is
    // 1-Lipschitz and convex along the segment, so it stays at least
    // (f_from + fx − length)/2.)
    if f_from <= -TOUCH || f_from + fx >= travel.length() {
        return None;
    }
    let (t, deepest) = deepest_on_segment(shape, from, x);
    if deepest >= 0.0 {
        return None;
    }
    let (at, normal) = entry(t);
    // Where it came out: the last zero, from the end back to the deepest.
    let back = x - (from + t * travel);
    let out = first_root(|s| shape.signed_distance(x - s * back).0, 0.0, 1.0);
    let exit = shape.signed_distance(x - out * back).1;
    if normal == Vec3A::ZERO || !went_through(shape, normal, exit, deepest) {
        return None;
    }
    back_to(at, x)
}

/// The push that puts a vertex at `x` back where it entered the solid, at
/// `at` (on its surface, relative to where the solid is now): it stays on
/// the side it came from, where it met the solid, and moves with it.
fn back_to(at: Vec3A, x: Vec3A) -> Option<(Vec3A, f32)> {
    let push = at - x;
    let depth = push.length();
    (depth > 0.0).then(|| (push / depth, depth))
}

/// Projects the cloth out of `solids` (grown by `thickness`) after a step
/// without tunnelling (see the module docs): each free vertex swept
/// relative to each solid, then, with [`Sweep::edges`], each surface edge.
/// The velocity changes by each displacement over `dt`, with Coulomb
/// friction on vertex contacts as in
/// [`project_shapes`](super::project_shapes). Returns the contacts made
/// (vertices and edges). `dt` must be positive.
pub fn project_swept(
    model: &ClothModel,
    state: &mut ClothState,
    solids: &[Shape],
    sweep: Sweep,
    thickness: f32,
    dt: f32,
) -> usize {
    let pinned = model.pinned();
    let inv_dt = 1.0 / dt;
    let mut count = 0;
    for (k, solid) in solids.iter().enumerate() {
        let shape = solid.grown(thickness);
        let mut motion = sweep.motion.get(k).copied().unwrap_or(Vec3A::ZERO);
        if !motion.is_finite() || motion.length() > TELEPORT {
            motion = Vec3A::ZERO;
        }
        let share = if sweep.share > 0.0 && sweep.share < 1.0 {
            sweep.share
        } else {
            1.0
        };
        let ClothState {
            positions,
            velocities,
        } = &mut *state;
        for (i, (x, v)) in positions.iter_mut().zip(velocities.iter_mut()).enumerate() {
            if pinned[i] {
                continue;
            }
            let was = match sweep.start.get(i) {
                Some(&start) if share == 1.0 => start,
                _ => *x - *v * (dt * share),
            };
            let from = was + motion * share;
            let Some((normal, depth)) = swept_contact(&shape, from, *x) else {
                continue;
            };
            if !(depth.is_finite() && normal.is_finite()) {
                continue;
            }
            // A vertex put back where it entered sticks there: no friction
            // (its push is not along the surface normal).
            let entered = (normal - shape.signed_distance(*x + depth * normal).1).length() > 1e-3;
            *x += depth * normal;
            count += 1;
            if entered {
                // It moves on with the solid.
                *v = motion * inv_dt;
            } else {
                *v += depth * inv_dt * normal;
                // On the vertex's own motion, not relative to the solid's
                // (as `stiff`'s substeps take it): a solid's motion here is
                // its centre's, and against a leg capsule swinging from the
                // hip it dragged the cape scene's skirt 10 % long.
                super::friction(x, v, normal, depth * inv_dt, shape.friction(), dt);
            }
        }
        if sweep.edges && has_edges(&shape) {
            count += project_edges(model, state, &shape);
        }
    }
    count
}

/// Passes of the edge test: an edge across a box's edge is pushed out in
/// one where the blended direction is right, and the rest (an edge over a
/// corner, one pushed back in by its neighbour's push) in the next.
const EDGE_PASSES: usize = 4;

/// Pushes each surface edge of the cloth out of `shape` (already grown)
/// at its deepest point, in up to [`EDGE_PASSES`] passes; returns how many
/// pushes were made.
fn project_edges(model: &ClothModel, state: &mut ClothState, shape: &Shape) -> usize {
    let mut count = 0;
    for _ in 0..EDGE_PASSES {
        let pushed = edge_pass(
            model,
            &mut state.positions,
            Some(&mut state.velocities),
            shape,
        );
        count += pushed;
        if pushed == 0 {
            break;
        }
    }
    count
}

/// One pass of [`project_edges`] over `positions`: the edges of the cloth
/// pushed out of `shape` (already grown). With `velocities`, each end stops
/// moving into the solid; without, the positions alone move (a
/// position-based method's substep, whose velocities follow its
/// positions). Returns the edges pushed.
pub(crate) fn edge_pass(
    model: &ClothModel,
    positions: &mut [Vec3A],
    velocities: Option<&mut [Vec3A]>,
    shape: &Shape,
) -> usize {
    let springs = model.topology().springs();
    edge_pass_over(
        model,
        positions,
        velocities,
        shape,
        (0..springs.len() as u32).filter(|&k| springs[k as usize].kind != SpringKind::Bend),
    )
}

/// The surface edges (stretch and shear springs, by index) that may meet
/// `shape` while each of their ends moves at most `margin`: the ones that
/// pass inside it grown by `margin` (or end inside it). A method with
/// substeps finds them once per step and tests only them in each substep
/// ([`edge_pass_over`]).
pub(crate) fn edge_candidates(
    model: &ClothModel,
    positions: &[Vec3A],
    shape: &Shape,
    margin: f32,
    out: &mut Vec<u32>,
) {
    out.clear();
    if matches!(shape, Shape::Plane(_)) || !margin.is_finite() {
        return;
    }
    let grown = shape.grown(margin);
    let (centre, reach) = bounding_sphere(&grown);
    for (k, spring) in model.topology().springs().iter().enumerate() {
        let (a, b) = (positions[spring.a as usize], positions[spring.b as usize]);
        if spring.kind == SpringKind::Bend || a.distance(centre) > reach + a.distance(b) {
            continue;
        }
        if passes_inside(&grown, a, b) || grown.signed_distance(a).0 < 0.0 {
            out.push(k as u32);
        }
    }
}

/// Whether `shape` has edges or corners that can cut between the cloth's
/// vertices: boxes only. A segment whose ends lie outside a plane, a sphere
/// or a capsule cuts it no deeper than a chord of the same length, which is
/// what a cloth of that spacing wrapped around it does with every vertex on
/// the surface (and what the stability map's reference does). Pushing those
/// chords out held the lab's coarse cloth (0.5 m between vertices over a
/// 2.7 m sphere) a centimetre off the sphere, away from the reference,
/// strained the stiff cloth draped there and overstretched the soft one
/// falling onto it. `stiff` still pushes them for a cloth with
/// self-collision (see [`XpbdSolver::collider_edges`](crate::solver::xpbd::XpbdSolver::collider_edges)).
pub(crate) fn has_edges(shape: &Shape) -> bool {
    matches!(shape, Shape::Cuboid(_))
}

/// Whether `stiff`'s substeps push the cloth's edges off `shape`: a box's
/// always ([`has_edges`]), a smooth solid's only for a cloth with
/// self-collision, whose layers folded on the solid keep their order only
/// with those pushes (see
/// [`XpbdSolver::collider_edges`](crate::solver::xpbd::XpbdSolver::collider_edges)).
pub(crate) fn pushes_edges(shape: &Shape, self_collision: bool) -> bool {
    has_edges(shape) || self_collision
}

/// A sphere around a solid that is not a plane: centre and radius.
fn bounding_sphere(shape: &Shape) -> (Vec3A, f32) {
    match *shape {
        Shape::Plane(p) => (p.point, f32::INFINITY),
        Shape::Capsule(c) => (0.5 * (c.a + c.b), 0.5 * c.a.distance(c.b) + c.radius),
        Shape::Cuboid(b) => (b.center, b.half_extents.length()),
    }
}

/// [`edge_pass`] over the springs `edges` (indices; stretch and shear).
pub(crate) fn edge_pass_over(
    model: &ClothModel,
    positions: &mut [Vec3A],
    mut velocities: Option<&mut [Vec3A]>,
    shape: &Shape,
    edges: impl IntoIterator<Item = u32>,
) -> usize {
    if matches!(shape, Shape::Plane(_)) {
        return 0;
    }
    // A sphere around the solid: an edge whose end is further from its
    // centre than its radius and the edge's length cannot touch it.
    let (centre, reach) = bounding_sphere(shape);
    let springs = model.topology().springs();
    let mut count = 0;
    for k in edges {
        let spring = springs[k as usize];
        let (i, j) = (spring.a as usize, spring.b as usize);
        let (a, b) = (positions[i], positions[j]);
        if a.distance(centre) > reach + a.distance(b) {
            continue;
        }
        // Only an edge whose ends are outside and whose middle goes in.
        if !passes_inside(shape, a, b)
            || shape.signed_distance(a).0 <= 0.0
            || shape.signed_distance(b).0 <= 0.0
        {
            continue;
        }
        let (t, deepest) = deepest_fast(shape, a, b, SEARCH);
        if deepest >= 0.0 || !deepest.is_finite() {
            continue;
        }
        let normal = push_direction(shape, a + t * (b - a));
        let Some([ra, rb]) = inverse_pushes(model, [i, j], [1.0 - t, t], 1.0) else {
            continue;
        };
        // How far (the deepest point's move) until the whole edge is out:
        // across a box's edge the blended direction needs more than the
        // depth (√2 of it over a right angle). At most 1.5 times the depth:
        // where the direction is poor, the next pass does the rest rather
        // than one push throwing the edge far.
        // (On a box, coarser searches here: a tenth of a percent of the push is
        // plenty, and this runs in every substep of `stiff`.)
        let clear =
            |s: f32| deepest_fast(shape, a + ra * s * normal, b + rb * s * normal, 22).1 >= 0.0;
        let most = -1.5 * deepest;
        let s = if clear(most) {
            let mut lo = 0.0;
            let mut hi = most;
            for _ in 0..12 {
                let mid = 0.5 * (lo + hi);
                if clear(mid) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            hi
        } else {
            most
        };
        positions[i] += ra * s * normal;
        positions[j] += rb * s * normal;
        // Inelastic: the ends stop moving into the solid, and are not
        // given the push as a velocity (a taut edge over a box's edge is
        // pushed out every step; as a velocity that would pump energy in).
        if let Some(v) = velocities.as_deref_mut() {
            for k in [i, j] {
                let into = v[k].dot(normal);
                if into < 0.0 {
                    v[k] -= into * normal;
                }
            }
        }
        count += 1;
    }
    count
}

/// Whether segment `a`–`b` passes through the inside of `shape` (a box's
/// slabs, a capsule's axis nearer than its radius; never a plane, where a
/// segment is deepest at an end): the exact, cheap test before the search
/// for its deepest point. An edge lying on a face is not inside.
fn passes_inside(shape: &Shape, a: Vec3A, b: Vec3A) -> bool {
    match shape {
        Shape::Plane(_) => false,
        Shape::Cuboid(c) => {
            let local = |x: Vec3A| {
                let d = x - c.center;
                Vec3A::new(d.dot(c.axes[0]), d.dot(c.axes[1]), d.dot(c.axes[2]))
            };
            let (p, q) = (local(a), local(b));
            let (mut lo, mut hi) = (0.0_f32, 1.0_f32);
            for k in 0..3 {
                let (h, from, d) = (c.half_extents[k], p[k], q[k] - p[k]);
                if d.abs() < 1e-12 {
                    if from.abs() >= h {
                        return false;
                    }
                    continue;
                }
                let (t1, t2) = ((-h - from) / d, (h - from) / d);
                lo = lo.max(t1.min(t2));
                hi = hi.min(t1.max(t2));
                if lo >= hi {
                    return false;
                }
            }
            true
        }
        Shape::Capsule(c) => segment_distance(a, b, c.a, c.b) < c.radius,
    }
}

/// The distance between segments `p0`–`p1` and `q0`–`q1` (the closest
/// points by clamped parameters, as in Ericson's *Real-Time Collision
/// Detection*, 5.1.9).
fn segment_distance(p0: Vec3A, p1: Vec3A, q0: Vec3A, q1: Vec3A) -> f32 {
    let (d1, d2, r) = (p1 - p0, q1 - q0, p0 - q0);
    let (a, e, f) = (d1.length_squared(), d2.length_squared(), d2.dot(r));
    let (s, t) = if a <= f32::EPSILON && e <= f32::EPSILON {
        (0.0, 0.0)
    } else if a <= f32::EPSILON {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = d1.dot(r);
        if e <= f32::EPSILON {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = d1.dot(d2);
            let denom = a * e - b * b;
            let mut s = if denom > 0.0 {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (p0 + s * d1).distance(q0 + t * d2)
}

/// The direction to push a point inside `shape` out along: the surface
/// normal, or, inside a box near its edge or corner, the faces' normals
/// blended by how near each is (within the point's depth again), so that
/// an edge across a box's edge is pushed off it diagonally.
fn push_direction(shape: &Shape, x: Vec3A) -> Vec3A {
    let (distance, normal) = shape.signed_distance(x);
    let Shape::Cuboid(b) = shape else {
        return normal;
    };
    if distance >= 0.0 {
        return normal;
    }
    let d = x - b.center;
    let mut blend = Vec3A::ZERO;
    for k in 0..3 {
        let local = d.dot(b.axes[k]);
        let q = local.abs() - b.half_extents[k];
        let weight = q - 2.0 * distance;
        if weight > 0.0 {
            blend += weight * local.signum() * b.axes[k];
        }
    }
    blend.try_normalize().unwrap_or(normal)
}

/// The lab's and the game's spheres as zero-length capsules, for
/// [`project_swept`].
pub fn sphere_solids(spheres: &[Sphere]) -> impl Iterator<Item = Shape> + '_ {
    spheres.iter().map(|s| {
        Shape::Capsule(Capsule {
            a: s.center,
            b: s.center,
            radius: s.radius,
            friction: s.friction,
        })
    })
}

#[cfg(test)]
mod tests;
