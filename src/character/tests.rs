use bevy::math::{Affine3A, Vec3, Vec3A};

use super::*;
use crate::model::ClothBuilder;
use crate::solver::xpbd::{XpbdSolver, XpbdWorkspace};
use crate::solver::{Method, StepParams};

/// A 2 m square cloth of `mass` kg in the x–y plane, its top row pinned.
fn cape_model(n: usize, mass: f32) -> ClothModel {
    ClothBuilder::grid(
        n,
        n,
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(-1.0, -2.0, 0.0),
    )
    .with_masses(vec![mass / (n * n) as f32; n * n])
    .with_pins(0..n as u32)
    .build()
    .unwrap()
}

/// Steps `state` `steps` times with `method`, holding it to `pose` by `c`
/// after each step, and hands each step's result to `each`.
fn step_and_hold<M: Method>(
    method: M,
    ws: &mut M::Workspace,
    (model, params, pose, c): (&ClothModel, &StepParams, &SkinPose, &SkinConstraints),
    state: &mut ClothState,
    steps: usize,
    mut each: impl FnMut(usize, &ClothState),
) {
    let mut tethers = SkinTethers::default();
    for step in 0..steps {
        method.step(model, state, params, &[], ws).unwrap();
        apply_skin(model, state, pose, c, &mut tethers, params.dt as f32);
        each(step, state);
    }
}

/// A 2 m cape of 1.5 kg in the x–y plane, its top row pinned, and its rest
/// shape as the skinned pose (normals +z).
fn cape(n: usize) -> (ClothModel, ClothState, SkinPose) {
    let model = cape_model(n, 1.5);
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
    let held = apply_skin(
        &model,
        &mut state,
        &pose,
        &c,
        &mut SkinTethers::default(),
        0.1,
    );
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
    let held = apply_skin(
        &model,
        &mut state,
        &pose,
        &c,
        &mut SkinTethers::default(),
        1.0 / 60.0,
    );
    assert_eq!(held, 1);
    assert!(
        (state.positions[behind].z + 0.05).abs() < 1e-3,
        "{}",
        state.positions[behind]
    );
    assert_eq!(state.positions[front].z, 0.2);
    // Just behind the skin but in front of the backstop: free.
    state.positions[front].z = -0.03;
    assert_eq!(
        apply_skin(
            &model,
            &mut state,
            &pose,
            &c,
            &mut SkinTethers::default(),
            1.0 / 60.0
        ),
        0
    );
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
            apply_skin(
                &model,
                &mut state,
                &pose,
                &c,
                &mut SkinTethers::default(),
                1.0 / steps as f32,
            );
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
    assert_eq!(
        ok.clone().with_tethers(0.9).validate(n, &pose),
        Err(SkinError::Tether(0.9))
    );
    assert!(matches!(
        ok.clone().with_tethers(f32::NAN).validate(n, &pose),
        Err(SkinError::Tether(t)) if t.is_nan()
    ));
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
    let mut worst: f32 = 0.0;
    let mut ws = XpbdWorkspace::default();
    step_and_hold(
        XpbdSolver::STIFF,
        &mut ws,
        (&model, &params, &pose, &c),
        &mut state,
        240,
        |step, state| {
            for i in 0..n {
                let off = (state.positions[i] - pose.positions[i]).length();
                assert!(
                    off <= c.max_distance[i] + 1e-5,
                    "step {step} vertex {i}: {off}"
                );
                worst = worst.max(-state.positions[i].z);
            }
        },
    );
    // The backstop is 5 cm behind (its 50 m spheres curve away by under 2 mm
    // within the max distance): nothing went further back.
    assert!(worst <= 0.06, "{worst}");
    assert!(state.is_finite());
}

#[test]
fn tethers_hold_a_heavy_cape_to_its_length_whatever_the_method() {
    // A 2 m cape of 15 kg of soft springs under the lab's Chebyshev method
    // stretches far beyond its length; with tethers at 1.02 no vertex is
    // further from its pin than 1.02 times its rest distance, and the cape
    // hangs within 2 % of 2 m.
    use crate::solver::implicit::{ImplicitSolver, ImplicitWorkspace};
    let (_, state, pose) = cape(12);
    let model = cape_model(12, 15.0);
    let n = model.vertex_count();
    let params = StepParams {
        dt: 1.0 / 60.0,
        stiffness: crate::solver::SpringStiffness::uniform(500.0),
        ..StepParams::LAB
    };
    let hang = |tethered: bool| {
        let mut state = state.clone();
        let c = SkinConstraints::free(n);
        let c = if tethered { c.with_tethers(1.02) } else { c };
        let mut ws = ImplicitWorkspace::default();
        let method = ImplicitSolver::chebyshev(32, 0.995);
        step_and_hold(
            method,
            &mut ws,
            (&model, &params, &pose, &c),
            &mut state,
            300,
            |_, _| {},
        );
        assert!(state.is_finite());
        -state.positions.iter().map(|p| p.y).fold(0.0, f32::min)
    };
    let (loose, held) = (hang(false), hang(true));
    assert!(loose > 2.1, "without tethers the cape stretches: {loose}");
    assert!((2.0 - 1e-3..=2.04 + 1e-4).contains(&held), "{held}");
}

#[test]
fn a_tether_reaches_round_a_curve_not_across_it() {
    // A half-cylinder (a skirt's front) pinned along its top edge: the
    // hem's tether is the path down the cloth, so a rest shape passes
    // untouched (a Euclidean tether to a pin across the curve would pull
    // it in).
    let (cols, rows) = (9, 6);
    let mut positions = Vec::new();
    for r in 0..rows {
        for c in 0..cols {
            let a = std::f32::consts::PI * c as f32 / (cols - 1) as f32;
            positions.push(Vec3::new(a.cos(), -0.2 * r as f32, a.sin()));
        }
    }
    let mut indices = Vec::new();
    for r in 0..rows - 1 {
        for c in 0..cols - 1 {
            let i = (r * cols + c) as u32;
            let w = cols as u32;
            indices.extend([i, i + w, i + 1, i + 1, i + w, i + w + 1]);
        }
    }
    let model = ClothBuilder::from_triangles(positions, indices)
        .with_pins(0..cols as u32)
        .build()
        .unwrap();
    let n = model.vertex_count();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let pose = SkinPose {
        positions: state.positions.clone(),
        normals: vec![Vec3A::Y; n],
    };
    let c = SkinConstraints::free(n).with_tethers(1.0);
    let before = state.clone();
    let held = apply_skin(
        &model,
        &mut state,
        &pose,
        &c,
        &mut SkinTethers::default(),
        0.01,
    );
    assert_eq!(held, 0);
    assert_eq!(state, before);
}

mod inertia {
    use bevy::math::{Affine3A, Quat, Vec3, Vec3A};

    use super::cape_model;
    use crate::character::SkinError;
    use crate::character::inertia::{Carried, ClothInertia, carry};
    use crate::ecs::Cloth;

    fn placed(n: usize) -> Cloth {
        let mut cloth = Cloth::new(cape_model(n, 1.5));
        cloth.place(&Affine3A::IDENTITY);
        let pins = cloth.model.pins().to_vec();
        cloth.pins_stepped = pins
            .iter()
            .map(|&p| (p, cloth.state.positions[p as usize]))
            .collect();
        cloth
    }

    fn at(x: f32) -> Affine3A {
        Affine3A::from_translation(Vec3::new(x, 0.0, 0.0))
    }

    #[test]
    fn a_velocity_scale_of_zero_carries_the_cloth_with_its_anchor() {
        let mut cloth = placed(4);
        let before = cloth.state.clone();
        let mut inertia = ClothInertia::default().with_scales(0.0, 1.0);
        assert_eq!(
            carry(&mut inertia, &mut cloth, None, at(0.0), 0.1),
            Carried::Nothing
        );
        assert_eq!(
            carry(&mut inertia, &mut cloth, None, at(0.5), 0.1),
            Carried::Scaled
        );
        for i in 0..cloth.model.vertex_count() {
            let moved = cloth.state.positions[i] - before.positions[i];
            let expected = if cloth.model.pinned()[i] { 0.0 } else { 0.5 };
            assert!((moved.x - expected).abs() < 1e-6, "{i}: {moved}");
            assert_eq!(cloth.state.velocities[i], before.velocities[i]);
        }
        // The pins' last positions moved too: the pins keep no velocity.
        for &(p, last) in &cloth.pins_stepped {
            assert!((last.x - before.positions[p as usize].x - 0.5).abs() < 1e-6);
        }
        // At half the scale, half the motion.
        let mut cloth = placed(4);
        let mut inertia = ClothInertia::default().with_scales(0.5, 1.0);
        carry(&mut inertia, &mut cloth, None, at(0.0), 0.1);
        carry(&mut inertia, &mut cloth, None, at(0.5), 0.1);
        let free = (0..16).find(|&i| !cloth.model.pinned()[i]).unwrap();
        assert!((cloth.state.positions[free].x - before.positions[free].x - 0.25).abs() < 1e-6);
    }

    #[test]
    fn an_acceleration_scale_of_zero_gives_the_cloth_its_anchors_change_of_velocity() {
        let mut cloth = placed(4);
        let mut inertia = ClothInertia::default().with_scales(1.0, 0.0);
        let free = (0..16).find(|&i| !cloth.model.pinned()[i]).unwrap();
        carry(&mut inertia, &mut cloth, None, at(0.0), 0.1);
        carry(&mut inertia, &mut cloth, None, at(0.0), 0.1);
        assert_eq!(cloth.state.velocities[free], Vec3A::ZERO);
        // Starts at 2 m/s: the cloth takes 2 m/s at once, positions untouched.
        let x = cloth.state.positions[free];
        carry(&mut inertia, &mut cloth, None, at(0.2), 0.1);
        assert!((cloth.state.velocities[free] - Vec3A::new(2.0, 0.0, 0.0)).length() < 1e-5);
        assert_eq!(cloth.state.positions[free], x);
        // At a steady 2 m/s, nothing more.
        carry(&mut inertia, &mut cloth, None, at(0.4), 0.1);
        assert!((cloth.state.velocities[free] - Vec3A::new(2.0, 0.0, 0.0)).length() < 1e-5);
        // The defaults change nothing at all.
        let mut cloth = placed(4);
        let before = cloth.state.clone();
        let mut inertia = ClothInertia::default();
        for x in [0.0, 0.3, 1.0, 50.0] {
            assert_ne!(
                carry(&mut inertia, &mut cloth, None, at(x), 0.1),
                Carried::Teleported
            );
        }
        assert_eq!(cloth.state, before);
    }

    #[test]
    fn a_teleported_anchor_moves_the_cloth_rigidly_velocities_turned() {
        let mut cloth = placed(4);
        for (i, v) in cloth.state.velocities.iter_mut().enumerate() {
            *v = Vec3A::new(i as f32, 1.0, 0.0);
        }
        let before = cloth.state.clone();
        let mut inertia = ClothInertia::default().with_teleport(10.0);
        carry(&mut inertia, &mut cloth, None, Affine3A::IDENTITY, 0.1);
        let jump = Affine3A::from_rotation_translation(
            Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            Vec3::new(100.0, 0.0, 0.0),
        );
        assert_eq!(
            carry(&mut inertia, &mut cloth, None, jump, 0.1),
            Carried::Teleported
        );
        for i in 0..16 {
            let v = jump.transform_vector3a(before.velocities[i]);
            assert!((cloth.state.velocities[i] - v).length() < 1e-4);
            if !cloth.model.pinned()[i] {
                let x = jump.transform_point3a(before.positions[i]);
                assert!((cloth.state.positions[i] - x).length() < 1e-4);
                assert!((cloth.last_good.positions[i] - x).length() < 1e-4);
            }
        }
        for &(p, last) in &cloth.pins_stepped {
            let x = jump.transform_point3a(before.positions[p as usize]);
            assert!((last - x).length() < 1e-4);
        }
        // A step of 9 m is no teleport.
        assert_ne!(
            carry(&mut inertia, &mut cloth, None, jump * at(9.0), 0.1),
            Carried::Teleported
        );
    }

    #[test]
    fn a_turning_anchor_teleported_far_away_gives_no_fling() {
        // The anchor turns steadily about its own origin, 2 m from the world
        // origin; a teleport takes it 100 m on, and it goes on turning: the
        // cloth must take no change of velocity for it (a reference motion
        // left where it was measured would read the turn 100 m off as a
        // fling of tens of metres per second).
        let mut cloth = placed(4);
        let mut inertia = ClothInertia::default()
            .with_scales(1.0, 0.0)
            .with_teleport(10.0);
        let turn = |k: f32, at: Vec3| {
            Affine3A::from_rotation_translation(Quat::from_rotation_y(0.05 * k), at)
        };
        let here = Vec3::new(2.0, 0.0, 0.0);
        let there = here + Vec3::new(100.0, 0.0, 0.0);
        for k in 0..3 {
            carry(&mut inertia, &mut cloth, None, turn(k as f32, here), 0.1);
        }
        let before = cloth.state.velocities.clone();
        assert_eq!(
            carry(&mut inertia, &mut cloth, None, turn(3.0, there), 0.1),
            Carried::Teleported
        );
        carry(&mut inertia, &mut cloth, None, turn(4.0, there), 0.1);
        for (v, b) in cloth.state.velocities.iter().zip(&before) {
            let b = Quat::from_rotation_y(0.05) * Vec3::from(*b);
            assert!((Vec3::from(*v) - b).length() < 1e-3, "{v} vs {b}");
        }
    }

    #[test]
    fn an_anchor_scaled_to_nothing_or_not_finite_moves_nothing() {
        let mut cloth = placed(4);
        let before = cloth.state.clone();
        let mut inertia = ClothInertia::default()
            .with_scales(0.0, 0.0)
            .with_teleport(1.0);
        let hidden = Affine3A::from_scale(Vec3::ZERO);
        let nan = Affine3A::from_translation(Vec3::NAN);
        for now in [at(0.0), hidden, at(0.1), nan, at(0.2)] {
            carry(&mut inertia, &mut cloth, None, now, 0.1);
            assert!(cloth.state.is_finite());
            assert!(cloth.last_good.is_finite());
        }
        // The hidden and the NaN anchors were skipped: it was carried from
        // 0 to 0.1 and from 0.1 to 0.2.
        let free = (0..16).find(|&i| !cloth.model.pinned()[i]).unwrap();
        let moved = cloth.state.positions[free].x - before.positions[free].x;
        assert!((moved - 0.2).abs() < 1e-5, "{moved}");
    }

    #[test]
    fn bad_inertia_is_a_typed_error() {
        let ok = ClothInertia::default();
        assert_eq!(ok.validate(), Ok(()));
        assert_eq!(
            ok.clone().with_scales(1.5, 1.0).validate(),
            Err(SkinError::Scale(1.5))
        );
        assert_eq!(
            ok.clone().with_scales(1.0, -0.1).validate(),
            Err(SkinError::Scale(-0.1))
        );
        assert!(ok.clone().with_scales(f32::NAN, 1.0).validate().is_err());
        assert_eq!(
            ok.clone().with_teleport(0.0).validate(),
            Err(SkinError::Teleport(0.0))
        );
        assert!(ok.with_teleport(f32::NAN).validate().is_err());
    }
}

#[test]
fn skinned_positions_and_normals_match_bevys_vertex_shader() {
    // Bevy's `skinning.wgsl`: `model = Σ wₖ·joint_matrices[k]` (each the
    // joint's global transform times its inverse bind pose, as `Mat4`),
    // position `model · (p, 1)`, normal
    // `normalize(inverse_transpose_3x3(model) · n)`. Reproduced here in
    // `Mat4` arithmetic, apart from `Skinning::pose`'s.
    use bevy::math::{Mat3, Mat4, Quat, Vec4};
    use bevy::mesh::skinning::{SkinnedMesh, SkinnedMeshInverseBindposes};
    use bevy::mesh::{Mesh, MeshBuilder, Meshable, VertexAttributeValues};
    use bevy::prelude::{Entity, Plane3d, Vec2};

    use super::Skinning;

    let mut mesh = Plane3d::new(Vec3::Z, Vec2::splat(1.0))
        .mesh()
        .subdivisions(5)
        .build();
    let Some(VertexAttributeValues::Float32x3(positions)) =
        mesh.attribute(Mesh::ATTRIBUTE_POSITION).cloned()
    else {
        panic!("a plane has positions");
    };
    let joints: Vec<[u16; 4]> = positions.iter().map(|_| [0, 1, 2, 0]).collect();
    let weights: Vec<[f32; 4]> = positions
        .iter()
        .map(|p| {
            let a = (1.0 - p[1]) / 4.0;
            let b = (1.0 + p[0]) / 4.0;
            [1.0 - a - b, a, b, 0.0]
        })
        .collect();
    mesh.insert_attribute(
        Mesh::ATTRIBUTE_JOINT_INDEX,
        VertexAttributeValues::Uint16x4(joints.clone()),
    );
    mesh.insert_attribute(Mesh::ATTRIBUTE_JOINT_WEIGHT, weights.clone());
    let model = ClothBuilder::from_mesh(&mesh).unwrap().build().unwrap();
    let entities: Vec<Entity> = (0..3)
        .map(|i| Entity::from_raw_u32(i + 1).unwrap())
        .collect();
    let skinned = SkinnedMesh {
        inverse_bindposes: Default::default(),
        joints: entities.clone(),
    };
    let bind = [
        Mat4::from_translation(Vec3::new(0.0, -1.0, 0.0)),
        Mat4::from_rotation_z(0.3) * Mat4::from_translation(Vec3::new(0.0, 1.0, 0.0)),
        Mat4::from_scale(Vec3::new(1.0, 0.5, 2.0)),
    ];
    let bindposes = SkinnedMeshInverseBindposes::from(bind.to_vec());
    let mut skinning = Skinning::from_mesh(&mesh, &skinned, &bindposes, &model).unwrap();
    // Joints turned, moved and scaled unevenly.
    let globals = [
        Affine3A::from_scale_rotation_translation(
            Vec3::new(1.0, 1.3, 0.8),
            Quat::from_rotation_y(0.7),
            Vec3::new(2.0, 1.0, -1.0),
        ),
        Affine3A::from_rotation_translation(Quat::from_rotation_x(-0.9), Vec3::new(0.5, 3.0, 0.0)),
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(1.5),
            Quat::from_rotation_z(1.2),
            Vec3::new(-1.0, 0.0, 4.0),
        ),
    ];
    let global = |e: Entity| entities.iter().position(|&j| j == e).map(|k| globals[k]);
    let mut pose = SkinPose::default();
    assert!(skinning.pose(global, &mut pose));
    let Some(VertexAttributeValues::Float32x3(normals)) =
        mesh.attribute(Mesh::ATTRIBUTE_NORMAL).cloned()
    else {
        panic!("a plane has normals");
    };
    let map = model.welded_from();
    let mut checked = 0;
    for j in 0..positions.len() {
        let c = map.map_or(j, |m| m[j] as usize);
        let mut m = Mat4::ZERO;
        for k in 0..4 {
            let joint = usize::from(joints[j][k]);
            m += (Mat4::from(globals[joint]) * bind[joint]) * weights[j][k];
        }
        let p = m * Vec4::from((Vec3::from(positions[j]), 1.0));
        let n = (Mat3::from_mat4(m).inverse().transpose() * Vec3::from(normals[j])).normalize();
        assert!(
            (Vec3::from(pose.positions[c]) - p.truncate()).length() < 1e-5,
            "{j}: {} vs {p}",
            pose.positions[c]
        );
        assert!(
            (Vec3::from(pose.normals[c]) - n).length() < 1e-5,
            "{j}: {} vs {n}",
            pose.normals[c]
        );
        checked += 1;
    }
    assert_eq!(checked, positions.len());
}

#[test]
fn painted_max_distance_and_backstop_come_from_the_mesh_welded_or_not() {
    use bevy::mesh::{Mesh, MeshBuilder, Meshable, VertexAttributeValues};
    use bevy::prelude::{Plane3d, Vec2};

    use super::{ATTRIBUTE_CLOTH_BACKSTOP, ATTRIBUTE_CLOTH_MAX_DISTANCE, SkinError};

    let mut mesh = Plane3d::new(Vec3::Y, Vec2::splat(1.0))
        .mesh()
        .subdivisions(3)
        .build();
    let Some(VertexAttributeValues::Float32x3(positions)) =
        mesh.attribute(Mesh::ATTRIBUTE_POSITION).cloned()
    else {
        panic!("a plane has positions");
    };
    // Painted by height along z: 0 at the top edge (follows the skin),
    // growing down the cape; the backstop 2 cm everywhere.
    let painted: Vec<f32> = positions.iter().map(|p| 0.1 * (p[2] + 1.0)).collect();
    mesh.insert_attribute(ATTRIBUTE_CLOTH_MAX_DISTANCE, painted.clone());
    mesh.insert_attribute(ATTRIBUTE_CLOTH_BACKSTOP, vec![0.02f32; positions.len()]);
    for weld in [false, true] {
        let model = ClothBuilder::from_mesh(&mesh)
            .unwrap()
            .with_welding(weld)
            .build()
            .unwrap();
        let n = model.vertex_count();
        let c = SkinConstraints::free(n)
            .with_painted(&mesh, &model)
            .unwrap();
        assert_eq!((c.max_distance.len(), c.backstop_distance.len()), (n, n));
        for (j, p) in positions.iter().enumerate() {
            let v = model.welded_from().map_or(j, |m| m[j] as usize);
            assert_eq!(
                c.max_distance[v],
                0.1 * (p[2] + 1.0),
                "weld {weld}, vertex {j}"
            );
            assert_eq!(c.backstop_distance[v], 0.02);
        }
        let pose = SkinPose {
            positions: vec![Vec3A::ZERO; n],
            normals: vec![Vec3A::Y; n],
        };
        assert_eq!(c.validate(n, &pose), Ok(()));
    }
    // Without the attributes the lists stay as they were.
    let bare = Plane3d::new(Vec3::Y, Vec2::splat(1.0)).mesh().build();
    let model = ClothBuilder::from_mesh(&bare).unwrap().build().unwrap();
    let free = SkinConstraints::free(model.vertex_count());
    assert_eq!(free.clone().with_painted(&bare, &model), Ok(free));
    // A negative value, and an attribute of the wrong length.
    let model = ClothBuilder::from_mesh(&mesh).unwrap().build().unwrap();
    let mut bad = mesh.clone();
    bad.insert_attribute(ATTRIBUTE_CLOTH_MAX_DISTANCE, vec![-1.0f32; positions.len()]);
    let free = SkinConstraints::free(model.vertex_count());
    assert_eq!(
        free.clone().with_painted(&bad, &model),
        Err(SkinError::Distance)
    );
    let mut short = mesh.clone();
    short.insert_attribute(ATTRIBUTE_CLOTH_BACKSTOP, vec![0.02f32; 3]);
    assert_eq!(free.with_painted(&short, &model), Err(SkinError::Mesh));
}

/// The skin's hold without a square root where the squared distance
/// decides ([`SkinInput::hold_with`]) moves every vertex as the plain
/// formula does (a unit normal, the distance's square root compared),
/// bit for bit, at points on both sides of the backstop sphere and of the
/// max distance within a few units in the last place, and further.
#[test]
fn the_skin_s_hold_is_the_plain_formula_bit_for_bit() {
    fn plain(input: &SkinInput<'_>, i: usize, skin: Vec3A, x: &mut Vec3A) -> bool {
        let normal = input.normals[i];
        let mut moved = false;
        let radius = input.backstop_radius;
        let centre = skin - (input.backstop_distance[i] + radius) * normal.normalize_or_zero();
        let d = *x - centre;
        let l = d.length();
        if l < radius {
            *x = centre + radius * if l > 0.0 { d / l } else { normal };
            moved = true;
        }
        let max = input.max_distance[i];
        let d = *x - skin;
        let l = d.length();
        if l > max {
            *x = skin + d * (max / l);
            moved = true;
        }
        moved
    }
    let skin = [Vec3A::new(0.3, 1.2, -0.1), Vec3A::new(100.0, 0.9, 7.0)];
    let normals = [Vec3A::new(0.0, 0.2, 2.0), Vec3A::new(-1.0, 0.0, 0.1)];
    let (max_distance, backstop_distance) = ([0.25, 0.6], [0.02, 0.0]);
    let input = SkinInput {
        positions: &skin,
        previous: None,
        normals: &normals,
        max_distance: &max_distance,
        backstop_distance: &backstop_distance,
        backstop_radius: 0.4,
        tether_scale: f32::INFINITY,
    };
    let (mut checked, mut moved) = (0, 0);
    for i in 0..2 {
        let unit = normals[i].normalize_or_zero();
        let centre = skin[i] - (backstop_distance[i] + 0.4) * unit;
        for k in 0..3000 {
            let u = (k as f32 + 0.5) / 3000.0;
            let (phi, z) = (k as f32 * 2.399_963, 1.0 - 2.0 * u);
            let ring = (1.0 - z * z).max(0.0).sqrt();
            let dir = Vec3A::new(ring * phi.cos(), z, ring * phi.sin());
            for scale in [0.5, 0.999_999, 1.0 - 1e-7, 1.0, 1.0 + 1e-7, 1.000_001, 1.5] {
                for start in [
                    centre + dir * (0.4 * scale),
                    skin[i] + dir * (max_distance[i] * scale),
                ] {
                    let (mut a, mut b) = (start, start);
                    let got = input.hold_with(i, skin[i], unit, &mut a);
                    let want = plain(&input, i, skin[i], &mut b);
                    assert_eq!(
                        (got, a.to_array().map(f32::to_bits)),
                        (want, b.to_array().map(f32::to_bits)),
                        "{start:?}"
                    );
                    assert_eq!(input.hold_at(i, skin[i], &mut start.clone()), want);
                    checked += 1;
                    moved += usize::from(want);
                }
            }
        }
    }
    // Both sides were met.
    assert!(
        moved > checked / 10 && moved < checked * 9 / 10,
        "{moved} of {checked}"
    );
}
