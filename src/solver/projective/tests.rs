use bevy::math::{Affine3A, Vec3};

use super::*;
use crate::collision::PenaltySphere;
use crate::model::ClothBuilder;
use crate::solver::exact::{ExactSolver, ExactWorkspace};
use crate::solver::{SpringStiffness, step_error};
use crate::testing::run_from_rest;

fn lab() -> ClothModel {
    ClothBuilder::lab().build().unwrap()
}

/// Both global solves.
const GLOBALS: [GlobalSolve; 2] = [GlobalSolve::Direct, GlobalSolve::Multigrid { cycles: 1 }];

/// The exact trajectory after `steps` steps (a swinging, bent sheet).
fn swinging(model: &ClothModel, params: &StepParams, steps: usize) -> ClothState {
    swinging_onto(model, params, &[], steps)
}

fn swinging_onto(
    model: &ClothModel,
    params: &StepParams,
    spheres: &[PenaltySphere],
    steps: usize,
) -> ClothState {
    run_from_rest(&ExactSolver::REFERENCE, model, params, spheres, steps)
}

/// The report's sphere scene's sphere: the lab's, as a penalty sphere
/// stiffer than the cloth's inertia (c = 1e4 against m/h² ≈ 900).
fn lab_penalty_sphere() -> PenaltySphere {
    PenaltySphere {
        center: Vec3A::new(0.0, -4.0, 4.0),
        radius: 2.7,
        stiffness: 1e4,
        surface: Default::default(),
    }
}

fn error_against_exact(
    model: &ClothModel,
    params: &StepParams,
    start: &ClothState,
    pd: ProjectiveSolver,
) -> f64 {
    error_against_exact_onto(model, params, &[], start, pd)
}

fn error_against_exact_onto(
    model: &ClothModel,
    params: &StepParams,
    spheres: &[PenaltySphere],
    start: &ClothState,
    pd: ProjectiveSolver,
) -> f64 {
    let mut exact = start.clone();
    ExactSolver::REFERENCE
        .step(
            model,
            &mut exact,
            params,
            spheres,
            &mut ExactWorkspace::default(),
        )
        .unwrap();
    let mut state = start.clone();
    pd.step(
        model,
        &mut state,
        params,
        spheres,
        &mut ProjectiveWorkspace::default(),
    )
    .unwrap();
    step_error(&state.positions, &exact.positions, &start.positions)
}

#[test]
fn converges_to_the_exact_step_on_a_penalty_sphere() {
    // The report's scene: the lab cloth falling onto the lab's sphere as
    // a penalty sphere stiffer than the cloth's inertia (c = 1e4 against
    // m/h² ≈ 900). As an explicit force at the iterate, more iterations
    // made it worse; as a projective term, it converges.
    let model = ClothBuilder::lab().with_total_mass(441.0).build().unwrap();
    let params = StepParams::LAB;
    let spheres = [lab_penalty_sphere()];
    let start = swinging_onto(&model, &params, &spheres, 20);
    let touching = start
        .positions
        .iter()
        .filter(|x| spheres[0].contact(**x).is_some())
        .count();
    assert!(touching > 10, "{touching} vertices in contact");
    for global in GLOBALS {
        let error = |pd: ProjectiveSolver| {
            error_against_exact_onto(&model, &params, &spheres, &start, pd.with_global(global))
        };
        let few = error(ProjectiveSolver::new(4));
        let many = error(ProjectiveSolver::new(400));
        let interactive = error(ProjectiveSolver::default());
        assert!(
            many < 1e-3 && many < few / 10.0,
            "{global:?}: {few} → {many}"
        );
        assert!(interactive < 2e-2, "{global:?}: {interactive}");
    }
}

#[test]
fn refactorises_only_when_the_vertices_near_a_sphere_change() {
    let model = lab();
    let params = StepParams::LAB;
    let far = [PenaltySphere {
        center: Vec3A::new(0.0, -50.0, 0.0),
        radius: 1.0,
        stiffness: 1e4,
        surface: Default::default(),
    }];
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut ws = ProjectiveWorkspace::default();
    let pd = ProjectiveSolver::default().with_global(GlobalSolve::Multigrid { cycles: 1 });
    for _ in 0..3 {
        pd.step(&model, &mut state, &params, &far, &mut ws).unwrap();
    }
    assert_eq!(ws.factorizations(), 1, "a sphere far away changes nothing");
    let near = [PenaltySphere {
        center: state.positions[220] + Vec3A::new(0.0, -0.5, 0.0),
        ..far[0]
    }];
    pd.step(&model, &mut state, &params, &near, &mut ws)
        .unwrap();
    assert_eq!(ws.factorizations(), 2);
    assert!(ws.contact_k.contains(&1e4));
    pd.step(&model, &mut state, &params, &far, &mut ws).unwrap();
    assert_eq!(ws.factorizations(), 3, "and back");
    assert!(ws.contact_k.iter().all(|&k| k == 0.0));
}

#[test]
fn converges_to_the_exact_implicit_step() {
    let model = lab();
    let params = StepParams::LAB;
    let start = swinging(&model, &params, 10);
    for global in GLOBALS {
        let error = |pd: ProjectiveSolver| {
            error_against_exact(&model, &params, &start, pd.with_global(global))
        };
        let few = error(ProjectiveSolver::new(4));
        let many = error(ProjectiveSolver::new(400));
        assert!(
            many < 1e-3 && many < few / 10.0,
            "{global:?}: {few} → {many}"
        );
        let accelerated = error(ProjectiveSolver::chebyshev(40));
        let plain = error(ProjectiveSolver::new(40));
        assert!(
            accelerated < plain,
            "{global:?}: Chebyshev {accelerated} vs plain {plain}"
        );
    }
}

#[test]
fn multigrid_gives_the_direct_solves_step_on_large_cloths_and_every_path() {
    use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
    ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
    // 101²: the automatic choice is multigrid; the assignment's six
    // spring families; stiff; the stencil kernels and the general ones;
    // plain, Chebyshev and Anderson.
    let lab = ClothBuilder::lab_grid(101).build().unwrap();
    let assignment = ClothBuilder::assignment(70, 70).build().unwrap();
    for (model, k) in [(&lab, 8000.0), (&lab, 1e6), (&assignment, 8000.0)] {
        let params = StepParams {
            stiffness: SpringStiffness::uniform(k),
            ..StepParams::LAB
        };
        // A bent, swinging sheet (40 lab steps), and its exact step.
        let mut start = ClothState::at_rest(model, &Affine3A::IDENTITY);
        let lab_method = crate::solver::implicit::ImplicitSolver::default();
        let mut lab_ws = Default::default();
        for _ in 0..40 {
            lab_method
                .step(model, &mut start, &params, &[], &mut lab_ws)
                .unwrap();
        }
        let mut exact = start.clone();
        ExactSolver::REFERENCE
            .step(
                model,
                &mut exact,
                &params,
                &[],
                &mut ExactWorkspace::default(),
            )
            .unwrap();
        for pd in [
            ProjectiveSolver::new(20),
            ProjectiveSolver::chebyshev(20),
            ProjectiveSolver::anderson(10, PD_ANDERSON_WINDOW),
        ] {
            let step = |global: GlobalSolve, params: &StepParams| {
                let mut state = start.clone();
                let mut ws = ProjectiveWorkspace::default();
                pd.with_global(global)
                    .step(model, &mut state, params, &[], &mut ws)
                    .unwrap();
                (state, ws.multigrid.is_some())
            };
            let (direct, _) = step(GlobalSolve::Direct, &params);
            // Auto is multigrid here, but direct with Anderson.
            let (_, multigrid) = step(GlobalSolve::Auto, &params);
            assert_eq!(multigrid, pd.anderson == 0, "{pd:?}");
            let mg = GlobalSolve::Multigrid { cycles: 1 };
            let (auto, _) = step(mg, &params);
            // As close to the exact step as the direct solve's iterate
            // (one V-cycle per iteration gains a little less).
            let direct = step_error(&direct.positions, &exact.positions, &start.positions);
            let error = step_error(&auto.positions, &exact.positions, &start.positions);
            assert!(
                error < 2.0 * direct + 1e-4,
                "{} k {k} {pd:?}: {error} against {direct}",
                model.vertex_count()
            );
            let general = StepParams {
                stencil: false,
                ..params
            };
            let (general, _) = step(mg, &general);
            let error = step_error(&general.positions, &auto.positions, &start.positions);
            assert!(error < 1e-3, "stencil against general: {error}");
            let serial = StepParams {
                parallel: false,
                ..params
            };
            assert_eq!(step(mg, &serial).0, auto, "same bits on 1 and 2 threads");
            for simd in [Simd::Baseline, Simd::Avx2, Simd::Avx512] {
                let at = StepParams { simd, ..params };
                assert_eq!(step(mg, &at).0, auto, "same bits at {simd:?}");
            }
        }
    }
}

#[test]
fn is_right_on_stiff_cloth_where_it_falls_as_the_exact_method_does() {
    // k = 1e6 at the lab's step: Jacobi locks here; PD does not.
    let model = lab();
    let params = StepParams {
        stiffness: SpringStiffness::uniform(1e6),
        ..StepParams::LAB
    };
    let start = swinging(&model, &params, 5);
    for global in GLOBALS {
        let pd = ProjectiveSolver::default().with_global(global);
        let e = error_against_exact(&model, &params, &start, pd);
        assert!(e < 0.1, "{global:?}: {e}");
    }
}

#[test]
fn factorises_once_and_again_only_when_k_h_or_pins_change() {
    for global in GLOBALS {
        factorises_once_and_again_only_when_k_h_or_pins_change_with(global);
    }
    // Switching between the direct solve and multigrid rebuilds.
    let model = lab();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut ws = ProjectiveWorkspace::default();
    // (Auto is the direct solve on the lab's 441 vertices.)
    for (global, builds) in [
        (GlobalSolve::Direct, 1),
        (GlobalSolve::Auto, 1),
        (GlobalSolve::Multigrid { cycles: 1 }, 2),
        (GlobalSolve::Multigrid { cycles: 2 }, 3),
        (GlobalSolve::Direct, 4),
    ] {
        ProjectiveSolver::default()
            .with_global(global)
            .step(&model, &mut state, &StepParams::LAB, &[], &mut ws)
            .unwrap();
        assert_eq!(ws.factorizations(), builds, "{global:?}");
    }
}

fn factorises_once_and_again_only_when_k_h_or_pins_change_with(global: GlobalSolve) {
    let model = lab();
    let mut params = StepParams::LAB;
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut ws = ProjectiveWorkspace::default();
    let pd = ProjectiveSolver::default().with_global(global);
    for _ in 0..5 {
        pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
    }
    assert_eq!(ws.factorizations(), 1);
    params.stiffness = SpringStiffness::uniform(9000.0);
    pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
    assert_eq!(ws.factorizations(), 2);
    params.dt = 0.02;
    pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
    assert_eq!(ws.factorizations(), 3);
    let unpinned = ClothBuilder::lab().with_pins([0]).build().unwrap();
    let mut s = ClothState::at_rest(&unpinned, &Affine3A::IDENTITY);
    pd.step(&unpinned, &mut s, &params, &[], &mut ws).unwrap();
    assert_eq!(ws.factorizations(), 4);
    // Moving a pin is a right-hand side change only.
    state.positions[0] += Vec3A::new(0.5, 0.0, 0.0);
    pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
    assert_eq!(ws.factorizations(), 5);
    pd.step(&model, &mut state, &params, &[], &mut ws).unwrap();
    assert_eq!(ws.factorizations(), 5);
    assert_eq!(state.positions[0].x, 5.5, "pins never move");
}

#[test]
fn edge_cases_are_typed_errors_or_plain_physics() {
    for global in GLOBALS {
        edge_cases_are_typed_errors_or_plain_physics_with(global);
    }
    assert_eq!(
        ProjectiveSolver::default()
            .with_global(GlobalSolve::Multigrid { cycles: 0 })
            .validate(),
        Err(ParamError::Iterations)
    );
}

fn edge_cases_are_typed_errors_or_plain_physics_with(global: GlobalSolve) {
    let pd = ProjectiveSolver::default().with_global(global);
    let model = lab();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut ws = ProjectiveWorkspace::default();
    // k = 0 is refused like every method refuses it; the state is kept.
    let zero = StepParams {
        stiffness: SpringStiffness::uniform(0.0),
        ..StepParams::LAB
    };
    let before = state.clone();
    assert_eq!(
        pd.step(&model, &mut state, &zero, &[], &mut ws),
        Err(StepError::Params(ParamError::Stiffness(0.0)))
    );
    assert_eq!(state, before);
    assert_eq!(
        ProjectiveSolver::new(0).step(&model, &mut state, &StepParams::LAB, &[], &mut ws),
        Err(StepError::Params(ParamError::Iterations))
    );
    // h → 0: the mass term dominates, nothing moves measurably.
    let tiny = StepParams {
        dt: 1e-9,
        ..StepParams::LAB
    };
    pd.step(&model, &mut state, &tiny, &[], &mut ws).unwrap();
    assert!(state.is_finite());
    assert!(state.positions[220].distance(before.positions[220]) < 1e-6);
    // No springs: a cloth without triangles cannot be built (a typed
    // error), so PD never sees an empty Laplacian.
    let loose =
        ClothBuilder::from_triangles(vec![Vec3::ZERO, Vec3::X, Vec3::Z], Vec::new()).build();
    assert!(loose.is_err(), "{loose:?}");
    // Every pin removed: the whole sheet falls, finite.
    let free = ClothBuilder::lab().with_pins([]).build().unwrap();
    let mut s = ClothState::at_rest(&free, &Affine3A::IDENTITY);
    let mut ws = ProjectiveWorkspace::default();
    for _ in 0..30 {
        pd.step(&free, &mut s, &StepParams::LAB, &[], &mut ws)
            .unwrap();
    }
    assert!(s.is_finite() && s.positions.iter().all(|p| p.y < -1.0));
}

#[test]
fn is_deterministic() {
    let model = lab();
    let run = |pd: ProjectiveSolver| {
        let mut s = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = ProjectiveWorkspace::default();
        for _ in 0..20 {
            pd.step(&model, &mut s, &StepParams::LAB, &[], &mut ws)
                .unwrap();
        }
        s.positions
            .iter()
            .flat_map(|p| p.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    for global in GLOBALS {
        for pd in [
            ProjectiveSolver::default(),
            ProjectiveSolver::anderson(PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW),
        ] {
            let pd = pd.with_global(global);
            assert_eq!(run(pd), run(pd));
        }
    }
}

/// The lowest point after 1 s of falling from rest, and the exact run's.
pub(super) fn lowest_after_one_second(params: &StepParams, pd: ProjectiveSolver) -> (f32, f32) {
    let model = lab();
    let steps = (1.0 / params.dt).ceil() as usize;
    let lowest = |s: &ClothState| s.positions.iter().map(|p| p.y).fold(f32::MAX, f32::min);
    let exact = swinging(&model, params, steps);
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut ws = ProjectiveWorkspace::default();
    for _ in 0..steps {
        pd.step(&model, &mut state, params, &[], &mut ws).unwrap();
    }
    (lowest(&state), lowest(&exact))
}

#[test]
fn anderson_falls_as_the_exact_method_on_stiff_cloth_where_chebyshev_locks() {
    // The stability map's cell k = 1e7, dt = 0.0333: 10 Chebyshev
    // iterations stay far above the exact sheet; 20 Anderson ones reach
    // it (the map's criterion: within 10 % of the drop).
    let params = StepParams {
        stiffness: SpringStiffness::uniform(1e7),
        ..StepParams::LAB
    };
    let rest = 0.0;
    let (chebyshev, exact) = lowest_after_one_second(&params, ProjectiveSolver::default());
    let (anderson, _) = lowest_after_one_second(
        &params,
        ProjectiveSolver::anderson(PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW),
    );
    let drop = rest - exact;
    assert!(drop > 1.0, "the exact sheet falls: {exact}");
    assert!(
        (anderson - exact).abs() < 0.1 * drop,
        "{anderson} vs {exact}"
    );
    assert!(
        (chebyshev - exact).abs() > 0.3 * drop,
        "{chebyshev} vs {exact}"
    );
}

#[test]
fn anderson_converges_to_the_exact_step_and_never_raises_the_objective() {
    let model = lab();
    let params = StepParams::LAB;
    let start = swinging(&model, &params, 10);
    let few = error_against_exact(&model, &params, &start, ProjectiveSolver::anderson(4, 5));
    let many = error_against_exact(&model, &params, &start, ProjectiveSolver::anderson(100, 5));
    let chebyshev = error_against_exact(&model, &params, &start, ProjectiveSolver::chebyshev(20));
    let anderson = error_against_exact(&model, &params, &start, ProjectiveSolver::anderson(20, 5));
    assert!(many < 1e-4 && many < few / 10.0, "{few} → {many}");
    assert!(
        anderson < chebyshev,
        "Anderson {anderson} vs Chebyshev {chebyshev}"
    );
    // Its safeguard: the objective at the step's result is no higher
    // than plain local–global iterations' from the same start (each of
    // which lowers it).
    let objective = |pd: ProjectiveSolver| {
        let mut s = start.clone();
        pd.step(
            &model,
            &mut s,
            &params,
            &[],
            &mut ProjectiveWorkspace::default(),
        )
        .unwrap();
        let mut ws = ProjectiveWorkspace::default();
        let mut probe = start.clone();
        ProjectiveSolver::new(1)
            .step(&model, &mut probe, &params, &[], &mut ws)
            .unwrap();
        let inv_h2 = 1.0 / (params.dt * params.dt);
        ws.local_with_energy(&model, &s.positions, &[])
            + ProjectiveSolver::inertia(
                &model,
                &s.positions,
                &ws,
                inv_h2,
                params.gravity.as_dvec3(),
            )
    };
    assert!(objective(ProjectiveSolver::anderson(20, 5)) <= objective(ProjectiveSolver::new(20)));
}

#[test]
fn stops_early_at_its_tolerance_on_the_iterates_of_the_whole_budget() {
    // The lab cloth falling (by both global solves, and onto a penalty
    // sphere: the right-hand side through `RhsParts::at`), and a 201²
    // cloth by the direct solve (the supernodal factor: the
    // column-major right-hand side), to a tighter tolerance: it is
    // within 1e-4 after one iteration.
    let lab = lab();
    let big = ClothBuilder::lab_grid(201).build().unwrap();
    let params = StepParams::LAB;
    let sphere = [lab_penalty_sphere()];
    let mg = GlobalSolve::Multigrid { cycles: 1 };
    const TIGHT: f64 = 5e-5;
    let cases: [(&ClothModel, &[PenaltySphere], GlobalSolve, f64); 4] = [
        (&lab, &[], GlobalSolve::Direct, PD_TOLERANCE),
        (&lab, &[], mg, PD_TOLERANCE),
        (&lab, &sphere, GlobalSolve::Direct, PD_TOLERANCE),
        (&big, &[], GlobalSolve::Direct, TIGHT),
    ];
    // Budgets for which Chebyshev's plain iterations (`ρ` estimated
    // from them) are as many as in a shorter run (2 up to 11), so that
    // a run of the iterations the early stop took is the same run.
    let fixed_rho = ProjectiveSolver {
        chebyshev: Some(Rho::Fixed(0.9)),
        ..ProjectiveSolver::chebyshev(60)
    };
    let methods = [
        ProjectiveSolver::new(60),
        ProjectiveSolver::chebyshev(PD_ITERATIONS),
        fixed_rho,
    ];
    for (model, spheres, global, tolerance) in cases {
        let mut start = ClothState::at_rest(model, &Affine3A::IDENTITY);
        let mut start_ws = ProjectiveWorkspace::default();
        for _ in 0..20 {
            ProjectiveSolver::PRESET
                .step(model, &mut start, &params, spheres, &mut start_ws)
                .unwrap();
        }
        for pd in methods {
            let pd = pd.with_global(global);
            let run = |pd: ProjectiveSolver| {
                let mut state = start.clone();
                let mut ws = ProjectiveWorkspace::default();
                let report = pd
                    .step(model, &mut state, &params, spheres, &mut ws)
                    .unwrap();
                (state, report, ws.cholesky.lanes_ref().is_some())
            };
            let case = format!("{} vertices, {pd:?}", model.vertex_count());
            let (early, report, lanes) = run(pd.with_tolerance(tolerance));
            assert_eq!(lanes, model.vertex_count() < 1000 && global != mg, "{case}");
            let j = report.iterations;
            // (Chebyshev's budget of 10 may run out before an iterate
            // is within the tolerance; the others' budget does not.)
            let stopped = j < pd.iterations;
            assert!(j > 0, "{case}");
            assert!(stopped || pd.chebyshev == Some(Rho::Auto), "{case}: {j}");
            // The budget's first j iterates, bit for bit.
            let (fixed, fixed_report, _) = run(ProjectiveSolver {
                iterations: j,
                ..pd
            });
            assert_eq!(early, fixed, "{case}");
            assert_eq!(report, fixed_report, "{case}");
            // What it stopped on is the step's reported error (made
            // afresh in `f64`), and the iterate before was not within
            // it (with a fixed `ρ`, every other one is estimated).
            let error = report.relative_error.unwrap();
            let tolerance = tolerance as f32;
            assert!(stopped == (error <= 1.02 * tolerance), "{case}: {error}");
            let back = if pd.chebyshev == fixed_rho.chebyshev {
                2
            } else {
                1
            };
            if stopped && j > back {
                let (_, before, _) = run(ProjectiveSolver {
                    iterations: j - back,
                    ..pd
                });
                let before = before.relative_error.unwrap();
                assert!(before > 0.98 * tolerance, "{case}: {before}");
            }
            // A tolerance no iterate reaches: the whole budget, the
            // same bits as without one.
            let (all, all_report, _) = run(pd.with_tolerance(1e-9));
            let (plain, plain_report, _) = run(pd);
            assert_eq!((all, all_report), (plain, plain_report), "{case}");
            assert_eq!(all_report.iterations, pd.iterations, "{case}");
        }
    }
}

#[test]
fn a_tolerance_is_a_number_and_not_with_anderson() {
    assert_eq!(ProjectiveSolver::PRESET.validate(), Ok(()));
    assert_eq!(ProjectiveSolver::default(), ProjectiveSolver::PRESET);
    for bad in [-1e-3, f64::NAN, f64::INFINITY] {
        let refused = ProjectiveSolver::PRESET.with_tolerance(bad).validate();
        assert!(matches!(refused, Err(ParamError::Tolerance(_))), "{bad}");
    }
    // Anderson's iterations have no estimate to stop on.
    let anderson = ProjectiveSolver::anderson(PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW);
    assert_eq!(anderson.validate(), Ok(()));
    assert_eq!(
        anderson.with_tolerance(PD_TOLERANCE).validate(),
        Err(ParamError::Tolerance(PD_TOLERANCE))
    );
}

#[test]
fn two_accelerations_are_refused() {
    let both = ProjectiveSolver {
        anderson: 5,
        ..ProjectiveSolver::default()
    };
    assert_eq!(both.validate(), Err(ParamError::Acceleration));
    assert_eq!(ProjectiveSolver::anderson(20, 5).name(), "pd-anderson");
    assert_eq!(ProjectiveSolver::default().name(), "pd");
}

#[test]
fn friction_in_the_objective_holds_a_cloth_on_a_slope_that_a_frictionless_one_slides_down() {
    // Issue M, item 2, for projective dynamics: a small stiff cloth laid on
    // a 20° slope taken as a penalty term of the objective, stepped by pd
    // alone (no projection after). μ = 0.5 > tan 20° holds it; without
    // friction the exact step slides g sin 20° t²/2 ≈ 1.7 m in 1 s, and so
    // does Anderson's. Chebyshev's 10 iterations slide a fifth of that:
    // the contact's weight on the diagonal (`PD_CONTACT_STIFFNESS`) holds
    // each iteration's tangential motion too, and its steps say so (their
    // estimated error is above the convergence tolerance).
    use crate::solver::CONVERGENCE_TOLERANCE;
    use crate::testing::slide_on_slope;
    let chebyshev = [
        ProjectiveSolver::PRESET,
        ProjectiveSolver::chebyshev(PD_ITERATIONS)
            .with_global(GlobalSolve::Multigrid { cycles: 1 }),
    ];
    let anderson = ProjectiveSolver::anderson(PD_ANDERSON_ITERATIONS, PD_ANDERSON_WINDOW);
    for method in chebyshev.into_iter().chain([anderson]) {
        let (held, off, _) = slide_on_slope(&method, 0.5);
        // The cloth is 2 m across; it stays on the slope.
        assert!(
            held.abs() < 5e-3 && off.abs() < 1e-2,
            "{method:?}: held cloth moved {held}, {off}"
        );
        let (slid, off, error) = slide_on_slope(&method, 0.0);
        assert!(off.abs() < 1e-2, "{method:?}: {off} off the slope");
        if method == anderson {
            assert!(
                (slid - 1.68).abs() < 0.1,
                "{method:?}: frictionless cloth moved {slid}"
            );
        } else {
            assert!(slid > 0.25, "{method:?}: frictionless cloth moved {slid}");
            assert!(error > CONVERGENCE_TOLERANCE, "{method:?}: {error}");
        }
    }
}
