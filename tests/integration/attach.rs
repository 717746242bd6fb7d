//! Pins held by other entities: follow, detach, re-attach, despawn.

use bevy::prelude::*;
use bevy_cloth::prelude::*;

use crate::common::{app, positions, run_steps, stats};

/// Moves every `Mover` by its velocity each fixed step, before the cloths.
#[derive(Component)]
struct Mover(Vec3);

fn move_movers(time: Res<Time>, mut movers: Query<(&mut Transform, &Mover)>) {
    for (mut t, m) in &mut movers {
        t.translation += m.0 * time.delta_secs();
    }
}

struct Scene {
    app: App,
    cloth: Entity,
    left: Entity,
    right: Entity,
}

/// An 11×11 cloth with no pins of its own whose corners 0 and 10 are held
/// by two entities moving apart along x and up.
fn scene(method: &AnyMethod) -> Scene {
    let mut app = app();
    app.add_systems(FixedUpdate, move_movers.in_set(ClothSystems::First));
    let left = app
        .world_mut()
        .spawn((Transform::default(), Mover(Vec3::new(0.5, 0.2, 0.0))))
        .id();
    let right = app
        .world_mut()
        .spawn((Transform::default(), Mover(Vec3::new(-0.5, 0.2, 0.0))))
        .id();
    let cloth = app
        .world_mut()
        .spawn((
            Cloth::build(ClothBuilder::lab_grid(11)).unwrap(),
            Transform::default(),
            ClothAttachments::new([Attachment::new(left, [0]), Attachment::new(right, [10])]),
        ))
        .id();
    method.insert(&mut app.world_mut().commands().entity(cloth));
    Scene {
        app,
        cloth,
        left,
        right,
    }
}

fn held_at(app: &App, target: Entity, rest: Vec3) -> Vec3A {
    let t = app.world().get::<Transform>(target).unwrap();
    Vec3A::from(t.transform_point(rest))
}

#[test]
fn vertices_held_by_two_moving_entities_follow_them_under_every_kind_of_method() {
    for name in ["chebyshev", "pbd", "linear-direct", "pd", "exact"] {
        let mut s = scene(&name.parse().unwrap());
        run_steps(&mut s.app, 30);
        let x = positions(&s.app, s.cloth);
        assert!(stats(&s.app, s.cloth).is_running(), "{name}");
        // Vertex 0 rests at (5, 0, 5), vertex 10 at (−5, 0, 5), placed by
        // their targets.
        assert_eq!(
            x[0],
            held_at(&s.app, s.left, Vec3::new(5.0, 0.0, 5.0)),
            "{name}"
        );
        assert_eq!(
            x[10],
            held_at(&s.app, s.right, Vec3::new(-5.0, 0.0, 5.0)),
            "{name}"
        );
        assert!(x[0].y > 0.1, "{name}: the targets rose");
        // The rest of the sheet hangs from them.
        assert!(x[120].y < -3.0, "{name}: {}", x[120]);
    }
}

#[test]
fn detached_vertices_fall_and_reattached_ones_come_back() {
    let mut s = scene(&"pd".parse().unwrap());
    run_steps(&mut s.app, 10);
    let left = s.left;
    let detached = s
        .app
        .world_mut()
        .get_mut::<ClothAttachments>(s.cloth)
        .unwrap()
        .detach(left);
    assert!(detached);
    run_steps(&mut s.app, 15);
    let held = held_at(&s.app, s.left, Vec3::new(5.0, 0.0, 5.0));
    let x = positions(&s.app, s.cloth);
    assert!(x[0].y < held.y - 1.0, "vertex 0 fell: {} vs {held}", x[0]);
    assert_eq!(x[10], held_at(&s.app, s.right, Vec3::new(-5.0, 0.0, 5.0)));
    // Re-attached with an offset: held 1 unit above the target's place.
    s.app
        .world_mut()
        .get_mut::<ClothAttachments>(s.cloth)
        .unwrap()
        .attach(Attachment::new(left, [0]).with_offset(Transform::from_xyz(0.0, 1.0, 0.0)));
    run_steps(&mut s.app, 3);
    let x = positions(&s.app, s.cloth);
    assert_eq!(x[0], held_at(&s.app, s.left, Vec3::new(5.0, 1.0, 5.0)));
    assert!(x.iter().all(|p| p.is_finite()));
    assert!(stats(&s.app, s.cloth).is_running());
}

#[test]
fn a_despawned_target_releases_its_vertices_not_a_panic() {
    let mut s = scene(&"chebyshev".parse().unwrap());
    run_steps(&mut s.app, 5);
    s.app.world_mut().despawn(s.right);
    run_steps(&mut s.app, 20);
    let attachments = s.app.world().get::<ClothAttachments>(s.cloth).unwrap();
    assert_eq!(attachments.0.len(), 1, "the dead attachment is removed");
    assert_eq!(attachments.0[0].target, s.left);
    let x = positions(&s.app, s.cloth);
    assert!(x.iter().all(|p| p.is_finite()));
    // Vertex 10 swings down from where it was let go.
    assert!(x[10].y < -1.0, "{}", x[10]);
    assert_eq!(x[0], held_at(&s.app, s.left, Vec3::new(5.0, 0.0, 5.0)));
    assert!(stats(&s.app, s.cloth).is_running());
}

#[test]
fn an_attachment_out_of_range_is_skipped_and_a_shared_vertex_goes_to_the_first() {
    let mut app = app();
    let a = app
        .world_mut()
        .spawn(Transform::from_xyz(0.0, 1.0, 0.0))
        .id();
    let b = app
        .world_mut()
        .spawn(Transform::from_xyz(0.0, 9.0, 0.0))
        .id();
    let cloth = app
        .world_mut()
        .spawn((
            Cloth::build(ClothBuilder::lab_grid(11)).unwrap(),
            ProjectiveSolver::default(),
            ClothAttachments::new([
                Attachment::new(a, [0, 10]),
                Attachment::new(b, [10, 5000]),
                Attachment::new(b, [10]),
            ]),
        ))
        .id();
    run_steps(&mut app, 10);
    let x = positions(&app, cloth);
    assert!(x.iter().all(|p| p.is_finite()));
    assert!(stats(&app, cloth).is_running());
    assert_eq!(
        x[10],
        Vec3A::new(-5.0, 1.0, 5.0),
        "the first attachment holds it"
    );
    assert_eq!(x[0], Vec3A::new(5.0, 1.0, 5.0));
}

#[test]
fn own_pins_and_held_vertices_together() {
    // The lab cloth keeps its own pin 0 on its entity; vertex 20 (its other
    // own pin) is handed to another entity, and given back on detach.
    let mut app = app();
    let hand = app
        .world_mut()
        .spawn(Transform::from_xyz(0.0, 3.0, 0.0))
        .id();
    let cloth = app
        .world_mut()
        .spawn((
            Cloth::build(ClothBuilder::lab()).unwrap(),
            ImplicitSolver::chebyshev_auto(32),
            ClothAttachments::new([Attachment::new(hand, [20])]),
        ))
        .id();
    run_steps(&mut app, 5);
    let x = positions(&app, cloth);
    assert_eq!(x[0], Vec3A::new(5.0, 0.0, 5.0));
    assert_eq!(x[20], Vec3A::new(-5.0, 3.0, 5.0));
    app.world_mut()
        .get_mut::<ClothAttachments>(cloth)
        .unwrap()
        .detach(hand);
    run_steps(&mut app, 1);
    assert_eq!(positions(&app, cloth)[20], Vec3A::new(-5.0, 0.0, 5.0));
    app.world_mut()
        .entity_mut(cloth)
        .remove::<ClothAttachments>();
    run_steps(&mut app, 2);
    assert_eq!(positions(&app, cloth)[20], Vec3A::new(-5.0, 0.0, 5.0));
}
