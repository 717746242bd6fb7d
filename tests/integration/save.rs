//! Saving a cloth's dynamic state and loading it into a new app.

use bevy::prelude::*;
use bevy_cloth::prelude::*;

use crate::common::*;

/// Moves every cloth entity 0.05 along x per frame, in `Update`.
fn walk(mut cloths: Query<&mut Transform, With<Cloth>>) {
    for mut transform in &mut cloths {
        transform.translation.x += 0.05;
    }
}

/// `app` with the lab's sphere and a lab cloth of `preset`.
fn lab_on_sphere(mut app: App, preset: &str) -> (App, Entity) {
    app.world_mut().spawn((
        SphereCollider::new(2.7),
        Transform::from_xyz(0.0, -4.0, 4.0),
    ));
    let cloth = spawn_lab(&mut app, ());
    preset
        .parse::<AnyMethod>()
        .unwrap()
        .insert(&mut app.world_mut().commands().entity(cloth));
    (app, cloth)
}

/// An app with the lab's sphere and a walking lab cloth of `preset`.
fn scene(preset: &str) -> (App, Entity) {
    let mut app = app_with((ClothPlugins::default(), TransformPlugin));
    app.add_systems(Update, walk);
    lab_on_sphere(app, preset)
}

#[test]
fn a_restored_cloth_continues_bitwise_in_a_new_app() {
    for preset in ["stiff", "chebyshev", "pd", "newton"] {
        let (mut first, cloth) = scene(preset);
        run_steps(&mut first, 40);
        // The save file: the snapshot as JSON, and the entity's transform.
        let saved =
            serde_json::to_string(&first.world().get::<Cloth>(cloth).unwrap().snapshot()).unwrap();
        let at = *first.world().get::<Transform>(cloth).unwrap();
        run_steps(&mut first, 40);
        let expected = positions(&first, cloth);

        // The new app runs its first frame (which runs no fixed step yet)
        // before the save is loaded into it, as a game loads a save into a
        // running world; then the entity's transform and the snapshot.
        let (mut second, restored) = scene(preset);
        second.update();
        *second.world_mut().get_mut::<Transform>(restored).unwrap() = at;
        let snapshot: ClothSnapshot = serde_json::from_str(&saved).unwrap();
        second
            .world_mut()
            .get_mut::<Cloth>(restored)
            .unwrap()
            .restore_snapshot(&snapshot)
            .unwrap();
        run_steps(&mut second, 40);
        assert_eq!(positions(&second, restored), expected, "{preset}");
        assert!(stats(&second, restored).is_running());
    }
}

#[test]
fn another_cloths_snapshot_is_refused_and_the_cloth_keeps_its_state() {
    let (mut app, cloth) = scene("stiff");
    run_steps(&mut app, 5);
    let snapshot = app.world().get::<Cloth>(cloth).unwrap().snapshot();
    // The same grid with other pins.
    let other = app
        .world_mut()
        .spawn((
            Cloth::build(ClothBuilder::lab_grid(21).with_pins([0])).unwrap(),
            XpbdSolver::default(),
            Transform::default(),
        ))
        .id();
    run_steps(&mut app, 5);
    let before = app.world().get::<Cloth>(other).unwrap().state().clone();
    let mut world = app.world_mut();
    let mut target = world.get_mut::<Cloth>(other).unwrap();
    assert_eq!(
        target.restore_snapshot(&snapshot),
        Err(StepError::PinsMismatch {
            expected: 1,
            got: 2
        })
    );
    // A snapshot edited into nonsense.
    let mut broken = snapshot.clone();
    broken.pins = vec![0];
    broken.velocities[3][1] = f32::NAN;
    assert_eq!(
        target.restore_snapshot(&broken),
        Err(StepError::InvalidSnapshot)
    );
    broken.positions.pop();
    assert_eq!(
        target.restore_snapshot(&broken),
        Err(StepError::StateMismatch {
            expected: 441,
            got: 440
        })
    );
    assert_eq!(*target.state(), before);
    world = app.world_mut();
    let _ = &mut world;
    run_steps(&mut app, 2);
    assert!(stats(&app, other).is_running());
}

/// An app with the lab's sphere and a still lab cloth of `preset`.
fn still_scene(preset: &str) -> (App, Entity) {
    lab_on_sphere(app(), preset)
}

#[test]
fn a_method_switch_continues_from_the_same_positions_and_velocities() {
    // Issue R: a cloth switched from one method to another continues as a
    // fresh cloth of the new method started from the state the old one
    // left (its positions, velocities, pins and the guard's memory): no
    // jump from anything the old method carried.
    for (from, to) in [
        ("pbd", "pd"),
        ("chebyshev", "stiff"),
        ("stiff", "newton"),
        ("pd", "pbd"),
        ("newton", "chebyshev"),
    ] {
        let (mut switched, cloth) = still_scene(from);
        run_steps(&mut switched, 40);
        let state = switched.world().get::<Cloth>(cloth).unwrap().snapshot();
        to.parse::<AnyMethod>()
            .unwrap()
            .insert(&mut switched.world_mut().commands().entity(cloth));
        run_steps(&mut switched, 10);

        let (mut fresh, other) = still_scene(to);
        fresh.update();
        fresh
            .world_mut()
            .get_mut::<Cloth>(other)
            .unwrap()
            .restore_snapshot(&state)
            .unwrap();
        run_steps(&mut fresh, 10);
        assert_eq!(
            positions(&switched, cloth),
            positions(&fresh, other),
            "{from} → {to}"
        );
        assert_eq!(stats(&switched, cloth).method, to);
    }
}
