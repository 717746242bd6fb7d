//! Dragging the sphere with (synthetic) picking events, headless.

use bevy::camera::NormalizedRenderTarget;
use bevy::picking::backend::HitData;
use bevy::picking::events::{Drag, DragStart, Pointer, Press, Release};
use bevy::picking::pointer::{Location, PointerButton, PointerId};
use bevy::prelude::*;
use bevy::window::{WindowRef, WindowResolution};
use bevy_cloth::drag::{DragPlugin, Draggable, Dragging, pointer_ray};
use bevy_cloth::prelude::*;

use crate::common::*;

const SIZE: Vec2 = Vec2::new(800.0, 600.0);

/// Where a world point appears on screen (the inverse of `pointer_ray`).
fn to_screen(camera: &GlobalTransform, projection: &Projection, world: Vec3) -> Vec2 {
    let Projection::Perspective(p) = projection else {
        unreachable!()
    };
    let local = camera.affine().inverse().transform_point3(world);
    let half = (p.fov * 0.5).tan();
    let ndc = Vec2::new(
        local.x / -local.z / (half * SIZE.x / SIZE.y),
        local.y / -local.z / half,
    );
    Vec2::new((ndc.x + 1.0) * 0.5 * SIZE.x, (1.0 - ndc.y) * 0.5 * SIZE.y)
}

#[test]
fn pointer_rays_go_through_the_pixels_they_came_from() {
    let camera = GlobalTransform::from(
        Transform::from_xyz(3.0, 2.0, 10.0).looking_at(Vec3::new(0.0, -1.0, 0.0), Vec3::Y),
    );
    let projection = Projection::default();
    for world in [
        Vec3::ZERO,
        Vec3::new(2.0, -3.0, 1.0),
        Vec3::new(-4.0, 1.0, -2.0),
    ] {
        let cursor = to_screen(&camera, &projection, world);
        let ray = pointer_ray(&camera, &projection, SIZE, cursor).unwrap();
        let along = (world - ray.origin).dot(*ray.direction);
        assert!(ray.get_point(along).distance(world) < 1e-4);
    }
    assert!(
        pointer_ray(
            &camera,
            &Projection::Orthographic(OrthographicProjection::default_3d()),
            SIZE,
            Vec2::ZERO
        )
        .is_none()
    );
}

#[test]
fn dragging_the_sphere_moves_it_and_it_pushes_the_cloth() {
    let mut app = app_with((
        ClothPlugins::default(),
        bevy::transform::TransformPlugin,
        DragPlugin,
    ));
    let window = app
        .world_mut()
        .spawn(Window {
            resolution: WindowResolution::new(SIZE.x as u32, SIZE.y as u32),
            ..default()
        })
        .id();
    // A camera on the +x side looking at the hanging curtain (plane z ≈ 5).
    let camera_transform =
        Transform::from_xyz(40.0, -5.0, 5.0).looking_at(Vec3::new(0.0, -5.0, 5.0), Vec3::Y);
    let camera = app
        .world_mut()
        .spawn((camera_transform, Projection::default()))
        .id();
    let cloth = spawn_lab(&mut app, ImplicitSolver::chebyshev(32, 0.995));
    let start = Vec3::new(0.0, -5.0, 12.0);
    let sphere = app
        .world_mut()
        .spawn((
            SphereCollider::new(2.7),
            Transform::from_translation(start),
            Draggable,
        ))
        .id();
    run_steps(&mut app, 300);
    let before = positions(&app, cloth);
    assert_eq!(stats(&app, cloth).contacts, 0);

    let camera_global = GlobalTransform::from(camera_transform);
    let projection = Projection::default();
    let target = NormalizedRenderTarget::Window(WindowRef::Entity(window).normalize(None).unwrap());
    let location = |world: Vec3| Location {
        target: target.clone(),
        position: to_screen(&camera_global, &projection, world),
    };
    let hit = HitData::new(camera, 40.0, Some(start), Some(Vec3::X));
    let world = app.world_mut();
    world.trigger(Pointer::new(
        PointerId::Mouse,
        location(start),
        Press {
            button: PointerButton::Primary,
            hit: hit.clone(),
            count: 1,
        },
        sphere,
    ));
    assert_eq!(app.world().resource::<Dragging>().entity, Some(sphere));
    app.world_mut().trigger(Pointer::new(
        PointerId::Mouse,
        location(start),
        DragStart {
            button: PointerButton::Primary,
            hit: hit.clone(),
        },
        sphere,
    ));
    // Drag through the curtain to z = −1, one pointer event per fixed step.
    let end = Vec3::new(0.0, -5.0, -1.0);
    let mut last = location(start).position;
    for k in 1..=130 {
        let goal = start.lerp(end, k as f32 / 130.0);
        let here = location(goal);
        app.world_mut().trigger(Pointer::new(
            PointerId::Mouse,
            here.clone(),
            Drag {
                button: PointerButton::Primary,
                distance: here.position - location(start).position,
                delta: here.position - last,
            },
            sphere,
        ));
        last = here.position;
        run_steps(&mut app, 1);
    }
    // The sphere followed the pointer in the plane facing the camera.
    let moved = app.world().get::<Transform>(sphere).unwrap().translation;
    assert!(moved.distance(end) < 1e-2, "sphere at {moved}");
    // The cloth responded: pushed back, and no vertex inside the sphere.
    let after = positions(&app, cloth);
    for p in &after {
        assert!(p.distance(moved.into()) >= 2.7 - 1e-3);
    }
    let mean_z = |x: &[Vec3A]| x.iter().map(|p| p.z).sum::<f32>() / x.len() as f32;
    assert!(mean_z(&after) < mean_z(&before) - 1.0);
    assert!(stats(&app, cloth).contacts > 0);
    app.world_mut().trigger(Pointer::new(
        PointerId::Mouse,
        location(end),
        Release {
            button: PointerButton::Primary,
            hit,
        },
        sphere,
    ));
    assert_eq!(app.world().resource::<Dragging>().entity, None);
}
