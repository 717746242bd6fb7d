use bevy::math::{Affine3A, Vec3, Vec3A};
use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};

use super::*;
use crate::collision::PenaltySphere;
use crate::methods::{AnyMethod, AnyWorkspace};
use crate::model::{ClothBuilder, ClothModel, ClothState};
use crate::solver::implicit::ImplicitSolver;
use crate::solver::pbd::PbdSolver;
use crate::solver::projective::ProjectiveSolver;
use crate::solver::symplectic::SymplecticSolver;
use crate::solver::{Method, PARALLEL_MIN, Simd, SpringStiffness, StepParams, StepReport};
use crate::testing::next_u64;

/// The implicit methods the stencil kernels run.
const METHODS: [ImplicitSolver; 3] = [
    ImplicitSolver::jacobi(32),
    ImplicitSolver::chebyshev(32, 0.995),
    ImplicitSolver::chebyshev_auto(32),
];

fn families(model: &ClothModel) -> Option<usize> {
    model.topology().stencil().map(Stencil::families)
}

/// `steps` steps from `start`; the state and the last report.
fn run(
    method: ImplicitSolver,
    model: &ClothModel,
    start: &ClothState,
    params: &StepParams,
    spheres: &[PenaltySphere],
    steps: usize,
) -> (ClothState, StepReport) {
    run_any(
        AnyMethod::Implicit(method),
        model,
        start,
        params,
        spheres,
        steps,
    )
}

/// As [`run`], for any method.
fn run_any(
    method: AnyMethod,
    model: &ClothModel,
    start: &ClothState,
    params: &StepParams,
    spheres: &[PenaltySphere],
    steps: usize,
) -> (ClothState, StepReport) {
    let mut state = start.clone();
    let mut ws = AnyWorkspace::default();
    let mut report = None;
    for _ in 0..steps {
        let r = method
            .step(model, &mut state, params, spheres, &mut ws)
            .unwrap();
        report = Some(r);
    }
    (state, report.unwrap())
}

fn bits(state: &ClothState) -> Vec<[u32; 3]> {
    state
        .positions
        .iter()
        .chain(&state.velocities)
        .map(|v| v.to_array().map(f32::to_bits))
        .collect()
}

/// The largest difference of any coordinate of `p` and `q`.
fn apart(p: &[Vec3A], q: &[Vec3A]) -> f32 {
    p.iter()
        .zip(q)
        .map(|(p, q)| (*p - *q).abs().max_element())
        .fold(0.0f32, f32::max)
}

/// The lab cloth after 20 Chebyshev steps: swinging, every spring stretched
/// differently.
fn swinging(model: &ClothModel) -> ClothState {
    let start = ClothState::at_rest(model, &Affine3A::IDENTITY);
    run(METHODS[1], model, &start, &StepParams::LAB, &[], 20).0
}

#[test]
fn the_builders_grids_form_a_stencil_and_a_scattered_mesh_does_not() {
    // The lab's triangle grid: right, down and one diagonal.
    assert_eq!(families(&ClothBuilder::lab().build().unwrap()), Some(3));
    // The assignment's: stretch (2), shear (2) and bending (2).
    assert_eq!(
        families(&ClothBuilder::assignment(10, 10).build().unwrap()),
        Some(6)
    );
    // A grid numbered at random: its springs join vertices at every
    // distance, so the families are far more than eight.
    let side = 12u32;
    let mut order: Vec<u32> = (0..side * side).collect();
    let mut seed = 7u64;
    for i in (1..order.len()).rev() {
        order.swap(i, (next_u64(&mut seed) >> 33) as usize % (i + 1));
    }
    let mut positions = vec![Vec3::ZERO; order.len()];
    for (v, &new) in order.iter().enumerate() {
        let v = v as u32;
        positions[new as usize] = Vec3::new((v % side) as f32, 0.0, (v / side) as f32);
    }
    let mut indices = Vec::new();
    for r in 0..side - 1 {
        for c in 0..side - 1 {
            let at = |r: u32, c: u32| order[(r * side + c) as usize];
            indices.extend([at(r, c), at(r + 1, c), at(r, c + 1)]);
            indices.extend([at(r, c + 1), at(r + 1, c), at(r + 1, c + 1)]);
        }
    }
    // (The builder renumbers it for locality, breadth first: close in
    // memory, but not a row-by-row grid.)
    let model = ClothBuilder::from_triangles(positions, indices)
        .build()
        .unwrap();
    assert_eq!(families(&model), None);
    // It steps on the general kernels.
    let start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let (state, _) = run(METHODS[0], &model, &start, &StepParams::LAB, &[], 3);
    assert!(state.positions.iter().all(|p| p.is_finite()));
}

#[test]
fn stencil_kernels_agree_with_the_general_kernels_within_rounding() {
    let lab = ClothBuilder::lab().build().unwrap();
    let assignment = ClothBuilder::assignment(12, 12).build().unwrap();
    let sphere = PenaltySphere::sphere(Vec3A::new(0.0, -3.0, 0.0), 3.0, 10_000.0);
    // Runs where the two kernels' bits differ: the stencil ones did run.
    let mut differing = 0;
    for (name, model, params) in [
        ("lab", &lab, StepParams::LAB),
        (
            "assignment",
            &assignment,
            StepParams {
                dt: 0.005,
                ..StepParams::LAB
            },
        ),
    ] {
        assert!(families(model).is_some(), "{name}");
        let start = swinging(model);
        for spheres in [&[][..], &[sphere]] {
            for method in METHODS {
                let general = StepParams {
                    stencil: false,
                    ..params
                };
                let (a, ra) = run(method, model, &start, &params, spheres, 3);
                let (b, rb) = run(method, model, &start, &general, spheres, 3);
                let scale = model.size();
                let worst = apart(&a.positions, &b.positions);
                assert!(
                    worst <= 2e-5 * scale,
                    "{name}, {} with {} spheres: positions {worst} apart",
                    method.name(),
                    spheres.len()
                );
                // They did move, and differ only by rounding.
                assert_ne!(bits(&a), bits(&start));
                differing += usize::from(bits(&a) != bits(&b));
                // The error estimate too (a ratio of small differences, so
                // rounding moves it more than the positions).
                let (ea, eb) = (ra.relative_error.unwrap(), rb.relative_error.unwrap());
                assert!(
                    (ea - eb).abs() <= 0.05 * eb.max(1e-3),
                    "{name}, {}: relative errors {ea} and {eb}",
                    method.name()
                );
                // Pinned vertices never move.
                for (i, &pinned) in model.pinned().iter().enumerate() {
                    if pinned {
                        assert_eq!(a.positions[i], start.positions[i]);
                    }
                }
            }
        }
    }
    assert!(differing > 0);
}

#[test]
fn stencil_kernels_give_the_same_bits_at_every_simd_level_run_after_run_and_on_any_thread_count() {
    ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
    // Large enough for the parallel chunks (32768 vertices and more).
    let model = ClothBuilder::lab_grid(185).build().unwrap();
    assert!(model.vertex_count() >= PARALLEL_MIN);
    let start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    // With and without a penalty sphere the sheet falls into.
    let sphere = PenaltySphere::sphere(Vec3A::new(0.0, -3.0, 0.0), 3.0, 10_000.0);
    // The implicit methods, PBD (its own stencil kernels) and symplectic
    // Euler (the spring pass and the term sums).
    let methods = METHODS
        .map(AnyMethod::Implicit)
        .into_iter()
        .chain([PBD, SYMPLECTIC, PD]);
    for (method, spheres) in
        methods.flat_map(|m| [(m, &[][..]), (m, std::slice::from_ref(&sphere))])
    {
        let of = |simd, parallel| {
            let params = StepParams {
                simd,
                parallel,
                ..StepParams::LAB
            };
            let (state, report) = run_any(method, &model, &start, &params, spheres, 2);
            (bits(&state), report.residual.map(f32::to_bits))
        };
        let reference = of(Simd::Baseline, false);
        assert_eq!(of(Simd::Baseline, false), reference, "run after run");
        for level in Simd::supported().into_iter().chain([Simd::Auto]) {
            for parallel in [false, true] {
                assert!(
                    of(level, parallel) == reference,
                    "{} at {level:?}, parallel {parallel}",
                    method.name()
                );
            }
        }
    }
}

#[test]
fn a_reused_workspace_follows_a_change_of_stiffness_or_cloth() {
    let lab = ClothBuilder::lab().build().unwrap();
    // The same grid over a smaller square (other rest lengths), pinned
    // elsewhere.
    let other = ClothBuilder::grid(
        21,
        21,
        Vec3::new(2.0, 0.0, 2.0),
        Vec3::new(-2.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, -2.0),
    )
    .with_pins([0, 440])
    .build()
    .unwrap();
    let stiff = StepParams {
        stiffness: SpringStiffness::uniform(1e5),
        ..StepParams::LAB
    };
    // One workspace through a soft step of the lab cloth, a stiff one, a
    // step of a cloth with the same grid and other rest lengths and pins,
    // and the lab cloth again; each must equal the same step on a fresh
    // workspace (coefficients rebuilt). Chebyshev, and PBD (its own
    // kernels: rest lengths and pins).
    for method in [AnyMethod::Implicit(METHODS[1]), PBD, SYMPLECTIC, PD] {
        let mut ws = AnyWorkspace::default();
        let steps = [
            (&lab, &StepParams::LAB),
            (&lab, &stiff),
            (&other, &stiff),
            (&lab, &StepParams::LAB),
        ];
        for (model, params) in steps {
            let start = ClothState::at_rest(model, &Affine3A::IDENTITY);
            let mut reused = start.clone();
            method
                .step(model, &mut reused, params, &[], &mut ws)
                .unwrap();
            let (fresh, _) = run_any(method, model, &start, params, &[], 1);
            assert_eq!(bits(&reused), bits(&fresh), "{}", method.name());
        }
    }
}

/// PBD (32 iterations), which runs its own stencil kernels.
const PBD: AnyMethod = AnyMethod::Pbd(PbdSolver::new(32));

/// Projective dynamics (10 Chebyshev iterations), whose local step and
/// right-hand side run on the stencil kernels.
const PD: AnyMethod = AnyMethod::Projective(ProjectiveSolver::chebyshev(10));

#[test]
fn projective_stencil_local_steps_agree_with_the_general_kernels_within_rounding() {
    let lab = ClothBuilder::lab().build().unwrap();
    let assignment = ClothBuilder::assignment(12, 12).build().unwrap();
    let sphere = PenaltySphere::sphere(Vec3A::new(0.0, -3.0, 0.0), 3.0, 10_000.0);
    let stiff = StepParams {
        stiffness: SpringStiffness::uniform(1e6),
        ..StepParams::LAB
    };
    let mut differing = 0;
    for (name, model) in [("lab", &lab), ("assignment", &assignment)] {
        let start = swinging(model);
        for params in [StepParams::LAB, stiff] {
            for spheres in [&[][..], &[sphere]] {
                let general = StepParams {
                    stencil: false,
                    ..params
                };
                let (a, ra) = run_any(PD, model, &start, &params, spheres, 3);
                let (b, rb) = run_any(PD, model, &start, &general, spheres, 3);
                let worst = apart(&a.positions, &b.positions);
                assert!(worst <= 2e-5 * model.size(), "{name}: {worst} apart");
                let (ea, eb) = (ra.relative_error.unwrap(), rb.relative_error.unwrap());
                assert!(
                    (ea - eb).abs() <= 0.05 * eb.max(1e-3),
                    "{name}: relative errors {ea} and {eb}"
                );
                assert_ne!(bits(&a), bits(&start));
                differing += usize::from(bits(&a) != bits(&b));
            }
        }
    }
    // The stencil kernels did run (the two differ by rounding).
    assert!(differing > 0);
}

/// Symplectic Euler, whose spring sums run on the stencil kernels.
const SYMPLECTIC: AnyMethod = AnyMethod::Symplectic(SymplecticSolver);

#[test]
fn symplectic_stencil_sums_agree_with_the_general_kernels_within_rounding() {
    let lab = ClothBuilder::lab().build().unwrap();
    let assignment = ClothBuilder::assignment(12, 12).build().unwrap();
    let sphere = PenaltySphere::sphere(Vec3A::new(0.0, -3.0, 0.0), 3.0, 10_000.0);
    // A step the explicit method is stable at (below 2/ω_max).
    let params = StepParams {
        dt: 0.002,
        ..StepParams::LAB
    };
    let general = StepParams {
        stencil: false,
        ..params
    };
    let mut differing = 0;
    for (name, model) in [("lab", &lab), ("assignment", &assignment)] {
        let start = swinging(model);
        for spheres in [&[][..], &[sphere]] {
            let (a, _) = run_any(SYMPLECTIC, model, &start, &params, spheres, 20);
            let (b, _) = run_any(SYMPLECTIC, model, &start, &general, spheres, 20);
            let worst = apart(&a.positions, &b.positions);
            assert!(worst <= 2e-5 * model.size(), "{name}: {worst} apart");
            assert_ne!(bits(&a), bits(&start));
            differing += usize::from(bits(&a) != bits(&b));
            for (i, &pinned) in model.pinned().iter().enumerate() {
                if pinned {
                    assert_eq!(a.positions[i], start.positions[i]);
                }
            }
        }
    }
    // The stencil kernels did run (the two differ by rounding).
    assert!(differing > 0);
}

#[test]
fn pbd_stencil_kernels_agree_with_the_general_kernels_within_rounding() {
    let lab = ClothBuilder::lab().build().unwrap();
    let assignment = ClothBuilder::assignment(12, 12).build().unwrap();
    let sphere = PenaltySphere::sphere(Vec3A::new(0.0, -3.0, 0.0), 3.0, 10_000.0);
    let mut differing = 0;
    for (name, model) in [("lab", &lab), ("assignment", &assignment)] {
        let start = swinging(model);
        for spheres in [&[][..], &[sphere]] {
            let params = StepParams::LAB;
            let general = StepParams {
                stencil: false,
                ..params
            };
            let (a, _) = run_any(PBD, model, &start, &params, spheres, 3);
            let (b, _) = run_any(PBD, model, &start, &general, spheres, 3);
            let scale = model.size();
            let worst = apart(&a.positions, &b.positions);
            assert!(worst <= 2e-5 * scale, "{name}: positions {worst} apart");
            // Velocities are moves over dt: rounding over dt.
            let worst = apart(&a.velocities, &b.velocities);
            assert!(
                worst <= 2e-5 * scale / params.dt as f32,
                "{name}: velocities {worst} apart"
            );
            assert_ne!(bits(&a), bits(&start));
            differing += usize::from(bits(&a) != bits(&b));
            for (i, &pinned) in model.pinned().iter().enumerate() {
                if pinned {
                    assert_eq!(a.positions[i], start.positions[i]);
                    assert_eq!(a.velocities[i], start.velocities[i]);
                }
            }
        }
    }
    // The stencil kernels did run (the two differ by rounding).
    assert!(differing > 0);
}
