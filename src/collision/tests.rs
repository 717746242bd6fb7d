use bevy::math::{Affine3A, Vec3A};

use super::*;
use crate::model::ClothBuilder;

#[test]
fn vertices_inside_are_projected_to_the_surface_with_matching_velocity() {
    let model = ClothBuilder::lab().build().unwrap();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    let before = state.clone();
    let sphere = Sphere {
        center: Vec3A::new(0.0, -1.0, 0.0),
        radius: 2.7,
    };
    let dt = 0.0333;
    let count = project_spheres(&model, &mut state, &[sphere], 0.0, dt);
    let inside = before
        .positions
        .iter()
        .filter(|p| p.distance(sphere.center) < 2.7)
        .count();
    assert!(count > 0);
    assert_eq!(count, inside);
    for i in 0..state.len() {
        let d = state.positions[i].distance(sphere.center);
        assert!(d >= 2.7 - 1e-4, "vertex {i} at distance {d}");
        let moved = state.positions[i] - before.positions[i];
        assert!((state.velocities[i] - moved / dt).length() < 1e-3);
    }
}

#[test]
fn pinned_vertices_and_the_centre_case() {
    let model = ClothBuilder::lab().build().unwrap();
    let mut state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
    // A sphere centred exactly on pinned vertex 0 and on free vertex 220.
    let spheres = [
        Sphere {
            center: state.positions[0],
            radius: 0.1,
        },
        Sphere {
            center: state.positions[220],
            radius: 0.1,
        },
    ];
    let pin = state.positions[0];
    let free = state.positions[220];
    assert_eq!(project_spheres(&model, &mut state, &spheres, 0.0, 0.01), 1);
    assert_eq!(state.positions[0], pin);
    assert!((state.positions[220] - (free + Vec3A::Y * 0.1)).length() < 1e-6);
}
