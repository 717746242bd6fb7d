//! A long run of the lab scene with the sphere moving: checks that pins do
//! not drift, nothing goes non-finite, the guard stays silent and the energy
//! stays bounded, and prints the figures.
//!
//! ```text
//! cargo run --release --example soak -- [--steps 100000] [--method chebyshev]
//! ```
//!
//! The lab's 21×21 cloth hangs from its two pins; the lab's sphere (radius
//! 2.7, projection) circles through it, once every 10 s. Exits with status 1
//! if a check fails.

#[path = "cli/mod.rs"]
mod cli;

use std::process::ExitCode;
use std::time::Instant;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;
use cli::{CliError, Long, Parser, Short, value};

#[derive(Component)]
struct Orbiting;

fn orbit(time: Res<Time>, mut spheres: Query<&mut Transform, With<Orbiting>>) {
    let t = time.elapsed_secs_f64() * std::f64::consts::TAU / 10.0;
    for mut transform in &mut spheres {
        transform.translation = Vec3::new(3.0 * t.cos() as f32, -4.0, 3.0 * t.sin() as f32);
    }
}

#[derive(Resource, Default)]
struct Guarded(u64);

fn count(mut messages: MessageReader<ClothDiverged>, mut seen: ResMut<Guarded>) {
    seen.0 += messages.read().count() as u64;
}

fn main() -> ExitCode {
    let mut steps: u64 = 100_000;
    let mut method = bevy_cloth::methods::preset("chebyshev")
        .expect("a preset")
        .method;
    let parse = |mut parser: Parser| -> Result<(), CliError> {
        while let Some(arg) = parser.next()? {
            match arg {
                Long("steps") => steps = value(&mut parser, "--steps")?,
                Long("method") => method = value(&mut parser, "--method")?,
                Long("help") | Short('h') => return Err(CliError::Help),
                _ => return Err(arg.unexpected().into()),
            }
        }
        Ok(())
    };
    if let Err(code) = cli::parse_args("usage: soak [--steps N] [--method NAME]", parse) {
        return code;
    }
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, ClothPlugins::default()))
        .insert_resource(Time::<Fixed>::from_seconds(StepParams::LAB.dt))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1))
        .init_resource::<Guarded>()
        .add_systems(ClothSchedule, orbit.in_set(ClothSystems::First))
        .add_systems(ClothSchedule, count.in_set(ClothSystems::Last));
    let cloth = app
        .world_mut()
        .spawn((
            Cloth::build(ClothBuilder::lab()).expect("the lab cloth"),
            Transform::default(),
        ))
        .id();
    method.insert(&mut app.world_mut().commands().entity(cloth));
    app.world_mut().spawn((
        SphereCollider::new(2.7),
        Transform::from_xyz(3.0, -4.0, 0.0),
        Orbiting,
    ));
    app.finish();
    app.cleanup();

    let start = Instant::now();
    let mut pin_drift = 0.0f32;
    let mut energy_min = f64::INFINITY;
    let mut energy_max = f64::NEG_INFINITY;
    let mut first_window_max = f64::NEG_INFINITY;
    let mut last_window_max = f64::NEG_INFINITY;
    let mut max_stretch = 0.0f32;
    let mut finite = true;
    let window = (steps / 10).max(1);
    let mut done = 0;
    while done < steps {
        app.update();
        let stats = app.world().get::<ClothStats>(cloth).expect("stats").clone();
        if stats.steps == done {
            continue;
        }
        done = stats.steps;
        let c = app.world().get::<Cloth>(cloth).expect("cloth");
        finite &= c.state().is_finite();
        let rest = c.model().topology().rest_positions();
        for &p in c.model().pins() {
            pin_drift =
                pin_drift.max(c.positions()[p as usize].distance(Vec3A::from(rest[p as usize])));
        }
        // The first second is the cloth falling from its flat start.
        if done > 30 {
            energy_min = energy_min.min(stats.energy);
            energy_max = energy_max.max(stats.energy);
            max_stretch = max_stretch.max(stats.max_stretch);
            if done <= window {
                first_window_max = first_window_max.max(stats.energy);
            }
            if done > steps - window {
                last_window_max = last_window_max.max(stats.energy);
            }
        }
        if !stats.is_running() {
            break;
        }
    }
    let elapsed = start.elapsed();
    let stats = app.world().get::<ClothStats>(cloth).expect("stats").clone();
    let guarded = app.world().resource::<Guarded>().0;
    println!(
        "soak: {} steps of '{}' in {:.1} s ({:.1} µs per update); status {:?}; guard messages {guarded}; \
         pin drift {pin_drift:.2e}; all finite {finite}; max stretch {max_stretch:.4}; \
         energy after the first second in [{energy_min:.1}, {energy_max:.1}], \
         max in the first tenth {first_window_max:.1}, in the last tenth {last_window_max:.1}",
        stats.steps,
        stats.method,
        elapsed.as_secs_f64(),
        elapsed.as_secs_f64() * 1e6 / stats.steps.max(1) as f64,
        stats.status,
    );
    // Bounded: the last tenth never exceeds the first tenth's peak by more
    // than 10 % of the energy range seen.
    let bounded =
        last_window_max <= first_window_max + 0.1 * (energy_max - energy_min).abs() + 1e-6;
    let ok = stats.steps == steps
        && stats.is_running()
        && finite
        && guarded == 0
        && pin_drift < 1e-4
        && bounded;
    if ok {
        ExitCode::SUCCESS
    } else {
        eprintln!("soak failed");
        ExitCode::FAILURE
    }
}
