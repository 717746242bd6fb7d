//! The drape scene, shared by `examples/drape.rs` (with a window) and
//! `headless --scene drape` (without): a square of cotton dropped onto a
//! ball on the ground drapes over it and folds onto itself, and a second
//! sheet, turned, lands on it a second later. Both have a
//! [`SelfCollision`] (switchable). A ball can be thrown through the drape
//! at 30 m/s ([`DrapeClock::throw`], or at a set time with
//! [`DrapeSettings::throw_at`]): half a metre a step, five times its
//! radius, and the swept projection carries the cloth ahead of it instead
//! of letting it pass. The scene counts, after every fixed
//! step, the mesh edges of each sheet through its own triangles and
//! through the other sheet's (the exact check,
//! `collision::self_contact::count_intersections` and `count_crossings`).

use bevy::prelude::*;
use bevy_cloth::collision::self_contact::{
    IntersectionCheck, count_crossings, count_intersections,
};
use bevy_cloth::prelude::*;

/// The scene's fixed step: a game's 60 Hz.
pub const DT: f64 = 1.0 / 60.0;

/// The ball the sheets drape over: radius and centre.
pub const BALL: (f32, Vec3) = (0.3, Vec3::new(0.0, 0.3, 0.0));

/// When the second sheet is dropped (s).
pub const SECOND_AT: f32 = 1.0;

/// The thrown ball: radius, speed (m/s), where it starts and how long it
/// flies (s) before it is gone. It flies along `+x`, 0.22 m up and 0.52 m
/// to the side of the ball's centre, through the skirt of cloth hanging
/// there, clear of the ball and the ground (cloth pinched between two
/// solids a few centimetres apart cannot be resolved, and the guard stops
/// it).
pub const THROW: (f32, f32, Vec3, f32) = (0.1, 30.0, Vec3::new(-2.5, 0.22, 0.52), 0.3);

/// The scene's choices.
#[derive(Resource, Clone, Debug)]
pub struct DrapeSettings {
    /// The sheets' method.
    pub method: AnyMethod,
    /// Vertices along each sheet's side.
    pub n: usize,
    /// Whether the sheets have a [`SelfCollision`].
    pub self_collision: bool,
    /// Throw a ball ([`THROW`]) at this scene time (s), once.
    pub throw_at: Option<f32>,
}

impl Default for DrapeSettings {
    fn default() -> Self {
        Self {
            method: AnyMethod::default(),
            n: 32,
            self_collision: true,
            throw_at: None,
        }
    }
}

/// One of the scene's sheets: 0 the first, 1 the one that lands on it.
#[derive(Component, Clone, Copy, Debug)]
pub struct Sheet(pub usize);

/// What the scene counted so far: mesh edges through a triangle (of the
/// same sheet or the other) summed over every fixed step, the most in one
/// step, and the steps counted.
#[derive(Resource, Clone, Debug, Default)]
pub struct Penetrations {
    /// Summed over every step.
    pub total: usize,
    /// The most in one step.
    pub worst: usize,
    /// Steps counted.
    pub steps: usize,
    /// The largest stretch of either sheet seen.
    pub max_stretch: f32,
    /// Sheet vertices within 2 cm of a thrown ball's surface, summed over
    /// the steps it flew: whether it met the drape.
    pub ball_touches: usize,
    /// Sheet vertices left inside a thrown ball after a step, summed.
    pub inside_ball: usize,
}

impl Penetrations {
    /// The count in the words both `headless --scene drape` and the
    /// windowed example print: `penetrations= worst_step_penetrations=
    /// ball_touches= inside_ball=`.
    pub fn summary(&self) -> String {
        format!(
            "penetrations={} worst_step_penetrations={} ball_touches={} inside_ball={}",
            self.total, self.worst, self.ball_touches, self.inside_ball
        )
    }
}

/// Scene time and whether the second sheet is down yet.
#[derive(Resource, Clone, Debug, Default)]
pub struct DrapeClock {
    /// Seconds since the scene (re)started.
    pub seconds: f32,
    /// The second sheet has been dropped.
    pub second: bool,
    /// Set to start the scene again (both sheets back up, counts cleared).
    pub restart: bool,
    /// Set to throw a ball ([`THROW`]) at the next fixed step.
    pub throw: bool,
    /// Balls thrown so far.
    pub thrown: usize,
}

/// A ball thrown through the scene: a [`SphereCollider`] moved along `+x`
/// at [`THROW`]'s speed each fixed step, gone after its flight.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct Thrown {
    /// Seconds in flight.
    pub age: f32,
}

/// Adds the scene: the ground, the ball, the first sheet at once and the
/// second at [`SECOND_AT`], and the count.
pub struct DrapeScenePlugin;

impl Plugin for DrapeScenePlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<DrapeSettings>()
            .init_resource::<Penetrations>()
            .init_resource::<DrapeClock>()
            .add_systems(Startup, spawn_scene)
            .add_systems(
                FixedUpdate,
                (
                    (drop_sheets, throw_balls)
                        .chain()
                        .in_set(ClothSystems::First),
                    count.in_set(ClothSystems::Last),
                ),
            )
            .add_systems(Update, follow_settings);
    }
}

fn spawn_scene(mut commands: Commands, settings: Res<DrapeSettings>) {
    commands.spawn((PlaneCollider::new(0.6), Transform::default()));
    commands.spawn((
        SphereCollider::new(BALL.0).with_friction(0.4),
        Transform::from_translation(BALL.1),
    ));
    spawn_sheet(&mut commands, &settings, 0);
}

/// A 1.2 m square of cotton, flat: the first a little off the ball's top,
/// the second higher and turned.
fn sheet_model(n: usize) -> ClothModel {
    let h = 0.6;
    ClothBuilder::grid(
        n,
        n,
        Vec3::new(-h, 0.0, -h),
        Vec3::new(-h, 0.0, h),
        Vec3::new(h, 0.0, -h),
    )
    .build()
    .expect("a valid grid")
}

fn place(index: usize) -> Transform {
    if index == 0 {
        Transform::from_xyz(0.15, 0.75, 0.1).with_rotation(Quat::from_rotation_z(0.2))
    } else {
        Transform::from_xyz(-0.1, 1.0, 0.0)
            .with_rotation(Quat::from_rotation_y(0.6) * Quat::from_rotation_x(-0.15))
    }
}

fn spawn_sheet(commands: &mut Commands, settings: &DrapeSettings, index: usize) {
    let model = sheet_model(settings.n.max(2));
    let sc = SelfCollision::for_model(&model);
    let mut sheet = commands.spawn((
        Cloth::new(model),
        ClothMaterial::COTTON,
        place(index),
        Sheet(index),
        Name::new(if index == 0 {
            "first sheet"
        } else {
            "second sheet"
        }),
    ));
    if settings.self_collision {
        sheet.insert(sc);
    }
    settings.method.insert(&mut sheet);
}

/// Drops the second sheet on time, and restarts the scene when asked.
fn drop_sheets(
    mut commands: Commands,
    time: Res<Time>,
    settings: Res<DrapeSettings>,
    mut clock: ResMut<DrapeClock>,
    mut counted: ResMut<Penetrations>,
    sheets: Query<Entity, With<Sheet>>,
) {
    if clock.restart {
        for e in &sheets {
            commands.entity(e).despawn();
        }
        *clock = DrapeClock::default();
        *counted = Penetrations::default();
        spawn_sheet(&mut commands, &settings, 0);
        return;
    }
    clock.seconds += time.delta_secs();
    if !clock.second && clock.seconds >= SECOND_AT {
        clock.second = true;
        spawn_sheet(&mut commands, &settings, 1);
    }
}

/// Throws a ball when asked (or at [`DrapeSettings::throw_at`]), moves the
/// balls in flight, and removes them when their flight is over.
fn throw_balls(
    mut commands: Commands,
    time: Res<Time>,
    settings: Res<DrapeSettings>,
    mut clock: ResMut<DrapeClock>,
    mut balls: Query<(Entity, &mut Transform, &mut Thrown)>,
) {
    let dt = time.delta_secs();
    let (radius, speed, start, flight) = THROW;
    for (entity, mut transform, mut thrown) in &mut balls {
        thrown.age += dt;
        transform.translation.x += speed * dt;
        if thrown.age > flight {
            commands.entity(entity).despawn();
        }
    }
    let due = settings
        .throw_at
        .is_some_and(|at| clock.thrown == 0 && clock.seconds >= at);
    if std::mem::take(&mut clock.throw) || due {
        clock.thrown += 1;
        commands.spawn((
            SphereCollider::new(radius),
            Transform::from_translation(start),
            Thrown::default(),
            Name::new("thrown ball"),
        ));
    }
}

/// Self-collision on or off as the settings say.
fn follow_settings(
    mut commands: Commands,
    settings: Res<DrapeSettings>,
    sheets: Query<(Entity, &Cloth, Has<SelfCollision>), With<Sheet>>,
) {
    if !settings.is_changed() {
        return;
    }
    for (e, cloth, has) in &sheets {
        match (settings.self_collision, has) {
            (true, false) => {
                commands
                    .entity(e)
                    .insert(SelfCollision::for_model(cloth.model()));
            }
            (false, true) => {
                commands.entity(e).remove::<SelfCollision>();
            }
            _ => {}
        }
    }
}

/// The exact check after every fixed step.
fn count(
    mut counted: ResMut<Penetrations>,
    mut check: Local<IntersectionCheck>,
    sheets: Query<(&Cloth, &Sheet, &ClothStats)>,
    balls: Query<(&Transform, &SphereCollider), With<Thrown>>,
) {
    for (at, ball) in &balls {
        for (cloth, _, _) in &sheets {
            for x in cloth.positions() {
                let d = x.distance(at.translation.into()) - ball.radius;
                counted.ball_touches += usize::from(d < 0.02);
                counted.inside_ball += usize::from(d < -1e-3);
            }
        }
    }
    let mut list: Vec<(&Cloth, usize)> = sheets
        .iter()
        .filter(|(_, _, stats)| stats.steps > 0)
        .map(|(cloth, sheet, stats)| {
            counted.max_stretch = counted.max_stretch.max(stats.max_stretch);
            (cloth, sheet.0)
        })
        .collect();
    if list.is_empty() {
        return;
    }
    list.sort_by_key(|&(_, i)| i);
    let mut now = 0;
    for (k, &(cloth, _)) in list.iter().enumerate() {
        let x = cloth.positions();
        now += count_intersections(cloth.model(), x, &mut check);
        for &(other, _) in &list[k + 1..] {
            now += count_crossings(
                (cloth.model(), x),
                (other.model(), other.positions()),
                &mut check,
            );
        }
    }
    counted.total += now;
    counted.worst = counted.worst.max(now);
    counted.steps += 1;
}

/// What [`run_headless`] measured.
#[derive(Clone, Debug)]
pub struct DrapeRun {
    /// The count.
    pub penetrations: Penetrations,
    /// Per sheet, in order: its vertices, its stats at the end, and its
    /// median step.
    pub sheets: Vec<(usize, ClothStats, std::time::Duration)>,
}

/// Step times per sheet, one per fixed step.
#[derive(Resource, Default)]
struct SheetTimes(Vec<(usize, std::time::Duration)>);

fn record_times(mut times: ResMut<SheetTimes>, sheets: Query<(&Sheet, &ClothStats)>) {
    for (sheet, stats) in &sheets {
        times.0.push((sheet.0, stats.step_time));
    }
}

/// Runs the scene without a window for `steps` fixed steps.
pub fn run_headless(settings: DrapeSettings, steps: usize) -> DrapeRun {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, ClothPlugins::default()))
        .insert_resource(settings)
        .insert_resource(Time::<Fixed>::from_seconds(DT))
        .add_plugins(DrapeScenePlugin)
        .insert_resource(bevy::time::TimeUpdateStrategy::FixedTimesteps(1))
        .init_resource::<SheetTimes>()
        .add_systems(FixedUpdate, record_times.in_set(ClothSystems::Last));
    app.finish();
    app.cleanup();
    app.update();
    for _ in 0..steps {
        app.update();
    }
    let world = app.world_mut();
    let penetrations = world.resource::<Penetrations>().clone();
    let times = std::mem::take(&mut world.resource_mut::<SheetTimes>().0);
    let mut query = world.query::<(&Sheet, &Cloth, &ClothStats)>();
    let mut sheets: Vec<(usize, usize, ClothStats, std::time::Duration)> = query
        .iter(world)
        .map(|(sheet, cloth, stats)| {
            let mut mine: Vec<std::time::Duration> = times
                .iter()
                .filter(|(i, _)| *i == sheet.0)
                .map(|&(_, t)| t)
                .collect();
            mine.sort();
            let median = mine.get(mine.len() / 2).copied().unwrap_or_default();
            (sheet.0, cloth.positions().len(), stats.clone(), median)
        })
        .collect();
    sheets.sort_by_key(|(i, ..)| *i);
    DrapeRun {
        penetrations,
        sheets: sheets.into_iter().map(|(_, n, s, t)| (n, s, t)).collect(),
    }
}
