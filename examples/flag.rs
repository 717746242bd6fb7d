//! A flag on a pole in gusty wind, over an avian ground with avian boxes
//! and a capsule to drag through the cloth.
//!
//! ```text
//! cargo run --example flag -- [--method M] [--screenshot out.png --frames 120]
//! ```
//!
//! The flag's edge is held by the pole entity (`ClothAttachments`); the wind
//! is the `Wind` resource (per-triangle drag and lift, deterministic gusts);
//! the ground, the boxes and the capsule are plain avian3d `Collider`s that
//! the cloth collides with through the crate's `avian` feature, with no
//! cloth component on them. Mouse: drag empty space to orbit, press on the
//! capsule and drag to move it through the flag. The "Wind" panel sets the
//! wind's speed, direction and gusts and the ground's friction; the
//! "bevy_cloth" panel switches the flag's method (default `pd-anderson`:
//! the light flag is stiff for its mass, where `pd` does not converge).

#[path = "cli/mod.rs"]
mod cli;
#[path = "common/mod.rs"]
mod common;

use std::process::ExitCode;

use avian3d::prelude::{Collider, Friction};
use bevy::picking::Pickable;
use bevy::prelude::*;
use bevy_cloth::drag::Draggable;
use bevy_cloth::prelude::*;
use bevy_cloth::render::cloth_mesh;
use bevy_egui::{EguiContexts, EguiPrimaryContextPass, egui};
use cli::{CliError, Long, Parser, Short, value};
use common::{ScreenshotArgs, ScreenshotMode};

const USAGE: &str = "usage: flag [--method NAME] [--screenshot FILE.png --frames N]";

/// The flag: 8 × 5 units, 33 × 21 vertices, 14 kg.
const FLAG_COLS: usize = 33;
const FLAG_ROWS: usize = 21;
/// The pole's height; the flag's top edge is at its top.
const POLE: f32 = 10.0;

#[derive(Resource, Clone, Copy)]
struct FlagOptions {
    method: AnyMethod,
}

/// The wind panel's settings (speed and heading rather than a vector).
#[derive(Resource, Clone, Copy)]
struct WindControls {
    speed: f32,
    heading_degrees: f32,
    turbulence: f32,
}

impl WindControls {
    fn wind(&self) -> Wind {
        let heading = self.heading_degrees.to_radians();
        Wind {
            seed: 11,
            ..Wind::new(self.speed * Vec3::new(heading.cos(), 0.0, heading.sin()))
                .with_turbulence(self.turbulence)
        }
    }
}

#[derive(Component)]
struct Ground;

fn parse(mut parser: Parser) -> Result<(FlagOptions, Option<ScreenshotMode>), CliError> {
    let mut screenshot = ScreenshotArgs::default();
    let mut options = FlagOptions {
        method: bevy_cloth::methods::preset("pd-anderson")
            .expect("a preset")
            .method,
    };
    while let Some(arg) = parser.next()? {
        match arg {
            Long("screenshot") => screenshot.set_path(&mut parser)?,
            Long("frames") => screenshot.set_frames(&mut parser)?,
            Long("method") => options.method = value(&mut parser, "--method")?,
            Long("help") | Short('h') => return Err(CliError::Help),
            _ => return Err(arg.unexpected().into()),
        }
    }
    Ok((options, screenshot.finish()))
}

fn main() -> ExitCode {
    let (options, screenshot) = match cli::parse_args(USAGE, parse) {
        Ok(parsed) => parsed,
        Err(code) => return code,
    };
    let controls = WindControls {
        speed: 9.0,
        heading_degrees: -10.0,
        turbulence: 0.4,
    };
    let mut app = common::windowed_app("bevy_cloth — flag", 1.0 / 60.0, screenshot);
    app.insert_resource(options)
        .insert_resource(controls)
        .insert_resource(controls.wind())
        .add_systems(Startup, setup)
        .add_systems(EguiPrimaryContextPass, wind_panel);
    common::run(app)
}

fn setup(
    mut commands: Commands,
    options: Res<FlagOptions>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut images: ResMut<Assets<Image>>,
) -> Result {
    // The flag in its own space: top-left corner at the origin, 8 units
    // along +x, 5 down.
    let mut model = ClothBuilder::grid(
        FLAG_ROWS,
        FLAG_COLS,
        Vec3::ZERO,
        Vec3::new(8.0, 0.0, 0.0),
        Vec3::new(0.0, -5.0, 0.0),
    )
    .with_total_mass(14.0)
    .build()?;
    let hoist = model.vertices_where(|p| p.x < 1e-3);
    model.set_pins(Vec::new())?;
    // The pole: a cylinder from the ground up, an avian collider too.
    let pole = commands
        .spawn((
            Mesh3d(meshes.add(Cylinder::new(0.12, POLE))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.8, 0.8, 0.82),
                metallic: 0.6,
                perceptual_roughness: 0.3,
                ..default()
            })),
            Transform::from_xyz(0.0, POLE / 2.0, 0.0),
            Collider::cylinder(0.12, POLE),
            Pickable::IGNORE,
        ))
        .id();
    let flag_material = common::checker_material(
        &mut materials,
        &mut images,
        8,
        Color::srgb(0.15, 0.3, 0.75),
        Color::srgb(0.95, 0.85, 0.2),
    );
    let mut flag = commands.spawn((
        Mesh3d(meshes.add(cloth_mesh(&model))),
        MeshMaterial3d(flag_material),
        Cloth::new(model),
        ClothParams::default().with_stiffness(2000.0),
        // The hoist (the edge at x = 0) held by the pole, its top at the
        // pole's top: pole · offset · rest.
        ClothAttachments::new([
            Attachment::new(pole, hoist).with_offset(Transform::from_xyz(
                0.16,
                POLE / 2.0 - 0.05,
                0.0,
            )),
        ]),
        Transform::from_xyz(0.16, POLE - 0.05, 0.0),
        Pickable::IGNORE,
    ));
    options.method.insert(&mut flag);
    // Avian boxes: one downwind behind the flag (seen from the camera) that
    // it beats against, two on the ground.
    let crate_material = materials.add(StandardMaterial {
        base_color: Color::srgb(0.55, 0.38, 0.22),
        perceptual_roughness: 0.9,
        ..default()
    });
    for (size, at) in [
        (Vec3::new(2.0, 6.5, 2.0), Vec3::new(7.0, 3.25, -3.2)),
        (Vec3::splat(1.5), Vec3::new(3.0, 0.75, -3.0)),
        (Vec3::new(3.0, 1.0, 2.0), Vec3::new(-4.0, 0.5, 2.0)),
    ] {
        commands.spawn((
            Mesh3d(meshes.add(Cuboid::from_size(size))),
            MeshMaterial3d(crate_material.clone()),
            Transform::from_translation(at),
            Collider::cuboid(size.x, size.y, size.z),
            Pickable::IGNORE,
        ));
    }
    // The capsule to drag through the flag: upwind of the pole, in view, so
    // its path through the flag is too.
    commands.spawn((
        Mesh3d(meshes.add(Capsule3d::new(0.6, 2.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.85, 0.25, 0.25),
            perceptual_roughness: 0.4,
            ..default()
        })),
        Transform::from_xyz(-2.5, 7.5, 0.0),
        Collider::capsule(0.6, 2.0),
        Draggable,
    ));
    common::light(&mut commands, 30.0);
    // The ground: an avian half-space with friction, drawn as a plane.
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(60.0, 60.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.30, 0.42, 0.30),
            perceptual_roughness: 0.95,
            ..default()
        })),
        Transform::default(),
        Collider::half_space(Vec3::Y),
        Friction::new(0.6),
        Ground,
        Pickable::IGNORE,
    ));
    common::orbit_camera(&mut commands, Vec3::new(3.5, 6.0, 0.0), 22.0);
    Ok(())
}

/// The wind and the ground's friction, live.
fn wind_panel(
    mut contexts: EguiContexts,
    mut controls: ResMut<WindControls>,
    mut wind: ResMut<Wind>,
    mut ground: Query<&mut Friction, With<Ground>>,
) -> Result {
    let ctx = contexts.ctx_mut()?;
    egui::Window::new("Wind")
        .anchor(egui::Align2::LEFT_TOP, [8.0, 8.0])
        .resizable(false)
        .show(ctx, |ui| {
            let mut changed = false;
            changed |= ui
                .add(egui::Slider::new(&mut controls.speed, 0.0..=30.0).text("speed (m/s)"))
                .changed();
            changed |= ui
                .add(
                    egui::Slider::new(&mut controls.heading_degrees, -180.0..=180.0)
                        .text("heading (°)"),
                )
                .changed();
            changed |= ui
                .add(egui::Slider::new(&mut controls.turbulence, 0.0..=1.0).text("gusts"))
                .changed();
            if changed {
                *wind = controls.wind();
            }
            ui.separator();
            for mut friction in &mut ground {
                let mut mu = friction.dynamic_coefficient;
                if ui
                    .add(egui::Slider::new(&mut mu, 0.0..=1.5).text("ground friction μ"))
                    .changed()
                {
                    *friction = Friction::new(mu);
                }
            }
        });
    Ok(())
}
