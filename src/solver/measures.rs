//! Measures of a state: the implicit-Euler objective and its gradient,
//! energy, stretch, and the per-step error against a reference.

use bevy::math::{Vec3A, Vec4};

use super::params::{SpringStiffness, StepParams};
use crate::model::{ClothModel, ClothState};
use crate::solver::engine::kernels::{for_chunks, spring_groups};
use crate::solver::springs::{spring_terms, stiffness_coeffs};

/// The gradient of the implicit-Euler objective (the lab's equation 1),
/// `g = M(x − x̃)/dt² − f(x)` with spring and gravity forces, into `out`.
/// Pinned vertices get zero. `terms` is scratch of one entry per spring.
/// Large cloths are done in parallel chunks (see [`PARALLEL_MIN`](super::PARALLEL_MIN)), with
/// bitwise the same result.
pub fn gradient(
    model: &ClothModel,
    x: &[Vec3A],
    x_tilde: &[Vec3A],
    params: &StepParams,
    terms: &mut [Vec3A],
    out: &mut [Vec3A],
) {
    let mut coeffs = Vec::new();
    stiffness_coeffs(model, &params.stiffness, &mut coeffs);
    spring_terms(params, model, x, &coeffs, terms);
    let terms = &*terms;
    let dt = params.dt as f32;
    let inv_dt2 = 1.0 / (dt * dt);
    let gravity = Vec3A::from(params.gravity);
    let adjacency = model.topology().adjacency();
    let masses = model.masses();
    let pinned = model.pinned();
    for_chunks(params.parallel, out, |start, out| {
        for (j, g) in out.iter_mut().enumerate() {
            let i = start + j;
            if pinned[i] {
                *g = Vec3A::ZERO;
                continue;
            }
            let m = masses[i];
            let mut acc = (x[i] - x_tilde[i]) * (m * inv_dt2) - gravity * m;
            for inc in adjacency.of(i) {
                acc += terms[inc.spring as usize] * inc.sign;
            }
            *g = acc;
        }
    });
}

/// A step's convergence measure, [`StepReport::relative_error`](super::StepReport::relative_error),
/// summed over the free vertices as a method's last pass visits them.
///
/// For each free vertex the method adds the estimated error of its result
/// `e_i` and the step's motion `x_i − x_i(start of step)`. The relative error
/// is `rms(e) / max(rms(motion), 0.01·size·dt / 1 s)`: the estimated distance
/// from the exact implicit-Euler solution per unit of motion, where a cloth
/// that hardly moves is measured against a floor of 1 % of its size per
/// second (the stability map's own floor).
///
/// The estimate is `e_i = dt²/m_i · g_i`, `g` the objective's gradient at
/// the method's final iterate: since the Hessian is at least `M/dt²` (with
/// compressed springs' negative stiffness left out), `‖H⁻¹g‖` is at most
/// this, and it is close for the smooth, slowly converging error that makes
/// a stiff cloth "lock". It overestimates a rough residual, which stiff
/// springs correct by themselves. (Projective dynamics' own matrix, `P⁻¹g`,
/// was tried and underestimates: `P` is stiff across springs where the true
/// Hessian is soft, so it missed every wrong cell of the map.)
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ConvergenceSums {
    error: f64,
    motion: f64,
    count: usize,
}

impl ConvergenceSums {
    /// Adds one free vertex: its estimated error and its motion over the step.
    #[inline]
    pub fn add(&mut self, error: Vec3A, motion: Vec3A) {
        self.error += f64::from(error.length_squared());
        self.motion += f64::from(motion.length_squared());
        self.count += 1;
    }

    /// Adds one free vertex in `f64`.
    #[inline]
    pub fn add_f64(&mut self, error: bevy::math::DVec3, motion: bevy::math::DVec3) {
        self.error += error.length_squared();
        self.motion += motion.length_squared();
        self.count += 1;
    }

    /// From sums made elsewhere: the squared errors and motions of `count`
    /// free vertices.
    pub(crate) fn from_parts(error: f64, motion: f64, count: usize) -> Self {
        Self {
            error,
            motion,
            count,
        }
    }

    /// The relative error of a step of `dt` seconds of `model` (0 for a
    /// cloth without free vertices).
    pub fn relative_error(&self, model: &ClothModel, dt: f64) -> f32 {
        if self.count == 0 {
            return 0.0;
        }
        let n = self.count as f64;
        let floor = 0.01 * f64::from(model.size()) * dt;
        let motion = (self.motion / n).sqrt().max(floor);
        let error = (self.error / n).sqrt();
        if motion > 0.0 {
            (error / motion) as f32
        } else if error > 0.0 {
            f32::INFINITY
        } else {
            0.0
        }
    }
}

/// A step's [`relative_error`](super::StepReport::relative_error) measured
/// after a collider's projection moved some of its vertices: the error the
/// projection does not undo.
///
/// A cloth resting on a collider is held by forces the implicit-Euler
/// objective does not contain: the solve falls into the collider and the
/// projection puts the vertices back. An iterative method stops short of
/// the exact solve's fall, and [`ConvergenceSums`] counts all of that
/// shortfall, though the projection would have undone it as well. Here each
/// vertex's estimated error `e = dt²/m·g` (the gradient `g` at the method's
/// result, as the iterative methods estimate it) is compared with where the
/// projection moved the vertex: along the push's direction `n` (depth `d`),
/// the exact solve's estimated position `x − e` would be projected to the
/// same place unless it lies outside the solid, so only `max(−e·n − d, 0)` of
/// that component remains; the component across the push remains whole
/// (friction, which would hold part of it, is not counted). A vertex the
/// projection did not move keeps its error whole. Motion and the floor are
/// as in [`ConvergenceSums`].
///
/// Scratch is kept between calls (no allocation once sized).
#[derive(Clone, Debug, Default)]
pub struct ContactError {
    x_tilde: Vec<Vec3A>,
    terms: Vec<Vec3A>,
    grad: Vec<Vec3A>,
}

impl ContactError {
    /// Whether a step is measured again after the projection: one step of
    /// the whole `dt` (`single`: no halvings by the guard) whose own
    /// relative error exceeds `tolerance`. A step within it is not flagged
    /// whatever the projection does, and a halved step's error is not
    /// measured against one projection.
    pub fn applies(error: Option<f32>, single: bool, tolerance: f32) -> bool {
        single && error.is_some_and(|e| e > tolerance)
    }

    /// The relative error of the step from `start` (the state before it,
    /// velocities undamped) to `solved` (the method's positions), after a
    /// projection moved them to `projected`. 0 for a cloth without free
    /// vertices; `None` if the three do not have one entry per vertex of
    /// `model`.
    pub fn relative_error(
        &mut self,
        model: &ClothModel,
        start: &ClothState,
        solved: &[Vec3A],
        projected: &[Vec3A],
        params: &StepParams,
    ) -> Option<f32> {
        let n = model.vertex_count();
        if start.len() != n || solved.len() != n || projected.len() != n {
            return None;
        }
        let dt = params.dt as f32;
        let damping = params.damping;
        self.x_tilde.clear();
        self.x_tilde.extend(
            start
                .positions
                .iter()
                .zip(&start.velocities)
                .map(|(&x, &v)| x + dt * damping * v),
        );
        self.terms
            .resize(model.topology().springs().len(), Vec3A::ZERO);
        self.grad.resize(n, Vec3A::ZERO);
        gradient(
            model,
            solved,
            &self.x_tilde,
            params,
            &mut self.terms,
            &mut self.grad,
        );
        let mut sums = ConvergenceSums::default();
        let moved = solved.iter().zip(projected).zip(&start.positions);
        for (i, ((&x, &p), &x0)) in moved.enumerate() {
            if model.pinned()[i] {
                continue;
            }
            let mut e = self.grad[i] * (dt * dt / model.masses()[i]);
            let push = p - x;
            let depth = push.length();
            if depth > 0.0 {
                let normal = push / depth;
                let along = e.dot(normal);
                e += normal * ((-along - depth).max(0.0) - along);
            }
            sums.add(e, x - x0);
        }
        Some(sums.relative_error(model, params.dt))
    }
}

/// The plugin's convergence rule for one step across the colliders'
/// projection after it, in one place for the plugin and the report.
///
/// [`stepped`](Self::stepped) records the step's own
/// [`relative_error`](super::StepReport::relative_error) and whether it may
/// be measured again ([`ContactError::applies`]);
/// [`before_projection`](Self::before_projection), called by each
/// projection before it moves the vertices, keeps where the step left them
/// (the first only); [`settle`](Self::settle) gives the step's judged error:
/// measured again without what the projection undid ([`ContactError`]) if a
/// projection moved vertices, else the step's own. A cloth resting on a
/// collider is held by forces the solve does not see.
///
/// Scratch is kept between steps (no allocation once sized).
#[derive(Clone, Debug, Default)]
pub struct ProjectedConvergence {
    /// `Some` after a step: its own relative error, if it has one.
    step: Option<Option<f32>>,
    /// The step may be measured again.
    remeasure: bool,
    /// The positions before the first projection, if one ran since.
    solved: Vec<Vec3A>,
    /// Whether `solved` holds this step's positions.
    kept: bool,
    /// Scratch of the measure.
    scratch: ContactError,
}

impl ProjectedConvergence {
    /// Records a step's own relative error (`error`), whether it was one
    /// step of the whole `dt` (`single`: no halvings by the guard), and the
    /// tolerance it is judged against.
    pub fn stepped(&mut self, error: Option<f32>, single: bool, tolerance: f32) {
        self.step = Some(error);
        self.remeasure = ContactError::applies(error, single, tolerance);
        self.kept = false;
    }

    /// Called by each projection before it moves the vertices (at
    /// `positions`): the first after a step that may be measured again
    /// keeps them.
    pub fn before_projection(&mut self, positions: &[Vec3A]) {
        if self.remeasure && !self.kept {
            self.solved.clear();
            self.solved.extend_from_slice(positions);
            self.kept = true;
        }
    }

    /// The recorded step's judged relative error, the step having started
    /// from `start` (velocities undamped) and the projections having left
    /// the vertices at `projected`: `None` if no step was recorded since the
    /// last call, `Some(None)` for a step without a measure of its own.
    pub fn settle(
        &mut self,
        model: &ClothModel,
        start: &ClothState,
        projected: &[Vec3A],
        params: &StepParams,
    ) -> Option<Option<f32>> {
        let mut error = self.step.take()?;
        if self.remeasure && self.kept && self.solved != projected {
            error = self
                .scratch
                .relative_error(model, start, &self.solved, projected, params)
                .or(error);
        }
        self.remeasure = false;
        self.kept = false;
        Some(error)
    }
}

/// The implicit-Euler objective whose minimiser is the next position:
/// `Σ m/(2dt²)‖x − x̃‖² + Σ_springs ½k(l − L)² − Σ m g·x`, in `f64`.
/// Its gradient is [`gradient`].
pub fn objective(model: &ClothModel, x: &[Vec3A], x_tilde: &[Vec3A], params: &StepParams) -> f64 {
    let inv_dt2 = 1.0 / (params.dt * params.dt);
    let mut e = 0.0;
    for (i, &m) in model.masses().iter().enumerate() {
        let m = f64::from(m);
        let d = x[i].as_dvec3() - x_tilde[i].as_dvec3();
        e += 0.5 * m * inv_dt2 * d.length_squared()
            - m * params.gravity.as_dvec3().dot(x[i].as_dvec3());
    }
    e + spring_energy(model, x, &params.stiffness)
}

fn spring_energy(model: &ClothModel, x: &[Vec3A], stiffness: &SpringStiffness) -> f64 {
    model
        .topology()
        .springs()
        .iter()
        .map(|s| {
            let l = (x[s.a as usize].as_dvec3() - x[s.b as usize].as_dvec3()).length();
            let stretch = l - f64::from(s.rest_length);
            0.5 * f64::from(stiffness.of(s.kind)) * stretch * stretch
        })
        .sum()
}

/// Total mechanical energy (kinetic + spring + gravitational, with `y = 0`
/// as zero height along gravity), summed in `f64` (see [`measure`], which
/// computes it with the largest stretch in the same passes); NaN if the
/// state is not finite.
pub fn energy(model: &ClothModel, state: &ClothState, params: &StepParams) -> f64 {
    measure(model, state, params).map_or(f64::NAN, |m| m.energy)
}

/// What [`measure`] finds in a state: what the divergence guard checks and
/// [`ClothStats`](crate::ecs::ClothStats) reports.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measured {
    /// Largest relative elongation `(l − L)/L` over all springs (as
    /// [`max_stretch`]; `−∞` for a cloth without springs).
    pub max_stretch: f32,
    /// Total mechanical energy (as [`energy`]).
    pub energy: f64,
    /// Largest speed of a free vertex (0 for a cloth without free vertices).
    pub max_free_speed: f32,
    /// Largest speed of a pinned vertex (0 for a cloth without pins): how
    /// fast whatever holds the cloth moves it.
    pub max_pin_speed: f32,
}

/// The largest stretch and the total energy of `state` in one pass over its
/// vertices and one over its springs, or `None` if a position or velocity
/// is NaN or infinite (or a spring of zero rest length has zero length).
///
/// The spring pass shares `spring_groups`' packed lengths: each spring's
/// `l − L`, stretch and energy `½k(l − L)²` are computed four at a time in
/// `f32` and summed in `f64`, in one pass instead of separate `f64`
/// passes for the stretch and the energy.
pub fn measure(model: &ClothModel, state: &ClothState, params: &StepParams) -> Option<Measured> {
    let g = params.gravity.as_dvec3();
    let mut finite = true;
    let mut energy = 0.0f64;
    let (mut free_speed, mut pin_speed) = (0.0f32, 0.0f32);
    for (((&m, x), v), &pinned) in model
        .masses()
        .iter()
        .zip(&state.positions)
        .zip(&state.velocities)
        .zip(model.pinned())
    {
        finite &= x.is_finite() & v.is_finite();
        let speed = v.length_squared();
        if pinned {
            pin_speed = pin_speed.max(speed);
        } else {
            free_speed = free_speed.max(speed);
        }
        let m = f64::from(m);
        energy += 0.5 * m * v.as_dvec3().length_squared() - m * g.dot(x.as_dvec3());
    }
    if !finite || state.positions.len() != model.vertex_count() {
        return None;
    }
    let (worst, nan, springs) =
        spring_measures(model, &state.positions, params.stiffness.as_array());
    energy += springs;
    (!nan).then_some(Measured {
        max_stretch: worst,
        energy,
        max_free_speed: free_speed.sqrt(),
        max_pin_speed: pin_speed.sqrt(),
    })
}

/// Over the springs at positions `x`: the largest stretch `(l − L)/L`, whether
/// one was NaN, and the spring energy `Σ ½k(l − L)²` with `k` per spring kind.
fn spring_measures(model: &ClothModel, x: &[Vec3A], k: [f32; 3]) -> (f32, bool, f64) {
    let springs = model.topology().springs();
    let mut worst = Vec4::NEG_INFINITY;
    let mut nan = false;
    let mut energy = 0.0f64;
    spring_groups(springs, x, |e, _, l2| {
        let s = &springs[e..e + 4];
        let rest = Vec4::new(
            s[0].rest_length,
            s[1].rest_length,
            s[2].rest_length,
            s[3].rest_length,
        );
        let stiffness = Vec4::new(
            k[s[0].kind as usize],
            k[s[1].kind as usize],
            k[s[2].kind as usize],
            k[s[3].kind as usize],
        );
        let stretch = l2.sqrt() - rest;
        let ratio = stretch / rest;
        nan |= ratio.is_nan_mask().any();
        worst = worst.max(ratio);
        let e = 0.5 * stiffness * stretch * stretch;
        energy += (f64::from(e.x) + f64::from(e.y)) + (f64::from(e.z) + f64::from(e.w));
    });
    let mut worst = worst.max_element();
    for s in &springs[springs.len() / 4 * 4..] {
        let d = x[s.a as usize] - x[s.b as usize];
        let stretch = d.length() - s.rest_length;
        let ratio = stretch / s.rest_length;
        nan |= ratio.is_nan();
        worst = worst.max(ratio);
        energy += f64::from(0.5 * k[s.kind as usize] * stretch * stretch);
    }
    (worst, nan, energy)
}

/// The per-step error of a method against the exact step from the same
/// state: `‖x_K − x*‖ / ‖x* − x_0‖`, with `x_K` the method's positions,
/// `x*` the exact step's and `x_0` the positions before the step (norms over
/// all vertices, in `f64`). 0 is exact; 1 means the method moved no closer
/// to `x*` than staying put.
pub fn step_error(method: &[Vec3A], exact: &[Vec3A], before: &[Vec3A]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for ((m, e), b) in method.iter().zip(exact).zip(before) {
        num += (m.as_dvec3() - e.as_dvec3()).length_squared();
        den += (e.as_dvec3() - b.as_dvec3()).length_squared();
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else {
        num.sqrt()
    }
}

/// Largest relative elongation `(l − L)/L` over all springs (0 at rest, 0.1
/// when some spring is 10 % longer than at rest). NaN if a position is.
/// Computed as [`measure`] computes it (four springs at a time), so the two
/// agree bit for bit.
pub fn max_stretch(model: &ClothModel, x: &[Vec3A]) -> f32 {
    let (worst, nan, _) = spring_measures(model, x, [0.0; 3]);
    if nan { f32::NAN } else { worst }
}
