//! The performance page: time per step of every method as the cloth grows,
//! within-cloth and across-cloth parallelism, the sparse CG step against
//! its parts, and the machine's limits. Written as `perf.md` and
//! `perf-scaling.svg`.
//!
//! ```text
//! cargo run --release --example perf            # docs/perf.md
//! bash scripts/perf.sh                          # the bevy_silk table too, then the page
//! ```
//!
//! # Method
//!
//! Every method steps the lab's cloth, kept physically the same at every
//! resolution ([`scale_model`]): `n×n` vertices over 10×10 units, total mass
//! 441 (1 per vertex at the lab's 21²), corners `0` and `n − 1` pinned,
//! `k = 8000`, `dt = 0.0333`, damping 0.99. `k` stays constant: a row of
//! `n − 1` springs in series has stiffness `k/(n − 1)` and `n` rows act in
//! parallel, so the sheet's stiffness is about `k` at every `n`.
//!
//! The timed step starts each time from the same swinging state (20
//! Chebyshev steps from rest; state copy not timed), so every sample does
//! the same work. A case is warmed up, then sampled until it has run for
//! its time budget (at least [`PerfConfig::min_samples`] samples); the page
//! gives the median and the quartiles. After the last sample the
//! divergence guard's default check ([`GuardBounds::default`]) runs on the
//! result: a timed step the guard would have rejected is marked.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use bevy::app::App;
use bevy::math::{Affine3A, Vec4};
use bevy::prelude::{Fixed, MinimalPlugins, Time, Transform, Virtual};
use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
use bevy::time::TimeUpdateStrategy;
use faer::sparse::linalg::matmul::sparse_dense_matmul;
use faer::{Accum, MatMut, MatRef, Par};
use plotters::prelude::*;

use crate::model::{ClothBuilder, ClothModel, ClothState};
use crate::solver::any::{AnyMethod, AnyWorkspace};
use crate::solver::guard::GuardBounds;
use crate::solver::implicit::ImplicitConfig;
use crate::solver::linear::{
    self, CgConfig, LinearConfig, LinearSolver, LinearSystem, LinearWorkspace, SpringJacobian,
};
use crate::solver::pbd::PbdConfig;
use crate::solver::{SpringStiffness, StepParams, set_parallel};

/// What the performance page measures.
#[derive(Clone, Debug)]
pub struct PerfConfig {
    /// Output folder (`perf.md`, `perf-scaling.svg`).
    pub out_dir: PathBuf,
    /// Grid sides of the scale sweep.
    pub sizes: Vec<usize>,
    /// Largest side at which the linearly implicit and exact methods run.
    pub max_side_sparse: usize,
    /// Wall time to sample each case for.
    pub budget: Duration,
    /// Fewest samples per case.
    pub min_samples: usize,
    /// Cloths in the many-cloths app.
    pub many: usize,
    /// Side of the CG comparison cloth (the assignment's).
    pub cg_side: usize,
    /// Elements per array of the memory-bandwidth kernel.
    pub stream_len: usize,
    /// A table from `compare/silk` to include, if the file exists.
    pub silk_table: Option<PathBuf>,
    /// Only the sweep's methods whose name starts with this (and nothing
    /// else: no page is written), for profiling one case.
    pub only: Option<String>,
}

impl PerfConfig {
    /// The committed page: 21² to 256², 100 cloths, CG at 100².
    pub fn full(out_dir: impl Into<PathBuf>) -> Self {
        let out_dir = out_dir.into();
        Self {
            silk_table: Some(out_dir.join("perf").join("silk.md")),
            out_dir,
            sizes: vec![21, 51, 101, 201, 256],
            max_side_sparse: 201,
            budget: Duration::from_millis(1500),
            min_samples: 7,
            many: 100,
            cg_side: 100,
            stream_len: 1 << 24,
            only: None,
        }
    }

    /// A seconds-long run for tests and CI (not a measurement).
    pub fn tiny(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            sizes: vec![6, 11],
            max_side_sparse: 11,
            budget: Duration::from_millis(5),
            min_samples: 3,
            many: 3,
            cg_side: 6,
            stream_len: 1 << 12,
            silk_table: None,
            only: None,
        }
    }
}

/// Median and quartiles of repeated runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// Median, in seconds.
    pub median: f64,
    /// First quartile, in seconds.
    pub q1: f64,
    /// Third quartile, in seconds.
    pub q3: f64,
    /// Samples taken.
    pub samples: usize,
}

impl Timing {
    /// Median, q1 and q3 of `samples` (seconds; at least one).
    pub fn of(mut samples: Vec<f64>) -> Self {
        samples.sort_by(f64::total_cmp);
        let at = |q: f64| samples[((samples.len() - 1) as f64 * q).round() as usize];
        Self {
            median: at(0.5),
            q1: at(0.25),
            q3: at(0.75),
            samples: samples.len(),
        }
    }

    /// `median (q1–q3)` in a readable unit.
    pub fn cell(&self) -> String {
        format!(
            "{} ({}–{})",
            human(self.median),
            human(self.q1),
            human(self.q3)
        )
    }
}

/// Seconds as µs or ms, three significant digits.
fn human(s: f64) -> String {
    if s < 1e-3 {
        format!("{:.1} µs", s * 1e6)
    } else if s < 1.0 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

/// Samples `sample` (which times what it measures and returns seconds):
/// two warm-up calls, then samples until `budget` has passed and there are
/// `min_samples`.
pub fn time_samples(
    budget: Duration,
    min_samples: usize,
    mut sample: impl FnMut() -> f64,
) -> Timing {
    for _ in 0..2 {
        sample();
    }
    let start = Instant::now();
    let mut samples = Vec::new();
    while samples.len() < min_samples.max(1) || start.elapsed() < budget {
        samples.push(sample());
    }
    Timing::of(samples)
}

/// [`time_samples`] of the whole of `run`.
pub fn time_runs(budget: Duration, min_samples: usize, mut run: impl FnMut()) -> Timing {
    time_samples(budget, min_samples, || {
        let t = Instant::now();
        run();
        t.elapsed().as_secs_f64()
    })
}

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
    let method = AnyMethod::Implicit(ImplicitConfig::chebyshev(32, 0.995));
    for _ in 0..20 {
        method
            .step(model, &mut state, params, &[], &mut ws)
            .expect("the lab cloth steps");
    }
    state
}

/// The methods of the scale sweep, with their table names.
pub fn sweep_methods() -> Vec<(&'static str, AnyMethod, bool)> {
    let cg = LinearConfig {
        solver: LinearSolver::Cg(CgConfig {
            max_iterations: 25,
            ..CgConfig::default()
        }),
        springs: SpringJacobian::ClampCompression,
        ..LinearConfig::default()
    };
    let direct = LinearConfig {
        solver: LinearSolver::Direct,
        ..cg
    };
    // (name, method, sparse: capped at `max_side_sparse`)
    vec![
        (
            "Jacobi 32",
            AnyMethod::Implicit(ImplicitConfig::jacobi(32)),
            false,
        ),
        (
            "Chebyshev 32",
            AnyMethod::Implicit(ImplicitConfig::chebyshev(32, 0.995)),
            false,
        ),
        (
            "PBD 32",
            AnyMethod::Pbd(PbdConfig { iterations: 32 }),
            false,
        ),
        ("symplectic", AnyMethod::Symplectic, false),
        ("linear CG 25", AnyMethod::Linear(cg), true),
        ("linear direct", AnyMethod::Linear(direct), true),
        ("exact Newton", AnyMethod::Exact(Default::default()), true),
    ]
}

/// One timed case of the scale sweep.
#[derive(Clone, Debug)]
pub struct Case {
    /// Table name of the method.
    pub method: &'static str,
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

fn time_method(
    config: &PerfConfig,
    method: AnyMethod,
    model: &ClothModel,
    params: &StepParams,
    start: &ClothState,
) -> (Timing, Option<String>) {
    let mut ws = AnyWorkspace::default();
    let mut state = start.clone();
    let mut failed = None;
    let timing = time_samples(config.budget, config.min_samples, || {
        state.copy_from(start);
        let t = Instant::now();
        let result = method.step(model, &mut state, params, &[], &mut ws);
        let elapsed = t.elapsed().as_secs_f64();
        if let Err(e) = result {
            failed = Some(e.to_string());
        }
        elapsed
    });
    let guard = failed.or_else(|| {
        GuardBounds::default()
            .check(model, &state, start, params)
            .err()
            .map(|e| format!("{e:?}"))
    });
    (timing, guard)
}

/// Does `method` have loops that run in parallel chunks at this size?
fn has_parallel_loops(method: &AnyMethod, model: &ClothModel) -> bool {
    matches!(method, AnyMethod::Implicit(_) | AnyMethod::Symplectic)
        && model.topology().springs().len() >= crate::solver::PARALLEL_MIN
}

/// The scale sweep.
pub fn sweep(config: &PerfConfig, progress: impl Fn(&str)) -> Vec<Case> {
    let params = StepParams::LAB;
    let mut cases = Vec::new();
    for &n in &config.sizes {
        let model = scale_model(n);
        let start = warm_state(&model, &params);
        for (name, method, sparse) in sweep_methods() {
            if sparse && n > config.max_side_sparse
                || config
                    .only
                    .as_ref()
                    .is_some_and(|only| !name.starts_with(only.as_str()))
            {
                continue;
            }
            progress(&format!("{name} at {n}²"));
            set_parallel(false);
            let (serial, guard) = time_method(config, method, &model, &params, &start);
            set_parallel(true);
            let parallel = has_parallel_loops(&method, &model)
                .then(|| time_method(config, method, &model, &params, &start).0);
            cases.push(Case {
                method: name,
                solver: method,
                n,
                serial,
                parallel,
                guard,
            });
        }
    }
    cases
}

/// Time per `App::update` (one fixed step of every cloth) with `cloths` lab
/// cloths (21², Chebyshev 32) under `MinimalPlugins` and the cloth plugins.
/// Bevy's task pools are set up once per process: after [`run`] has made
/// the compute pool, the app uses that one.
pub fn many_cloths(config: &PerfConfig, cloths: usize) -> Timing {
    use crate::{Cloth, ClothParams, ImplicitSolver};
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, crate::ClothPlugins::default()))
        .insert_resource(Time::<Fixed>::from_seconds(0.0333))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1));
    let model = ClothBuilder::lab().build().expect("the lab cloth");
    for c in 0..cloths {
        app.world_mut().spawn((
            Cloth::new(model.clone()),
            ClothParams::default(),
            ImplicitSolver::chebyshev(32, 0.995),
            Transform::from_xyz(12.0 * c as f32, 0.0, 0.0),
        ));
    }
    app.world_mut()
        .resource_mut::<Time<Virtual>>()
        .set_max_delta(Duration::from_secs_f64(0.25));
    app.finish();
    app.cleanup();
    for _ in 0..21 {
        app.update();
    }
    time_runs(config.budget, config.min_samples, || app.update())
}

/// At 21²: the time of 32 spring passes alone and of a whole Chebyshev 32
/// step (seconds), or `None` when 21 is not among the sizes.
fn spring_pass_share(config: &PerfConfig) -> Option<(f64, f64)> {
    if !config.sizes.contains(&21) {
        return None;
    }
    let params = StepParams::LAB;
    let model = scale_model(21);
    let start = warm_state(&model, &params);
    let mut coeffs = Vec::new();
    crate::solver::stiffness_coeffs(&model, &params.stiffness, &mut coeffs);
    let mut terms = vec![bevy::math::Vec3A::ZERO; model.topology().springs().len()];
    let springs = time_runs(config.budget, config.min_samples, || {
        for _ in 0..32 {
            crate::solver::spring_terms(&model, &start.positions, &coeffs, &mut terms);
            std::hint::black_box(&mut terms);
        }
    });
    let method = AnyMethod::Implicit(ImplicitConfig::chebyshev(32, 0.995));
    let (step, _) = time_method(config, method, &model, &params, &start);
    Some((springs.median, step.median))
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
    let cg = LinearConfig {
        solver: LinearSolver::Cg(CgConfig {
            max_iterations: 25,
            tolerance: 0.0,
            ..CgConfig::default()
        }),
        springs: SpringJacobian::ClampCompression,
        ..LinearConfig::default()
    };
    let mut start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut ws = LinearWorkspace::default();
    for _ in 0..20 {
        linear::step(&model, &mut start, &params, &cg, &[], &mut ws).expect("valid step");
    }
    let mut state = start.clone();
    let mut iterations = 0;
    let step = time_samples(config.budget, config.min_samples, || {
        state.copy_from(&start);
        let t = Instant::now();
        let report = linear::step(&model, &mut state, &params, &cg, &[], &mut ws);
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

/// What one core of this machine achieves on simple kernels.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Triad `a = b + s·c` over arrays far larger than the caches, GB/s.
    pub memory_gbs: f64,
    /// The same triad over arrays that fit in L1/L2 (3 × 16 KiB), GB/s.
    pub cache_gbs: f64,
    /// The same triad over arrays past L2 but within a last-level cache
    /// (3 × 2 MiB), GB/s.
    pub l3_gbs: f64,
    /// Scalar `f32` multiply–adds, 8 independent chains, GFLOP/s.
    pub scalar_gflops: f64,
    /// 4-lane `Vec4` multiply–adds, 8 independent chains, GFLOP/s: the
    /// packed width this crate's build uses (baseline x86-64: SSE2).
    pub simd_gflops: f64,
}

fn triad(len: usize, budget: Duration, min_samples: usize) -> f64 {
    let b = vec![1.0f32; len];
    let c = vec![2.0f32; len];
    let mut a = vec![0.0f32; len];
    let s = std::hint::black_box(0.5f32);
    let reps = (1 << 22) / len.max(1) + 1;
    let t = time_runs(budget, min_samples, || {
        for _ in 0..reps {
            for ((a, b), c) in a.iter_mut().zip(&b).zip(&c) {
                *a = b + s * c;
            }
            std::hint::black_box(&mut a);
        }
    });
    (12 * len * reps) as f64 / t.median / 1e9
}

/// `x`, hidden from the optimiser in a register of its own, so that eight
/// scalar chains stay scalar (the compiler would otherwise pack them into
/// two `Vec4`s, and the scalar kernel would measure SIMD).
#[inline(always)]
fn opaque(x: f32) -> f32 {
    #[cfg(target_arch = "x86_64")]
    {
        let mut x = x;
        // SAFETY: an empty instruction that reads and writes one register.
        unsafe {
            core::arch::asm!("/* {0} */", inout(xmm_reg) x, options(pure, nomem, nostack));
        }
        x
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        std::hint::black_box(x)
    }
}

/// Measures [`Limits`].
pub fn limits(config: &PerfConfig) -> Limits {
    const OPS: usize = 1 << 22;
    let scalar = time_runs(config.budget, config.min_samples, || {
        let mut acc = [1.0f32, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7];
        let m = std::hint::black_box(0.999_999f32);
        let a = std::hint::black_box(1e-7f32);
        for _ in 0..OPS / 8 {
            for x in &mut acc {
                *x = opaque(*x * m + a);
            }
        }
        std::hint::black_box(acc);
    });
    let simd = time_runs(config.budget, config.min_samples, || {
        let mut acc = [Vec4::ONE; 8];
        let m = Vec4::splat(std::hint::black_box(0.999_999f32));
        let a = Vec4::splat(std::hint::black_box(1e-7f32));
        for _ in 0..OPS / 8 {
            for x in &mut acc {
                *x = *x * m + a;
            }
        }
        std::hint::black_box(acc);
    });
    Limits {
        memory_gbs: triad(config.stream_len, config.budget, config.min_samples),
        cache_gbs: triad(4096, config.budget, config.min_samples),
        l3_gbs: triad(
            (1 << 19).min(config.stream_len),
            config.budget,
            config.min_samples,
        ),
        scalar_gflops: (2 * OPS) as f64 / scalar.median / 1e9,
        simd_gflops: (2 * 4 * OPS) as f64 / simd.median / 1e9,
    }
}

/// For a spring-loop method: its iterations per step, and the bytes and
/// flops one iteration must at least move and do, from the counts of its
/// loops (see the page for the per-item model). `None` for the sparse
/// methods, whose work is faer's.
pub fn work_per_iteration(method: &AnyMethod, model: &ClothModel) -> Option<(u32, f64, f64)> {
    let v = model.vertex_count() as f64;
    let s = model.topology().springs().len() as f64;
    // Per iteration: a spring reads its record (16 B), coefficients (8 B)
    // and writes its term (16 B); each of its 2 incidences reads an index
    // (4 B) and the term (16 B); a vertex reads and writes x and the
    // previous iterate and reads its target and 2 scalars (88 B).
    // Flops: 14 per spring (difference, dot, sqrt, divide, scale), 3 per
    // incidence, about 21 per vertex.
    let iteration = (
        40.0 * s + 2.0 * 20.0 * s + 88.0 * v,
        14.0 * s + 6.0 * s + 21.0 * v,
    );
    let iterations = match method {
        AnyMethod::Implicit(c) => c.iterations,
        AnyMethod::Pbd(c) => c.iterations,
        AnyMethod::Symplectic => 1,
        AnyMethod::Linear(_) | AnyMethod::Exact(_) => return None,
    };
    Some((iterations, iteration.0, iteration.1))
}

/// Runs the page and writes its files. Returns the markdown.
pub fn run(config: &PerfConfig, progress: impl Fn(&str)) -> std::io::Result<String> {
    std::fs::create_dir_all(&config.out_dir)?;
    super::register_chart_font();
    // Two compute threads for the parallel columns (Bevy's default plugin
    // would give this 2-core machine one).
    let pool = ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
    let threads = pool.thread_num();

    if config.only.is_some() {
        let cases = sweep(config, &progress);
        let mut md = String::new();
        for c in cases {
            write!(md, "{} {}²: {}", c.method, c.n, c.serial.cell()).ok();
            if let Some(p) = c.parallel {
                write!(md, "; parallel {}", p.cell()).ok();
            }
            writeln!(md, "; guard {}", c.guard.as_deref().unwrap_or("silent")).ok();
        }
        return Ok(md);
    }
    progress("limits");
    let limits = limits(config);
    let cases = sweep(config, &progress);
    progress("spring pass at 21²");
    let split = spring_pass_share(config);
    progress("many cloths");
    let one_app = many_cloths(config, 1);
    let many_app = many_cloths(config, config.many);
    progress("CG parts");
    let cg = cg_parts(config);

    let mut md = String::new();
    let w = &mut md;
    writeln!(w, "# Performance").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "Written by `cargo run --release --example perf` ({}). Machine: {}, {} logical cores; \
         compute pool for the parallel columns: {threads} threads. Build: release, baseline \
         x86-64 target (SSE2, 4-lane packed `f32`).",
        std::env::consts::ARCH,
        super::machine(),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "Method: each case starts every sample from the same swinging state (20 Chebyshev \
         steps from rest; the state copy is not timed), warms up twice, then samples for \
         {:.1} s (at least {} samples). Cells are `median (first–third quartile)`. The cloth \
         is the lab's, physically the same at every size: 10×10 units, total mass 441, \
         corners pinned, k = 8000 at every resolution (a row of n − 1 springs in series has \
         stiffness k/(n − 1) and n rows act in parallel, so the sheet's stiffness stays about \
         k), dt = 0.0333, damping 0.99. \"guard\" is the divergence guard's default check on \
         the timed step's result: silent means it would have accepted it.",
        config.budget.as_secs_f64(),
        config.min_samples
    )
    .ok();
    writeln!(w).ok();

    writeln!(w, "## Time per step against cloth size").ok();
    writeln!(w).ok();
    writeln!(w, "![time per step against vertices](perf-scaling.svg)").ok();
    writeln!(w).ok();
    write!(w, "| method |").ok();
    for n in &config.sizes {
        write!(w, " {n}² ({} vertices) |", n * n).ok();
    }
    writeln!(w).ok();
    write!(w, "|---|").ok();
    for _ in &config.sizes {
        write!(w, "---|").ok();
    }
    writeln!(w).ok();
    for (name, _, _) in sweep_methods() {
        write!(w, "| {name} |").ok();
        for &n in &config.sizes {
            match cases.iter().find(|c| c.method == name && c.n == n) {
                Some(c) => {
                    write!(w, " {}", c.serial.cell()).ok();
                    if let Some(p) = c.parallel {
                        write!(w, "; {threads} threads: {}", p.cell()).ok();
                    }
                    match &c.guard {
                        None => write!(w, " |").ok(),
                        Some(why) => write!(w, " ⚠ guard: {why} |").ok(),
                    };
                }
                None => {
                    write!(w, " – |").ok();
                }
            }
        }
        writeln!(w).ok();
    }
    writeln!(w).ok();
    let silent = cases.iter().filter(|c| c.guard.is_none()).count();
    writeln!(
        w,
        "{silent} of {} timed steps pass the guard's check. Sparse methods stop at {}².",
        cases.len(),
        config.max_side_sparse
    )
    .ok();
    writeln!(w).ok();
    if let Some(big) = cases
        .iter()
        .filter(|c| c.method == "Chebyshev 32")
        .max_by_key(|c| c.n)
    {
        let best = big
            .parallel
            .map_or(big.serial.median, |p| p.median.min(big.serial.median));
        writeln!(
            w,
            "Chebyshev 32 at {}²: {:.1} steps per second ({}).",
            big.n,
            1.0 / best,
            human(best)
        )
        .ok();
        writeln!(w).ok();
    }

    if let Some((springs, step)) = split {
        writeln!(
            w,
            "The lab step at 21² (Chebyshev 32), timed again beside 32 bare spring passes (so \
             its median differs a little from the tables'): {} per step, of which the 32 spring \
             passes take {} ({:.0} %) and the 32 vertex passes (gather and update) most of the \
             rest. The target was 100 µs.",
            human(step),
            human(springs),
            100.0 * springs / step
        )
        .ok();
        writeln!(w).ok();
    }

    writeln!(w, "## Many cloths").ok();
    writeln!(w).ok();
    let single = cases
        .iter()
        .find(|c| c.method == "Chebyshev 32" && c.n == 21)
        .map(|c| c.serial.median);
    writeln!(
        w,
        "One `App::update` (one fixed step of every cloth, guard and stats included; \
         `MinimalPlugins` + `ClothPlugins`, the compute pool at {threads} threads) with lab \
         cloths of 21², Chebyshev 32:"
    )
    .ok();
    writeln!(w).ok();
    writeln!(w, "| cloths | per update | per cloth |").ok();
    writeln!(w, "|---|---|---|").ok();
    for (count, t) in [(1, one_app), (config.many, many_app)] {
        writeln!(
            w,
            "| {count} | {} | {} |",
            t.cell(),
            human(t.median / count as f64)
        )
        .ok();
    }
    writeln!(w).ok();
    if let Some(single) = single {
        writeln!(
            w,
            "{} cloths take {:.2}× the time of {} bare solver steps of one cloth ({} each): the \
             systems run the cloths with `par_iter_mut` on the compute pool.",
            config.many,
            many_app.median / (config.many as f64 * single),
            config.many,
            human(single)
        )
        .ok();
        writeln!(w).ok();
        writeln!(
            w,
            "With one cloth, an update costs {} more than the bare step: the fixed cost of a \
             frame (Bevy's schedules, the cloth systems, the divergence guard's backup and \
             checks, the stats), paid once per update however many cloths there are.",
            human((one_app.median - single).max(0.0))
        )
        .ok();
        writeln!(w).ok();
    }

    writeln!(w, "## Sparse CG against its parts").ok();
    writeln!(w).ok();
    let parts = cg.spmv25.median + cg.assembly.median;
    writeln!(
        w,
        "The assignment's cloth at {0}×{0} (stretch, shear and bending springs; `A` of order \
         {1} with {2} stored nonzeros), one linearly implicit step with 25 CG iterations \
         (tolerance 0, so all 25 run; {3} ran):",
        cg.side, cg.dimension, cg.nonzeros, cg.iterations
    )
    .ok();
    writeln!(w).ok();
    writeln!(w, "| part | time |").ok();
    writeln!(w, "|---|---|").ok();
    writeln!(w, "| whole step (CG 25) | {} |", cg.step.cell()).ok();
    writeln!(w, "| one assembly of `A`, `b` | {} |", cg.assembly.cell()).ok();
    writeln!(w, "| 25 products `A·v` (faer) | {} |", cg.spmv25.cell()).ok();
    writeln!(w, "| assembly + 25 products | {} |", human(parts)).ok();
    writeln!(w).ok();
    writeln!(
        w,
        "The step takes **{:.2}×** its assembly and 25 bare products (target: within 2×).",
        cg.step.median / parts
    )
    .ok();
    writeln!(w).ok();

    writeln!(w, "## The limit").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "One core, simple kernels: a triad `a = b + s·c` streams {:.1} GB/s from memory \
         (3 × {} MiB), {:.1} GB/s from the last-level cache (3 × 2 MiB) and {:.1} GB/s from \
         L1/L2 (3 × 16 KiB); multiply–adds in 8 independent chains run at {:.2} GFLOP/s \
         scalar and {:.2} GFLOP/s in 4-lane `Vec4` (this CPU also has AVX-512, 4× wider, \
         which a baseline x86-64 build does not use).",
        limits.memory_gbs,
        (4 * config.stream_len) >> 20,
        limits.l3_gbs,
        limits.cache_gbs,
        limits.scalar_gflops,
        limits.simd_gflops
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "Per step, a spring-loop method must at least move, per iteration, 40 B per spring \
         (its record, coefficients and term), 20 B per incidence (an index and a term; two per \
         spring) and 88 B per vertex, and do about 14 flops per spring, 3 per incidence and 21 \
         per vertex. Its limit is the larger of bytes / bandwidth and flops / SIMD rate, with \
         the bandwidth of where one iteration's working set fits (up to 512 KiB: L1/L2; up to \
         the last-level cache's {} MiB: last-level cache; else memory); the table gives the limit as a fraction of \
         the measured single-thread median (100 % would be at the limit).",
        last_level_cache() >> 20
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "| method | size | bytes/step | flops/step | limit | measured | fraction of limit |"
    )
    .ok();
    writeln!(w, "|---|---|---|---|---|---|---|").ok();
    for c in &cases {
        let model = scale_model(c.n);
        if let Some((iterations, per_iteration, flops)) = work_per_iteration(&c.solver, &model) {
            let (bytes, flops) = (
                per_iteration * f64::from(iterations),
                flops * f64::from(iterations),
            );
            let bandwidth = if per_iteration <= (512 << 10) as f64 {
                limits.cache_gbs
            } else if per_iteration <= last_level_cache() as f64 {
                limits.l3_gbs
            } else {
                limits.memory_gbs
            };
            let limit = (bytes / (bandwidth * 1e9)).max(flops / (limits.simd_gflops * 1e9));
            writeln!(
                w,
                "| {} | {}² | {:.2} MB | {:.2} Mflop | {} | {} | {:.0} % |",
                c.method,
                c.n,
                bytes / 1e6,
                flops / 1e6,
                human(limit),
                human(c.serial.median),
                100.0 * limit / c.serial.median
            )
            .ok();
        }
    }
    writeln!(w).ok();
    writeln!(
        w,
        "The sparse CG step's limit is its 25 products: each streams the {} nonzeros (8 B \
         value + 8 B row index) = {:.1} MB, {:.2} ms at memory bandwidth for 25; measured \
         {}: {:.0} % of the limit.",
        cg.nonzeros,
        16.0 * cg.nonzeros as f64 / 1e6,
        25.0 * 16.0 * cg.nonzeros as f64 / (limits.memory_gbs * 1e9) * 1e3,
        human(cg.step.median),
        100.0 * 25.0 * 16.0 * cg.nonzeros as f64 / (limits.memory_gbs * 1e9) / cg.step.median
    )
    .ok();
    writeln!(w).ok();

    if let Some(path) = &config.silk_table {
        writeln!(w, "## Side by side with bevy_silk").ok();
        writeln!(w).ok();
        match std::fs::read_to_string(path) {
            Ok(table) => {
                writeln!(
                    w,
                    "From `cargo run --release --manifest-path compare/silk/Cargo.toml` (a crate \
                     outside the workspace, so bevy_silk's Bevy 0.17 stays out of our lock \
                     file). Same cloth, same vertices and triangles, 32 iterations, one thread, \
                     one process. bevy_silk's solver is Gauss–Seidel over a hash map of sticks; \
                     ours is Jacobi (PBD) or Chebyshev-accelerated Jacobi (implicit)."
                )
                .ok();
                writeln!(w).ok();
                writeln!(w, "{}", table.trim()).ok();
            }
            Err(_) => {
                writeln!(
                    w,
                    "Not run: {} is missing (run `bash scripts/perf.sh`).",
                    path.display()
                )
                .ok();
            }
        }
        writeln!(w).ok();
    }

    writeln!(w, "## Rerun").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "`bash scripts/perf.sh` (about 15 minutes on this machine, the first time longer: it \
         builds bevy_silk's Bevy) reruns the bevy_silk comparison and then this page; \
         `cargo run --release --example perf` reruns this page alone. The criterion \
         benchmarks (`cargo bench`) time the same steps at 21² and 101²."
    )
    .ok();

    std::fs::write(config.out_dir.join("perf.md"), &md)?;
    chart(&config.out_dir.join("perf-scaling.svg"), &cases).map_err(std::io::Error::other)?;
    Ok(md)
}

/// The last-level cache's size in bytes from sysfs (32 MiB if unknown).
fn last_level_cache() -> usize {
    (0..8)
        .rev()
        .find_map(|i| {
            let size = std::fs::read_to_string(format!(
                "/sys/devices/system/cpu/cpu0/cache/index{i}/size"
            ))
            .ok()?;
            let kib: usize = size.trim().strip_suffix('K')?.parse().ok()?;
            Some(kib << 10)
        })
        .unwrap_or(32 << 20)
}

fn chart(path: &Path, cases: &[Case]) -> Result<(), String> {
    let point = |c: &Case| ((c.n * c.n) as f64, c.serial.median * 1e3);
    let (x_lo, x_hi, y_lo, y_hi) = cases.iter().map(point).fold(
        (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64),
        |(x_lo, x_hi, y_lo, y_hi), (x, y)| (x_lo.min(x), x_hi.max(x), y_lo.min(y), y_hi.max(y)),
    );
    if cases.is_empty() {
        return Ok(());
    }
    let series: Vec<(&str, Vec<(f64, f64)>)> = sweep_methods()
        .iter()
        .map(|(name, _, _)| {
            let points = cases.iter().filter(|c| c.method == *name).map(point);
            (*name, points.collect::<Vec<_>>())
        })
        .filter(|(_, points)| !points.is_empty())
        .collect();
    super::log_log_chart(
        path,
        (900, 600),
        "Time per step against vertex count (single thread, log–log)",
        ("vertices", "ms per step"),
        (x_lo / 1.3..x_hi * 1.3, y_lo / 2.0..y_hi * 2.0),
        &series,
        SeriesLabelPosition::UpperLeft,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_perf_page_runs_end_to_end_on_a_tiny_configuration() {
        let dir = std::env::temp_dir().join(format!("bevy_cloth_perf_{}", std::process::id()));
        let md = run(&PerfConfig::tiny(&dir), |_| {}).unwrap();
        for heading in [
            "## Time per step",
            "## Many cloths",
            "## Sparse CG",
            "## The limit",
        ] {
            assert!(md.contains(heading), "{heading} missing:\n{md}");
        }
        // Every method ran at every tiny size, and the guard passed them.
        for (name, _, _) in sweep_methods() {
            assert!(md.contains(&format!("| {name} |")), "{name}");
        }
        assert!(!md.contains("⚠"), "{md}");
        let svg = std::fs::read_to_string(dir.join("perf-scaling.svg")).unwrap();
        assert!(svg.contains("<circle") && svg.contains("Chebyshev 32"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn timing_takes_the_median_and_quartiles() {
        let t = Timing::of(vec![5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!((t.median, t.q1, t.q3, t.samples), (3.0, 2.0, 4.0, 5));
    }
}
