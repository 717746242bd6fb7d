use bevy::math::{Affine3A, Vec3, Vec3A};

use super::*;
use crate::model::ClothBuilder;
use crate::solver::xpbd::{XpbdSolver, XpbdWorkspace};
use crate::solver::{Method, StepParams};

/// A 2 m cape of 1.5 kg in the x–y plane, its top row pinned, and its rest
/// shape as the skinned pose (normals +z).
fn cape(n: usize) -> (ClothModel, ClothState, SkinPose) {
    let model = ClothBuilder::grid(
        n,
        n,
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, -2.0, 0.0),
    )
    .with_masses(vec![1.5 / (n * n) as f32; n * n])
    .with_pins(0..n as u32)
    .build()
    .unwrap();
    let state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let pose = SkinPose {
        positions: state.positions.clone(),
        normals: vec![Vec3A::Z; n * n],
    };
    (model, state, pose)
}

#[test]
fn a_max_distance_of_zero_follows_the_skin_and_its_velocity_says_so() {
    let (model, mut state, mut pose) = cape(4);
    let n = model.vertex_count();
    // The skin moved 0.3 m along +x; every free vertex must follow.
    for p in &mut pose.positions {
        *p += Vec3A::new(0.3, 0.0, 0.0);
    }
    let c = SkinConstraints::free(n).with_max_distance(|_| 0.0);
    c.validate(n, &pose).unwrap();
    let before = state.clone();
    let held = apply_skin(&model, &mut state, &pose, &c, 0.1);
    assert_eq!(held, n - 4);
    for i in 0..n {
        if model.pinned()[i] {
            assert_eq!(state.positions[i], before.positions[i], "pins stay");
        } else {
            assert!((state.positions[i] - pose.positions[i]).length() < 1e-6);
            assert!((state.velocities[i] - Vec3A::new(3.0, 0.0, 0.0)).length() < 1e-4);
        }
    }
}

#[test]
fn a_backstop_pushes_a_vertex_out_from_behind_the_skin_and_leaves_one_in_front() {
    let (model, mut state, pose) = cape(4);
    let n = model.vertex_count();
    // Backstops 0.05 m behind the skin, spheres of 10 m (nearly a plane).
    let c = SkinConstraints::free(n).with_backstop(10.0, |_| 0.05);
    let (behind, front) = (5, 6);
    state.positions[behind].z = -0.2;
    state.positions[front].z = 0.2;
    let held = apply_skin(&model, &mut state, &pose, &c, 1.0 / 60.0);
    assert_eq!(held, 1);
    assert!(
        (state.positions[behind].z + 0.05).abs() < 1e-3,
        "{}",
        state.positions[behind]
    );
    assert_eq!(state.positions[front].z, 0.2);
    // Just behind the skin but in front of the backstop: free.
    state.positions[front].z = -0.03;
    assert_eq!(apply_skin(&model, &mut state, &pose, &c, 1.0 / 60.0), 0);
}

#[test]
fn the_anim_drive_closes_its_share_of_the_gap_per_second_at_any_rate() {
    for steps in [10, 60, 240] {
        let (model, mut state, mut pose) = cape(3);
        let n = model.vertex_count();
        for p in &mut pose.positions {
            *p += Vec3A::new(0.0, 0.0, 1.0);
        }
        let c = SkinConstraints::free(n).with_drive(0.75);
        for _ in 0..steps {
            apply_skin(&model, &mut state, &pose, &c, 1.0 / steps as f32);
        }
        // A quarter of the gap is left after one second.
        let free = (0..n).find(|&i| !model.pinned()[i]).unwrap();
        let gap = pose.positions[free].z - state.positions[free].z;
        assert!((gap - 0.25).abs() < 1e-4, "{steps}: {gap}");
    }
}

#[test]
fn bad_constraints_are_typed_errors() {
    let (model, _, pose) = cape(3);
    let n = model.vertex_count();
    let ok = SkinConstraints::free(n);
    assert_eq!(ok.validate(n, &pose), Ok(()));
    assert_eq!(
        SkinConstraints::free(n + 1).validate(n, &pose),
        Err(SkinError::Length {
            expected: n,
            got: n + 1
        })
    );
    let nan = ok.clone().with_max_distance(|_| f32::NAN);
    assert_eq!(nan.validate(n, &pose), Err(SkinError::Distance));
    let negative = ok.clone().with_backstop(1.0, |_| -1.0);
    assert_eq!(negative.validate(n, &pose), Err(SkinError::Distance));
    let radius = ok.clone().with_backstop(0.0, |_| 0.1);
    assert_eq!(radius.validate(n, &pose), Err(SkinError::Radius(0.0)));
    assert_eq!(
        ok.clone().with_drive(1.5).validate(n, &pose),
        Err(SkinError::Drive(1.5))
    );
    let mut bad_pose = pose.clone();
    bad_pose.normals[2] = Vec3A::NAN;
    assert_eq!(ok.validate(n, &bad_pose), Err(SkinError::Pose));
}

#[test]
fn a_cape_swinging_under_stiff_keeps_within_its_max_distance_and_behind_nothing() {
    // The cape starts tilted 60° forward and swings back onto its own
    // skinned pose (a flat back behind it, 5 cm backstop): with a max
    // distance growing to 0.4 m at the hem it never strays further, and it
    // never crosses the backstop.
    let (model, mut state, pose) = cape(12);
    let n = model.vertex_count();
    let params = StepParams {
        dt: 1.0 / 60.0,
        ..StepParams::LAB
    };
    for (x, r) in state
        .positions
        .iter_mut()
        .zip(model.topology().rest_positions())
    {
        *x = Vec3A::new(r.x, r.y * 0.5, -r.y * 0.87);
    }
    let rest = model.topology().rest_positions().to_vec();
    let c = SkinConstraints::free(n)
        .with_max_distance(|i| 0.2 * -rest[i].y)
        .with_backstop(50.0, |_| 0.05);
    let method = XpbdSolver::STIFF;
    let mut ws = XpbdWorkspace::default();
    let mut worst: f32 = 0.0;
    for step in 0..240 {
        method
            .step(&model, &mut state, &params, &[], &mut ws)
            .unwrap();
        apply_skin(&model, &mut state, &pose, &c, params.dt as f32);
        for i in 0..n {
            let off = (state.positions[i] - pose.positions[i]).length();
            assert!(
                off <= c.max_distance[i] + 1e-5,
                "step {step} vertex {i}: {off}"
            );
            worst = worst.max(-state.positions[i].z);
        }
    }
    // The backstop is 5 cm behind (its 50 m spheres curve away by under 2 mm
    // within the max distance): nothing went further back.
    assert!(worst <= 0.06, "{worst}");
    assert!(state.is_finite());
}
