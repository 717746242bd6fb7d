//! The API driven by random sequences of calls: spawns, despawns, parameter,
//! material and method changes (valid and invalid, NaN included),
//! colliders, attachments, snapshots, hand edits and time-step changes.
//! After every frame: no panic, every cloth's positions and every
//! `Transform` finite.

use std::time::Duration;

use bevy::prelude::*;
use bevy::time::TimeUpdateStrategy;
use bevy_cloth::prelude::*;

/// A small deterministic generator (xorshift64*): the same seed, the same
/// sequence, on every machine.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[self.below(items.len())]
    }

    fn chance(&mut self, one_in: usize) -> bool {
        self.below(one_in) == 0
    }
}

/// Values for a stiffness, density, friction or radius: good and bad.
const NUMBERS: [f32; 10] = [
    f32::NAN,
    f32::INFINITY,
    -1.0,
    0.0,
    1e-3,
    0.3,
    10.0,
    8000.0,
    1e6,
    1e9,
];

/// Fixed steps run so far.
#[derive(Resource, Default)]
struct Steps(u64);

fn count(mut steps: ResMut<Steps>) {
    steps.0 += 1;
}

fn app() -> App {
    let mut app = App::new();
    app.add_plugins((MinimalPlugins, TransformPlugin, ClothPlugins::default()))
        .init_resource::<Steps>()
        .add_systems(FixedUpdate, count.in_set(ClothSystems::Last))
        .insert_resource(Time::<Fixed>::from_seconds(1.0 / 60.0))
        .insert_resource(TimeUpdateStrategy::ManualDuration(Duration::from_secs_f64(
            1.0 / 60.0,
        )));
    app.finish();
    app.cleanup();
    app
}

/// One random action on the app's world; says which.
fn act(app: &mut App, rng: &mut Rng) -> usize {
    let world = app.world_mut();
    let cloths: Vec<Entity> = world
        .query_filtered::<Entity, With<Cloth>>()
        .iter(world)
        .collect();
    let others: Vec<Entity> = world
        .query_filtered::<Entity, (With<Transform>, Without<Cloth>)>()
        .iter(world)
        .collect();
    let cloth = (!cloths.is_empty()).then(|| rng.pick(&cloths));
    let action = rng.below(17);
    match action {
        0 | 1 => {
            // A new cloth: a grid of 2..8 per side, random pins, perhaps a
            // material and a method.
            let n = 2 + rng.below(7);
            let pins: Vec<u32> = (0..rng.below(4))
                .map(|_| rng.below(n * n + 1) as u32)
                .collect();
            let mut builder = ClothBuilder::lab_grid(n).with_pins(pins);
            if rng.chance(3) {
                builder = builder.with_areal_density(rng.pick(&NUMBERS));
            }
            let Ok(cloth) = Cloth::build(builder) else {
                return action;
            };
            let at = Transform::from_xyz(rng.below(5) as f32, rng.below(5) as f32, 0.0);
            let mut entity = world.spawn((cloth, at));
            if rng.chance(3) {
                entity.insert(ClothMaterial {
                    stretch: rng.pick(&NUMBERS),
                    shear: rng.pick(&NUMBERS),
                    bend: rng.pick(&NUMBERS),
                    density: rng.pick(&NUMBERS),
                });
            }
            if !rng.chance(5) {
                PRESETS[rng.below(PRESETS.len())]
                    .method
                    .insert_now(&mut entity);
            }
        }
        2 => {
            if let Some(e) = cloth.or_else(|| others.first().copied()) {
                world.despawn(e);
            }
        }
        3 => {
            if let Some(e) = cloth {
                let mut params = ClothParams::default().with_stiffness(rng.pick(&NUMBERS));
                if rng.chance(3) {
                    params.damping = rng.pick(&[f32::NAN, 1.5, 0.99, 1.0, 0.0]);
                }
                if rng.chance(4) {
                    params.gravity.y = rng.pick(&[f32::NAN, -9.8, -1e4, 0.0]);
                }
                if rng.chance(4) {
                    params.particle_radius = rng.pick(&NUMBERS);
                }
                world.entity_mut(e).insert(params);
            }
        }
        4 => {
            if let Some(e) = cloth {
                let preset = PRESETS[rng.below(PRESETS.len())].method;
                preset.insert_now(&mut world.entity_mut(e));
            }
        }
        5 => {
            // A collider of any kind, with good or bad parameters.
            let at = Transform::from_xyz(
                rng.below(7) as f32 - 3.0,
                -(rng.below(5) as f32),
                rng.below(7) as f32 - 3.0,
            );
            let number = rng.pick(&NUMBERS);
            match rng.below(6) {
                0 => world.spawn((SphereCollider::new(number.abs().min(4.0)), at)),
                1 => world.spawn((SphereCollider::penalty(1.5, number), at)),
                2 => world.spawn((PlaneCollider::new(number), at)),
                3 => world.spawn((CapsuleCollider::new(0.5, number), at)),
                4 => world.spawn((CuboidCollider::new(Vec3::splat(number)), at)),
                _ => world.spawn((CuboidCollider::new(Vec3::ONE).with_penalty(number), at)),
            };
        }
        6 => {
            // Move anything, by a little or by a teleport.
            let all: Vec<Entity> = cloths.iter().chain(&others).copied().collect();
            if !all.is_empty() {
                let e = rng.pick(&all);
                let jump = rng.pick(&[0.05, 1.0, 1e3]);
                if let Some(mut t) = world.get_mut::<Transform>(e) {
                    t.translation.x += jump;
                    t.rotate_y(0.3);
                }
            }
        }
        7 => {
            // Attach a few vertices to some entity (perhaps one that is
            // despawned later), or detach.
            if let Some(e) = cloth {
                let target = rng.pick(&[others.first().copied(), cloths.first().copied()]);
                let Some(target) = target else {
                    return action;
                };
                let vertices: Vec<u32> = (0..1 + rng.below(3))
                    .map(|_| rng.below(80) as u32)
                    .collect();
                world
                    .entity_mut(e)
                    .insert(ClothAttachments::new([Attachment::new(target, vertices)]));
            }
        }
        8 => {
            // A snapshot of one cloth into another (often another size).
            if let (Some(a), Some(b)) = (cloth, cloth.map(|_| rng.pick(&cloths))) {
                let snapshot = world.get::<Cloth>(a).unwrap().snapshot();
                let mut snapshot = snapshot;
                if rng.chance(3) && !snapshot.velocities.is_empty() {
                    snapshot.velocities[0][0] = f32::NAN;
                }
                let _ = world
                    .get_mut::<Cloth>(b)
                    .unwrap()
                    .restore_snapshot(&snapshot);
            }
        }
        9 => {
            // Hand edits: a vertex teleported, or NaN written in.
            if let Some(e) = cloth {
                let mut cloth = world.get_mut::<Cloth>(e).unwrap();
                let state = cloth.state_mut();
                let i = rng.below(state.positions.len());
                state.positions[i].y += rng.pick(&[0.5, 50.0, f32::NAN]);
            }
        }
        10 => {
            let step = rng.pick(&[1e-4, 1.0 / 120.0, 1.0 / 60.0, 1.0 / 30.0, 0.1, 0.25]);
            world.insert_resource(Time::<Fixed>::from_seconds(step));
        }
        11 => {
            if let Some(e) = cloth {
                let guard = rng.pick(&[
                    ClothGuard::default(),
                    ClothGuard::pause(),
                    ClothGuard::retry(0),
                    ClothGuard::retry(8),
                    ClothGuard::default().with_convergence_tolerance(f32::NAN),
                ]);
                world.entity_mut(e).insert(guard);
            }
        }
        12 => {
            if let Some(e) = cloth {
                if let Some(mut stats) = world.get_mut::<ClothStats>(e) {
                    stats.resume();
                }
                if rng.chance(2) {
                    world.get_mut::<Cloth>(e).unwrap().reset();
                }
            }
        }
        13 => {
            // Inertia: any scales and teleport distance, anchored to the
            // cloth or to any other entity (which may be despawned later).
            if let Some(e) = cloth {
                let mut inertia = ClothInertia::default()
                    .with_scales(rng.pick(&NUMBERS), rng.pick(&NUMBERS))
                    .with_teleport(rng.pick(&NUMBERS));
                if !others.is_empty() && rng.chance(2) {
                    inertia = inertia.with_anchor(rng.pick(&others));
                }
                world.entity_mut(e).insert(inertia);
            }
        }
        14 => {
            // A skin on where the cloth is now, with any constraints (or a
            // list of the wrong length).
            if let Some(e) = cloth {
                let x = world.get::<Cloth>(e).unwrap().positions().to_vec();
                let n = x.len() + usize::from(rng.chance(8));
                let pose = SkinPose {
                    normals: vec![Vec3A::Y; x.len()],
                    positions: x,
                };
                let (r, d) = (rng.pick(&NUMBERS), rng.pick(&NUMBERS));
                let constraints = SkinConstraints::free(n)
                    .with_max_distance(|_| r)
                    .with_backstop(rng.pick(&NUMBERS), |_| d)
                    .with_drive(rng.pick(&NUMBERS))
                    .with_tethers(rng.pick(&NUMBERS));
                world
                    .entity_mut(e)
                    .insert(ClothSkin::new(constraints, pose));
            }
        }
        15 => {
            // Self-collision: the cloth's own setting, or any thickness and
            // friction.
            if let Some(e) = cloth {
                let sc = if rng.chance(2) {
                    SelfCollision::for_model(world.get::<Cloth>(e).unwrap().model())
                } else {
                    SelfCollision {
                        thickness: rng.pick(&NUMBERS),
                        friction: rng.pick(&NUMBERS),
                    }
                };
                world.entity_mut(e).insert(sc);
            }
        }
        _ => {
            world.insert_resource(Wind::new(Vec3::new(rng.pick(&NUMBERS), 0.0, 3.0)));
        }
    }
    action
}

/// After a frame: if a fixed step ran, every running cloth is finite (a NaN
/// written by hand stays in the state until the next step, whose guard
/// stops the cloth; the mesh write-back skips a state that is not finite),
/// and every transform is finite.
fn check(app: &mut App, seed: u64, frame: usize, log: &[usize], stepped: bool) {
    let world = app.world_mut();
    for (cloth, stats) in world.query::<(&Cloth, &ClothStats)>().iter(world) {
        if stepped && stats.is_running() && stats.steps > 0 {
            assert!(
                cloth.positions().iter().all(|x| x.is_finite()),
                "seed {seed}, frame {frame}: a running cloth is not finite ({:?}); actions {log:?}",
                stats.status
            );
        }
    }
    for transform in world.query::<&Transform>().iter(world) {
        assert!(
            transform.translation.is_finite() && transform.rotation.is_finite(),
            "seed {seed}, frame {frame}: {transform:?}"
        );
    }
}

/// `sequences` random sequences of `frames` frames each, from `seed` on.
fn fuzz(seed: u64, sequences: u64, frames: usize) {
    for s in seed..seed + sequences {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ (s + 1).wrapping_mul(0xD1B5_4A32_D192_ED03));
        let mut app = app();
        let mut log = Vec::new();
        for frame in 0..frames {
            for _ in 0..rng.below(3) {
                log.push(act(&mut app, &mut rng));
            }
            log.push(99);
            let before = app.world().resource::<Steps>().0;
            app.update();
            let stepped = app.world().resource::<Steps>().0 > before;
            check(&mut app, s, frame, &log, stepped);
        }
    }
}

#[test]
fn random_sequences_of_calls_never_panic_or_let_a_nan_out() {
    fuzz(0, 300, 40);
}

/// The long run: `cargo test --release --test integration -- --ignored fuzz`.
#[test]
#[ignore = "long: about 100 000 frames"]
fn random_sequences_of_calls_long() {
    fuzz(1_000_000, 2500, 40);
}
