//! Property tests: random meshes, pins, masses, stiffnesses, time steps and
//! spheres never panic any method, and valid input to the exact implicit
//! method stays finite and is never stopped by the guard.

use bevy::math::{Vec3, Vec3A};
use bevy_cloth::collision::PenaltySphere;
use bevy_cloth::model::{ClothBuilder, ClothModel};
use bevy_cloth::solver::guard::GuardBounds;
use bevy_cloth::solver::{SpringStiffness, StepParams};
use bevy_cloth_report::scenarios::{Scenario, map_methods, run};
use proptest::prelude::*;

/// A random triangle soup: vertices in a 10-unit box, triangles of three
/// distinct vertices (overlapping, sliver or crossing ones included). One
/// case in eight also gets a triangle with an out-of-range or repeated index,
/// which the builder must refuse with an error, not a panic.
fn mesh() -> impl Strategy<Value = (Vec<Vec3>, Vec<u32>)> {
    (3usize..24).prop_flat_map(|n| {
        let n32 = n as u32;
        let triangle = (0..n32, 0..n32, 0..n32)
            .prop_filter("distinct vertices", |(a, b, c)| a != b && b != c && a != c)
            .prop_map(|(a, b, c)| [a, b, c]);
        let bad = prop_oneof![
            Just(Vec::new()),
            Just(Vec::new()),
            Just(Vec::new()),
            Just(Vec::new()),
            Just(Vec::new()),
            Just(Vec::new()),
            Just(vec![0, n32, 1]),
            Just(vec![1, 1, 2]),
        ];
        (
            prop::collection::vec(
                (-5.0f32..5.0, -5.0f32..5.0, -5.0f32..5.0).prop_map(|(x, y, z)| Vec3::new(x, y, z)),
                n,
            ),
            prop::collection::vec(triangle, 1..30),
            bad,
        )
            .prop_map(|(positions, triangles, bad)| {
                let mut indices: Vec<u32> = triangles.into_iter().flatten().collect();
                indices.extend(bad);
                (positions, indices)
            })
    })
}

fn sphere() -> impl Strategy<Value = PenaltySphere> {
    (
        (-6.0f32..6.0, -6.0f32..6.0, -6.0f32..6.0),
        0.0f32..4.0,
        1.0f32..1e5,
    )
        .prop_map(|((x, y, z), radius, stiffness)| PenaltySphere {
            center: Vec3A::new(x, y, z),
            radius,
            stiffness,
            surface: Default::default(),
        })
}

/// Parameters over the whole valid range and beyond it (zero, negative and
/// NaN values included).
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => (0.0f32..8.0).prop_map(|e| 10f32.powf(e)),
        1 => Just(0.0f32),
        1 => Just(-1.0f32),
        1 => Just(f32::NAN),
    ]
}

/// Five steps of `model` with stiffness `k`, time step `dt` and `spheres`.
fn five_steps(
    model: ClothModel,
    k: f32,
    dt: f64,
    spheres: Vec<PenaltySphere>,
    bounds: GuardBounds,
) -> Scenario {
    Scenario {
        name: "fuzz".into(),
        model,
        params: StepParams {
            dt,
            stiffness: SpringStiffness::uniform(k),
            ..StepParams::LAB
        },
        spheres,
        contacts: Vec::new(),
        steps: 5,
        events: Vec::new(),
        bounds,
        start: None,
        record_every: 0,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn nothing_panics_on_any_input(
        (positions, indices) in mesh(),
        pins in prop::collection::vec(0u32..30, 0..4),
        mass in any_f32(),
        k in any_f32(),
        dt in prop_oneof![4 => (-4.0f64..-1.0).prop_map(|e| 10f64.powf(e)), 1 => Just(0.0), 1 => Just(f64::NAN)],
        spheres in prop::collection::vec(sphere(), 0..2),
    ) {
        let built = ClothBuilder::from_triangles(positions, indices)
            .with_mass_per_vertex(mass)
            .with_pins(pins)
            .build();
        let Ok(model) = built else {
            // Refused with a typed error: fine.
            return Ok(());
        };
        let scenario = five_steps(model, k, dt, spheres, GuardBounds::default());
        for method in map_methods() {
            let r = run(&scenario, &method);
            // Invalid parameters are refused with a typed error; nothing
            // panics and nothing non-finite passes the guard.
            if let Some(why) = &r.failed {
                prop_assert!(why.starts_with("refused"), "{}: {why}", method.name());
            }
            prop_assert!(r.state.is_finite());
        }
    }

    #[test]
    fn valid_input_keeps_the_exact_method_finite(
        (positions, indices) in mesh(),
        pins in prop::collection::vec(0u32..3, 0..3),
        masses in prop::collection::vec(0.01f32..100.0, 24),
        k in (0.0f32..6.0).prop_map(|e| 10f32.powf(e)),
        dt in (-4.0f64..-1.0).prop_map(|e| 10f64.powf(e)),
        spheres in prop::collection::vec(sphere(), 0..2),
    ) {
        let n = positions.len();
        let Ok(model) = ClothBuilder::from_triangles(positions, indices)
            .with_masses(masses[..n].to_vec())
            .with_pins(pins)
            .build() else { return Ok(()); };
        let scenario = five_steps(model, k, dt, spheres, GuardBounds::FINITE_ONLY);
        let exact = map_methods().pop().unwrap();
        let r = run(&scenario, &exact);
        prop_assert!(r.failed.is_none(), "{:?}", r.failed);
        prop_assert!(r.caught.is_none(), "{:?}", r.caught);
        prop_assert!(r.state.is_finite());
    }
}
