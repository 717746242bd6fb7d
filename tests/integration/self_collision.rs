//! Self-collision in an app: a sheet crumpling on the ground does not pass
//! through itself with `stiff`, passes through itself far less with a
//! method that leaves it to after the step, and a bad setting is refused
//! with the cloth still running.

use bevy::prelude::*;
use bevy_cloth::collision::self_contact::{
    IntersectionCheck, count_crossings, count_intersections,
};
use bevy_cloth::prelude::*;

use crate::common::{app, run_steps, stats};

/// A 1 m sheet of 20² cotton standing on its edge, a little tilted, above
/// the ground, with `method`; `thickness` (a share of the shortest rest
/// edge) picks the component, `None` for none. The most edges through the
/// sheet after any of 120 steps, the most pairs touching, the last stats.
fn crumple(method: AnyMethod, thickness: Option<f32>) -> (usize, u32, ClothStats) {
    let mut app = app();
    app.insert_resource(Time::<Fixed>::from_seconds(1.0 / 60.0));
    app.world_mut()
        .spawn((PlaneCollider::new(0.5), Transform::default()));
    let model = ClothBuilder::grid(
        20,
        20,
        Vec3::new(0.0, 0.02, 0.0),
        Vec3::new(0.0, 1.0, 0.15),
        Vec3::new(1.0, 0.02, 0.0),
    )
    .build()
    .unwrap();
    let mut sc = SelfCollision::for_model(&model);
    let mut entity = app.world_mut().spawn((
        Cloth::new(model),
        ClothMaterial::COTTON,
        Transform::default(),
    ));
    if let Some(share) = thickness {
        // `for_model` is 0.9 of the shortest edge.
        sc.thickness *= share / 0.9;
        entity.insert(sc);
    }
    let cloth = entity.id();
    method.insert(&mut app.world_mut().commands().entity(cloth));
    let mut check = IntersectionCheck::default();
    let (mut worst, mut most_pairs) = (0, 0);
    for _ in 0..120 {
        run_steps(&mut app, 1);
        let c = app.world().get::<Cloth>(cloth).unwrap();
        worst = worst.max(count_intersections(
            c.model(),
            &c.state().positions,
            &mut check,
        ));
        most_pairs = most_pairs.max(stats(&app, cloth).self_contacts);
    }
    (worst, most_pairs, stats(&app, cloth))
}

#[test]
fn stiff_keeps_a_crumpling_sheet_off_itself_in_an_app() {
    let stiff = AnyMethod::default();
    let (without, pairs, _) = crumple(stiff, None);
    assert!(without > 0, "the scene must fold through itself without it");
    assert_eq!(pairs, 0, "no self-contacts without the component");
    let (with, pairs, s) = crumple(stiff, Some(0.9));
    assert_eq!(
        with, 0,
        "{without} edges through the sheet without self-collision"
    );
    assert!(pairs > 0, "the folds touch");
    assert!(s.is_running(), "{s:?}");
}

#[test]
fn a_method_without_it_inside_gets_it_after_the_step() {
    let pd = PRESETS.iter().find(|p| p.name() == "pd").unwrap().method;
    let (without, _, _) = crumple(pd, None);
    let (with, pairs, s) = crumple(pd, Some(0.9));
    println!("pd: {without} edges through the sheet without, {with} with");
    assert!(pairs > 0 && s.is_running(), "{s:?}");
    assert!(with * 2 < without, "{with} with against {without} without");
}

/// A thin setting (0.3 of the edges, below `FACES_BELOW`: vertex–triangle
/// and edge–edge pairs as well as vertex pairs) through the plugin: `stiff`
/// (pairs in every substep) and `pd` (the vertex–triangle pairs in its
/// solve) and `chebyshev` (after its step) keep the crumpling sheet off
/// itself, unstretched.
#[test]
fn a_thin_setting_keeps_a_crumpling_sheet_off_itself_in_an_app() {
    use bevy_cloth::collision::self_contact::FACES_BELOW;
    const { assert!(0.3 < FACES_BELOW) };
    let preset = |name: &str| PRESETS.iter().find(|p| p.name() == name).unwrap().method;
    for name in ["stiff", "pd", "chebyshev"] {
        let (without, _, _) = crumple(preset(name), None);
        let (with, pairs, s) = crumple(preset(name), Some(0.3));
        println!(
            "{name}, thin: {without} edges through the sheet at worst without, {with} with, {pairs} pairs, stretch {:.3}",
            s.max_stretch
        );
        assert!(s.is_running(), "{name}: {s:?}");
        assert!(pairs > 0, "{name}: the folds touch");
        assert!(without > 0, "{name}: the scene must fold through itself");
        assert_eq!(with, 0, "{name}: {without} without");
        assert!(s.max_stretch < 0.05, "{name}: {s:?}");
    }
}

#[test]
fn a_bad_setting_is_refused_and_the_cloth_keeps_running() {
    let mut app = app();
    let cloth = Cloth::build(ClothBuilder::lab_grid(11)).unwrap();
    let bad = SelfCollision {
        thickness: f32::NAN,
        friction: 0.2,
    };
    assert!(bad.validate(cloth.model()).is_err());
    let entity = app
        .world_mut()
        .spawn((cloth, ImplicitSolver::chebyshev(32, 0.995), bad))
        .id();
    run_steps(&mut app, 10);
    let s = stats(&app, entity);
    assert!(s.is_running() && s.steps >= 9, "{s:?}");
    assert_eq!(s.self_contacts, 0);
    let c = app.world().get::<Cloth>(entity).unwrap();
    assert!(c.state().positions.iter().all(|p| p.is_finite()));
}

/// A 1 m sheet of 16² cotton, flat, at `height`, turned by `turn` about y,
/// stepped by `method`.
fn flat_sheet(
    app: &mut App,
    (height, turn): (f32, f32),
    method: AnyMethod,
    self_collision: bool,
) -> Entity {
    let model = ClothBuilder::grid(
        16,
        16,
        Vec3::new(-0.5, 0.0, -0.5),
        Vec3::new(-0.5, 0.0, 0.5),
        Vec3::new(0.5, 0.0, -0.5),
    )
    .build()
    .unwrap();
    let sc = SelfCollision::for_model(&model);
    let at = Transform::from_xyz(0.0, height, 0.0).with_rotation(Quat::from_rotation_y(turn));
    let mut entity = app
        .world_mut()
        .spawn((Cloth::new(model), ClothMaterial::COTTON, at));
    if self_collision {
        entity.insert(sc);
    }
    let e = entity.id();
    method.insert(&mut app.world_mut().commands().entity(e));
    e
}

/// Two sheets dropped onto each other over a ball on the ground, stepped by
/// `method`, over two seconds: the most edges of either through the other
/// at any step, the most through a sheet's own triangles, and the sheets'
/// last stats.
struct SheetOnSheet {
    crossings: usize,
    own: usize,
    stats: [ClothStats; 2],
}

/// See [`SheetOnSheet`].
fn sheet_on_sheet(method: AnyMethod, self_collision: bool) -> SheetOnSheet {
    let mut app = app();
    app.insert_resource(Time::<Fixed>::from_seconds(1.0 / 60.0));
    app.world_mut()
        .spawn((PlaneCollider::new(0.5), Transform::default()));
    // A ball on the ground for the sheets to drape over.
    app.world_mut().spawn((
        SphereCollider::new(0.3).with_friction(0.5),
        Transform::from_xyz(0.0, 0.3, 0.0),
    ));
    let lower = flat_sheet(&mut app, (0.65, 0.0), method, self_collision);
    let upper = flat_sheet(&mut app, (0.9, 0.35), method, self_collision);
    let mut check = IntersectionCheck::default();
    let (mut worst, mut own) = (0, 0);
    for _ in 0..120 {
        run_steps(&mut app, 1);
        let world = app.world();
        let (a, b) = (
            world.get::<Cloth>(lower).unwrap(),
            world.get::<Cloth>(upper).unwrap(),
        );
        let now = count_crossings(
            (a.model(), &a.state().positions),
            (b.model(), &b.state().positions),
            &mut check,
        );
        worst = worst.max(now);
        for c in [a, b] {
            own = own.max(count_intersections(
                c.model(),
                &c.state().positions,
                &mut check,
            ));
        }
    }
    SheetOnSheet {
        crossings: worst,
        own,
        stats: [stats(&app, lower), stats(&app, upper)],
    }
}

#[test]
fn a_sheet_falling_on_a_sheet_stays_on_top() {
    let without = sheet_on_sheet(AnyMethod::default(), false);
    assert!(
        without.crossings > 0,
        "without it the sheets must pass through each other"
    );
    let with = sheet_on_sheet(AnyMethod::default(), true);
    for s in &with.stats {
        assert!(s.is_running(), "{s:?}");
    }
    assert_eq!(
        with.crossings, 0,
        "{} crossings at worst without",
        without.crossings
    );
    assert_eq!(with.own, 0);
}

/// Two cloths, likewise, with every method: no sheet through the other or
/// through itself at any step, and what the guard stops is reported (the
/// symplectic method's step is past its stability limit for cotton at
/// 60 Hz; the linearly implicit method with a direct solve lands the upper
/// sheet on the lower at 49 % stretch, where the stability map's folded
/// rows catch it too), never left NaN.
#[test]
fn sheets_falling_on_each_other_stay_apart_with_every_method() {
    let mut ran = Vec::new();
    for p in PRESETS {
        let run = sheet_on_sheet(p.method, true);
        let [a, b] = &run.stats;
        println!(
            "{}: {} crossings, {} own at worst; stretch {:.3} / {:.3}; {:?} / {:?}",
            p.name(),
            run.crossings,
            run.own,
            a.max_stretch,
            b.max_stretch,
            a.status,
            b.status
        );
        for s in &run.stats {
            assert!(
                s.is_running() || matches!(s.status, ClothStatus::Diverged(_)),
                "{}: {s:?}",
                p.name()
            );
        }
        assert_eq!((run.crossings, run.own), (0, 0), "{}", p.name());
        if run.stats.iter().all(ClothStats::is_running) {
            ran.push(p.name());
        }
    }
    // Every method but those two runs the whole scene.
    assert_eq!(ran.len(), PRESETS.len() - 2, "{ran:?}");
    assert!(!ran.contains(&"symplectic") && !ran.contains(&"linear-direct"));
}

/// The edges of either of two cloths through the other's triangles.
fn crossings(app: &App, [a, b]: [Entity; 2], check: &mut IntersectionCheck) -> usize {
    let world = app.world();
    let (a, b) = (
        world.get::<Cloth>(a).unwrap(),
        world.get::<Cloth>(b).unwrap(),
    );
    count_crossings(
        (a.model(), &a.state().positions),
        (b.model(), &b.state().positions),
        check,
    )
}

/// A sheet like `grid` whose rest shape has its middle vertex moved by
/// `poke`, of cotton with `sc`, at `height`, stepped by the default method.
fn poked_sheet(
    app: &mut App,
    grid: &ClothModel,
    sc: SelfCollision,
    poke: Vec3,
    height: f32,
) -> Entity {
    let mut positions = grid.topology().rest_positions().to_vec();
    positions[8 * 16 + 8] += poke;
    let indices = grid
        .topology()
        .triangles()
        .iter()
        .flatten()
        .copied()
        .collect();
    let model = ClothBuilder::from_triangles(positions, indices)
        .with_material(ClothMaterial::COTTON)
        .build()
        .unwrap();
    let e = app
        .world_mut()
        .spawn((
            Cloth::new(model),
            ClothMaterial::COTTON,
            sc,
            Transform::from_xyz(0.0, height, 0.0),
        ))
        .id();
    AnyMethod::default().insert(&mut app.world_mut().commands().entity(e));
    e
}

/// Two sheets spawned with one already poked through the other, at rest
/// in that shape (the upper sheet's rest shape has its middle vertex a
/// third of the thickness under the lower sheet, a third of an edge aside:
/// nothing moves fast, and both fall together): the take-back between
/// cloths checks them the first step it sees them together and takes the
/// poke back out. After that step the check runs only after fast relative
/// motion or while it finds edges through; the pairs' pushes alone held
/// the poke through for good.
#[test]
fn sheets_spawned_through_each_other_are_taken_apart() {
    let mut app = app();
    app.insert_resource(Time::<Fixed>::from_seconds(1.0 / 60.0));
    let lower = flat_sheet(&mut app, (0.6, 0.0), AnyMethod::default(), true);
    let grid = app.world().get::<Cloth>(lower).unwrap().model().clone();
    let sc = SelfCollision::for_model(&grid);
    let (h, above) = (1.0 / 15.0, 0.7 * sc.thickness);
    let poke = Vec3::new(h / 3.0, -above - sc.thickness / 3.0, h / 3.0);
    let upper = poked_sheet(&mut app, &grid, sc, poke, 0.6 + above);
    let mut check = IntersectionCheck::default();
    // (Without the first step's check, the poke is through after it.)
    for step in 0..60 {
        run_steps(&mut app, 1);
        assert_eq!(
            crossings(&app, [lower, upper], &mut check),
            0,
            "step {step}"
        );
    }
    for e in [lower, upper] {
        let s = stats(&app, e);
        assert!(s.is_running() && s.max_stretch < 0.1, "{s:?}");
    }
}

/// A thin setting (0.3 of the edges) between two cloths: the upper sheet's
/// rest shape has a vertex poked 1.3 thicknesses under it, a third of an
/// edge aside of the lower sheet's vertices (further from them than the
/// thickness), and it sinks onto the lower one at 0.3 m/s without gravity,
/// slower than the take-back's motion gate (half the thickness a step
/// relative to the two). The vertex pairs cannot see the poke pass through
/// a triangle; the take-back checks such cloths every step and keeps it
/// out (without that, it stayed through).
#[test]
fn a_thin_setting_keeps_a_slow_poke_out_of_another_cloth() {
    use bevy::math::Vec3A;
    let mut app = app();
    app.insert_resource(Time::<Fixed>::from_seconds(1.0 / 60.0));
    let still = ClothParams::default().with_gravity(Vec3::ZERO);
    let lower = flat_sheet(&mut app, (0.6, 0.0), AnyMethod::default(), true);
    let grid = app.world().get::<Cloth>(lower).unwrap().model().clone();
    let mut sc = SelfCollision::for_model(&grid);
    sc.thickness *= 0.3 / 0.9;
    let h = 1.0 / 15.0;
    let poke = Vec3::new(h / 3.0, -1.3 * sc.thickness, h / 3.0);
    let upper = poked_sheet(&mut app, &grid, sc, poke, 0.6 + 1.3 * sc.thickness + 0.004);
    app.world_mut().entity_mut(lower).insert((sc, still));
    app.world_mut().entity_mut(upper).insert(still);
    run_steps(&mut app, 1);
    for v in app
        .world_mut()
        .get_mut::<Cloth>(upper)
        .unwrap()
        .state_mut()
        .velocities
        .iter_mut()
    {
        *v = Vec3A::new(0.0, -0.3, 0.0);
    }
    let mut check = IntersectionCheck::default();
    let mut worst = 0;
    for _ in 0..30 {
        run_steps(&mut app, 1);
        worst = worst.max(crossings(&app, [lower, upper], &mut check));
    }
    for e in [lower, upper] {
        let s = stats(&app, e);
        assert!(s.is_running(), "{s:?}");
    }
    assert_eq!(worst, 0, "edges through at worst");
}

/// The drape scene's thrown ball (10 cm at 30 m/s through the two 32²
/// sheets' skirt, `stiff`): it presses one sheet through the other within
/// a step, and the edges crossed are taken back out in the next steps
/// (before, the pushes held 40 of them crossed for the rest of the run:
/// 1,793 summed over these 200 steps).
#[test]
fn sheets_a_thrown_ball_pressed_through_each_other_come_apart() {
    use crate::drape_scene::{DrapeSettings, run_headless};
    let run = run_headless(
        DrapeSettings {
            throw_at: Some(2.5),
            ..Default::default()
        },
        200,
    );
    let p = &run.penetrations;
    println!(
        "drape 32², a ball thrown at 2.5 s: {} edges through a sheet summed over 200 steps, {} in the worst step, {} touches",
        p.total, p.worst, p.ball_touches
    );
    assert!(p.ball_touches > 0, "the ball missed the sheets");
    assert!(p.total < 200, "{} edges through summed", p.total);
    for (_, stats, _) in &run.sheets {
        assert!(stats.is_running(), "{stats:?}");
    }
}

/// The drape scene at 20² with `stiff`'s chains and the ball thrown at
/// 2.5 s, 600 steps: the untangling after a step moves vertices, and the
/// sheet settles after them (positions only) before the next step's
/// chains see the stretch the move left. Without the settling the chains
/// took it back at once, as velocity: 28.9 % stretch and 2 edges through.
#[test]
fn with_chains_an_untangled_sheet_is_not_thrown() {
    use crate::drape_scene::{DrapeSettings, run_headless};
    let run = run_headless(
        DrapeSettings {
            method: AnyMethod::Xpbd(XpbdSolver::STIFF.with_chains(true)),
            n: 20,
            throw_at: Some(2.5),
            ..Default::default()
        },
        600,
    );
    let p = &run.penetrations;
    println!(
        "drape 20² with chains, a ball thrown at 2.5 s: {} edges through summed over 600 steps, {} touches, max stretch {:.3}",
        p.total, p.ball_touches, p.max_stretch
    );
    assert!(p.ball_touches > 0, "the ball missed the sheets");
    assert!(p.max_stretch < 0.1, "stretched {}", p.max_stretch);
    for (_, stats, _) in &run.sheets {
        assert!(stats.is_running(), "{stats:?}");
    }
}

/// The drape scene (two 24² sheets of cotton onto a ball, `stiff`): with
/// self-collision a small fraction of the edges through a sheet it has
/// without, both sheets still running and not torn.
#[test]
fn the_drape_scene_keeps_its_sheets_apart() {
    use crate::drape_scene::{DrapeSettings, run_headless};
    let settings = |self_collision| DrapeSettings {
        n: 24,
        self_collision,
        ..Default::default()
    };
    let without = run_headless(settings(false), 200);
    let with = run_headless(settings(true), 200);
    let (a, b) = (without.penetrations.total, with.penetrations.total);
    println!(
        "drape 24²: {a} edges through a sheet summed over 200 steps without, {b} with (most in a step {} / {}), max stretch {:.3}",
        without.penetrations.worst, with.penetrations.worst, with.penetrations.max_stretch
    );
    assert!(
        a > 1000,
        "the sheets must pass through each other without it: {a}"
    );
    assert!(b * 50 < a, "{b} with against {a} without");
    assert_eq!(with.sheets.len(), 2);
    for (_, stats, _) in &with.sheets {
        assert!(stats.is_running(), "{stats:?}");
    }
    assert!(with.penetrations.max_stretch < 0.25);
}

/// Removing the component clears the stats' pair count on the next step.
#[test]
fn removing_it_clears_the_pair_count() {
    let mut app = app();
    // Two lab cloths 0.3 m apart (the thickness is 0.9 m): pairs touch.
    let spawn = |app: &mut App, z: f32| {
        let model = ClothBuilder::lab_grid(11).build().unwrap();
        let sc = SelfCollision::for_model(&model);
        app.world_mut()
            .spawn((
                Cloth::new(model),
                ImplicitSolver::chebyshev(32, 0.995),
                sc,
                Transform::from_xyz(0.0, 0.0, z),
            ))
            .id()
    };
    let cloth = spawn(&mut app, 0.0);
    spawn(&mut app, 0.3);
    run_steps(&mut app, 3);
    assert!(stats(&app, cloth).self_contacts > 0);
    app.world_mut().entity_mut(cloth).remove::<SelfCollision>();
    run_steps(&mut app, 1);
    assert_eq!(stats(&app, cloth).self_contacts, 0);
}
