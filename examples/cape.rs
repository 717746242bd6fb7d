//! Character cloth: a character made in code runs a circle, turns sharply
//! and jumps, wearing a cape and a skirt skinned to its joints, in a
//! breeze.
//!
//! ```text
//! cargo run --example cape -- [--method M] [--cols 20] [--screenshot out.png --frames 120]
//! ```
//!
//! The garments are meshes with joint indices and weights bound to the
//! skeleton by a `SkinnedMesh`, as a glTF character's are
//! (`Skinning::from_mesh`); `ClothSkin` pins the collar and the waistband
//! on the skin and holds the rest near it (tethers, max distance, backstop);
//! `ClothInertia` lets them feel half of the character's velocity and a
//! quarter of its acceleration, and moves them with it when it is
//! teleported. The body is capsules on the bones (`CapsuleCollider`).
//!
//! The "Character" panel switches each constraint on and off so the
//! difference shows, and teleports the character 100 m (key `t`); the
//! camera follows it. `--cols` sets the cape's columns (it has 8/5 as many
//! rows: 50 gives the perf page's 4,000-vertex cape). The garments run
//! `stiff` with its refinement near colliders capped at 4×
//! (`character::GARMENT_METHOD`; `--method stiff` runs the preset's 16×).

// Shared with `headless --scene cape`, whose run without a window this
// example does not use.
#[path = "character/mod.rs"]
#[allow(dead_code)]
mod character;
#[path = "cli/mod.rs"]
mod cli;
#[path = "common/mod.rs"]
mod common;

use std::process::ExitCode;

use bevy::picking::Pickable;
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use bevy_cloth::render::cloth_mesh;
use bevy_egui::{EguiContexts, EguiPrimaryContextPass, egui};
use bevy_panorbit_camera::PanOrbitCamera;
use character::{BodyPart, BodyPenetrations, CapeScenePlugin, CapeSettings, Garment, Rig, Running};
use cli::{CliError, Long, Parser, Short, value};
use common::{ScreenshotArgs, ScreenshotMode};

const USAGE: &str = "usage: cape [--method NAME] [--cols N] [--screenshot FILE.png --frames N]";

fn parse(mut parser: Parser) -> Result<(CapeSettings, Option<ScreenshotMode>), CliError> {
    let mut screenshot = ScreenshotArgs::default();
    let mut settings = CapeSettings::default();
    while let Some(arg) = parser.next()? {
        match arg {
            Long("screenshot") => screenshot.set_path(&mut parser)?,
            Long("frames") => screenshot.set_frames(&mut parser)?,
            Long("method") => settings.method = value(&mut parser, "--method")?,
            Long("cols") => settings.cape_cols = value(&mut parser, "--cols")?,
            Long("help") | Short('h') => return Err(CliError::Help),
            _ => return Err(arg.unexpected().into()),
        }
    }
    if !(2..=200).contains(&settings.cape_cols) {
        return Err("--cols must be between 2 and 200".into());
    }
    Ok((settings, screenshot.finish()))
}

fn main() -> ExitCode {
    let (settings, screenshot) = match cli::parse_args(USAGE, parse) {
        Ok(parsed) => parsed,
        Err(code) => return code,
    };
    let mut app = common::windowed_app("bevy_cloth — cape", character::DT, screenshot);
    app.insert_resource(settings)
        .insert_resource(Wind::new(Vec3::new(2.0, 0.0, 1.0)).with_turbulence(0.3))
        .add_plugins(CapeScenePlugin)
        .add_systems(Startup, setup)
        .add_systems(Update, (dress, follow_character, teleport_key))
        .add_systems(EguiPrimaryContextPass, character_panel);
    common::run(app)
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    common::light(&mut commands, 20.0);
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(400.0, 60.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.32, 0.42, 0.3),
            perceptual_roughness: 0.95,
            ..default()
        })),
        Transform::from_xyz(50.0, 0.0, 0.0),
        Pickable::IGNORE,
    ));
    common::orbit_camera(&mut commands, Vec3::new(0.0, 1.0, 0.0), 3.2);
}

/// Gives the body's capsules and the garments their meshes once spawned,
/// and the joints the visibility their drawn children inherit.
fn dress(
    mut commands: Commands,
    rig: Option<Res<Rig>>,
    parts: Query<(Entity, &CapsuleCollider), Added<BodyPart>>,
    garments: Query<(Entity, &Cloth, &Garment), Added<Garment>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    if let Some(rig) = rig.filter(|r| r.is_added()) {
        for joint in rig.joints() {
            commands.entity(joint).insert(Visibility::default());
        }
    }
    for (entity, capsule) in &parts {
        commands.entity(entity).insert((
            Mesh3d(meshes.add(Capsule3d::new(capsule.radius, 2.0 * capsule.half_length))),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.85, 0.7, 0.55),
                perceptual_roughness: 0.6,
                ..default()
            })),
            Pickable::IGNORE,
        ));
    }
    for (entity, cloth, garment) in &garments {
        let (a, b) = if garment.name == "cape" {
            (Color::srgb(0.6, 0.1, 0.12), Color::srgb(0.85, 0.7, 0.2))
        } else {
            (Color::srgb(0.15, 0.25, 0.55), Color::srgb(0.9, 0.9, 0.92))
        };
        commands.entity(entity).insert((
            Mesh3d(meshes.add(cloth_mesh(cloth.model()))),
            MeshMaterial3d(common::checker_material(
                &mut materials,
                &mut images,
                6,
                a,
                b,
            )),
            Pickable::IGNORE,
        ));
    }
}

/// Keeps the camera's focus on the character.
fn follow_character(running: Res<Running>, mut cameras: Query<&mut PanOrbitCamera>) {
    let focus = running.root_position() + Vec3::Y;
    for mut camera in &mut cameras {
        if camera.target_focus.distance(focus) > 1e-3 {
            camera.target_focus = focus;
            camera.force_update = true;
        }
    }
}

fn teleport_key(keys: Res<ButtonInput<KeyCode>>, mut running: ResMut<Running>) {
    if keys.just_pressed(KeyCode::KeyT) {
        running.teleport = true;
    }
}

/// The constraints' toggles, the teleport, and what the scene counts.
fn character_panel(
    mut contexts: EguiContexts,
    mut settings: ResMut<CapeSettings>,
    mut running: ResMut<Running>,
    count: Res<BodyPenetrations>,
    rig: Option<Res<Rig>>,
    garments: Query<(&Garment, &ClothStats)>,
) -> Result {
    let ctx = contexts.ctx_mut()?;
    egui::Window::new("Character")
        .anchor(egui::Align2::LEFT_TOP, [8.0, 8.0])
        .resizable(false)
        .show(ctx, |ui| {
            let mut s = *settings;
            ui.checkbox(&mut s.tethers, "tethers (at most 1 % from the pins)");
            ui.checkbox(&mut s.max_distance, "max distance from the skin");
            ui.checkbox(&mut s.backstop, "the cape's backstop behind the back");
            ui.checkbox(
                &mut s.inertia,
                "inertia: ½ of the velocity, ¼ of the acceleration",
            );
            ui.checkbox(
                &mut s.drive,
                "anim drive: ½ of the way to the skin per second",
            );
            if s.tethers != settings.tethers
                || s.max_distance != settings.max_distance
                || s.backstop != settings.backstop
                || s.inertia != settings.inertia
                || s.drive != settings.drive
            {
                *settings = s;
            }
            if ui.button("teleport 100 m (t)").clicked() && rig.is_some() {
                running.teleport = true;
            }
            ui.separator();
            for (garment, stats) in &garments {
                ui.label(format!(
                    "{}: {} · stretch {:.1} % · {:?}",
                    garment.name,
                    stats.method,
                    100.0 * stats.max_stretch,
                    stats.status
                ));
            }
            ui.label(format!(
                "vertices inside the body so far: {} (deepest {:.1} mm)",
                count.count,
                1e3 * count.deepest
            ));
            ui.label(format!("teleports: {}", running.teleports));
        });
    Ok(())
}
