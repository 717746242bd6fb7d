//! Cloth given as a material, and capes of real mass with the default
//! method.

use bevy::prelude::*;
use bevy_cloth::prelude::*;

use crate::common::*;

/// A square cape `side` metres wide of `n×n` vertices, level, pinned along
/// its edge `z = 0`: mass 1 per vertex until a material says otherwise.
fn cape(n: usize, side: f32) -> ClothModel {
    ClothBuilder::grid(
        n,
        n,
        Vec3::new(side / 2.0, 0.0, 0.0),
        Vec3::new(-side / 2.0, 0.0, 0.0),
        Vec3::new(side / 2.0, 0.0, side),
    )
    .with_pins(0..n as u32)
    .build()
    .unwrap()
}

/// An app stepping at 60 Hz.
fn app_60() -> App {
    let mut app = app();
    app.insert_resource(Time::<Fixed>::from_seconds(1.0 / 60.0));
    app
}

#[test]
fn a_material_component_sets_the_springs_and_masses_and_follows_changes() {
    let mut app = app_60();
    let model = cape(16, 2.0);
    let cloth = app
        .world_mut()
        .spawn((
            Cloth::new(model.clone()),
            ClothMaterial::COTTON,
            Transform::default(),
        ))
        .id();
    AnyMethod::default().insert(&mut app.world_mut().commands().entity(cloth));
    run_steps(&mut app, 2);
    let world = app.world();
    let params = world.get::<ClothParams>(cloth).unwrap();
    assert_eq!(
        params.stiffness,
        ClothMaterial::COTTON.spring_stiffness(&model)
    );
    let total = |app: &App| -> f32 {
        app.world()
            .get::<Cloth>(cloth)
            .unwrap()
            .model()
            .masses()
            .iter()
            .sum()
    };
    assert!((total(&app) - 1.0).abs() < 1e-4, "{}", total(&app));

    // A denser, stiffer material acts at the next step.
    app.world_mut()
        .get_mut::<ClothMaterial>(cloth)
        .unwrap()
        .density = 0.5;
    app.world_mut()
        .get_mut::<ClothMaterial>(cloth)
        .unwrap()
        .stretch = 2.4e4;
    run_steps(&mut app, 1);
    assert!((total(&app) - 2.0).abs() < 1e-4, "{}", total(&app));
    let k = app.world().get::<ClothParams>(cloth).unwrap().stiffness;
    assert_eq!(
        k.stretch,
        2.0 * ClothMaterial::COTTON.spring_stiffness(&model).stretch
    );

    // A density of NaN leaves the masses as they were and the cloth
    // running; a stretch of NaN is refused with a typed error until fixed.
    app.world_mut()
        .get_mut::<ClothMaterial>(cloth)
        .unwrap()
        .density = f32::NAN;
    run_steps(&mut app, 1);
    assert!((total(&app) - 2.0).abs() < 1e-4);
    assert!(stats(&app, cloth).is_running());
    app.world_mut()
        .get_mut::<ClothMaterial>(cloth)
        .unwrap()
        .stretch = f32::NAN;
    run_steps(&mut app, 1);
    assert!(
        matches!(stats(&app, cloth).status, ClothStatus::Invalid(_)),
        "{:?}",
        stats(&app, cloth).status
    );
    *app.world_mut().get_mut::<ClothMaterial>(cloth).unwrap() = ClothMaterial::COTTON;
    run_steps(&mut app, 2);
    assert!(stats(&app, cloth).is_running());
    assert!(positions(&app, cloth).iter().all(|x| x.is_finite()));
}

#[test]
fn capes_of_real_mass_keep_their_length_with_the_default_material_and_method() {
    // Capes of 1 and 2 kg of the default material (2 m and 2.83 m square at
    // 0.25 kg/m²), 16² to 64² vertices, at 60 Hz with the default preset,
    // swinging down from level for 10 s: no step unconverged or retried,
    // and at most 5 % stretch (the 64² cape from its second second on: the
    // bottom of its first swing reaches a little over 5 %).
    for n in [16, 32, 64] {
        for side in [2.0f32, 2.0 * 2f32.sqrt()] {
            let mut app = app_60();
            let cloth = app
                .world_mut()
                .spawn((
                    Cloth::new(cape(n, side)),
                    ClothMaterial::default(),
                    Transform::default(),
                ))
                .id();
            AnyMethod::default().insert(&mut app.world_mut().commands().entity(cloth));
            let mut worst = 0.0f32;
            for step in 0..600 {
                run_steps(&mut app, 1);
                if n < 64 || step >= 60 {
                    worst = worst.max(stats(&app, cloth).max_stretch);
                }
            }
            let s = stats(&app, cloth);
            let mass: f32 = app
                .world()
                .get::<Cloth>(cloth)
                .unwrap()
                .model()
                .masses()
                .iter()
                .sum();
            let label = format!("{n}² cape of {mass:.2} kg");
            assert!((mass - side * side * 0.25).abs() < 1e-3, "{label}");
            assert_eq!(s.method, "stiff", "{label}");
            assert!(s.is_running() && s.steps == 600, "{label}: {s:?}");
            assert_eq!((s.unconverged_steps, s.retried_steps), (0, 0), "{label}");
            assert!(worst <= 0.05, "{label}: max stretch {worst}");
        }
    }
}
