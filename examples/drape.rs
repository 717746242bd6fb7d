//! Self-collision: a square of cotton dropped onto a ball drapes over it
//! and folds onto itself, and a second sheet, turned, lands on it.
//!
//! ```text
//! cargo run --example drape -- [--method M] [--n 32] [--screenshot out.png --frames 120]
//! ```
//!
//! Both sheets have a `SelfCollision` (0.9 of their edge thick): each keeps
//! off itself and off the other. The "Drape" panel switches it off and on,
//! drops the sheets again (key `r` resets them in place, as in the lab),
//! throws a ball through the drape at 30 m/s (key `t`), and shows what the
//! scene counts after every step: mesh edges through a triangle of either
//! sheet (the exact check). The ball can be dragged with the mouse. When
//! the app exits (the screenshot mode's last frame, or the window closed)
//! it prints that count in the words of `headless --scene drape`
//! (`steps= max_stretch= penetrations= worst_step_penetrations=
//! ball_touches= inside_ball=`), so a windowed run can be set beside a
//! headless one of as many steps.

// Shared with `headless --scene drape`, whose run without a window this
// example does not use.
#[path = "cli/mod.rs"]
mod cli;
#[path = "common/mod.rs"]
mod common;
#[path = "drape/mod.rs"]
#[allow(dead_code)]
mod drape;

use std::process::ExitCode;

use bevy::picking::Pickable;
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use bevy_cloth::render::cloth_mesh;
use bevy_egui::{EguiContexts, EguiPrimaryContextPass, egui};
use cli::{CliError, Long, Parser, Short, value};
use common::{ScreenshotArgs, ScreenshotMode};
use drape::{DrapeClock, DrapeScenePlugin, DrapeSettings, Penetrations, Sheet};

const USAGE: &str = "usage: drape [--method NAME] [--n N] [--screenshot FILE.png --frames N]";

fn parse(mut parser: Parser) -> Result<(DrapeSettings, Option<ScreenshotMode>), CliError> {
    let mut screenshot = ScreenshotArgs::default();
    let mut settings = DrapeSettings::default();
    while let Some(arg) = parser.next()? {
        match arg {
            Long("screenshot") => screenshot.set_path(&mut parser)?,
            Long("frames") => screenshot.set_frames(&mut parser)?,
            Long("method") => settings.method = value(&mut parser, "--method")?,
            Long("n") => settings.n = value(&mut parser, "--n")?,
            Long("help") | Short('h') => return Err(CliError::Help),
            _ => return Err(arg.unexpected().into()),
        }
    }
    if !(2..=256).contains(&settings.n) {
        return Err("--n must be between 2 and 256".into());
    }
    Ok((settings, screenshot.finish()))
}

fn main() -> ExitCode {
    let (settings, screenshot) = match cli::parse_args(USAGE, parse) {
        Ok(parsed) => parsed,
        Err(code) => return code,
    };
    let mut app = common::windowed_app("bevy_cloth — drape", drape::DT, screenshot);
    app.insert_resource(settings)
        .add_plugins(DrapeScenePlugin)
        .add_systems(Startup, setup)
        .add_systems(Update, (dress, throw_key))
        .add_systems(EguiPrimaryContextPass, drape_panel)
        .add_systems(Last, print_count_on_exit);
    common::run(app)
}

/// When the app exits (the screenshot mode's last frame, or the window
/// closed), prints what the scene counted, in the words of `headless
/// --scene drape`, so a windowed run can be set beside a headless one of as
/// many steps.
fn print_count_on_exit(mut exits: MessageReader<AppExit>, counted: Res<Penetrations>) {
    if exits.read().next().is_some() {
        println!(
            "steps={} max_stretch={:.4} {}",
            counted.steps,
            counted.max_stretch,
            counted.summary()
        );
    }
}

fn setup(
    mut commands: Commands,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
) {
    common::light(&mut commands, 6.0);
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(8.0, 8.0))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.32, 0.36, 0.40),
            perceptual_roughness: 0.95,
            ..default()
        })),
        Pickable::IGNORE,
    ));
    common::orbit_camera(&mut commands, Vec3::new(0.0, 0.35, 0.0), 2.2);
}

/// Gives the ball and each new sheet their meshes: the first sheet red, the
/// second blue.
fn dress(
    mut commands: Commands,
    balls: Query<(Entity, &SphereCollider), Added<SphereCollider>>,
    sheets: Query<(Entity, &Cloth, &Sheet), Added<Sheet>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut images: ResMut<Assets<Image>>,
) {
    for (entity, ball) in &balls {
        // A hair smaller than the collider, so the cloth resting on it does
        // not flicker into it.
        commands.entity(entity).insert((
            Mesh3d(meshes.add(Sphere::new(ball.radius * 0.97).mesh().ico(4).unwrap())),
            MeshMaterial3d(materials.add(StandardMaterial {
                base_color: Color::srgb(0.85, 0.82, 0.75),
                perceptual_roughness: 0.5,
                ..default()
            })),
        ));
    }
    for (entity, cloth, sheet) in &sheets {
        let (a, b) = if sheet.0 == 0 {
            (Color::srgb(0.75, 0.12, 0.12), Color::srgb(0.95, 0.85, 0.8))
        } else {
            (Color::srgb(0.12, 0.25, 0.7), Color::srgb(0.85, 0.9, 0.95))
        };
        commands.entity(entity).insert((
            Mesh3d(meshes.add(cloth_mesh(cloth.model()))),
            MeshMaterial3d(common::checker_material(
                &mut materials,
                &mut images,
                8,
                a,
                b,
            )),
            Pickable::IGNORE,
        ));
    }
}

/// Key `t` throws a ball through the drape.
fn throw_key(keys: Res<ButtonInput<KeyCode>>, mut clock: ResMut<DrapeClock>) {
    if keys.just_pressed(KeyCode::KeyT) {
        clock.throw = true;
    }
}

/// Self-collision on and off, the sheets dropped again, and what the scene
/// counts.
fn drape_panel(
    mut contexts: EguiContexts,
    mut settings: ResMut<DrapeSettings>,
    mut clock: ResMut<DrapeClock>,
    counted: Res<Penetrations>,
    sheets: Query<(&Sheet, &ClothStats)>,
) -> Result {
    let ctx = contexts.ctx_mut()?;
    egui::Window::new("Drape")
        .anchor(egui::Align2::LEFT_TOP, [8.0, 8.0])
        .resizable(false)
        .show(ctx, |ui| {
            let mut on = settings.self_collision;
            if ui
                .checkbox(&mut on, "self-collision (each sheet and the two)")
                .changed()
            {
                settings.self_collision = on;
            }
            ui.horizontal(|ui| {
                if ui.button("drop the sheets again").clicked() {
                    clock.restart = true;
                }
                if ui.button("throw a ball (t)").clicked() {
                    clock.throw = true;
                }
            });
            ui.separator();
            let mut list: Vec<_> = sheets.iter().collect();
            list.sort_by_key(|(s, _)| s.0);
            for (sheet, stats) in list {
                ui.label(format!(
                    "sheet {}: {} · stretch {:.1} % · contacts {} · self pairs {}",
                    sheet.0 + 1,
                    stats.method,
                    100.0 * stats.max_stretch,
                    stats.contacts,
                    stats.self_contacts
                ));
            }
            ui.label(format!(
                "edges through a sheet: {} over {} steps (most in one step: {})",
                counted.total, counted.steps, counted.worst
            ));
        });
    Ok(())
}
