//! An inspector panel (cargo feature `egui`): switch each cloth's method and
//! tune it live, watch its statistics, pause, single-step and reset.
//!
//! Add [`ClothInspectorPlugin`] to any app with cloths; it adds
//! `bevy_egui`'s `EguiPlugin` if missing. Keyboard shortcuts (on by
//! default): space pauses and resumes, `h` runs one step (pausing first),
//! `r` resets every cloth. A cloth that carries a [`ClothResolution`] gets a
//! resolution slider that rebuilds it.

use std::collections::VecDeque;

use bevy::diagnostic::{DiagnosticsStore, FrameTimeDiagnosticsPlugin};
use bevy::prelude::*;
use bevy_egui::{EguiContexts, EguiPlugin, EguiPrimaryContextPass, egui};

use crate::collision::SelfCollision;
use crate::ecs::{
    Cloth, ClothMethods, ClothParams, ClothSimulation, ClothStats, ClothStatus, SphereCollider,
    SphereResponse,
};
use crate::methods::{AnyMethod, AnyMethodData, PRESETS};
use crate::model::{ClothBuildError, ClothMaterial, ClothModel};

mod settings;
use settings::settings_ui;

/// The inspector panel and its keyboard shortcuts.
#[derive(Debug, Clone, Copy)]
pub struct ClothInspectorPlugin {
    /// Space / `h` / `r` shortcuts.
    pub keyboard: bool,
}

impl Default for ClothInspectorPlugin {
    fn default() -> Self {
        Self { keyboard: true }
    }
}

impl Plugin for ClothInspectorPlugin {
    fn build(&self, app: &mut App) {
        if !app.is_plugin_added::<EguiPlugin>() {
            app.add_plugins(EguiPlugin::default());
        }
        app.init_resource::<Inspector>()
            .init_resource::<ClothSimulation>()
            .add_systems(Update, (record_defaults, record_history))
            .add_systems(EguiPrimaryContextPass, inspector_panel);
        if self.keyboard {
            app.add_systems(Update, keyboard_shortcuts);
        }
    }
}

/// How to rebuild a cloth at another resolution, for the panel's slider.
#[derive(Component, Clone, Copy, Debug)]
pub struct ClothResolution {
    /// Current resolution (vertices along a side).
    pub n: u32,
    /// Slider range.
    pub range: (u32, u32),
    /// Builds the model at a resolution.
    pub build: fn(u32) -> Result<ClothModel, ClothBuildError>,
}

/// Named settings of one cloth that the panel offers as buttons: each sets
/// the cloth's parameters and method at once (the lab's faithful scene and
/// its stiff fabric, say).
#[derive(Component, Clone, Debug, Default)]
pub struct ClothScenes(pub Vec<ClothScene>);

/// One of [`ClothScenes`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClothScene {
    /// The button's text.
    pub label: &'static str,
    /// What the button says it does (shown on hover).
    pub about: &'static str,
    /// The cloth's parameters in this scene.
    pub params: ClothParams,
    /// Its method.
    pub method: AnyMethod,
}

/// Panel state: the selected cloth and its step-time history.
#[derive(Resource, Debug, Default)]
pub struct Inspector {
    /// The cloth shown.
    pub selected: Option<Entity>,
    /// Recent step times of the selected cloth, in microseconds.
    pub history: VecDeque<f32>,
    last_step: u64,
    /// The fixed time step when the panel first ran, for "Reset all".
    initial_step: Option<std::time::Duration>,
}

const HISTORY: usize = 240;

fn record_history(mut inspector: ResMut<Inspector>, stats: Query<(Entity, &ClothStats)>) {
    if inspector.selected.is_none_or(|e| !stats.contains(e)) {
        inspector.selected = stats.iter().map(|(e, _)| e).min();
        inspector.history.clear();
    }
    let Some((_, s)) = inspector.selected.and_then(|e| stats.get(e).ok()) else {
        return;
    };
    if s.steps != inspector.last_step {
        inspector.last_step = s.steps;
        inspector.history.push_back(s.step_time.as_secs_f32() * 1e6);
        if inspector.history.len() > HISTORY {
            inspector.history.pop_front();
        }
    }
}

/// The values a cloth was spawned with, recorded by the panel the first time
/// it sees the cloth, for "reset all".
#[derive(Component, Clone, Copy, Debug, PartialEq)]
pub struct ClothDefaults {
    /// The cloth's parameters at spawn.
    pub params: ClothParams,
    /// Its method at spawn.
    pub method: Option<AnyMethod>,
}

/// Cloths the panel has not recorded yet.
type Unrecorded = (With<Cloth>, Without<ClothDefaults>);

fn record_defaults(
    cloths: Query<(Entity, &ClothParams, AnyMethodData), Unrecorded>,
    mut commands: Commands,
) {
    for (entity, params, method) in &cloths {
        commands.entity(entity).insert(ClothDefaults {
            params: *params,
            method: AnyMethod::from_item(method),
        });
    }
}

/// Puts a cloth back at rest where its entity is, now, with fresh stats.
fn reset_cloth(cloth: &mut Cloth, stats: &mut ClothStats, transform: Option<&GlobalTransform>) {
    match transform {
        Some(t) => cloth.reset_at(t),
        None => cloth.reset(),
    }
    stats.clear();
}

type ResetItem = (
    &'static mut Cloth,
    &'static mut ClothStats,
    Option<&'static GlobalTransform>,
);

fn keyboard_shortcuts(
    keys: Res<ButtonInput<KeyCode>>,
    mut contexts: EguiContexts,
    mut simulation: ResMut<ClothSimulation>,
    mut cloths: Query<ResetItem>,
) {
    // Keys typed into a text field are the field's.
    if contexts.ctx_mut().is_ok_and(|ctx| ctx.text_edit_focused()) {
        return;
    }
    if keys.just_pressed(KeyCode::Space) {
        simulation.paused = !simulation.paused;
    }
    if keys.just_pressed(KeyCode::KeyH) {
        simulation.paused = true;
        simulation.step_once();
    }
    if keys.just_pressed(KeyCode::KeyR) {
        for (mut cloth, mut stats, transform) in &mut cloths {
            reset_cloth(&mut cloth, &mut stats, transform);
        }
    }
}

type ClothItem = (
    Entity,
    &'static mut Cloth,
    &'static mut ClothParams,
    &'static mut ClothStats,
    Option<&'static mut ClothResolution>,
    Option<&'static Mesh3d>,
    Option<&'static GlobalTransform>,
    Option<&'static ClothDefaults>,
    Option<&'static ClothScenes>,
);

#[allow(clippy::too_many_arguments)]
fn inspector_panel(
    mut contexts: EguiContexts,
    mut inspector: ResMut<Inspector>,
    mut simulation: ResMut<ClothSimulation>,
    mut fixed: ResMut<Time<Fixed>>,
    methods: Res<ClothMethods>,
    mut cloths: Query<ClothItem>,
    method_of: Query<AnyMethodData>,
    mut colliders: Query<(Entity, &mut SphereCollider)>,
    mut materials: Query<&mut ClothMaterial>,
    mut self_collisions: Query<&mut SelfCollision>,
    mut meshes: ResMut<Assets<Mesh>>,
    diagnostics: Option<Res<DiagnosticsStore>>,
    mut commands: Commands,
) -> Result {
    let ctx = contexts.ctx_mut()?;
    let initial_step = *inspector.initial_step.get_or_insert(fixed.timestep());
    egui::Window::new("bevy_cloth")
        .anchor(egui::Align2::RIGHT_TOP, [-8.0, 8.0])
        .default_width(300.0)
        .default_height(ctx.content_rect().height() - 24.0)
        .resizable(true)
        .show(ctx, |ui| {
            egui::ScrollArea::vertical()
                .auto_shrink([false, false])
                .show(ui, |ui| {
                    ui.heading("Cloth");
                    // Simulation controls.
                    ui.horizontal(|ui| {
                        let label = if simulation.paused {
                            "▶ Resume"
                        } else {
                            "⏸ Pause"
                        };
                        if ui.button(label).clicked() {
                            simulation.paused = !simulation.paused;
                        }
                        if ui.button("Step").clicked() {
                            simulation.paused = true;
                            simulation.step_once();
                        }
                        if ui
                            .button("Reset cloth")
                            .on_hover_text("every cloth back at rest (r)")
                            .clicked()
                        {
                            for (_, mut cloth, _, mut stats, _, _, transform, _, _) in &mut cloths {
                                reset_cloth(&mut cloth, &mut stats, transform);
                            }
                        }
                        if ui
                            .button("Reset all")
                            .on_hover_text(
                                "and the parameters, methods and time step the scene started with",
                            )
                            .clicked()
                        {
                            fixed.set_timestep(initial_step);
                            for (
                                entity,
                                mut cloth,
                                mut params,
                                mut stats,
                                resolution,
                                _,
                                transform,
                                defaults,
                                _,
                            ) in &mut cloths
                            {
                                reset_cloth(&mut cloth, &mut stats, transform);
                                if materials.contains(entity) {
                                    drop_material(
                                        &mut commands,
                                        entity,
                                        &mut cloth,
                                        resolution.as_deref(),
                                    );
                                }
                                if let Some(defaults) = defaults {
                                    *params = defaults.params;
                                    if let Some(method) = defaults.method {
                                        method.insert(&mut commands.entity(entity));
                                    }
                                }
                            }
                        }
                    });
                    ui.label("space: pause · h: step · r: reset cloth");
                    let mut dt = fixed.timestep().as_secs_f64() * 1000.0;
                    if ui
                        .add(
                            egui::Slider::new(&mut dt, 0.5..=50.0)
                                .text("time step (ms)")
                                .logarithmic(true),
                        )
                        .changed()
                    {
                        fixed.set_timestep_seconds(dt / 1000.0);
                    }
                    // Cloth selection.
                    let entities: Vec<Entity> = cloths.iter().map(|c| c.0).collect();
                    if entities.len() > 1 {
                        let selected = inspector.selected;
                        egui::ComboBox::from_label("cloth")
                            .selected_text(selected.map_or("-".into(), |e| format!("{e}")))
                            .show_ui(ui, |ui| {
                                for e in &entities {
                                    ui.selectable_value(
                                        &mut inspector.selected,
                                        Some(*e),
                                        format!("{e}"),
                                    );
                                }
                            });
                    }
                    let Some(selected) = inspector.selected else {
                        ui.label("No cloth.");
                        return;
                    };
                    let Ok((
                        entity,
                        mut cloth,
                        mut params,
                        mut stats,
                        resolution,
                        mesh,
                        _,
                        defaults,
                        scenes,
                    )) = cloths.get_mut(selected)
                    else {
                        return;
                    };
                    ui.separator();
                    if let Some(scenes) = scenes {
                        ui.horizontal_wrapped(|ui| {
                            ui.label("scene:");
                            for scene in &scenes.0 {
                                if ui.button(scene.label).on_hover_text(scene.about).clicked() {
                                    if materials.contains(entity) {
                                        drop_material(
                                            &mut commands,
                                            entity,
                                            &mut cloth,
                                            resolution.as_deref(),
                                        );
                                    }
                                    *params = scene.params;
                                    scene.method.insert(&mut commands.entity(entity));
                                }
                            }
                        });
                    }
                    let current = method_of.get(entity).ok().and_then(AnyMethod::from_item);
                    method_ui(ui, &methods, &mut commands, entity, current);
                    ui.separator();
                    let defaults = defaults.map_or_else(ClothParams::default, |d| d.params);
                    let material = material_ui(
                        ui,
                        &mut commands,
                        entity,
                        materials.get_mut(entity).ok(),
                        &mut cloth,
                        resolution.as_deref(),
                    );
                    self_collision_ui(
                        ui,
                        &mut commands,
                        entity,
                        self_collisions.get_mut(entity).ok(),
                        cloth.model(),
                    );
                    // PBD restores rest lengths: it has no stiffness to tune;
                    // a material sets the springs' every step.
                    let stiffness = !matches!(current, Some(AnyMethod::Pbd(_))) && !material;
                    let kinds = cloth.model().topology().spring_counts();
                    params_ui(ui, &mut params, &defaults, stiffness, kinds);
                    if let Some(mut resolution) = resolution {
                        let mut n = resolution.n;
                        let (lo, hi) = resolution.range;
                        if ui
                            .add(egui::Slider::new(&mut n, lo..=hi).text("resolution"))
                            .drag_stopped()
                            || (n != resolution.n && !ui.ctx().egui_is_using_pointer())
                        {
                            match (resolution.build)(n) {
                                Ok(model) => {
                                    if let Some(mesh) = mesh {
                                        let _ = meshes
                                            .insert(&mesh.0, crate::render::cloth_mesh(&model));
                                    }
                                    *cloth = Cloth::new(model);
                                    stats.clear();
                                    resolution.n = n;
                                }
                                Err(e) => warn!("cannot rebuild the cloth at {n}: {e}"),
                            }
                        }
                    }
                    ui.separator();
                    stats_ui(ui, &stats, &inspector.history, diagnostics.as_deref());
                    ui.separator();
                    colliders_ui(ui, &mut colliders);
                });
        });
    release_focus(ctx);
    Ok(())
}

/// The cloth as a material (`ClothMaterial`: sheet stiffness in N/m,
/// areal density in kg/m²) or with the per-spring `k` and per-vertex masses
/// it was built with; returns whether it has a material now.
fn material_ui(
    ui: &mut egui::Ui,
    commands: &mut Commands,
    entity: Entity,
    material: Option<Mut<ClothMaterial>>,
    cloth: &mut Cloth,
    resolution: Option<&ClothResolution>,
) -> bool {
    let mut on = material.is_some();
    if ui
        .checkbox(&mut on, "as a material (N/m, kg/m²)")
        .on_hover_text(
            "cotton to start with: the sheet's stiffness and mass per m² set every spring's k \
             and every vertex's mass, the same at every resolution; off keeps the springs' k \
             the material gave (its reset restores the scene's) and rebuilds the cloth with its \
             own masses",
        )
        .changed()
    {
        if on {
            commands.entity(entity).insert(ClothMaterial::COTTON);
        } else {
            drop_material(commands, entity, cloth, resolution);
        }
        return on;
    }
    let Some(mut material) = material else {
        return false;
    };
    let m = material.bypass_change_detection();
    let before = *m;
    let d = ClothMaterial::COTTON;
    log_value(ui, &mut m.stretch, d.stretch, "sheet stretch (N/m)");
    log_value(ui, &mut m.density, d.density, "areal density (kg/m²)");
    if *m != before {
        material.set_changed();
    }
    true
}

/// Self-collision on or off, its thickness (up to just below the shortest
/// rest edge) and friction.
fn self_collision_ui(
    ui: &mut egui::Ui,
    commands: &mut Commands,
    entity: Entity,
    current: Option<Mut<SelfCollision>>,
    model: &ClothModel,
) {
    let mut on = current.is_some();
    let default = SelfCollision::for_model(model);
    if ui
        .checkbox(&mut on, "self-collision")
        .on_hover_text(
            "every pair of the cloth's vertices kept a thickness apart: inside stiff's \
             substeps, after the step for the other methods",
        )
        .changed()
    {
        if on {
            commands.entity(entity).insert(default);
        } else {
            commands.entity(entity).remove::<SelfCollision>();
        }
        return;
    }
    let Some(mut sc) = current else {
        return;
    };
    let edge = default.thickness / 0.9;
    if !edge.is_finite() {
        return;
    }
    let (mut thickness, mut friction) = (sc.thickness, sc.friction);
    // Shown to three decimals, not rounded to them: with `max_decimals` the
    // slider rounded the value itself (and said it changed), so the drape
    // scene's first sheet went from `for_model`'s 0.03484 m to 0.035 at the
    // panel's first frame, and the windowed scene parted from the headless
    // one. Written only when a slider says it moved.
    let moved = ui
        .add(
            egui::Slider::new(&mut thickness, 0.1 * edge..=0.99 * edge)
                .text("thickness (m)")
                .custom_formatter(|v, _| format!("{v:.3}")),
        )
        .on_hover_text(
            "below 0.71 of the shortest edge, vertex–triangle and edge–edge pairs keep the layers \
             apart, at two to three times the cost",
        )
        .changed();
    let moved = ui
        .add(egui::Slider::new(&mut friction, 0.0..=1.0).text("self friction"))
        .changed()
        || moved;
    if moved {
        sc.thickness = thickness;
        sc.friction = friction;
    }
}

/// Removes a cloth's material; a cloth the panel can rebuild (one with a
/// [`ClothResolution`]) is rebuilt with its own masses, which the material
/// had replaced.
fn drop_material(
    commands: &mut Commands,
    entity: Entity,
    cloth: &mut Cloth,
    resolution: Option<&ClothResolution>,
) {
    commands.entity(entity).remove::<ClothMaterial>();
    if let Some(resolution) = resolution {
        match (resolution.build)(resolution.n) {
            Ok(model) => *cloth = Cloth::new(model),
            Err(e) => warn!("cannot rebuild the cloth without its material: {e}"),
        }
    }
}

/// egui keeps keyboard focus on the last slider or button clicked, and while
/// it does, the orbit camera and the shortcuts ignore the scene. Focus stays
/// only while a text field is being typed into; otherwise it is released as
/// soon as the pointer is off the panel and not dragging a widget.
fn release_focus(ctx: &egui::Context) {
    if ctx.is_pointer_over_egui() || ctx.egui_is_using_pointer() || ctx.text_edit_focused() {
        return;
    }
    if let Some(id) = ctx.memory(|m| m.focused()) {
        ctx.memory_mut(|m| m.surrender_focus(id));
    }
}

fn method_ui(
    ui: &mut egui::Ui,
    methods: &ClothMethods,
    commands: &mut Commands,
    entity: Entity,
    current: Option<AnyMethod>,
) {
    let name = current.map(|m| m.name());
    let label = |name: &'static str| {
        PRESETS
            .iter()
            .find(|p| p.name() == name)
            .map_or(name, |p| p.label)
    };
    let mut chosen = name;
    egui::ComboBox::from_label("method")
        .selected_text(name.map_or("none", label))
        .show_ui(ui, |ui| {
            for p in PRESETS {
                ui.add_enabled_ui(methods.contains(p.method.type_id()), |ui| {
                    ui.selectable_value(&mut chosen, Some(p.name()), p.label);
                });
            }
        });
    if chosen != name
        && let Some(preset) = PRESETS.iter().find(|p| Some(p.name()) == chosen)
    {
        // A preset is a whole setting: its iterations, tolerance and
        // acceleration, whatever the previous method's were.
        preset.method.insert(&mut commands.entity(entity));
        return;
    }
    let Some(mut method) = current else {
        return;
    };
    settings_ui(ui, &mut method);
    if Some(method) != current {
        method.insert(&mut commands.entity(entity));
    }
}

/// The cloth's parameters; the stiffness only if the method reads it, and
/// of each spring kind only if the cloth has springs of that kind
/// (`kinds`: stretch, shear, bend counts).
fn params_ui(
    ui: &mut egui::Ui,
    params: &mut Mut<ClothParams>,
    defaults: &ClothParams,
    stiffness: bool,
    kinds: [usize; 3],
) {
    let p = params.bypass_change_detection();
    let before = *p;
    let d = defaults;
    if stiffness {
        let k = &mut p.stiffness;
        let values = [
            (&mut k.stretch, d.stiffness.stretch, "stretch k (N/m)"),
            (&mut k.shear, d.stiffness.shear, "shear k (N/m)"),
            (&mut k.bend, d.stiffness.bend, "bend k (N/m)"),
        ];
        for ((value, default, text), count) in values.into_iter().zip(kinds) {
            if count > 0 {
                log_value(ui, value, default, text);
            }
        }
    }
    // Damping as the cloth has it: per second (the default) or per step
    // (the lab's).
    match &mut p.damping_per_second {
        Some(rate) => {
            let default = d.damping_per_second.unwrap_or(*rate);
            linear_value(ui, rate, default, 0.0..=1.0, 0.001, "damping per second");
        }
        None => linear_value(
            ui,
            &mut p.damping,
            d.damping,
            0.0..=1.0,
            0.001,
            "damping per step",
        ),
    }
    linear_value(
        ui,
        &mut p.gravity.y,
        d.gravity.y,
        -100.0..=100.0,
        0.1,
        "gravity y",
    );
    linear_value(
        ui,
        &mut p.particle_radius,
        d.particle_radius,
        0.0..=1.0,
        0.001,
        "particle radius",
    );
    if *p != before {
        params.set_changed();
    }
}

/// A wide-range positive value (a stiffness): a drag value that moves about
/// a decade per 100 px and accepts typed values, ÷10 and ×10 buttons, and a
/// reset to `default`.
fn log_value(ui: &mut egui::Ui, value: &mut f32, default: f32, text: &str) {
    const RANGE: core::ops::RangeInclusive<f32> = 1e-3..=1e12;
    ui.horizontal(|ui| {
        // d(value)/dpx = value·ln(10)/100: a factor of 10 per 100 px.
        let speed = f64::from(value.abs().max(1e-3)) * core::f64::consts::LN_10 / 100.0;
        ui.add(
            egui::DragValue::new(value)
                .speed(speed)
                .range(RANGE)
                .custom_formatter(|v, _| format!("{v:.4e}")),
        );
        if ui.small_button("÷10").clicked() {
            *value = (*value / 10.0).clamp(*RANGE.start(), *RANGE.end());
        }
        if ui.small_button("×10").clicked() {
            *value = (*value * 10.0).clamp(*RANGE.start(), *RANGE.end());
        }
        reset_button(ui, value, default);
        ui.label(text);
    });
}

/// A bounded value: a drag value (typed values accepted) and a reset.
fn linear_value(
    ui: &mut egui::Ui,
    value: &mut f32,
    default: f32,
    range: core::ops::RangeInclusive<f32>,
    speed: f64,
    text: &str,
) {
    ui.horizontal(|ui| {
        ui.add(egui::DragValue::new(value).speed(speed).range(range));
        reset_button(ui, value, default);
        ui.label(text);
    });
}

fn reset_button(ui: &mut egui::Ui, value: &mut f32, default: f32) {
    if ui
        .add_enabled(*value != default, egui::Button::new("reset").small())
        .on_hover_text(format!("reset to {default}"))
        .clicked()
    {
        *value = default;
    }
}

fn stats_ui(
    ui: &mut egui::Ui,
    stats: &ClothStats,
    history: &VecDeque<f32>,
    diagnostics: Option<&DiagnosticsStore>,
) {
    if let Some(frame) = diagnostics
        .and_then(|d| d.get(&FrameTimeDiagnosticsPlugin::FRAME_TIME))
        .and_then(|d| d.smoothed())
    {
        ui.label(format!(
            "frame: {frame:.1} ms ({:.0} FPS)",
            1000.0 / frame.max(1e-3)
        ));
    }
    ui.label(format!("method: {}   steps: {}", stats.method, stats.steps));
    let iterations = if stats.method == "stiff" {
        "substeps"
    } else {
        "iterations"
    };
    ui.label(format!(
        "step: {:.1} µs   {iterations}: {}",
        stats.step_time.as_secs_f64() * 1e6,
        stats.iterations
    ))
    .on_hover_text("the last step's wall time, and its iterations (substeps for stiff)");
    ui.label(format!(
        "residual: {}",
        stats
            .residual
            .map_or("-".to_string(), |r| format!("{r:.3e}"))
    ))
    .on_hover_text(match stats.method {
        "newton" | "exact" => "the gradient's norm relative to the step's start (no unit)",
        "linear-cg" => "CG's relative residual ‖b − Ax‖/‖b‖ (no unit)",
        "stiff" | "pbd" | "symplectic" | "linear-direct" => "this method has no residual",
        _ => "the implicit-Euler objective's gradient norm, in newtons",
    });
    ui.label(format!(
        "max stretch: {:.2} %   contacts: {}   self: {}",
        stats.max_stretch * 100.0,
        stats.contacts,
        stats.self_contacts
    ))
    .on_hover_text(
        "the longest spring over its rest length; vertices on a collider; pairs of the cloth's \
         own vertices touching (self-collision)",
    );
    ui.label(format!("energy: {:.3e} J", stats.energy))
        .on_hover_text("kinetic + spring + gravitational (zero height at y = 0)");
    if let Some(error) = stats.relative_error {
        let text = format!("step error: {:.1} % of its motion", 100.0 * error);
        if stats.converged {
            ui.label(text);
        } else {
            ui.colored_label(
                egui::Color32::YELLOW,
                format!(
                    "{text}: not converged (raise iterations, or use {})",
                    match stats.method {
                        "pd" | "pd-anderson" => "stiff or newton",
                        "newton" | "exact" => "a smaller time step",
                        _ => "stiff or pd",
                    }
                ),
            );
        }
    }
    if stats.retried_steps > 0 {
        ui.label(format!(
            "guard: {} steps retried, now {} substeps per step",
            stats.retried_steps, stats.substeps
        ));
    }
    let status = match &stats.status {
        ClothStatus::Running => None,
        ClothStatus::Invalid(error) => Some(format!("skipped: {error}")),
        ClothStatus::NoMethod { method: Some(name) } => {
            Some(format!("not simulated: no plugin for '{name}'"))
        }
        ClothStatus::NoMethod { method: None } => {
            Some("not simulated: no method component".to_string())
        }
        ClothStatus::Diverged(reason) => Some(format!("stopped by the guard: {reason:?}")),
    };
    if let Some(status) = status {
        ui.colored_label(egui::Color32::LIGHT_RED, status);
    }
    // Step-time history, its label above the plot.
    let max = history.iter().copied().fold(1.0f32, f32::max);
    ui.label(
        egui::RichText::new(format!("step time (last {HISTORY} steps), max {max:.0} µs"))
            .small()
            .color(egui::Color32::GRAY),
    );
    let (rect, _) =
        ui.allocate_exact_size(egui::vec2(ui.available_width(), 60.0), egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, egui::Color32::from_gray(30));
    if history.len() > 1 {
        let points: Vec<egui::Pos2> = history
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                egui::pos2(
                    rect.left() + rect.width() * i as f32 / (HISTORY - 1) as f32,
                    rect.bottom() - rect.height() * t / max,
                )
            })
            .collect();
        painter.add(egui::Shape::line(
            points,
            egui::Stroke::new(1.5, egui::Color32::LIGHT_GREEN),
        ));
    }
}

fn colliders_ui(ui: &mut egui::Ui, colliders: &mut Query<(Entity, &mut SphereCollider)>) {
    for (entity, mut collider) in colliders {
        ui.label(format!("sphere {entity}"));
        let c = collider.bypass_change_detection();
        let before = *c;
        ui.add(
            egui::Slider::new(&mut c.radius, 0.01..=10.0)
                .text("radius")
                .logarithmic(true),
        );
        let mut penalty = matches!(c.response, SphereResponse::Penalty { .. });
        ui.horizontal(|ui| {
            ui.radio_value(&mut penalty, false, "projection");
            ui.radio_value(&mut penalty, true, "penalty");
        });
        c.response = match (penalty, c.response) {
            (false, _) => SphereResponse::Projection,
            (true, SphereResponse::Penalty { stiffness }) => SphereResponse::Penalty { stiffness },
            (true, _) => SphereResponse::Penalty { stiffness: 1e3 },
        };
        if let SphereResponse::Penalty { stiffness } = &mut c.response {
            ui.add(
                egui::Slider::new(stiffness, 1.0..=1e6)
                    .text("penalty stiffness")
                    .logarithmic(true),
            );
        } else {
            // Friction acts with the projection only.
            ui.add(egui::Slider::new(&mut c.friction, 0.0..=1.5).text("friction μ"));
        }
        if *c != before {
            collider.set_changed();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_panel_system_has_no_conflicting_access() {
        // Bevy checks a system's parameters for conflicts when it is
        // initialised (error B0001); the lab found one at run time once.
        let mut world = World::new();
        let mut system = IntoSystem::<(), Result, _>::into_system(inspector_panel);
        system.initialize(&mut world);
    }

    #[test]
    fn the_self_collision_controls_write_nothing_the_user_did_not_move() {
        // The drape scene's sheets: `for_model`'s thickness has more
        // decimals than the slider shows.
        let model = crate::model::ClothBuilder::grid(
            32,
            32,
            Vec3::new(-0.6, 0.0, -0.6),
            Vec3::new(-0.6, 0.0, 0.6),
            Vec3::new(0.6, 0.0, -0.6),
        )
        .build()
        .unwrap();
        let sc = SelfCollision::for_model(&model);
        assert_ne!(sc.thickness, (sc.thickness * 1000.0).round() / 1000.0);
        let mut world = World::new();
        let entity = world.spawn(sc).id();
        let mut queue = bevy::ecs::world::CommandQueue::default();
        let elsewhere = World::new();
        let mut commands = Commands::new(&mut queue, &elsewhere);
        let ctx = egui::Context::default();
        let before = world.change_tick();
        for _ in 0..3 {
            let _ = ctx.run_ui(egui::RawInput::default(), |ui| {
                let current = world.get_mut::<SelfCollision>(entity);
                self_collision_ui(ui, &mut commands, entity, current, &model);
            });
        }
        let after = world.entity(entity).get_ref::<SelfCollision>().unwrap();
        assert_eq!(*after, sc);
        assert!(
            !after
                .last_changed()
                .is_newer_than(before, world.change_tick())
        );
    }
}
