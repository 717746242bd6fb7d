//! Edges already through a triangle taken back out, and the thin settings' pairs
//! keeping layers and crossing edges apart.

use bevy::math::{Affine3A, Vec3, Vec3A};

use crate::collision::SelfCollision;
use crate::collision::self_contact::{
    FOLLOW_RINGS, IntersectionCheck, SelfCollisionInput, count_crossings, count_intersections,
    untangle, untangle_between,
};
use crate::model::{ClothBuilder, ClothMaterial, ClothModel, ClothState};
use crate::solver::xpbd::{XpbdSolver, XpbdWorkspace};
use crate::solver::{Method, StepParams};

/// Two 1 m layers of `n²` cotton in one cloth, built 20 cm apart (the
/// second above the first).
fn two_layers(n: u32) -> ClothModel {
    crate::testing::two_layers(n, 1.0, 0.2)
}

/// `stiff` with `sc`, no gravity, one 60 Hz step of `model` at `state`.
fn step(model: &ClothModel, state: &mut ClothState, sc: SelfCollision, ws: &mut XpbdWorkspace) {
    let params = StepParams {
        dt: 1.0 / 60.0,
        stiffness: ClothMaterial::COTTON.spring_stiffness(model),
        gravity: Vec3::ZERO,
        ..StepParams::LAB
    };
    let input = crate::testing::self_colliding(model, &params, sc);
    XpbdSolver::STIFF.step_with(input, state, ws).unwrap();
}

/// The two layers 2 thicknesses apart, and one vertex of the upper
/// poked through the lower (a fifth of the thickness below it, over
/// the middle of one of its triangles), as a step that went wrong
/// leaves it: the model, the thickness, the positions and the poked
/// vertex.
pub(super) fn poked(n: u32) -> (ClothModel, SelfCollision, Vec<Vec3A>, usize) {
    let model = two_layers(n);
    let sc = SelfCollision::for_model(&model);
    let mut x = ClothState::at_rest(&model, &Affine3A::IDENTITY).positions;
    let nn = (n * n) as usize;
    for p in &mut x[nn..] {
        p.y = 2.0 * sc.thickness;
    }
    let h = 1.0 / (n - 1) as f32;
    let below = 7 * n as usize + 7;
    let poked = nn + below;
    x[poked] = x[below] + Vec3A::new(h / 3.0, -0.2 * sc.thickness, h / 3.0);
    (model, sc, x, poked)
}

/// Vertex–vertex self-collision holds an edge already through a
/// triangle where it is (its pushes keep the end on its side):
/// `untangle` takes the end that went through back to the other end's
/// side, the triangle's corners taking their share, and touches
/// nothing else.
#[test]
fn untangle_takes_an_edge_through_a_triangle_back_out() {
    let (model, sc, mut x, poked) = poked(16);
    let start = x.clone();
    let mut check = IntersectionCheck::default();
    assert!(count_intersections(&model, &x, &mut check) > 0);
    let found = untangle(&model, &mut x, &mut check, sc.thickness);
    assert!(found > 0);
    assert_eq!(count_intersections(&model, &x, &mut check), 0);
    // Back above the lower layer (at y = 0), within the thickness.
    assert!(
        x[poked].y > 0.0 && x[poked].y < sc.thickness,
        "{}",
        x[poked].y
    );
    // Only the poked vertex and one lower triangle's corners moved,
    // along y (the triangle's normal), the corners down.
    let moved: Vec<usize> = (0..x.len()).filter(|&i| x[i] != start[i]).collect();
    assert!(moved.contains(&poked) && moved.len() <= 4, "{moved:?}");
    for &i in &moved {
        let d = x[i] - start[i];
        assert!(d.x.abs() < 1e-6 && d.z.abs() < 1e-6, "{d}");
        assert!(i == poked || x[i].y < start[i].y);
    }
    // Nothing left to do.
    let again = x.clone();
    assert_eq!(untangle(&model, &mut x, &mut check, sc.thickness), 0);
    assert_eq!(x, again);
}

/// Two cloths, one sheet each, one vertex of the upper poked through
/// the lower (as a ball that pressed it through within a step leaves
/// it): `untangle_between` takes it back out, moving only vertices
/// near the poke, each by less than the thickness (with the rings around
/// the moved ends following, or not).
#[test]
fn untangle_between_takes_an_edge_through_another_cloth_back_out() {
    let n = 16u32;
    let sheet = |y: f32| {
        let h = 1.0 / (n - 1) as f32;
        ClothBuilder::grid(
            n as usize,
            n as usize,
            Vec3::new(0.0, y, 0.0),
            Vec3::new(1.0, y, 0.0),
            Vec3::new(0.0, y, 1.0),
        )
        .with_material(ClothMaterial::COTTON)
        .build()
        .map(|m| (m, h))
        .unwrap()
    };
    let ((lower, h), (upper, _)) = (sheet(0.0), sheet(0.05));
    let sc = SelfCollision::for_model(&lower);
    // Either cloth first, following or not.
    for (swap, follow) in [false, true]
        .into_iter()
        .flat_map(|s| [(s, [false; 2]), (s, [true; 2])])
    {
        let mut a = ClothState::at_rest(&lower, &Affine3A::IDENTITY).positions;
        let mut b = ClothState::at_rest(&upper, &Affine3A::IDENTITY).positions;
        let below = 7 * n as usize + 7;
        b[below] = a[below] + Vec3A::new(h / 3.0, -0.2 * sc.thickness, h / 3.0);
        let (start_a, start_b) = (a.clone(), b.clone());
        let mut check = IntersectionCheck::default();
        assert!(count_crossings((&lower, &a), (&upper, &b), &mut check) > 0);
        let mut untangle = |a: &mut Vec<Vec3A>, b: &mut Vec<Vec3A>| {
            if swap {
                untangle_between((&upper, b), (&lower, a), &mut check, sc.thickness, follow)
            } else {
                untangle_between((&lower, a), (&upper, b), &mut check, sc.thickness, follow)
            }
        };
        assert!(untangle(&mut a, &mut b) > 0);
        // Nothing left to do.
        assert_eq!(untangle(&mut a, &mut b), 0);
        assert_eq!(count_crossings((&lower, &a), (&upper, &b), &mut check), 0);
        assert!(
            b[below].y > a[below].y && b[below].y < sc.thickness,
            "{swap}: {} over {}",
            b[below].y,
            a[below].y
        );
        // Small moves near the poke only: the edges' ends, the triangles'
        // corners and the rings that follow the ends.
        let rings = if follow[0] { FOLLOW_RINGS as f32 } else { 0.0 };
        let near = (3.0 + rings * core::f32::consts::SQRT_2) * h;
        for (x, start) in [(&a, &start_a), (&b, &start_b)] {
            for (p, q) in x.iter().zip(start) {
                assert!(p.distance(*q) < sc.thickness, "{swap}: {q} moved to {p}");
                if p != q {
                    assert!(p.distance(a[below]) < near, "{swap}: {q} moved to {p}");
                }
            }
        }
    }
}

/// The same poke stepped with `stiff`: the edges through the sheet are
/// out after the first step and stay out.
#[test]
fn an_edge_poked_through_the_cloth_is_taken_back_out_in_a_step() {
    let (model, sc, x, _) = poked(16);
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    state.positions = x;
    let mut check = IntersectionCheck::default();
    let mut ws = XpbdWorkspace::default();
    for _ in 0..60 {
        step(&model, &mut state, sc, &mut ws);
        assert_eq!(count_intersections(&model, &state.positions, &mut check), 0);
    }
    assert!(state.positions.iter().all(|p| p.is_finite()));
}

/// Two layers of 16² cotton started a millimetre apart (the upper moved
/// down whole: the springs are content), far inside the thickness:
/// stepped with `stiff` without gravity, they are parted gently, never
/// launched.
#[test]
fn a_cloth_that_starts_interpenetrated_is_parted_without_a_launch() {
    let n = 16u32;
    let model = two_layers(n);
    let sc = SelfCollision::for_model(&model);
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let nn = (n * n) as usize;
    for p in &mut state.positions[nn..] {
        p.y = 0.001;
    }
    let mut ws = XpbdWorkspace::default();
    let mut fastest = 0.0f32;
    for _ in 0..60 {
        step(&model, &mut state, sc, &mut ws);
        let speed = state
            .velocities
            .iter()
            .map(|v| v.length())
            .fold(0.0, f32::max);
        fastest = fastest.max(speed);
    }
    assert!(state.positions.iter().all(|p| p.is_finite()));
    // A quarter of the thickness per step at 60 Hz is about 0.5 m/s.
    assert!(fastest < 1.0, "launched at {fastest} m/s");
    // The layers have come apart to about the thickness.
    let gap = (0..nn)
        .map(|k| state.positions[nn + k].distance(state.positions[k]))
        .fold(f32::INFINITY, f32::min);
    assert!(
        gap > 0.8 * sc.thickness,
        "layers {gap} apart, thickness {}",
        sc.thickness
    );
}

/// A thin setting (0.3 of the edges): the upper layer, over the middle
/// of the lower one's triangles (no vertex within the thickness of
/// another), moves down by three thicknesses in one step, through the
/// lower layer. Vertex pairs cannot see it; the vertex–triangle pairs
/// keep it on its side, a thickness apart, and a default setting
/// (above [`FACES_BELOW`]) finds none.
#[test]
fn a_thin_setting_keeps_a_layer_from_passing_through_another() {
    use crate::collision::self_contact::{FACES_BELOW, SelfContacts};
    let n = 16;
    let model = two_layers(n);
    let h = 1.0 / (n - 1) as f32;
    let mut sc = SelfCollision::for_model(&model);
    assert!((sc.thickness - 0.9 * h).abs() < 1e-6);
    let mut contacts = SelfContacts::default();
    let start_at = |thickness: f32| {
        let mut x = ClothState::at_rest(&model, &Affine3A::IDENTITY).positions;
        let nn = (n * n) as usize;
        for p in &mut x[nn..] {
            *p = Vec3A::new(p.x + h / 3.0, 2.0 * thickness, p.z + h / 3.0);
        }
        // Its middle only, so that its edges cross the lower layer.
        let v = x
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let middle = (p.x - 0.5).abs() < 0.25 && (p.z - 0.5).abs() < 0.25;
                Vec3A::new(
                    0.0,
                    -3.0 * thickness * 60.0 * f32::from(u8::from(i >= nn && middle)),
                    0.0,
                )
            })
            .collect::<Vec<_>>();
        (x, v)
    };
    let dt = 1.0 / 60.0;
    let (x, v) = start_at(sc.thickness);
    contacts.find(&model, &x, &v, dt, SelfCollisionInput::alone(sc), 0.0);
    assert_eq!(contacts.face_pair_count(), 0, "0.9 > {FACES_BELOW}");
    sc.thickness = 0.3 * h;
    let (start, v) = start_at(sc.thickness);
    contacts.find(&model, &start, &v, dt, SelfCollisionInput::alone(sc), 0.0);
    assert!(contacts.face_pair_count() > 0);
    let mut x: Vec<Vec3A> = start.iter().zip(&v).map(|(&x, &v)| x + v * dt).collect();
    let mut check = IntersectionCheck::default();
    let through = count_intersections(&model, &x, &mut check);
    assert!(through > 100, "the step's motion passes through: {through}");
    for _ in 0..4 {
        contacts.resolve(&model, &mut x, |i| start[i], 1.0);
    }
    assert_eq!(count_intersections(&model, &x, &mut check), 0);
    // Every upper vertex is above the lower vertex nearest it.
    let nn = (n * n) as usize;
    let lowest_gap = x[nn..]
        .iter()
        .map(|p| {
            let (j, i) = ((p.x / h).round() as usize, (p.z / h).round() as usize);
            p.y - x[(i.min(n as usize - 1)) * n as usize + j.min(n as usize - 1)].y
        })
        .fold(f32::INFINITY, f32::min);
    assert!(
        lowest_gap > 0.5 * sc.thickness,
        "{lowest_gap} against {}",
        sc.thickness
    );
}

/// Two strips of one cloth crossing like an X, the second coming down
/// through the first in one step, tilted, so that its long edges pass
/// through the first's triangles while no vertex of either comes over
/// a triangle of the other: the vertex–triangle pairs see nothing, and
/// the edge–edge pairs keep the second strip's edges above the first's.
#[test]
fn a_thin_setting_keeps_two_edges_from_passing_through_each_other() {
    use crate::collision::self_contact::SelfContacts;
    let w = 0.1;
    let positions = vec![
        // Along x, in y = 0, z in [0, w].
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(-1.0, 0.0, w),
        Vec3::new(1.0, 0.0, w),
        // Along z, x in [0, w], above.
        Vec3::new(0.0, 0.06, -1.0),
        Vec3::new(w, 0.06, -1.0),
        Vec3::new(0.0, 0.06, 1.0),
        Vec3::new(w, 0.06, 1.0),
    ];
    let indices = vec![0, 2, 1, 1, 2, 3, 4, 6, 5, 5, 6, 7];
    let model = ClothBuilder::from_triangles(positions, indices)
        .with_material(ClothMaterial::COTTON)
        .build()
        .unwrap();
    let sc = SelfCollision {
        thickness: 0.3 * w,
        friction: 0.3,
    };
    sc.validate(&model).unwrap();
    let start = ClothState::at_rest(&model, &Affine3A::IDENTITY).positions;
    // The second strip's far end comes down so that its edges cross
    // y = 0 at z = w/2, over the first strip.
    let dt = 1.0 / 60.0;
    let drop = 2.0 * 0.06 / (1.0 + 0.5 * w);
    let v: Vec<Vec3A> = (0..8)
        .map(|i| Vec3A::new(0.0, if i >= 6 { -drop / dt } else { 0.0 }, 0.0))
        .collect();
    let mut contacts = SelfContacts::default();
    contacts.find(&model, &start, &v, dt, SelfCollisionInput::alone(sc), 0.0);
    assert_eq!(contacts.face_pair_count(), 0);
    assert!(contacts.edge_pair_count() > 0);
    let mut x: Vec<Vec3A> = start.iter().zip(&v).map(|(&x, &v)| x + v * dt).collect();
    let mut check = IntersectionCheck::default();
    let through = count_intersections(&model, &x, &mut check);
    assert!(through > 0, "the step's motion passes through: {through}");
    for _ in 0..4 {
        contacts.resolve(&model, &mut x, |i| start[i], 1.0);
    }
    assert_eq!(count_intersections(&model, &x, &mut check), 0);
    // The second strip's long edges are above the first's at z = w/2.
    let at = |a: usize, b: usize, z: f32| {
        let t = (z - x[a].z) / (x[b].z - x[a].z);
        x[a].lerp(x[b], t).y
    };
    for (a, b) in [(4, 6), (5, 7)] {
        let y = at(a, b, 0.5 * w);
        assert!(y > 0.0, "edge {a}–{b} at {y}");
    }
}
