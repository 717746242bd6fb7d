//! Stiff and extreme cases over every method (issue E): nothing panics or
//! lets a NaN through, the exact method stays correct, divergence is caught.

use bevy::math::{Affine3A, Vec3A};
use bevy_cloth::methods::{AnyMethod, AnyWorkspace};
use bevy_cloth::model::ClothState;
use bevy_cloth::solver::StepParams;
use bevy_cloth::solver::guard::DivergenceReason;
use bevy_cloth_report::scenarios::{
    Scenario, Verdict, explicit_limit, map_methods, measured_explicit_limit, sweep,
};

fn find<'a>(
    outcomes: &'a [bevy_cloth_report::scenarios::Outcome],
    label: &str,
) -> &'a bevy_cloth_report::scenarios::Outcome {
    outcomes.iter().find(|o| o.method == label).unwrap()
}

#[test]
fn every_method_survives_the_extreme_cases() {
    // 301×301 runs in the release stability map; a debug test run takes 61.
    for scenario in Scenario::extreme_cases(61) {
        let outcomes = sweep(&scenario, &map_methods());
        for o in &outcomes {
            let case = format!("{} / {}: {:?}", scenario.name, o.method, o.verdict);
            assert!(!matches!(o.verdict, Verdict::Failed(_)), "{case}");
            assert!(o.run.state.is_finite(), "{case}");
            if let Some(bound) = scenario.bounds.max_stretch
                && o.run.caught.is_none()
            {
                // What the guard passed is within its bound (or recovering).
                assert!(o.max_stretch <= bound.max(250.0), "{case}");
            }
        }
        // The reference itself never diverges, on any case.
        let exact = find(&outcomes, "exact");
        assert_eq!(exact.verdict, Verdict::Correct, "{}", scenario.name);
        // Symplectic Euler is either inside the bounds or caught.
        let explicit = find(&outcomes, "symplectic");
        assert!(
            matches!(
                explicit.verdict,
                Verdict::Correct | Verdict::Wrong { .. } | Verdict::Caught { .. }
            ),
            "{}: {:?}",
            scenario.name,
            explicit.verdict
        );
    }
}

#[test]
fn fixed_iterations_at_huge_stiffness_are_finite_but_wrong() {
    let outcomes = sweep(&Scenario::lab(1e8, StepParams::LAB.dt), &map_methods());
    for label in ["jacobi", "chebyshev", "chebyshev-auto"] {
        // The sheet hardly falls: the lowest point is off by ~100 % of the
        // exact run's drop.
        match find(&outcomes, label).verdict {
            Verdict::Wrong { lowest, .. } => assert!(lowest > 0.9, "{label}: {lowest}"),
            ref v => panic!("{label}: {v:?}"),
        }
    }
    // PBD with 32 iterations stretches the 21×21 cloth far past its rest
    // lengths.
    assert!(find(&outcomes, "pbd").max_stretch > 0.5);
    assert!(matches!(
        find(&outcomes, "symplectic").verdict,
        Verdict::Caught { .. }
    ));
}

#[test]
fn clamping_compression_rescues_the_linearly_implicit_method() {
    // The sphere jumps into the hanging cloth: springs compress around it,
    // and with the exact spring blocks CG meets negative curvature.
    let scenarios = Scenario::extreme_cases(3);
    let sphere = scenarios
        .iter()
        .find(|s| s.name.starts_with("sphere"))
        .unwrap();
    let outcomes = sweep(sphere, &map_methods());
    assert!(matches!(
        find(&outcomes, "linear-cg exact-k").verdict,
        Verdict::Caught {
            reason: DivergenceReason::SolveFailed,
            ..
        }
    ));
    assert_eq!(find(&outcomes, "linear-cg").verdict, Verdict::Correct);
    // At k = 1e8 the exact blocks make the direct solve blow up; clamped, it
    // stays finite.
    let stiff = sweep(&Scenario::lab(1e8, StepParams::LAB.dt), &map_methods());
    assert!(matches!(
        find(&stiff, "linear-direct exact-k").verdict,
        Verdict::Caught { .. }
    ));
    assert!(!matches!(
        find(&stiff, "linear-direct").verdict,
        Verdict::Caught { .. }
    ));
}

#[test]
fn unsimulatable_input_gets_a_typed_error_from_every_method() {
    let scenario = Scenario::lab(8000.0, StepParams::LAB.dt);
    let bad = [
        StepParams {
            dt: 0.0,
            ..StepParams::LAB
        },
        StepParams {
            dt: -0.1,
            ..StepParams::LAB
        },
        StepParams {
            dt: f64::NAN,
            ..StepParams::LAB
        },
        StepParams {
            damping: f32::NAN,
            ..StepParams::LAB
        },
        StepParams {
            gravity: bevy::math::Vec3::NAN,
            ..StepParams::LAB
        },
        StepParams {
            stiffness: bevy_cloth::solver::SpringStiffness::uniform(f32::NAN),
            ..StepParams::LAB
        },
    ];
    for method in map_methods() {
        for params in &bad {
            let mut state = ClothState::at_rest(&scenario.model, &Affine3A::IDENTITY);
            let before = state.clone();
            let r = method.step(
                &scenario.model,
                &mut state,
                params,
                &[],
                &mut AnyWorkspace::default(),
            );
            if matches!(method, AnyMethod::Pbd(_)) && params.stiffness.validate().is_err() {
                // PBD never reads the stiffness, so it does not refuse it.
                assert!(r.is_ok() && state.is_finite(), "pbd: {r:?}");
                continue;
            }
            assert!(
                matches!(r, Err(bevy_cloth::solver::StepError::Params(_))),
                "{}: {params:?} gave {r:?}",
                method.name()
            );
            assert_eq!(state, before, "untouched");
        }
    }
}

#[test]
fn symplectic_limit_matches_two_over_omega_max() {
    // The lab cloth without damping; predicted at the rest shape by power
    // iteration, measured by bisection over 1000 steps (33 s at the lab's dt).
    let mut s = Scenario::lab(8000.0, 0.0333);
    s.params.damping = 1.0;
    let rest = ClothState::at_rest(&s.model, &Affine3A::IDENTITY);
    let predicted = explicit_limit(&s.model, &rest.positions, &s.params.stiffness);
    let measured = measured_explicit_limit(&s, 1e-4, 0.1, 1000, 1e-3);
    let ratio = measured / predicted;
    assert!((0.9..=1.1).contains(&ratio), "{measured} vs {predicted}");
}

#[test]
fn every_method_is_deterministic() {
    let mut scenario = Scenario::lab(8000.0, StepParams::LAB.dt).with_steps(40);
    scenario.spheres.push(bevy_cloth::collision::PenaltySphere {
        center: Vec3A::new(0.0, -4.0, 4.0),
        radius: 2.7,
        stiffness: 1e4,
        surface: Default::default(),
    });
    for method in map_methods() {
        let a = bevy_cloth_report::scenarios::run(&scenario, &method);
        let b = bevy_cloth_report::scenarios::run(&scenario, &method);
        let bits = |s: &ClothState| -> Vec<u32> {
            s.positions
                .iter()
                .flat_map(|p| p.to_array().map(f32::to_bits))
                .collect()
        };
        assert_eq!(bits(&a.state), bits(&b.state), "{}", method.name());
        assert_eq!(a.caught, b.caught);
    }
    let _ = AnyMethod::Symplectic;
}

#[test]
fn parallel_chunks_give_the_same_bits_as_serial() {
    use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
    ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
    // 182×182 = 33 124 vertices (and about 3× as many springs): both the
    // spring and the vertex loops are above the parallel threshold.
    let n = 182;
    assert!(n * n >= bevy_cloth::solver::PARALLEL_MIN);
    let scenario = Scenario::grid(n, 8000.0, StepParams::LAB.dt).with_steps(3);
    let bits = |s: &ClothState| -> Vec<u32> {
        s.positions
            .iter()
            .flat_map(|p| p.to_array().map(f32::to_bits))
            .collect()
    };
    let mut serial_scenario = scenario.clone();
    serial_scenario.params.parallel = false;
    for method in [
        AnyMethod::Implicit(bevy_cloth::solver::implicit::ImplicitSolver::jacobi(8)),
        AnyMethod::Implicit(bevy_cloth::solver::implicit::ImplicitSolver::chebyshev_auto(16)),
    ] {
        let serial = bevy_cloth_report::scenarios::run(&serial_scenario, &method);
        let parallel = bevy_cloth_report::scenarios::run(&scenario, &method);
        assert_eq!(
            bits(&serial.state),
            bits(&parallel.state),
            "{}",
            method.name()
        );
        assert_eq!(serial.steps, 3);
    }
}

#[test]
#[ignore = "timing, run by hand: cargo test --release -- --ignored --nocapture"]
fn time_parallel_chunks() {
    use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
    ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
    let mut scenario = Scenario::grid(256, 8000.0, StepParams::LAB.dt).with_steps(20);
    let method = AnyMethod::Implicit(bevy_cloth::solver::implicit::ImplicitSolver::chebyshev(
        32, 0.995,
    ));
    for parallel in [false, true, false, true] {
        scenario.params.parallel = parallel;
        let t = std::time::Instant::now();
        let r = bevy_cloth_report::scenarios::run(&scenario, &method);
        println!(
            "parallel {parallel}: {:.1} ms per step ({} steps)",
            t.elapsed().as_secs_f64() * 1e3 / r.steps as f64,
            r.steps
        );
    }
}

#[test]
fn the_convergence_flag_follows_the_maps_verdicts() {
    // Cells of the map's lab sweep (issue L): the plugin's not-converged flag
    // is raised in the wrong runs of Jacobi and Chebyshev and not in the
    // correct ones. The map itself lists every cell ("Convergence").
    let methods: Vec<AnyMethod> = map_methods()
        .into_iter()
        .filter(|m| matches!(m, AnyMethod::Implicit(_)))
        .collect();
    assert_eq!(methods.len(), 3);
    let (mut wrong, mut correct) = (0, 0);
    for (k, dt) in [(1e3, 0.0333), (1e4, 0.0333), (1e5, 0.0333), (1e5, 0.01)] {
        for o in sweep(&Scenario::lab(k, dt), &methods) {
            let case = format!(
                "k={k:e} dt={dt} {}: {:?} {:?}",
                o.method, o.verdict, o.run.max_relative_error
            );
            match o.verdict {
                Verdict::Wrong { .. } => {
                    wrong += 1;
                    assert!(o.run.flagged(), "{case}");
                }
                Verdict::Correct => {
                    correct += 1;
                    assert!(!o.run.flagged(), "{case}");
                }
                _ => panic!("{case}"),
            }
        }
    }
    // Both kinds were exercised.
    assert!(
        wrong >= 4 && correct >= 4,
        "{wrong} wrong, {correct} correct"
    );
    // The case: Chebyshev at k = 1e12 hangs frozen in the air.
    for m in &methods {
        let run = bevy_cloth_report::scenarios::run(&Scenario::lab(1e12, StepParams::LAB.dt), m);
        assert!(run.flagged(), "{m:?}: {:?}", run.max_relative_error);
    }
}
