//! The parameters of a step, what a step reports, and why it can fail.

use bevy::math::Vec3;
use bevy::reflect::Reflect;
use bevy::reflect::std_traits::ReflectDefault;
use thiserror::Error;

pub use super::engine::cholesky::SolveError;
use crate::model::{ClothModel, ClothState, SpringKind};

/// Stiffness of each [`SpringKind`].
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Debug, PartialEq, Default)]
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

    /// Checks that every stiffness is finite and positive.
    pub fn validate(&self) -> Result<(), ParamError> {
        for k in self.as_array() {
            if !(k.is_finite() && k > 0.0) {
                return Err(ParamError::Stiffness(k));
            }
        }
        Ok(())
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
    /// Whether a large cloth (at least [`PARALLEL_MIN`](super::PARALLEL_MIN)
    /// springs or vertices) may split its loops over Bevy's compute pool.
    /// Results are bitwise the same either way; this only trades speed for
    /// threads (default `true`).
    pub parallel: bool,
    /// The SIMD instruction set of the spring pass, and of both passes of
    /// the stencil kernels (default [`Simd::Auto`](super::engine::simd::Simd::Auto): the
    /// fastest this CPU has). Every choice gives the same bits; this only
    /// trades speed.
    pub simd: super::engine::simd::Simd,
    /// Whether a cloth whose springs form a stencil (a grid numbered row by
    /// row, as every builder's) runs the implicit iteration's, PBD's,
    /// symplectic Euler's and projective dynamics' local step's
    /// structure-of-arrays kernels (default `true`; about 2× faster on the
    /// lab cloth and 2.5× at 256²: see `docs/perf.md`). They agree with the general
    /// kernels within `f32` rounding, not bitwise: a vertex sums its
    /// springs in another order (and PBD adds the step's move to the
    /// velocity once, not per iteration). `false` runs the general
    /// kernels, for comparison (the report's and the tests'; hidden from
    /// the docs, as the engine room is).
    #[doc(hidden)]
    pub stencil: bool,
    /// How fast the fastest collider moved over this step (its
    /// displacement since the last step over `dt`; 0 for none or unknown):
    /// what a collider can give the cloth, for the guard's speed bound
    /// ([`GuardBounds::speed_bound`](super::guard::GuardBounds::speed_bound)).
    /// The plugin sets it from [`ClothColliders`](crate::ecs::ClothColliders);
    /// the methods do not read it.
    pub collider_speed: f32,
}

impl StepParams {
    /// The lab's parameters: `dt = 0.0333`, `k = 8000`, damping 0.99,
    /// gravity `(0, −9.8, 0)`.
    pub const LAB: Self = Self {
        dt: 0.0333,
        stiffness: SpringStiffness::uniform(8000.0),
        damping: 0.99,
        gravity: Vec3::new(0.0, -9.8, 0.0),
        parallel: true,
        simd: super::engine::simd::Simd::Auto,
        stencil: true,
        collider_speed: 0.0,
    };

    /// How far gravity alone takes a vertex within the step, `|g|·dt²`: the
    /// slack by which self-collision's search grows each vertex's swept box,
    /// so that the pairs the step's forces (not only its velocities) bring
    /// together are found.
    pub fn fall(&self) -> f32 {
        self.gravity.length() * (self.dt * self.dt) as f32
    }

    /// Checks every parameter; a solver calls this before it touches state.
    pub fn validate(&self) -> Result<(), ParamError> {
        self.validate_without_stiffness()?;
        self.stiffness.validate()
    }

    /// Checks every parameter but the stiffness, for methods that do not use
    /// it (PBD restores rest lengths instead).
    pub fn validate_without_stiffness(&self) -> Result<(), ParamError> {
        if !(self.dt.is_finite() && self.dt > 0.0 && (self.dt as f32) > 0.0) {
            return Err(ParamError::TimeStep(self.dt));
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
#[derive(Error, Reflect, Debug, Clone, Copy, PartialEq)]
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
    /// A [`ClothSnapshot`](crate::ClothSnapshot) pins other vertices than
    /// the cloth it is restored into.
    #[error("the snapshot pins {got} vertices, the cloth {expected} (or other ones)")]
    PinsMismatch {
        /// Pins of the cloth.
        expected: usize,
        /// Pins of the snapshot.
        got: usize,
    },
    /// A [`ClothSnapshot`](crate::ClothSnapshot) holds a position or
    /// velocity that is not finite, or a pin that is not a vertex.
    #[error("the snapshot holds a non-finite position or velocity, or a pin past the vertices")]
    InvalidSnapshot,
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
    /// How far the step's result is from the exact implicit-Euler solution
    /// of the same step, relative to how far the step moved the cloth: the
    /// iterative methods' convergence measure (see
    /// [`ConvergenceSums`](super::ConvergenceSums); Newton estimates it
    /// from its last step). `None` for methods that do not minimise the
    /// implicit-Euler objective (PBD, symplectic Euler) or take one linear
    /// solve for it (linearly implicit Euler).
    pub relative_error: Option<f32>,
    /// Vertices the method itself held on a collider at the end of its step
    /// (`stiff`, which projects the colliders inside its substeps); 0 for
    /// the methods that leave the projection to after the step, where it is
    /// counted. Added to [`ClothStats::contacts`](crate::ClothStats::contacts).
    pub contacts: u32,
    /// Pairs of the cloth's own vertices the method held apart at the end
    /// of its step, if it handles self-collision inside its step (`stiff`);
    /// `None` otherwise (the plugin then resolves it after the step).
    pub self_contacts: Option<u32>,
    /// The substeps the method took the step in, each vertex's velocity
    /// its motion over the last (`stiff`'s); 1 for the methods that take
    /// the step whole. The projection after the step sweeps each vertex
    /// over the last substep only: a vertex the substeps carried round a
    /// solid did not move in a straight line from the step's start.
    pub substeps: u32,
}

/// The relative error above which a step counts as not converged
/// ([`StepReport::relative_error`]): an estimated distance from the exact
/// implicit-Euler solution of more than 25 % of the step's motion.
///
/// Chosen from the stability map (`docs/report/stability.md`, section
/// "Convergence"), where it separates the right runs of the iterative
/// methods from the wrong ones but for the few the map lists by name; it is
/// set high in that gap. In contact, the plugin measures a step again after
/// the projection ([`ContactError`](super::ContactError)): the solve
/// ignores the collider, which then undoes the part of the fall the solve
/// did not finish.
pub const CONVERGENCE_TOLERANCE: f32 = 0.25;

/// Checks that `state` has one position and velocity per vertex of `model`.
pub(crate) fn check_state(model: &ClothModel, state: &ClothState) -> Result<(), StepError> {
    let expected = model.vertex_count();
    for got in [state.positions.len(), state.velocities.len()] {
        if got != expected {
            return Err(StepError::StateMismatch { expected, got });
        }
    }
    Ok(())
}

/// Why simulation parameters are invalid.
///
/// Returned by [`StepParams::validate`](crate::solver::StepParams::validate)
/// and by every solver's step. Inside a running app the cloth is skipped and a
/// warning is logged until the parameters are fixed.
#[derive(Error, Reflect, Debug, Clone, Copy, PartialEq)]
pub enum ParamError {
    /// The time step is zero, negative or not finite.
    #[error("time step {0} must be finite and positive")]
    TimeStep(f64),
    /// A spring stiffness is zero, negative or not finite.
    #[error("stiffness {0} must be finite and positive")]
    Stiffness(f32),
    /// Damping must lie in `[0, 1]` (it multiplies the velocity each step).
    #[error("damping {0} must lie in [0, 1]")]
    Damping(f32),
    /// Gravity has a non-finite component.
    #[error("gravity must be finite")]
    Gravity,
    /// A solver was asked for zero iterations.
    #[error("a solver needs at least one iteration")]
    Iterations,
    /// Chebyshev's spectral radius estimate must lie in `(0, 1)`.
    #[error("Chebyshev rho {0} must lie in (0, 1)")]
    Rho(f32),
    /// A solver tolerance is negative or not finite.
    #[error("tolerance {0} must be finite and non-negative")]
    Tolerance(f64),
    /// A divergence-guard bound is NaN, or a stretch bound is not positive.
    #[error("guard bound {0} must be a positive number")]
    Bound(f64),
    /// A particle radius is negative or not finite.
    #[error("particle radius {0} must be finite and non-negative")]
    ParticleRadius(f32),
    /// A convergence tolerance is not a positive number.
    #[error("convergence tolerance {0} must be positive (or infinite to turn the check off)")]
    ConvergenceTolerance(f32),
    /// An areal density is zero, negative or not finite.
    #[error("areal density {0} kg/m² must be finite and positive")]
    Density(f32),
    /// Two accelerations were asked of one solver (projective dynamics'
    /// Chebyshev and Anderson).
    #[error("choose one acceleration: Chebyshev or Anderson, not both")]
    Acceleration,
}

/// Checks an iterative solve's budget: at least one iteration, and a
/// tolerance that is a number and not negative (0: run every iteration).
/// Shared by the methods that stop at a tolerance within a cap (Newton,
/// conjugate gradients).
pub(crate) fn check_budget(max_iterations: u32, tolerance: f64) -> Result<(), ParamError> {
    if max_iterations == 0 {
        return Err(ParamError::Iterations);
    }
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(ParamError::Tolerance(tolerance));
    }
    Ok(())
}
