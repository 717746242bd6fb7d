//! The mass-spring assignment's scene: a particle grid with stretch, shear
//! and bending springs, two corners fixed, falling from horizontal, and a
//! moving penalty sphere sweeping through it; linearly implicit Euler with
//! sparse conjugate gradients by default.
//!
//! ```text
//! cargo run --example assignment -- [--method linear-cg|linear-direct|symplectic|...]
//!     [--rows 30] [--cols 30] [--h 5e-3] [--stiffness 10] [--mass 0.1]
//!     [--screenshot out.png --frames 120]
//! ```
//!
//! Space pauses and resumes, `h` runs one step, `r` resets (as in the
//! assignment). The sphere's path is ours (the assignment leaves it open):
//! radius 0.1, centre (0, 0.2, 0.5·sin(t/2)) with `t` the simulated time.

#[path = "cli/mod.rs"]
mod cli;
#[path = "common/mod.rs"]
mod common;

use std::process::ExitCode;

use bevy::picking::Pickable;
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use bevy_cloth::render::cloth_mesh;
use cli::{CliError, Long, Parser, Short, value};
use common::{ScreenshotArgs, ScreenshotMode};

const USAGE: &str = "usage: assignment [--method M] [--rows R] [--cols C] [--h SECONDS] \
[--stiffness E] [--mass TOTAL] [--screenshot FILE.png --frames N]";

#[derive(Resource, Clone, Copy)]
struct Options {
    method: AnyMethod,
    rows: usize,
    cols: usize,
    h: f64,
    stiffness: f32,
    mass: f32,
}

fn parse(mut parser: Parser) -> Result<(Options, Option<ScreenshotMode>), CliError> {
    let mut screenshot = ScreenshotArgs::default();
    let mut o = Options {
        method: bevy_cloth::methods::preset("linear-cg")
            .expect("a preset")
            .method,
        rows: 30,
        cols: 30,
        h: 5e-3,
        stiffness: 10.0,
        mass: 0.1,
    };
    while let Some(arg) = parser.next()? {
        match arg {
            Long("screenshot") => screenshot.set_path(&mut parser)?,
            Long("frames") => screenshot.set_frames(&mut parser)?,
            Long("method") => o.method = value(&mut parser, "--method")?,
            Long("rows") => o.rows = value(&mut parser, "--rows")?,
            Long("cols") => o.cols = value(&mut parser, "--cols")?,
            Long("h") | Long("dt") => o.h = value(&mut parser, "--dt")?,
            Long("stiffness") | Long("k") => o.stiffness = value(&mut parser, "--k")?,
            Long("mass") => o.mass = value(&mut parser, "--mass")?,
            Long("help") | Short('h') => return Err(CliError::Help),
            _ => return Err(arg.unexpected().into()),
        }
    }
    let params = ClothParams::default().with_stiffness(o.stiffness);
    params
        .step_params(o.h)
        .validate()
        .map_err(|e| e.to_string())?;
    Ok((o, screenshot.finish()))
}

/// Marks the sphere that sweeps through the cloth.
#[derive(Component)]
struct Sweeping;

fn main() -> ExitCode {
    let (options, screenshot) = match cli::parse_args(USAGE, parse) {
        Ok(parsed) => parsed,
        Err(code) => return code,
    };
    let mut app = common::windowed_app("bevy_cloth — assignment", options.h, screenshot);
    app.insert_resource(options)
        .add_systems(Startup, setup)
        .add_systems(ClothSchedule, sweep.in_set(ClothSystems::First));
    common::run(app)
}

/// Moves the sphere with the simulated time (it stops while paused).
fn sweep(
    options: Res<Options>,
    cloths: Query<&ClothStats>,
    mut spheres: Query<&mut Transform, With<Sweeping>>,
) {
    let steps = cloths.iter().map(|s| s.steps).max().unwrap_or(0);
    let t = steps as f64 * options.h;
    for mut transform in &mut spheres {
        transform.translation.z = 0.5 * (0.5 * t).sin() as f32;
    }
}

fn setup(
    mut commands: Commands,
    options: Res<Options>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut images: ResMut<Assets<Image>>,
) -> Result {
    let model = ClothBuilder::assignment(options.rows, options.cols)
        .with_total_mass(options.mass)
        .build()?;
    let mut cloth = commands.spawn((
        Mesh3d(meshes.add(cloth_mesh(&model))),
        MeshMaterial3d(common::checker_material(
            &mut materials,
            &mut images,
            8,
            Color::srgb(0.2, 0.6, 0.45),
            Color::srgb(0.92, 0.92, 0.85),
        )),
        Cloth::new(model),
        ClothParams::default()
            .with_stiffness(options.stiffness)
            .with_damping(1.0)
            .with_particle_radius(0.01),
        Transform::default(),
        Pickable::IGNORE,
    ));
    options.method.insert(&mut cloth);
    commands.spawn((
        Mesh3d(meshes.add(Sphere::new(0.1).mesh().ico(4)?)),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.85, 0.55, 0.2),
            ..default()
        })),
        Transform::from_xyz(0.0, 0.2, 0.0),
        SphereCollider::penalty(0.1, 10.0),
        Sweeping,
    ));
    common::light_and_ground(&mut commands, &mut meshes, &mut materials, -0.05, 3.0);
    common::orbit_camera(&mut commands, Vec3::new(0.0, 0.25, -0.1), 1.6);
    Ok(())
}
