//! The lab's scenes, driven through the real plugin.

use bevy::prelude::*;
use bevy_cloth::prelude::*;

use crate::common::*;

const SPHERE_RADIUS: f32 = 2.7;

#[test]
fn lab_cloth_hangs_from_its_pins_and_comes_to_rest() {
    let mut app = app();
    let cloth = spawn_lab(&mut app, ImplicitSolver::default());
    run_steps(&mut app, 1500);
    let x = positions(&app, cloth);
    assert_eq!(x[0], Vec3A::new(5.0, 0.0, 5.0));
    assert_eq!(x[20], Vec3A::new(-5.0, 0.0, 5.0));
    assert!(x.iter().all(|p| p.is_finite()));
    let lowest = x.iter().map(|p| p.y).fold(f32::INFINITY, f32::min);
    // It hangs: the far edge (10 units away at rest) is now well below the pins.
    assert!(lowest < -9.0, "lowest y {lowest}");
    let s = stats(&app, cloth);
    assert_eq!(s.steps, 1500);
    assert_eq!(s.method, "jacobi");
    assert_eq!(s.iterations, 32);
    // At rest after 50 s (0.99 damping per step), with bounded stretch: the
    // springs at the pins carry the whole 441-unit weight at k = 8000 and sit
    // 37 % over their rest length; none exceeds 40 %.
    assert!(
        max_speed(&app, cloth) < 0.01,
        "speed {}",
        max_speed(&app, cloth)
    );
    assert!(
        s.max_stretch > 0.3 && s.max_stretch < 0.4,
        "max stretch {}",
        s.max_stretch
    );
}

#[test]
fn chebyshev_reaches_a_smaller_gradient_norm_than_jacobi() {
    let mut app = app();
    let jacobi = spawn_lab(&mut app, ImplicitSolver::jacobi(32));
    let chebyshev = spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 0.995));
    // The same first step from the same state.
    run_steps(&mut app, 1);
    let rj = stats(&app, jacobi).residual.unwrap();
    let rc = stats(&app, chebyshev).residual.unwrap();
    assert!(rc < 0.5 * rj, "chebyshev {rc} vs jacobi {rj}");
}

#[test]
fn pbd_keeps_stretch_under_its_bound() {
    let mut app = app();
    let coarse = spawn_lab(&mut app, PbdSolver::new(32));
    let fine = spawn_lab(&mut app, PbdSolver::new(256));
    let mut worst = [0.0f32; 2];
    for _ in 0..300 {
        run_steps(&mut app, 1);
        worst[0] = worst[0].max(stats(&app, coarse).max_stretch);
        worst[1] = worst[1].max(stats(&app, fine).max_stretch);
    }
    // The lab's 0.2-weighted Jacobi averaging converges slowly, so the bound
    // depends on the iteration count. Measured worst spring over the first
    // 300 steps: 1.54 (32 iterations), 0.32 (256). Stated bounds: with 32
    // iterations no spring exceeds 2.6× its rest length while swinging and
    // 2× once hanging; with 256, 1.4×.
    assert!(worst[0] < 1.6, "32 iterations: {}", worst[0]);
    assert!(stats(&app, coarse).max_stretch < 1.0);
    assert!(worst[1] < 0.4, "256 iterations: {}", worst[1]);
}

fn assert_outside(x: &[Vec3A], center: Vec3A) {
    for (i, p) in x.iter().enumerate() {
        let d = p.distance(center);
        assert!(
            d >= SPHERE_RADIUS - 1e-4,
            "vertex {i} at {d} from the centre"
        );
    }
}

#[test]
fn a_cloth_falling_onto_a_sphere_ends_outside_it() {
    for method in [0, 1, 2] {
        let mut app = app();
        let cloth = match method {
            0 => spawn_lab(&mut app, ImplicitSolver::jacobi(32)),
            1 => spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 0.995)),
            _ => spawn_lab(&mut app, PbdSolver::new(32)),
        };
        let center = Vec3::new(0.0, -4.0, 4.0);
        app.world_mut().spawn((
            SphereCollider::new(SPHERE_RADIUS),
            Transform::from_translation(center),
        ));
        let mut touched = 0;
        for _ in 0..300 {
            run_steps(&mut app, 1);
            touched = touched.max(stats(&app, cloth).contacts);
        }
        assert!(touched > 10, "method {method}: only {touched} contacts");
        let x = positions(&app, cloth);
        assert!(x.iter().all(|p| p.is_finite()));
        assert_outside(&x, center.into());
        assert!(stats(&app, cloth).is_running());
    }
}

#[test]
fn a_moving_sphere_pushes_the_hanging_cloth() {
    let mut app = app();
    let cloth = spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 0.995));
    let start = Vec3::new(0.0, -5.0, 12.0);
    let sphere = app
        .world_mut()
        .spawn((
            SphereCollider::new(SPHERE_RADIUS),
            Transform::from_translation(start),
        ))
        .id();
    // Let the cloth settle into a curtain hanging near z = 5.
    run_steps(&mut app, 300);
    let before = positions(&app, cloth);
    assert_eq!(stats(&app, cloth).contacts, 0);
    // Drag the sphere through the curtain, 0.1 per step, as the lab's mouse does.
    for k in 1..=100 {
        app.world_mut()
            .get_mut::<Transform>(sphere)
            .unwrap()
            .translation = start - Vec3::Z * (0.1 * k as f32);
        run_steps(&mut app, 1);
    }
    let center = Vec3A::new(0.0, -5.0, 2.0);
    let after = positions(&app, cloth);
    assert_outside(&after, center);
    assert!(stats(&app, cloth).contacts > 0);
    // The part of the curtain in front of the sphere was pushed back (−z).
    let mean_z = |x: &[Vec3A]| x.iter().map(|p| p.z).sum::<f32>() / x.len() as f32;
    assert!(
        mean_z(&after) < mean_z(&before) - 1.0,
        "mean z {} -> {}",
        mean_z(&before),
        mean_z(&after)
    );
    let pushed = after.iter().map(|p| p.z).fold(f32::INFINITY, f32::min);
    assert!(pushed < -0.5, "deepest vertex z {pushed}");
}

#[test]
fn the_convergence_flag_is_quiet_on_a_cloth_hanging_still_or_resting_on_the_sphere() {
    // The lab cloth at the lab's settings, 10 s hanging and 10 s falling
    // onto the lab's sphere and resting there: no step of a method that
    // converges there is flagged; Jacobi 32, which lags in the fall, is
    // flagged only then, not hanging still nor resting on the sphere (the
    // projection undoes what its solve leaves of the fall into it:
    // `ContactError`). The stability map's verdicts, judged over the same
    // runs, are in `docs/report/stability.md`.
    for preset in [
        "jacobi",
        "chebyshev",
        "chebyshev-auto",
        "pd",
        "pd-anderson",
        "newton",
        "stiff",
    ] {
        for sphere in [false, true] {
            let mut app = app();
            let cloth = spawn_lab(&mut app, ());
            preset
                .parse::<AnyMethod>()
                .unwrap()
                .insert(&mut app.world_mut().commands().entity(cloth));
            if sphere {
                app.world_mut().spawn((
                    SphereCollider::new(SPHERE_RADIUS),
                    Transform::from_xyz(0.0, -4.0, 4.0),
                ));
            }
            run_steps(&mut app, 30);
            let falling = stats(&app, cloth).unconverged_steps;
            run_steps(&mut app, 270);
            let s = stats(&app, cloth);
            assert!(s.is_running() && s.steps == 300, "{preset}: {s:?}");
            assert_eq!(
                s.unconverged_steps, falling,
                "{preset}, sphere {sphere}: flagged after the fall: {s:?}"
            );
            if preset != "jacobi" {
                assert_eq!(falling, 0, "{preset}, sphere {sphere}: {s:?}");
            }
            if sphere {
                assert!(s.contacts > 10, "{preset}: {s:?}");
            }
        }
    }
}

#[test]
fn the_convergence_flag_still_calls_the_maps_wrong_cells_in_contact() {
    // The stability map's "Falling onto the sphere" at k = 1e6, dt = 1/30:
    // Chebyshev and `pd` are wrong there (they fall short of the exact run
    // and hover), and so they are flagged while they rest on the sphere
    // too; the exact method is right and is not.
    for (preset, flagged) in [("chebyshev", true), ("pd", true), ("exact", false)] {
        let mut app = app();
        app.insert_resource(Time::<Fixed>::from_seconds(1.0 / 30.0));
        let cloth = spawn_lab(&mut app, ());
        app.world_mut()
            .get_mut::<ClothParams>(cloth)
            .unwrap()
            .stiffness = SpringStiffness::uniform(1e6);
        preset
            .parse::<AnyMethod>()
            .unwrap()
            .insert(&mut app.world_mut().commands().entity(cloth));
        app.world_mut().spawn((
            SphereCollider::new(SPHERE_RADIUS),
            Transform::from_xyz(0.0, -4.0, 4.0),
        ));
        run_steps(&mut app, 150);
        let falling = stats(&app, cloth).unconverged_steps;
        run_steps(&mut app, 150);
        let s = stats(&app, cloth);
        assert!(s.is_running() && s.contacts > 10, "{preset}: {s:?}");
        let resting = s.unconverged_steps - falling;
        if flagged {
            assert!(
                resting > 100,
                "{preset}: {resting} of 150 flagged at rest: {s:?}"
            );
        } else {
            assert_eq!(s.unconverged_steps, 0, "{preset}: {s:?}");
        }
    }
}
