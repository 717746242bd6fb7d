use bevy::math::{Affine3A, DMat3, DVec3, Vec3, Vec3A};

use super::*;
use crate::collision::PenaltySphere;
use crate::model::{ClothBuilder, ClothModel, ClothState};
use crate::solver::{SpringStiffness, StepParams};
use crate::testing::noise;

/// The assignment's scene parameters: h = 5e-3, E = 10, gravity −9.8 y, no
/// damping.
fn spec_params() -> StepParams {
    StepParams {
        dt: 5e-3,
        stiffness: SpringStiffness::uniform(10.0),
        damping: 1.0,
        gravity: Vec3::new(0.0, -9.8, 0.0),
        ..StepParams::LAB
    }
}

fn rest(model: &ClothModel) -> ClothState {
    ClothState::at_rest(model, &Affine3A::IDENTITY)
}

fn assemble(
    model: &ClothModel,
    state: &ClothState,
    params: &StepParams,
    config: &LinearImplicitSolver,
    spheres: &[PenaltySphere],
) -> LinearSystem {
    let mut system = LinearSystem::new(model);
    system.assemble(
        model,
        &state.positions,
        &state.velocities,
        params,
        config,
        spheres,
    );
    system
}

/// Dense Cholesky: true if the symmetric matrix is positive definite.
fn positive_definite(a: &[f64], n: usize) -> bool {
    crate::solver::engine::cholesky::cholesky_in_place(&mut a[..n * n].to_vec(), n)
}

#[test]
fn golden_first_step_of_the_assignment() {
    // The matrix printed in the assignment, for the 2×2 cloth's first step.
    let printed_a = [
        [0.0254, 0.0, 0.0001, -0.0003, 0.0, 0.0],
        [0.0, 0.0250, 0.0, 0.0, 0.0, 0.0],
        [0.0001, 0.0, 0.0254, 0.0, 0.0, 0.0],
        [-0.0003, 0.0, 0.0, 0.0254, 0.0, -0.0001],
        [0.0, 0.0, 0.0, 0.0, 0.0250, 0.0],
        [0.0, 0.0, 0.0, -0.0001, 0.0, 0.0254],
    ];
    let printed_b = [0.0, -0.0012, 0.0, 0.0, -0.0012, 0.0];
    let model = ClothBuilder::assignment(2, 2).build().unwrap();
    // Particles 0 and 1 (row 0) are fixed; 2 and 3 carry the 6 unknowns.
    assert_eq!(model.pins(), &[0, 1]);
    let system = assemble(
        &model,
        &rest(&model),
        &spec_params(),
        &LinearImplicitSolver::default(),
        &[],
    );
    assert_eq!(system.dimension(), 6);
    assert_eq!(system.dof(2), Some(0));
    assert_eq!(system.dof(3), Some(3));
    let a = system.to_dense();
    for r in 0..6 {
        for c in 0..6 {
            let got = a[r * 6 + c];
            // Within half a unit of the 4th decimal: it prints as printed.
            assert!(
                (got - printed_a[r][c]).abs() <= 0.5e-4 * (1.0 + 1e-9),
                "A[{r}][{c}] = {got:.6}, printed {}",
                printed_a[r][c]
            );
        }
        let got = system.rhs()[r];
        assert!(
            (got - printed_b[r]).abs() <= 0.5e-4 * (1.0 + 1e-9),
            "b[{r}] = {got:.6}, printed {}",
            printed_b[r]
        );
    }
    // The exact values behind the rounding: m = 0.1/4, h²E = 2.5e-4, the
    // shear springs at 45° add h²E/2 to xx, zz and ±h²E/2 to xz.
    // (Masses are f32: 0.1/4 is 0.025 to 4e-10.)
    assert!((a[0] - (0.025 + 2.5e-4 + 1.25e-4)).abs() < 1e-9);
    assert!((a[2] - 1.25e-4).abs() < 1e-9);
    assert!((a[3] + 2.5e-4).abs() < 1e-9);
    assert!((a[3 * 6 + 5] + 1.25e-4).abs() < 1e-9);
    assert!((system.rhs()[1] + 0.025 * 9.8 * 5e-3).abs() < 1e-9);
}

/// `K` from the assembled `A = M − h²K`, and `f` from `b = Mv + hf` (v = 0).
fn stiffness_and_force(
    model: &ClothModel,
    x: &[Vec3A],
    params: &StepParams,
    config: &LinearImplicitSolver,
    spheres: &[PenaltySphere],
) -> (Vec<f64>, Vec<f64>, usize) {
    let zero = vec![Vec3A::ZERO; x.len()];
    let mut system = LinearSystem::new(model);
    system.assemble(model, x, &zero, params, config, spheres);
    let n = system.dimension();
    let h = params.dt;
    let a = system.to_dense();
    let mut k = vec![0.0; n * n];
    for r in 0..n {
        for c in 0..n {
            let m = if r == c {
                f64::from(model.masses()[0])
            } else {
                0.0
            };
            k[r * n + c] = (m - a[r * n + c]) / (h * h);
        }
    }
    let gravity = params.gravity.as_dvec3();
    let mut f: Vec<f64> = system.rhs().iter().map(|b| b / h).collect();
    // Remove gravity: f here is the spring (and penalty) force only.
    for (i, &m) in model.masses().iter().enumerate() {
        if let Some(d) = system.dof(i) {
            for axis in 0..3 {
                f[d + axis] -= f64::from(m) * gravity[axis];
            }
        }
    }
    (k, f, n)
}

#[test]
fn assembled_stiffness_matches_finite_differences_of_the_force() {
    let model = ClothBuilder::assignment(4, 4).build().unwrap();
    let mut seed = 3;
    // Some springs stretched, some compressed.
    let x: Vec<Vec3A> = rest(&model)
        .positions
        .iter()
        .map(|&p| p + 0.05 * noise(&mut seed))
        .collect();
    let params = StepParams {
        stiffness: SpringStiffness {
            stretch: 10.0,
            shear: 7.0,
            bend: 3.0,
        },
        ..spec_params()
    };
    let sphere = PenaltySphere {
        center: x[10] + Vec3A::new(0.0, -0.05, 0.0),
        radius: 0.1,
        stiffness: 50.0,
        surface: Default::default(),
    };
    let config = LinearImplicitSolver {
        penalty: PenaltyJacobian::Exact,
        ..LinearImplicitSolver::default()
    };
    let (k, _, n) = stiffness_and_force(&model, &x, &params, &config, &[sphere]);
    let system = LinearSystem::new(&model);
    let eps = 1e-3f32;
    let mut worst = 0.0f64;
    let mut scale = 0.0f64;
    for i in 0..model.vertex_count() {
        let Some(d) = system.dof(i) else { continue };
        for axis in 0..3 {
            let mut xp = x.clone();
            let mut xm = x.clone();
            xp[i][axis] += eps;
            xm[i][axis] -= eps;
            let step = f64::from(xp[i][axis]) - f64::from(xm[i][axis]);
            let (_, fp, _) = stiffness_and_force(&model, &xp, &params, &config, &[sphere]);
            let (_, fm, _) = stiffness_and_force(&model, &xm, &params, &config, &[sphere]);
            for r in 0..n {
                let fd = (fp[r] - fm[r]) / step;
                worst = worst.max((fd - k[r * n + d + axis]).abs());
                scale = scale.max(k[r * n + d + axis].abs());
            }
        }
    }
    assert!(worst < 1e-3 * scale, "worst {worst} of {scale}");
}

#[test]
fn one_spring_block_matches_its_formula_and_finite_differences() {
    // K_s = ∂f₀/∂x₁ for f₀ = E(l − L)Δx/l, Δx = x₁ − x₀.
    let e = 10.0;
    let rest_length = 1.0;
    let x0 = DVec3::new(0.1, -0.2, 0.3);
    let x1 = DVec3::new(1.3, 0.4, -0.2);
    let force = |x1: DVec3| {
        let dx = x1 - x0;
        let l = dx.length();
        dx * (e * (l - rest_length) / l)
    };
    let dx = x1 - x0;
    let l = dx.length();
    let strain = (l - rest_length) / l;
    let outer = DMat3::from_cols(dx * dx.x, dx * dx.y, dx * dx.z);
    let ks = (outer * (1.0 - strain) + DMat3::IDENTITY * (strain * l * l)) * (e / (l * l));
    for c in 0..3 {
        let mut d = DVec3::ZERO;
        d[c] = 1e-6;
        let fd = (force(x1 + d) - force(x1 - d)) / 2e-6;
        assert!((fd - ks.col(c)).length() < 1e-6, "column {c}");
    }
}

#[test]
fn sparse_matches_a_dense_reference() {
    let model = ClothBuilder::assignment(3, 4).build().unwrap();
    let mut seed = 11;
    let mut state = rest(&model);
    for (p, v) in state.positions.iter_mut().zip(state.velocities.iter_mut()) {
        *p += 0.02 * noise(&mut seed);
        *v = noise(&mut seed);
    }
    let params = spec_params();
    let system = assemble(
        &model,
        &state,
        &params,
        &LinearImplicitSolver::default(),
        &[],
    );
    // An independent dense assembly over all 3·12 coordinates, then the
    // fixed particles' rows and columns dropped.
    let nv = model.vertex_count();
    let h = params.dt;
    let mut a = vec![0.0; 9 * nv * nv];
    let mut b = vec![0.0; 3 * nv];
    let n3 = 3 * nv;
    for i in 0..nv {
        let m = f64::from(model.masses()[i]);
        for axis in 0..3 {
            a[(3 * i + axis) * n3 + 3 * i + axis] += m;
            b[3 * i + axis] +=
                m * f64::from(state.velocities[i][axis]) + h * m * f64::from(params.gravity[axis]);
        }
    }
    for s in model.topology().springs() {
        let (i, j) = (s.a as usize, s.b as usize);
        let dx = state.positions[j].as_dvec3() - state.positions[i].as_dvec3();
        let l = dx.length();
        let big_l = f64::from(s.rest_length);
        let e = f64::from(params.stiffness.of(s.kind));
        let fs = dx * (e * (l - big_l) / l);
        for axis in 0..3 {
            b[3 * i + axis] += h * fs[axis];
            b[3 * j + axis] -= h * fs[axis];
        }
        for r in 0..3 {
            for c in 0..3 {
                let id = if r == c { dx.dot(dx) } else { 0.0 };
                let ks =
                    e / (l * l) * ((1.0 - (l - big_l) / l) * dx[r] * dx[c] + (l - big_l) / l * id);
                // K = [[−Ks, Ks], [Ks, −Ks]], A = M − h²K.
                a[(3 * i + r) * n3 + 3 * i + c] += h * h * ks;
                a[(3 * j + r) * n3 + 3 * j + c] += h * h * ks;
                a[(3 * i + r) * n3 + 3 * j + c] -= h * h * ks;
                a[(3 * j + r) * n3 + 3 * i + c] -= h * h * ks;
            }
        }
    }
    let free: Vec<usize> = (0..nv)
        .filter(|&i| !model.pinned()[i])
        .flat_map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
        .collect();
    let n = free.len();
    assert_eq!(n, system.dimension());
    let sparse = system.to_dense();
    for (r, &fr) in free.iter().enumerate() {
        assert!((system.rhs()[r] - b[fr]).abs() < 1e-12);
        for (c, &fc) in free.iter().enumerate() {
            assert!(
                (sparse[r * n + c] - a[fr * n3 + fc]).abs() < 1e-12,
                "A[{r}][{c}]"
            );
        }
    }
    // Symmetric, and only the blocks a spring couples are stored.
    for r in 0..n {
        for c in 0..n {
            assert_eq!(sparse[r * n + c], sparse[c * n + r]);
        }
    }
    assert!(system.nonzeros() < n * n);
}

fn step_with(
    model: &ClothModel,
    start: &ClothState,
    params: &StepParams,
    config: &LinearImplicitSolver,
) -> (ClothState, StepReport) {
    let mut state = start.clone();
    let mut ws = LinearWorkspace::default();
    let report = Method::step(config, model, &mut state, params, &[], &mut ws).unwrap();
    (state, report)
}

#[test]
fn cg_converges_to_the_direct_solution() {
    let model = ClothBuilder::assignment(10, 10).build().unwrap();
    let params = spec_params();
    let mut start = rest(&model);
    let mut ws = LinearWorkspace::default();
    let direct_config = LinearImplicitSolver {
        solver: LinearSolver::Direct,
        ..LinearImplicitSolver::default()
    };
    for _ in 0..20 {
        Method::step(&direct_config, &model, &mut start, &params, &[], &mut ws).unwrap();
    }
    let (direct, report) = step_with(&model, &start, &params, &direct_config);
    assert!(report.residual.unwrap() < 1e-12, "{report:?}");
    let error = |iterations: u32, preconditioner: Preconditioner| {
        let config = LinearImplicitSolver {
            solver: LinearSolver::Cg(CgConfig {
                max_iterations: iterations,
                tolerance: 1e-14,
                preconditioner,
            }),
            ..LinearImplicitSolver::default()
        };
        let (cg, _) = step_with(&model, &start, &params, &config);
        cg.velocities
            .iter()
            .zip(&direct.velocities)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f32::max)
    };
    let e2 = error(2, Preconditioner::None);
    let e10 = error(10, Preconditioner::None);
    let e200 = error(200, Preconditioner::None);
    assert!(e10 < e2 && e200 < e10, "{e2} {e10} {e200}");
    assert!(e200 < 1e-5, "{e200}");
    assert!(error(200, Preconditioner::Jacobi) < 1e-5);
}

#[test]
fn the_pattern_is_built_once_and_fixed_particles_never_move() {
    let model = ClothBuilder::assignment(6, 6).build().unwrap();
    let mut state = rest(&model);
    let pins: Vec<Vec3A> = model
        .pins()
        .iter()
        .map(|&p| state.positions[p as usize])
        .collect();
    let mut ws = LinearWorkspace::default();
    for solver in [LinearSolver::Direct, LinearSolver::Cg(CgConfig::default())] {
        let config = LinearImplicitSolver {
            solver,
            ..LinearImplicitSolver::default()
        };
        for _ in 0..50 {
            Method::step(&config, &model, &mut state, &spec_params(), &[], &mut ws).unwrap();
        }
    }
    assert_eq!(ws.pattern_builds(), 1);
    for (&p, &x) in model.pins().iter().zip(&pins) {
        assert_eq!(state.positions[p as usize], x);
    }
    assert!(state.positions[35].y < 0.4, "the free corner fell");
    // Other pins: a new pattern.
    let repinned = ClothBuilder::assignment(6, 6)
        .with_pins([0])
        .build()
        .unwrap();
    let mut other = rest(&repinned);
    Method::step(
        &LinearImplicitSolver::default(),
        &repinned,
        &mut other,
        &spec_params(),
        &[],
        &mut ws,
    )
    .unwrap();
    assert_eq!(ws.pattern_builds(), 2);
}

#[test]
fn penalty_jacobians_differ_in_definiteness() {
    let model = ClothBuilder::assignment(2, 2).build().unwrap();
    let state = rest(&model);
    // A sphere deep under particle 2, with a stiffness that dominates the mass.
    let sphere = PenaltySphere {
        center: state.positions[2] - Vec3A::new(0.0, 0.05, 0.0),
        radius: 0.1,
        stiffness: 1e5,
        surface: Default::default(),
    };
    let params = spec_params();
    let matrix = |penalty| {
        let config = LinearImplicitSolver {
            penalty,
            ..LinearImplicitSolver::default()
        };
        assemble(&model, &state, &params, &config, &[sphere]).to_dense()
    };
    let normal = matrix(PenaltyJacobian::Normal);
    let isotropic = matrix(PenaltyJacobian::Isotropic);
    let exact = matrix(PenaltyJacobian::Exact);
    let h2c = 2.5e-5 * 1e5;
    // Normal: h²c along the normal (y) only.
    assert!((normal[7] - (0.025 + h2c)).abs() < 1e-6);
    assert!((normal[0] - 0.025_375).abs() < 1e-6);
    // Isotropic (the assignment's c·d·I): h²c·d on x, y and z, d = 0.05.
    assert!((isotropic[7] - (0.025 + h2c * 0.05)).abs() < 1e-6);
    assert!((isotropic[0] - (0.025_375 + h2c * 0.05)).abs() < 1e-6);
    // Exact: the normal term plus −h²c·d/l = −h²c across the normal (l = d):
    // the tangential diagonal goes negative.
    assert!((exact[7] - (0.025 + h2c)).abs() < 1e-6);
    assert!(exact[0] < 0.0);
    assert!(positive_definite(&normal, 6));
    assert!(positive_definite(&isotropic, 6));
    assert!(!positive_definite(&exact, 6));
}

#[test]
fn clamping_compression_keeps_the_matrix_definite() {
    // Light particles and stiff springs, compressed to half their length.
    let model = ClothBuilder::assignment(6, 6)
        .with_total_mass(1e-3)
        .build()
        .unwrap();
    let mut state = rest(&model);
    for p in &mut state.positions {
        *p *= 0.5;
    }
    let params = StepParams {
        stiffness: SpringStiffness::uniform(1e3),
        dt: 1e-2,
        ..spec_params()
    };
    let dense = |springs| {
        let config = LinearImplicitSolver {
            springs,
            ..LinearImplicitSolver::default()
        };
        let system = assemble(&model, &state, &params, &config, &[]);
        (system.to_dense(), system.dimension())
    };
    let (exact, n) = dense(SpringJacobian::Exact);
    let (clamped, _) = dense(SpringJacobian::ClampCompression);
    assert!(!positive_definite(&exact, n));
    assert!(positive_definite(&clamped, n));
}

#[test]
fn a_penalty_sphere_pushes_particles_out() {
    let model = ClothBuilder::assignment(10, 10).build().unwrap();
    let params = spec_params();
    // A sphere where the cloth, swinging down from its fixed row at z = 0,
    // would hang: it drapes over it.
    let sphere = PenaltySphere {
        center: Vec3A::new(0.0, 0.15, -0.1),
        radius: 0.15,
        stiffness: 100.0,
        surface: Default::default(),
    };
    for config in [
        LinearImplicitSolver::default(),
        LinearImplicitSolver {
            solver: LinearSolver::Direct,
            penalty: PenaltyJacobian::Isotropic,
            ..LinearImplicitSolver::default()
        },
    ] {
        let mut state = rest(&model);
        let mut ws = LinearWorkspace::default();
        let mut deepest = 0.0f32;
        for k in 0..600 {
            Method::step(&config, &model, &mut state, &params, &[sphere], &mut ws).unwrap();
            if k > 300 {
                for p in &state.positions {
                    deepest = deepest.max(sphere.radius - p.distance(sphere.center));
                }
            }
        }
        assert!(state.is_finite());
        // Resting on the sphere: touching it, never deep inside (the penalty
        // balances the weight at a depth of a few millimetres).
        assert!(deepest > 0.0, "{config:?}: never touched");
        assert!(deepest < 0.02, "{config:?}: {deepest} deep");
    }
}
