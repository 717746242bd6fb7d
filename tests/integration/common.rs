//! Test helpers: a headless app that runs exactly one fixed step per update.

use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;

/// The lab's time step.
pub const DT: f64 = 0.0333;

/// Fixed steps run so far.
#[derive(Resource, Default)]
pub struct FixedSteps(pub u64);

fn count(mut steps: ResMut<FixedSteps>) {
    steps.0 += 1;
}

/// `MinimalPlugins` + `plugins`, the lab's fixed time step, one fixed step
/// per update.
pub fn app_with<M>(plugins: impl bevy::app::Plugins<M>) -> App {
    let mut app = App::new();
    app.add_plugins(MinimalPlugins)
        .add_plugins(plugins)
        .insert_resource(Time::<Fixed>::from_seconds(DT))
        .insert_resource(TimeUpdateStrategy::FixedTimesteps(1))
        .init_resource::<FixedSteps>()
        .add_systems(ClothSchedule, count.in_set(ClothSystems::Last));
    app.finish();
    app.cleanup();
    app
}

/// An app with every cloth plugin.
pub fn app() -> App {
    app_with(ClothPlugins::default())
}

/// Runs updates until `n` more fixed steps have run.
pub fn run_steps(app: &mut App, n: u64) {
    let target = app.world().resource::<FixedSteps>().0 + n;
    let mut guard = 0;
    while app.world().resource::<FixedSteps>().0 < target {
        app.update();
        guard += 1;
        assert!(guard < 2 * n + 10, "fixed steps are not running");
    }
}

/// The lab's cloth entity with a method.
pub fn spawn_lab(app: &mut App, method: impl Bundle) -> Entity {
    let cloth = Cloth::build(ClothBuilder::lab()).unwrap();
    app.world_mut()
        .spawn((cloth, method, ClothParams::LAB, Transform::default()))
        .id()
}

/// A cloth's world positions.
pub fn positions(app: &App, cloth: Entity) -> Vec<Vec3A> {
    app.world()
        .get::<Cloth>(cloth)
        .unwrap()
        .positions()
        .to_vec()
}

/// A cloth's stats.
pub fn stats(app: &App, cloth: Entity) -> ClothStats {
    app.world().get::<ClothStats>(cloth).unwrap().clone()
}

/// Largest speed of any vertex.
pub fn max_speed(app: &App, cloth: Entity) -> f32 {
    app.world()
        .get::<Cloth>(cloth)
        .unwrap()
        .state()
        .velocities
        .iter()
        .map(|v| v.length())
        .fold(0.0, f32::max)
}

/// Allows a step of `dt` per update, past Bevy's 0.25 s frame cap.
#[allow(dead_code)]
pub fn allow_long_steps(app: &mut App, dt: f64) {
    app.world_mut()
        .resource_mut::<Time<Virtual>>()
        .set_max_delta(Duration::from_secs_f64(dt.max(0.25)));
}

/// One cloth of `builder` per preset, at the origin, each with its preset's
/// method.
pub fn spawn_every_preset(
    app: &mut App,
    builder: &ClothBuilder,
) -> Vec<(&'static bevy_cloth::Preset, Entity)> {
    PRESETS
        .iter()
        .map(|p| {
            let e = app
                .world_mut()
                .spawn((Cloth::build(builder.clone()).unwrap(), Transform::default()))
                .id();
            p.method.insert(&mut app.world_mut().commands().entity(e));
            (p, e)
        })
        .collect()
}
