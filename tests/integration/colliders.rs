//! Plane colliders: the ground stops a cloth, friction holds it on a slope.

use bevy::math::Vec3A;
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use std::f32::consts::FRAC_PI_2;

use crate::common::{app, positions, run_steps, spawn_every_preset, stats};

fn spawn_unpinned(app: &mut App, n: usize, at: Transform) -> Entity {
    let cloth = Cloth::build(ClothBuilder::lab_grid(n)).unwrap();
    app.world_mut()
        .spawn((cloth, ImplicitSolver::chebyshev_auto(32), at))
        .id()
}

#[test]
fn the_ground_stops_a_falling_cloth_at_its_surface() {
    let mut app = app();
    app.world_mut()
        .spawn((PlaneCollider::new(0.5), Transform::from_xyz(0.0, -2.0, 0.0)));
    let cloth = spawn_unpinned(&mut app, 11, Transform::default());
    run_steps(&mut app, 60);
    let lowest = positions(&app, cloth)
        .iter()
        .map(|p| p.y)
        .fold(f32::MAX, f32::min);
    assert!(lowest >= -2.0 - 1e-4, "a vertex below the ground: {lowest}");
    assert!(lowest < -1.99, "the cloth reached the ground: {lowest}");
    let s = stats(&app, cloth);
    assert!(s.contacts > 0 && s.is_running(), "{s:?}");
}

/// Mean displacement along the slope's downhill direction after 2 s, for a
/// cloth resting on a 20° slope with friction `mu`.
fn slide_on_a_slope(mu: f32) -> f32 {
    let mut app = app();
    let tilt = Transform::from_rotation(Quat::from_rotation_z(20f32.to_radians()));
    app.world_mut().spawn((PlaneCollider::new(mu), tilt));
    let cloth = spawn_unpinned(&mut app, 11, tilt);
    let before = positions(&app, cloth);
    run_steps(&mut app, 60);
    let after = positions(&app, cloth);
    let normal = Vec3A::from(tilt.rotation * Vec3::Y);
    let downhill = (Vec3A::NEG_Y - Vec3A::NEG_Y.dot(normal) * normal).normalize();
    for p in &after {
        assert!(normal.dot(*p) >= -1e-4, "a vertex under the slope: {p}");
    }
    after
        .iter()
        .zip(&before)
        .map(|(a, b)| (*a - *b).dot(downhill))
        .sum::<f32>()
        / after.len() as f32
}

#[test]
fn static_friction_holds_a_cloth_on_a_slope_and_none_lets_it_slide() {
    // tan 20° ≈ 0.36: μ = 0.8 holds it, μ = 0 does not.
    let held = slide_on_a_slope(0.8);
    let slid = slide_on_a_slope(0.0);
    assert!(held.abs() < 0.05, "moved {held} with μ = 0.8");
    assert!(slid > 2.0, "slid only {slid} without friction");
}

#[test]
fn a_plane_with_bad_values_is_skipped_not_a_panic() {
    let mut app = app();
    for bad in [
        PlaneCollider {
            friction: f32::NAN,
            ..default()
        },
        PlaneCollider {
            thickness: -1.0,
            ..default()
        },
        PlaneCollider::penalty(-5.0),
    ] {
        app.world_mut()
            .spawn((bad, Transform::from_xyz(0.0, -2.0, 0.0)));
    }
    let cloth = spawn_unpinned(&mut app, 11, Transform::default());
    run_steps(&mut app, 60);
    let ys: Vec<f32> = positions(&app, cloth).iter().map(|p| p.y).collect();
    assert!(ys.iter().all(|y| y.is_finite()));
    assert!(
        ys.iter().any(|&y| y < -2.5),
        "the skipped planes stopped it"
    );
    assert_eq!(stats(&app, cloth).contacts, 0);
}

/// Runs a cloth falling onto one collider for 1.5 s; returns its positions.
fn drop_onto(collider: impl Bundle) -> (Vec<Vec3A>, ClothStats) {
    let mut app = app();
    app.world_mut().spawn(collider);
    let cloth = spawn_unpinned(&mut app, 21, Transform::default());
    run_steps(&mut app, 45);
    (positions(&app, cloth), stats(&app, cloth))
}

#[test]
fn a_capsule_and_a_box_hold_the_cloth_out() {
    // A capsule lying along x, rotated from its local y, 3 below the cloth.
    let (capsule_at, radius) = (Vec3A::new(0.0, -3.0, 0.0), 1.0);
    let (xs, s) = drop_onto((
        CapsuleCollider::new(radius, 4.0),
        Transform::from_translation(capsule_at.into())
            .with_rotation(Quat::from_rotation_z(std::f32::consts::FRAC_PI_2)),
    ));
    assert!(s.contacts > 0 && s.is_running(), "{s:?}");
    for p in &xs {
        let along = p.x.clamp(-4.0, 4.0);
        let axis_point = capsule_at + Vec3A::new(along, 0.0, 0.0);
        assert!(
            p.distance(axis_point) >= radius - 1e-3,
            "{p} inside the capsule"
        );
    }
    // A box rotated 30° about y, its top 2 below the cloth.
    let half = Vec3::new(2.0, 1.0, 2.0);
    let rotation = Quat::from_rotation_y(30f32.to_radians());
    let (xs, s) = drop_onto((
        CuboidCollider::new(half),
        Transform::from_xyz(0.0, -3.0, 0.0).with_rotation(rotation),
    ));
    assert!(s.contacts > 0, "{s:?}");
    let inverse = rotation.inverse();
    let mut on_top = 0;
    for p in &xs {
        let local = inverse * (Vec3::from(*p) - Vec3::new(0.0, -3.0, 0.0));
        let inside = local.abs().cmplt(half - Vec3::splat(1e-3)).all();
        assert!(!inside, "{p} inside the box");
        on_top += usize::from(local.y > 0.99 && local.x.abs() < 2.0 && local.z.abs() < 2.0);
    }
    assert!(on_top > 10, "{on_top} vertices rest on the box's top");
}

#[test]
fn bad_capsules_and_boxes_are_skipped() {
    let (xs, s) = drop_onto((
        CapsuleCollider::new(f32::NAN, 1.0),
        CuboidCollider::new(Vec3::new(1.0, -1.0, 1.0)),
        Transform::from_xyz(0.0, -3.0, 0.0),
    ));
    assert_eq!(s.contacts, 0);
    assert!(xs.iter().all(|p| p.is_finite()));
}

#[test]
fn penalty_planes_and_boxes_hold_a_cloth_under_every_method() {
    // A penalty ground (c = 800) and a penalty box on it: the cloth falls
    // onto both inside each method's step (no projection anywhere). The
    // explicit methods need c·h²/m < 1 (here 0.9); symplectic Euler is
    // unstable at this step with the lab's springs anyway (its limit is
    // 2/ω_max), so it is only checked for NaN.
    let mut app = app();
    app.world_mut().spawn((
        PlaneCollider::penalty(800.0),
        Transform::from_xyz(0.0, -3.0, 0.0),
    ));
    app.world_mut().spawn((
        CuboidCollider::new(Vec3::new(1.5, 0.5, 1.5)).with_penalty(800.0),
        Transform::from_xyz(0.0, -2.5, 0.0),
    ));
    let cloths = spawn_every_preset(&mut app, &ClothBuilder::lab_grid(11));
    run_steps(&mut app, 60);
    let mut held = 0;
    for (p, e) in cloths {
        let s = stats(&app, e);
        let x = positions(&app, e);
        assert!(x.iter().all(|v| v.is_finite()), "{}", p.name());
        if p.name() == "symplectic" {
            continue;
        }
        assert!(s.is_running(), "{}: {:?}", p.name(), s.status);
        let lowest = x.iter().map(|v| v.y).fold(f32::MAX, f32::min);
        // Penalty contacts sink in a little (m·g/c ≈ 0.012 at rest, more
        // while landing), never through: 3.04–3.05 for the implicit methods.
        assert!(lowest > -3.0 - 0.1, "{}: lowest {lowest}", p.name());
        assert!(lowest < -2.8, "{}: reached the ground: {lowest}", p.name());
        // The middle rests on the box top (y = −2).
        let centre = x[60];
        assert!(
            (centre.y + 2.0).abs() < 0.1,
            "{}: centre {centre}",
            p.name()
        );
        assert!(s.contacts > 0, "{}", p.name());
        held += 1;
    }
    assert_eq!(held, PRESETS.len() - 1);
}

#[test]
fn no_method_gains_energy_resting_on_a_stiff_penalty_box() {
    // Issue R: at c = 1e5, c·dt²/m ≈ 110, an explicit penalty force
    // launched PBD's cloth to tens of metres. Every method now lands the
    // cloth on the box top (y = −2) and lets it rest there for ten seconds
    // without gaining energy: the implicit methods have the penalty inside
    // their solve, the position-based ones project it (the stiff method's
    // floppy cloth crumples a little on the top, up to y ≈ −1.8), and
    // symplectic Euler, explicit, is stopped or retried in substeps by the
    // guard rather than launched.
    for preset in PRESETS {
        let method = preset.method;
        let mut app = app();
        app.world_mut().spawn((
            CuboidCollider::new(Vec3::new(1.5, 0.5, 1.5)).with_penalty(1e5),
            Transform::from_xyz(0.0, -2.5, 0.0),
        ));
        let cloth = Cloth::build(ClothBuilder::lab_grid(11)).unwrap();
        let e = app.world_mut().spawn((cloth, Transform::default())).id();
        method.insert(&mut app.world_mut().commands().entity(e));
        run_steps(&mut app, 60);
        let landed = stats(&app, e).energy;
        for _ in 0..8 {
            run_steps(&mut app, 30);
            let x = positions(&app, e);
            assert!(x.iter().all(|v| v.is_finite()), "{}", method.name());
            let highest = x.iter().map(|v| v.y).fold(f32::MIN, f32::max);
            let s = stats(&app, e);
            assert!(highest < -1.5, "{} rose to {highest}", method.name());
            assert!(
                s.energy <= landed + 1e-2 * landed.abs(),
                "{}: energy {} after landing at {landed}",
                method.name(),
                s.energy
            );
        }
        let s = stats(&app, e);
        assert!(
            s.contacts > 0 || !s.is_running(),
            "{}: {s:?}",
            method.name()
        );
    }
}

/// An app with what `spawn` puts in its world and the lab cloth at
/// stiffness `k` stepped by `method`.
fn lab_cloth_over(method: AnyMethod, k: f32, spawn: impl FnOnce(&mut World)) -> (App, Entity) {
    let mut app = app();
    spawn(app.world_mut());
    let cloth = app
        .world_mut()
        .spawn((
            Cloth::build(ClothBuilder::lab()).unwrap(),
            ClothParams::default().with_stiffness(k),
            Transform::default(),
        ))
        .id();
    method.insert(&mut app.world_mut().commands().entity(cloth));
    (app, cloth)
}

/// The lab cloth at `k = 1e7` with `method`, falling onto the lab's sphere
/// for 3 s: its max stretch and how many vertices were inside the sphere
/// after any fixed step (the plugin's projection runs after the step for
/// every method; `stiff` also projects inside its substeps).
fn stiff_cloth_on_the_sphere(method: AnyMethod) -> (f32, usize) {
    stiff_cloth_on_the_sphere_at(method, 1e7, 90)
}

/// [`stiff_cloth_on_the_sphere`] at stiffness `k` for `steps` steps.
fn stiff_cloth_on_the_sphere_at(method: AnyMethod, k: f32, steps: usize) -> (f32, usize) {
    let (mut app, cloth) = lab_cloth_over(method, k, |world| {
        world.spawn((
            SphereCollider::new(2.7),
            Transform::from_xyz(0.0, -4.0, 4.0),
        ));
    });
    let mut inside = 0;
    for _ in 0..steps {
        run_steps(&mut app, 1);
        let centre = Vec3A::new(0.0, -4.0, 4.0);
        inside += positions(&app, cloth)
            .iter()
            .filter(|p| p.distance(centre) < 2.7 - 1e-3)
            .count();
    }
    let x = positions(&app, cloth);
    let model = app.world().get::<Cloth>(cloth).unwrap().model().clone();
    (bevy_cloth::solver::max_stretch(&model, &x), inside)
}

#[test]
fn stiff_cloth_on_a_sphere_keeps_its_length_with_the_contacts_inside_the_step() {
    // `stiff` projects the sphere inside its substeps, `newton` has it as a
    // penalty in its objective: neither leaves the projection after the
    // step much to do.
    let (stiff, inside) = stiff_cloth_on_the_sphere("stiff".parse().unwrap());
    assert_eq!(inside, 0);
    let (newton, inside) = stiff_cloth_on_the_sphere("newton".parse().unwrap());
    assert_eq!(inside, 0);
    assert!(stiff < 0.02, "stiff stretched {stiff}");
    assert!(newton < 0.02, "newton stretched {newton}");
    // Newton's exact implicit step without the contact, then the
    // projection after it, strains the same cloth several times more (the
    // projection moves vertices the springs cannot pull back within the
    // step).
    let without = AnyMethod::Exact(ExactSolver {
        contacts: false,
        ..ExactSolver::BUDGET
    });
    let (projected, _) = stiff_cloth_on_the_sphere(without);
    assert!(
        projected > 2.0 * newton.max(0.005),
        "{projected} against {newton}"
    );
}

#[test]
fn projective_dynamics_keeps_stiff_cloth_on_a_sphere_at_its_length_with_the_contacts_in_its_objective()
 {
    // `pd` and `pd-anderson` take the sphere as a projective penalty term
    // (`ProjectiveSolver::contacts`), as `newton` does: the projection
    // after the step has little left to do, and the cloth keeps its length
    // (k = 1e6, 10 s).
    let on_sphere = |method| stiff_cloth_on_the_sphere_at(method, 1e6, 300);
    for preset in ["pd", "pd-anderson"] {
        let (with, _) = on_sphere(preset.parse().unwrap());
        assert!(with < 0.02, "{preset} stretched {with}");
        let AnyMethod::Projective(pd) = preset.parse().unwrap() else {
            unreachable!()
        };
        let without = AnyMethod::Projective(ProjectiveSolver {
            contacts: false,
            ..pd
        });
        let (projected, _) = on_sphere(without);
        assert!(
            projected > 2.0 * with,
            "{preset}: {projected} against {with}"
        );
    }
}

#[test]
fn a_penalty_sphere_jumped_into_stiff_cloth_is_a_typed_outcome_under_every_method() {
    // Issue M, bad input: a stiff penalty sphere (c = 1e6) jumps into the
    // middle of a hanging stiff cloth (k = 1e6). Deep inside it the penalty
    // energy is not convex (its tangential term is negative), which is
    // where Newton's true Hessian fails to factorise and its line search
    // can stall. Every method ends finite, either running (Newton and the
    // exact method fall back to the projected Hessian) or stopped by the
    // guard with a reason it names; never a panic or a NaN.
    let mut app = app();
    let sphere = app
        .world_mut()
        .spawn((
            SphereCollider::penalty(1.5, 1e6),
            Transform::from_xyz(0.0, -30.0, 0.0),
        ))
        .id();
    let cloths = spawn_every_preset(&mut app, &ClothBuilder::lab_grid(11));
    for &(_, e) in &cloths {
        app.world_mut()
            .entity_mut(e)
            .insert(ClothParams::default().with_stiffness(1e6));
    }
    run_steps(&mut app, 10);
    // Centred on the Newton cloth's middle vertex.
    let newton = cloths.iter().find(|(p, _)| p.name() == "newton").unwrap().1;
    let middle = positions(&app, newton)[60];
    app.world_mut()
        .get_mut::<Transform>(sphere)
        .unwrap()
        .translation = Vec3::from(middle);
    run_steps(&mut app, 1);
    assert!(
        stats(&app, newton).contacts > 0,
        "the sphere is inside the cloth"
    );
    run_steps(&mut app, 29);
    for (p, e) in cloths {
        let s = stats(&app, e);
        let x = positions(&app, e);
        assert!(x.iter().all(|v| v.is_finite()), "{}", p.name());
        match &s.status {
            ClothStatus::Running => {}
            ClothStatus::Diverged(reason) => {
                assert!(!reason.to_string().is_empty(), "{}", p.name());
            }
            other => panic!("{}: {other:?}", p.name()),
        }
        if matches!(p.name(), "newton" | "exact") {
            assert!(s.is_running(), "{}: {s:?}", p.name());
        }
    }
}

/// The lab cloth at stiffness `k` with `method`, falling for `steps` steps
/// onto what `spawn` puts in the world: its max stretch at the end and the
/// deepest any vertex was inside `inside` (a signed depth, positive inside)
/// after any fixed step, and whether it still runs.
fn stiff_cloth_onto(
    method: AnyMethod,
    k: f32,
    steps: usize,
    spawn: impl Fn(&mut World),
    inside: impl Fn(Vec3A) -> f32,
) -> (f32, f32, bool) {
    let (mut app, cloth) = lab_cloth_over(method, k, spawn);
    let mut deepest = f32::MIN;
    for _ in 0..steps {
        run_steps(&mut app, 1);
        let x = positions(&app, cloth);
        deepest = x.iter().map(|&p| inside(p)).fold(deepest, f32::max);
    }
    let running = stats(&app, cloth).is_running();
    let x = positions(&app, cloth);
    let model = app.world().get::<Cloth>(cloth).unwrap().model().clone();
    (
        bevy_cloth::solver::max_stretch(&model, &x),
        deepest,
        running,
    )
}

#[test]
fn the_implicit_methods_keep_stiff_cloth_at_its_length_on_a_capsule_and_a_box_with_contacts_in_their_objective()
 {
    // Issue M, item 2: a capsule (a log lying across the cloth's path) and
    // a box (a table whose edge the cloth swings over), each as a contact
    // term of pd's, pd-anderson's and newton's objective. The cloth keeps
    // about its length (k = 1e6, 5 s) and stays outside; without the terms
    // the projection after the step strains it several times more (over the
    // box's edge pd's even comes apart, caught by the guard).
    let capsule_spawn = |world: &mut World| {
        world.spawn((
            CapsuleCollider::new(1.5, 6.0),
            Transform::from_xyz(0.0, -4.0, 4.0).with_rotation(Quat::from_rotation_z(FRAC_PI_2)),
        ));
    };
    let capsule_inside = |p: Vec3A| {
        let axis = Vec3A::new(p.x.clamp(-6.0, 6.0), -4.0, 4.0);
        1.5 - p.distance(axis)
    };
    let box_spawn = |world: &mut World| {
        world.spawn((
            CuboidCollider::new(Vec3::new(6.0, 1.0, 2.0)),
            Transform::from_xyz(0.0, -5.0, 4.0),
        ));
    };
    let box_inside = |p: Vec3A| {
        let d = (p - Vec3A::new(0.0, -5.0, 4.0)).abs() - Vec3A::new(6.0, 1.0, 2.0);
        -d.max_element()
    };
    for preset in ["pd", "pd-anderson", "newton"] {
        let with: AnyMethod = preset.parse().unwrap();
        let without = match with {
            AnyMethod::Projective(pd) => AnyMethod::Projective(ProjectiveSolver {
                contacts: false,
                ..pd
            }),
            AnyMethod::Exact(newton) => AnyMethod::Exact(ExactSolver {
                contacts: false,
                ..newton
            }),
            _ => unreachable!(),
        };
        for (name, in_objective, projected) in [
            (
                "capsule",
                stiff_cloth_onto(with, 1e6, 150, capsule_spawn, capsule_inside),
                stiff_cloth_onto(without, 1e6, 150, capsule_spawn, capsule_inside),
            ),
            (
                "box",
                stiff_cloth_onto(with, 1e6, 150, box_spawn, box_inside),
                stiff_cloth_onto(without, 1e6, 150, box_spawn, box_inside),
            ),
        ] {
            let (stretch, deepest, running) = in_objective;
            assert!(running, "{preset} on the {name}");
            assert!(stretch < 0.02, "{preset} on the {name} stretched {stretch}");
            assert!(deepest < 1e-3, "{preset} {deepest} inside the {name}");
            assert!(
                projected.0 > 2.0 * stretch,
                "{preset} on the {name}: projected {projected:?}, in the objective {stretch}"
            );
        }
    }
}
