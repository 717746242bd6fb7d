//! The divergence guard: a cheap check after each step, and a policy for a
//! step that fails it.
//!
//! A step *fails* when the method returns a solve error, when a position or
//! velocity becomes NaN or infinite, or when the cloth leaves the bounds of a
//! [`GuardBounds`]: a spring stretched beyond `max_stretch` times its rest
//! length or beyond what the cloth's weight could stretch it
//! ([`GuardBounds::stretch_bound`]), a free vertex faster than its fall,
//! its pins and its colliders could make it ([`GuardBounds::speed_bound`]),
//! or a total energy beyond `max_energy`. The bounds catch a blow-up
//! while the state is still finite, so the state the guard keeps is never
//! absurd.
//!
//! On a failed step [`guarded_step`] restores the state from before the step
//! and applies the [`GuardPolicy`]: give up at once, or retry the step as 2,
//! 4, 8, … substeps of `dt/2`, `dt/4`, `dt/8`, … (each substep checked) up to
//! a limit. Smaller steps rescue the explicit method (stable for
//! `dt < 2/ω_max`), a fixed-ρ Chebyshev iteration (its ρ is nearer the true
//! one when `dt²k/m` is smaller) and a linear system that lost definiteness
//! (`M − h²K` is positive definite for small `h`). The ECS runs this for
//! every cloth (see [`ClothGuard`](crate::ecs::ClothGuard)).

use bevy::reflect::Reflect;

use super::ParamError;
use super::{Measured, StepError, StepParams, StepReport, max_stretch, measure};
use crate::model::{ClothModel, ClothState};

/// Why the guard rejected a step.
#[derive(Reflect, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DivergenceReason {
    /// A position or velocity became NaN or infinite.
    NonFinite,
    /// The method's solve failed (a matrix that is not positive definite, a
    /// failed factorisation, or Newton's line search finding no decrease);
    /// the state was left as it was.
    SolveFailed,
    /// A spring became longer than [`GuardBounds::max_stretch`] allows.
    Stretch,
    /// The total energy exceeded [`GuardBounds::max_energy`].
    Energy,
    /// A free vertex moved faster than [`GuardBounds::speed_bound`] allows.
    Speed,
}

impl std::fmt::Display for DivergenceReason {
    /// What a player would see, in a few words.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::NonFinite => "blew up: a position or velocity became NaN or infinite",
            Self::SolveFailed => {
                "its solve failed: a matrix that is not positive definite, a failed \
                 factorisation, or a line search that found no decrease"
            }
            Self::Stretch => {
                "it is stretching apart: a spring passed the guard's stretch bound (far past what \
                 its weight and stiffness allow)"
            }
            Self::Energy => "it is gaining energy: its energy passed the guard's bound",
            Self::Speed => {
                "it is flying apart: a vertex moved far faster than gravity, its pins and its \
                 colliders could make it (the guard's speed bound)"
            }
        })
    }
}

/// What a state must satisfy after a step, besides being finite.
#[derive(Reflect, Clone, Copy, Debug, PartialEq)]
pub struct GuardBounds {
    /// Largest allowed relative elongation `(l − L)/L` of any spring; `None`
    /// checks none. Default `10`: no cloth stretches to eleven times its rest
    /// length, and an unstable step crosses it long before its state is
    /// absurd, so the state the guard keeps is still usable. A step that
    /// ends beyond the bound passes if it reduced the largest stretch (a pin
    /// teleported far away leaves springs stretched before any step runs).
    /// A scene whose physics stretches springs further than this (huge loads
    /// on soft springs) needs a larger bound, and no
    /// [`load_factor`](Self::load_factor) if its load is not its weight (the
    /// smaller of the two bounds applies).
    pub max_stretch: Option<f32>,
    /// The bound a player would judge by: a cloth may stretch at most
    /// `0.5 + load_factor · ε_w`, where `ε_w = M·|g| / (k·L)` is the stretch
    /// its whole free weight `M·|g|` would give one stretch spring of
    /// stiffness `k` and mean rest length `L` (see
    /// [`GuardBounds::stretch_bound`]). Its weight is spread over several
    /// springs, so cloth that a method keeps right stretches a fraction of
    /// `ε_w`; a cloth stretched half its length beyond ten times that is
    /// coming apart, whatever the method says. Default `10`: it binds for
    /// cloth of real mass on stiff springs (a 1.5 kg cape on the lab's
    /// `k = 8000`: 61 %), while [`max_stretch`](Self::max_stretch)
    /// binds for the lab's heavy soft cloth. `None` checks only
    /// `max_stretch`. Like it, the bound passes a step that reduced the
    /// largest stretch.
    pub load_factor: Option<f32>,
    /// Largest allowed total energy (see [`energy`](super::energy)); `None`
    /// (the default) checks none. It depends on the scene, so only its
    /// author can set it.
    pub max_energy: Option<f64>,
    /// The speed bound of a cloth held by pins (see
    /// [`GuardBounds::speed_bound`]): a free vertex may move at most
    /// `speed_factor · √(2|g|·D) + v_pin + v_collider + D/dt`, where `D` is
    /// the cloth's size, `√(2|g|·D)` the speed of a fall from its pins'
    /// height to its far end, `v_pin` the fastest pin and `v_collider` the
    /// fastest collider (what holds or pushes the cloth may move it as fast
    /// as it likes), and `D/dt` crossing its own size in one step. Default
    /// `10`: a 1 m square cape at 60 Hz may move about 140 m/s faster than
    /// its pins and colliders, a 2 m one about 240 m/s, the lab's cloth at
    /// its 30 Hz about 590 m/s; past that it is
    /// exploding. A cloth without pins falls as
    /// fast as gravity makes it and has no speed bound. `None` checks none.
    /// Like the stretch bounds, it passes a step that began beyond the
    /// stretch bound: a cloth recovering from a pin teleported far away
    /// moves fast.
    pub speed_factor: Option<f32>,
}

impl Default for GuardBounds {
    fn default() -> Self {
        Self {
            max_stretch: Some(10.0),
            load_factor: Some(10.0),
            max_energy: None,
            speed_factor: Some(10.0),
        }
    }
}

impl GuardBounds {
    /// No bounds: only non-finite values and solve failures are caught.
    pub const FINITE_ONLY: Self = Self {
        max_stretch: None,
        load_factor: None,
        max_energy: None,
        speed_factor: None,
    };

    /// These bounds for a method that does (`uses_stiffness`) or does not
    /// use the springs' stiffness: without it, no load bound (it is
    /// derived from the stiffness).
    #[must_use]
    pub fn for_method(self, uses_stiffness: bool) -> Self {
        if uses_stiffness {
            self
        } else {
            Self {
                load_factor: None,
                ..self
            }
        }
    }

    /// Checks the bounds themselves (positive, not NaN).
    pub fn validate(&self) -> Result<(), ParamError> {
        if let Some(s) = self.max_stretch
            && (s.is_nan() || s <= 0.0)
        {
            return Err(ParamError::Bound(f64::from(s)));
        }
        if let Some(f) = self.load_factor
            && (f.is_nan() || f < 0.0)
        {
            return Err(ParamError::Bound(f64::from(f)));
        }
        if let Some(e) = self.max_energy
            && e.is_nan()
        {
            return Err(ParamError::Bound(e));
        }
        if let Some(f) = self.speed_factor
            && (f.is_nan() || f < 0.0)
        {
            return Err(ParamError::Bound(f64::from(f)));
        }
        Ok(())
    }

    /// The largest stretch this cloth may reach under `params`: the smaller
    /// of [`max_stretch`](Self::max_stretch) and the load bound
    /// `0.5 + load_factor · M·|g|/(k·L)` (see
    /// [`load_factor`](Self::load_factor); `M` the mass of the free
    /// vertices, `k` the stretch springs' stiffness, `L` their mean rest
    /// length), plus `2·v_collider·dt/L`: twice as far as the fastest
    /// collider ([`params.collider_speed`](StepParams::collider_speed))
    /// moved this step, in rest lengths, since it may have pushed a vertex
    /// that far past its neighbours in this step and the last. `None` if neither applies (a cloth without stretch springs,
    /// or of zero stiffness, has no load bound).
    pub fn stretch_bound(&self, model: &ClothModel, params: &StepParams) -> Option<f32> {
        let load = self.load_factor.and_then(|factor| {
            let k = params.stiffness.as_array()[0];
            let l = model.topology().mean_rest_lengths()[0];
            let weight = model.free_mass() * params.gravity.length();
            let strain = weight / (k * l);
            (k > 0.0 && l > 0.0 && strain.is_finite()).then_some(0.5 + factor * strain)
        });
        // A collider that moved `d` this step may have pushed a vertex
        // that far past its neighbours, and the step before's push on
        // top: `2d/L` more, where the speed bound likewise allows the
        // colliders' speed (a ball thrown through the cloth stretches it,
        // and that is no wreck).
        let l = model.topology().mean_rest_lengths()[0];
        let pushed = 2.0 * params.collider_speed * params.dt as f32 / l;
        let pushed = if pushed.is_finite() { pushed } else { 0.0 };
        match (self.max_stretch, load) {
            (Some(a), Some(b)) => Some(a.min(b) + pushed),
            (a, b) => a.or(b).map(|bound| bound + pushed),
        }
    }

    /// The largest speed a free vertex of this cloth may reach in a step of
    /// `params.dt` while its pins move at most `pin_speed` and its colliders
    /// at most [`params.collider_speed`](StepParams::collider_speed):
    /// `speed_factor · √(2|g|·D) + pin_speed + collider_speed + D/dt` with
    /// `D` the cloth's [size](ClothModel::size) (see
    /// [`speed_factor`](Self::speed_factor)). `None` without a factor, for a
    /// cloth without pins, or when a speed is not finite.
    pub fn speed_bound(
        &self,
        model: &ClothModel,
        params: &StepParams,
        pin_speed: f32,
    ) -> Option<f32> {
        let factor = self.speed_factor?;
        if model.pins().is_empty() || params.dt <= 0.0 {
            return None;
        }
        let size = model.size();
        let fall = (2.0 * params.gravity.length() * size).sqrt();
        let bound = factor * fall + pin_speed + params.collider_speed + size / params.dt as f32;
        bound.is_finite().then_some(bound)
    }

    /// Checks `state` after a step from `before`: finite, and within the
    /// bounds that are set. A stretch beyond the bound passes if it is no
    /// larger than before the step: the cloth is recovering from something
    /// done to it (a pin teleported far away), not blowing up. Costs one pass
    /// over the vertices and one over the springs ([`measure`]), whatever
    /// bounds are set; returns what it measured (the largest stretch and
    /// the energy), so a caller need not measure it again.
    pub fn check(
        &self,
        model: &ClothModel,
        state: &ClothState,
        before: &ClothState,
        params: &StepParams,
    ) -> Result<Measured, DivergenceReason> {
        self.check_recovering(model, state, before, params, false)
            .map(|(measured, _)| measured)
    }

    /// [`check`](Self::check) for a cloth that may be `recovering` (see
    /// [`GuardMemory::recovering`]); also says whether the cloth is (still)
    /// recovering: faster than the speed bound, passed because the step
    /// began beyond the stretch bound or the cloth was recovering already.
    fn check_recovering(
        &self,
        model: &ClothModel,
        state: &ClothState,
        before: &ClothState,
        params: &StepParams,
        recovering: bool,
    ) -> Result<(Measured, bool), DivergenceReason> {
        let measured = measure(model, state, params).ok_or(DivergenceReason::NonFinite)?;
        let bound = self.stretch_bound(model, params);
        // Measured once, and only when a bound needs it (`before` passed the
        // guard, so it is finite).
        let mut stretch_before = None;
        let mut before_stretch =
            || *stretch_before.get_or_insert_with(|| max_stretch(model, &before.positions));
        if let Some(bound) = bound {
            let stretch = measured.max_stretch;
            // Fails if it grew while beyond the bound.
            if stretch > bound && before_stretch() < stretch {
                return Err(DivergenceReason::Stretch);
            }
        }
        let mut still_recovering = false;
        if let Some(limit) = self.speed_bound(model, params, measured.max_pin_speed)
            && measured.max_free_speed > limit
        {
            still_recovering = recovering || bound.is_some_and(|b| before_stretch() > b);
            if !still_recovering {
                return Err(DivergenceReason::Speed);
            }
        }
        if let Some(bound) = self.max_energy
            && (measured.energy.is_nan() || measured.energy > bound)
        {
            return Err(DivergenceReason::Energy);
        }
        Ok((measured, still_recovering))
    }
}

/// What to do with a step that fails the guard.
#[derive(Reflect, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GuardPolicy {
    /// Restore the state from before the step and stop.
    Pause,
    /// Restore the state and retry the step as `2^h` substeps of `dt/2^h`,
    /// for `h = 1 ..= max_halvings`; stop if the last try fails too.
    Retry {
        /// Most halvings tried (each doubles the work of the retry).
        max_halvings: u8,
    },
}

impl Default for GuardPolicy {
    /// Retry with up to 4 halvings (16 substeps).
    fn default() -> Self {
        Self::Retry { max_halvings: 4 }
    }
}

/// A step the guard accepted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GuardedStep {
    /// The report of the last (sub)step.
    pub report: StepReport,
    /// Substeps the step took: 1, or `2^h` after `h` halvings.
    pub substeps: u32,
    /// Why the full step failed, when it was retried.
    pub retried_because: Option<DivergenceReason>,
    /// What the guard's check measured on the final state.
    pub measured: Measured,
}

impl GuardedStep {
    /// The share of the step over which the method last moved each vertex
    /// in a straight line, at its velocity, when that is less than the
    /// whole step: `stiff`'s last substep (of the guard's last retry
    /// substep, if it split the step). `None` for a method that takes the
    /// step whole: the projection after the step then sweeps each vertex
    /// from where the step began ([`Sweep`](crate::collision::Sweep)).
    pub fn last_substep(&self) -> Option<f32> {
        (self.report.substeps > 1)
            .then(|| 1.0 / (self.report.substeps as f32 * self.substeps.max(1) as f32))
    }
}

/// Why [`guarded_step`] gave up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GuardError {
    /// The step was refused for its input (parameters, state size); the state
    /// is untouched. Not a divergence: it is not retried.
    Refused(StepError),
    /// Every try failed; the state is the one from before the step.
    Diverged {
        /// Why the first try failed.
        reason: DivergenceReason,
        /// Halvings tried after it.
        halvings: u8,
    },
}

/// What the guard remembers of a cloth between steps: how many halvings its
/// steps currently take.
///
/// A step that needed `h` halvings is followed by steps of `h + 1` halvings
/// (the first count that passes is at the edge of stability; one more gives
/// a margin), up to the policy's limit. After [`RELAX_AFTER`] steps in a row
/// pass, one halving is dropped again, so a cloth that was hit hard once goes
/// back to full steps.
#[derive(Reflect, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GuardMemory {
    /// Halvings the next step starts with.
    pub halvings: u8,
    /// Steps in a row that passed at the current level.
    pub calm_steps: u32,
    /// The cloth is recovering from something done to it (a step began
    /// beyond the stretch bound: a pin teleported far away) and still moves
    /// faster than [`GuardBounds::speed_bound`]: the speed bound waits until
    /// it has slowed down.
    pub recovering: bool,
}

/// Steps in a row that must pass before [`GuardMemory`] drops one halving.
pub const RELAX_AFTER: u32 = 600;

/// Runs `step` (one step of some method over `params.dt`) under the guard.
///
/// `backup` is scratch for the state before the step (reused, so no
/// allocation once sized). On failure `state` is restored from it; see the
/// [module docs](self). `memory` carries the number of halvings from step to
/// step (see [`GuardMemory`]).
#[allow(clippy::too_many_arguments)]
pub fn guarded_step<F>(
    bounds: &GuardBounds,
    policy: GuardPolicy,
    memory: &mut GuardMemory,
    model: &ClothModel,
    state: &mut ClothState,
    backup: &mut ClothState,
    params: &StepParams,
    mut step: F,
) -> Result<GuardedStep, GuardError>
where
    F: FnMut(&mut ClothState, &StepParams) -> Result<StepReport, StepError>,
{
    bounds
        .validate()
        .map_err(|e| GuardError::Refused(e.into()))?;
    let max_halvings = match policy {
        GuardPolicy::Pause => 0,
        GuardPolicy::Retry { max_halvings } => max_halvings.min(20),
    };
    let start = memory.halvings.min(max_halvings);
    backup.copy_from(state);
    let check = Check {
        bounds,
        model,
        recovering: memory.recovering,
    };
    let first = match try_level(&check, state, backup, params, start, &mut step) {
        Ok((report, measured, recovering)) => {
            memory.recovering = recovering;
            memory.halvings = start;
            memory.calm_steps += 1;
            if memory.calm_steps >= RELAX_AFTER && memory.halvings > 0 {
                memory.halvings -= 1;
                memory.calm_steps = 0;
            }
            return Ok(GuardedStep {
                report,
                substeps: 1 << start,
                retried_because: None,
                measured,
            });
        }
        Err(Failure::Refused(e)) => {
            state.copy_from(backup);
            return Err(GuardError::Refused(e));
        }
        Err(Failure::Diverged(reason)) => reason,
    };
    for h in start + 1..=max_halvings {
        state.copy_from(backup);
        if let Ok((report, measured, recovering)) =
            try_level(&check, state, backup, params, h, &mut step)
        {
            memory.recovering = recovering;
            memory.halvings = (h + 1).min(max_halvings);
            memory.calm_steps = 0;
            return Ok(GuardedStep {
                report,
                substeps: 1 << h,
                retried_because: Some(first),
                measured,
            });
        }
    }
    state.copy_from(backup);
    Err(GuardError::Diverged {
        reason: first,
        halvings: max_halvings.saturating_sub(start),
    })
}

/// What a try checks its substeps against: the bounds, and whether the
/// cloth was recovering before the step (see [`GuardMemory::recovering`]).
struct Check<'a> {
    bounds: &'a GuardBounds,
    model: &'a ClothModel,
    recovering: bool,
}

/// `2^halvings` substeps of `dt / 2^halvings`; with what the last one
/// measured and whether the cloth is still recovering after it.
fn try_level<F>(
    check: &Check,
    state: &mut ClothState,
    before: &ClothState,
    params: &StepParams,
    halvings: u8,
    step: &mut F,
) -> Result<(StepReport, Measured, bool), Failure>
where
    F: FnMut(&mut ClothState, &StepParams) -> Result<StepReport, StepError>,
{
    let substeps = 1u32 << halvings;
    let sub = StepParams {
        dt: params.dt / f64::from(substeps),
        ..*params
    };
    try_substeps(check, state, before, &sub, substeps, step)
}

enum Failure {
    Refused(StepError),
    Diverged(DivergenceReason),
}

fn try_substeps<F>(
    check: &Check,
    state: &mut ClothState,
    before: &ClothState,
    params: &StepParams,
    substeps: u32,
    step: &mut F,
) -> Result<(StepReport, Measured, bool), Failure>
where
    F: FnMut(&mut ClothState, &StepParams) -> Result<StepReport, StepError>,
{
    let mut last = (StepReport::default(), Measured::default(), check.recovering);
    for _ in 0..substeps {
        let report = match step(state, params) {
            Ok(report) => report,
            Err(StepError::Solve(_)) => {
                return Err(Failure::Diverged(DivergenceReason::SolveFailed));
            }
            Err(e) => return Err(Failure::Refused(e)),
        };
        let (measured, recovering) = check
            .bounds
            .check_recovering(check.model, state, before, params, last.2)
            .map_err(Failure::Diverged)?;
        last = (report, measured, recovering);
    }
    Ok(last)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::ClothBuilder;
    use crate::solver::symplectic::{SymplecticSolver, SymplecticWorkspace};
    use crate::solver::{Method, energy};
    use bevy::math::{Affine3A, Vec3A};

    fn lab() -> (ClothModel, ClothState) {
        let model = ClothBuilder::lab().build().unwrap();
        let state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        (model, state)
    }

    #[test]
    fn an_unstable_explicit_step_is_caught_before_it_is_absurd_and_restored() {
        let (model, mut state) = lab();
        let mut backup = ClothState::default();
        let mut ws = SymplecticWorkspace::default();
        let params = StepParams::LAB; // far past the explicit limit
        let mut caught = None;
        for n in 0..200 {
            let before = state.clone();
            let r = guarded_step(
                &GuardBounds::default(),
                GuardPolicy::Pause,
                &mut GuardMemory::default(),
                &model,
                &mut state,
                &mut backup,
                &params,
                |s, p| Method::step(&SymplecticSolver, &model, s, p, &[], &mut ws),
            );
            if let Err(e) = r {
                assert_eq!(state, before, "restored");
                caught = Some((n, e));
                break;
            }
        }
        let (n, e) = caught.expect("symplectic Euler at the lab's dt diverges");
        assert_eq!(
            e,
            GuardError::Diverged {
                reason: DivergenceReason::Stretch,
                halvings: 0
            }
        );
        assert!(n > 0, "the first steps from rest are fine");
        assert!(max_stretch(&model, &state.positions) <= 10.0);
    }

    #[test]
    fn halving_rescues_an_explicit_step_just_past_its_limit() {
        let (model, mut state) = lab();
        let mut backup = ClothState::default();
        let mut ws = SymplecticWorkspace::default();
        // The lab cloth's explicit limit is about 2/sqrt(8·8000) ≈ 0.008 s.
        let params = StepParams {
            dt: 0.012,
            ..StepParams::LAB
        };
        let mut substeps = Vec::new();
        let mut memory = GuardMemory::default();
        for _ in 0..300 {
            let r = guarded_step(
                &GuardBounds::default(),
                GuardPolicy::default(),
                &mut memory,
                &model,
                &mut state,
                &mut backup,
                &params,
                |s, p| Method::step(&SymplecticSolver, &model, s, p, &[], &mut ws),
            )
            .expect("halving keeps it stable");
            substeps.push(r.substeps);
        }
        assert!(substeps.iter().any(|&s| s > 1), "some steps were retried");
        // After the first retry the guard keeps a margin: later steps start
        // with the extra halving and need no retry.
        assert_eq!(memory.halvings, 2);
        assert_eq!(substeps.last(), Some(&4));
        assert!(state.is_finite());
        assert!(max_stretch(&model, &state.positions) < 1.0);
    }

    #[test]
    fn bad_input_is_refused_not_retried() {
        let (model, mut state) = lab();
        let mut backup = ClothState::default();
        let mut calls = 0;
        let params = StepParams {
            dt: -1.0,
            ..StepParams::LAB
        };
        let mut ws = SymplecticWorkspace::default();
        let r = guarded_step(
            &GuardBounds::default(),
            GuardPolicy::default(),
            &mut GuardMemory::default(),
            &model,
            &mut state,
            &mut backup,
            &params,
            |s, p| {
                calls += 1;
                Method::step(&SymplecticSolver, &model, s, p, &[], &mut ws)
            },
        );
        assert!(matches!(
            r,
            Err(GuardError::Refused(StepError::Params(
                ParamError::TimeStep(_)
            )))
        ));
        assert_eq!(calls, 1);
        let bad = GuardBounds {
            max_stretch: Some(f32::NAN),
            ..GuardBounds::default()
        };
        assert!(bad.validate().is_err());
        let bad = GuardBounds {
            load_factor: Some(-1.0),
            ..GuardBounds::default()
        };
        assert!(bad.validate().is_err());
    }

    #[test]
    fn the_energy_bound_trips_when_set() {
        let (model, state) = lab();
        let params = StepParams::LAB;
        let e = energy(&model, &state, &params);
        let tight = GuardBounds {
            max_energy: Some(e - 1.0),
            ..GuardBounds::FINITE_ONLY
        };
        assert_eq!(
            tight.check(&model, &state, &state, &params),
            Err(DivergenceReason::Energy)
        );
        // Without bounds only non-finite values fail, and the measures come
        // back all the same.
        let measured = GuardBounds::FINITE_ONLY
            .check(&model, &state, &state, &params)
            .unwrap();
        assert_eq!(measured.energy, e);
        assert_eq!(measured.max_stretch, max_stretch(&model, &state.positions));
    }

    #[test]
    fn a_cloth_flung_far_faster_than_its_fall_is_caught_by_the_speed_bound() {
        let (model, state) = lab();
        let params = StepParams::LAB;
        let bounds = GuardBounds::default();
        // Lab cloth: √(2·9.8·14.1)·10 + 14.1/0.0333 ≈ 590 m/s.
        let limit = bounds.speed_bound(&model, &params, 0.0).unwrap();
        assert!((550.0..650.0).contains(&limit), "{limit}");
        // No spring stretched (a rigid motion of the free vertices), so only
        // the speed can tell.
        let flung = |speed: f32| {
            let mut s = state.clone();
            for (v, &pinned) in s.velocities.iter_mut().zip(model.pinned()) {
                if !pinned {
                    *v = Vec3A::new(0.0, 0.0, speed);
                }
            }
            s
        };
        let fast = flung(1.5 * limit);
        assert_eq!(
            bounds.check(&model, &fast, &state, &params),
            Err(DivergenceReason::Speed)
        );
        let before_the_change = GuardBounds {
            speed_factor: None,
            ..bounds
        };
        assert!(
            before_the_change
                .check(&model, &fast, &state, &params)
                .is_ok()
        );
        // A swing well inside it passes, and so does the same speed when the
        // pins move that fast (the cloth is carried).
        assert!(
            bounds
                .check(&model, &flung(0.5 * limit), &state, &params)
                .is_ok()
        );
        let mut carried = fast.clone();
        carried
            .velocities
            .iter_mut()
            .for_each(|v| *v = Vec3A::new(0.0, 0.0, 1.5 * limit));
        assert!(bounds.check(&model, &carried, &state, &params).is_ok());
        // And when a collider moved that fast (it may have thrown the cloth).
        let pushed = StepParams {
            collider_speed: 1.5 * limit,
            ..params
        };
        assert!(bounds.check(&model, &fast, &state, &pushed).is_ok());
        // A cloth without pins falls as fast as gravity makes it.
        let free = ClothBuilder::lab().with_pins([]).build().unwrap();
        assert_eq!(bounds.speed_bound(&free, &params, 0.0), None);
        assert!(bounds.check(&free, &fast, &state, &params).is_ok());
        // A bad factor is refused.
        let bad = GuardBounds {
            speed_factor: Some(f32::NAN),
            ..bounds
        };
        assert!(bad.validate().is_err());
        assert!(DivergenceReason::Speed.to_string().contains("flying apart"));
    }

    #[test]
    fn the_speed_bound_leaves_the_lab_cloth_falling_onto_its_pins_alone() {
        // Soft and heavy at the lab's step: the fastest swing the guard must
        // let through, under the implicit method with its default bounds.
        let (model, mut state) = lab();
        let params = StepParams::LAB;
        let mut backup = ClothState::default();
        let mut ws = crate::solver::implicit::ImplicitWorkspace::default();
        let method = crate::solver::implicit::ImplicitSolver::default();
        let mut memory = GuardMemory::default();
        for _ in 0..300 {
            guarded_step(
                &GuardBounds::default(),
                GuardPolicy::Pause,
                &mut memory,
                &model,
                &mut state,
                &mut backup,
                &params,
                |s, p| Method::step(&method, &model, s, p, &[], &mut ws),
            )
            .unwrap();
        }
    }

    #[test]
    fn a_cloth_recovering_from_a_teleported_pin_may_move_fast_until_it_slows_down() {
        let (model, rest) = lab();
        let params = StepParams::LAB;
        let bounds = GuardBounds::default();
        let limit = bounds.speed_bound(&model, &params, 0.0).unwrap();
        // A pin teleported 100 units away: the spring at it far beyond the
        // stretch bound before the step.
        let mut state = rest.clone();
        let pin = model.pins()[0] as usize;
        state.positions[pin].x += 100.0;
        let (mut backup, mut memory) = (ClothState::default(), GuardMemory::default());
        // A "step" that leaves the positions and sets every free speed.
        let mut step_at = |state: &mut ClothState, memory: &mut GuardMemory, speed: f32| {
            guarded_step(
                &bounds,
                GuardPolicy::Pause,
                memory,
                &model,
                state,
                &mut backup,
                &params,
                |s, _| {
                    for (v, &pinned) in s.velocities.iter_mut().zip(model.pinned()) {
                        if !pinned {
                            *v = Vec3A::new(speed, 0.0, 0.0);
                        }
                    }
                    Ok(StepReport::default())
                },
            )
        };
        assert!(step_at(&mut state, &mut memory, 2.0 * limit).is_ok());
        assert!(memory.recovering);
        // Pulled back within the bound, still fast: still recovering.
        state.positions[pin] = rest.positions[pin];
        assert!(step_at(&mut state, &mut memory, 2.0 * limit).is_ok());
        assert!(memory.recovering);
        // Slowed down: recovered; fast again is now a wreck.
        assert!(step_at(&mut state, &mut memory, 0.5 * limit).is_ok());
        assert!(!memory.recovering);
        assert_eq!(
            step_at(&mut state, &mut memory, 2.0 * limit),
            Err(GuardError::Diverged {
                reason: DivergenceReason::Speed,
                halvings: 0
            })
        );
    }
}
