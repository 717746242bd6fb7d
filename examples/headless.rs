//! Runs the cloth plugin in a window-less `App` for a number of fixed steps
//! and prints one summary line.
//!
//! ```text
//! cargo run --release --example headless -- [--scene lab|assignment|cape|drape] [--method M] \
//!     [--n 21 | --rows R --cols C] [--cloths 1] [--steps 300] [--iterations K] [--k STIFFNESS] \
//!     [--dt SECONDS] [--damping D] [--mass TOTAL] [--material cotton|E,RHO] \
//!     [--rho 0.995] [--refinement 16] [--chains] [--sphere] \
//!     [--penalty C] [--exact-k] [--global auto|direct|mg|mgN] [--dump positions.csv] \
//!     [--compute-threads N]
//! ```
//!
//! Methods: the preset names of `bevy_cloth::methods::PRESETS` (`jacobi`,
//! also `implicit`, `chebyshev`, `chebyshev-auto`, `pbd`, `symplectic`,
//! `linear-cg`, `linear-direct`, `pd`, `pd-anderson`, `newton`, `exact`, `stiff`), at
//! their interactive settings (default `chebyshev`, as the lab);
//! `--iterations` and `--rho` change them. Every method runs on every scene.
//!
//! - `lab` (default): the Unity lab's `n×n` cloth (10×10 units, total mass
//!   441 — 1 per vertex at the lab's 21² —, pinned at 0 and n−1),
//!   `k = 8000`, `dt = 0.0333`, damping 0.99. The cloth is physically the
//!   same at every `n` (same size, mass and sheet stiffness: `n` rows of
//!   `n − 1` springs in series keep about `k`), so `--n 256` is the lab's
//!   cloth at a finer resolution, not a heavier one.
//!   `--sphere` adds a projecting sphere of radius 2.7 at (0, −4, 4) that the
//!   swinging cloth falls onto.
//! - `assignment`: the assignment's `rows×cols` particle grid (0.5×0.5,
//!   horizontal at y = 0.5, total mass 0.1, stretch, shear and bending
//!   springs, the two corners of row 0 fixed), `E = 10`, `h = 5e-3`, no
//!   damping, particle radius 0.01. `--sphere` adds the moving sphere: a
//!   penalty sphere of radius 0.1 at (0, 0.2, 0.5·sin(t/2)) sweeping through
//!   the hanging cloth (the spec leaves its path open; this is ours), with
//!   stiffness `--penalty` (default 10).
//! - `cape`: the character of `examples/cape.rs` (run, sharp turns, jumps,
//!   teleported 100 m at 6 s) in its cape (`--n` columns, 8/5 as many rows)
//!   and skirt, with tethers, max distance, backstop and inertia (`stiff`
//!   with its refinement capped at 4× by default); the line
//!   is the cape's, with `max_stretch` its largest over the run (and
//!   `skirt_max_stretch` the skirt's), and adds `teleports=` and `body_penetrations=` (garment
//!   vertices found inside a body capsule after a step, counted over the
//!   run). A retried step counts as a failure.
//! - `drape`: two 1.2 m sheets of cotton (`--n`², default 32², `stiff` by
//!   default) dropped onto a ball on the ground, the second a second after
//!   the first and turned, both with `SelfCollision` (`--no-self-collision`
//!   drops it); the line is the first sheet's, and adds `penetrations=` (mesh
//!   edges through a triangle of either sheet, counted after every step and
//!   summed over the run: the exact check) and `worst_step_penetrations=`.
//!
//! `--cloths N` spawns `N` copies of the cloth side by side, stepped in
//! parallel across the compute pool; the summary then reports the median
//! wall time of a whole update (every cloth's step) too.
//!
//! The linearly implicit presets drop the compressive term of each spring
//! block (keeps `A` positive definite; see `SpringJacobian`); `--exact-k`
//! gives them the assignment's exact blocks instead. `--global` chooses
//! projective dynamics' global solve (`GlobalSolve`): `auto` (the default),
//! `direct`, or `mg`/`mgN` for one/`N` multigrid V-cycles per iteration. `--dump` writes the final positions as CSV `i,x,y,z`. `--help` prints
//! the usage and exits with status 0; bad arguments print the usage and exit
//! with status 2.

// The cape scene, shared with `examples/cape.rs` (whose window parts this
// example does not use).
#[path = "character/mod.rs"]
#[allow(dead_code)]
mod character;
#[path = "cli/mod.rs"]
mod cli;
// The drape scene, shared with `examples/drape.rs`.
#[path = "drape/mod.rs"]
mod drape;

use std::process::ExitCode;
use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;
use cli::{CliError, Long, Parser, Short, value};

const USAGE: &str = "usage: headless [OPTIONS]

  --scene lab|assignment|cape|drape   the scene (default lab)
  --method NAME            a preset (default chebyshev, the lab's; stiff in the drape
                           scene, a game's default, and in the cape scene stiff with
                           its refinement capped at 4, --refinement 4): jacobi, chebyshev,
                           chebyshev-auto, pbd, symplectic, linear-cg, linear-direct, pd,
                           pd-anderson, newton, exact, stiff
  --n N                    the lab cloth's side in vertices (default 21); in the cape
                           scene, the cape's columns (default 20; 50: 4,000 vertices);
                           in the drape scene, the sheets' side (default 32)
  --rows R --cols C        the assignment's grid (default 30 x 30)
  --cloths N               copies side by side (default 1)
  --steps S                fixed steps to run (default 300)
  --iterations K           the method's iterations per step (default: the preset's;
                           for stiff, its substeps per step)
  --k STIFFNESS            spring stiffness (default: the scene's, 8000 or E = 10)
  --dt SECONDS             time step (default: the scene's, 0.0333 or 0.005)
  --damping D              velocity multiplier per step (default: 0.99 or 1)
  --mass TOTAL             the cloth's total mass (default: 441 or 0.1)
  --material cotton|E,RHO  a ClothMaterial instead of --k and --mass: cotton
                           (12 kN/m, 0.25 kg/m²), or a stretch modulus E in
                           N/m and an areal density RHO in kg/m² (default: none)
  --rho RHO                Chebyshev's fixed spectral radius (default: the preset's)
  --refinement R           stiff's most substeps x near a collider (default 16)
  --chains                 stiff solves its chains of stretch springs whole
  --sphere                 add the scene's sphere (default: none)
  --no-self-collision      the drape scene's sheets without SelfCollision
  --throw-at S             the drape scene throws a ball through it at S seconds
  --penalty C              the assignment sphere's penalty stiffness (default 10)
  --exact-k                the linearly implicit methods' exact spring blocks
  --global auto|direct|mg|mgN   projective dynamics' global solve (default auto)
  --dump FILE.csv          write the final positions
  --compute-threads N      the compute pool's threads (default: Bevy's)
  --help                   this text

Exits 0 when the cloth ran to the end, 1 when it diverged, was refused or
is not finite (and says why), 2 on a bad argument.";

#[derive(Debug, Clone, Copy, PartialEq)]
enum Scene {
    Lab,
    Assignment,
    Cape,
    Drape,
}

#[derive(Debug, Clone)]
struct Options {
    scene: Scene,
    method: AnyMethod,
    n: Option<usize>,
    cloths: usize,
    rows: usize,
    cols: usize,
    steps: usize,
    iterations: Option<u32>,
    k: Option<f32>,
    dt: Option<f64>,
    damping: Option<f32>,
    mass: Option<f32>,
    material: Option<ClothMaterial>,
    rho: Option<f32>,
    refinement: Option<u32>,
    chains: bool,
    /// Whether `--method` was given (the drape scene's default is the
    /// game's, `stiff`; the cape scene's `character::GARMENT_METHOD`).
    method_given: bool,
    sphere: bool,
    /// The drape scene without its sheets' self-collision.
    no_self_collision: bool,
    /// When the drape scene throws its ball (s).
    throw_at: Option<f32>,
    penalty: f32,
    exact_k: bool,
    global: Option<GlobalSolve>,
    dump: Option<String>,
    compute_threads: Option<usize>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            scene: Scene::Lab,
            method: bevy_cloth::methods::preset("chebyshev")
                .expect("a preset")
                .method,
            n: None,
            cloths: 1,
            rows: 30,
            cols: 30,
            steps: 300,
            iterations: None,
            k: None,
            dt: None,
            damping: None,
            mass: None,
            material: None,
            rho: None,
            refinement: None,
            chains: false,
            method_given: false,
            sphere: false,
            no_self_collision: false,
            throw_at: None,
            penalty: 10.0,
            exact_k: false,
            global: None,
            dump: None,
            compute_threads: None,
        }
    }
}

fn parse_args(mut parser: Parser) -> Result<Options, CliError> {
    let mut o = Options::default();
    while let Some(arg) = parser.next()? {
        match arg {
            Long("scene") => {
                let scene: String = value(&mut parser, "--scene")?;
                o.scene = match scene.as_str() {
                    "lab" => Scene::Lab,
                    "assignment" => Scene::Assignment,
                    "cape" => Scene::Cape,
                    "drape" => Scene::Drape,
                    _ => {
                        return Err(format!(
                            "unknown scene '{scene}' (known: lab, assignment, cape, drape)"
                        )
                        .into());
                    }
                };
            }
            Long("method") => {
                o.method = value(&mut parser, "--method")?;
                o.method_given = true;
            }
            Long("n") => o.n = Some(value(&mut parser, "--n")?),
            Long("cloths") => o.cloths = value(&mut parser, "--cloths")?,
            Long("rows") => o.rows = value(&mut parser, "--rows")?,
            Long("cols") => o.cols = value(&mut parser, "--cols")?,
            Long("steps") => o.steps = value(&mut parser, "--steps")?,
            Long("iterations") => o.iterations = Some(value(&mut parser, "--iterations")?),
            Long("k") | Long("stiffness") => o.k = Some(value(&mut parser, "--k")?),
            Long("dt") | Long("h") => o.dt = Some(value(&mut parser, "--dt")?),
            Long("damping") => o.damping = Some(value(&mut parser, "--damping")?),
            Long("mass") => o.mass = Some(value(&mut parser, "--mass")?),
            Long("material") => {
                o.material = Some(parse_material(&value::<String>(
                    &mut parser,
                    "--material",
                )?)?)
            }
            Long("rho") => o.rho = Some(value(&mut parser, "--rho")?),
            Long("refinement") => o.refinement = Some(value(&mut parser, "--refinement")?),
            Long("chains") => o.chains = true,
            Long("sphere") => o.sphere = true,
            Long("no-self-collision") => o.no_self_collision = true,
            Long("throw-at") => o.throw_at = Some(value(&mut parser, "--throw-at")?),
            Long("penalty") => o.penalty = value(&mut parser, "--penalty")?,
            Long("exact-k") => o.exact_k = true,
            Long("global") => {
                o.global = Some(parse_global(&value::<String>(&mut parser, "--global")?)?)
            }
            Long("dump") => o.dump = Some(value(&mut parser, "--dump")?),
            Long("compute-threads") => {
                o.compute_threads = Some(value(&mut parser, "--compute-threads")?)
            }
            Long("help") | Short('h') => return Err(CliError::Help),
            _ => return Err(arg.unexpected().into()),
        }
    }
    if !o.method_given {
        match o.scene {
            Scene::Cape => o.method = character::GARMENT_METHOD,
            Scene::Drape => o.method = AnyMethod::default(),
            Scene::Lab | Scene::Assignment => {}
        }
    }
    if o.iterations == Some(0) {
        return Err("--iterations must be at least 1".into());
    }
    if o.cloths == 0 {
        return Err("--cloths must be at least 1".into());
    }
    if let Some(k) = o.iterations {
        o.method = match o.method {
            // `stiff` has substeps where the others have iterations: K per
            // step of the scene's time step.
            AnyMethod::Xpbd(x) => {
                let dt = o.dt.unwrap_or(match o.scene {
                    Scene::Lab => LAB_DT,
                    Scene::Assignment => ASSIGNMENT_DT,
                    Scene::Cape => character::DT,
                    Scene::Drape => drape::DT,
                });
                AnyMethod::Xpbd(x.with_substeps(k, dt))
            }
            method => method.with_iterations(k),
        };
    }
    match (&mut o.method, o.refinement) {
        (AnyMethod::Xpbd(x), Some(r)) if r >= 1 => *x = x.with_max_refinement(r),
        (_, Some(_)) => {
            return Err("--refinement goes with stiff and is at least 1".into());
        }
        _ => {}
    }
    match (&mut o.method, o.chains) {
        (AnyMethod::Xpbd(x), true) => *x = x.with_chains(true),
        (_, true) => return Err("--chains goes with stiff".into()),
        _ => {}
    }
    match (&mut o.method, o.rho) {
        (AnyMethod::Implicit(i), Some(rho)) => i.chebyshev = Some(Rho::Fixed(rho)),
        (_, Some(_)) => return Err("--rho goes with the implicit methods".into()),
        _ => {}
    }
    if o.exact_k {
        match &mut o.method {
            AnyMethod::Linear(l) => l.springs = SpringJacobian::Exact,
            _ => return Err("--exact-k goes with the linearly implicit methods".into()),
        }
    }
    if let Some(global) = o.global {
        match &mut o.method {
            AnyMethod::Projective(p) => p.global = global,
            _ => return Err("--global goes with the projective methods (pd, pd-anderson)".into()),
        }
    }
    o.method.validate().map_err(|e| e.to_string())?;
    Ok(o)
}

/// `auto`, `direct`, `mg` (one V-cycle) or `mgN` (`N` V-cycles).
fn parse_global(value: &str) -> Result<GlobalSolve, String> {
    match value {
        "auto" => Ok(GlobalSolve::Auto),
        "direct" => Ok(GlobalSolve::Direct),
        "mg" => Ok(GlobalSolve::Multigrid { cycles: 1 }),
        _ => value
            .strip_prefix("mg")
            .and_then(|n| n.parse().ok())
            .map(|cycles| GlobalSolve::Multigrid { cycles })
            .ok_or_else(|| format!("--global: expected auto, direct, mg or mgN, got '{value}'")),
    }
}

/// `cotton`, or `E,RHO`: a stretch modulus in N/m and an areal density in
/// kg/m² (the rest of cotton's moduli kept).
fn parse_material(value: &str) -> Result<ClothMaterial, String> {
    if value == "cotton" {
        return Ok(ClothMaterial::COTTON);
    }
    let bad = || format!("--material: expected cotton or E,RHO (N/m, kg/m²), got '{value}'");
    let (e, rho) = value.split_once(',').ok_or_else(bad)?;
    let (e, rho): (f32, f32) = (
        e.trim().parse().map_err(|_| bad())?,
        rho.trim().parse().map_err(|_| bad())?,
    );
    let material = ClothMaterial::COTTON.with_stretch(e).with_density(rho);
    material
        .validate()
        .map_err(|e| format!("--material: {e}"))?;
    Ok(material)
}

/// The lab's time step.
const LAB_DT: f64 = 0.0333;
/// The assignment's time step.
const ASSIGNMENT_DT: f64 = 5e-3;

/// The scene's cloth, parameters and time step.
fn scene(o: &Options) -> Result<(ClothBuilder, ClothParams, f64), String> {
    let (builder, params, dt) = match o.scene {
        Scene::Lab => {
            let n = o.n.unwrap_or(21);
            let b = ClothBuilder::lab_grid(n)
                .with_pins([0, n.saturating_sub(1) as u32])
                .with_total_mass(o.mass.unwrap_or(441.0));
            (b, ClothParams::LAB, LAB_DT)
        }
        Scene::Cape | Scene::Drape => {
            return Err("the cape and drape scenes build their own cloths".into());
        }
        Scene::Assignment => {
            let mut b = ClothBuilder::assignment(o.rows, o.cols);
            if let Some(total) = o.mass {
                b = b.with_total_mass(total);
            }
            let params = ClothParams::default()
                .with_stiffness(10.0)
                .with_damping(1.0)
                .with_particle_radius(0.01);
            (b, params, ASSIGNMENT_DT)
        }
    };
    let mut params = params;
    if let Some(k) = o.k {
        params = params.with_stiffness(k);
    }
    if let Some(d) = o.damping {
        params = params.with_damping(d);
    }
    let dt = o.dt.unwrap_or(dt);
    params
        .step_params(dt)
        .validate()
        .map_err(|e| e.to_string())?;
    Ok((builder, params, dt))
}

/// Step times of the cloth, one per fixed step.
#[derive(Resource, Default)]
struct StepTimes(Vec<Duration>);

fn record(mut times: ResMut<StepTimes>, stats: Query<&ClothStats>) {
    for s in &stats {
        times.0.push(s.step_time);
    }
}

/// The assignment's moving sphere: z = 0.5·sin(t/2).
#[derive(Component)]
struct Sweeping;

fn sweep(time: Res<Time>, mut spheres: Query<&mut Transform, With<Sweeping>>) {
    for mut t in &mut spheres {
        t.translation.z = 0.5 * (0.5 * time.elapsed_secs_f64()).sin() as f32;
    }
}

fn run(o: &Options) -> Result<(), String> {
    if o.scene == Scene::Cape {
        return run_cape(o);
    }
    if o.scene == Scene::Drape {
        return run_drape(o);
    }
    let (builder, params, dt) = scene(o)?;
    let model = builder.build().map_err(|e| e.to_string())?;
    let mut app = App::new();
    // Bevy gives its compute pool what the IO and async pools leave: one
    // thread on a 2-core machine. `--compute-threads` asks for more, so the
    // chunked solver loops of a large cloth can run in parallel.
    let mut tasks = TaskPoolOptions::default();
    if let Some(n) = o.compute_threads {
        tasks.compute.min_threads = n;
    }
    app.add_plugins((
        MinimalPlugins.set(TaskPoolPlugin {
            task_pool_options: tasks,
        }),
        ClothPlugins::default(),
    ))
    .insert_resource(Time::<Fixed>::from_seconds(dt))
    .insert_resource(TimeUpdateStrategy::FixedTimesteps(1))
    .init_resource::<StepTimes>()
    .add_systems(
        FixedUpdate,
        (
            sweep.in_set(ClothSystems::First),
            record.in_set(ClothSystems::Last),
        ),
    );
    let mut ids = Vec::new();
    for c in 0..o.cloths {
        let mut cloth = app.world_mut().spawn((
            Cloth::new(model.clone()),
            params,
            Transform::from_xyz(12.0 * c as f32, 0.0, 0.0),
        ));
        if let Some(material) = o.material {
            cloth.insert(material);
        }
        o.method.insert_now(&mut cloth);
        ids.push(cloth.id());
    }
    let cloth = ids[0];
    if o.sphere {
        match o.scene {
            Scene::Lab => {
                app.world_mut().spawn((
                    SphereCollider::new(2.7),
                    Transform::from_xyz(0.0, -4.0, 4.0),
                ));
            }
            Scene::Cape | Scene::Drape => {}
            Scene::Assignment => {
                app.world_mut().spawn((
                    SphereCollider::penalty(0.1, o.penalty),
                    Transform::from_xyz(0.0, 0.2, 0.0),
                    Sweeping,
                ));
            }
        }
    }
    // Let one update carry a whole step even when dt exceeds Bevy's default
    // 0.25 s cap on a frame's virtual time.
    app.world_mut()
        .resource_mut::<Time<Virtual>>()
        .set_max_delta(Duration::from_secs_f64(dt.max(0.25)));
    app.finish();
    app.cleanup();
    // The first update starts the clock; each later one runs one fixed step.
    app.update();
    let mut updates = Vec::with_capacity(o.steps);
    for _ in 0..o.steps {
        let t = std::time::Instant::now();
        app.update();
        updates.push(t.elapsed());
    }
    updates.sort();
    let median_update = updates.get(updates.len() / 2).copied().unwrap_or_default();

    let world = app.world();
    let stats = world.get::<ClothStats>(cloth).expect("cloth exists");
    let positions = world.get::<Cloth>(cloth).expect("cloth exists").positions();
    let mut times = world.resource::<StepTimes>().0.clone();
    times.sort();
    let median = times.get(times.len() / 2).copied().unwrap_or_default();
    let lowest = positions.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
    let finite = positions.iter().all(|p| p.is_finite());
    println!(
        "scene={:?} method={} vertices={} cloths={} steps={} iterations={} residual={} relative_error={} unconverged_steps={} median_step_us={:.1} median_update_us={:.1} retried_steps={} max_stretch={:.4} lowest_y={:.4} finite={} status={:?}",
        o.scene,
        stats.method,
        positions.len(),
        o.cloths,
        stats.steps,
        stats.iterations,
        stats
            .residual
            .map_or_else(|| "-".to_string(), |r| format!("{r:.3e}")),
        stats
            .relative_error
            .map_or_else(|| "-".to_string(), |r| format!("{r:.3}")),
        stats.unconverged_steps,
        median.as_secs_f64() * 1e6,
        median_update.as_secs_f64() * 1e6,
        stats.retried_steps,
        stats.max_stretch,
        lowest,
        finite,
        stats.status,
    );
    if let Some(path) = &o.dump {
        let mut csv = String::from("i,x,y,z\n");
        for (i, p) in positions.iter().enumerate() {
            csv.push_str(&format!("{i},{},{},{}\n", p.x, p.y, p.z));
        }
        std::fs::write(path, csv).map_err(|e| format!("cannot write {path}: {e}"))?;
    }
    // A run whose cloth stopped is a failed run: say why, exit non-zero.
    if !finite {
        return Err("the cloth's positions are not finite".into());
    }
    match &stats.status {
        ClothStatus::Running => Ok(()),
        status => Err(format!("the cloth did not finish running: {status:?}")),
    }
}

/// The drape scene: two sheets of `--n`² cotton (default 32) dropped onto a
/// ball, folding onto themselves and each other; prints the first sheet's
/// line and `penetrations=` (mesh edges through a triangle of either
/// sheet, summed over every step: the exact check).
fn run_drape(o: &Options) -> Result<(), String> {
    let n = o.n.unwrap_or(32);
    if !(2..=256).contains(&n) {
        return Err("--n (the sheets' side) must be between 2 and 256".into());
    }
    if o.throw_at.is_some_and(|t| !(t.is_finite() && t >= 0.0)) {
        return Err("--throw-at must be a time in seconds, 0 or more".into());
    }
    let settings = drape::DrapeSettings {
        method: o.method,
        n,
        self_collision: !o.no_self_collision,
        throw_at: o.throw_at,
    };
    let run = drape::run_headless(settings, o.steps);
    let Some((vertices, stats, median)) = run.sheets.first() else {
        return Err("the drape scene has no sheet".into());
    };
    let p = &run.penetrations;
    let finite = run.sheets.iter().all(|(_, s, _)| s.energy.is_finite());
    let running = run.sheets.iter().all(|(_, s, _)| s.is_running());
    let statuses: Vec<String> = run
        .sheets
        .iter()
        .map(|(_, s, _)| format!("{:?}", s.status))
        .collect();
    println!(
        "scene=Drape method={} vertices={vertices} sheets={} steps={} median_step_us={:.1} retried_steps={} max_stretch={:.4} self_contacts={} finite={finite} status={} {}",
        stats.method,
        run.sheets.len(),
        stats.steps,
        median.as_secs_f64() * 1e6,
        run.sheets
            .iter()
            .map(|(_, s, _)| s.retried_steps)
            .sum::<u64>(),
        p.max_stretch,
        stats.self_contacts,
        statuses.join(","),
        p.summary(),
    );
    if finite && running {
        Ok(())
    } else {
        Err("a sheet stopped".into())
    }
}

/// The cape scene: the character runs, turns, jumps and is teleported 100 m
/// at 6 s; prints the cape's line and the body's count.
fn run_cape(o: &Options) -> Result<(), String> {
    let settings = character::CapeSettings {
        method: o.method,
        cape_cols: o.n.unwrap_or(20),
        ..Default::default()
    };
    if !(2..=200).contains(&settings.cape_cols) {
        return Err("--n (the cape's columns) must be between 2 and 200".into());
    }
    let run = character::run_headless(settings, o.steps, Some(6.0));
    let stretch = |name| {
        run.garments
            .iter()
            .find(|g| g.name == name)
            .map_or(f32::NAN, |g| g.max_stretch)
    };
    if let Some(cape) = run.garments.iter().find(|g| g.name == "cape") {
        println!(
            "scene=Cape method={} vertices={} steps={} median_step_us={:.1} retried_steps={} max_stretch={:.4} skirt_max_stretch={:.4} finite={} status={:?} teleports={} body_penetrations={} deepest_mm={:.2}",
            cape.method,
            cape.vertices,
            cape.steps,
            cape.median_step().as_secs_f64() * 1e6,
            cape.retried_steps,
            cape.max_stretch,
            stretch("skirt"),
            cape.finite,
            cape.status,
            run.teleports,
            run.penetrations.count,
            1e3 * run.penetrations.deepest
        );
    }
    match run.garments.iter().find(|g| !g.clean()) {
        Some(g) => Err(format!(
            "the {} did not run cleanly: finite={} retried_steps={} status={:?}",
            g.name, g.finite, g.retried_steps, g.status
        )),
        None if run.garments.is_empty() => Err("the scene has no garments".into()),
        None => Ok(()),
    }
}

fn main() -> ExitCode {
    let options = match cli::parse_args(USAGE, parse_args) {
        Ok(o) => o,
        Err(code) => return code,
    };
    match run(&options) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
