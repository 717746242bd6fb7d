//! Plugin mechanics: schedule, pins, method switching, errors, guard.

use bevy::prelude::*;
use bevy_cloth::ClothMethods;
use bevy_cloth::prelude::*;

use crate::common::*;

fn system_count(app: &mut App, schedule: impl bevy::ecs::schedule::ScheduleLabel) -> usize {
    app.world_mut()
        .resource_mut::<Schedules>()
        .get(schedule)
        .unwrap()
        .systems_len()
}

fn fixed_system_count(app: &mut App) -> usize {
    system_count(app, ClothSchedule)
}

/// What ran, in order, in one fixed step.
#[derive(Resource, Default)]
struct Ran(Vec<(&'static str, f32)>);

/// A system that logs its name and the height of the lab cloth's vertex 220.
fn log(name: &'static str) -> impl FnMut(ResMut<Ran>, Query<&Cloth>) {
    move |mut ran, cloths| {
        let y = cloths
            .iter()
            .next()
            .map_or(f32::NAN, |c| c.positions()[220].y);
        ran.0.push((name, y));
    }
}

#[test]
fn the_cloth_schedule_runs_once_per_fixed_step_between_the_outer_hooks() {
    let mut app = app();
    app.init_resource::<Ran>()
        .add_systems(FixedUpdate, log("outer first").in_set(ClothSystems::First))
        .add_systems(FixedUpdate, log("outer last").in_set(ClothSystems::Last))
        .add_systems(ClothSchedule, log("first").in_set(ClothSystems::First))
        .add_systems(ClothSchedule, log("last").in_set(ClothSystems::Last));
    spawn_lab(&mut app, ImplicitSolver::default());
    // `FixedUpdate` holds the one system that runs the cloth schedule and
    // the test's own two.
    assert_eq!(system_count(&mut app, FixedUpdate), 3);
    run_steps(&mut app, 3);
    let ran = &app.world().resource::<Ran>().0;
    let names: Vec<_> = ran.iter().map(|&(n, _)| n).collect();
    assert_eq!(
        names,
        ["outer first", "first", "last", "outer last"].repeat(3)
    );
    // The step happens between `First` and `Last`, and nowhere else.
    for s in ran.chunks(4).skip(1) {
        assert_eq!(s[0].1, s[1].1);
        assert!(s[2].1 < s[1].1, "the cloth falls during the step: {s:?}");
        assert_eq!(s[2].1, s[3].1);
    }
}

#[test]
fn pinned_vertices_sit_exactly_where_their_entity_puts_them() {
    let mut app = app();
    let parent = app
        .world_mut()
        .spawn(Transform::from_xyz(0.0, 10.0, 0.0))
        .id();
    let cloth = spawn_lab(&mut app, ImplicitSolver::default());
    app.world_mut().entity_mut(cloth).insert(ChildOf(parent));
    run_steps(&mut app, 5);
    let rest = [Vec3::new(5.0, 0.0, 5.0), Vec3::new(-5.0, 0.0, 5.0)];
    for k in 0..20 {
        let local = Transform::from_xyz(k as f32, 0.5 * k as f32, 0.0)
            .with_rotation(Quat::from_rotation_y(0.1 * k as f32));
        *app.world_mut().get_mut::<Transform>(cloth).unwrap() = local;
        run_steps(&mut app, 1);
        let global = Transform::from_xyz(0.0, 10.0, 0.0).mul_transform(local);
        let x = positions(&app, cloth);
        for (pin, r) in [0, 20].into_iter().zip(rest) {
            let expected = GlobalTransform::from(global)
                .affine()
                .transform_point3a(r.into());
            assert_eq!(x[pin], expected, "pin {pin} at step {k}");
        }
    }
    // The entity moved 19 units in x: the sheet followed its pins.
    let x = positions(&app, cloth);
    assert!(x[220].x > 10.0, "{}", x[220]);
}

#[test]
fn a_new_cloth_is_placed_at_its_transform() {
    let mut app = app();
    let cloth = Cloth::build(ClothBuilder::lab()).unwrap();
    let entity = app
        .world_mut()
        .spawn((
            cloth,
            ImplicitSolver::default(),
            Transform::from_xyz(1.0, 2.0, 3.0),
        ))
        .id();
    run_steps(&mut app, 1);
    assert_eq!(positions(&app, entity)[0], Vec3A::new(6.0, 2.0, 8.0));
}

#[test]
fn an_app_with_only_pbd_runs_no_implicit_or_collision_system() {
    let mut app = app_with(PbdPlugin::default());
    let pbd = spawn_lab(&mut app, PbdSolver::default());
    let implicit = spawn_lab(&mut app, ImplicitSolver::default());
    app.world_mut().spawn((
        SphereCollider::new(2.7),
        Transform::from_xyz(0.0, -4.0, 4.0),
    ));
    run_steps(&mut app, 50);
    // Registered: the core and PBD only. Scheduled: materials, attachments
    // and the self-colliding cloths' gathering and joint pass (each run only
    // while some cloth has one), place/pin, guard, the pause bookkeeping,
    // the PBD step, the no-method diagnostic the first method plugin adds
    // and the test's step counter; nothing else.
    let methods: Vec<_> = app.world().resource::<ClothMethods>().names().collect();
    assert_eq!(methods, ["pbd"]);
    assert!(app.is_plugin_added::<ClothCorePlugin>());
    assert!(!app.is_plugin_added::<ImplicitPlugin>());
    assert!(!app.is_plugin_added::<SphereCollisionPlugin>());
    assert_eq!(fixed_system_count(&mut app), 10);
    let mut full = app_with(ClothPlugins::default());
    run_steps(&mut full, 1);
    // Core (7) + seven methods + the no-method diagnostic + sphere and shape
    // gathering and projection + wind + character cloth's skinning, inertia
    // and holding + counter (+ avian gathering and projection with the
    // `avian` feature).
    let avian = usize::from(cfg!(feature = "avian"));
    assert_eq!(fixed_system_count(&mut full), 24 + 2 * avian);
    assert_eq!(stats(&app, pbd).steps, 50);
    assert_eq!(stats(&app, pbd).contacts, 0);
    // The implicit cloth has no plugin to step it: it is placed, never moved.
    assert_eq!(stats(&app, implicit).steps, 0);
    assert_eq!(positions(&app, implicit)[440], Vec3A::new(-5.0, 0.0, -5.0));
}

#[test]
fn method_systems_do_no_work_without_their_component() {
    let mut app = app();
    let cloth = spawn_lab(&mut app, PbdSolver::default());
    // Only PBD cloths and no collider: the implicit and collision systems are
    // skipped by their run conditions, so their stats stay untouched.
    run_steps(&mut app, 3);
    let s = stats(&app, cloth);
    assert_eq!((s.method, s.steps, s.contacts), ("pbd", 3, 0));
}

#[test]
fn swapping_the_method_component_switches_the_method() {
    let mut app = app();
    let cloth = spawn_lab(&mut app, ImplicitSolver::default());
    run_steps(&mut app, 10);
    assert_eq!(stats(&app, cloth).method, "jacobi");
    app.world_mut()
        .entity_mut(cloth)
        .insert(PbdSolver::default());
    app.world_mut().flush();
    run_steps(&mut app, 10);
    let e = app.world().entity(cloth);
    assert!(e.contains::<PbdSolver>());
    assert!(!e.contains::<ImplicitSolver>(), "one method per cloth");
    let s = stats(&app, cloth);
    // A method switch starts the stats afresh.
    assert_eq!((s.method, s.steps), ("pbd", 10));
    // And back.
    app.world_mut()
        .entity_mut(cloth)
        .insert(ImplicitSolver::chebyshev(16, 0.99));
    run_steps(&mut app, 1);
    assert!(!app.world().entity(cloth).contains::<PbdSolver>());
    let s = stats(&app, cloth);
    assert_eq!((s.method, s.steps, s.iterations), ("chebyshev", 1, 16));
    // To the assignment's methods and back: one method at a time throughout.
    app.world_mut()
        .entity_mut(cloth)
        .insert(LinearImplicitSolver::direct());
    run_steps(&mut app, 1);
    assert!(!app.world().entity(cloth).contains::<ImplicitSolver>());
    assert_eq!(stats(&app, cloth).method, "linear-direct");
    app.world_mut().entity_mut(cloth).insert(SymplecticSolver);
    run_steps(&mut app, 1);
    assert!(!app.world().entity(cloth).contains::<LinearImplicitSolver>());
    assert_eq!(stats(&app, cloth).method, "symplectic");
}

#[test]
fn invalid_parameters_skip_the_cloth_until_fixed() {
    let mut app = app();
    let cloth = spawn_lab(&mut app, ImplicitSolver::default());
    run_steps(&mut app, 2);
    let before = positions(&app, cloth);
    app.world_mut()
        .get_mut::<ClothParams>(cloth)
        .unwrap()
        .damping = 2.0;
    run_steps(&mut app, 3);
    let s = stats(&app, cloth);
    assert_eq!(
        s.status,
        ClothStatus::Invalid(ParamError::Damping(2.0).into())
    );
    assert_eq!(s.steps, 2);
    // Pins are re-placed each step, but nothing else moved.
    assert_eq!(positions(&app, cloth), before);
    app.world_mut()
        .get_mut::<ClothParams>(cloth)
        .unwrap()
        .damping = 0.99;
    run_steps(&mut app, 1);
    let s = stats(&app, cloth);
    assert!(s.is_running());
    assert_eq!(s.steps, 3);
}

#[test]
fn invalid_solver_settings_and_colliders_do_not_panic() {
    let mut app = app();
    let zero = spawn_lab(&mut app, ImplicitSolver::jacobi(0));
    let rho = spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 1.5));
    let ok = spawn_lab(&mut app, PbdSolver::default());
    app.world_mut().spawn((
        SphereCollider::new(f32::NAN),
        Transform::from_xyz(0.0, -4.0, 4.0),
    ));
    app.world_mut()
        .spawn((SphereCollider::new(-1.0), Transform::default()));
    run_steps(&mut app, 5);
    assert_eq!(
        stats(&app, zero).status,
        ClothStatus::Invalid(ParamError::Iterations.into())
    );
    assert_eq!(
        stats(&app, rho).status,
        ClothStatus::Invalid(ParamError::Rho(1.5).into())
    );
    assert!(stats(&app, ok).is_running());
    assert!(positions(&app, ok).iter().all(|p| p.is_finite()));
}

#[derive(Resource, Default)]
struct Diverged(Vec<ClothDiverged>);

fn collect(mut reader: MessageReader<ClothDiverged>, mut seen: ResMut<Diverged>) {
    seen.0.extend(reader.read().copied());
}

#[test]
fn a_diverging_cloth_is_stopped_restored_and_reported() {
    let mut app = app();
    app.init_resource::<Diverged>()
        .add_systems(ClothSchedule, collect.in_set(ClothSystems::Last));
    // Chebyshev with rho far above the Jacobi iteration's spectral radius at
    // k = 1e6 diverges within a few dozen steps.
    let cloth = spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 0.9999));
    app.world_mut().entity_mut(cloth).insert((
        ClothParams::default().with_stiffness(1e6),
        ClothGuard::pause(),
    ));
    let calm = spawn_lab(&mut app, ImplicitSolver::default());
    run_steps(&mut app, 60);
    let s = stats(&app, cloth);
    // The stretch bound sees the blow-up before it reaches infinity.
    assert_eq!(s.status, ClothStatus::Diverged(DivergenceReason::Stretch));
    let seen = &app.world().resource::<Diverged>().0;
    assert_eq!(seen.len(), 1, "reported once");
    assert_eq!(seen[0].entity, cloth);
    assert_eq!(seen[0].method, "chebyshev");
    assert_eq!(seen[0].action, GuardAction::Paused);
    assert_eq!(seen[0].step, s.steps);
    // Restored to its last good state, which is within the bound, and no
    // longer stepped.
    let x = positions(&app, cloth);
    assert!(x.iter().all(|p| p.is_finite()));
    let model = app.world().get::<Cloth>(cloth).unwrap().model().clone();
    assert!(bevy_cloth::solver::max_stretch(&model, &x) <= 10.0);
    run_steps(&mut app, 5);
    assert_eq!(stats(&app, cloth).steps, s.steps);
    assert_eq!(positions(&app, cloth)[100], x[100]);
    // The other cloth is unaffected.
    assert_eq!(stats(&app, calm).steps, 65);
    assert!(stats(&app, calm).is_running());
}

#[test]
fn past_the_explicit_limit_the_guard_retries_with_halved_steps() {
    // The lab's dt is four times symplectic Euler's limit on the lab cloth
    // (about 0.0085 s): under the default policy every step is undone and
    // retried with halved steps, and the cloth hangs as it should.
    let mut app = app();
    app.init_resource::<Diverged>()
        .add_systems(ClothSchedule, collect.in_set(ClothSystems::Last));
    let cloth = spawn_lab(&mut app, SymplecticSolver);
    let paused = spawn_lab(&mut app, SymplecticSolver);
    app.world_mut()
        .entity_mut(paused)
        .insert(ClothGuard::pause());
    run_steps(&mut app, 100);
    let s = stats(&app, cloth);
    assert!(s.is_running(), "{:?}", s.status);
    assert_eq!(s.steps, 100);
    assert!(s.retried_steps > 0 && s.substeps >= 4, "{s:?}");
    assert!(s.max_stretch < 0.5, "{}", s.max_stretch);
    let seen = &app.world().resource::<Diverged>().0;
    let recovered = seen.iter().filter(|d| d.entity == cloth).count() as u64;
    assert_eq!(recovered, s.retried_steps);
    assert!(seen.iter().filter(|d| d.entity == cloth).all(|d| matches!(
        d.action,
        GuardAction::Recovered { substeps } if substeps >= 4
    )));
    // The same cloth under the pause policy stops.
    assert!(matches!(
        stats(&app, paused).status,
        ClothStatus::Diverged(_)
    ));
}

#[test]
fn the_same_scene_gives_bitwise_identical_results() {
    let run = || {
        let mut app = app();
        let cloths: Vec<Entity> = (0..4)
            .map(|k| {
                let e = spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 0.995));
                app.world_mut()
                    .get_mut::<Transform>(e)
                    .unwrap()
                    .translation
                    .x = 12.0 * k as f32;
                e
            })
            .collect();
        app.world_mut().spawn((
            SphereCollider::new(2.7),
            Transform::from_xyz(0.0, -4.0, 4.0),
        ));
        run_steps(&mut app, 60);
        cloths
            .iter()
            .map(|&c| positions(&app, c))
            .collect::<Vec<_>>()
    };
    assert_eq!(run(), run());
}

#[test]
fn components_are_reflected_and_registered() {
    let app = app();
    let registry = app.world().resource::<AppTypeRegistry>().read();
    for path in [
        "bevy_cloth::ecs::components::Cloth",
        "bevy_cloth::ecs::components::ClothParams",
        "bevy_cloth::ecs::components::ClothStats",
        "bevy_cloth::solver::implicit::ImplicitSolver",
        "bevy_cloth::solver::pbd::PbdSolver",
        "bevy_cloth::ecs::collision::SphereCollider",
    ] {
        let registration = registry
            .get_with_type_path(path)
            .unwrap_or_else(|| panic!("{path} is not registered"));
        assert!(
            registration
                .data::<bevy::ecs::reflect::ReflectComponent>()
                .is_some(),
            "{path} does not reflect Component"
        );
    }
}

#[test]
fn the_cloth_systems_have_no_ambiguities() {
    use bevy::ecs::schedule::{LogLevel, ScheduleBuildSettings};
    let mut app = app();
    app.edit_schedule(FixedUpdate, |schedule| {
        schedule.set_build_settings(ScheduleBuildSettings {
            ambiguity_detection: LogLevel::Error,
            ..default()
        });
    });
    spawn_lab(&mut app, ImplicitSolver::default());
    spawn_lab(&mut app, PbdSolver::default());
    app.world_mut()
        .spawn((SphereCollider::new(2.7), Transform::default()));
    // Building the schedule with ambiguities reported as errors panics if any.
    run_steps(&mut app, 2);
}

#[test]
fn pausing_stops_every_cloth_and_single_steps_run_one_step() {
    let mut app = app();
    let cloth = spawn_lab(&mut app, ImplicitSolver::default());
    run_steps(&mut app, 3);
    app.world_mut().resource_mut::<ClothSimulation>().paused = true;
    run_steps(&mut app, 5);
    assert_eq!(stats(&app, cloth).steps, 3);
    let frozen = positions(&app, cloth);
    app.world_mut()
        .resource_mut::<ClothSimulation>()
        .step_once();
    run_steps(&mut app, 4);
    assert_eq!(stats(&app, cloth).steps, 4);
    assert_ne!(positions(&app, cloth), frozen);
    app.world_mut().resource_mut::<ClothSimulation>().paused = false;
    run_steps(&mut app, 2);
    assert_eq!(stats(&app, cloth).steps, 6);
}

#[test]
fn teleporting_the_cloth_entity_and_the_sphere_never_lets_a_nan_out() {
    let mut app = app();
    let cloths = spawn_every_preset(&mut app, &ClothBuilder::lab());
    let sphere = app
        .world_mut()
        .spawn((
            SphereCollider::new(2.7),
            Transform::from_xyz(0.0, -30.0, 0.0),
        ))
        .id();
    run_steps(&mut app, 20);
    // The pinned entity jumps 100 units; the sphere jumps into the sheet.
    for &(_, e) in &cloths {
        app.world_mut()
            .get_mut::<Transform>(e)
            .unwrap()
            .translation
            .x += 100.0;
    }
    app.world_mut()
        .get_mut::<Transform>(sphere)
        .unwrap()
        .translation = Vec3::new(100.0, -3.0, 2.0);
    run_steps(&mut app, 40);
    for (m, e) in cloths {
        let s = stats(&app, e);
        let x = positions(&app, e);
        assert!(x.iter().all(|p| p.is_finite()), "{}", m.name());
        assert!(
            s.is_running() || matches!(s.status, ClothStatus::Diverged(_)),
            "{}: {:?}",
            m.name(),
            s.status
        );
        if s.is_running() {
            // The pins followed the entity exactly.
            assert_eq!(x[0], Vec3A::new(105.0, 0.0, 5.0), "{}", m.name());
        }
    }
}

#[test]
fn projective_dynamics_refactorises_when_k_changes_live_and_follows_moving_pins() {
    // The direct solve (the lab's size) and the multigrid (larger cloths).
    for global in [GlobalSolve::Auto, GlobalSolve::Multigrid { cycles: 1 }] {
        projective_dynamics_follows_k_and_pins_with(global);
    }
}

fn projective_dynamics_follows_k_and_pins_with(global: GlobalSolve) {
    use bevy_cloth::ClothWorkspace;
    use bevy_cloth::solver::projective::ProjectiveWorkspace;
    let mut app = app();
    let cloth = spawn_lab(&mut app, ProjectiveSolver::default().with_global(global));
    run_steps(&mut app, 5);
    let factorizations = |app: &App| {
        app.world()
            .get::<ClothWorkspace<ProjectiveWorkspace>>(cloth)
            .unwrap()
            .solver
            .factorizations()
    };
    assert_eq!(factorizations(&app), 1);
    assert_eq!(stats(&app, cloth).method, "pd");
    // Moving the entity moves the pins: no refactorisation, pins exact.
    app.world_mut()
        .get_mut::<Transform>(cloth)
        .unwrap()
        .translation
        .x += 1.0;
    run_steps(&mut app, 2);
    assert_eq!(factorizations(&app), 1);
    assert_eq!(positions(&app, cloth)[0], Vec3A::new(6.0, 0.0, 5.0));
    // Stiffer springs through ClothParams: the next step refactorises and
    // the sheet stretches less than before.
    let soft = stats(&app, cloth).max_stretch;
    app.world_mut()
        .get_mut::<ClothParams>(cloth)
        .unwrap()
        .stiffness = SpringStiffness::uniform(1e6);
    run_steps(&mut app, 30);
    assert_eq!(factorizations(&app), 2);
    let s = stats(&app, cloth);
    assert!(s.is_running(), "{:?}", s.status);
    assert!(
        s.max_stretch < soft / 5.0,
        "{global:?}: {} vs {soft}",
        s.max_stretch
    );
}

/// The stats are measured once per step (the guard's check after the method
/// step is reused by the check after collision) but always describe the
/// state the frame ends with, after collision moved it.
#[test]
fn stats_measure_the_state_after_collision() {
    for collider in [
        SphereCollider::new(2.7),
        SphereCollider::penalty(2.7, 5000.0),
    ] {
        let mut app = app();
        let cloth = spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 0.995));
        app.world_mut()
            .spawn((collider, Transform::from_xyz(0.0, -3.0, 4.0)));
        let mut touched = 0;
        for _ in 0..60 {
            run_steps(&mut app, 1);
            let s = stats(&app, cloth);
            touched = touched.max(s.contacts);
            let c = app.world().get::<Cloth>(cloth).unwrap();
            let params = app
                .world()
                .get::<ClothParams>(cloth)
                .unwrap()
                .step_params(DT);
            let measured = bevy_cloth::solver::measure(c.model(), c.state(), &params).unwrap();
            assert_eq!(s.max_stretch, measured.max_stretch);
            assert_eq!(s.energy, measured.energy);
        }
        assert!(touched > 10, "{collider:?}: only {touched} contacts");
    }
}

/// Moves every cloth entity 0.1 along x per frame, in `Update`.
fn walk(mut cloths: Query<&mut Transform, With<Cloth>>) {
    for mut transform in &mut cloths {
        transform.translation.x += 0.1;
    }
}

#[test]
fn a_pin_moved_in_update_steps_with_its_velocity() {
    // The follow after `Update` puts the pins in place before the next
    // fixed step: their velocity there is still their motion since the
    // last step, which `stiff` spreads over its substeps.
    let mut app = app_with((ClothPlugins::default(), TransformPlugin));
    let cloth = spawn_lab(&mut app, XpbdSolver::default());
    app.add_systems(Update, walk);
    run_steps(&mut app, 10);
    let world = app.world();
    let state = world.get::<Cloth>(cloth).unwrap().state();
    for pin in [0, 20] {
        let v = state.velocities[pin];
        assert!(
            (v.x - 0.1 / DT as f32).abs() < 1e-3 && v.y == 0.0 && v.z == 0.0,
            "pin {pin}: {v}"
        );
    }
    // The cloth came along, without a jump at its pins.
    assert!(state.positions[220].x > 0.1, "{}", state.positions[220]);
    let stats = world.get::<ClothStats>(cloth).unwrap();
    assert!(stats.is_running() && stats.max_stretch < 0.5, "{stats:?}");
}
