//! The assignment's methods through the plugin.

use bevy::prelude::*;
use bevy_cloth::prelude::*;

use crate::common::*;

fn spawn_assignment(app: &mut App, rows: usize, cols: usize, method: impl Bundle) -> Entity {
    let cloth = Cloth::build(ClothBuilder::assignment(rows, cols)).unwrap();
    let params = ClothParams::default()
        .with_stiffness(10.0)
        .with_damping(1.0)
        .with_particle_radius(0.01);
    app.world_mut()
        .spawn((cloth, params, method, Transform::default()))
        .id()
}

fn assignment_app(dt: f64) -> App {
    let mut app = app();
    app.insert_resource(Time::<Fixed>::from_seconds(dt));
    allow_long_steps(&mut app, dt);
    app
}

#[test]
fn symplectic_euler_is_stable_at_the_assignment_settings() {
    let mut app = assignment_app(5e-3);
    let cloth = spawn_assignment(&mut app, 2, 2, SymplecticSolver);
    run_steps(&mut app, 2000);
    let s = stats(&app, cloth);
    assert!(s.is_running(), "{:?}", s.status);
    assert_eq!(s.method, "symplectic");
    let x = positions(&app, cloth);
    assert!(x.iter().all(|p| p.is_finite()));
    // Fixed particles 0 and 1 never moved; the free row swung down.
    assert_eq!(x[0], Vec3A::new(-0.25, 0.5, 0.0));
    assert_eq!(x[1], Vec3A::new(0.25, 0.5, 0.0));
    assert!(x[2].y < 0.3 && x[3].y < 0.3);
    // A flat sheet that does not bend: stretch stays small.
    assert!(s.max_stretch < 0.1, "{}", s.max_stretch);
}

#[derive(Resource, Default)]
struct Diverged(Vec<ClothDiverged>);

fn collect(mut reader: MessageReader<ClothDiverged>, mut seen: ResMut<Diverged>) {
    seen.0.extend(reader.read().copied());
}

#[test]
fn above_its_step_limit_symplectic_euler_is_caught_and_linearly_implicit_is_not() {
    // 10×10 particles of 1e-3 kg on springs of 10 N/m: the explicit limit is
    // a few milliseconds; 0.05 s is far above it.
    let mut app = assignment_app(0.05);
    app.init_resource::<Diverged>()
        .add_systems(ClothSchedule, collect.in_set(ClothSystems::Last));
    let explicit = spawn_assignment(&mut app, 10, 10, (SymplecticSolver, ClothGuard::pause()));
    let cg = spawn_assignment(&mut app, 10, 10, LinearImplicitSolver::default());
    let direct = spawn_assignment(&mut app, 10, 10, LinearImplicitSolver::direct());
    run_steps(&mut app, 200);
    let s = stats(&app, explicit);
    assert!(
        matches!(s.status, ClothStatus::Diverged(_)),
        "{:?}",
        s.status
    );
    let seen = &app.world().resource::<Diverged>().0;
    assert_eq!(seen.len(), 1);
    assert_eq!((seen[0].entity, seen[0].method), (explicit, "symplectic"));
    assert!(positions(&app, explicit).iter().all(|p| p.is_finite()));
    for cloth in [cg, direct] {
        let s = stats(&app, cloth);
        assert!(s.is_running(), "{}: {:?}", s.method, s.status);
        assert_eq!(s.steps, 200);
        assert!(positions(&app, cloth).iter().all(|p| p.is_finite()));
        assert!(s.max_stretch < 0.5, "{}: {}", s.method, s.max_stretch);
    }
}

#[test]
fn cg_and_direct_solves_report_their_convergence() {
    let mut app = assignment_app(5e-3);
    let cg = spawn_assignment(&mut app, 10, 10, LinearImplicitSolver::default());
    let direct = spawn_assignment(&mut app, 10, 10, LinearImplicitSolver::direct());
    run_steps(&mut app, 50);
    let s = stats(&app, cg);
    assert_eq!(s.method, "linear-cg");
    assert!(s.iterations > 0 && s.iterations <= 25);
    assert!(s.residual.unwrap() < 1e-5, "{:?}", s.residual);
    let d = stats(&app, direct);
    assert_eq!((d.method, d.iterations), ("linear-direct", 0));
    assert!(d.residual.unwrap() < 1e-10);
    // Same physics: CG at 1e-6 tracks the direct solve closely.
    let worst = positions(&app, cg)
        .iter()
        .zip(positions(&app, direct))
        .map(|(a, b)| a.distance(b))
        .fold(0.0, f32::max);
    assert!(worst < 1e-3, "{worst}");
}

#[test]
fn a_penalty_sphere_holds_the_cloth_outside_it() {
    for method in [0, 1, 2] {
        let mut app = assignment_app(5e-3);
        let cloth = match method {
            0 => spawn_assignment(&mut app, 10, 10, LinearImplicitSolver::default()),
            1 => spawn_assignment(&mut app, 10, 10, LinearImplicitSolver::direct()),
            _ => spawn_assignment(&mut app, 10, 10, ImplicitSolver::default()),
        };
        // Where the cloth would hang: it drapes over the sphere instead.
        let center = Vec3::new(0.0, 0.15, -0.1);
        app.world_mut().spawn((
            SphereCollider::penalty(0.14, 100.0),
            Transform::from_translation(center),
        ));
        run_steps(&mut app, 600);
        let s = stats(&app, cloth);
        assert!(s.is_running(), "{}: {:?}", s.method, s.status);
        // Contact distance is 0.14 + the particle radius 0.01.
        let deepest = positions(&app, cloth)
            .iter()
            .map(|p| 0.15 - p.distance(center.into()))
            .fold(f32::NEG_INFINITY, f32::max);
        assert!(
            deepest > -0.01,
            "{}: not resting on the sphere ({deepest})",
            s.method
        );
        assert!(deepest < 0.02, "{}: {deepest} deep", s.method);
        // Resting on it: penalty contacts are counted like projections.
        assert!(s.contacts > 0, "{}: contacts {}", s.method, s.contacts);
    }
}
