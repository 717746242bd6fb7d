//! The cape scene, shared by `examples/cape.rs` (in a window) and
//! `headless --scene cape` (without one): a character made in code — a
//! skeleton of joint entities with capsules on its bones — that runs a
//! circle, turns sharply, jumps and can be teleported, wearing a cape and a
//! skirt skinned to its joints.
//!
//! The garments are meshes with joint indices and weights, as a glTF
//! character's are, bound to the skeleton by a [`SkinnedMesh`]:
//! [`Skinning::from_mesh`] skins their vertices on the CPU each step, the
//! collar and the waistband are pinned on the skin, and [`ClothSkin`] holds
//! the rest near it (tethers, max distance, backstop). [`ClothInertia`]
//! measures the character's root: the garments feel its motion at the
//! settings' scale and jump with it when it is teleported. Every step
//! counts the garments' vertices inside a body capsule
//! ([`BodyPenetrations`]).

use bevy::asset::RenderAssetUsages;
use bevy::math::Mat4;
use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
use bevy::mesh::{Indices, PrimitiveTopology};
use bevy::prelude::*;
use bevy::transform::helper::TransformHelper;
use bevy_cloth::prelude::*;

/// The scene's fixed step.
pub const DT: f64 = 1.0 / 60.0;
/// The circle the character runs, its radius (m) and speed (m/s).
const CIRCLE: f32 = 4.0;
const SPEED: f32 = 3.5;
/// The script repeats every `LOOP` seconds: a jump at `JUMP`, a sharp turn
/// (180° in `TURN_TIME`) at `TURN`.
const LOOP: f32 = 5.0;
const JUMP: f32 = 1.5;
const JUMP_TIME: f32 = 0.6;
const JUMP_HEIGHT: f32 = 0.5;
const TURN: f32 = 3.5;
const TURN_TIME: f32 = 0.4;
/// The run gets up to speed over this long from standing.
const START: f32 = 1.0;
/// Where a teleport sends the character, from where it is.
pub const TELEPORT: Vec3 = Vec3::new(100.0, 0.0, 0.0);
/// A jump of the root beyond this in one step is a teleport for the cloth.
const TELEPORT_DISTANCE: f32 = 5.0;
/// Tethers' scale: a garment stretches at most this much from its pins.
const TETHER_SCALE: f32 = 1.01;

/// What the scene is built with; the panel changes the toggles live.
#[derive(Resource, Clone, Copy, Debug)]
pub struct CapeSettings {
    /// The garments' method.
    pub method: AnyMethod,
    /// The cape's columns; it has 8/5 as many rows (50: 4,000 vertices).
    pub cape_cols: usize,
    /// Tethers to the collar and waistband.
    pub tethers: bool,
    /// Max distance from the skin (0 at the pins, growing to the hem).
    pub max_distance: bool,
    /// The cape's backstop behind the skin (it stays off the back and out
    /// of the legs).
    pub backstop: bool,
    /// The garments feel half of the character's velocity and a quarter of
    /// its acceleration (otherwise all of both).
    pub inertia: bool,
    /// An anim drive pulling every vertex towards its skinned place
    /// ([`ANIM_DRIVE`] of the way per second): the garments keep their
    /// modelled shape.
    pub drive: bool,
}

/// The anim drive's share of the way to the skin per second, when on.
pub const ANIM_DRIVE: f32 = 0.5;

/// The garments' method unless one is chosen: the library's
/// [`XpbdSolver::GARMENT`], `stiff` with its refinement near colliders
/// capped at 4× its substeps (the preset's is 16×). The perf page's
/// "Character cloth" section measures this scene's 640-vertex cape at a
/// quarter of the preset's step with both garments' stretch within a point
/// of it (a 4,000-vertex cape needs the preset's 16×, and so does
/// self-colliding cloth, as the drape scene's; `--method stiff` runs the
/// preset).
pub const GARMENT_METHOD: AnyMethod = AnyMethod::Xpbd(XpbdSolver::GARMENT);

impl Default for CapeSettings {
    fn default() -> Self {
        Self {
            method: GARMENT_METHOD,
            cape_cols: 20,
            tethers: true,
            max_distance: true,
            backstop: true,
            inertia: true,
            drive: false,
        }
    }
}

/// A garment's painted weights, kept to switch each constraint on and off.
#[derive(Component, Clone, Debug)]
pub struct Garment {
    /// Its name.
    pub name: &'static str,
    /// Max distance and backstop distance per cloth vertex, as painted on
    /// its mesh ([`SkinConstraints::with_painted`]).
    painted: SkinConstraints,
    /// The backstop spheres' radius.
    backstop_radius: f32,
}

impl Garment {
    /// The constraints `settings` switch on.
    fn constraints(&self, settings: &CapeSettings) -> SkinConstraints {
        let painted = &self.painted;
        let mut c = SkinConstraints::free(painted.max_distance.len());
        if settings.max_distance {
            c = c.with_max_distance(|i| painted.max_distance[i]);
        }
        if settings.backstop {
            c = c.with_backstop(self.backstop_radius, |i| painted.backstop_distance[i]);
        }
        if settings.tethers {
            c = c.with_tethers(TETHER_SCALE);
        }
        if settings.drive {
            c = c.with_drive(ANIM_DRIVE);
        }
        c
    }

    /// The inertia `settings` ask for, measured on `root`.
    fn inertia(settings: &CapeSettings, root: Entity) -> ClothInertia {
        let (velocity, acceleration) = if settings.inertia {
            (0.5, 0.25)
        } else {
            (1.0, 1.0)
        };
        ClothInertia::default()
            .with_anchor(root)
            .with_scales(velocity, acceleration)
            .with_teleport(TELEPORT_DISTANCE)
    }
}

/// A capsule on one of the character's bones.
#[derive(Component)]
pub struct BodyPart;

/// The character's joints.
#[derive(Resource, Clone, Copy, Debug)]
pub struct Rig {
    /// Its root: on the ground, facing its local −z.
    pub root: Entity,
    pelvis: Entity,
    spine: Entity,
    thighs: [Entity; 2],
}

impl Rig {
    /// Every joint entity, the root first.
    pub fn joints(&self) -> [Entity; 5] {
        [
            self.root,
            self.pelvis,
            self.spine,
            self.thighs[0],
            self.thighs[1],
        ]
    }
}

/// The character's run: time, place on the circle, direction.
#[derive(Resource, Clone, Debug)]
pub struct Running {
    t: f32,
    angle: f32,
    /// Where the circle is (moved by a teleport).
    centre: Vec3,
    /// A teleport asked for (the windowed example's key, the headless
    /// scene's script).
    pub teleport: bool,
    /// Teleports so far.
    pub teleports: u32,
}

impl Default for Running {
    fn default() -> Self {
        Self {
            t: 0.0,
            angle: 0.0,
            centre: Vec3::new(-CIRCLE, 0.0, 0.0),
            teleport: false,
            teleports: 0,
        }
    }
}

impl Running {
    /// The root's place now.
    pub fn root_position(&self) -> Vec3 {
        self.centre + CIRCLE * Vec3::new(self.angle.cos(), 0.0, -self.angle.sin())
    }
}

/// Garment vertices found inside a body capsule, over the run.
#[derive(Resource, Clone, Debug, Default)]
pub struct BodyPenetrations {
    /// Vertex–capsule overlaps counted at the end of every step.
    pub count: u64,
    /// The deepest, in metres.
    pub deepest: f32,
    /// Each garment's largest stretch at any step.
    pub max_stretch: Vec<(&'static str, f32)>,
}

/// The scene: the character, its garments, the run and the count.
pub struct CapeScenePlugin;

impl Plugin for CapeScenePlugin {
    fn build(&self, app: &mut App) {
        app.init_resource::<CapeSettings>()
            .init_resource::<Running>()
            .init_resource::<BodyPenetrations>()
            .insert_resource(Time::<Fixed>::from_seconds(DT))
            .add_systems(Startup, spawn_scene)
            .add_systems(
                FixedUpdate,
                (
                    run.before(ClothScheduleSystems),
                    count_penetrations.after(ClothScheduleSystems),
                ),
            )
            .add_systems(
                Update,
                apply_settings.run_if(resource_changed::<CapeSettings>),
            );
    }
}

/// The skeleton in its bind pose (the root at the origin): pelvis 1 m up,
/// the spine from there, a thigh at each hip.
const PELVIS: Vec3 = Vec3::new(0.0, 1.0, 0.0);
const HIP: Vec3 = Vec3::new(0.1, -0.05, 0.0);

fn spawn_scene(mut commands: Commands, settings: Res<CapeSettings>, running: Res<Running>) {
    let start = Transform::from_translation(running.root_position());
    let root = commands.spawn((start, Name::new("root"))).id();
    let pelvis = commands
        .spawn((Transform::from_translation(PELVIS), ChildOf(root)))
        .id();
    let spine = commands.spawn((Transform::default(), ChildOf(pelvis))).id();
    let thighs = [-1.0, 1.0].map(|side| {
        commands
            .spawn((
                Transform::from_translation(HIP * Vec3::new(side, 1.0, 1.0)),
                ChildOf(pelvis),
            ))
            .id()
    });
    // The body: torso and head on the spine, hips on the pelvis, a leg
    // below each hip (a capsule's axis is its local y).
    let mut part = |parent: Entity, at: Transform, capsule: CapsuleCollider| {
        let capsule = CapsuleCollider {
            friction: 0.3,
            ..capsule
        };
        commands.spawn((at, capsule, BodyPart, ChildOf(parent)));
    };
    part(
        spine,
        Transform::from_xyz(0.0, 0.25, 0.0),
        CapsuleCollider::new(0.17, 0.18),
    );
    part(
        spine,
        Transform::from_xyz(0.0, 0.68, 0.0),
        CapsuleCollider::new(0.11, 0.0),
    );
    part(
        pelvis,
        Transform::from_xyz(0.0, -0.02, 0.0).with_rotation(Quat::from_rotation_z(FRAC_PI_2)),
        CapsuleCollider::new(0.15, 0.03),
    );
    for thigh in thighs {
        part(
            thigh,
            Transform::from_xyz(0.0, -0.45, 0.0),
            CapsuleCollider::new(0.075, 0.38),
        );
    }
    let rig = Rig {
        root,
        pelvis,
        spine,
        thighs,
    };
    commands.insert_resource(rig);
    // The joints' order in the garments' meshes, and their inverse bind
    // poses (the bind pose is the rig above at the origin).
    let joints = vec![pelvis, spine, thighs[0], thighs[1]];
    let bindposes = SkinnedMeshInverseBindposes::from(
        [
            PELVIS,
            PELVIS,
            PELVIS + HIP * Vec3::new(-1.0, 1.0, 1.0),
            PELVIS + HIP,
        ]
        .map(|at| Mat4::from_translation(-at))
        .to_vec(),
    );
    let skinned = SkinnedMesh {
        // The garments are drawn by the cloth's own mesh, not skinned by the
        // renderer: the bind poses are read here, not from an asset.
        inverse_bindposes: Handle::default(),
        joints,
    };
    for (mesh, (name, backstop_radius)) in [cape(settings.cape_cols), skirt()] {
        let model = match ClothBuilder::from_mesh(&mesh).and_then(|b| {
            b.with_material(ClothMaterial::COTTON.with_density(0.4))
                .with_pins(garment_pins(&mesh))
                .build()
        }) {
            Ok(model) => model,
            Err(error) => {
                error!("the {name} is not a cloth: {error}");
                continue;
            }
        };
        let garment = match SkinConstraints::free(model.vertex_count()).with_painted(&mesh, &model)
        {
            Ok(painted) => Garment {
                name,
                painted,
                backstop_radius,
            },
            Err(error) => {
                error!("the {name}'s painted weights: {error}");
                continue;
            }
        };
        let skinning = match Skinning::from_mesh(&mesh, &skinned, &bindposes, &model) {
            Ok(skinning) => skinning,
            Err(error) => {
                error!("the {} is not skinned: {error}", garment.name);
                continue;
            }
        };
        let mut entity = commands.spawn((
            Cloth::new(model),
            ClothSkin::skinned(garment.constraints(&settings), skinning),
            Garment::inertia(&settings, root),
            // The garments are placed in the world as their pins' skin is:
            // their own entity stays at the origin.
            start,
            Name::new(garment.name),
            garment,
        ));
        settings.method.insert(&mut entity);
    }
}

use std::f32::consts::{FRAC_PI_2, PI, TAU};

/// The collar (the cape's top row) and the waistband (the skirt's top
/// ring): every vertex at the garment's top.
fn garment_pins(mesh: &Mesh) -> Vec<u32> {
    let Some(top) = mesh
        .attribute(Mesh::ATTRIBUTE_POSITION)
        .and_then(|a| a.as_float3())
        .map(|p| p.iter().map(|p| p[1]).fold(f32::MIN, f32::max))
    else {
        return Vec::new();
    };
    mesh_vertices_where(mesh, Mesh::ATTRIBUTE_POSITION, |p| p[1] > top - 1e-4).unwrap_or_default()
}

/// A mesh of a `cols × rows` grid of `vertex(i, j)` (position, normal,
/// joints, weights), triangulated, wrapped round in `i` if `ring`.
fn grid_mesh(
    cols: usize,
    rows: usize,
    ring: bool,
    vertex: impl Fn(usize, usize) -> ([f32; 3], [f32; 3], [u16; 4], [f32; 4]),
) -> Mesh {
    let (mut p, mut n, mut j, mut w) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for r in 0..rows {
        for c in 0..cols {
            let v = vertex(c, r);
            p.push(v.0);
            n.push(v.1);
            j.push(v.2);
            w.push(v.3);
        }
    }
    let mut indices = Vec::new();
    let across = if ring { cols } else { cols - 1 };
    for r in 0..rows - 1 {
        for c in 0..across {
            let at = |c: usize, r: usize| (r * cols + c % cols) as u32;
            let (a, b, d, e) = (at(c, r), at(c + 1, r), at(c, r + 1), at(c + 1, r + 1));
            indices.extend([a, d, b, b, d, e]);
        }
    }
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, p)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, n)
    .with_inserted_attribute(
        Mesh::ATTRIBUTE_JOINT_INDEX,
        bevy::mesh::VertexAttributeValues::Uint16x4(j),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT, w)
    .with_inserted_indices(Indices::U32(indices))
}

/// The cape: from the shoulders (1.45 m, 0.6 m wide) to 0.35 m above the
/// ground (0.9 m wide), 2 cm behind the back; skinned to the spine at the
/// top, the pelvis below. Max distance grows to 0.6 m at the hem; the
/// backstop is 2 cm behind the skin (spheres of 3 m: nearly a plane): both
/// painted on the mesh as vertex attributes. Returns the mesh, the name and
/// the backstop spheres' radius.
fn cape(cols: usize) -> (Mesh, (&'static str, f32)) {
    let cols = cols.max(2);
    let rows = (cols * 8).div_ceil(5).max(2);
    let (top, bottom) = (1.45, 0.35);
    let mesh = grid_mesh(cols, rows, false, |c, r| {
        let (u, v) = (c as f32 / (cols - 1) as f32, r as f32 / (rows - 1) as f32);
        let half = 0.3 + 0.15 * v;
        let y = top + (bottom - top) * v;
        let spine = ((y - 0.8) / 0.5).clamp(0.0, 1.0);
        (
            [(2.0 * u - 1.0) * half, y, 0.19],
            [0.0, 0.0, 1.0],
            [1, 0, 0, 0],
            [spine, 1.0 - spine, 0.0, 0.0],
        )
    });
    let depth = |p: &[f32; 3]| (top - p[1]).max(0.0) / (top - bottom);
    let positions = mesh
        .attribute(Mesh::ATTRIBUTE_POSITION)
        .and_then(|a| a.as_float3())
        .unwrap_or_default();
    let max_distance: Vec<f32> = positions.iter().map(|p| 0.6 * depth(p)).collect();
    let backstop = vec![0.02f32; positions.len()];
    let mesh = mesh
        .with_inserted_attribute(ATTRIBUTE_CLOTH_MAX_DISTANCE, max_distance)
        .with_inserted_attribute(ATTRIBUTE_CLOTH_BACKSTOP, backstop);
    (mesh, ("cape", 3.0))
}

/// The skirt: a flared cone round the hips from the waist (0.98 m, radius
/// 0.2) to 0.62 m (radius 0.4), skinned to the pelvis at the waist, more and
/// more to the thigh on its side below. Max distance grows to 0.25 m at the
/// hem. No backstop: a backstop sphere stands for a body part no wider than
/// itself, and round a tube a vertex sliding sideways would be pushed out of
/// it; the hips' and legs' capsules keep the skirt off the body.
fn skirt() -> (Mesh, (&'static str, f32)) {
    let (around, rows) = (40, 12);
    let (top, bottom) = (0.98, 0.62);
    let mesh = grid_mesh(around, rows, true, |c, r| {
        let (a, v) = (TAU * c as f32 / around as f32, r as f32 / (rows - 1) as f32);
        let radius = 0.2 + 0.2 * v;
        let (x, z) = (radius * a.cos(), radius * a.sin());
        let leg = 0.7 * v * a.cos().abs();
        let thigh = if x < 0.0 { 2 } else { 3 };
        (
            [x, top + (bottom - top) * v, z],
            [a.cos(), 0.0, a.sin()],
            [0, thigh, 0, 0],
            [1.0 - leg, leg, 0.0, 0.0],
        )
    });
    let count = around * rows;
    let max_distance: Vec<f32> = (0..count)
        .map(|i| 0.25 * (i / around) as f32 / (rows - 1) as f32)
        .collect();
    (
        mesh.with_inserted_attribute(ATTRIBUTE_CLOTH_MAX_DISTANCE, max_distance),
        ("skirt", 0.15),
    )
}

/// Runs the script one fixed step: round the circle, a jump, a sharp turn
/// (the run reverses), the legs' stride; a teleport moves the circle.
fn run(
    time: Res<Time>,
    rig: Option<Res<Rig>>,
    mut running: ResMut<Running>,
    mut transforms: Query<&mut Transform>,
) {
    let Some(rig) = rig else {
        return;
    };
    let dt = time.delta_secs();
    let running = &mut *running;
    running.t += dt;
    if std::mem::take(&mut running.teleport) {
        running.centre += TELEPORT;
        running.teleports += 1;
    }
    let phase = running.t % LOOP;
    let lap = (running.t / LOOP) as u32;
    // The direction flips at each turn; between, it is held.
    let ramp = ((phase - TURN) / TURN_TIME).clamp(0.0, 1.0);
    let before = if lap.is_multiple_of(2) { 1.0 } else { -1.0 };
    // Eased in and out, as an animation curve would.
    let turning = ramp * ramp * (3.0 - 2.0 * ramp) * PI;
    // Speed drops to nothing at the middle of the turn and back; the run
    // starts from standing over its first second.
    let speed = SPEED * (2.0 * ramp - 1.0).abs() * running.t.min(START) / START;
    let direction = if ramp < 0.5 { before } else { -before };
    running.angle += direction * speed / CIRCLE * dt;
    // The jump: up and down as an animation curve eases it (no jolt at
    // take-off or landing), the knees drawn up and let down.
    let (lift, tuck) = if (JUMP..JUMP + JUMP_TIME).contains(&phase) {
        let u = (phase - JUMP) / JUMP_TIME;
        let s = (PI * u).sin();
        (JUMP_HEIGHT * s * s, 0.25 * s)
    } else {
        (0.0, 0.0)
    };
    // Facing along the run (the tangent), turned through 180° in the turn.
    let tangent_yaw = running.angle + if before > 0.0 { 0.0 } else { PI };
    let yaw = tangent_yaw + turning;
    if let Ok(mut root) = transforms.get_mut(rig.root) {
        root.translation = running.root_position() + Vec3::Y * lift;
        root.rotation = Quat::from_rotation_y(yaw);
    }
    if let Ok(mut spine) = transforms.get_mut(rig.spine) {
        spine.rotation = Quat::from_rotation_x(-0.15 * speed / SPEED);
    }
    if let Ok(mut pelvis) = transforms.get_mut(rig.pelvis) {
        pelvis.rotation = Quat::from_rotation_y(0.1 * (TAU * 1.6 * running.t).sin());
    }
    let stride = 0.4 * speed / SPEED * (TAU * 1.6 * running.t).sin();
    for (thigh, side) in rig.thighs.into_iter().zip([1.0, -1.0]) {
        if let Ok(mut t) = transforms.get_mut(thigh) {
            t.rotation = Quat::from_rotation_x(side * stride + tuck);
        }
    }
}

/// Counts the garments' vertices inside a body capsule after the step, and
/// their largest stretch.
fn count_penetrations(
    helper: TransformHelper,
    parts: Query<(Entity, &CapsuleCollider), With<BodyPart>>,
    garments: Query<(&Cloth, &ClothStats, &Garment)>,
    mut count: ResMut<BodyPenetrations>,
) {
    let capsules: Vec<(Vec3, Vec3, f32)> = parts
        .iter()
        .filter_map(|(entity, capsule)| {
            let g = helper.compute_global_transform(entity).ok()?;
            let axis =
                g.affine().transform_vector3(Vec3::Y).normalize_or_zero() * capsule.half_length;
            let centre = g.translation();
            Some((centre - axis, centre + axis, capsule.radius))
        })
        .collect();
    for (cloth, stats, garment) in &garments {
        match count
            .max_stretch
            .iter_mut()
            .find(|(name, _)| *name == garment.name)
        {
            Some((_, worst)) => *worst = worst.max(stats.max_stretch),
            None => count.max_stretch.push((garment.name, stats.max_stretch)),
        }
        for &x in cloth.positions() {
            let x = Vec3::from(x);
            for &(a, b, r) in &capsules {
                let ab = b - a;
                let s = ((x - a).dot(ab) / ab.length_squared().max(1e-12)).clamp(0.0, 1.0);
                let depth = r - x.distance(a + s * ab);
                // A millimetre's tolerance for the projection's rounding.
                if depth > 1e-3 {
                    count.count += 1;
                    count.deepest = count.deepest.max(depth);
                }
            }
        }
    }
}

/// Applies the panel's toggles to the garments.
fn apply_settings(
    settings: Res<CapeSettings>,
    rig: Option<Res<Rig>>,
    mut garments: Query<(&Garment, &mut ClothSkin, &mut ClothInertia)>,
) {
    let Some(rig) = rig else {
        return;
    };
    for (garment, mut skin, mut inertia) in &mut garments {
        skin.constraints = garment.constraints(&settings);
        let wanted = Garment::inertia(&settings, rig.root);
        inertia.velocity_scale = wanted.velocity_scale;
        inertia.acceleration_scale = wanted.acceleration_scale;
    }
}

/// One garment's result of a [`run_headless`].
#[derive(Clone, Debug)]
pub struct GarmentRun {
    /// The garment's name.
    pub name: &'static str,
    /// Its method's name.
    pub method: &'static str,
    /// Its vertices.
    pub vertices: usize,
    /// Its steps.
    pub steps: u64,
    /// Its step times (solver step, collision excluded), one per step.
    pub step_times: Vec<std::time::Duration>,
    /// Its largest stretch at any step.
    pub max_stretch: f32,
    /// Steps the guard retried.
    pub retried_steps: u64,
    /// Whether every position is finite at the end.
    pub finite: bool,
    /// Its status at the end.
    pub status: ClothStatus,
}

impl GarmentRun {
    /// Whether it ran cleanly: finite, running, nothing retried.
    pub fn clean(&self) -> bool {
        self.finite && self.status == ClothStatus::Running && self.retried_steps == 0
    }

    /// The median step time.
    pub fn median_step(&self) -> std::time::Duration {
        let mut times = self.step_times.clone();
        times.sort();
        times.get(times.len() / 2).copied().unwrap_or_default()
    }
}

/// What a [`run_headless`] measured.
#[derive(Clone, Debug)]
pub struct CapeRun {
    /// The cape, then the skirt.
    pub garments: Vec<GarmentRun>,
    /// Teleports done.
    pub teleports: u32,
    /// Garment vertices found inside a body capsule, and the deepest.
    pub penetrations: BodyPenetrations,
}

/// Step times per garment, one per fixed step.
#[derive(Resource, Default)]
struct GarmentTimes(Vec<(&'static str, std::time::Duration)>);

fn record_times(mut times: ResMut<GarmentTimes>, garments: Query<(&Garment, &ClothStats)>) {
    for (garment, stats) in &garments {
        times.0.push((garment.name, stats.step_time));
    }
}

/// Runs the scene without a window for `steps` fixed steps (one per
/// update), teleporting the character at `teleport_at` seconds if given.
pub fn run_headless(settings: CapeSettings, steps: usize, teleport_at: Option<f32>) -> CapeRun {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, ClothPlugins::default()))
        .insert_resource(settings)
        .add_plugins(CapeScenePlugin)
        .insert_resource(bevy::time::TimeUpdateStrategy::FixedTimesteps(1))
        .init_resource::<GarmentTimes>()
        .add_systems(FixedUpdate, record_times.in_set(ClothSystems::Last));
    app.finish();
    app.cleanup();
    app.update();
    for step in 0..steps {
        if teleport_at.is_some_and(|t| step as f32 * DT as f32 >= t) {
            let mut running = app.world_mut().resource_mut::<Running>();
            if running.teleports == 0 && !running.teleport {
                running.teleport = true;
            }
        }
        app.update();
    }
    let world = app.world_mut();
    let penetrations = world.resource::<BodyPenetrations>().clone();
    let teleports = world.resource::<Running>().teleports;
    let times = std::mem::take(&mut world.resource_mut::<GarmentTimes>().0);
    let mut query = world.query::<(&Garment, &Cloth, &ClothStats)>();
    let mut garments: Vec<GarmentRun> = query
        .iter(world)
        .map(|(garment, cloth, stats)| GarmentRun {
            name: garment.name,
            method: stats.method,
            vertices: cloth.positions().len(),
            steps: stats.steps,
            step_times: times
                .iter()
                .filter(|(name, _)| *name == garment.name)
                .map(|&(_, t)| t)
                .collect(),
            max_stretch: penetrations
                .max_stretch
                .iter()
                .find(|(name, _)| *name == garment.name)
                .map_or(0.0, |&(_, s)| s),
            retried_steps: stats.retried_steps,
            finite: cloth.positions().iter().all(|p| p.is_finite()),
            status: stats.status.clone(),
        })
        .collect();
    garments.sort_by_key(|g| g.name != "cape");
    CapeRun {
        garments,
        teleports,
        penetrations,
    }
}
