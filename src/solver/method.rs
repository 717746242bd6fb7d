//! What every method is: a settings type implementing [`Method`].
//!
//! A method's settings *are* its type: [`ImplicitSolver`](super::implicit::ImplicitSolver),
//! [`PbdSolver`](super::pbd::PbdSolver), … Each implements [`Method`] once,
//! in its own file, and the crate's method table
//! ([`methods`](crate::methods)) turns each into an ECS component, a plugin,
//! a variant of [`AnyMethod`](crate::methods::AnyMethod) and named presets.

use core::fmt::Debug;

use bevy::math::Vec3A;

use super::params::{ParamError, StepError, StepParams, StepReport, check_state};
use crate::collision::{PenaltySphere, Shape};
use crate::model::{ClothModel, ClothState};

/// The lab's iteration count (32) for the iterative methods' interactive
/// presets and defaults.
pub const LAB_ITERATIONS: u32 = 32;

/// The lab's Chebyshev spectral radius, `ρ = 0.995`.
pub const LAB_RHO: f32 = 0.995;

/// What a step reads: the cloth, the step's parameters and the penalty
/// spheres acting inside it. [`Method::advance`] takes it whole.
#[derive(Clone, Copy, Debug)]
pub struct StepInput<'a> {
    /// The cloth's topology, masses and pins.
    pub model: &'a ClothModel,
    /// The time step, gravity, stiffness, damping and kernel choices.
    pub params: &'a StepParams,
    /// Penalty spheres acting inside the step (contact distance includes
    /// the cloth's particle radius).
    pub spheres: &'a [PenaltySphere],
    /// The solids that are projected out after the step (the projection
    /// spheres as capsules of zero length, planes, capsules, boxes), grown
    /// by the cloth's particle radius. A method that handles contacts
    /// inside its step projects them there too (the `stiff` method, in
    /// every substep); the others ignore them and leave them to the
    /// projection after the step. Empty from [`Method::step`].
    pub contacts: &'a [Shape],
    /// How far each of [`contacts`](Self::contacts) moved over the step
    /// (parallel to it; empty, or shorter, for solids that did not move): a
    /// method with substeps moves them through its substeps from where
    /// they were, so a fast one pushes the cloth along its path instead of
    /// appearing at its end (the `stiff` method). A solid that moved
    /// further than [`TELEPORT`](crate::collision::swept::TELEPORT) is
    /// taken as teleported and held at its end.
    pub contact_motion: &'a [Vec3A],
    /// A character cloth's skinned pose and constraints
    /// ([`ClothSkin`](crate::ClothSkin)): a method that can holds its
    /// vertices to them inside its step (the `stiff` method, in every
    /// substep); all are held to them after the step. `None` from
    /// [`Method::step`].
    pub skin: Option<SkinInput<'a>>,
    /// The cloth's self-collision ([`SelfCollision`](crate::SelfCollision),
    /// validated) and the other cloths' vertices it collides with: a method
    /// that can keeps the cloth off itself and them inside its
    /// step (the `stiff` method, in every substep) and says so in
    /// [`StepReport::self_contacts`](super::StepReport::self_contacts); for
    /// the others the plugin resolves it after the step. `None` from
    /// [`Method::step`].
    pub self_collision: Option<crate::collision::self_contact::SelfCollisionInput<'a>>,
}

/// A character cloth's skinned pose and per-vertex constraints, as a
/// method reads them (see [`crate::character`]): one entry per vertex in
/// each list.
#[derive(Clone, Copy, Debug)]
pub struct SkinInput<'a> {
    /// Skinned positions at the step's end.
    pub positions: &'a [Vec3A],
    /// Skinned positions at the step's start, if known: a method with
    /// substeps moves the skin from them to `positions` through its
    /// substeps, as it moves the pins (an end pose held from the first
    /// substep would pull the cloth ahead of its pins).
    pub previous: Option<&'a [Vec3A]>,
    /// Skinned unit normals.
    pub normals: &'a [Vec3A],
    /// Max distance from the skinned position (`∞`: none).
    pub max_distance: &'a [f32],
    /// Backstop distance behind it along the normal (`∞`: none).
    pub backstop_distance: &'a [f32],
    /// The backstop spheres' radius.
    pub backstop_radius: f32,
    /// Tethers' scale over the rest distance to the nearest pin (`∞`:
    /// none).
    pub tether_scale: f32,
}

impl SkinInput<'_> {
    /// Moves vertex `i` at `x` out of its backstop sphere and back within
    /// its max distance; whether it moved.
    #[inline]
    pub fn hold(&self, i: usize, x: &mut Vec3A) -> bool {
        self.hold_at(i, self.positions[i], x)
    }

    /// [`hold`](Self::hold) with the skin of vertex `i` at `skin`.
    #[inline]
    pub fn hold_at(&self, i: usize, skin: Vec3A, x: &mut Vec3A) -> bool {
        self.hold_with(i, skin, self.normals[i].normalize_or_zero(), x)
    }

    /// [`hold_at`](Self::hold_at) with vertex `i`'s normal already made unit
    /// (`normals[i].normalize_or_zero()`), as a method with substeps keeps
    /// it through its step. The same result bit for bit: a vertex whose
    /// squared distance says, with room for its rounding, that it is
    /// outside its backstop sphere or within its max distance is left
    /// without a square root.
    #[inline]
    pub fn hold_with(&self, i: usize, skin: Vec3A, unit_normal: Vec3A, x: &mut Vec3A) -> bool {
        /// Room for the rounding of a squared length against a squared
        /// radius (each within a few units in the last place).
        const ROOM: f32 = 1e-5;
        let (max, backstop) = (self.max_distance[i], self.backstop_distance[i]);
        let mut moved = false;
        if backstop.is_finite() {
            let radius = self.backstop_radius;
            let centre = skin - (backstop + radius) * unit_normal;
            let d = *x - centre;
            let l2 = d.length_squared();
            // `length` is the square root of this same `length_squared`;
            // a NaN is not surely outside.
            let surely_outside = l2 >= radius * radius * (1.0 + ROOM);
            if !surely_outside {
                let l = d.length();
                if l < radius {
                    let out = if l > 0.0 { d / l } else { self.normals[i] };
                    *x = centre + radius * out;
                    moved = true;
                }
            }
        }
        if max.is_finite() {
            let d = *x - skin;
            let surely_within = d.length_squared() <= max * max * (1.0 - ROOM);
            if !surely_within {
                let l = d.length();
                if l > max {
                    *x = skin + d * (max / l);
                    moved = true;
                }
            }
        }
        moved
    }
}

/// A simulation method: settings that advance a [`ClothState`] by one step
/// with a reusable workspace. Pure numerics, no ECS.
pub trait Method: Clone + Copy + Debug + PartialEq + Send + Sync + 'static {
    /// Scratch buffers reused from step to step (allocated on the first
    /// step, so a cloth allocates only what its method needs).
    type Workspace: Default + Send + Sync + 'static;

    /// The name of this configuration, the one used everywhere (panel,
    /// [`ClothStats`](crate::ClothStats), messages, report, perf page,
    /// command lines): lower case, words joined by `-`, e.g. `chebyshev`
    /// or `linear-cg`.
    fn name(&self) -> &'static str;

    /// The iteration count per step of an iterative method, to read or set
    /// (`None` for a method without one).
    fn iterations_mut(&mut self) -> Option<&mut u32> {
        None
    }

    /// Iterations per step of an iterative method (`None` for a direct one).
    fn iterations(&self) -> Option<u32> {
        let mut method = *self;
        method.iterations_mut().map(|k| *k)
    }

    /// The same method with another iteration count (unchanged for a
    /// method without iterations).
    #[must_use]
    fn with_iterations(mut self, iterations: u32) -> Self {
        if let Some(k) = self.iterations_mut() {
            *k = iterations;
        }
        self
    }

    /// Checks the settings.
    fn validate(&self) -> Result<(), ParamError>;

    /// Whether the springs' stiffness acts in this method (true by
    /// default). PBD restores rest lengths instead, so the guard's load
    /// bound, which is derived from the stiffness, does not apply to it.
    fn uses_stiffness(&self) -> bool {
        true
    }

    /// Checks the parameters this method uses: all of them by default
    /// ([`StepParams::validate`]); a method that ignores some (PBD has no
    /// stiffness) checks only the others, so a value it never reads cannot
    /// stop it.
    fn validate_params(&self, params: &StepParams) -> Result<(), ParamError> {
        params.validate()
    }

    /// Advances `state` by one step, with penalty `spheres` acting inside it,
    /// after checking the parameters it uses, the settings and the state's size. On
    /// error the state is unchanged, with one exception: projective dynamics
    /// factorises (after a sphere's contacts change) and solves in the
    /// middle of its step, so its [`StepError::Solve`] (a failed
    /// factorisation or a non-finite solution, which finite input with
    /// positive masses does not produce) can come after it has moved the
    /// state; the divergence guard ([`guarded_step`](super::guard::guarded_step))
    /// restores it then.
    fn step(
        &self,
        model: &ClothModel,
        state: &mut ClothState,
        params: &StepParams,
        spheres: &[PenaltySphere],
        workspace: &mut Self::Workspace,
    ) -> Result<StepReport, StepError> {
        let input = StepInput {
            model,
            params,
            spheres,
            contacts: &[],
            contact_motion: &[],
            skin: None,
            self_collision: None,
        };
        self.step_with(input, state, workspace)
    }

    /// [`step`](Self::step) with the whole [`StepInput`], the solids
    /// projected after the step included (what the ECS plugin calls).
    fn step_with(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        workspace: &mut Self::Workspace,
    ) -> Result<StepReport, StepError> {
        self.validate_params(input.params)?;
        self.validate()?;
        check_state(input.model, state)?;
        self.advance(input, state, workspace)
    }

    /// [`step`](Self::step) without its checks: what each method implements,
    /// reading `input` and advancing `state` with its `workspace`. Callers
    /// use `step`.
    fn advance(
        &self,
        input: StepInput<'_>,
        state: &mut ClothState,
        workspace: &mut Self::Workspace,
    ) -> Result<StepReport, StepError>;
}
