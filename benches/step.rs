//! One step of each pipeline on the lab cloth at 21×21 and 101×101.
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
use bevy_cloth::solver::StepParams;
use bevy_cloth::solver::implicit::{self, ImplicitConfig, ImplicitWorkspace};
use bevy_cloth::solver::pbd::{self, PbdConfig, PbdWorkspace};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

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
        implicit::step(
            model,
            &mut state,
            params,
            &ImplicitConfig::chebyshev(32, 0.995),
            &[],
            &mut ws,
        )
        .expect("valid step");
    }
    state
}

fn steps(c: &mut Criterion) {
    let mut group = c.benchmark_group("step");
    for n in [21, 101] {
        let (model, params) = scene(n);
        let start = warm(&model, &params);
        for (name, config) in [
            ("jacobi32", ImplicitConfig::jacobi(32)),
            ("chebyshev32", ImplicitConfig::chebyshev(32, 0.995)),
        ] {
            let mut ws = ImplicitWorkspace::default();
            let mut state = start.clone();
            group.bench_function(BenchmarkId::new(name, n), |b| {
                b.iter(|| {
                    state.copy_from(&start);
                    implicit::step(&model, &mut state, &params, &config, &[], &mut ws).unwrap();
                    black_box(&state);
                })
            });
        }
        let mut ws = PbdWorkspace::default();
        let mut state = start.clone();
        group.bench_function(BenchmarkId::new("pbd32", n), |b| {
            b.iter(|| {
                state.copy_from(&start);
                pbd::step(
                    &model,
                    &mut state,
                    &params,
                    &PbdConfig { iterations: 32 },
                    &[],
                    &mut ws,
                )
                .unwrap();
                black_box(&state);
            })
        });
        let sphere = [Sphere {
            center: bevy::math::Vec3A::new(0.0, -4.0, 4.0),
            radius: 2.7,
        }];
        let mut state = start.clone();
        group.bench_function(BenchmarkId::new("sphere_projection", n), |b| {
            b.iter(|| {
                state.copy_from(&start);
                black_box(project_spheres(&model, &mut state, &sphere, 0.0, params.dt));
            })
        });
    }
    group.finish();
}

criterion_group!(benches, steps);
criterion_main!(benches);
