//! What the unit tests share: deterministic pseudo-random numbers (Knuth's
//! MMIX linear congruential generator: the same sequence on every machine
//! and run) and a cloth run for some steps of a method.

use bevy::math::{Affine3A, Vec3A};

use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState};
use crate::solver::{Method, StepParams};

/// Advances `seed` and returns it.
pub(crate) fn next_u64(seed: &mut u64) -> u64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    *seed
}

/// A pseudo-random vector in [-1, 1]³.
pub(crate) fn noise(seed: &mut u64) -> Vec3A {
    let mut next = || ((next_u64(seed) >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0;
    Vec3A::new(next(), next(), next())
}

/// Two cotton layers of `n²` vertices in one cloth, `side` metres
/// across, the second `gap` metres above the first: vertices `0..n²` are
/// the lower layer's.
pub(crate) fn two_layers(n: u32, side: f32, gap: f32) -> ClothModel {
    use crate::model::{ClothBuilder, ClothMaterial};
    let h = side / (n - 1) as f32;
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for layer in 0..2u32 {
        let base = layer * n * n;
        for i in 0..n {
            for j in 0..n {
                let at = bevy::math::Vec3::new(j as f32 * h, gap * layer as f32, i as f32 * h);
                positions.push(at);
            }
        }
        for i in 0..n - 1 {
            for j in 0..n - 1 {
                let a = base + i * n + j;
                indices.extend([a, a + n, a + 1, a + 1, a + n, a + n + 1]);
            }
        }
    }
    ClothBuilder::from_triangles(positions, indices)
        .with_material(ClothMaterial::COTTON)
        .build()
        .expect("a valid two-layer cloth")
}

/// One step's input of `model` under `params` with self-collision `sc` (the
/// cloth alone) and nothing else.
pub(crate) fn self_colliding<'a>(
    model: &'a ClothModel,
    params: &'a StepParams,
    sc: crate::collision::SelfCollision,
) -> crate::solver::StepInput<'a> {
    crate::solver::StepInput {
        model,
        params,
        spheres: &[],
        contacts: &[],
        contact_motion: &[],
        skin: None,
        self_collision: Some(crate::collision::self_contact::SelfCollisionInput::alone(
            sc,
        )),
    }
}

/// `model` from rest after `steps` steps of `method` (a fresh workspace),
/// with `spheres` acting inside each step.
pub(crate) fn run_from_rest<M: Method>(
    method: &M,
    model: &ClothModel,
    params: &StepParams,
    spheres: &[PenaltySphere],
    steps: usize,
) -> ClothState {
    let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
    let mut ws = M::Workspace::default();
    for _ in 0..steps {
        method
            .step(model, &mut state, params, spheres, &mut ws)
            .expect("a valid step");
    }
    state
}

/// Issue M's slope: a 2 m cloth (5×5, k = 1e5, 60 Hz, no damping) laid on a
/// 20° slope of friction `friction`, taken as a contact inside `method`'s
/// step (no projection after), for one second. Returns the mean motion
/// along the slope (down it positive) and off it, and the largest
/// estimated error of a step. Without friction it slides
/// `g sin 20° t²/2 ≈ 1.7 m`.
pub(crate) fn slide_on_slope<M: Method>(method: &M, friction: f32) -> (f32, f32, f32) {
    use crate::collision::{Plane, Shape};
    use crate::model::ClothBuilder;
    use crate::solver::{SpringStiffness, StepInput};
    use bevy::math::Vec3;
    let angle = 20f32.to_radians();
    let normal = Vec3A::new(-angle.sin(), angle.cos(), 0.0);
    let down_slope = Vec3::new(-angle.cos(), -angle.sin(), 0.0);
    let model = ClothBuilder::grid(5, 5, Vec3::ZERO, 2.0 * down_slope, 2.0 * Vec3::Z)
        .build()
        .expect("a valid grid");
    let params = StepParams {
        dt: 1.0 / 60.0,
        damping: 1.0,
        stiffness: SpringStiffness::uniform(1e5),
        ..StepParams::LAB
    };
    let slope = Shape::Plane(Plane {
        point: Vec3A::ZERO,
        normal,
        friction,
    });
    let rest = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let mut state = rest.clone();
    let mut ws = M::Workspace::default();
    let mut error = 0.0f32;
    for _ in 0..60 {
        let input = StepInput {
            model: &model,
            params: &params,
            spheres: &[],
            contacts: &[slope],
            contact_motion: &[],
            skin: None,
            self_collision: None,
        };
        let report = method
            .step_with(input, &mut state, &mut ws)
            .expect("a valid step");
        error = error.max(report.relative_error.unwrap_or(f32::INFINITY));
    }
    let moved = state
        .positions
        .iter()
        .zip(&rest.positions)
        .map(|(x, r)| *x - *r)
        .sum::<Vec3A>()
        / state.positions.len() as f32;
    (moved.dot(Vec3A::from(down_slope)), moved.dot(normal), error)
}
