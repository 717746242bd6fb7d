//! Extended position-based dynamics with small steps — the `stiff` method
//! (Macklin, Müller, Chentanez 2016; Macklin, Storey, Lu et al. 2019).
//!
//! One step of length `dt` is `n = ⌈dt·r⌉` substeps of length `h = dt/n`,
//! `r` the substep rate ([`XpbdSolver::substep_rate`]: 960 per second, 32
//! substeps of the lab's 30 Hz step, 16 of a game's 60 Hz one). Each
//! substep, for every free vertex `i`:
//!
//! 1. `vᵢ ← d^{1/n} vᵢ + h g` (`d` the step's damping, so the step damps
//!    as the other methods do), `pᵢ ← xᵢ`, `xᵢ ← xᵢ + h vᵢ`;
//! 2. with [`XpbdSolver::chains`] (off in the preset), each of the
//!    cloth's chains of stretch springs (its rows, columns and diagonal
//!    lines) solved
//!    whole: one tridiagonal system in their multipliers, so a pull passes
//!    from one end of a chain to the other within the substep (see
//!    `chains.rs`); then
//!    one Gauss–Seidel sweep over the springs, colour by colour (a greedy
//!    edge colouring: springs of one colour share no vertex): a spring
//!    `(a, b)` of rest length `L`, stiffness `k`, violation `C = l − L`
//!    moves its ends along `n = (xₐ − x_b)/l` by
//!    `xₐ ← xₐ − wₐ C/(wₐ + w_b + α̃) n`, `x_b ← x_b + w_b C/(…) n`, with
//!    `w = 1/m` (0 at a pin) and the compliance `α̃ = 1/(k h²)`: XPBD's
//!    update with its multiplier starting at zero each substep (one
//!    iteration per substep, as Macklin et al. 2019 recommend);
//! 3. every vertex inside a solid of [`StepInput::contacts`] or a penalty
//!    collider ([`StepInput::spheres`], whose stiffness it does not use: an
//!    explicit penalty force at the substep bounces the cloth off
//!    elastically) is moved to its surface, with position-based Coulomb
//!    friction: of its tangential motion over the substep relative to the
//!    solid's (a solid that moved this step moves through the substeps),
//!    up to `μ` times the depth is taken back (all of it: static
//!    friction), so a moving solid carries the cloth it holds;
//! 4. `vᵢ ← (xᵢ − pᵢ)/h` (computed as the predicted velocity plus the
//!    substep's corrections over `h`, which keeps `f32` precision far from
//!    the origin).
//!
//! The projection after the step ([`project_swept`](crate::collision::project_swept))
//! sweeps each vertex over the last substep only
//! ([`StepReport::substeps`]): the substeps carried it round the solids on
//! a path that is no straight line from the step's start.
//!
//! After the last substep, a cloth with self-collision has the edges that
//! went through its own triangles anyway taken back out (see
//! [`collision::self_contact`](crate::collision::self_contact), "Edges
//! already through").
//!
//! Soft springs (`α̃ ≫ w`) move by about `h² k C/m`, an explicit spring
//! force at the substep; stiff ones (`α̃ ≪ w`) are projected to their rest
//! length, so stiffness costs nothing in stability. What one sweep leaves
//! undone shrinks with the substep: the substep count is the method's one
//! knob (its "iterations"). It does not minimise the implicit-Euler
//! objective, so it reports no convergence measure; it is judged against
//! the physical reference on the stability map (`docs/report/stability.md`).
//!
//! Contacts act inside every substep, so stiff cloth on a collider is not
//! strained by a projection after the step. Near a collider one sweep per
//! substep is not enough for stiff cloth: the springs next to the
//! contacts stretch on impact, and cloth draped on a frictionless collider
//! creeps off it. A step whose swept cloth comes near a collider therefore
//! multiplies its substeps by the power of two at or above `κ = k h²/m`
//! (stiffness over the mean free vertex mass at the substep), up to
//! [`XpbdSolver::max_refinement`] (16 in the preset). The lab's cloth
//! (`κ ≈ 0.01`) and cloth hanging free pay nothing; the lab's stiff fabric
//! (`k = 1e7`) takes 16× its substeps while it touches the sphere. The other methods leave the
//! same solids to the projection after the step (which then finds nothing
//! left to do here).

mod bound;
mod chains;
mod colouring;
#[cfg(test)]
mod tests;
pub(crate) mod tethers;

use bevy::math::Vec3A;
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;

use self::bound::{Bound, Near, Solids, project, project_near};
use self::colouring::{Colouring, Links};
use self::tethers::{Tethers, hold};
use super::{Method, ParamError, StepError, StepInput, StepReport};
use crate::collision::self_contact::{IntersectionCheck, SelfContacts, untangle};
use crate::collision::swept::{edge_candidates, edge_pass_over, pushes_edges};
use crate::collision::{PenaltySphere, Shape};
use crate::model::{ClothState, SpringKind};
use crate::solver::engine::sweep::{ColouredSprings, sweep};

/// A pin's motion over one step, in cloth sizes, from which it counts as a
/// teleport (see [`XpbdSolver`]'s step).
const TELEPORT: f32 = 0.5;

/// Steps a cloth by XPBD with small steps: substeps of one Gauss–Seidel
/// sweep each at a rate per second, contacts projected in every substep
/// (see the module docs). Right for stiff cloth at a game's frame rate. As
/// a component on a cloth entity it selects this method
/// ([`XpbdPlugin`](crate::XpbdPlugin)); its preset is `stiff`.
///
/// The substep is set by a rate, not a count per step, because what one
/// sweep leaves undone depends on the substep's length: at a fixed count a
/// long step took substeps too long for stiff springs, and a short one
/// substeps so short that `f32` positions lost their motion to rounding
/// (the stability map; the CHANGELOG has the numbers).
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Default, Debug, PartialEq)]
pub struct XpbdSolver {
    /// Substeps per second: a step of `dt` takes `⌈dt·rate⌉` substeps (at
    /// least one), each one sweep over the springs.
    pub substep_rate: u32,
    /// Whether each free vertex is tethered to its nearest pin (long-range
    /// attachments, Kim et al. 2012): no further from it than at rest,
    /// times a slack that lets the springs stretch as far as the cloth's
    /// weight can stretch them (see the module docs). It takes back the
    /// sag one sweep per substep leaves in a long hanging cloth.
    pub tethers: bool,
    /// The most a step near a collider multiplies its substeps by (1: never).
    /// One sweep per substep leaves stiff cloth's contacts half resolved:
    /// on impact the springs next to the contacts stretch, and a cloth
    /// draped on a frictionless collider creeps off it. What it leaves
    /// undone grows with `κ = k h²/m` (the stretch stiffness over the mean
    /// free vertex mass, at the substep `h`), so a step whose swept cloth
    /// comes near a collider (see [`XpbdSolver::refinement`]) takes
    /// `2^⌈log₂ κ⌉` times its substeps, up to this many. A cloth far
    /// from every collider, and cloth with `κ ≤ 1` (the lab's, and
    /// cotton at 16² and coarser), pays nothing. A character's garments
    /// are always near the body's capsules and pay it in every step: the
    /// perf page's "Character cloth" section compares 16 (the preset), 4
    /// and 1 on the cape scene, and the README says which to choose.
    pub max_refinement: u32,
    /// Whether boxes push the cloth's edges in every substep, not only its
    /// vertices (see [`collision::swept`](crate::collision::swept)): cloth
    /// drapes over a box's edge instead of cutting it. Spheres and capsules
    /// push the edges of a cloth with self-collision only: without, a chord
    /// between two vertices on their surface is how cloth of that spacing
    /// wraps them (and how the stability map's reference does), where
    /// pushing it out holds a coarse cloth off the solid and strains it;
    /// with, the layers folded on the solid keep their order only with the
    /// pushes (the drape scene's sheets on the ball: edges through a sheet
    /// without them, none with them). It costs a test of each edge near the solid
    /// in every substep (a 32² sheet resting on a box: about four times the
    /// step).
    /// Default on (also for a saved cloth from before it existed).
    #[reflect(default = "on")]
    pub collider_edges: bool,
    /// Whether each substep first solves the cloth's chains of stretch
    /// springs whole (its rows, columns and diagonal lines: paths of springs that go on
    /// straight through their vertices), one tridiagonal system per chain,
    /// eight chains at a time, before its sweep (see the `chains` module).
    /// One sweep passes a pull one spring on per substep, so a fine cloth
    /// answers its pins and colliders slowly and stretches; a chain passes
    /// it from end to end in one substep. The cape scene's 4,000-vertex
    /// cape without refinement: 48 % largest stretch without, 22 % with (the
    /// perf page, which also gives its cost). Off in the `stiff` preset,
    /// which the stability map and the report measure without it (the
    /// map's contact cases show it beside, as `stiff chains`); a saved
    /// method from before it is off.
    #[reflect(default)]
    pub chains: bool,
}

/// [`XpbdSolver::collider_edges`]' default when a saved method lacks it.
fn on() -> bool {
    true
}

impl XpbdSolver {
    /// The `stiff` preset: 960 substeps per second (32 per step of the
    /// lab's 30 Hz, as many spring passes as its 32 Chebyshev iterations;
    /// 16 per step at 60 Hz), with tethers, refined up to 16× near a
    /// collider.
    pub const STIFF: Self = Self::new(960);

    /// `stiff` for a character's garments: [`STIFF`](Self::STIFF) with its
    /// refinement near colliders capped at 4×
    /// ([`max_refinement`](Self::max_refinement)). A garment is always near
    /// its body's capsules, so it pays the refinement in every step; a
    /// garment of a few hundred vertices keeps about the preset's stretch
    /// at a quarter of its substeps. A finer garment (thousands of
    /// vertices) stretches about three times as far with the cap, and
    /// self-colliding cloth goes through itself: both need the preset's
    /// 16× (the perf page's "Character cloth" section and
    /// `docs/measurements.md`).
    pub const GARMENT: Self = Self::STIFF.with_max_refinement(4);

    /// With `substep_rate` substeps per second, tethers, and refinement near
    /// colliders up to 16×.
    pub const fn new(substep_rate: u32) -> Self {
        Self {
            substep_rate,
            tethers: true,
            max_refinement: 16,
            collider_edges: true,
            chains: false,
        }
    }

    /// The same method with the colliders pushing the cloth's edges
    /// ([`collider_edges`](Self::collider_edges)) or its vertices only.
    #[must_use]
    pub const fn with_collider_edges(mut self, on: bool) -> Self {
        self.collider_edges = on;
        self
    }

    /// The same method with its chains of stretch springs solved whole in
    /// each substep ([`chains`](Self::chains)) or not.
    #[must_use]
    pub const fn with_chains(mut self, on: bool) -> Self {
        self.chains = on;
        self
    }

    /// The same method refining its substeps near colliders up to `max`
    /// times (1: never).
    #[must_use]
    pub const fn with_max_refinement(mut self, max: u32) -> Self {
        self.max_refinement = max;
        self
    }

    /// How many times a step of `substeps` substeps of `dt` seconds near a
    /// collider multiplies them, for stretch stiffness `k` and mean free
    /// vertex mass `mass`: `2^⌈log₂ κ⌉` with `κ = k h²/m`, `h = dt/substeps`,
    /// between 1 and [`max_refinement`](Self::max_refinement).
    pub fn refinement(&self, substeps: u32, dt: f64, k: f32, mass: f32) -> u32 {
        let h = dt / f64::from(substeps.max(1));
        let kappa = f64::from(k) * h * h / f64::from(mass);
        let max = self.max_refinement.max(1);
        if kappa.is_nan() || kappa <= 1.0 {
            return 1;
        }
        if kappa >= f64::from(max) {
            return max;
        }
        (kappa.ceil() as u32).next_power_of_two().min(max)
    }

    /// The same method with tethers on or off.
    #[must_use]
    pub const fn with_tethers(mut self, on: bool) -> Self {
        self.tethers = on;
        self
    }

    /// The same method with `substeps` substeps per step of `dt` seconds
    /// (the rate rounded up so that a step takes exactly that many).
    #[must_use]
    pub fn with_substeps(self, substeps: u32, dt: f64) -> Self {
        let rate = (f64::from(substeps) / dt).ceil().min(f64::from(u32::MAX)) as u32;
        let mut method = Self {
            substep_rate: rate.max(1),
            ..self
        };
        // ⌈dt·rate⌉ can exceed the count by rounding: step the rate down.
        while method.substeps(dt) > substeps && method.substep_rate > 1 {
            method.substep_rate -= 1;
        }
        method
    }

    /// The substeps of a step of `dt` seconds: `⌈dt·rate⌉`, at least one
    /// (a rate within a millionth of a whole count per step takes that
    /// count, so 960 per second is 32 at the lab's `dt = 0.0333`).
    pub fn substeps(&self, dt: f64) -> u32 {
        let exact = dt * f64::from(self.substep_rate);
        (exact * (1.0 - 1e-6))
            .ceil()
            .clamp(1.0, f64::from(u32::MAX)) as u32
    }
}

impl Default for XpbdSolver {
    /// [`XpbdSolver::STIFF`].
    fn default() -> Self {
        Self::STIFF
    }
}

impl Method for XpbdSolver {
    type Workspace = XpbdWorkspace;

    fn name(&self) -> &'static str {
        "stiff"
    }

    fn validate(&self) -> Result<(), ParamError> {
        if self.substep_rate == 0 || self.max_refinement == 0 {
            return Err(ParamError::Iterations);
        }
        Ok(())
    }

    /// Advances `state` by XPBD substeps at the substep rate (see the
    /// module docs).
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        ws: &mut XpbdWorkspace,
    ) -> Result<StepReport, StepError> {
        let StepInput {
            model,
            params,
            spheres,
            contacts,
            contact_motion,
            skin,
            self_collision,
        } = input;
        let n = model.vertex_count();
        let base = self.substeps(params.dt);
        let k = params.stiffness.as_array();
        let substeps = if self.max_refinement > 1 && (!contacts.is_empty() || !spheres.is_empty()) {
            // Pins are unique (the model checks), so this is the free count.
            let free = (n - model.pins().len()).max(1);
            let mass = model.free_mass() / free as f32;
            let refine = self.refinement(base, params.dt, k[SpringKind::Stretch as usize], mass);
            let near = refine > 1 && {
                // A solid that moved is near if it was near where it was,
                // too (it swept the space between).
                let was = contacts
                    .iter()
                    .zip(contact_motion)
                    .filter(|&(_, m)| *m != Vec3A::ZERO && m.is_finite())
                    .map(|(s, m)| s.translated(-*m));
                let solids = contacts
                    .iter()
                    .copied()
                    .chain(was)
                    .chain(spheres.iter().map(PenaltySphere::as_shape));
                near_any(
                    &state.positions[..n],
                    &state.velocities[..n],
                    params,
                    solids,
                )
            };
            if near {
                base.saturating_mul(refine)
            } else {
                base
            }
        } else {
            base
        };
        let h = (params.dt / f64::from(substeps)) as f32;
        let inv_h = 1.0 / h;
        let damping = params.damping.powf(1.0 / substeps as f32);
        let gravity = Vec3A::from(params.gravity);
        let pinned = model.pinned();

        ws.colouring.update(model);
        ws.links.update(model, &ws.colouring, k, h);
        let ClothState {
            positions: x,
            velocities: v,
        } = state;
        let (x, v) = (&mut x[..n], &mut v[..n]);
        ws.previous.clear();
        ws.previous.extend(x.iter().map(|&x| [x; 2]));
        let prev = &mut ws.previous[..n];

        // Every collider is projected in the substeps, penalty ones too:
        // their force, explicit at the substep, bounces the cloth off
        // elastically, where a projection stops it.
        ws.solids.clear();
        ws.solids.extend_from_slice(contacts);
        ws.solids
            .extend(spheres.iter().map(PenaltySphere::as_shape));
        // Solids that moved this step move through the substeps, from where
        // they were to where they are (`ws.solids` holds them at the end;
        // `ws.moving` where they are in the substep).
        ws.motion.clear();
        ws.motion.extend(ws.solids.iter().enumerate().map(|(k, _)| {
            let m = contact_motion.get(k).copied().unwrap_or(Vec3A::ZERO);
            if m.is_finite() && m.length() <= crate::collision::swept::TELEPORT {
                m
            } else {
                Vec3A::ZERO
            }
        }));
        let sweeping = ws.motion.iter().any(|m| *m != Vec3A::ZERO);
        // Each solid's motion over one substep: friction acts on a vertex's
        // motion relative to the solid it touches.
        ws.shift.clear();
        ws.shift
            .extend(ws.motion.iter().map(|&m| m / substeps as f32));
        ws.moving.clear();
        ws.moving.extend_from_slice(&ws.solids);
        ws.bounds.clear();
        ws.bounds.extend(ws.solids.iter().map(Bound::of));
        let contacts = &ws.solids[..];
        // The projection's boxes (and, with self-collision, its smooth
        // solids) push the cloth's edges too; the penalty solids (last) its
        // vertices only, as their force would.
        let projected = if self.collider_edges {
            ws.solids.len() - spheres.len()
        } else {
            0
        };
        // The edges each solid may meet this step, found once: within what
        // a vertex can move in the step (its speed, the fall) and the
        // solid's own motion of it; none for a solid that pushes vertices
        // only.
        let pushing = |solid: &Shape| pushes_edges(solid, self_collision.is_some());
        let reach = if ws.solids[..projected].iter().any(pushing) {
            v.iter().map(|v| v.length()).fold(0.0_f32, f32::max) * params.dt as f32 + params.fall()
        } else {
            0.0
        };
        ws.edges.resize_with(projected, Vec::new);
        for ((solid, motion), edges) in ws.solids[..projected]
            .iter()
            .zip(&ws.motion)
            .zip(&mut ws.edges)
        {
            if pushing(solid) {
                edge_candidates(model, x, solid, reach + motion.length() + 1e-3, edges);
            } else {
                edges.clear();
            }
        }
        // Each pass over the vertices ends one substep (contacts, velocity)
        // and begins the next (prediction), so each substep reads them once.
        // Without penalty spheres or solids it is a plain loop (the general
        // one kept its constants on the stack: a third of the lab step).
        // A character cloth's skin, held in every substep (its lists cover
        // the cloth: the plugin checks).
        let skin = skin.filter(|s| {
            s.positions.len().min(s.normals.len()) >= n
                && s.max_distance.len().min(s.backstop_distance.len()) >= n
        });
        // The skin moves through the substeps from where it was, as the
        // pins do, unless a vertex's skin jumped (a teleport).
        let skin_start = skin.and_then(|s| s.previous).filter(|p| p.len() >= n);
        ws.skin_now.clear();
        ws.skin_normals.clear();
        if let Some(s) = skin {
            ws.skin_now.extend_from_slice(&s.positions[..n]);
            ws.skin_normals
                .extend(s.normals[..n].iter().map(|n| n.normalize_or_zero()));
        }
        let skin_tethers = skin.map_or(f32::INFINITY, |s| s.tether_scale);
        let tethered = (self.tethers || skin_tethers.is_finite()) && !model.pins().is_empty() && {
            ws.tethers.update(model);
            ws.tethers.any()
        };
        // Pins move along their step's motion (their velocity, the
        // displacement over the step) one substep at a time: at the step's
        // start all at once, they would drag the springs at their ends
        // through what one sweep cannot pass on.
        let pins = model.pins();
        ws.pin_paths.clear();
        ws.pin_paths.extend(
            pins.iter()
                .map(|&p| (x[p as usize], v[p as usize] * params.dt as f32)),
        );
        // A pin that jumped by half the cloth's size or more in one step was
        // teleported, not moved: dragging the cloth along that path would
        // whip it apart, so it is where it jumped to from the first substep
        // on (as for the other methods).
        let teleport = (TELEPORT * model.size()).powi(2);
        let moving = ws.pin_paths.iter().any(|&(_, shift)| shift != Vec3A::ZERO)
            && ws
                .pin_paths
                .iter()
                .all(|&(_, shift)| shift.length_squared() < teleport);
        ws.anchors.clear();
        let mut slack = 1.0;
        if tethered {
            if self.tethers {
                slack = tethers::slack(model, params.gravity, k[SpringKind::Stretch as usize]);
            }
            // The skin's tethers where they are tighter (or the only ones).
            slack = if self.tethers {
                slack.min(skin_tethers)
            } else {
                skin_tethers
            };
            ws.anchors.extend(ws.pin_paths.iter().map(|&(end, _)| end));
        }
        // A cloth far outside its tethers' reach (its pins teleported away)
        // is not pulled back in one substep: the springs drag it, as they
        // do for the other methods.
        let reach = TELEPORT * model.size();
        let tethered = tethered
            && ws.tethers.ties[..n]
                .iter()
                .zip(&x[..])
                .all(|(&(place, rest), x)| {
                    !rest.is_finite()
                        || x.distance(ws.anchors[place as usize]) <= rest * slack + reach
                });
        let ties = if tethered { &ws.tethers.ties[..n] } else { &[] };
        let plain = contacts.is_empty() && !tethered && skin.is_none();
        let fall = h * gravity;
        let pass = |x: &mut [Vec3A],
                    v: &mut [Vec3A],
                    prev: &mut [[Vec3A; 2]],
                    (anchors, skin_now, skin_normals): (&[Vec3A], &[Vec3A], &[Vec3A]),
                    solids: Solids<'_>,
                    near: &mut Near,
                    end: bool,
                    begin: bool| {
            if end && !plain && !(contacts.is_empty() && skin.is_none()) {
                // The tethers and the skin hold each vertex first; then the
                // solids' quick tests run over the whole cloth at once
                // (`Near`). A vertex's steps read and write its own
                // values only, so their order across vertices changes
                // nothing.
                let holding = x.iter_mut().zip(pinned).enumerate();
                for (i, (x, _)) in holding.filter(|(_, (_, pinned))| !**pinned) {
                    if let Some(&(place, rest)) = ties.get(i) {
                        hold(x, anchors[place as usize], rest * slack);
                    }
                    if let Some(skin) = &skin {
                        skin.hold_with(i, skin_now[i], skin_normals[i], x);
                    }
                }
                if !solids.0.is_empty() {
                    near.update(x, solids.1);
                }
            }
            let vertices = x.iter_mut().zip(v.iter_mut()).zip(prev.iter_mut());
            let vertices = vertices.zip(pinned.iter());
            if plain {
                for (((x, v), p), &pinned) in vertices {
                    if !pinned {
                        plain_pass(x, v, p, [end, begin], [inv_h, damping, h], fall);
                    }
                }
                return 0;
            }
            if contacts.is_empty() && skin.is_none() {
                // Tethers only.
                for ((((x, v), p), &pinned), &(place, rest)) in vertices.zip(ties) {
                    if !pinned {
                        if end {
                            hold(x, anchors[place as usize], rest * slack);
                        }
                        plain_pass(x, v, p, [end, begin], [inv_h, damping, h], fall);
                    }
                }
                return 0;
            }
            let mut touching = 0;
            for (i, (((x, v), p), &pinned)) in vertices.enumerate() {
                if pinned {
                    continue;
                }
                if end && !solids.0.is_empty() {
                    touching += u32::from(project_near(x, p[0], solids, near.mask(i)));
                }
                plain_pass(x, v, p, [end, begin], [inv_h, damping, h], fall);
            }
            touching
        };
        // Self-collision's pairs, once per step from where the cloth is and
        // where its velocities take it (before the first prediction), each
        // box grown by the step's fall. (Half of it, enough for gravity
        // alone, missed pairs of a sheet yanked by a thrown ball: the drape
        // scene tangled.)
        if let Some(sc) = self_collision {
            ws.self_contacts
                .find(model, x, v, params.dt as f32, sc, params.fall());
        }
        pass(
            x,
            v,
            prev,
            (&[], &[], &[]),
            (&[], &[], &[]),
            &mut ws.near,
            false,
            true,
        );
        // Chains of stretch springs solved whole before each sweep.
        let chain_compliance = if self.chains {
            ws.chains.update(model);
            ws.inv_mass.clear();
            ws.inv_mass.extend(
                model.masses().iter().zip(pinned).map(
                    |(&m, &pinned)| {
                        if pinned { 0.0 } else { 1.0 / m }
                    },
                ),
            );
            (1.0 / (f64::from(h) * f64::from(h) * f64::from(k[SpringKind::Stretch as usize])))
                as f32
        } else {
            0.0
        };
        let springs = ColouredSprings::new(
            &ws.links.ends,
            &ws.links.rest,
            &ws.links.shares,
            &ws.colouring.colours,
            n,
        );
        let (mut contacts_held, mut self_held) = (0, 0);
        for substep in 1..=substeps {
            if moving {
                // Where the pins are at this substep's end.
                let behind = 1.0 - substep as f32 / substeps as f32;
                for (&p, &(end, shift)) in pins.iter().zip(&ws.pin_paths) {
                    x[p as usize] = end - shift * behind;
                }
                for (anchor, &p) in ws.anchors.iter_mut().zip(pins) {
                    *anchor = x[p as usize];
                }
            }
            if let (Some(s), Some(start)) = (skin, skin_start) {
                let t = substep as f32 / substeps as f32;
                // The pins' teleport threshold, taken above.
                for ((now, &end), &start) in ws.skin_now.iter_mut().zip(s.positions).zip(start) {
                    *now = if end.distance_squared(start) < teleport {
                        start + (end - start) * t
                    } else {
                        end
                    };
                }
            }
            if self.chains {
                ws.chains
                    .solve(params.simd, x, &ws.inv_mass, chain_compliance);
            }
            sweep(params.simd, springs, x);
            if self_collision.is_some() {
                let progress = [substep - 1, substep].map(|k| k as f32 / substeps as f32);
                self_held = ws
                    .self_contacts
                    .resolve_substep(model, x, |i| prev[i][0], progress);
            }
            // Boxes (and smooth solids, with self-collision) push the
            // cloth's edges too, here
            // where the springs answer in the next sweep (after the step, a
            // taut edge over a box's edge would be pushed out and pulled
            // back in every step).
            if sweeping {
                let behind = 1.0 - substep as f32 / substeps as f32;
                for ((now, end), (motion, b)) in ws
                    .moving
                    .iter_mut()
                    .zip(contacts)
                    .zip(ws.motion.iter().zip(&mut ws.bounds))
                {
                    if *motion != Vec3A::ZERO {
                        *now = end.translated(-behind * *motion);
                        *b = Bound::of(now);
                    }
                }
            }
            let mut edges_held = 0;
            for (shape, edges) in ws.moving[..projected].iter().zip(&ws.edges) {
                edges_held += edge_pass_over(model, x, None, shape, edges.iter().copied()) as u32;
            }
            contacts_held = edges_held
                + pass(
                    x,
                    v,
                    prev,
                    (&ws.anchors, &ws.skin_now, &ws.skin_normals),
                    (&ws.moving, &ws.bounds, &ws.shift),
                    &mut ws.near,
                    true,
                    substep < substeps,
                );
        }
        // Edges that went through the cloth's own triangles anyway are
        // taken back out (the pairs' pushes would hold them there).
        if let Some(sc) = self_collision {
            let through = untangle(model, x, &mut ws.untangle, sc.setting.thickness);
            if through > 0 && self.chains {
                // The cloth settles after the moved vertices, positions
                // only, with its pairs found again where they now are
                // (see [`SETTLE_PASSES`]).
                ws.self_contacts
                    .find(model, x, v, params.dt as f32, sc, params.fall());
                ws.shift.clear();
                ws.shift.resize(ws.solids.len(), Vec3A::ZERO);
                ws.bounds.clear();
                ws.bounds.extend(ws.solids.iter().map(Bound::of));
                let solids = (&ws.solids[..], &ws.bounds[..], &ws.shift[..]);
                for _ in 0..SETTLE_PASSES {
                    for (start, &x) in prev.iter_mut().zip(x.iter()) {
                        start[0] = x;
                    }
                    ws.chains
                        .pull(params.simd, x, &ws.inv_mass, chain_compliance);
                    ws.self_contacts
                        .resolve_substep(model, x, |i| prev[i][0], [0.0, 0.0]);
                    for ((x, start), &pinned) in x.iter_mut().zip(prev.iter()).zip(pinned) {
                        if !pinned {
                            project(x, start[0], solids);
                        }
                    }
                }
            }
        }
        Ok(StepReport {
            iterations: substeps,
            residual: None,
            relative_error: None,
            contacts: contacts_held,
            self_contacts: self_collision.map(|_| self_held),
            substeps,
        })
    }
}

/// Passes over the cloth, positions only, after `stiff`'s untangling
/// moved vertices of a cloth with chains. The untangling moves an edge's
/// end by up to the thickness and more, and its rings follow only so far
/// ([`Follow`](crate::collision::self_contact::Follow)); the next step's chains
/// then took the stretch left around the moved vertices back in their
/// first substep, all at once, as velocity: on the 48² drape with chains,
/// a vertex of a sheet at rest moved 2.1 cm and its neighbours were thrown
/// up at up to 8.7 m/s the step after. Each pass instead pulls the chains
/// (a compressed spring's violation taken as zero), resolves the
/// self-collision's pairs, found again after the moves so that they hold
/// the moved ends on their new side, each kept no closer than it is
/// (progress `[0, 0]`: no parting allowance), and projects the cloth out of
/// the solids; velocities are left as they were. Not in them, each tried
/// on the 48² drape's first fold and worse: the whole chain solve (its
/// linearised push on springs the move had squeezed to 0.4 of their length
/// stretched their neighbours from 2 % to 21 %), the sweep (without
/// inertia, the bending springs across the fold pulled the stretch from 2 %
/// to 19 %), and the substeps' parting allowance (taken in every pass, 2 %
/// to 9 %). A character cloth's skin constraints are not in them either:
/// the next step's substeps hold them again.
const SETTLE_PASSES: usize = 8;

/// One free vertex's pass without forces but gravity (`fall = h·g`): ends
/// the substep and begins the next. The velocity at the end is the
/// predicted one plus the substep's corrections over `h`,
/// `v ← v + (x − x_predicted)/h`, which is `(x − x_start)/h` in exact
/// arithmetic; in `f32` a difference of positions far from the origin
/// loses the substep's motion to the positions' rounding, while the
/// corrections are small numbers of their own.
#[inline(always)]
fn plain_pass(
    x: &mut Vec3A,
    v: &mut Vec3A,
    [start, predicted]: &mut [Vec3A; 2],
    [end, begin]: [bool; 2],
    [inv_h, damping, h]: [f32; 3],
    fall: Vec3A,
) {
    if end {
        *v += (*x - *predicted) * inv_h;
    }
    if begin {
        *v = *v * damping + fall;
        *start = *x;
        *x += h * *v;
        *predicted = *x;
    }
}

/// Whether the cloth's swept box over the step (its positions and where
/// its velocities take them in `dt`, grown by the fall `|g| dt²` and a
/// hundredth of its size) comes within reach of any of `solids`: the box
/// against a plane, or against a sphere around the solid ([`Bound`]).
fn near_any(
    x: &[Vec3A],
    v: &[Vec3A],
    params: &super::StepParams,
    solids: impl Iterator<Item = Shape>,
) -> bool {
    if x.is_empty() {
        return false;
    }
    let dt = params.dt as f32;
    let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
    for (&x, &v) in x.iter().zip(v) {
        let end = x + dt * v;
        lo = lo.min(x).min(end);
        hi = hi.max(x).max(end);
    }
    let margin = params.fall() + 0.01 * (hi - lo).max_element();
    if !margin.is_finite() {
        return true;
    }
    let (lo, hi) = (lo - margin, hi + margin);
    solids
        .into_iter()
        .any(|shape| match (shape, Bound::of(&shape).sphere()) {
            (Shape::Plane(p), _) => {
                // The box's corner deepest along the inward normal.
                let deepest = Vec3A::select(p.normal.cmplt(Vec3A::ZERO), hi, lo);
                (deepest - p.point).dot(p.normal) <= 0.0
            }
            (_, Some((centre, r2))) => centre.clamp(lo, hi).distance_squared(centre) <= r2,
            (_, None) => true,
        })
}

/// Scratch buffers of the XPBD solver, sized on first use.
#[derive(Clone, Debug, Default)]
pub struct XpbdWorkspace {
    /// The springs in colour order (taken once per topology).
    colouring: Colouring,
    /// Per spring in colour order: ends, rest length and shares (taken again
    /// when the cloth, its stiffness or the substep change).
    links: Links,
    /// Per vertex, its position at the substep's start and its predicted
    /// position.
    previous: Vec<[Vec3A; 2]>,
    /// The step's contacts and penalty colliders, projected alike (where
    /// they are at the step's end).
    solids: Vec<Shape>,
    /// Each solid's motion over the step (zero for a static one).
    motion: Vec<Vec3A>,
    /// The solids where they are in the current substep.
    moving: Vec<Shape>,
    /// Each solid's motion over one substep.
    shift: Vec<Vec3A>,
    /// Per projected solid, the cloth's edges it may meet this step.
    edges: Vec<Vec<u32>>,
    /// Per solid, its quick test ([`Bound`]).
    bounds: Vec<Bound>,
    /// The solids' quick tests over the whole cloth, each substep.
    near: Near,
    /// Each vertex's nearest pin and rest distance (taken once per topology
    /// and pins).
    tethers: Tethers,
    /// The pins' positions at the current substep (the tethers' anchors);
    /// empty without tethers.
    anchors: Vec<Vec3A>,
    /// Per pin: its position at the step's end and its motion over the step.
    pin_paths: Vec<(Vec3A, Vec3A)>,
    /// A character cloth's skinned positions at the current substep.
    skin_now: Vec<Vec3A>,
    /// Its unit normals, made once per step.
    skin_normals: Vec<Vec3A>,
    /// Self-collision's pairs for the step.
    self_contacts: SelfContacts,
    /// Self-collision's check for edges through the cloth after the step.
    untangle: IntersectionCheck,
    /// The chains of stretch springs (taken once per topology).
    chains: chains::Chains,
    /// Per vertex: its inverse mass, 0 at a pin (with chains).
    inv_mass: Vec<f32>,
}

impl XpbdWorkspace {
    /// The number of spring colours of the last cloth stepped.
    pub fn colours(&self) -> usize {
        self.colouring.count()
    }
}
