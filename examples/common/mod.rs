//! Shared by the windowed examples: the screenshot options, the scene's
//! light, ground and camera, and the screenshot mode.

use std::path::PathBuf;
use std::time::Duration;

use std::process::ExitCode;

use bevy::asset::RenderAssetUsages;
use bevy::picking::mesh_picking::MeshPickingPlugin;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};
use bevy::render::view::screenshot::{Screenshot, save_to_disk};
use bevy::window::WindowResolution;
use bevy_cloth::drag::{DragPlugin, Dragging};
use bevy_cloth::prelude::*;
use bevy_cloth::render::ClothRenderPlugin;
use bevy_cloth::ui::ClothInspectorPlugin;
use bevy_panorbit_camera::{PanOrbitCamera, PanOrbitCameraPlugin};

use crate::cli::{CliError, Parser};

/// Screenshot mode: render `frames` frames, save a PNG, exit.
#[derive(Resource, Debug, Clone)]
pub struct ScreenshotMode {
    pub path: PathBuf,
    pub frames: u32,
}

/// `--screenshot FILE --frames N`, read among an example's other options
/// (its parser matches the two names and calls the setters).
#[derive(Debug, Default)]
pub struct ScreenshotArgs {
    path: Option<PathBuf>,
    frames: Option<u32>,
}

impl ScreenshotArgs {
    /// `--screenshot FILE`: the value read from `parser`.
    pub fn set_path(&mut self, parser: &mut Parser) -> Result<(), CliError> {
        self.path = Some(parser.value()?.into());
        Ok(())
    }

    /// `--frames N`: the value read from `parser`.
    pub fn set_frames(&mut self, parser: &mut Parser) -> Result<(), CliError> {
        self.frames = Some(crate::cli::value(parser, "--frames")?);
        Ok(())
    }

    /// The screenshot mode, if `--screenshot` was given (120 frames unless
    /// `--frames` says otherwise).
    pub fn finish(self) -> Option<ScreenshotMode> {
        let frames = self.frames.unwrap_or(120);
        self.path.map(|path| ScreenshotMode { path, frames })
    }
}

/// A windowed app with the cloth, rendering, picking, drag, panel and orbit
/// camera plugins, stepping every `dt` seconds, in screenshot mode if given.
pub fn windowed_app(title: &str, dt: f64, screenshot: Option<ScreenshotMode>) -> App {
    let mut app = App::new();
    app.add_plugins(DefaultPlugins.set(WindowPlugin {
        primary_window: Some(Window {
            title: title.into(),
            resolution: WindowResolution::new(1280, 720),
            ..default()
        }),
        ..default()
    }))
    .add_plugins((
        MeshPickingPlugin,
        PanOrbitCameraPlugin,
        ClothPlugins::default(),
        ClothRenderPlugin,
        DragPlugin,
        ClothInspectorPlugin::default(),
    ))
    .add_plugins(bevy::diagnostic::FrameTimeDiagnosticsPlugin::default())
    .insert_resource(Time::<Fixed>::from_seconds(dt))
    .add_systems(Update, (hold_camera_while_dragging, spare_a_cpu_renderer));
    if let Some(mode) = screenshot {
        app.insert_resource(mode)
            .add_systems(Update, screenshot_and_exit);
    }
    app
}

/// Runs the app and turns its exit into the process's.
pub fn run(mut app: App) -> ExitCode {
    match app.run() {
        AppExit::Success => ExitCode::SUCCESS,
        AppExit::Error(code) => ExitCode::from(code.get()),
    }
}

/// A sun with shadows over a scene of about `size` units, and soft ambient
/// light.
pub fn light(commands: &mut Commands, size: f32) {
    commands.spawn((
        DirectionalLight {
            illuminance: 8000.0,
            shadow_maps_enabled: true,
            ..default()
        },
        Transform::from_xyz(size * 0.4, size, size * 0.6).looking_at(Vec3::ZERO, Vec3::Y),
    ));
    commands.insert_resource(GlobalAmbientLight {
        brightness: 600.0,
        ..default()
    });
}

/// A sun with shadows, soft ambient light, and a ground plane at `ground_y`
/// that cloths collide with (friction 0.5).
// The flag example has an avian ground instead.
#[allow(dead_code)]
pub fn light_and_ground(
    commands: &mut Commands,
    meshes: &mut Assets<Mesh>,
    materials: &mut Assets<StandardMaterial>,
    ground_y: f32,
    size: f32,
) {
    light(commands, size);
    commands.spawn((
        Mesh3d(meshes.add(Plane3d::default().mesh().size(size, size))),
        MeshMaterial3d(materials.add(StandardMaterial {
            base_color: Color::srgb(0.32, 0.36, 0.40),
            perceptual_roughness: 0.95,
            ..default()
        })),
        Transform::from_xyz(0.0, ground_y, 0.0),
        // The cloth lands on the floor instead of falling through it.
        PlaneCollider::new(0.5),
        bevy::picking::Pickable::IGNORE,
    ));
}

/// An orbit camera (drag: orbit, right-drag: pan, wheel: zoom in even
/// steps of about 6 % per notch, without smoothing, which at a software
/// renderer's few frames per second made each notch a large, uneven jump).
pub fn orbit_camera(commands: &mut Commands, focus: Vec3, radius: f32) {
    commands.spawn((
        Camera3d::default(),
        Transform::from_translation(focus + Vec3::new(radius * 0.6, radius * 0.35, radius * 0.75))
            .looking_at(focus, Vec3::Y),
        PanOrbitCamera {
            focus,
            radius: Some(radius),
            zoom_sensitivity: 0.3,
            zoom_smoothness: 0.0,
            ..default()
        },
    ));
}

/// On a CPU renderer (llvmpipe, as in CI and on machines without a GPU),
/// turns off what costs most and shows least: the sun's shadow maps and
/// MSAA. Once, as soon as the adapter is known.
pub fn spare_a_cpu_renderer(
    adapter: Option<Res<bevy::render::renderer::RenderAdapterInfo>>,
    mut done: Local<bool>,
    mut lights: Query<&mut DirectionalLight>,
    cameras: Query<Entity, With<Camera3d>>,
    mut commands: Commands,
) {
    let Some(adapter) = adapter else {
        return;
    };
    if *done || lights.is_empty() || cameras.is_empty() {
        return;
    }
    *done = true;
    if format!("{:?}", adapter.device_type) != "Cpu" {
        return;
    }
    info!(
        "CPU renderer '{}': shadows and MSAA off to keep the frame rate up",
        adapter.name
    );
    for mut light in &mut lights {
        light.shadow_maps_enabled = false;
    }
    for camera in &cameras {
        commands.entity(camera).insert(Msaa::Off);
    }
}

/// The camera does not orbit while an entity is dragged.
pub fn hold_camera_while_dragging(
    dragging: Res<Dragging>,
    mut cameras: Query<&mut PanOrbitCamera>,
) {
    for mut camera in &mut cameras {
        let enabled = dragging.entity.is_none();
        if camera.enabled != enabled {
            camera.enabled = enabled;
        }
    }
}

/// Frame counting, the screenshot and the exit of screenshot mode.
pub fn screenshot_and_exit(
    mode: Res<ScreenshotMode>,
    time: Res<Time<Real>>,
    mut frame: Local<u32>,
    mut started: Local<Option<Duration>>,
    mut commands: Commands,
    mut exit: MessageWriter<AppExit>,
) {
    *frame += 1;
    if *frame == 10 {
        *started = Some(time.elapsed());
    }
    if *frame == mode.frames {
        let _ = std::fs::remove_file(&mode.path);
        if let Some(dir) = mode.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            let _ = std::fs::create_dir_all(dir);
        }
        commands
            .spawn(Screenshot::primary_window())
            .observe(save_to_disk(mode.path.clone()));
        if let Some(start) = *started {
            let frames = mode.frames - 10;
            let per_frame = (time.elapsed() - start).as_secs_f64() * 1000.0 / f64::from(frames);
            println!("frames={} mean_frame_ms={per_frame:.1}", mode.frames);
        }
    }
    if *frame > mode.frames {
        if mode.path.exists() && std::fs::metadata(&mode.path).is_ok_and(|m| m.len() > 0) {
            // Give the writer a frame to finish the file.
            if *frame > mode.frames + 5 {
                println!("screenshot saved to {}", mode.path.display());
                exit.write(AppExit::Success);
            }
        } else if *frame > mode.frames + 600 {
            eprintln!("the screenshot was never written");
            exit.write(AppExit::error());
        }
    }
}

/// A double-sided cloth material with a checkerboard texture
/// ([`checker_image`]).
pub fn checker_material(
    materials: &mut Assets<StandardMaterial>,
    images: &mut Assets<Image>,
    cells: u32,
    a: Color,
    b: Color,
) -> Handle<StandardMaterial> {
    materials.add(StandardMaterial {
        base_color_texture: Some(images.add(checker_image(cells, a, b))),
        double_sided: true,
        cull_mode: None,
        perceptual_roughness: 0.8,
        ..default()
    })
}

/// A checkerboard texture (`cells×cells`, two colours) that makes folds
/// readable on a cloth.
pub fn checker_image(cells: u32, a: Color, b: Color) -> Image {
    let size = cells * 16;
    let (a, b) = (a.to_srgba().to_u8_array(), b.to_srgba().to_u8_array());
    let mut data = Vec::with_capacity((size * size * 4) as usize);
    for y in 0..size {
        for x in 0..size {
            let odd = ((x / 16) + (y / 16)) % 2 == 1;
            data.extend_from_slice(if odd { &a } else { &b });
        }
    }
    Image::new(
        Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    )
}
