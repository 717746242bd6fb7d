use bevy::math::{Affine3A, Vec3, Vec3A};

use super::*;
use crate::model::{ClothBuilder, ClothModel};

/// A flat `n`² sheet of 1 m in the xz plane at the origin, at rest.
pub(crate) fn flat_sheet(n: usize) -> (ClothModel, Vec<Vec3A>) {
    let model = ClothBuilder::grid(n, n, Vec3::ZERO, Vec3::X, Vec3::Z)
        .build()
        .unwrap();
    let x = ClothState::at_rest(&model, &Affine3A::IDENTITY).positions;
    (model, x)
}

#[test]
fn vertices_inside_are_projected_to_the_surface_with_matching_velocity() {
    let model = ClothBuilder::lab().build().unwrap();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let before = state.clone();
    let sphere = Sphere {
        center: Vec3A::new(0.0, -1.0, 0.0),
        radius: 2.7,
        friction: 0.0,
    };
    let dt = 0.0333;
    let count = project_spheres(&model, &mut state, &[sphere], 0.0, dt);
    let inside = before
        .positions
        .iter()
        .filter(|p| p.distance(sphere.center) < 2.7)
        .count();
    assert!(count > 0);
    assert_eq!(count, inside);
    for i in 0..state.len() {
        let d = state.positions[i].distance(sphere.center);
        assert!(d >= 2.7 - 1e-4, "vertex {i} at distance {d}");
        let moved = state.positions[i] - before.positions[i];
        assert!((state.velocities[i] - moved / dt).length() < 1e-3);
    }
}

#[test]
fn pinned_vertices_and_the_centre_case() {
    let model = ClothBuilder::lab().build().unwrap();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    // A sphere centred exactly on pinned vertex 0 and on free vertex 220.
    let spheres = [
        Sphere {
            center: state.positions[0],
            radius: 0.1,
            friction: 0.0,
        },
        Sphere {
            center: state.positions[220],
            radius: 0.1,
            friction: 0.0,
        },
    ];
    let pin = state.positions[0];
    let free = state.positions[220];
    assert_eq!(project_spheres(&model, &mut state, &spheres, 0.0, 0.01), 1);
    assert_eq!(state.positions[0], pin);
    assert!((state.positions[220] - (free + Vec3A::Y * 0.1)).length() < 1e-6);
}

#[test]
fn planes_project_out_and_friction_takes_at_most_mu_times_the_normal_impulse() {
    let model = ClothBuilder::lab_grid(2).build().unwrap();
    let dt = 0.01;
    let plane = |friction| {
        Shape::Plane(Plane {
            point: Vec3A::ZERO,
            normal: Vec3A::Y,
            friction,
        })
    };
    // Vertex 0 is 0.001 below the ground, sliding along x at 1 unit/s.
    let start = |state: &mut ClothState| {
        for (x, v) in state.positions.iter_mut().zip(&mut state.velocities) {
            *x = Vec3A::new(x.x, 1.0, x.z);
            *v = Vec3A::ZERO;
        }
        state.positions[0].y = -0.001;
        state.velocities[0] = Vec3A::new(1.0, -0.1, 0.0);
    };
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    start(&mut state);
    assert_eq!(
        project_shapes(&model, &mut state, &[plane(0.0)], 0.0, dt),
        1
    );
    assert!(state.positions[0].y.abs() < 1e-7);
    assert!(
        (state.velocities[0].x - 1.0).abs() < 1e-6,
        "frictionless keeps its slide"
    );
    // Kinetic: j = depth/dt = 0.1, μ = 2 takes 0.2 of the 1.0.
    start(&mut state);
    let x0 = state.positions[0].x;
    project_shapes(&model, &mut state, &[plane(2.0)], 0.0, dt);
    assert!(
        (state.velocities[0].x - 0.8).abs() < 1e-5,
        "{}",
        state.velocities[0]
    );
    assert!((state.positions[0].x - (x0 - 0.2 * dt)).abs() < 1e-6);
    // Static: μ·j ≥ the tangential speed stops it.
    start(&mut state);
    project_shapes(&model, &mut state, &[plane(20.0)], 0.0, dt);
    assert!(state.velocities[0].x.abs() < 1e-6);
    // Thickness keeps vertices above the surface; other vertices untouched.
    start(&mut state);
    assert_eq!(
        project_shapes(&model, &mut state, &[plane(0.0)], 0.05, dt),
        1
    );
    assert!((state.positions[0].y - 0.05).abs() < 1e-6);
    assert_eq!(state.positions[1].y, 1.0);
}

#[test]
fn capsules_and_boxes_push_points_out_to_their_surface() {
    let capsule = Shape::Capsule(Capsule {
        a: Vec3A::new(-1.0, 0.0, 0.0),
        b: Vec3A::new(1.0, 0.0, 0.0),
        radius: 0.5,
        friction: 0.0,
    });
    let (n, depth) = capsule.contact(Vec3A::new(0.3, 0.2, 0.0), 0.0).unwrap();
    assert!((n - Vec3A::Y).length() < 1e-6 && (depth - 0.3).abs() < 1e-6);
    // Past an end: out from the end's centre.
    let (n, depth) = capsule.contact(Vec3A::new(1.3, 0.0, 0.0), 0.1).unwrap();
    assert!((n - Vec3A::X).length() < 1e-6 && (depth - 0.3).abs() < 1e-6);
    assert!(capsule.contact(Vec3A::new(0.0, 0.6, 0.0), 0.0).is_none());
    // On the axis: out across it, never NaN.
    let (n, depth) = capsule.contact(Vec3A::ZERO, 0.0).unwrap();
    assert!(n.is_finite() && n.dot(Vec3A::X).abs() < 1e-6 && depth == 0.5);
    // A zero-length capsule (a sphere) at its centre: up, like a sphere.
    let ball = Shape::Capsule(Capsule {
        a: Vec3A::ONE,
        b: Vec3A::ONE,
        radius: 0.5,
        friction: 0.0,
    });
    assert_eq!(ball.contact(Vec3A::ONE, 0.0), Some((Vec3A::Y, 0.5)));
    // A box rotated 45° about y: out through the nearest face.
    let (s, c) = (0.5f32.sqrt(), 0.5f32.sqrt());
    let cuboid = Shape::Cuboid(Cuboid {
        center: Vec3A::new(0.0, 1.0, 0.0),
        axes: [Vec3A::new(c, 0.0, -s), Vec3A::Y, Vec3A::new(s, 0.0, c)],
        half_extents: Vec3A::new(1.0, 0.5, 2.0),
        friction: 0.0,
    });
    let (n, depth) = cuboid.contact(Vec3A::new(0.0, 1.4, 0.0), 0.0).unwrap();
    assert!((n - Vec3A::Y).length() < 1e-6 && (depth - 0.1).abs() < 1e-6);
    let p = Vec3A::new(c, 1.0, -s) * 0.9 + Vec3A::new(0.0, 1.0, 0.0) * 0.1;
    let (n, depth) = cuboid.contact(p, 0.0).unwrap();
    let out = p + depth * n;
    assert!((depth - 0.1).abs() < 1e-5, "{depth}");
    assert!(
        cuboid.contact(out, 0.0).is_none_or(|(_, d)| d < 1e-5),
        "pushed out to {out}"
    );
    assert!(cuboid.contact(Vec3A::new(0.0, 3.0, 0.0), 0.0).is_none());
}

#[test]
fn a_sphere_with_friction_holds_what_a_frictionless_one_lets_slide() {
    // A vertex sinking into the side of a sphere while sliding along it:
    // with μ = 0 it keeps its tangential speed (the lab's equation 4), with
    // enough friction it sticks.
    let model = ClothBuilder::lab().build().unwrap();
    let dt = 0.01;
    let slide = |friction: f32| {
        let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let i = 220;
        let center = state.positions[i] - Vec3A::new(0.0, 0.99, 0.0);
        state.velocities[i] = Vec3A::new(0.5, -1.0, 0.0);
        let sphere = Sphere {
            center,
            radius: 1.0,
            friction,
        };
        assert_eq!(project_spheres(&model, &mut state, &[sphere], 0.0, dt), 1);
        let n = (state.positions[i] - center).normalize();
        let v = state.velocities[i];
        (v - v.dot(n) * n).length()
    };
    let free = slide(0.0);
    assert!((free - 0.5).abs() < 0.01, "{free}");
    assert!(slide(10.0) < 1e-5, "{}", slide(10.0));
    let some = slide(0.5);
    assert!(some > 0.0 && some < free, "{some}");
}

#[test]
fn penalty_shapes_match_their_projection_contacts_in_f32_and_f64() {
    let shapes = [
        Shape::Plane(Plane {
            point: Vec3A::new(0.0, -1.0, 0.0),
            normal: Vec3A::Y,
            friction: 0.0,
        }),
        Shape::Capsule(Capsule {
            a: Vec3A::new(-1.0, 0.0, 0.0),
            b: Vec3A::new(1.0, 0.0, 0.0),
            radius: 0.5,
            friction: 0.0,
        }),
        Shape::Cuboid(Cuboid {
            center: Vec3A::ZERO,
            axes: [Vec3A::X, Vec3A::Y, Vec3A::Z],
            half_extents: Vec3A::new(1.0, 0.5, 2.0),
            friction: 0.0,
        }),
    ];
    let points = [
        Vec3A::new(0.3, 0.2, 0.1),
        Vec3A::new(0.9, -1.2, 0.0),
        Vec3A::new(-0.2, 0.45, 1.9),
        Vec3A::new(3.0, 3.0, 3.0),
    ];
    for shape in shapes {
        let penalty = PenaltySphere::shape(shape, 100.0);
        for x in points {
            let f32_contact = shape.contact(x, 0.0);
            let f64_contact = shape.contact_f64(x.as_dvec3(), 0.0);
            assert_eq!(
                f32_contact.is_some(),
                f64_contact.is_some(),
                "{shape:?} {x}"
            );
            if let (Some((n, d)), Some((n64, d64))) = (f32_contact, f64_contact) {
                assert!((n.as_dvec3() - n64).length() < 1e-6 && (f64::from(d) - d64).abs() < 1e-6);
                let c = penalty.contact(x).unwrap();
                assert_eq!(c.force, n * (100.0 * d));
                // The tangential term: none on flat faces, the axis
                // distance on a capsule.
                match shape {
                    Shape::Capsule(_) => assert!((c.distance - (0.5 - d)).abs() < 1e-6),
                    _ => assert_eq!(c.distance, f32::INFINITY),
                }
            }
            assert!(penalty.contact(Vec3A::splat(9.0)).is_none());
        }
    }
    // The near test finds a segment that passes through the plane.
    let plane = PenaltySphere::shape(shapes[0], 1.0);
    assert!(plane.near_segment(Vec3A::new(0.0, 1.0, 0.0), Vec3A::new(0.0, -3.0, 0.0)));
    assert!(!plane.near_segment(Vec3A::new(0.0, 1.0, 0.0), Vec3A::new(0.0, 0.5, 0.0)));
    // Grown by a particle radius: the plane rises.
    let grown = plane.grown(0.25);
    assert!(grown.contact(Vec3A::new(0.0, -0.8, 0.0)).is_some());
    assert!(plane.contact(Vec3A::new(0.0, -0.8, 0.0)).is_none());
}

mod self_collision {
    use bevy::math::{Affine3A, Vec3, Vec3A};

    use crate::collision::self_contact::{
        AFTER_STEP_PASSES, IntersectionCheck, Pass, SETTLED, SelfCollisionInput, SelfContacts,
        count_intersections, settle,
    };
    use crate::collision::{SelfCollision, SelfCollisionError};
    use crate::model::{ClothBuilder, ClothModel, ClothState};
    use crate::solver::StepParams;
    use crate::solver::implicit::ImplicitSolver;
    use crate::solver::{Method, max_stretch};

    /// A flat 1 m sheet of `n²` vertices in the xz-plane, 1 kg a vertex.
    fn sheet(n: usize) -> ClothModel {
        ClothBuilder::grid(n, n, Vec3::ZERO, Vec3::Z, Vec3::X)
            .build()
            .unwrap()
    }

    #[test]
    fn bad_settings_are_refused_with_their_reason() {
        let model = sheet(11);
        let good = SelfCollision::for_model(&model);
        assert_eq!(good.validate(&model), Ok(()));
        assert!((good.thickness - 0.09).abs() < 1e-4, "{}", good.thickness);
        for t in [0.0, -0.01, f32::NAN, f32::INFINITY] {
            let sc = SelfCollision {
                thickness: t,
                ..good
            };
            assert!(matches!(
                sc.validate(&model),
                Err(SelfCollisionError::Thickness(_))
            ));
        }
        let thick = SelfCollision {
            thickness: 0.1,
            ..good
        };
        assert!(matches!(
            thick.validate(&model),
            Err(SelfCollisionError::ThickerThanEdges { .. })
        ));
        for f in [-0.1, f32::NAN] {
            let sc = SelfCollision {
                friction: f,
                ..good
            };
            assert!(matches!(
                sc.validate(&model),
                Err(SelfCollisionError::Friction(_))
            ));
            assert!(
                sc.validate(&model)
                    .unwrap_err()
                    .to_string()
                    .contains("friction")
            );
        }
    }

    #[test]
    fn the_exact_check_counts_an_edge_through_the_sheet_and_nothing_at_rest() {
        let model = sheet(7);
        let mut check = IntersectionCheck::default();
        let mut x = ClothState::at_rest(&model, &Affine3A::IDENTITY).positions;
        assert_eq!(count_intersections(&model, &x, &mut check), 0);
        // Two neighbours of one corner, put above and below the middle of a
        // triangle far from them: the edge between them passes through it.
        let (a, b) = (0, 1);
        let middle = (x[24] + x[25] + x[31]) / 3.0;
        x[a] = middle + Vec3A::Y * 0.3;
        x[b] = middle - Vec3A::Y * 0.3;
        assert!(count_intersections(&model, &x, &mut check) >= 1);
        // Lying in the sheet's plane is touching, not passing.
        x[a] = middle + Vec3A::X * 0.01;
        x[b] = middle - Vec3A::X * 0.01;
        assert_eq!(count_intersections(&model, &x, &mut check), 0);
    }

    /// Vertex 60 falls from twice the thickness above vertex 0's place to
    /// a millimetre above it within one step: the pair found at the step's
    /// start, resolved at its end.
    fn fold_onto_vertex_0(model: &ClothModel, contacts: &mut SelfContacts) -> [Vec<Vec3A>; 2] {
        let sc = SelfCollision::for_model(model);
        let dt = 1.0 / 60.0;
        let mut start = ClothState::at_rest(model, &Affine3A::IDENTITY).positions;
        start[60] = start[0] + Vec3A::Y * (2.0 * sc.thickness);
        let mut v = vec![Vec3A::ZERO; start.len()];
        v[60] = -Vec3A::Y * ((2.0 * sc.thickness - 0.001) / dt);
        contacts.find(model, &start, &v, dt, SelfCollisionInput::alone(sc), 0.0);
        let mut end = start.clone();
        end[60] = end[0] + Vec3A::Y * 0.001;
        [start, end]
    }

    #[test]
    fn two_vertices_too_close_are_pushed_to_the_thickness_and_pins_stay() {
        let model = sheet(11);
        let sc = SelfCollision::for_model(&model);
        let (a, b) = (0usize, 60usize);
        let mut contacts = SelfContacts::default();
        let [start, mut x] = fold_onto_vertex_0(&model, &mut contacts);
        assert!(contacts.pair_count() > 0);
        let end = x.clone();
        let touching = contacts.resolve(&model, &mut x, |i| start[i], 1.0);
        assert_eq!(touching, 1);
        assert!((x[a].distance(x[b]) - sc.thickness).abs() < 1e-5);
        // Equal masses share the push along y.
        assert!((x[a].y + x[b].y - end[a].y - end[b].y).abs() < 1e-6);
        // With vertex 0 pinned, only the other moves.
        let mut model = model;
        model.set_pins(vec![0]).unwrap();
        let [start, mut x] = fold_onto_vertex_0(&model, &mut contacts);
        contacts.resolve(&model, &mut x, |i| start[i], 1.0);
        assert_eq!(x[a], start[a]);
        assert!((x[b].y - start[a].y - sc.thickness).abs() < 1e-5);
    }

    #[test]
    fn the_passes_after_the_step_end_once_one_pushes_nothing_deeper_than_settled() {
        let run = |script: &[(u32, f32)]| {
            let mut calls = 0;
            let first = settle(|| {
                let (touching, deepest) = script[calls.min(script.len() - 1)];
                calls += 1;
                Pass { touching, deepest }
            });
            (first, calls)
        };
        // The third pass pushes less than SETTLED deep: no fourth.
        let settling = [(10, 0.5), (8, 10.0 * SETTLED), (6, 0.5 * SETTLED), (4, 0.0)];
        assert_eq!(run(&settling), (10, 3));
        // Nothing touching: one pass.
        assert_eq!(run(&[(0, 0.0)]), (0, 1));
        // Still deep: every pass, and the first pass's count.
        assert_eq!(run(&[(7, 0.5)]), (7, AFTER_STEP_PASSES as usize));
    }

    #[test]
    fn the_substep_list_resolves_as_every_pair_does_bit_for_bit() {
        let model = sheet(16);
        substeps_resolve_as_every_pair_does(&model, SelfCollision::for_model(&model));
    }

    #[test]
    fn a_thin_settings_substep_lists_resolve_as_every_pair_does_bit_for_bit() {
        // Vertex–triangle and edge pairs too: a push of any kind that moves
        // a vertex beyond the lists' reach goes on over every pair after it.
        let model = sheet(16);
        let edge = 1.0 / 15.0;
        let sc = SelfCollision {
            thickness: 0.3 * edge,
            ..SelfCollision::for_model(&model)
        };
        let every = substeps_resolve_as_every_pair_does(&model, sc);
        assert!(every.face_pair_count() > 0 && every.edge_pair_count() > 0);
    }

    /// A sheet squeezed to 0.3 of its size and crumpled (many pairs),
    /// moved a little in every substep and a lot in every sixteenth:
    /// `resolve_substep` and `resolve` agree bit for bit. Returns the
    /// contacts of `resolve`.
    fn substeps_resolve_as_every_pair_does(model: &ClothModel, sc: SelfCollision) -> SelfContacts {
        let model = model.clone();
        let mut seed = 3;
        let start: Vec<Vec3A> = ClothState::at_rest(&model, &Affine3A::IDENTITY)
            .positions
            .iter()
            .map(|&p| p * 0.3 + Vec3A::Y * (0.01 * crate::testing::noise(&mut seed).y))
            .collect();
        let v = vec![Vec3A::ZERO; start.len()];
        let mut every = SelfContacts::default();
        let input = SelfCollisionInput::alone(sc);
        every.find(&model, &start, &v, 1.0 / 60.0, input, 0.01);
        let mut listed = every.clone();
        let (mut x, mut y) = (start.clone(), start.clone());
        let (mut touching, mut fewest) = (0, usize::MAX);
        for substep in 1..=64 {
            let jolt = sc.thickness * if substep % 16 == 0 { 0.3 } else { 0.002 };
            for (x, y) in x.iter_mut().zip(&mut y) {
                let d = crate::testing::noise(&mut seed) * jolt;
                *x += d;
                *y += d;
            }
            let progress = substep as f32 / 64.0;
            let a = every.resolve(&model, &mut x, |i| start[i], progress);
            let b = listed.resolve_substep(&model, &mut y, |i| start[i], [0.0, progress]);
            assert_eq!(a, b, "substep {substep}");
            assert_eq!(x, y, "substep {substep}");
            touching += a;
            fewest = fewest.min(listed.active_pairs());
        }
        assert!(touching > 0);
        assert!(
            fewest < every.pair_count(),
            "{fewest} of {} pairs",
            every.pair_count()
        );
        every
    }

    /// The grid's pairs are those of a test of every pair of vertices (the
    /// pairs' definition, written out here on its own): a sheet squeezed
    /// and crumpled into many layers, falling, its vertices moving every
    /// way, a few fast and a few pinned.
    #[test]
    fn the_grid_finds_the_pairs_a_test_of_every_pair_finds() {
        let model = ClothBuilder::grid(24, 24, Vec3::ZERO, Vec3::Z, Vec3::X)
            .with_pins([0, 23])
            .build()
            .unwrap();
        let sc = SelfCollision::for_model(&model);
        let (dt, slack) = (1.0 / 60.0, 0.004);
        let mut seed = 11;
        let rest = ClothState::at_rest(&model, &Affine3A::IDENTITY).positions;
        let x: Vec<Vec3A> = rest
            .iter()
            .map(|&p| p * Vec3A::new(0.25, 1.0, 0.3) + crate::testing::noise(&mut seed) * 0.03)
            .collect();
        let v: Vec<Vec3A> = (0..x.len())
            .map(|i| {
                let fast = if i % 97 == 5 { 2.5 } else { 0.5 };
                // Falling and carried as a whole too (the grid's frame).
                crate::testing::noise(&mut seed) * fast + Vec3A::new(0.4, -1.5, 0.0)
            })
            .collect();
        let mut contacts = SelfContacts::default();
        contacts.find(&model, &x, &v, dt, SelfCollisionInput::alone(sc), slack);
        let topology = model.topology();
        let (adjacency, springs) = (topology.adjacency(), topology.springs());
        let half = 0.5 * sc.thickness;
        let margin = |i: usize| half + slack + 0.25 * v[i].length() * dt;
        let mut every = Vec::new();
        for a in 0..x.len() {
            for b in a + 1..x.len() {
                let linked = adjacency.of(a).iter().any(|inc| {
                    inc.other as usize == b
                        && springs[inc.spring as usize].kind != crate::model::SpringKind::Bend
                });
                let min = sc
                    .thickness
                    .min(topology.rest_positions()[a].distance(topology.rest_positions()[b]));
                if linked || (model.pinned()[a] && model.pinned()[b]) || min <= 0.0 {
                    continue;
                }
                let (d, dd) = (x[b] - x[a], (v[b] - v[a]) * dt);
                let t = if dd.length_squared() > 0.0 {
                    (-d.dot(dd) / dd.length_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let approach = (d + t * dd).length();
                if approach <= min + margin(a) - half + margin(b) - half {
                    every.push((a as u32, b as u32, min));
                }
            }
        }
        assert!(every.len() > 1000, "{} pairs", every.len());
        assert_eq!(contacts.skipped(), 0);
        assert_eq!(contacts.pair_list(), every);
    }

    #[test]
    fn a_vertex_flying_off_to_infinity_is_left_out_without_a_panic() {
        let model = sheet(5);
        let sc = SelfCollision::for_model(&model);
        let x = ClothState::at_rest(&model, &Affine3A::IDENTITY).positions;
        let mut v = vec![Vec3A::ZERO; x.len()];
        v[3] = Vec3A::new(f32::INFINITY, 0.0, f32::NAN);
        let mut contacts = SelfContacts::default();
        contacts.find(
            &model,
            &x,
            &v,
            1.0 / 60.0,
            SelfCollisionInput::alone(sc),
            0.0,
        );
        assert_eq!(contacts.skipped(), 1);
        let mut check = IntersectionCheck::default();
        let mut y = x.clone();
        y[3] = Vec3A::splat(f32::INFINITY);
        count_intersections(&model, &y, &mut check);
    }

    /// The crumpling sheet of the `stiff` test, under Chebyshev with the
    /// self-collision after the step: far fewer edges through the cloth.
    #[test]
    fn after_the_step_it_helps_every_method() {
        let n = 16;
        let model = ClothBuilder::grid(
            n,
            n,
            Vec3::new(0.0, 0.02, 0.0),
            Vec3::new(0.0, 1.0, 0.15),
            Vec3::new(1.0, 0.02, 0.0),
        )
        .with_total_mass(2.56)
        .build()
        .unwrap();
        let params = StepParams {
            dt: 1.0 / 60.0,
            stiffness: crate::solver::SpringStiffness::uniform(400.0),
            ..StepParams::LAB
        };
        let ground = crate::collision::Shape::Plane(crate::collision::Plane {
            point: Vec3A::ZERO,
            normal: Vec3A::Y,
            friction: 0.5,
        });
        let method = ImplicitSolver::chebyshev(32, 0.9);
        let run = |sc: Option<SelfCollision>| {
            let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
            let (mut ws, mut contacts, mut check) = Default::default();
            let mut before = state.clone();
            let (mut worst, mut stretch) = (0, 0.0f32);
            for _ in 0..180 {
                before.copy_from(&state);
                method
                    .step(&model, &mut state, &params, &[], &mut ws)
                    .unwrap();
                crate::collision::project_shapes(&model, &mut state, &[ground], 0.0, 1.0 / 60.0);
                if let Some(sc) = sc {
                    SelfContacts::resolve_after_step(
                        &mut contacts,
                        &model,
                        &mut state,
                        &before,
                        &params,
                        SelfCollisionInput::alone(sc),
                    );
                }
                worst = worst.max(count_intersections(&model, &state.positions, &mut check));
                stretch = stretch.max(max_stretch(&model, &state.positions));
            }
            assert!(state.positions.iter().all(|p| p.is_finite()));
            (worst, stretch)
        };
        let (without, _) = run(None);
        let (with, stretch) = run(Some(SelfCollision::for_model(&model)));
        println!("chebyshev: {without} without, {with} with, stretch {stretch}");
        assert!(without > 0);
        assert!(with * 4 < without, "{with} with against {without} without");
    }
}

mod layers;
mod untangle;
