//! The pass between cloths after their steps ([`ClothLayers`]).

use bevy::math::{Affine3A, Vec3, Vec3A};

use super::flat_sheet;
use crate::collision::SelfCollision;
use crate::collision::self_contact::ClothLayers;
use crate::model::{ClothBuilder, ClothState};
use crate::solver::max_stretch;

/// A small pinned triangle of another cloth (a heavy cloth's corner), a
/// third of `thickness` over `vertex`, its corners a fifth of it away.
fn corner_over(vertex: Vec3A, thickness: f32) -> crate::model::ClothModel {
    let over = Vec3::from(vertex) + Vec3::Y * (thickness / 3.0);
    let r = 0.2 * thickness;
    ClothBuilder::from_triangles(
        vec![
            over + Vec3::new(r, 0.0, 0.0),
            over + Vec3::new(-r, 0.0, r),
            over + Vec3::new(-r, 0.0, -r),
        ],
        vec![0, 1, 2],
    )
    .with_pins([0, 1, 2])
    .build()
    .unwrap()
}

/// A flat 16² sheet of 1 m and, a third of its thickness over its middle
/// vertex, a small pinned triangle of another cloth (a heavy cloth's
/// corner): the pass pushes that vertex and its nearest neighbours down,
/// alone. Its springs take the whole push until
/// [`ClothLayers::follow`] pulls its rings after it: the vertex stays
/// down, the stretch is spread, and the same each run.
#[test]
fn the_rings_around_a_pushed_vertex_follow_it() {
    let n = 16;
    let (sheet, x) = flat_sheet(n);
    let sc = SelfCollision::for_model(&sheet);
    let middle = (n / 2) * n + n / 2;
    let corner = corner_over(x[middle], sc.thickness);
    let y = ClothState::at_rest(&corner, &Affine3A::IDENTITY).positions;
    let run = || {
        let mut layers = ClothLayers::default();
        let dt = 1.0 / 60.0;
        layers.add(&sheet, &x, &x, dt, sc);
        layers.add(&corner, &y, &y, dt, sc);
        layers.resolve(dt);
        let pushed = layers.positions(0).to_vec();
        layers.follow(0, &sheet);
        (pushed, layers.positions(0).to_vec())
    };
    let (pushed, followed) = run();
    assert!(
        pushed[middle].y < -0.2 * sc.thickness,
        "{} {}",
        pushed[middle],
        sc.thickness
    );
    let moved = |p: &[Vec3A]| (0..p.len()).filter(|&i| p[i] != x[i]).count();
    // The middle vertex and its nearest neighbours, pushed; more follow,
    // and the middle one stays down.
    let (few, more) = (moved(&pushed), moved(&followed));
    assert!(few <= 9 && more > few, "{few} pushed, {more} followed");
    assert!(
        followed[middle].y < pushed[middle].y / 2.0,
        "{}",
        followed[middle]
    );
    let (alone, spread) = (max_stretch(&sheet, &pushed), max_stretch(&sheet, &followed));
    println!("{spread} from {alone}, thickness {}", sc.thickness);
    assert!(spread < alone / 2.0, "{spread} from {alone}");
    assert_eq!(run(), (pushed, followed));
}

/// The plugin's pass between cloths on a `stiff` cloth (one whose rings
/// follow its pushed vertices) that has an edge through its own triangles
/// (two layers of one cloth, a vertex of the upper poked through the
/// lower) and a pinned corner of another cloth pressing on its upper
/// layer: the pass moves it, and its own edge through is taken back out
/// before the step ends, as its step ends with. The rings pulled after a
/// pushed vertex have no eye on the cloth's own folds.
#[test]
fn a_followed_cloth_the_pass_moved_ends_with_no_own_edge_through() {
    use bevy::ecs::system::RunSystemOnce;
    use bevy::prelude::{Time, World};
    use core::time::Duration;

    use crate::collision::self_contact::{IntersectionCheck, count_intersections};
    use crate::ecs::{ClothLayerVertices, collide_cloths, gather_layers};
    use crate::{Cloth, ClothStats};

    let n = 16;
    let (model, sc, x, _) = super::untangle::poked(n);
    // Over the upper layer's vertex at (3, 3), a third of the thickness up.
    let pressed = (n * n + 3 * n + 3) as usize;
    let corner = corner_over(x[pressed], sc.thickness);
    // Thinner than the corner's own edges, as the component must be.
    let thin = SelfCollision {
        thickness: 0.2 * sc.thickness,
        ..sc
    };
    assert!(thin.validate(&corner).is_ok());
    let run = |followed: bool| {
        let mut world = World::new();
        let mut time = Time::<()>::default();
        time.advance_by(Duration::from_secs_f64(1.0 / 60.0));
        world.insert_resource(time);
        world.init_resource::<ClothLayerVertices>();
        // The component's hook places it at rest: the poked positions after.
        let a = world
            .spawn((Cloth::new(model.clone()), sc, ClothStats::default()))
            .id();
        world.spawn((Cloth::new(corner.clone()), thin, ClothStats::default()));
        for mut cloth in world.query::<&mut Cloth>().iter_mut(&mut world) {
            cloth.initialized = true;
        }
        let mut layered = world.get_mut::<Cloth>(a).unwrap();
        layered.state.positions.clone_from(&x);
        layered.last_good.positions.clone_from(&x);
        layered.held_others = followed;
        world.run_system_once(gather_layers).unwrap();
        world.run_system_once(collide_cloths).unwrap();
        let cloth = world.get::<Cloth>(a).unwrap();
        let moved = (0..x.len())
            .filter(|&i| cloth.state.positions[i] != x[i])
            .count();
        let through = count_intersections(
            &model,
            &cloth.state.positions,
            &mut IntersectionCheck::default(),
        );
        (moved, through, cloth.state.positions.clone())
    };
    // Not followed (the other methods' cloths): pushed, its own edge
    // left for its next step.
    let (moved, through, _) = run(false);
    assert!(moved > 0 && through > 0, "{moved} moved, {through} through");
    let (moved, through, followed) = run(true);
    assert!(moved > 0, "{moved}");
    assert_eq!(through, 0);
    assert_eq!(run(true).2, followed);
}
