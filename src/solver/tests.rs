use bevy::math::{Affine3A, Vec3, Vec3A};

use super::implicit::{ImplicitSolver, ImplicitWorkspace};
use super::pbd::{PbdSolver, PbdWorkspace};
use super::*;
use crate::model::{ClothBuilder, ClothModel, ClothState};
use crate::solver::ParamError;
use crate::solver::engine::kernels::Springs;
use crate::solver::engine::simd;
use crate::testing::{noise, run_from_rest};

fn lab() -> (ClothModel, ClothState) {
    let model = ClothBuilder::lab().build().unwrap();
    let state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    (model, state)
}

/// A swinging state: the lab cloth after `steps` Jacobi steps.
fn swinging(steps: usize) -> (ClothModel, ClothState) {
    let model = ClothBuilder::lab().build().unwrap();
    let state = run_from_rest(
        &ImplicitSolver::default(),
        &model,
        &StepParams::LAB,
        &[],
        steps,
    );
    (model, state)
}

#[test]
fn gradient_matches_finite_differences() {
    let (model, state) = lab();
    let mut seed = 7;
    let x: Vec<Vec3A> = state
        .positions
        .iter()
        .map(|&p| p + 0.3 * noise(&mut seed))
        .collect();
    let x_tilde: Vec<Vec3A> = state
        .positions
        .iter()
        .map(|&p| p + 0.1 * noise(&mut seed))
        .collect();
    let params = StepParams::LAB;
    let mut terms = vec![Vec3A::ZERO; model.topology().springs().len()];
    let mut g = vec![Vec3A::ZERO; model.vertex_count()];
    gradient(&model, &x, &x_tilde, &params, &mut terms, &mut g);
    let eps = 1e-2f32;
    let mut worst = 0.0f64;
    for i in [1usize, 5, 21, 220, 440] {
        for axis in 0..3 {
            let mut xp = x.clone();
            let mut xm = x.clone();
            xp[i][axis] += eps;
            xm[i][axis] -= eps;
            let h = f64::from(xp[i][axis]) - f64::from(xm[i][axis]);
            let fd = (objective(&model, &xp, &x_tilde, &params)
                - objective(&model, &xm, &x_tilde, &params))
                / h;
            let analytic = f64::from(g[i][axis]);
            let err = (fd - analytic).abs() / analytic.abs().max(1.0);
            worst = worst.max(err);
        }
    }
    assert!(worst < 1e-3, "worst relative error {worst}");
    // Pinned vertices have no gradient (no degrees of freedom).
    assert_eq!(g[0], Vec3A::ZERO);
    assert_eq!(g[20], Vec3A::ZERO);
}

#[test]
fn jacobi_residual_falls_with_iterations_and_chebyshev_beats_it() {
    let (model, start) = swinging(20);
    let residual = |config: ImplicitSolver| {
        let mut state = start.clone();
        let mut ws = ImplicitWorkspace::default();
        Method::step(&config, &model, &mut state, &StepParams::LAB, &[], &mut ws)
            .unwrap()
            .residual
            .unwrap()
    };
    let r8 = residual(ImplicitSolver::jacobi(8));
    let r32 = residual(ImplicitSolver::jacobi(32));
    let r128 = residual(ImplicitSolver::jacobi(128));
    assert!(r32 < r8 && r128 < r32, "{r8} {r32} {r128}");
    let c32 = residual(ImplicitSolver::chebyshev(32, 0.995));
    assert!(c32 < r32, "chebyshev {c32} jacobi {r32}");
}

#[test]
fn implicit_step_keeps_pins_and_is_deterministic() {
    let (model, start) = swinging(5);
    let run = || {
        let mut state = start.clone();
        let mut ws = ImplicitWorkspace::default();
        for _ in 0..3 {
            Method::step(
                &ImplicitSolver::chebyshev(32, 0.995),
                &model,
                &mut state,
                &StepParams::LAB,
                &[],
                &mut ws,
            )
            .unwrap();
        }
        state
    };
    let a = run();
    let b = run();
    assert_eq!(a, b);
    assert_eq!(a.positions[0], start.positions[0]);
    assert_eq!(a.positions[20], start.positions[20]);
    assert_ne!(a.positions[440], start.positions[440]);
}

#[test]
fn invalid_parameters_are_refused_and_leave_the_state_alone() {
    let (model, start) = lab();
    let cases = [
        (
            StepParams {
                dt: 0.0,
                ..StepParams::LAB
            },
            ParamError::TimeStep(0.0),
        ),
        (
            StepParams {
                stiffness: SpringStiffness::uniform(-1.0),
                ..StepParams::LAB
            },
            ParamError::Stiffness(-1.0),
        ),
        (
            StepParams {
                damping: 1.5,
                ..StepParams::LAB
            },
            ParamError::Damping(1.5),
        ),
        (
            StepParams {
                gravity: Vec3::new(0.0, f32::NAN, 0.0),
                ..StepParams::LAB
            },
            ParamError::Gravity,
        ),
    ];
    for (params, expected) in cases {
        let mut state = start.clone();
        let err = Method::step(
            &ImplicitSolver::default(),
            &model,
            &mut state,
            &params,
            &[],
            &mut ImplicitWorkspace::default(),
        )
        .unwrap_err();
        assert_eq!(err, StepError::Params(expected));
        let pbd = Method::step(
            &PbdSolver::default(),
            &model,
            &mut state,
            &params,
            &[],
            &mut PbdWorkspace::default(),
        );
        if matches!(expected, ParamError::Stiffness(_)) {
            // PBD does not read the stiffness, so an invalid one cannot stop it.
            assert!(pbd.is_ok(), "{pbd:?}");
            assert!(state.is_finite());
            state = start.clone();
        } else {
            assert_eq!(pbd.unwrap_err(), StepError::Params(expected));
        }
        assert_eq!(state, start);
    }
    let mut state = start.clone();
    assert_eq!(
        Method::step(
            &ImplicitSolver::chebyshev(32, 1.0),
            &model,
            &mut state,
            &StepParams::LAB,
            &[],
            &mut ImplicitWorkspace::default()
        ),
        Err(StepError::Params(ParamError::Rho(1.0)))
    );
    assert_eq!(
        Method::step(
            &PbdSolver { iterations: 0 },
            &model,
            &mut state,
            &StepParams::LAB,
            &[],
            &mut PbdWorkspace::default()
        ),
        Err(StepError::Params(ParamError::Iterations))
    );
    state.positions.pop();
    assert_eq!(
        Method::step(
            &PbdSolver::default(),
            &model,
            &mut state,
            &StepParams::LAB,
            &[],
            &mut PbdWorkspace::default()
        ),
        Err(StepError::StateMismatch {
            expected: 441,
            got: 440
        })
    );
}

#[test]
fn pbd_stretch_falls_with_iterations_and_pins_hold() {
    let stretch_after = |iterations: u32| {
        let (model, mut state) = lab();
        let mut ws = PbdWorkspace::default();
        for _ in 0..100 {
            Method::step(
                &PbdSolver { iterations },
                &model,
                &mut state,
                &StepParams::LAB,
                &[],
                &mut ws,
            )
            .unwrap();
        }
        assert_eq!(state.positions[0], Vec3A::new(5.0, 0.0, 5.0));
        assert_eq!(state.positions[20], Vec3A::new(-5.0, 0.0, 5.0));
        max_stretch(&model, &state.positions)
    };
    let s8 = stretch_after(8);
    let s32 = stretch_after(32);
    let s128 = stretch_after(128);
    assert!(s128 < s32 && s32 < s8, "{s8} {s32} {s128}");
}

#[test]
fn max_stretch_and_energy_measure_the_state() {
    let (model, mut state) = lab();
    assert_eq!(max_stretch(&model, &state.positions), 0.0);
    let params = StepParams::LAB;
    // At rest in the y = 0 plane: no kinetic, spring or potential energy.
    assert!(energy(&model, &state, &params).abs() < 1e-6);
    // Stretch the cloth by 10 % in x: every x spring is 10 % longer.
    for p in &mut state.positions {
        p.x *= 1.1;
    }
    assert!((max_stretch(&model, &state.positions) - 0.1).abs() < 1e-5);
    assert!(energy(&model, &state, &params) > 0.0);
}

#[test]
fn measure_finds_the_stretch_and_energy_of_the_f64_formulas_in_one_pass() {
    let (model, state) = swinging(40);
    let params = StepParams::LAB;
    let measured = measure(&model, &state, &params).unwrap();
    // The same quantities summed spring by spring and vertex by vertex in f64.
    let k = params.stiffness.as_array();
    let x = &state.positions;
    let (mut worst, mut springs) = (f64::NEG_INFINITY, 0.0f64);
    for s in model.topology().springs() {
        let l = (x[s.a as usize].as_dvec3() - x[s.b as usize].as_dvec3()).length();
        let rest = f64::from(s.rest_length);
        worst = worst.max((l - rest) / rest);
        springs += 0.5 * f64::from(k[s.kind as usize]) * (l - rest) * (l - rest);
    }
    let g = params.gravity.as_dvec3();
    let vertices: f64 = model
        .masses()
        .iter()
        .zip(x.iter().zip(&state.velocities))
        .map(|(&m, (x, v))| {
            let m = f64::from(m);
            0.5 * m * v.as_dvec3().length_squared() - m * g.dot(x.as_dvec3())
        })
        .sum();
    assert!(worst > 0.01, "the swinging cloth is stretched: {worst}");
    assert!((f64::from(measured.max_stretch) - worst).abs() < 1e-5 * (1.0 + worst));
    let exact = springs + vertices;
    assert!(
        (measured.energy - exact).abs() < 1e-5 * (springs.abs() + vertices.abs()),
        "{} against {exact}",
        measured.energy
    );
    // The separate functions are the same measures, bit for bit.
    assert_eq!(measured.max_stretch, max_stretch(&model, x));
    assert_eq!(measured.energy, energy(&model, &state, &params));
    // A non-finite velocity (not only a position) makes it `None`.
    let mut bad = state.clone();
    bad.velocities[7].y = f32::INFINITY;
    assert_eq!(measure(&model, &bad, &params), None);
    assert!(energy(&model, &bad, &params).is_nan());
}

#[test]
fn spring_products_refuse_positions_fewer_than_the_vertices() {
    // The pass reads positions without a check per index: too few
    // positions must panic at its entry, at every level, never read past.
    let (model, state) = swinging(5);
    let springs = Springs::of(&model);
    let short = &state.positions[..state.positions.len() - 1];
    for simd in Simd::supported() {
        let mut out = vec![Vec3A::ZERO; springs.list().len()];
        let coeffs = vec![[1.0, 1.0]; out.len()];
        let run = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            simd::spring_products(simd, springs, &coeffs, short, &mut out)
        }));
        assert!(run.is_err(), "{simd:?} ran on too few positions");
    }
}

#[test]
fn spring_products_give_the_same_bits_at_every_simd_level() {
    let (model, mut state) = swinging(5);
    let mut seed = 7;
    for x in &mut state.positions {
        *x += 0.05 * noise(&mut seed);
    }
    // A spring of zero length: its direction is undefined, its product 0.
    let springs = model.topology().springs();
    let s = springs[springs.len() - 3];
    state.positions[s.a as usize] = state.positions[s.b as usize];
    // Every spring count from 0 to past a 16-lane group, and the whole cloth
    // (1240 springs: 77 full 16-lane groups and a tail).
    let coeffs: Vec<[f32; 2]> = (0..springs.len())
        .map(|e| [1000.0 + e as f32, 3.0 * e as f32 - 700.0])
        .collect();
    let levels = Simd::supported();
    assert_eq!(levels[0], Simd::Baseline);
    assert!(levels.contains(&Simd::Auto.resolve()));
    eprintln!("levels run: {levels:?}");
    for len in (0..40).chain([springs.len() - 16, springs.len()]) {
        let start = springs.len() - len;
        let run = |simd| {
            let mut out = vec![Vec3A::splat(f32::NAN); len];
            simd::spring_products(
                simd,
                Springs::of(&model).range(start..springs.len()),
                &coeffs[start..],
                &state.positions,
                &mut out,
            );
            out.iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        let baseline = run(Simd::Baseline);
        // The baseline is the formula: d·(α − β/l), 0 for a zero length.
        for (e, (spring, [alpha, beta])) in
            springs[start..].iter().zip(&coeffs[start..]).enumerate()
        {
            let d = state.positions[spring.a as usize] - state.positions[spring.b as usize];
            let l = d.length();
            let expected = if l > 0.0 {
                d * (alpha - beta / l)
            } else {
                Vec3A::ZERO
            };
            let got = Vec3A::from_array(baseline[e].map(f32::from_bits));
            assert!(
                (got - expected).length() <= 1e-5 * expected.length().max(1.0),
                "spring {e}: {got} against {expected}"
            );
        }
        for &level in &levels {
            let got = run(level);
            let first = got.iter().zip(&baseline).position(|(a, b)| a != b);
            assert!(
                first.is_none(),
                "{level:?} with {len} springs: spring {first:?} differs"
            );
        }
    }
}

#[test]
fn every_method_steps_to_the_same_bits_at_every_simd_level() {
    let (model, start) = swinging(5);
    for preset in crate::methods::PRESETS {
        let run = |simd| {
            let params = StepParams {
                simd,
                ..StepParams::LAB
            };
            let mut state = start.clone();
            let mut ws = crate::methods::AnyWorkspace::default();
            for _ in 0..3 {
                preset
                    .method
                    .step(&model, &mut state, &params, &[], &mut ws)
                    .unwrap();
            }
            state
                .positions
                .iter()
                .chain(&state.velocities)
                .map(|v| v.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        let baseline = run(Simd::Baseline);
        for level in Simd::supported().into_iter().chain([Simd::Auto]) {
            let got = run(level);
            let first = got.iter().zip(&baseline).position(|(a, b)| a != b);
            assert!(
                first.is_none(),
                "{} at {level:?}: {first:?} differs",
                preset.name()
            );
        }
    }
}

#[test]
fn contact_error_counts_only_what_the_projection_does_not_undo() {
    // The lab cloth without pins, flat and at rest on a floor at its own
    // height: a method that did not move it at all is a whole step's fall
    // short of the exact step (x − g·dt²) ...
    let model = ClothBuilder::lab().with_pins([]).build().unwrap();
    let start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let params = StepParams::LAB;
    let dt = params.dt as f32;
    let fall = Vec3A::from(params.gravity) * (dt * dt);
    let mut measure = ContactError::default();
    let unmoved = start.positions.clone();
    let free = measure
        .relative_error(&model, &start, &unmoved, &unmoved, &params)
        .unwrap();
    assert!(free > 1.0, "no projection: {free}");
    // ... which the floor would undo: the exact step falls into it.
    let fallen: Vec<Vec3A> = unmoved.iter().map(|&x| x + 0.5 * fall).collect();
    let on_floor = measure
        .relative_error(&model, &start, &fallen, &unmoved, &params)
        .unwrap();
    assert!(on_floor < 1e-3, "resting on the floor: {on_floor}");
    // A solid above pushing it down by half the fall: the exact step falls
    // away from it and half the fall remains.
    let pushed_down: Vec<Vec3A> = unmoved.iter().map(|&x| x + 0.5 * fall).collect();
    let under = measure
        .relative_error(&model, &start, &unmoved, &pushed_down, &params)
        .unwrap();
    assert!(
        (under - 0.5 * free).abs() < 1e-3 * free,
        "{under} vs {free}"
    );
    // Mismatched lengths are refused.
    assert!(
        measure
            .relative_error(&model, &start, &unmoved[1..], &unmoved, &params)
            .is_none()
    );
}

#[test]
fn projected_convergence_judges_a_step_across_its_projection_once() {
    use crate::solver::{CONVERGENCE_TOLERANCE, ProjectedConvergence};
    // The floor scene above: a step that left the cloth where it was is a
    // whole step's fall short of the exact step.
    let model = ClothBuilder::lab().with_pins([]).build().unwrap();
    let start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let params = StepParams::LAB;
    let fall = Vec3A::from(params.gravity) * (params.dt * params.dt) as f32;
    let unmoved = start.positions.clone();
    let fallen: Vec<Vec3A> = unmoved.iter().map(|&x| x + 0.5 * fall).collect();
    let tolerance = CONVERGENCE_TOLERANCE;
    let flagged = Some(10.0 * tolerance);
    let mut rule = ProjectedConvergence::default();
    // No step recorded: nothing to judge.
    assert_eq!(rule.settle(&model, &start, &unmoved, &params), None);
    // A flagged step that fell halfway into the floor, put back by the
    // projection: measured again, within the tolerance.
    rule.stepped(flagged, true, tolerance);
    rule.before_projection(&fallen);
    // A second projection does not replace where the step left it.
    rule.before_projection(&unmoved);
    let judged = rule.settle(&model, &start, &unmoved, &params).unwrap();
    assert!(judged.is_some_and(|e| e < 1e-3), "{judged:?}");
    // Judged once: the next call has no step.
    assert_eq!(rule.settle(&model, &start, &unmoved, &params), None);
    // The same step not moved by the projection keeps its own error.
    rule.stepped(flagged, true, tolerance);
    rule.before_projection(&fallen);
    let kept = rule.settle(&model, &start, &fallen, &params).unwrap();
    assert_eq!(kept, flagged);
    // A halved step, or one within the tolerance, is never measured again.
    for (error, single) in [
        (flagged, false),
        (Some(0.5 * tolerance), true),
        (None, true),
    ] {
        rule.stepped(error, single, tolerance);
        rule.before_projection(&fallen);
        assert_eq!(rule.settle(&model, &start, &unmoved, &params), Some(error));
    }
}
