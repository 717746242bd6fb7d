//! One step of each pipeline on the lab cloth at 21×21 and 101×101
//! (projective dynamics at its preset and with its direct solve), and of
//! the assignment's methods on its cloth at 10×10, 30×30 and 100×100; and
//! self-collision's pair search on a folded sheet at 64² and 101².
//!
//! The 101×101 cloth keeps the lab's size (10×10 units) and total mass (441,
//! spread over the vertices) and the lab's `k = 8000`: on a square grid a
//! row of `n − 1` springs in series has stiffness `k/(n − 1)` and `n` rows
//! act in parallel, so the sheet's stiffness is about `k` at any resolution.
//! The state is a swinging cloth after 20 warm-up steps, so every benchmark
//! times a representative step.

use std::hint::black_box;

use bevy::math::Affine3A;
use bevy_cloth::collision::{Sphere, project_spheres};
use bevy_cloth::model::{ClothBuilder, ClothModel, ClothState};
use bevy_cloth::solver::implicit::{ImplicitSolver, ImplicitWorkspace};
use bevy_cloth::solver::linear::{LinearImplicitSolver, LinearSolver, LinearWorkspace};
use bevy_cloth::solver::pbd::PbdSolver;
use bevy_cloth::solver::projective::{GlobalSolve, PD_ITERATIONS, ProjectiveSolver};
use bevy_cloth::solver::symplectic::SymplecticSolver;
use bevy_cloth::solver::symplectic::SymplecticWorkspace;
use bevy_cloth::solver::{Method, SpringStiffness, StepParams};
use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, BenchmarkId, Criterion, criterion_group, criterion_main};

fn scene(n: usize) -> (ClothModel, StepParams) {
    let model = ClothBuilder::lab_grid(n)
        .with_total_mass(441.0)
        .with_pins([0, n as u32 - 1])
        .build()
        .expect("valid cloth");
    (model, StepParams::LAB)
}

fn warm(model: &ClothModel, params: &StepParams) -> ClothState {
    let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
    let mut ws = ImplicitWorkspace::default();
    for _ in 0..20 {
        Method::step(
            &ImplicitSolver::chebyshev(32, 0.995),
            model,
            &mut state,
            params,
            &[],
            &mut ws,
        )
        .expect("valid step");
    }
    state
}

/// Times one step of `method` from `start` (the state copy included, as
/// every benchmark here), its workspace kept from step to step.
fn bench_step<M: Method>(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: BenchmarkId,
    method: &M,
    model: &ClothModel,
    params: &StepParams,
    start: &ClothState,
) {
    let mut ws = M::Workspace::default();
    let mut state = start.clone();
    group.bench_function(id, |b| {
        b.iter(|| {
            state.copy_from(start);
            method
                .step(model, &mut state, params, &[], &mut ws)
                .unwrap();
            black_box(&state);
        })
    });
}

fn steps(c: &mut Criterion) {
    let mut group = c.benchmark_group("step");
    for n in [21, 101] {
        let (model, params) = scene(n);
        let start = warm(&model, &params);
        for (name, config) in [
            ("jacobi32", ImplicitSolver::jacobi(32)),
            ("chebyshev32", ImplicitSolver::chebyshev(32, 0.995)),
        ] {
            bench_step(
                &mut group,
                BenchmarkId::new(name, n),
                &config,
                &model,
                &params,
                &start,
            );
        }
        bench_step(
            &mut group,
            BenchmarkId::new("pbd32", n),
            &PbdSolver { iterations: 32 },
            &model,
            &params,
            &start,
        );
        // Projective dynamics at its preset (at most 10 iterations, stopping
        // early at an estimated 1 % error), its whole budget of 10 (the
        // direct solve at 21², one multigrid V-cycle per iteration at 101²),
        // and that always direct.
        for (name, config) in [
            ("pd_preset", ProjectiveSolver::PRESET),
            ("pd10", ProjectiveSolver::chebyshev(PD_ITERATIONS)),
            (
                "pd10_direct",
                ProjectiveSolver::chebyshev(PD_ITERATIONS).with_global(GlobalSolve::Direct),
            ),
        ] {
            bench_step(
                &mut group,
                BenchmarkId::new(name, n),
                &config,
                &model,
                &params,
                &start,
            );
        }
        let sphere = [Sphere {
            center: bevy::math::Vec3A::new(0.0, -4.0, 4.0),
            radius: 2.7,
            friction: 0.0,
        }];
        let mut state = start.clone();
        group.bench_function(BenchmarkId::new("sphere_projection", n), |b| {
            b.iter(|| {
                state.copy_from(&start);
                black_box(project_spheres(
                    &model,
                    &mut state,
                    &sphere,
                    0.0,
                    params.dt as f32,
                ));
            })
        });
    }
    group.finish();
}

/// One linearly implicit step of the assignment's cloth (stretch, shear and
/// bending springs; its parameters) at 10×10, 30×30 and 100×100, with CG
/// (25 iterations, 1e-6, warm-started) and with the direct LDLᵀ solve
/// (symbolic analysis reused), from a swinging state.
fn linear(c: &mut Criterion) {
    let mut group = c.benchmark_group("linear");
    group.sample_size(20);
    let params = StepParams {
        dt: 5e-3,
        stiffness: SpringStiffness::uniform(10.0),
        damping: 1.0,
        ..StepParams::LAB
    };
    for n in [10, 30, 100] {
        let model = ClothBuilder::assignment(n, n).build().expect("valid cloth");
        let mut start = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let mut ws = LinearWorkspace::default();
        let direct = LinearImplicitSolver {
            solver: LinearSolver::Direct,
            ..LinearImplicitSolver::default()
        };
        for _ in 0..20 {
            Method::step(&direct, &model, &mut start, &params, &[], &mut ws).expect("valid step");
        }
        for (name, config) in [
            ("cg25", LinearImplicitSolver::default()),
            ("direct", direct),
        ] {
            let mut ws = LinearWorkspace::default();
            let mut state = start.clone();
            group.bench_function(BenchmarkId::new(name, n), |b| {
                b.iter(|| {
                    state.copy_from(&start);
                    Method::step(&config, &model, &mut state, &params, &[], &mut ws).unwrap();
                    black_box(&state);
                })
            });
        }
        let mut state = start.clone();
        let mut ws = SymplecticWorkspace::default();
        group.bench_function(BenchmarkId::new("symplectic", n), |b| {
            b.iter(|| {
                state.copy_from(&start);
                Method::step(&SymplecticSolver, &model, &mut state, &params, &[], &mut ws).unwrap();
                black_box(&state);
            })
        });
    }
    group.finish();
}

/// Self-collision's pair search (`SelfContacts::find`) on a cotton sheet
/// of 1 m at 64² and 101², folded flat in four layers 1.3 thicknesses
/// apart (the perf page's landing sheet, its folds sharp) and falling at
/// 1 m/s: the search a landing step makes.
fn self_collision(c: &mut Criterion) {
    use bevy::math::{Vec3, Vec3A};
    use bevy_cloth::collision::SelfCollision;
    use bevy_cloth::collision::self_contact::{SelfCollisionInput, SelfContacts};
    use bevy_cloth::model::ClothMaterial;

    let mut group = c.benchmark_group("self_collision");
    for n in [64, 101] {
        let model = ClothBuilder::grid(n, n, Vec3::ZERO, Vec3::Z, Vec3::X)
            .with_material(ClothMaterial::COTTON)
            .build()
            .expect("valid cloth");
        let sc = SelfCollision::for_model(&model);
        let layer = 0.25;
        let x: Vec<Vec3A> = ClothState::at_rest(&model, &Affine3A::IDENTITY)
            .positions
            .iter()
            .map(|p| {
                let j = ((p.x / layer) as usize).min(3);
                let u = p.x - j as f32 * layer;
                let along = if j.is_multiple_of(2) { u } else { layer - u };
                Vec3A::new(along, 0.05 + 1.3 * sc.thickness * j as f32, p.z)
            })
            .collect();
        let v = vec![Vec3A::new(0.0, -1.0, 0.0); x.len()];
        let mut contacts = SelfContacts::default();
        group.bench_function(BenchmarkId::new("find", n), |b| {
            b.iter(|| {
                contacts.find(
                    &model,
                    &x,
                    &v,
                    1.0 / 60.0,
                    SelfCollisionInput::alone(sc),
                    0.0,
                );
                black_box(contacts.pair_count());
            })
        });
    }
    group.finish();
}

criterion_group!(benches, steps, linear, self_collision);
criterion_main!(benches);
