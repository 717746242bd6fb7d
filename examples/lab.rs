//! The Unity cloth lab as a Bevy scene: the 21×21 cloth pinned at two
//! corners, the sphere of radius 2.7, an orbit camera, the sphere picked and
//! dragged with the mouse, and a panel to switch methods and tune them live.
//!
//! ```text
//! cargo run --example lab -- [--scene lab|stiff-fabric] [--method M] [--n 21] \
//!     [--screenshot out.png --frames 120]
//! ```
//!
//! Two scenes, also buttons in the panel: `lab` (the default), the Unity
//! lab's cloth as it is (`k = 8000`: it stretches about a third where it
//! drapes), and `stiff-fabric`, the same cloth as a woven fabric (`k = 1e7`,
//! the `stiff` method: it drapes stretched by about 1 %). `--method`
//! replaces the scene's method.
//!
//! Mouse: drag empty space to orbit, right-drag to pan, wheel to zoom; press
//! on the sphere and drag to move it. Keys: space pauses, `h` steps once, `r`
//! resets. `--screenshot` renders that many frames, saves a PNG and exits.

#[path = "cli/mod.rs"]
mod cli;
#[path = "common/mod.rs"]
mod common;

use std::process::ExitCode;

use bevy::picking::Pickable;
use bevy::prelude::*;
use bevy_cloth::drag::Draggable;
use bevy_cloth::prelude::*;
use bevy_cloth::render::cloth_mesh;
use bevy_cloth::ui::{ClothResolution, ClothScene, ClothScenes};
use cli::{CliError, Long, Parser, Short, value};
use common::{ScreenshotArgs, ScreenshotMode};

const USAGE: &str = "usage: lab [--scene lab|stiff-fabric] [--method jacobi|chebyshev|chebyshev-auto|pbd|symplectic|linear-cg|linear-direct|pd|pd-anderson|newton|exact|stiff] \
[--n N] [--screenshot FILE.png --frames N]";

#[derive(Resource, Clone, Copy)]
struct LabOptions {
    scene: ClothScene,
    method: Option<AnyMethod>,
    n: u32,
}

/// The lab's scenes: the faithful one and the stiff fabric.
fn scenes() -> [ClothScene; 2] {
    let preset = |name| bevy_cloth::methods::preset(name).expect("a preset").method;
    [
        ClothScene {
            label: "Lab (faithful)",
            about: "the Unity lab's cloth: k = 8000, Chebyshev 32",
            params: ClothParams::LAB,
            method: preset("chebyshev"),
        },
        ClothScene {
            label: "Stiff fabric",
            about: "k = 1e7 with the stiff method (XPBD, 960 substeps per second): drapes stretched about 1 %",
            params: ClothParams::default().with_stiffness(STIFF_FABRIC_K),
            method: preset("stiff"),
        },
    ]
}

/// The stiff fabric's spring stiffness: stiff enough that the cloth drapes
/// on the sphere as a woven fabric does, barely stretched, with the `stiff`
/// method (the README's screenshot shows its stretch).
const STIFF_FABRIC_K: f32 = 1e7;

fn parse(mut parser: Parser) -> Result<(LabOptions, Option<ScreenshotMode>), CliError> {
    let mut screenshot = ScreenshotArgs::default();
    let mut options = LabOptions {
        scene: scenes()[0],
        method: None,
        n: 21,
    };
    while let Some(arg) = parser.next()? {
        match arg {
            Long("screenshot") => screenshot.set_path(&mut parser)?,
            Long("frames") => screenshot.set_frames(&mut parser)?,
            Long("method") => options.method = Some(value(&mut parser, "--method")?),
            Long("scene") => {
                let name: String = value(&mut parser, "--scene")?;
                options.scene = match name.as_str() {
                    "lab" => scenes()[0],
                    "stiff-fabric" => scenes()[1],
                    _ => return Err(format!("--scene is lab or stiff-fabric, got {name}").into()),
                };
            }
            Long("n") => {
                options.n = value(&mut parser, "--n")?;
                if !(2..=201).contains(&options.n) {
                    return Err(format!("--n must lie in 2..=201, got {}", options.n).into());
                }
            }
            Long("help") | Short('h') => return Err(CliError::Help),
            _ => return Err(arg.unexpected().into()),
        }
    }
    Ok((options, screenshot.finish()))
}

/// The lab's cloth at resolution `n`: 10×10 units, pinned at 0 and n − 1,
/// with the lab's total mass of 441 (1 per vertex at 21²) at every `n`.
/// With 1 per vertex a 101² sheet is 23× heavier on the same springs: it
/// stretched to 9.6× its length and the guard stopped it (the exact method
/// too). Like the headless example and the report, the slider changes the
/// resolution, not the cloth.
fn lab_cloth(n: u32) -> Result<ClothModel, ClothBuildError> {
    ClothBuilder::lab_grid(n as usize)
        .with_pins([0, n - 1])
        .with_total_mass(LAB_MASS)
        .build()
}

/// The Unity lab's cloth: 21² vertices of mass 1.
const LAB_MASS: f32 = 441.0;

fn main() -> ExitCode {
    let (options, screenshot) = match cli::parse_args(USAGE, parse) {
        Ok(parsed) => parsed,
        Err(code) => return code,
    };
    let mut app = common::windowed_app("bevy_cloth — lab", 0.0333, screenshot);
    app.insert_resource(options)
        .add_systems(Startup, setup)
        .add_systems(Update, draw_spheres_at_their_radius);
    common::run(app)
}

/// The drawn sphere is this much smaller than the collision sphere: the
/// projection puts vertices on the collision surface, and the flat triangles
/// between them cut chords up to ~0.9 % of the radius deep into it (a 0.7
/// diagonal across a 2.7 sphere), so a sphere drawn at full size pokes
/// through the cloth between its vertices.
const DRAWN_RADIUS: f32 = 0.985;

/// Scales each sphere's unit mesh to its collider's radius (the panel's
/// radius slider changes the collider), times [`DRAWN_RADIUS`].
fn draw_spheres_at_their_radius(
    mut spheres: Query<(&SphereCollider, &mut Transform), Changed<SphereCollider>>,
) {
    for (sphere, mut transform) in &mut spheres {
        transform.scale = Vec3::splat(sphere.radius * DRAWN_RADIUS);
    }
}

fn setup(
    mut commands: Commands,
    options: Res<LabOptions>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut images: ResMut<Assets<Image>>,
) -> Result {
    let model = lab_cloth(options.n)?;
    let cloth_material = common::checker_material(
        &mut materials,
        &mut images,
        10,
        Color::srgb(0.85, 0.25, 0.2),
        Color::srgb(0.95, 0.9, 0.8),
    );
    let mut cloth = commands.spawn((
        Mesh3d(meshes.add(cloth_mesh(&model))),
        MeshMaterial3d(cloth_material),
        Cloth::new(model),
        options.scene.params,
        ClothScenes(scenes().to_vec()),
        Transform::default(),
        ClothResolution {
            n: options.n,
            range: (5, 101),
            build: lab_cloth,
        },
        // Clicks go through the cloth to the sphere behind it.
        Pickable::IGNORE,
    ));
    options
        .method
        .unwrap_or(options.scene.method)
        .insert(&mut cloth);
    commands.spawn((
        Mesh3d(meshes.add(Sphere::new(1.0).mesh().ico(5)?)),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.25, 0.45, 0.85),
            perceptual_roughness: 0.4,
            ..default()
        })),
        Transform::from_xyz(0.0, -4.0, 4.0).with_scale(Vec3::splat(2.7 * DRAWN_RADIUS)),
        SphereCollider::new(2.7),
        Draggable,
    ));
    common::light_and_ground(&mut commands, &mut meshes, &mut materials, -12.5, 60.0);
    common::orbit_camera(&mut commands, Vec3::new(0.0, -5.0, 3.0), 22.0);
    Ok(())
}
