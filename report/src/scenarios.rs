//! Stiff and extreme cases: run a method through a [`Scenario`] under the
//! divergence guard and classify the result against the exact method.
//!
//! A run ends in one of four [`Verdict`]s:
//!
//! - **correct**: finite, and close to the exact implicit-Euler run of the
//!   same scenario: the lowest point within 10 % of how far the exact run's
//!   lowest point moved (or of 1 % of the cloth's size, if more), and the
//!   largest spring stretch within `0.02 + 10 %` of the exact run's;
//! - **finite but wrong**: finite and inside the guard's bounds, but not
//!   close (the verdict says by how much): an iteration that has not
//!   converged, or PBD stretching beyond its rest lengths;
//! - **caught**: the guard rejected a step (non-finite, beyond its bounds,
//!   or a failed solve) and stopped the cloth at its last good state;
//! - **failed**: the method panicked, or refused valid input, or its final
//!   state is not finite although the guard passed it. Never expected.
//!
//! PBD has no stiffness (it restores rest lengths), so its reference is the
//! exact run with springs of `k = 1e6` per unit mass, nearly inextensible.
//!
//! The guard runs with [`GuardPolicy::Pause`] here, so a divergence is seen
//! rather than rescued by halving.

use std::panic::{AssertUnwindSafe, catch_unwind};

use bevy::math::{Affine3A, Vec3, Vec3A};

use bevy_cloth::collision::{Capsule, PenaltySphere, Shape, project_shapes};
use bevy_cloth::methods::{AnyMethod, AnyWorkspace, PRESETS};
use bevy_cloth::model::{ClothBuilder, ClothModel, ClothState};
use bevy_cloth::solver::exact::ExactSolver;
use bevy_cloth::solver::guard::{
    DivergenceReason, GuardBounds, GuardError, GuardMemory, GuardPolicy, guarded_step,
};
use bevy_cloth::solver::linear::SpringJacobian;
use bevy_cloth::solver::{
    CONVERGENCE_TOLERANCE, ProjectedConvergence, SpringStiffness, StepInput, StepParams, energy,
    max_stretch,
};

/// Something that happens to the scene at the start of a step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// Every pinned vertex jumps by `by` (a pinned entity teleported).
    MovePins {
        /// Step at which it happens.
        at_step: usize,
        /// The displacement.
        by: Vec3A,
    },
    /// Penalty sphere `index` jumps to `to`.
    MoveSphere {
        /// Step at which it happens.
        at_step: usize,
        /// Which sphere.
        index: usize,
        /// Its new centre.
        to: Vec3A,
    },
}

/// A cloth, its parameters and what happens to it, for a number of steps.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Short name.
    pub name: String,
    /// The cloth.
    pub model: ClothModel,
    /// Its parameters.
    pub params: StepParams,
    /// Penalty spheres acting on it.
    pub spheres: Vec<PenaltySphere>,
    /// Solids the cloth is projected out of after every step (as the
    /// plugin's colliders are), and which the `stiff` method projects
    /// inside its substeps too.
    pub contacts: Vec<Shape>,
    /// Steps to run.
    pub steps: usize,
    /// Events, in any order.
    pub events: Vec<Event>,
    /// The guard's bounds for this scenario.
    pub bounds: GuardBounds,
    /// The state it starts from; `None` is the rest shape, at rest.
    pub start: Option<ClothState>,
    /// Record a [`Sample`] after every this many steps (0: none).
    pub record_every: usize,
}

impl Scenario {
    /// The lab's 21×21 cloth (mass 1 per vertex, pinned at two corners) with
    /// stiffness `k` and time step `dt`, run for `min(⌈1 s/dt⌉, 300)` steps.
    pub fn lab(k: f32, dt: f64) -> Self {
        Self::grid(21, k, dt).named(format!("lab k={k:e} dt={dt}"))
    }

    /// The lab's cloth at `n×n` vertices (same 10×10 size, mass 1 per vertex,
    /// so heavier as `n` grows, pinned at two corners).
    pub fn grid(n: usize, k: f32, dt: f64) -> Self {
        let model = ClothBuilder::lab_grid(n)
            .with_pins([0, n as u32 - 1])
            .build()
            .expect("a valid grid");
        Self {
            name: format!("grid {n}² k={k:e} dt={dt}"),
            model,
            params: StepParams {
                dt,
                stiffness: SpringStiffness::uniform(k),
                ..StepParams::LAB
            },
            spheres: Vec::new(),
            contacts: Vec::new(),
            steps: ((1.0 / dt).ceil() as usize).clamp(1, 300),
            events: Vec::new(),
            bounds: GuardBounds::default(),
            start: None,
            record_every: 0,
        }
    }

    /// The lab's cloth falling onto the lab's sphere (radius 2.7 at
    /// (0, −4, 4), projection, frictionless: the headless example's
    /// `--sphere`) and resting there, for `seconds` of simulated time.
    pub fn on_sphere(k: f32, dt: f64, seconds: f64) -> Self {
        let mut s = Self::grid(21, k, dt).named(format!("on the sphere k={k:e} dt={dt}"));
        s.contacts.push(Shape::Capsule(Capsule {
            a: Vec3A::new(0.0, -4.0, 4.0),
            b: Vec3A::new(0.0, -4.0, 4.0),
            radius: 2.7,
            friction: 0.0,
        }));
        s.steps = (seconds / dt).round().max(1.0) as usize;
        s
    }

    /// This scenario under another name.
    pub fn named(mut self, name: impl Into<String>) -> Self {
        self.name = name.into();
        self
    }

    /// This scenario recording a [`Sample`] after every step.
    pub fn recorded(mut self) -> Self {
        self.record_every = 1;
        self
    }

    /// This scenario run for `steps` steps.
    pub fn with_steps(mut self, steps: usize) -> Self {
        self.steps = steps;
        self
    }

    /// The stiff and extreme cases of the stability tests, on the lab cloth
    /// at its time step unless said otherwise; `large` is the side of the
    /// large grid (301 in the map, smaller in debug test runs).
    pub fn extreme_cases(large: usize) -> Vec<Self> {
        let lab = || Self::lab(8000.0, StepParams::LAB.dt).with_steps(60);
        let mut cases = Vec::new();
        for k in [1e1, 1e8] {
            cases.push(Self::lab(k, StepParams::LAB.dt).named(format!("stiffness {k:e}")));
        }
        for dt in [1e-4, 0.1] {
            cases.push(Self::lab(8000.0, dt).named(format!("time step {dt}")));
        }
        // Neighbours alternate between 1 and 1e-6 kg.
        let mut heavy_light = lab();
        let masses = (0..21 * 21)
            .map(|v| {
                if (v / 21 + v % 21) % 2 == 0 {
                    1.0
                } else {
                    1e-6
                }
            })
            .collect();
        heavy_light.model = ClothBuilder::lab_grid(21)
            .with_masses(masses)
            .with_pins([0, 20])
            .build()
            .expect("valid masses");
        cases.push(heavy_light.named("mass ratio 1e6"));
        let mut gravity = lab();
        gravity.params.gravity = Vec3::new(0.0, -1e4, 0.0);
        // The exact answer stretches the top springs about 500-fold (the
        // sheet's weight, 4.4e6 N, on springs of 8000 N/m), so the stretch
        // bound is raised past that.
        gravity.bounds.max_stretch = Some(1e4);
        cases.push(gravity.named("gravity 1e4"));
        // The lab's sphere, first below the cloth, then jumped to the middle
        // of the hanging sheet.
        let mut sphere = lab();
        sphere.spheres.push(PenaltySphere {
            center: Vec3A::new(0.0, -20.0, 0.0),
            radius: 2.7,
            stiffness: 1e4,
            surface: Default::default(),
        });
        sphere.events.push(Event::MoveSphere {
            at_step: 30,
            index: 0,
            to: Vec3A::new(0.0, -3.0, 2.0),
        });
        cases.push(sphere.named("sphere teleported into the cloth"));
        let mut pins = lab();
        pins.events.push(Event::MovePins {
            at_step: 30,
            by: Vec3A::new(100.0, 0.0, 0.0),
        });
        // The jump stretches the springs at the pins 200-fold, and the cloth
        // overshoots as it catches up (the exact method too), so the bound
        // is raised past that, and the load bound (which would bind first)
        // is off. So is the speed bound: within the raised bound the jump is
        // not a recovery the guard would wait for, and the cloth flies 100
        // units in a few steps.
        pins.bounds.max_stretch = Some(1e3);
        pins.bounds.load_factor = None;
        pins.bounds.speed_factor = None;
        cases.push(pins.named("pins moved 100 units"));
        // The grid sheared until its triangles have a millionth of their
        // area: every spring keeps a normal length.
        let mut sliver = lab();
        sliver.model = ClothBuilder::grid(
            21,
            21,
            Vec3::new(-5.0, 0.0, 0.0),
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(5.0, 0.0, 1e-5),
        )
        .with_pins([0, 20])
        .build()
        .expect("a valid sheared grid");
        cases.push(sliver.named("near-zero-area triangles"));
        cases.push(
            Self::grid(2, 8000.0, StepParams::LAB.dt)
                .with_steps(60)
                .named("2×2"),
        );
        cases.push(
            Self::grid(large, 8000.0, StepParams::LAB.dt)
                .with_steps(10)
                .named(format!("{large}×{large}")),
        );
        let mut falling = lab().with_steps(1500);
        falling.model = ClothBuilder::lab_grid(21).build().expect("valid");
        cases.push(falling.named("no pins, falling for 50 s"));
        cases
    }

    fn reference_params(&self, method: &AnyMethod) -> StepParams {
        match method {
            AnyMethod::Pbd(_) => {
                let mean_mass = self
                    .model
                    .masses()
                    .iter()
                    .map(|&m| f64::from(m))
                    .sum::<f64>()
                    / self.model.vertex_count() as f64;
                StepParams {
                    stiffness: SpringStiffness::uniform((1e6 * mean_mass) as f32),
                    ..self.params
                }
            }
            _ => self.params,
        }
    }
}

/// The methods of the stability map: every preset at its interactive
/// setting ([`PRESETS`]: 32 iterations for the iterative lab methods, CG with
/// 25, the linearly implicit methods with clamped spring blocks, the exact
/// method), and the linearly implicit methods again with the assignment's
/// exact spring blocks.
pub fn map_methods() -> Vec<AnyMethod> {
    let mut methods: Vec<AnyMethod> = PRESETS.iter().map(|p| p.method).collect();
    methods.extend(PRESETS.iter().filter_map(|p| match p.method {
        AnyMethod::Linear(l) => Some(AnyMethod::Linear(l.with_springs(SpringJacobian::Exact))),
        _ => None,
    }));
    methods
}

/// The methods of the map's contact section: [`map_methods`], then `stiff`
/// with its chains of stretch springs solved whole
/// ([`XpbdSolver::chains`](bevy_cloth::solver::xpbd::XpbdSolver::chains),
/// off in the preset), whose reach the contact cases show (a ball carrying a
/// sheet, layers pressed together) and the map's other cases would not.
pub fn contact_methods() -> Vec<AnyMethod> {
    let mut methods = map_methods();
    methods.extend(PRESETS.iter().filter_map(|p| match p.method {
        AnyMethod::Xpbd(x) => Some(AnyMethod::Xpbd(x.with_chains(true))),
        _ => None,
    }));
    methods
}

/// The end of one run.
#[derive(Clone, Debug)]
pub struct Run {
    /// The final state (the last good one if the guard stopped the run).
    pub state: ClothState,
    /// Steps completed.
    pub steps: usize,
    /// The guard's stop: the step at which it happened and why.
    pub caught: Option<(usize, DivergenceReason)>,
    /// Why the run failed (a panic, or valid input refused).
    pub failed: Option<String>,
    /// Largest energy seen after any step, minus the energy at the start.
    pub energy_rise: f64,
    /// Largest [`relative_error`](bevy_cloth::solver::StepReport::relative_error)
    /// of any step, for the methods that report one.
    pub max_relative_error: Option<f32>,
    /// Steps whose relative error exceeded
    /// [`CONVERGENCE_TOLERANCE`]: what raises the plugin's
    /// `ClothNotConverged`.
    pub unconverged_steps: usize,
    /// What the scenario asked to record ([`Scenario::record_every`]).
    pub samples: Vec<Sample>,
}

/// The cloth after some step of a recorded run.
#[derive(Clone, Debug)]
pub struct Sample {
    /// Vertex positions.
    pub positions: Vec<Vec3A>,
    /// The largest spring stretch.
    pub stretch: f32,
}

impl Sample {
    /// The mean height of the vertices.
    pub fn mean_height(&self) -> f64 {
        self.positions.iter().map(|p| f64::from(p.y)).sum::<f64>()
            / self.positions.len().max(1) as f64
    }
}

impl Run {
    /// True if the plugin would have flagged this run as not converged (at
    /// least one step beyond [`CONVERGENCE_TOLERANCE`]).
    pub fn flagged(&self) -> bool {
        self.unconverged_steps > 0
    }

    /// Lowest `y` of the final state.
    pub fn lowest(&self) -> f32 {
        self.state
            .positions
            .iter()
            .map(|p| p.y)
            .fold(f32::INFINITY, f32::min)
    }
}

/// Runs `method` through `scenario` under the guard (pause policy, the
/// scenario's bounds).
pub fn run(scenario: &Scenario, method: &AnyMethod) -> Run {
    run_with(scenario, method, &scenario.params)
}

fn run_with(scenario: &Scenario, method: &AnyMethod, params: &StepParams) -> Run {
    let bounds = &scenario.bounds.for_method(method.uses_stiffness());
    let model = &scenario.model;
    let mut state = scenario
        .start
        .clone()
        .unwrap_or_else(|| ClothState::at_rest(model, &Affine3A::IDENTITY));
    let mut run = Run {
        state: state.clone(),
        steps: 0,
        caught: None,
        failed: None,
        energy_rise: 0.0,
        max_relative_error: None,
        unconverged_steps: 0,
        samples: Vec::new(),
    };
    let e0 = energy(model, &state, params);
    let mut spheres = scenario.spheres.clone();
    let mut ws = AnyWorkspace::default();
    let mut backup = ClothState::default();
    let mut memory = GuardMemory::default();
    let mut convergence = ProjectedConvergence::default();
    let result = catch_unwind(AssertUnwindSafe(|| {
        for n in 0..scenario.steps {
            // A sphere moved this step moved that fast (the guard's speed
            // bound allows the cloth what a collider gives it).
            let mut step_params = *params;
            for event in &scenario.events {
                match *event {
                    Event::MovePins { at_step, by } if at_step == n => {
                        for &p in model.pins() {
                            state.positions[p as usize] += by;
                        }
                    }
                    Event::MoveSphere { at_step, index, to } if at_step == n => {
                        if let Some(s) = spheres.get_mut(index) {
                            let speed = (to - s.center).length() / params.dt as f32;
                            step_params.collider_speed = step_params.collider_speed.max(speed);
                            s.center = to;
                        }
                    }
                    _ => {}
                }
            }
            let r = guarded_step(
                bounds,
                GuardPolicy::Pause,
                &mut memory,
                model,
                &mut state,
                &mut backup,
                &step_params,
                |s, p| {
                    let input = StepInput {
                        model,
                        params: p,
                        spheres: &spheres,
                        contacts: &scenario.contacts,
                        contact_motion: &[],
                        skin: None,
                        self_collision: None,
                    };
                    method.step_with(input, s, &mut ws)
                },
            );
            // Judged after the projection, as the plugin judges it
            // (`ProjectedConvergence`).
            let mut judged = None;
            if let Ok(done) = &r {
                convergence.stepped(
                    done.report.relative_error,
                    done.substeps == 1,
                    CONVERGENCE_TOLERANCE,
                );
                if !scenario.contacts.is_empty() {
                    convergence.before_projection(&state.positions);
                    project_shapes(model, &mut state, &scenario.contacts, 0.0, params.dt as f32);
                }
                judged = convergence
                    .settle(model, &backup, &state.positions, &step_params)
                    .flatten();
            }
            match r {
                Ok(_) => {
                    if let Some(e) = judged {
                        run.max_relative_error =
                            Some(run.max_relative_error.map_or(e, |m| m.max(e)));
                        if e > CONVERGENCE_TOLERANCE {
                            run.unconverged_steps += 1;
                        }
                    }
                    run.steps = n + 1;
                    run.energy_rise = run.energy_rise.max(energy(model, &state, params) - e0);
                    if scenario.record_every > 0 && run.steps.is_multiple_of(scenario.record_every)
                    {
                        run.samples.push(Sample {
                            positions: state.positions.clone(),
                            stretch: max_stretch(model, &state.positions),
                        });
                    }
                }
                Err(GuardError::Diverged { reason, .. }) => {
                    run.caught = Some((n, reason));
                    break;
                }
                Err(GuardError::Refused(e)) => {
                    run.failed = Some(format!("refused: {e}"));
                    break;
                }
            }
        }
    }));
    run.failed = ended(result, run.failed, &state);
    run.state = state;
    run
}

/// A caught panic's message: `panicked: ` and its text.
pub(crate) fn panicked(panic: &(dyn std::any::Any + Send)) -> String {
    let text = panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_default();
    format!("panicked: {text}")
}

/// Why a run that ended with `result` (the run inside `catch_unwind`) and
/// `failed` at `state` failed: the panic's text, the failure it gave, or a
/// non-finite state the guard let through; `None` for a run that did not.
pub(crate) fn ended(
    result: std::thread::Result<()>,
    failed: Option<String>,
    state: &ClothState,
) -> Option<String> {
    match result {
        Err(panic) => Some(panicked(&*panic)),
        Ok(()) if failed.is_none() && !state.is_finite() => {
            Some("non-finite state passed the guard".into())
        }
        Ok(()) => failed,
    }
}

/// How a run ended; see the [module docs](self).
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// Close to the exact run.
    Correct,
    /// Finite but not close to the exact run.
    Wrong {
        /// `|lowest − lowest*|` over how far the exact run's lowest point
        /// moved (at least 1 % of the cloth's size).
        lowest: f64,
        /// `|max stretch − max stretch*|`.
        stretch: f64,
    },
    /// Stopped by the guard.
    Caught {
        /// At which step.
        step: usize,
        /// Why.
        reason: DivergenceReason,
    },
    /// Panicked, refused valid input, or let a non-finite state through.
    Failed(String),
    /// Finite, but the exact run (the reference) was itself stopped, so there
    /// is nothing to compare with.
    NoReference,
}

impl Verdict {
    /// One word: `correct`, `wrong`, `caught`, `failed`, `no reference`.
    pub fn class(&self) -> &'static str {
        match self {
            Self::Correct => "correct",
            Self::Wrong { .. } => "wrong",
            Self::Caught { .. } => "caught",
            Self::Failed(_) => "failed",
            Self::NoReference => "no reference",
        }
    }
}

/// One classified run.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The method's label ([`AnyMethod::name`]).
    pub method: String,
    /// The verdict.
    pub verdict: Verdict,
    /// The run.
    pub run: Run,
    /// Its largest spring stretch at the end.
    pub max_stretch: f32,
    /// The floor of its reference, when judged against the physical one.
    pub floor: Option<Floor>,
}

/// Classifies `run` of `method` against `reference` (the exact method's run
/// of the same scenario; for PBD, of the stiff scenario: see
/// [`reference_for`]).
pub fn classify(scenario: &Scenario, method: &AnyMethod, run: Run, reference: &Run) -> Outcome {
    classify_within(scenario, method, run, reference, None)
}

/// How far a reference is from itself at half its step: what a comparison
/// with it cannot resolve, added to the verdict's tolerances.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Floor {
    /// The lowest point's difference, relative as in [`Verdict::Wrong`].
    pub lowest: f64,
    /// The max-stretch difference.
    pub stretch: f64,
}

/// The lowest point's error relative to how far `reference`'s lowest point
/// moved (at least 1 % of the cloth's size), and the max-stretch difference.
fn differences(model: &ClothModel, run: &Run, reference: &Run) -> (f64, f64) {
    let rest_low = model
        .topology()
        .rest_positions()
        .iter()
        .map(|p| p.y)
        .fold(f32::INFINITY, f32::min);
    let size = extent(model);
    let moved = f64::from((reference.lowest() - rest_low).abs()).max(0.01 * size);
    let lowest = f64::from((run.lowest() - reference.lowest()).abs()) / moved;
    let stretch = f64::from(max_stretch(model, &run.state.positions));
    let ref_stretch = f64::from(max_stretch(model, &reference.state.positions));
    (lowest, (stretch - ref_stretch).abs())
}

/// [`classify`] with the reference's own [`Floor`], if it has one, added
/// to the tolerances.
pub fn classify_within(
    scenario: &Scenario,
    method: &AnyMethod,
    run: Run,
    reference: &Run,
    floor: Option<Floor>,
) -> Outcome {
    let model = &scenario.model;
    let slack = floor.unwrap_or_default();
    let stretch = max_stretch(model, &run.state.positions);
    let verdict = if let Some(f) = &run.failed {
        Verdict::Failed(f.clone())
    } else if let Some((step, reason)) = run.caught {
        Verdict::Caught { step, reason }
    } else if reference.caught.is_some() || reference.failed.is_some() {
        Verdict::NoReference
    } else {
        let (lowest, stretch_err) = differences(model, &run, reference);
        let ref_stretch = f64::from(max_stretch(model, &reference.state.positions));
        if lowest <= 0.1 + slack.lowest
            && stretch_err <= 0.02 + 0.1 * ref_stretch.abs() + slack.stretch
        {
            Verdict::Correct
        } else {
            Verdict::Wrong {
                lowest,
                stretch: stretch_err,
            }
        }
    };
    Outcome {
        method: crate::variant(method),
        verdict,
        run,
        max_stretch: stretch,
        floor,
    }
}

/// The exact method's run that `method` is compared with.
pub fn reference_for(scenario: &Scenario, method: &AnyMethod) -> Run {
    let exact = AnyMethod::Exact(ExactSolver::REFERENCE);
    run_with(scenario, &exact, &scenario.reference_params(method))
}

/// The longest step of the physical reference: the exact method at the
/// scenario's step halved until it is at most this (1/960 s: 16 substeps of
/// a 60 Hz frame). Halving it once more moves the lab cloth's trajectory by
/// the [`Floor`] the map prints, which the verdicts against it allow for.
pub const PHYSICAL_STEP: f64 = 1.0 / 960.0;

/// The largest cloth (in vertices) judged against the physical reference:
/// the exact method at a step 32–128 times smaller costs minutes beyond it.
pub const PHYSICAL_MAX_VERTICES: usize = 51 * 51;

impl Scenario {
    /// This scenario with each step split into `m` (the same simulated time,
    /// the same damping per second, events at the same times).
    pub fn refined(&self, m: usize) -> Self {
        let mut s = self.clone();
        s.params.dt /= m as f64;
        s.params.damping = self.params.damping.powf(1.0 / m as f32);
        s.steps *= m;
        s.record_every *= m;
        for event in &mut s.events {
            match event {
                Event::MovePins { at_step, .. } | Event::MoveSphere { at_step, .. } => {
                    *at_step *= m
                }
            }
        }
        s
    }

    /// How many physical-reference steps make one of this scenario's
    /// (a power of two; see [`PHYSICAL_STEP`]).
    pub fn physical_split(&self) -> usize {
        let mut m = 1;
        while self.params.dt / m as f64 > PHYSICAL_STEP * (1.0 + 1e-9) {
            m *= 2;
        }
        m
    }
}

/// The physical reference of `scenario`: the exact method at its step split
/// by [`Scenario::physical_split`], and its floor (the same run at half
/// that step, compared with it).
pub fn physical_reference(scenario: &Scenario) -> (Run, Floor) {
    let exact = AnyMethod::Exact(ExactSolver::REFERENCE);
    let m = scenario.physical_split();
    let fine = scenario.refined(m);
    let finer = scenario.refined(2 * m);
    let reference = run(&fine, &exact);
    let half = run(&finer, &exact);
    let (lowest, stretch) = differences(&scenario.model, &half, &reference);
    (reference, Floor { lowest, stretch })
}

/// Whether `method` is judged against the physical reference on
/// `scenario`: the `stiff` method (XPBD does not solve implicit Euler, whose
/// large steps damp stiff cloth: the physics is its target) on cloths of at
/// most [`PHYSICAL_MAX_VERTICES`].
pub fn judged_physically(scenario: &Scenario, method: &AnyMethod) -> bool {
    matches!(method, AnyMethod::Xpbd(_)) && scenario.model.vertex_count() <= PHYSICAL_MAX_VERTICES
}

/// Runs and classifies every method of `methods` on `scenario` (the exact
/// references are computed once each; the `stiff` method against the
/// physical one where [`judged_physically`]).
pub fn sweep(scenario: &Scenario, methods: &[AnyMethod]) -> Vec<Outcome> {
    let mut exact_ref: Option<Run> = None;
    let mut stiff_ref: Option<Run> = None;
    let mut physical: Option<(Run, Floor)> = None;
    methods
        .iter()
        .map(|m| {
            if judged_physically(scenario, m) {
                let (reference, floor) =
                    physical.get_or_insert_with(|| physical_reference(scenario));
                let (reference, floor) = (reference.clone(), *floor);
                return classify_within(scenario, m, run(scenario, m), &reference, Some(floor));
            }
            let is_pbd = matches!(m, AnyMethod::Pbd(_));
            let slot = if is_pbd {
                &mut stiff_ref
            } else {
                &mut exact_ref
            };
            let reference = slot
                .get_or_insert_with(|| reference_for(scenario, m))
                .clone();
            let r = if *m == AnyMethod::Exact(ExactSolver::REFERENCE) {
                reference.clone()
            } else {
                run(scenario, m)
            };
            classify(scenario, m, r, &reference)
        })
        .collect()
}

/// The diagonal of the cloth's rest shape's bounding box.
pub fn extent(model: &ClothModel) -> f64 {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &p in model.topology().rest_positions() {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    f64::from((hi - lo).length())
}

/// The largest eigenvalue `ω_max²` of `M⁻¹K` for the free vertices at
/// positions `x` (`K` the springs' stiffness matrix with the
/// compression-clamped blocks, which equal the true ones for springs at
/// or beyond rest length), by power iteration from a fixed start vector;
/// `iterations` products, in `f64`.
///
/// `M⁻¹K` is similar to the symmetric `M^{-1/2} K M^{-1/2}`, so its
/// eigenvalues are real and the power iteration's Rayleigh quotient
/// converges to the largest.
pub fn omega_max_squared(
    model: &ClothModel,
    x: &[Vec3A],
    stiffness: &SpringStiffness,
    iterations: u32,
) -> f64 {
    use bevy::math::DVec3;
    let n = model.vertex_count();
    let pinned = model.pinned();
    let masses = model.masses();
    let k = stiffness.as_array();
    // Deterministic, non-smooth start (a smooth one barely excites the
    // highest mode).
    let mut v: Vec<DVec3> = (0..n)
        .map(|i| {
            if pinned[i] {
                DVec3::ZERO
            } else {
                let s = if (i * 7919) % 3 == 0 { 1.0 } else { -1.0 };
                DVec3::new(s, -0.5 * s, 0.25 + (i % 5) as f64 * 0.1)
            }
        })
        .collect();
    let mut w = vec![DVec3::ZERO; n];
    let mut lambda = 0.0;
    for _ in 0..iterations {
        // w = M⁻¹ K v, with K the positive semi-definite spring stiffness.
        w.iter_mut().for_each(|e| *e = DVec3::ZERO);
        for s in model.topology().springs() {
            let (a, b) = (s.a as usize, s.b as usize);
            let d = x[a].as_dvec3() - x[b].as_dvec3();
            let l = d.length();
            if l == 0.0 {
                continue;
            }
            let u = d / l;
            let kk = f64::from(k[s.kind as usize]);
            let t = (1.0 - f64::from(s.rest_length) / l).max(0.0);
            let dv = v[a] - v[b];
            // (k uuᵀ + k t (I − uuᵀ)) (v_a − v_b)
            let along = u * u.dot(dv);
            let f = kk * (along + t * (dv - along));
            w[a] += f;
            w[b] -= f;
        }
        let mut num = 0.0;
        let mut den = 0.0;
        for i in 0..n {
            if pinned[i] {
                w[i] = DVec3::ZERO;
                continue;
            }
            let m = f64::from(masses[i]);
            // Rayleigh quotient of the symmetric form: (vᵀ K v)/(vᵀ M v).
            num += v[i].dot(w[i]);
            den += m * v[i].length_squared();
            w[i] /= m;
        }
        if den > 0.0 {
            lambda = num / den;
        }
        let norm = w.iter().map(|e| e.length_squared()).sum::<f64>().sqrt();
        if norm == 0.0 {
            break;
        }
        for (vi, wi) in v.iter_mut().zip(&w) {
            *vi = *wi / norm;
        }
    }
    lambda
}

/// Symplectic Euler's predicted step limit `2/ω_max` (for damping `d` the
/// limit is `sqrt(2(1 + d))/ω_max`, within 0.3 % of it for the lab's 0.99).
pub fn explicit_limit(model: &ClothModel, x: &[Vec3A], stiffness: &SpringStiffness) -> f64 {
    2.0 / omega_max_squared(model, x, stiffness, 500).sqrt()
}

/// Symplectic Euler's largest stable time step on `scenario`, measured by
/// bisection between `lo` (stable) and `hi` (unstable): a step is stable if
/// `steps` steps from rest stay within the scenario's guard bounds.
/// `tolerance` is the relative width at which bisection stops.
pub fn measured_explicit_limit(
    scenario: &Scenario,
    mut lo: f64,
    mut hi: f64,
    steps: usize,
    tolerance: f64,
) -> f64 {
    while (hi - lo) / lo > tolerance {
        let mid = 0.5 * (lo + hi);
        let mut s = scenario.clone().with_steps(steps);
        s.params.dt = mid;
        let r = run(&s, &AnyMethod::Symplectic(Default::default()));
        if r.caught.is_none() && r.failed.is_none() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}
