//! With the `avian` feature: cloths collide with avian colliders already in
//! the scene, no extra component.

use avian3d::prelude::{Collider, Friction, Sensor};
use bevy::math::Vec3A;
use bevy::prelude::*;
use bevy_cloth::prelude::*;

use crate::common::{app, positions, run_steps, stats};

#[test]
fn a_cloth_falls_onto_an_avian_cuboid_and_rests_on_it() {
    let mut app = app();
    // A 6×1×6 box with its top at y = −2.5, an avian half-space ground at
    // y = −6, and a sensor the cloth must fall through.
    app.world_mut().spawn((
        Collider::cuboid(6.0, 1.0, 6.0),
        Transform::from_xyz(0.0, -3.0, 0.0),
    ));
    app.world_mut().spawn((
        Collider::half_space(Vec3::Y),
        Friction::new(0.8),
        Transform::from_xyz(0.0, -6.0, 0.0),
    ));
    app.world_mut().spawn((
        Collider::sphere(1.0),
        Sensor,
        Transform::from_xyz(0.0, -1.0, 0.0),
    ));
    let cloth = app
        .world_mut()
        .spawn((
            Cloth::build(ClothBuilder::lab_grid(11)).unwrap(),
            ProjectiveSolver::default(),
            Transform::default(),
        ))
        .id();
    run_steps(&mut app, 150);
    let x = positions(&app, cloth);
    assert!(x.iter().all(|p| p.is_finite()));
    for p in &x {
        let inside_box = p.x.abs() < 3.0 - 1e-3
            && p.z.abs() < 3.0 - 1e-3
            && p.y < -2.5 - 1e-3
            && p.y > -3.5 + 1e-3;
        assert!(!inside_box, "a vertex inside the box: {p}");
        assert!(p.y >= -6.0 - 1e-4, "a vertex under the ground: {p}");
    }
    // The middle of the sheet rests on the box top; its rim hangs over.
    let centre = x[60];
    assert!((centre.y + 2.5).abs() < 0.05, "centre {centre}");
    assert!(
        x.iter().any(|p| p.y < -3.0),
        "the rim drapes over the edges"
    );
    let s = stats(&app, cloth);
    assert!(s.contacts > 0 && s.is_running(), "{s:?}");
    // At rest on top: the part on the box does not slide off.
    let on_top: Vec<usize> = (0..x.len())
        .filter(|&i| (x[i].y + 2.5).abs() < 0.05)
        .collect();
    assert!(on_top.len() > 20, "{} vertices on the box", on_top.len());
    run_steps(&mut app, 30);
    let after = positions(&app, cloth);
    let moved = on_top
        .iter()
        .map(|&i| (after[i] - x[i]).length())
        .fold(0.0, f32::max);
    assert!(moved < 0.05, "the part on the box moved by {moved}");
}

#[test]
fn stiff_cloth_keeps_its_length_over_an_avian_box_with_the_contacts_in_the_implicit_objectives() {
    // Issue M, item 2, with avian's colliders: the lab cloth at k = 1e6
    // swings over the edge of an avian box (12×2×4, top at y = −4) and
    // rests on it; pd, pd-anderson and newton take the box as a term of
    // their objective, and stiff projects it inside its substeps, so it
    // keeps about its length and stays outside.
    for preset in ["pd", "pd-anderson", "newton", "stiff"] {
        let mut app = app();
        app.world_mut().spawn((
            Collider::cuboid(12.0, 2.0, 4.0),
            Transform::from_xyz(0.0, -5.0, 4.0),
        ));
        let cloth = app
            .world_mut()
            .spawn((
                Cloth::build(ClothBuilder::lab()).unwrap(),
                ClothParams::default().with_stiffness(1e6),
                Transform::default(),
            ))
            .id();
        let method: AnyMethod = preset.parse().unwrap();
        method.insert(&mut app.world_mut().commands().entity(cloth));
        run_steps(&mut app, 150);
        let s = stats(&app, cloth);
        assert!(s.is_running() && s.contacts > 0, "{preset}: {s:?}");
        assert!(s.max_stretch < 0.02, "{preset} stretched {}", s.max_stretch);
        for p in positions(&app, cloth) {
            let d = (p - Vec3A::new(0.0, -5.0, 4.0)).abs() - Vec3A::new(6.0, 1.0, 2.0);
            assert!(
                d.max_element() > -1e-3,
                "{preset}: a vertex inside the box: {p}"
            );
        }
    }
}
