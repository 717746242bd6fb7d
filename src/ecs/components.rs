//! The cloth components: [`Cloth`], [`ClothParams`], [`ClothStats`].

use core::time::Duration;

use bevy::ecs::lifecycle::HookContext;
use bevy::ecs::world::DeferredWorld;
use bevy::math::Vec3A;
use bevy::prelude::*;

use crate::model::{ClothBuildError, ClothBuilder, ClothModel, ClothState};
use crate::solver::guard::{DivergenceReason, GuardBounds, GuardMemory, GuardPolicy};
use crate::solver::{CONVERGENCE_TOLERANCE, ParamError, SpringStiffness, StepError, StepParams};

/// A simulated cloth: its model (topology, masses, pins) and its state
/// (world-space positions and velocities).
///
/// Spawn it with a method component ([`ImplicitSolver`](crate::ImplicitSolver),
/// [`PbdSolver`](crate::PbdSolver)) and a [`Transform`]: the moment it is
/// inserted, its rest shape is placed by the entity's global transform
/// (computed from the `Transform` hierarchy), so [`positions`](Self::positions)
/// is never empty. From then on the pinned vertices follow that transform
/// while the others are simulated in world space. If the transform changes
/// before the first fixed step, the cloth is placed again there.
/// [`ClothParams`], [`ClothStats`] and [`ClothGuard`] are added
/// automatically.
///
/// ```
/// use bevy::prelude::*;
/// use bevy_cloth::prelude::*;
///
/// fn spawn(mut commands: Commands) {
///     let cloth = Cloth::new(ClothBuilder::lab().build().unwrap());
///     commands.spawn((cloth, ImplicitSolver::chebyshev(32, 0.995), Transform::default()));
/// }
/// # bevy::ecs::system::assert_is_system(spawn);
/// ```
#[derive(Component, Reflect, Clone, Debug, Default)]
#[reflect(Component, Default, Debug)]
#[require(ClothParams, ClothStats, ClothGuard, Transform)]
#[component(on_insert = place_on_insert)]
pub struct Cloth {
    #[reflect(ignore)]
    pub(crate) model: ClothModel,
    #[reflect(ignore)]
    pub(crate) state: ClothState,
    #[reflect(ignore)]
    pub(crate) last_good: ClothState,
    pub(crate) initialized: bool,
    /// Set by a step the guard rejected; sent as a message in `SyncOut`.
    #[reflect(ignore)]
    pub(crate) event: Option<(DivergenceReason, GuardAction)>,
    /// Halvings the guard currently applies to this cloth's steps.
    pub(crate) guard_memory: GuardMemory,
    /// Where the rest shape was placed, until the first fixed step (which
    /// places it again if the entity has moved since).
    #[reflect(ignore)]
    pub(crate) placed_at: Option<bevy::math::Affine3A>,
    /// Set by a method's step system each fixed step; a cloth no method
    /// claims has no stepping method ([`ClothStatus::NoMethod`]).
    pub(crate) claimed: bool,
    /// Set once a [`ClothNotConverged`](super::ClothNotConverged) message was
    /// sent; cleared when the method or its parameters change.
    pub(crate) convergence_reported: bool,
    /// The last step's convergence, judged in `SyncOut` once the colliders
    /// have projected the cloth (see
    /// [`ProjectedConvergence`](crate::solver::ProjectedConvergence)).
    #[reflect(ignore)]
    pub(crate) convergence: crate::solver::ProjectedConvergence,
    /// The pins the cloth was built with, which follow its own entity.
    #[reflect(ignore)]
    pub(crate) own_pins: Vec<u32>,
    /// The vertices held by other entities now
    /// ([`ClothAttachments`](super::ClothAttachments)), sorted; pinned in the
    /// model too.
    #[reflect(ignore)]
    pub(crate) attached: Vec<u32>,
    /// What the guard measured on the state after this fixed step's
    /// method step, for the guard's second check and the stats in
    /// `SyncOut`; dropped by anything that changes the state in between
    /// (collision, [`Cloth::state_mut`]).
    #[reflect(ignore)]
    pub(crate) measured: Option<crate::solver::Measured>,
    /// Set by the step system: the cloth's method ignores the springs'
    /// stiffness (PBD), so the guard's load bound does not apply to it.
    pub(crate) stiffness_free: bool,
    /// Each pinned vertex and where the last step left it: a pin's
    /// velocity at the next step is its displacement since, wherever it
    /// was moved (the fixed step's pinning, or the follow after `Update`).
    /// Cleared by anything that places or edits the state.
    #[reflect(ignore)]
    pub(crate) pins_stepped: Vec<(u32, Vec3A)>,
    /// The density a [`ClothMaterial`](crate::model::ClothMaterial)
    /// component last gave the model's masses.
    #[reflect(ignore)]
    pub(crate) density_applied: Option<f32>,
    /// The share of the last step its method's last substep took, when it
    /// took substeps (`stiff`): the colliders' projection after the step
    /// sweeps the vertices over that share only (see
    /// [`Sweep::share`](crate::collision::Sweep::share)).
    #[reflect(ignore)]
    pub(crate) last_substep: Option<f32>,
    /// Set by the step system: the last step's method kept this cloth off
    /// the other cloths inside its solve (`stiff`'s substeps; not PBD,
    /// which limits its springs' strain itself), so the pass
    /// between cloths after the steps pulls the rings around the vertices
    /// it pushes after them
    /// ([`ClothLayers::follow`](crate::collision::self_contact::ClothLayers::follow)).
    pub(crate) held_others: bool,
}

/// Places a cloth's rest shape at its entity's global transform as soon as the
/// component is inserted, so its state is usable at once.
fn place_on_insert(mut world: DeferredWorld, context: HookContext) {
    let entity = context.entity;
    let mut affine = bevy::math::Affine3A::IDENTITY;
    let mut current = Some(entity);
    // Walk the hierarchy as `TransformHelper` does (at most a few levels).
    while let Some(e) = current {
        if let Some(t) = world.get::<Transform>(e) {
            affine = t.compute_affine() * affine;
        }
        current = world.get::<ChildOf>(e).map(ChildOf::parent);
    }
    if let Some(mut cloth) = world.get_mut::<Cloth>(entity) {
        cloth.place(&affine);
        cloth.placed_at = Some(affine);
    }
}

/// A cloth's positions and velocities to edit in place
/// ([`Cloth::state_mut`]): one of each per vertex, a count that cannot
/// change through them.
#[derive(Debug)]
pub struct ClothStateMut<'a> {
    /// World-space vertex positions.
    pub positions: &'a mut [Vec3A],
    /// Vertex velocities.
    pub velocities: &'a mut [Vec3A],
}

impl Cloth {
    /// A cloth of this model; it is placed at its entity's transform on the
    /// first fixed step.
    pub fn new(model: ClothModel) -> Self {
        Self {
            own_pins: model.pins().to_vec(),
            model,
            ..default()
        }
    }

    /// Builds the model and wraps it.
    pub fn build(builder: ClothBuilder) -> Result<Self, ClothBuildError> {
        builder.build().map(Self::new)
    }

    /// The model: topology, masses, pins.
    #[inline]
    pub fn model(&self) -> &ClothModel {
        &self.model
    }

    /// The current state: the rest shape at the entity's transform from the
    /// moment the component is inserted, then the simulated one.
    #[inline]
    pub fn state(&self) -> &ClothState {
        &self.state
    }

    /// The positions and velocities to edit in place, for teleporting or
    /// nudging vertices by hand: one of each per vertex, a count that cannot
    /// change here. To put back a whole saved state,
    /// [`restore`](Self::restore) checks its size first.
    #[inline]
    pub fn state_mut(&mut self) -> ClothStateMut<'_> {
        self.measured = None;
        self.pins_stepped.clear();
        ClothStateMut {
            positions: &mut self.state.positions,
            velocities: &mut self.state.velocities,
        }
    }

    /// Replaces the state with `state` (a saved one, say), if it is this
    /// cloth's size: one position and one velocity per vertex. Otherwise
    /// the cloth keeps its state and this is
    /// [`StepError::StateMismatch`]. The cloth continues from `state` at its
    /// next step, where it is (no placement at its entity's transform).
    pub fn restore(&mut self, state: ClothState) -> Result<(), StepError> {
        crate::solver::params::check_state(&self.model, &state)?;
        self.state = state;
        self.measured = None;
        self.pins_stepped.clear();
        self.initialized = true;
        self.placed_at = None;
        Ok(())
    }

    /// World-space vertex positions (the placed rest shape until the first
    /// fixed step).
    #[inline]
    pub fn positions(&self) -> &[Vec3A] {
        &self.state.positions
    }

    /// True once the cloth has been placed in the world.
    #[inline]
    pub fn is_initialized(&self) -> bool {
        self.initialized
    }

    /// Puts the cloth back to its rest shape at its entity's transform on the
    /// next fixed step (until then the state is unchanged).
    pub fn reset(&mut self) {
        self.initialized = false;
        self.guard_memory = GuardMemory::default();
    }

    /// Puts the cloth back to its rest shape at `transform` now (the mesh
    /// shows it in the same frame), forgetting the guard's halvings.
    pub fn reset_at(&mut self, transform: &GlobalTransform) {
        self.place(&transform.affine());
        self.guard_memory = GuardMemory::default();
    }

    /// The rest shape at `affine`, at rest.
    pub(crate) fn place(&mut self, affine: &bevy::math::Affine3A) {
        self.state = ClothState::at_rest(&self.model, affine);
        self.last_good.copy_from(&self.state);
        self.measured = None;
        self.pins_stepped.clear();
        // Held vertices are taken again, from rest, at the next step.
        self.attached.clear();
        self.initialized = true;
    }

    /// Gives each pin the velocity of its displacement since the last step
    /// (over `dt`), if that step had the same pins: the fixed step's
    /// pinning computes it too, but a pin already moved after `Update`
    /// (`ClothFollowSystems`) has no displacement left there. A method that
    /// moves pins along their motion within the step (`stiff`) reads it.
    pub(crate) fn pin_velocities(&mut self, dt: f32) {
        let pins = self.model.pins();
        if dt <= 0.0
            || self.pins_stepped.len() != pins.len()
            || self
                .pins_stepped
                .iter()
                .zip(pins)
                .any(|(&(v, _), &p)| v != p)
        {
            return;
        }
        for &(p, before) in &self.pins_stepped {
            let v = (self.state.positions[p as usize] - before) / dt;
            if v.is_finite() {
                self.state.velocities[p as usize] = v;
            }
        }
    }
}

/// Physical parameters of a cloth. The time step is the schedule's
/// (`Time<Fixed>` in `FixedUpdate`). Defaults are the lab's, with its
/// damping given per second ([`ClothParams::LAB`] is the lab's exactly).
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct ClothParams {
    /// Spring stiffness per kind (the lab: 8000 for all).
    pub stiffness: SpringStiffness,
    /// Velocity multiplier per step, in `[0, 1]` (the lab: 0.99), used when
    /// [`damping_per_second`](Self::damping_per_second) is `None` (as in
    /// [`ClothParams::LAB`], for fidelity to the lab). Per step, a cloth
    /// settles at a different rate at 30 and 60 Hz.
    pub damping: f32,
    /// Velocity multiplier per second, in `[0, 1]`: when set, each step of
    /// `dt` seconds multiplies the velocities by `damping_per_second^dt`
    /// (so the cloth settles at the same rate at any step), and
    /// [`damping`](Self::damping) is unused. The default,
    /// [`DAMPING_PER_SECOND`](Self::DAMPING_PER_SECOND), is the lab's 0.99
    /// per step at 60 Hz made a rate; `None` uses the per-step factor.
    pub damping_per_second: Option<f32>,
    /// Gravitational acceleration (the lab: `(0, −9.8, 0)`).
    pub gravity: Vec3,
    /// Radius of the cloth's particles for collisions: sphere contacts
    /// happen at the sphere's radius plus this (the lab: 0; the assignment
    /// gives particles a small radius).
    pub particle_radius: f32,
    /// Whether a large cloth may split its loops over Bevy's compute pool
    /// (see [`StepParams::parallel`]; default `true`). Results are bitwise
    /// the same either way.
    pub parallel: bool,
}

impl Default for ClothParams {
    /// The lab's parameters ([`ClothParams::LAB`]) with its damping given
    /// per second ([`DAMPING_PER_SECOND`](Self::DAMPING_PER_SECOND)), so a
    /// cloth settles alike at 30, 60 or 240 Hz.
    fn default() -> Self {
        Self {
            damping_per_second: Some(Self::DAMPING_PER_SECOND),
            ..Self::LAB
        }
    }
}

impl ClothParams {
    /// The lab's parameters as its specification gives them: `k = 8000`,
    /// gravity `(0, −9.8, 0)`, and its damping of 0.99 *per step*
    /// (`damping_per_second: None`), bitwise the solver's
    /// [`StepParams::LAB`] at the lab's step. The lab example's faithful
    /// scene and the headless example's lab use it.
    pub const LAB: Self = Self {
        stiffness: StepParams::LAB.stiffness,
        damping: StepParams::LAB.damping,
        damping_per_second: None,
        gravity: StepParams::LAB.gravity,
        particle_radius: 0.0,
        parallel: StepParams::LAB.parallel,
    };

    /// The default damping per second: the lab's 0.99 per step at a game's
    /// 60 Hz (`0.99⁶⁰ ≈ 0.547`), rounded, so a game's cloth at 60 Hz damps
    /// as the lab's factor did there (at the lab's own 30 Hz that factor
    /// is `0.99³⁰ ≈ 0.74` per second).
    pub const DAMPING_PER_SECOND: f32 = 0.55;

    /// The solver parameters for a step of `dt` seconds.
    pub fn step_params(&self, dt: f64) -> StepParams {
        StepParams {
            dt,
            stiffness: self.stiffness,
            damping: self
                .damping_per_second
                .map_or(self.damping, |r| r.powf(dt as f32)),
            gravity: self.gravity,
            parallel: self.parallel,
            // The fastest the CPU has: every level gives the same bits.
            simd: crate::solver::Simd::Auto,
            // The structure-of-arrays kernels wherever the cloth is a grid.
            stencil: true,
            // Set by the plugin from the colliders' motion.
            collider_speed: 0.0,
        }
    }

    /// Checks what the ECS layer adds to [`StepParams`]: the particle radius
    /// must be finite and non-negative, a damping per second in `[0, 1]`. (The method checks the rest when it
    /// steps, each parameter it uses.)
    pub fn validate(&self) -> Result<(), ParamError> {
        if !(self.particle_radius.is_finite() && self.particle_radius >= 0.0) {
            return Err(ParamError::ParticleRadius(self.particle_radius));
        }
        if let Some(r) = self.damping_per_second
            && !(0.0..=1.0).contains(&r)
        {
            return Err(ParamError::Damping(r));
        }
        Ok(())
    }

    /// These parameters with one stiffness for every spring kind.
    pub fn with_stiffness(mut self, k: f32) -> Self {
        self.stiffness = SpringStiffness::uniform(k);
        self
    }

    /// These parameters with another damping per step (and no damping per
    /// second).
    pub fn with_damping(mut self, damping: f32) -> Self {
        self.damping = damping;
        self.damping_per_second = None;
        self
    }

    /// These parameters with a damping per second (see
    /// [`damping_per_second`](Self::damping_per_second)).
    pub fn with_damping_per_second(mut self, per_second: f32) -> Self {
        self.damping_per_second = Some(per_second);
        self
    }

    /// These parameters with another particle radius.
    pub fn with_particle_radius(mut self, radius: f32) -> Self {
        self.particle_radius = radius;
        self
    }

    /// These parameters with another gravity.
    pub fn with_gravity(mut self, gravity: Vec3) -> Self {
        self.gravity = gravity;
        self
    }
}

/// The divergence guard of one cloth (added with [`Cloth`]): the bounds a
/// step must keep and what to do when it does not. See
/// [`guard`](crate::solver::guard).
///
/// After every step the guard checks that the state is finite and within
/// `bounds`. A step that fails is undone and, under
/// [`GuardPolicy::Retry`] (the default), retried with halved time steps; if
/// that fails too, the cloth is stopped at its last good state
/// ([`ClothStatus::Diverged`]). Either way a
/// [`ClothDiverged`](super::ClothDiverged) message names it.
///
/// It also watches convergence: a step of an iterative method whose
/// [`relative_error`](crate::solver::StepReport::relative_error) exceeds
/// `convergence_tolerance` is kept (it is finite and inside the bounds), but
/// marks the cloth [`ClothStats::converged`]` = false` and sends
/// [`ClothNotConverged`](super::ClothNotConverged) once.
#[derive(Component, Reflect, Clone, Copy, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct ClothGuard {
    /// What a state must satisfy after a step.
    pub bounds: GuardBounds,
    /// What to do with a step that fails.
    pub policy: GuardPolicy,
    /// The relative error above which a step is not converged (default
    /// [`CONVERGENCE_TOLERANCE`], 0.25; `f32::INFINITY` turns the check off).
    pub convergence_tolerance: f32,
}

impl Default for ClothGuard {
    fn default() -> Self {
        Self {
            bounds: GuardBounds::default(),
            policy: GuardPolicy::default(),
            convergence_tolerance: CONVERGENCE_TOLERANCE,
        }
    }
}

impl ClothGuard {
    /// A guard that stops the cloth at the first failed step.
    pub fn pause() -> Self {
        Self {
            policy: GuardPolicy::Pause,
            ..default()
        }
    }

    /// A guard that retries a failed step with up to `max_halvings` halvings
    /// of the time step.
    pub fn retry(max_halvings: u8) -> Self {
        Self {
            policy: GuardPolicy::Retry { max_halvings },
            ..default()
        }
    }

    /// This guard with other bounds.
    pub fn with_bounds(mut self, bounds: GuardBounds) -> Self {
        self.bounds = bounds;
        self
    }

    /// This guard with another convergence tolerance.
    pub fn with_convergence_tolerance(mut self, tolerance: f32) -> Self {
        self.convergence_tolerance = tolerance;
        self
    }

    /// Checks the convergence tolerance (the bounds are checked by the step).
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.convergence_tolerance.is_nan() || self.convergence_tolerance <= 0.0 {
            return Err(ParamError::ConvergenceTolerance(self.convergence_tolerance));
        }
        Ok(())
    }
}

/// What the guard did about a rejected step.
#[derive(Reflect, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GuardAction {
    /// The step was retried with smaller time steps and succeeded.
    Recovered {
        /// Substeps it took (`2^halvings`).
        substeps: u32,
    },
    /// Every try failed: the cloth is back at its last good state and stopped.
    Paused,
}

/// Whether a cloth is being simulated.
#[derive(Reflect, Clone, Debug, Default, PartialEq)]
pub enum ClothStatus {
    /// Simulated normally.
    #[default]
    Running,
    /// Skipped because its parameters, its method's settings or its state
    /// are invalid: the typed error says which. It resumes by itself once
    /// they are fixed.
    Invalid(StepError),
    /// Not stepped: no plugin steps the cloth's method. `method` names the
    /// crate's method component the cloth carries whose plugin was not added
    /// (for example `Some("chebyshev")` in an app with only `PbdPlugin`), or
    /// is `None` if it carries no method component at all. It resumes by
    /// itself once a method with a plugin is inserted.
    NoMethod {
        /// The method component the cloth carries, if it is one of the
        /// crate's.
        method: Option<&'static str>,
    },
    /// Stopped by the divergence guard, at its last good state; call
    /// [`ClothStats::resume`] (or [`Cloth::reset`] and resume) to go on.
    Diverged(DivergenceReason),
}

/// What the last step of a cloth did. Updated every fixed step.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component, Default, Debug, PartialEq)]
pub struct ClothStats {
    /// The method that stepped the cloth last (for example `"implicit"`).
    pub method: &'static str,
    /// Completed steps since the cloth was spawned, reset by the panel or
    /// switched to another method (each starts the stats afresh).
    pub steps: u64,
    /// Wall-clock time of the last solver step (collision excluded).
    pub step_time: Duration,
    /// Solver iterations in the last step.
    pub iterations: u32,
    /// The method's residual (gradient norm for the implicit solver and
    /// projective dynamics, CG's relative residual), if it has one.
    pub residual: Option<f32>,
    /// The last step's estimated distance from the exact implicit-Euler
    /// solution relative to its motion (see
    /// [`StepReport::relative_error`](crate::solver::StepReport::relative_error)),
    /// for the iterative methods that minimise it (Jacobi, Chebyshev,
    /// projective dynamics). A step whose own measure exceeds the tolerance
    /// and whose vertices a collider's projection (or a skin's limits) then
    /// moved is measured again without what the projection undoes
    /// ([`ContactError`](crate::solver::ContactError)): a cloth resting on
    /// a collider is held by forces its solve does not see.
    pub relative_error: Option<f32>,
    /// False while the last step's `relative_error` exceeds the guard's
    /// [`convergence_tolerance`](ClothGuard::convergence_tolerance): the cloth
    /// moves, but not as implicit Euler would (a stiff cloth "locks").
    /// Raise the iterations or use projective dynamics (`pd`).
    pub converged: bool,
    /// Steps so far that ended not converged.
    pub unconverged_steps: u64,
    /// Largest relative spring elongation `(l − L)/L` after the step.
    pub max_stretch: f32,
    /// Total mechanical energy after the step (kinetic + spring +
    /// gravitational).
    pub energy: f64,
    /// Vertex–collider contacts in the last step: vertices inside a penalty
    /// sphere after the step, plus vertices a projection sphere moved.
    pub contacts: u32,
    /// Pairs of the cloth's own vertices held apart in the last step
    /// ([`SelfCollision`](crate::SelfCollision); 0 without it).
    pub self_contacts: u32,
    /// Substeps the last step took: 1, or more when the guard retried it with
    /// halved time steps.
    pub substeps: u32,
    /// Steps the guard had to retry with halved time steps so far.
    pub retried_steps: u64,
    /// Whether the cloth is simulated.
    pub status: ClothStatus,
}

impl Default for ClothStats {
    fn default() -> Self {
        Self {
            method: "",
            steps: 0,
            step_time: Duration::ZERO,
            iterations: 0,
            residual: None,
            relative_error: None,
            converged: true,
            unconverged_steps: 0,
            max_stretch: 0.0,
            energy: 0.0,
            contacts: 0,
            self_contacts: 0,
            substeps: 0,
            retried_steps: 0,
            status: ClothStatus::Running,
        }
    }
}

impl ClothStats {
    /// True if the cloth is being simulated.
    #[inline]
    pub fn is_running(&self) -> bool {
        self.status == ClothStatus::Running
    }

    /// Back to a fresh cloth's statistics (step counter, guard notes,
    /// convergence), keeping nothing: what the panel's reset and a method
    /// switch do.
    pub fn clear(&mut self) {
        *self = Self::default();
    }

    /// Lets a cloth stopped by the divergence guard run again.
    pub fn resume(&mut self) {
        self.status = ClothStatus::Running;
    }
}
