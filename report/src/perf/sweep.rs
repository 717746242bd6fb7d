//! The scale sweep: every method from 21² to 256², many cloths in one app,
//! and the sparse CG step against its parts.

use std::time::{Duration, Instant};

use bevy::app::App;
use bevy::math::Affine3A;
use bevy::prelude::{Fixed, MinimalPlugins, Time, Transform, Virtual};
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::methods::{AnyMethod, AnyWorkspace, PRESETS};
use bevy_cloth::model::{ClothBuilder, ClothModel, ClothState};
use bevy_cloth::solver::Method;
use bevy_cloth::solver::guard::GuardBounds;
use bevy_cloth::solver::implicit::ImplicitSolver;
use bevy_cloth::solver::linear::{
    CgConfig, LinearImplicitSolver, LinearSystem, LinearWorkspace, SpringJacobian,
};
use bevy_cloth::solver::projective::{
    GlobalSolve, PD_ITERATIONS, ProjectiveSolver, ProjectiveWorkspace,
};
use bevy_cloth::solver::{LAB_ITERATIONS, LAB_RHO, Simd, SpringStiffness, StepParams};
use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::{Accum, MatMut, MatRef, Par};

use super::*;

/// The lab's cloth at `n×n` vertices, physically the same at every `n`
/// (see the module docs).
pub fn scale_model(n: usize) -> ClothModel {
    ClothBuilder::lab_grid(n)
        .with_total_mass(441.0)
        .with_pins([0, n as u32 - 1])
        .build()
        .expect("the lab grid is a valid cloth")
}

/// The swinging state every timed step starts from: 20 Chebyshev steps.
pub fn warm_state(model: &ClothModel, params: &StepParams) -> ClothState {
    let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
    let mut ws = AnyWorkspace::default();
    let method = AnyMethod::Implicit(ImplicitSolver::chebyshev(LAB_ITERATIONS, LAB_RHO));
    for _ in 0..20 {
        method
            .step(model, &mut state, params, &[], &mut ws)
            .expect("the lab cloth steps");
    }
    state
}

/// The methods of the scale sweep: every preset, with its table name
/// ([`crate::label`]) and whether it is sparse (a factorisation or sparse
/// assembly per step: capped at [`PerfConfig::max_side_sparse`]).
pub fn sweep_methods() -> Vec<(String, AnyMethod, bool)> {
    let mut methods: Vec<(String, AnyMethod, bool)> = PRESETS
        .iter()
        .map(|p| {
            let sparse = matches!(p.method, AnyMethod::Linear(_) | AnyMethod::Exact(_));
            (crate::label(&p.method), p.method, sparse)
        })
        .collect();
    // `pd` with its global solve always direct: what the automatic choice
    // of multigrid on large cloths is measured against; and `pd` running
    // its whole budget, without the early stop.
    let direct = AnyMethod::Projective(ProjectiveSolver::PRESET.with_global(GlobalSolve::Direct));
    let budget = AnyMethod::Projective(ProjectiveSolver::chebyshev(PD_ITERATIONS));
    let at = methods
        .iter()
        .position(|(_, m, _)| matches!(m, AnyMethod::Projective(_)))
        .map_or(methods.len(), |p| p + 1);
    methods.insert(at, (crate::label(&direct), direct, false));
    methods.insert(at + 1, (crate::label(&budget), budget, false));
    methods
}

/// One timed case of the scale sweep.
#[derive(Clone, Debug)]
pub struct Case {
    /// Table name of the method.
    pub method: String,
    /// The method and its settings.
    pub solver: AnyMethod,
    /// Grid side.
    pub n: usize,
    /// Single-thread time per step.
    pub serial: Timing,
    /// Time per step with the compute pool's threads, for methods with
    /// parallel chunked loops at sizes where they engage.
    pub parallel: Option<Timing>,
    /// `None` if the guard's default check passes on the timed step, else
    /// why it would have rejected it.
    pub guard: Option<String>,
}

/// Does `method` have loops that run in parallel chunks at this size?
fn has_parallel_loops(method: &AnyMethod, model: &ClothModel) -> bool {
    // Projective dynamics splits its three-column solve over two threads
    // when the factor is supernodal (faer picks it for the larger cloths).
    matches!(
        method,
        AnyMethod::Implicit(_) | AnyMethod::Symplectic(_) | AnyMethod::Projective(_)
    ) && model.topology().springs().len() >= bevy_cloth::solver::PARALLEL_MIN
}

/// Time slices per case in the scale sweep: each size's cases take turns,
/// a slice each per round, so that a slow phase of a shared machine falls
/// on every method of the size alike and their ratios stay fair.
pub const SWEEP_ROUNDS: u32 = 5;

/// One timed column of one method at one size.
struct Slot<'a> {
    case: usize,
    parallel: bool,
    params: StepParams,
    stepper: Stepper<'a>,
    samples: Vec<f64>,
    failed: Option<String>,
}

/// The scale sweep. At each size the cases are timed in
/// [`SWEEP_ROUNDS`] turns of `budget / SWEEP_ROUNDS` each (after two
/// warm-up steps), so each case still gets [`PerfConfig::budget`] and
/// [`PerfConfig::min_samples`] in all.
pub fn sweep(config: &PerfConfig, progress: impl Fn(&str)) -> Vec<Case> {
    let params = StepParams::LAB;
    let mut cases = Vec::new();
    for &n in &config.sizes {
        let model = scale_model(n);
        let start = warm_state(&model, &params);
        let mut slots = Vec::new();
        for (name, method, sparse) in sweep_methods() {
            if sparse && n > config.max_side_sparse
                || config
                    .only
                    .as_ref()
                    .is_some_and(|only| !name.starts_with(only.as_str()))
            {
                continue;
            }
            let case = cases.len();
            let columns = if has_parallel_loops(&method, &model) {
                &[false, true][..]
            } else {
                &[false][..]
            };
            for &parallel in columns {
                slots.push(Slot {
                    case,
                    parallel,
                    params: StepParams { parallel, ..params },
                    stepper: Stepper::new(method, &model, &start),
                    samples: Vec::new(),
                    failed: None,
                });
            }
            cases.push(Case {
                method: name,
                solver: method,
                n,
                // Filled in after the rounds.
                serial: Timing {
                    median: 0.0,
                    q1: 0.0,
                    q3: 0.0,
                    samples: 0,
                },
                parallel: None,
                guard: None,
            });
        }
        let slice = config.budget / SWEEP_ROUNDS;
        for round in 0..SWEEP_ROUNDS {
            progress(&format!("{n}²: round {} of {SWEEP_ROUNDS}", round + 1));
            let wanted =
                (config.min_samples.max(1) * (round as usize + 1)).div_ceil(SWEEP_ROUNDS as usize);
            for slot in &mut slots {
                let sample = |slot: &mut Slot| match slot.stepper.try_time(&slot.params) {
                    Ok(t) => t,
                    Err(e) => {
                        slot.failed.get_or_insert(e);
                        0.0
                    }
                };
                if round == 0 {
                    for _ in 0..2 {
                        sample(slot);
                    }
                }
                let begun = Instant::now();
                while slot.samples.len() < wanted || begun.elapsed() < slice {
                    let t = sample(slot);
                    slot.samples.push(t);
                }
            }
        }
        for slot in slots {
            let case = &mut cases[slot.case];
            let timing = Timing::of(slot.samples);
            if slot.parallel {
                case.parallel = Some(timing);
            } else {
                case.serial = timing;
                let state = &slot.stepper.state;
                case.guard = slot.failed.or_else(|| {
                    GuardBounds::default()
                        .check(&model, state, &start, &slot.params)
                        .err()
                        .map(|e| format!("{e:?}"))
                });
            }
        }
    }
    cases
}

/// One size of [`sphere_steps`].
#[derive(Clone, Debug)]
pub struct SphereRow {
    /// Grid side.
    pub n: usize,
    /// Time per step (one thread).
    pub step: Timing,
    /// Mean iterations per step.
    pub iterations: f64,
    /// Steps whose set of vertices near the sphere changed (each updates
    /// the global solve's factor or multigrid hierarchy).
    pub changes: u32,
    /// Timed steps.
    pub steps: usize,
}

/// `pd` (its preset) on [`scale_model`] falling from rest onto the
/// report's sphere ([`penalty_sphere`](crate::accuracy::penalty_sphere)): 40 consecutive steps after 20, each timed, at each
/// of [`PerfConfig::sphere_sides`]. Unlike the sweep's, the steps run on:
/// the sphere's contacts change from step to step.
pub fn sphere_steps(config: &PerfConfig) -> Vec<SphereRow> {
    let params = StepParams {
        parallel: false,
        ..StepParams::LAB
    };
    let spheres = [crate::accuracy::penalty_sphere()];
    let method = ProjectiveSolver::PRESET;
    config
        .sphere_sides
        .iter()
        .map(|&n| {
            let model = scale_model(n);
            let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
            let mut ws = ProjectiveWorkspace::default();
            let (mut samples, mut iterations, mut changes) = (Vec::new(), 0, 0);
            for step in 0..60 {
                let before = ws.factorizations();
                let t = Instant::now();
                let report = method
                    .step(&model, &mut state, &params, &spheres, &mut ws)
                    .expect("the lab cloth steps onto the sphere");
                let elapsed = t.elapsed().as_secs_f64();
                if step >= 20 {
                    samples.push(elapsed);
                    iterations += report.iterations;
                    changes += u32::from(ws.factorizations() > before);
                }
            }
            let steps = samples.len();
            SphereRow {
                n,
                step: Timing::of(samples),
                iterations: f64::from(iterations) / steps as f64,
                changes,
                steps,
            }
        })
        .collect()
}

/// An app of `MinimalPlugins` with `cloths` lab cloths (21², Chebyshev 32)
/// and the cloth plugins (none if `cloths` is `None`: Bevy's bare frame),
/// warmed up, one fixed step per update. With `single_threaded`, every
/// schedule gets Bevy's single-threaded executor.
fn lab_app(cloths: Option<usize>, single_threaded: bool) -> App {
    use bevy::ecs::schedule::{Schedules, SingleThreadedExecutor};
    use bevy_cloth::{Cloth, ClothParams};
    let mut app = App::new();
    app.add_plugins(MinimalPlugins)
        .insert_resource(Time::<Fixed>::from_seconds(0.0333))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    if let Some(cloths) = cloths {
        app.add_plugins(bevy_cloth::ClothPlugins::default());
        let model = ClothBuilder::lab().build().expect("the lab cloth");
        for c in 0..cloths {
            app.world_mut().spawn((
                Cloth::new(model.clone()),
                ClothParams::LAB,
                ImplicitSolver::chebyshev(32, 0.995),
                Transform::from_xyz(12.0 * c as f32, 0.0, 0.0),
            ));
        }
    }
    app.world_mut()
        .resource_mut::<Time<Virtual>>()
        .set_max_delta(Duration::from_secs_f64(0.25));
    app.finish();
    app.cleanup();
    if single_threaded {
        let mut schedules = app.world_mut().resource_mut::<Schedules>();
        for (_, schedule) in schedules.iter_mut() {
            schedule.set_executor(SingleThreadedExecutor::new());
        }
    }
    for _ in 0..21 {
        app.update();
    }
    app
}

/// Time per `App::update` (one fixed step of every cloth) with `cloths` lab
/// cloths (21², Chebyshev 32) under `MinimalPlugins` and the cloth plugins.
/// Bevy's task pools are set up once per process: after [`run`] has made
/// the compute pool, the app uses that one.
pub fn many_cloths(config: &PerfConfig, cloths: usize) -> Timing {
    let mut app = lab_app(Some(cloths), false);
    time_runs(config.budget, config.min_samples, || app.update())
}

/// One `App::update` with and without one lab cloth, under Bevy's default
/// (multi-threaded) executor and under the single-threaded one, timed in
/// turns ([`frame_costs`]).
#[derive(Clone, Copy, Debug)]
pub struct FrameCosts {
    /// `MinimalPlugins` alone: Bevy's own frame.
    pub bare: Timing,
    /// `MinimalPlugins` + `ClothPlugins` + one lab cloth.
    pub one: Timing,
    /// [`bare`](Self::bare), every schedule single-threaded.
    pub bare_single: Timing,
    /// [`one`](Self::one), every schedule single-threaded.
    pub one_single: Timing,
    /// The lab cloth's bare step (Chebyshev 32, one thread), timed in the
    /// same turns.
    pub step: Timing,
}

/// Times the four apps of [`FrameCosts`] in turns, so that the machine's
/// slow and fast spells fall on each alike.
pub fn frame_costs(config: &PerfConfig) -> FrameCosts {
    let mut apps = [
        lab_app(None, false),
        lab_app(Some(1), false),
        lab_app(None, true),
        lab_app(Some(1), true),
    ];
    let model = ClothBuilder::lab().build().expect("the lab cloth");
    let params = StepParams {
        parallel: false,
        ..StepParams::LAB
    };
    let start = warm_state(&model, &params);
    let method = AnyMethod::Implicit(ImplicitSolver::chebyshev(LAB_ITERATIONS, LAB_RHO));
    let mut stepper = Stepper::new(method, &model, &start);
    let t = interleaved(config, &[0, 1, 2, 3, 4], |a| {
        if a == 4 {
            return stepper.time(&params);
        }
        let t = Instant::now();
        apps[a].update();
        t.elapsed().as_secs_f64()
    });
    FrameCosts {
        bare: t[0],
        one: t[1],
        bare_single: t[2],
        one_single: t[3],
        step: t[4],
    }
}

/// One SIMD level of the spring pass, timed ([`simd_levels`]).
#[derive(Clone, Debug)]
pub struct SimdRow {
    /// The level (resolved: one this CPU runs).
    pub level: Simd,
    /// 32 bare spring passes of the general kernels at 21², one thread.
    pub springs: Timing,
    /// One Chebyshev 32 step at 21², one thread (the stencil kernels).
    pub step: Timing,
    /// The same step on the general kernels
    /// ([`StepParams::stencil`] off).
    pub general: Timing,
    /// One Chebyshev 32 step at the sweep's largest size, one thread, and
    /// that size; `None` if it is 21².
    pub large: Option<(usize, Timing)>,
}

/// Every SIMD level this CPU runs ([`Simd::supported`]), timed on the lab
/// step at 21² (its 32 spring passes alone and the whole step) and at the
/// sweep's largest size, or nothing when 21 is not among the sizes.
///
/// The levels are timed in turns (one sample of each, then again), for the
/// page's budget per measure and level, so that the machine's slow and fast
/// spells fall on every level alike: timed one after the other, the levels'
/// medians differed by more than the levels do.
pub fn simd_levels(config: &PerfConfig) -> Vec<SimdRow> {
    if !config.sizes.contains(&21) {
        return Vec::new();
    }
    let largest = config.sizes.iter().copied().max().unwrap_or(21);
    let method = AnyMethod::Implicit(ImplicitSolver::chebyshev(LAB_ITERATIONS, LAB_RHO));
    let model = scale_model(21);
    let start = warm_state(&model, &StepParams::LAB);
    let levels = Simd::supported();
    let params = |level| StepParams {
        simd: level,
        parallel: false,
        ..StepParams::LAB
    };
    let mut coeffs = Vec::new();
    bevy_cloth::solver::springs::stiffness_coeffs(&model, &StepParams::LAB.stiffness, &mut coeffs);
    let mut terms = vec![bevy::math::Vec3A::ZERO; model.topology().springs().len()];
    let passes = interleaved(config, &levels, |level| {
        let t = Instant::now();
        for _ in 0..32 {
            bevy_cloth::solver::springs::spring_terms(
                &params(level),
                &model,
                &start.positions,
                &coeffs,
                &mut terms,
            );
            std::hint::black_box(&mut terms);
        }
        t.elapsed().as_secs_f64()
    });
    let mut stepper = Stepper::new(method, &model, &start);
    let steps = interleaved(config, &levels, |level| stepper.time(&params(level)));
    let general = interleaved(config, &levels, |level| {
        stepper.time(&StepParams {
            stencil: false,
            ..params(level)
        })
    });
    let large = (largest > 21).then(|| {
        let model = scale_model(largest);
        let start = warm_state(&model, &StepParams::LAB);
        let mut stepper = Stepper::new(method, &model, &start);
        interleaved(config, &levels, |level| stepper.time(&params(level)))
    });
    levels
        .iter()
        .enumerate()
        .map(|(l, &level)| SimdRow {
            level,
            springs: passes[l],
            step: steps[l],
            general: general[l],
            large: large.as_ref().map(|t| (largest, t[l])),
        })
        .collect()
}

/// One method's step from one state, timed again and again.
struct Stepper<'a> {
    method: AnyMethod,
    model: &'a ClothModel,
    start: &'a ClothState,
    state: ClothState,
    ws: AnyWorkspace,
}

impl<'a> Stepper<'a> {
    fn new(method: AnyMethod, model: &'a ClothModel, start: &'a ClothState) -> Self {
        Self {
            method,
            model,
            start,
            state: start.clone(),
            ws: AnyWorkspace::default(),
        }
    }

    /// Seconds for one step from the start state (the copy is not timed).
    fn time(&mut self, params: &StepParams) -> f64 {
        self.try_time(params).expect("the lab cloth steps")
    }

    /// [`Stepper::time`], or why the step failed.
    fn try_time(&mut self, params: &StepParams) -> Result<f64, String> {
        self.state.copy_from(self.start);
        let t = Instant::now();
        let result = self
            .method
            .step(self.model, &mut self.state, params, &[], &mut self.ws);
        let elapsed = t.elapsed().as_secs_f64();
        result.map(|_| elapsed).map_err(|e| e.to_string())
    }
}

/// `sample(level)` for every level in turn, two warm-up rounds, then rounds
/// until each level has [`PerfConfig::min_samples`] samples and the rounds
/// have taken the page's budget times the number of levels.
fn interleaved<T: Copy>(
    config: &PerfConfig,
    levels: &[T],
    mut sample: impl FnMut(T) -> f64,
) -> Vec<Timing> {
    for _ in 0..2 {
        for &level in levels {
            sample(level);
        }
    }
    let mut samples = vec![Vec::new(); levels.len()];
    let budget = config.budget * levels.len() as u32;
    let start = Instant::now();
    while samples[0].len() < config.min_samples.max(1) || start.elapsed() < budget {
        for (l, &level) in levels.iter().enumerate() {
            samples[l].push(sample(level));
        }
    }
    samples.into_iter().map(Timing::of).collect()
}

/// The sparse CG step against its parts, on the assignment's cloth.
#[derive(Clone, Debug)]
pub struct CgParts {
    /// Side of the cloth.
    pub side: usize,
    /// Order of `A` and its stored nonzeros.
    pub dimension: usize,
    /// Stored nonzeros of `A`.
    pub nonzeros: usize,
    /// One whole linearly implicit step with 25 CG iterations.
    pub step: Timing,
    /// One assembly of `A` and `b`.
    pub assembly: Timing,
    /// 25 sparse matrix–vector products `A·v` (faer, as CG calls it).
    pub spmv25: Timing,
    /// CG iterations the timed step ran.
    pub iterations: u32,
}

/// Times [`CgParts`].
pub fn cg_parts(config: &PerfConfig) -> CgParts {
    let n = config.cg_side;
    let params = StepParams {
        dt: 5e-3,
        stiffness: SpringStiffness::uniform(10.0),
        damping: 1.0,
        ..StepParams::LAB
    };
    let model = ClothBuilder::assignment(n, n)
        .build()
        .expect("the assignment cloth");
    let cg = LinearImplicitSolver::cg(CgConfig {
        tolerance: 0.0,
        ..CgConfig::ASSIGNMENT
    })
    .with_springs(SpringJacobian::ClampCompression);
    let mut start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut ws = LinearWorkspace::default();
    for _ in 0..20 {
        Method::step(&cg, &model, &mut start, &params, &[], &mut ws).expect("valid step");
    }
    let mut state = start.clone();
    let mut iterations = 0;
    let step = time_samples(config.budget, config.min_samples, || {
        state.copy_from(&start);
        let t = Instant::now();
        let report = Method::step(&cg, &model, &mut state, &params, &[], &mut ws);
        let elapsed = t.elapsed().as_secs_f64();
        iterations = report.expect("valid step").iterations;
        elapsed
    });
    let mut system = LinearSystem::new(&model);
    let assembly = time_runs(config.budget, config.min_samples, || {
        system.assemble(
            &model,
            &start.positions,
            &start.velocities,
            &params,
            &cg,
            &[],
        )
    });
    let dim = system.dimension();
    let mut v: Vec<f64> = (0..dim).map(|i| 1.0 + (i % 7) as f64 * 0.1).collect();
    let mut out = vec![0.0; dim];
    let spmv25 = time_runs(config.budget, config.min_samples, || {
        for _ in 0..25 {
            sparse_dense_matmul(
                MatMut::from_column_major_slice_mut(&mut out, dim, 1),
                Accum::Replace,
                system.matrix(),
                MatRef::from_column_major_slice(&v, dim, 1),
                1.0,
                Par::Seq,
            );
            std::mem::swap(&mut v, &mut out);
        }
    });
    CgParts {
        side: n,
        dimension: dim,
        nonzeros: system.nonzeros(),
        step,
        assembly,
        spmv25,
        iterations,
    }
}
