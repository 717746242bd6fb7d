//! The pass between cloths after their steps ([`ClothLayers`]).

use bevy::math::{Affine3A, Vec3, Vec3A};

use super::flat_sheet;
use crate::collision::SelfCollision;
use crate::collision::self_contact::ClothLayers;
use crate::model::{ClothBuilder, ClothState};
use crate::solver::max_stretch;

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
    let over = Vec3::from(x[middle]) + Vec3::Y * (sc.thickness / 3.0);
    let r = 0.2 * sc.thickness;
    let corner = ClothBuilder::from_triangles(
        vec![
            over + Vec3::new(r, 0.0, 0.0),
            over + Vec3::new(-r, 0.0, r),
            over + Vec3::new(-r, 0.0, -r),
        ],
        vec![0, 1, 2],
    )
    .with_pins([0, 1, 2])
    .build()
    .unwrap();
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
