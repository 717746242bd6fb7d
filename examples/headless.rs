//! Runs the cloth plugin in a window-less `App` for a number of fixed steps
//! and prints one summary line.
//!
//! ```text
//! cargo run --release --example headless -- --scene lab --method implicit|chebyshev|pbd \
//!     --n 21 --steps 300 [--iterations 32] [--k 8000] [--dt 0.0333] [--damping 0.99] \
//!     [--rho 0.995] [--sphere] [--dump positions.csv]
//! ```
//!
//! Defaults are the lab's. `--sphere` adds a sphere of radius 2.7 at
//! (0, −4, 4) that the swinging cloth falls onto. `--dump` writes the final
//! positions as CSV `i,x,y,z`.

use std::process::ExitCode;
use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;

const USAGE: &str = "usage: headless [--scene lab] [--method implicit|chebyshev|pbd] [--n N] \
[--steps S] [--iterations K] [--k STIFFNESS] [--dt SECONDS] [--damping D] [--rho RHO] \
[--sphere] [--dump FILE.csv]";

#[derive(Debug, Clone, Copy, PartialEq)]
enum Method {
    Implicit,
    Chebyshev,
    Pbd,
}

#[derive(Debug, Clone)]
struct Options {
    method: Method,
    n: usize,
    steps: usize,
    iterations: u32,
    k: f32,
    dt: f32,
    damping: f32,
    rho: f32,
    sphere: bool,
    dump: Option<String>,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            method: Method::Implicit,
            n: 21,
            steps: 300,
            iterations: 32,
            k: 8000.0,
            dt: 0.0333,
            damping: 0.99,
            rho: 0.995,
            sphere: false,
            dump: None,
        }
    }
}

fn parse<T: std::str::FromStr>(flag: &str, value: Option<String>) -> Result<T, String> {
    let value = value.ok_or_else(|| format!("{flag} needs a value"))?;
    value
        .parse()
        .map_err(|_| format!("{flag}: cannot parse '{value}'"))
}

fn parse_args(args: impl IntoIterator<Item = String>) -> Result<Options, String> {
    let mut o = Options::default();
    let mut args = args.into_iter();
    while let Some(flag) = args.next() {
        match flag.as_str() {
            "--scene" => {
                let scene: String = parse(&flag, args.next())?;
                if scene != "lab" {
                    return Err(format!("unknown scene '{scene}' (known: lab)"));
                }
            }
            "--method" => {
                let m: String = parse(&flag, args.next())?;
                o.method = match m.as_str() {
                    "implicit" => Method::Implicit,
                    "chebyshev" => Method::Chebyshev,
                    "pbd" => Method::Pbd,
                    _ => {
                        return Err(format!(
                            "unknown method '{m}' (known: implicit, chebyshev, pbd)"
                        ));
                    }
                };
            }
            "--n" => o.n = parse(&flag, args.next())?,
            "--steps" => o.steps = parse(&flag, args.next())?,
            "--iterations" => o.iterations = parse(&flag, args.next())?,
            "--k" => o.k = parse(&flag, args.next())?,
            "--dt" => o.dt = parse(&flag, args.next())?,
            "--damping" => o.damping = parse(&flag, args.next())?,
            "--rho" => o.rho = parse(&flag, args.next())?,
            "--sphere" => o.sphere = true,
            "--dump" => o.dump = Some(parse(&flag, args.next())?),
            "-h" | "--help" => return Err(String::new()),
            other => return Err(format!("unknown argument '{other}'")),
        }
    }
    if !(o.dt.is_finite() && o.dt > 0.0) {
        return Err(format!("--dt must be positive, got {}", o.dt));
    }
    let params = StepParams {
        dt: o.dt,
        stiffness: SpringStiffness::uniform(o.k),
        damping: o.damping,
        gravity: StepParams::LAB.gravity,
    };
    params.validate().map_err(|e| e.to_string())?;
    if o.iterations == 0 {
        return Err("--iterations must be at least 1".into());
    }
    if o.method == Method::Chebyshev && !(o.rho > 0.0 && o.rho < 1.0) {
        return Err(format!("--rho must lie in (0, 1), got {}", o.rho));
    }
    Ok(o)
}

/// Step times of the first cloth, one per fixed step.
#[derive(Resource, Default)]
struct StepTimes(Vec<Duration>);

fn record(mut times: ResMut<StepTimes>, stats: Query<&ClothStats>) {
    for s in &stats {
        times.0.push(s.step_time);
    }
}

fn run(o: &Options) -> Result<(), String> {
    let model = ClothBuilder::lab_grid(o.n)
        .with_pins([0, o.n as u32 - 1])
        .build()
        .map_err(|e| e.to_string())?;
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, ClothPlugins::default()))
        .insert_resource(Time::<Fixed>::from_seconds(f64::from(o.dt)))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1))
        .init_resource::<StepTimes>()
        .add_systems(FixedUpdate, record.in_set(ClothSystems::Last));
    let params = ClothParams::default()
        .with_stiffness(o.k)
        .with_damping(o.damping);
    let mut cloth = app
        .world_mut()
        .spawn((Cloth::new(model), params, Transform::default()));
    match o.method {
        Method::Implicit => cloth.insert(ImplicitSolver::jacobi(o.iterations)),
        Method::Chebyshev => cloth.insert(ImplicitSolver::chebyshev(o.iterations, o.rho)),
        Method::Pbd => cloth.insert(PbdSolver::new(o.iterations)),
    };
    let cloth = cloth.id();
    if o.sphere {
        app.world_mut().spawn((
            SphereCollider::new(2.7),
            Transform::from_xyz(0.0, -4.0, 4.0),
        ));
    }
    // Let one update carry a whole step even when dt exceeds Bevy's default
    // 0.25 s cap on a frame's virtual time.
    app.world_mut()
        .resource_mut::<Time<Virtual>>()
        .set_max_delta(Duration::from_secs_f64(f64::from(o.dt).max(0.25)));
    app.finish();
    app.cleanup();
    // The first update starts the clock; each later one runs one fixed step.
    app.update();
    for _ in 0..o.steps {
        app.update();
    }

    let world = app.world();
    let stats = world.get::<ClothStats>(cloth).expect("cloth exists");
    let positions = world.get::<Cloth>(cloth).expect("cloth exists").positions();
    let mut times = world.resource::<StepTimes>().0.clone();
    times.sort();
    let median = times.get(times.len() / 2).copied().unwrap_or_default();
    let lowest = positions.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
    let finite = positions.iter().all(|p| p.is_finite());
    println!(
        "scene=lab method={:?} n={} steps={} iterations={} median_step_us={:.1} max_stretch={:.4} lowest_y={:.4} finite={} status={:?}",
        o.method,
        o.n,
        stats.steps,
        o.iterations,
        median.as_secs_f64() * 1e6,
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
    Ok(())
}

fn main() -> ExitCode {
    let options = match parse_args(std::env::args().skip(1)) {
        Ok(o) => o,
        Err(e) => {
            if !e.is_empty() {
                eprintln!("error: {e}");
            }
            eprintln!("{USAGE}");
            return ExitCode::from(2);
        }
    };
    match run(&options) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
