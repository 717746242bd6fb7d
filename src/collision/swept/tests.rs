use bevy::math::{Affine3A, Vec3, Vec3A};

use super::*;
use crate::collision::{Cuboid, Plane, project_shapes};
use crate::model::ClothBuilder;

/// A 2 m square of `n×n` vertices at height `y`, in the xz plane.
fn sheet(n: usize, y: f32) -> (ClothModel, ClothState) {
    let model = ClothBuilder::grid(
        n,
        n,
        Vec3::new(-1.0, y, -1.0),
        Vec3::new(1.0, y, -1.0),
        Vec3::new(-1.0, y, 1.0),
    )
    .build()
    .unwrap();
    let state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    (model, state)
}

fn slab(half_height: f32) -> Shape {
    Shape::Cuboid(Cuboid {
        center: Vec3A::ZERO,
        axes: [Vec3A::X, Vec3A::Y, Vec3A::Z],
        half_extents: Vec3A::new(3.0, half_height, 3.0),
        friction: 0.0,
    })
}

#[test]
fn signed_distances_agree_with_the_contacts_inside_and_measure_outside() {
    let shapes = [
        slab(0.5),
        Shape::Capsule(Capsule {
            a: Vec3A::new(-1.0, 0.0, 0.0),
            b: Vec3A::new(1.0, 0.0, 0.0),
            radius: 0.5,
            friction: 0.0,
        }),
        Shape::Plane(Plane {
            point: Vec3A::ZERO,
            normal: Vec3A::Y,
            friction: 0.0,
        }),
    ];
    let inside = [Vec3A::new(0.3, -0.2, 0.1), Vec3A::new(0.9, -0.1, 0.3)];
    for shape in &shapes {
        for &x in &inside {
            let (d, n) = shape.signed_distance(x);
            let (normal, depth) = shape.contact(x, 0.0).expect("inside");
            assert!(
                (d + depth).abs() < 1e-5,
                "{shape:?} at {x}: {d} against {depth}"
            );
            assert!((n - normal).length() < 1e-5);
        }
    }
    // Outside a box's corner: the distance to the corner, along it.
    let (d, n) = slab(0.5).signed_distance(Vec3A::new(4.0, 1.5, 0.0));
    assert!((d - 2f32.sqrt()).abs() < 1e-5);
    assert!((n - Vec3A::new(1.0, 1.0, 0.0).normalize()).length() < 1e-5);
}

#[test]
fn a_fast_vertex_through_a_thin_box_is_put_back_on_top() {
    let (model, mut state) = sheet(3, 0.04);
    let dt = 1.0 / 60.0;
    // Every vertex fell 7 cm this step, ending 3 cm below a 2 cm slab's
    // top, past its middle: the nearest way out is the bottom.
    for (x, v) in state.positions.iter_mut().zip(&mut state.velocities) {
        *v = Vec3A::new(0.0, -0.07 / dt, 0.0);
        x.y -= 0.07;
    }
    let mut plain = state.clone();
    project_shapes(&model, &mut plain, &[slab(0.01)], 0.0, dt);
    assert!(
        plain.positions.iter().all(|x| x.y < -0.009),
        "{:?}",
        plain.positions[0]
    );
    let count = project_swept(&model, &mut state, &[slab(0.01)], Sweep::default(), 0.0, dt);
    assert_eq!(count, 9);
    for (x, v) in state.positions.iter().zip(&state.velocities) {
        assert!((x.y - 0.01).abs() < 1e-4, "put at {x}");
        // From 4 cm above the slab's top 1 cm to it this step.
        assert!((v.y - (0.01 - 0.04) / dt).abs() < 1e-2, "velocity {v}");
    }
    // A vertex that fell through it entirely (ends outside below) too.
    let (model, mut state) = sheet(2, -0.2);
    for v in &mut state.velocities {
        *v = Vec3A::new(0.0, -0.3 / dt, 0.0);
    }
    project_swept(&model, &mut state, &[slab(0.01)], Sweep::default(), 0.0, dt);
    assert!(state.positions.iter().all(|x| (x.y - 0.01).abs() < 1e-4));
}

#[test]
fn slow_contact_goes_out_the_nearest_way_as_before() {
    let (model, mut state) = sheet(5, -0.003);
    let dt = 1.0 / 60.0;
    for v in &mut state.velocities {
        *v = Vec3A::new(0.2, -0.5, 0.0);
    }
    let mut plain = state.clone();
    let shape = [slab(0.0).grown(0.01)];
    let a = project_shapes(&model, &mut plain, &shape, 0.0, dt);
    let b = project_swept(&model, &mut state, &shape, Sweep::default(), 0.0, dt);
    assert_eq!(a, b);
    for (p, q) in plain.positions.iter().zip(&state.positions) {
        assert!((*p - *q).length() < 1e-5, "{p} against {q}");
    }
}

#[test]
fn a_ball_thrown_through_the_cloth_pushes_it_ahead_instead_of_passing() {
    let n = 33;
    let (model, mut state) = sheet(n, 0.0);
    let dt = 1.0 / 60.0;
    let radius = 0.15;
    // 30 m/s upwards: 0.5 m this step, from 0.3 m below the sheet to
    // 0.2 m above it, its centre past every vertex it met.
    let motion = Vec3A::new(0.0, 0.5, 0.0);
    let ball = Sphere {
        center: Vec3A::new(0.0, 0.2, 0.0),
        radius,
        friction: 0.0,
    };
    let solids: Vec<Shape> = sphere_solids(&[ball]).collect();
    let mut plain = state.clone();
    project_swept(&model, &mut plain, &solids, Sweep::default(), 0.0, dt);
    let met = |s: &ClothState| {
        s.positions
            .iter()
            .filter(|x| Vec3A::new(x.x, 0.0, x.z).length() < radius * 0.9)
            .count()
    };
    // Static (not swept): the vertices under it are left behind it.
    assert!(met(&plain) > 0);
    let sweep = Sweep {
        motion: &[motion],
        ..Sweep::default()
    };
    let count = project_swept(&model, &mut state, &solids, sweep, 0.0, dt);
    assert!(count > 0);
    for (x, v) in state.positions.iter().zip(&state.velocities) {
        if Vec3A::new(x.x, 0.0, x.z).length() < radius * 0.5 {
            assert!(x.y >= ball.center.y, "left below the ball at {x}");
            assert!(v.y > 20.0, "not carried: {v}");
        }
        assert!(x.distance(ball.center) >= radius - 1e-4);
    }
    // A teleport is not a sweep.
    let (model, mut state) = sheet(n, 0.0);
    let far = Sweep {
        motion: &[Vec3A::new(0.0, 50.0, 0.0)],
        ..Sweep::default()
    };
    let mut plain = state.clone();
    project_swept(&model, &mut state, &solids, far, 0.0, dt);
    project_swept(&model, &mut plain, &solids, Sweep::default(), 0.0, dt);
    assert_eq!(state.positions, plain.positions);
}

#[test]
fn edges_over_a_box_corner_are_pushed_out() {
    // One edge from beside the box's left face to above its top: both ends
    // outside, its middle 5 cm inside, under the box's top-left edge.
    let model = ClothBuilder::from_triangles(
        vec![
            Vec3::new(-0.55, 0.35, 0.0),
            Vec3::new(-0.35, 0.55, 0.0),
            Vec3::new(-0.45, 0.7, 1.0),
        ],
        vec![0, 1, 2],
    )
    .build()
    .unwrap();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let cube = Shape::Cuboid(Cuboid {
        center: Vec3A::ZERO,
        axes: [Vec3A::X, Vec3A::Y, Vec3A::Z],
        half_extents: Vec3A::new(0.5, 0.5, 2.0),
        friction: 0.0,
    });
    let edge = |s: &ClothState| deepest_on_segment(&cube, s.positions[0], s.positions[1]).1;
    assert!(edge(&state) < -0.04);
    let mut vertices_only = state.clone();
    assert_eq!(
        project_swept(
            &model,
            &mut vertices_only,
            &[cube],
            Sweep::default(),
            0.0,
            0.01
        ),
        0
    );
    let with_edges = Sweep {
        edges: true,
        ..Sweep::default()
    };
    assert!(project_swept(&model, &mut state, &[cube], with_edges, 0.0, 0.01) > 0);
    assert!(edge(&state) > -1e-4, "still {} inside", -edge(&state));
    // Both ends moved equally (the deepest point is the edge's middle),
    // diagonally off the box's edge, as far as the edge's line is from it
    // (0.1/√2): one face's depth would leave it half inside.
    let moved = state.positions[0] - Vec3A::new(-0.55, 0.35, 0.0);
    assert!(
        (moved - Vec3A::new(-0.05, 0.05, 0.0)).length() < 1e-3,
        "moved {moved}"
    );
    assert!((moved - (state.positions[1] - Vec3A::new(-0.35, 0.55, 0.0))).length() < 1e-3);
}

#[test]
fn a_vertex_sliding_over_a_box_edge_is_not_thrown_back_on_top() {
    // A vertex that slid off the top of a box over its edge in one step
    // cut the corner (and ended just inside the side face): it goes out
    // the nearest way, by the side, not back up to the top.
    let model = ClothBuilder::from_triangles(
        vec![
            Vec3::new(0.495, 0.4, 0.0),
            Vec3::new(2.0, 2.0, 0.0),
            Vec3::new(2.0, 2.0, 1.0),
        ],
        vec![0, 1, 2],
    )
    .build()
    .unwrap();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let dt = 0.01;
    // From 2 cm above the top, 3 cm in from the edge, to 10 cm down the side.
    state.velocities[0] = (Vec3A::new(0.495, 0.4, 0.0) - Vec3A::new(0.47, 0.52, 0.0)) / dt;
    let cube = Shape::Cuboid(Cuboid {
        center: Vec3A::ZERO,
        axes: [Vec3A::X, Vec3A::Y, Vec3A::Z],
        half_extents: Vec3A::splat(0.5),
        friction: 0.0,
    });
    project_swept(&model, &mut state, &[cube], Sweep::default(), 0.0, dt);
    let x = state.positions[0];
    assert!(
        (x - Vec3A::new(0.5, 0.4, 0.0)).length() < 1e-4,
        "put at {x}"
    );
}

#[test]
fn a_sweep_over_the_last_substep_leaves_a_vertex_carried_round_a_solid() {
    // A vertex that a method's substeps carried round a ball, from under
    // it to beside it, ends outside it: swept in a straight line from
    // the step's start it passed through the ball and is put back under
    // it; swept over the last of 16 substeps (at its velocity), it stays.
    let model = ClothBuilder::from_triangles(
        vec![
            Vec3::new(0.0, -0.3, 0.0),
            Vec3::new(0.5, -0.3, 0.0),
            Vec3::new(0.0, -0.3, 0.5),
        ],
        vec![0, 1, 2],
    )
    .build()
    .unwrap();
    let ball = Shape::Capsule(Capsule {
        a: Vec3A::ZERO,
        b: Vec3A::ZERO,
        radius: 0.25,
        friction: 0.0,
    });
    let start = model
        .topology()
        .rest_positions()
        .iter()
        .map(|&p| Vec3A::from(p))
        .collect::<Vec<_>>();
    let dt = 1.0 / 60.0;
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    // Now just beside the ball's top, moving up along its side.
    state.positions[0] = Vec3A::new(0.0, 0.3, 0.0);
    state.velocities[0] = Vec3A::new(0.0, 2.0, 0.0);
    let end = state.positions[0];
    let sweep = |share: f32| Sweep {
        start: &start,
        share,
        ..Sweep::default()
    };
    let mut whole = state.clone();
    project_swept(&model, &mut whole, &[ball], sweep(1.0), 0.0, dt);
    assert!(
        whole.positions[0].y < 0.0,
        "put back at {}",
        whole.positions[0]
    );
    project_swept(&model, &mut state, &[ball], sweep(1.0 / 16.0), 0.0, dt);
    assert_eq!(state.positions[0], end);
}

#[test]
fn the_closed_form_deepest_point_agrees_with_the_search() {
    // Segments of every kind against a sphere, a capsule and a plane: the
    // closed form's depth is the search's (which it replaces in the edge
    // pass) within rounding, and never shallower.
    let shapes = [
        Shape::Capsule(Capsule {
            a: Vec3A::new(0.1, 0.2, -0.1),
            b: Vec3A::new(0.1, 0.2, -0.1),
            radius: 0.3,
            friction: 0.0,
        }),
        Shape::Capsule(Capsule {
            a: Vec3A::new(-0.4, 0.0, 0.1),
            b: Vec3A::new(0.5, 0.3, -0.2),
            radius: 0.15,
            friction: 0.0,
        }),
        Shape::Plane(Plane {
            point: Vec3A::new(0.0, 0.1, 0.0),
            normal: Vec3A::new(0.6, 0.8, 0.0),
            friction: 0.0,
        }),
    ];
    let mut seed = 0x2545_f491_u32;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        seed as f32 / u32::MAX as f32 * 2.0 - 1.0
    };
    let mut inside = 0;
    for shape in &shapes {
        for k in 0..2000 {
            let a = Vec3A::new(next(), next(), next());
            // Long, short, a point, and parallel to the capsule's axis.
            let b = match k % 4 {
                0 => a,
                1 => a + 0.05 * Vec3A::new(next(), next(), next()),
                2 => match shape {
                    Shape::Capsule(c) => a + 0.7 * (c.b - c.a),
                    _ => a + Vec3A::X,
                },
                _ => Vec3A::new(next(), next(), next()),
            };
            let (t, fast) = deepest_fast(shape, a, b, SEARCH);
            let (_, search) = deepest_within(shape, a, b, SEARCH);
            assert!((0.0..=1.0).contains(&t), "{t}");
            assert_eq!(fast, shape.signed_distance(a + t * (b - a)).0);
            assert!(
                fast <= search + 1e-6,
                "{shape:?} {a} {b}: {fast} > {search}"
            );
            assert!(
                (fast - search).abs() <= 1e-5,
                "{shape:?} {a} {b}: {fast} vs {search}"
            );
            inside += usize::from(fast < 0.0);
        }
    }
    assert!(inside > 500, "too few segments meet a solid: {inside}");
}
