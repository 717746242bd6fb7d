//! Pure numerics: one file per method, one entry point each. No ECS types.
//!
//! Every method advances a [`ClothState`] by one time step of a
//! [`ClothModel`] under [`StepParams`], using a method-specific workspace that
//! is allocated on the first step and reused afterwards (no allocation per
//! step once the sizes are known).
//!
//! | method | entry point | the lab's name |
//! |---|---|---|
//! | implicit Euler, diagonal-Hessian Newton (Jacobi), optional Chebyshev | [`implicit::step`] | part 1 |
//! | position-based dynamics, Jacobi strain limiting | [`pbd::step`] | part 2 |
//! | symplectic Euler (`A = M`) | [`symplectic::step`] | the assignment's first stage |
//! | linearly implicit Euler (`A = M − h²K`), sparse CG or LDLᵀ | [`linear::step`] | the assignment |
//! | exact implicit Euler: Newton + sparse Cholesky + line search | [`exact::step`] | the reference |
//!
//! Penalty spheres ([`PenaltySphere`](crate::collision::PenaltySphere)) act
//! inside every step: as forces with their stiffness in the linear system
//! (linearly implicit), in the gradient and diagonal (implicit Jacobi), or
//! as explicit forces (symplectic, and PBD's velocity prediction).
//!
//! The divergence guard ([`guard`]) checks a step and retries it with
//! halved time steps when it fails.
//!
//! Shared measures — [`objective`], [`gradient`], [`max_stretch`],
//! [`energy`] — are here.

pub mod any;
pub mod exact;
pub mod guard;
pub mod implicit;
pub mod linear;
pub mod pbd;
pub mod symplectic;

use bevy::math::{Mat4, Vec3, Vec3A, Vec4};
use thiserror::Error;

use crate::model::{ClothModel, ClothState, ParamError, Spring, SpringKind};

/// Stiffness of each [`SpringKind`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpringStiffness {
    /// Stiffness of stretch springs (triangle edges).
    pub stretch: f32,
    /// Stiffness of shear (diagonal) springs.
    pub shear: f32,
    /// Stiffness of bending (skip-one) springs.
    pub bend: f32,
}

impl SpringStiffness {
    /// The same stiffness for every kind.
    pub const fn uniform(k: f32) -> Self {
        Self {
            stretch: k,
            shear: k,
            bend: k,
        }
    }

    /// The stiffness of one kind.
    #[inline]
    pub fn of(&self, kind: SpringKind) -> f32 {
        match kind {
            SpringKind::Stretch => self.stretch,
            SpringKind::Shear => self.shear,
            SpringKind::Bend => self.bend,
        }
    }

    /// Per-kind values as an array indexed by `SpringKind as usize`.
    #[inline]
    pub fn as_array(&self) -> [f32; 3] {
        [self.stretch, self.shear, self.bend]
    }
}

impl Default for SpringStiffness {
    /// The lab's `k = 8000` for every kind.
    fn default() -> Self {
        Self::uniform(8000.0)
    }
}

/// Physical parameters of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepParams {
    /// Time step in seconds (`f64`, as `Time` keeps it: the assembled
    /// systems use it exactly; the `f32` loops round it once).
    pub dt: f64,
    /// Spring stiffness per kind.
    pub stiffness: SpringStiffness,
    /// Velocity multiplier applied at the start of each step (the lab: 0.99).
    pub damping: f32,
    /// Gravitational acceleration.
    pub gravity: Vec3,
}

impl StepParams {
    /// The lab's parameters: `dt = 0.0333`, `k = 8000`, damping 0.99,
    /// gravity `(0, −9.8, 0)`.
    pub const LAB: Self = Self {
        dt: 0.0333,
        stiffness: SpringStiffness::uniform(8000.0),
        damping: 0.99,
        gravity: Vec3::new(0.0, -9.8, 0.0),
    };

    /// Checks every parameter; a solver calls this before it touches state.
    pub fn validate(&self) -> Result<(), ParamError> {
        if !(self.dt.is_finite() && self.dt > 0.0 && (self.dt as f32) > 0.0) {
            return Err(ParamError::TimeStep(self.dt));
        }
        for k in self.stiffness.as_array() {
            if !(k.is_finite() && k > 0.0) {
                return Err(ParamError::Stiffness(k));
            }
        }
        if !(0.0..=1.0).contains(&self.damping) {
            return Err(ParamError::Damping(self.damping));
        }
        if !self.gravity.is_finite() {
            return Err(ParamError::Gravity);
        }
        Ok(())
    }
}

impl Default for StepParams {
    fn default() -> Self {
        Self::LAB
    }
}

/// Why a step was refused. The state is left untouched.
#[derive(Error, Debug, Clone, Copy, PartialEq)]
pub enum StepError {
    /// A parameter is invalid.
    #[error(transparent)]
    Params(#[from] ParamError),
    /// The linear solve failed; see [`SolveError`].
    #[error(transparent)]
    Solve(#[from] SolveError),
    /// The state does not have one position and velocity per vertex.
    #[error("state has {got} vertices, the model {expected}")]
    StateMismatch {
        /// Vertices in the model.
        expected: usize,
        /// Positions or velocities in the state.
        got: usize,
    },
}

/// Why a linear solve failed. The state is left untouched.
#[derive(Error, Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveError {
    /// Conjugate gradients met a direction of non-positive curvature: `A` is
    /// not positive definite (compressed springs under the exact spring
    /// Jacobian, or an exact penalty Jacobian).
    #[error("the system matrix is not positive definite")]
    NotPositiveDefinite,
    /// The sparse factorisation failed or produced a non-finite solution.
    #[error("the sparse factorisation failed")]
    Factorization,
}

/// What a step reports about its solve.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepReport {
    /// Iterations performed.
    pub iterations: u32,
    /// The method's own convergence measure, if it has one: the Euclidean
    /// norm of the objective's gradient over free vertices for the implicit
    /// solver.
    pub residual: Option<f32>,
}

pub(crate) fn check_state(model: &ClothModel, state: &ClothState) -> Result<(), StepError> {
    let expected = model.vertex_count();
    for got in [state.positions.len(), state.velocities.len()] {
        if got != expected {
            return Err(StepError::StateMismatch { expected, got });
        }
    }
    Ok(())
}

/// Vertices (or springs) per chunk of the chunked loops. Fixed, so that
/// reductions over chunks give the same bits whatever the thread count.
pub(crate) const CHUNK: usize = 4096;

/// Below this many elements the chunked loops run serially: a task per
/// chunk costs more than it saves.
pub const PARALLEL_MIN: usize = 32_768;

static PARALLEL: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(true);

/// Turns the parallel chunked loops on (the default) or off, process-wide.
/// Results are bitwise the same either way; this only trades speed for
/// threads.
pub fn set_parallel(enabled: bool) {
    PARALLEL.store(enabled, core::sync::atomic::Ordering::Relaxed);
}

fn parallel_pool(len: usize) -> Option<&'static bevy::tasks::ComputeTaskPool> {
    if len >= PARALLEL_MIN && PARALLEL.load(core::sync::atomic::Ordering::Relaxed) {
        bevy::tasks::ComputeTaskPool::try_get().filter(|p| p.thread_num() > 1)
    } else {
        None
    }
}

/// Runs `f(start, chunk)` over `CHUNK`-sized chunks of `data`, on Bevy's
/// `ComputeTaskPool` when `data` has at least [`PARALLEL_MIN`] elements and
/// the pool (set up by Bevy's `TaskPoolPlugin`) has more than one thread,
/// else serially. The chunks are the same either way, and each element is
/// written by exactly one call, so the result is bitwise the same.
pub(crate) fn for_chunks<T: Send>(data: &mut [T], f: impl Fn(usize, &mut [T]) + Send + Sync) {
    match parallel_pool(data.len()) {
        Some(pool) => {
            let f = &f;
            pool.scope(|scope| {
                for (i, chunk) in data.chunks_mut(CHUNK).enumerate() {
                    scope.spawn(async move { f(i * CHUNK, chunk) });
                }
            });
        }
        None => {
            for (i, chunk) in data.chunks_mut(CHUNK).enumerate() {
                f(i * CHUNK, chunk);
            }
        }
    }
}

/// [`for_chunks`] over two slices of the same length, chunked alike;
/// `f(start, a, b)` returns a value per chunk, written to `results[chunk]`
/// (so reductions can add them in chunk order).
pub(crate) fn for_chunks2<A: Send, B: Send, R: Send + Copy + Default>(
    a: &mut [A],
    b: &mut [B],
    results: &mut Vec<R>,
    f: impl Fn(usize, &mut [A], &mut [B]) -> R + Send + Sync,
) {
    let chunks = a.len().div_ceil(CHUNK);
    results.clear();
    results.resize(chunks, R::default());
    let pool = parallel_pool(a.len());
    let work = a
        .chunks_mut(CHUNK)
        .zip(b.chunks_mut(CHUNK))
        .zip(results.iter_mut())
        .enumerate();
    match pool {
        Some(pool) => {
            let f = &f;
            pool.scope(|scope| {
                for (i, ((a, b), r)) in work {
                    scope.spawn(async move {
                        *r = f(i * CHUNK, a, b);
                    });
                }
            });
        }
        None => {
            for (i, ((a, b), r)) in work {
                *r = f(i * CHUNK, a, b);
            }
        }
    }
}

/// For every spring `e = (a, b)` of `springs`, with `d = x_a − x_b` and
/// `l = ‖d‖`: calls `emit(e, d, α_e − β_e/l)` (`0` for a spring of zero
/// length, whose direction is undefined), with `[α_e, β_e] = coeffs[e]`.
///
/// Both spring-based pipelines have this form: the implicit gradient term is
/// `d·k(1 − L/l)` (`α = k`, `β = kL`), and PBD's half correction is
/// `d·L/(2l)` (`α = 0`, `β = −L/2`). `e` counts from 0 within `springs`.
///
/// Four springs at a time: their four `d` are transposed in registers
/// (glam's `Mat4`) into `x`, `y` and `z` lanes, so the squared lengths, the
/// square roots and the divisions are one packed SIMD instruction each for
/// the four (glam's `Vec4`: SSE2 on x86-64, NEON on aarch64). Per spring,
/// a horizontal dot product and a scalar `sqrtss` + `divss` bounded the
/// loop before; on the lab cloth this halves the spring pass (see
/// `docs/perf.md`).
#[inline]
pub(crate) fn spring_scales(
    springs: &[Spring],
    coeffs: &[[f32; 2]],
    x: &[Vec3A],
    mut emit: impl FnMut(usize, Vec3A, f32),
) {
    let groups = springs.chunks_exact(4).zip(coeffs.chunks_exact(4));
    let done = springs.len() / 4 * 4;
    for (g, (s, c)) in groups.enumerate() {
        let d = [
            x[s[0].a as usize] - x[s[0].b as usize],
            x[s[1].a as usize] - x[s[1].b as usize],
            x[s[2].a as usize] - x[s[2].b as usize],
            x[s[3].a as usize] - x[s[3].b as usize],
        ];
        let lanes = Mat4::from_cols(
            d[0].extend(0.0),
            d[1].extend(0.0),
            d[2].extend(0.0),
            d[3].extend(0.0),
        )
        .transpose();
        let l2 =
            lanes.x_axis * lanes.x_axis + lanes.y_axis * lanes.y_axis + lanes.z_axis * lanes.z_axis;
        let alpha = Vec4::new(c[0][0], c[1][0], c[2][0], c[3][0]);
        let beta = Vec4::new(c[0][1], c[1][1], c[2][1], c[3][1]);
        let scale = Vec4::select(l2.cmpgt(Vec4::ZERO), alpha - beta / l2.sqrt(), Vec4::ZERO);
        emit(4 * g, d[0], scale.x);
        emit(4 * g + 1, d[1], scale.y);
        emit(4 * g + 2, d[2], scale.z);
        emit(4 * g + 3, d[3], scale.w);
    }
    for (j, (s, [alpha, beta])) in springs[done..].iter().zip(&coeffs[done..]).enumerate() {
        let d = x[s.a as usize] - x[s.b as usize];
        let l2 = d.length_squared();
        let scale = if l2 > 0.0 {
            alpha - beta / l2.sqrt()
        } else {
            0.0
        };
        emit(done + j, d, scale);
    }
}

/// Per spring `[k, kL]`, the coefficients of the implicit gradient term
/// `d·k(1 − L/l)` for [`spring_scales`].
pub(crate) fn stiffness_coeffs(
    model: &ClothModel,
    stiffness: &SpringStiffness,
    out: &mut Vec<[f32; 2]>,
) {
    let k = stiffness.as_array();
    out.clear();
    out.extend(model.topology().springs().iter().map(|s| {
        let k = k[s.kind as usize];
        [k, k * s.rest_length]
    }));
}

/// Fills `terms[e]` with each spring's gradient term `k(1 − L/l)(x_a − x_b)`
/// at positions `x`, in parallel chunks for large cloths. `coeffs` is from
/// [`stiffness_coeffs`].
pub(crate) fn spring_terms(
    model: &ClothModel,
    x: &[Vec3A],
    coeffs: &[[f32; 2]],
    terms: &mut [Vec3A],
) {
    let springs = model.topology().springs();
    for_chunks(terms, |start, terms| {
        let end = start + terms.len();
        spring_scales(&springs[start..end], &coeffs[start..end], x, |e, d, s| {
            terms[e] = d * s;
        });
    });
}

/// The gradient of the implicit-Euler objective (the lab's equation 1),
/// `g = M(x − x̃)/dt² − f(x)` with spring and gravity forces, into `out`.
/// Pinned vertices get zero. `terms` is scratch of one entry per spring.
/// Large cloths are done in parallel chunks (see [`PARALLEL_MIN`]), with
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
    spring_terms(model, x, &coeffs, terms);
    let terms = &*terms;
    let dt = params.dt as f32;
    let inv_dt2 = 1.0 / (dt * dt);
    let gravity = Vec3A::from(params.gravity);
    let adjacency = model.topology().adjacency();
    let masses = model.masses();
    let pinned = model.pinned();
    for_chunks(out, |start, out| {
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
/// as zero height along gravity), in `f64`.
pub fn energy(model: &ClothModel, state: &ClothState, params: &StepParams) -> f64 {
    let g = params.gravity.as_dvec3();
    let mut e = 0.0;
    for (i, &m) in model.masses().iter().enumerate() {
        let m = f64::from(m);
        e += 0.5 * m * state.velocities[i].as_dvec3().length_squared()
            - m * g.dot(state.positions[i].as_dvec3());
    }
    e + spring_energy(model, &state.positions, &params.stiffness)
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
pub fn max_stretch(model: &ClothModel, x: &[Vec3A]) -> f32 {
    let mut worst = f32::NEG_INFINITY;
    for s in model.topology().springs() {
        let l = x[s.a as usize].distance(x[s.b as usize]);
        let r = (l - s.rest_length) / s.rest_length;
        if r.is_nan() {
            return f32::NAN;
        }
        worst = worst.max(r);
    }
    worst
}

#[cfg(test)]
mod tests;
