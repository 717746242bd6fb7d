//! Mouse dragging (cargo feature `picking`): [`DragPlugin`] lets the mouse
//! drag any entity marked [`Draggable`] in the plane through it that faces
//! the camera (press on it and move). While an entity is held, [`Dragging`]
//! names it, so a camera controller can stop orbiting. Needs Bevy's picking
//! with a backend (`MeshPickingPlugin`).

use bevy::camera::NormalizedRenderTarget;
use bevy::picking::events::{Drag, DragStart, Pointer, Press, Release};
use bevy::picking::pointer::Location;
use bevy::prelude::*;

/// Marks an entity the mouse can drag (it needs a mesh to be picked).
#[derive(Component, Reflect, Debug, Default, Clone, Copy, PartialEq)]
#[reflect(Component, Default, Debug)]
pub struct Draggable;

/// The entity held by the mouse, if any (set on press, cleared on release).
#[derive(Resource, Debug, Default, Clone, Copy, PartialEq)]
pub struct Dragging {
    /// The held entity.
    pub entity: Option<Entity>,
    /// Plane of the drag: a point and the normal facing the camera.
    plane: Option<(Vec3, Vec3)>,
    /// Offset from the grab point to the entity's origin.
    offset: Vec3,
    /// The camera the drag started from.
    camera_hint: Option<Entity>,
}

/// Drags [`Draggable`] entities with the mouse in the camera-facing plane.
/// Needs Bevy's picking with a backend (`MeshPickingPlugin`).
#[derive(Debug, Default, Clone, Copy)]
pub struct DragPlugin;

impl Plugin for DragPlugin {
    fn build(&self, app: &mut App) {
        app.register_type::<Draggable>()
            .init_resource::<Dragging>()
            .add_observer(on_press)
            .add_observer(on_drag_start)
            .add_observer(on_drag)
            .add_observer(on_release);
    }
}

/// The world-space ray through `cursor` (logical pixels from the top-left of
/// a `viewport` of that logical size) of a camera at `camera` with a
/// perspective `projection`.
///
/// This is `Camera::viewport_to_world` for a full-window viewport, computed
/// from the projection and window size alone, so it also works where the
/// render world never computed the camera's viewport (headless tests).
pub fn pointer_ray(
    camera: &GlobalTransform,
    projection: &Projection,
    viewport: Vec2,
    cursor: Vec2,
) -> Option<Ray3d> {
    let Projection::Perspective(perspective) = projection else {
        return None;
    };
    if viewport.x <= 0.0 || viewport.y <= 0.0 {
        return None;
    }
    let ndc = Vec2::new(
        2.0 * cursor.x / viewport.x - 1.0,
        1.0 - 2.0 * cursor.y / viewport.y,
    );
    let half = (perspective.fov * 0.5).tan();
    let aspect = viewport.x / viewport.y;
    let local = Vec3::new(ndc.x * half * aspect, ndc.y * half, -1.0);
    let direction = Dir3::new(camera.affine().transform_vector3(local)).ok()?;
    Some(Ray3d::new(camera.translation(), direction))
}

fn on_press(
    press: On<Pointer<Press>>,
    draggable: Query<(), With<Draggable>>,
    mut dragging: ResMut<Dragging>,
) {
    if draggable.contains(press.entity) {
        dragging.entity = Some(press.entity);
        dragging.plane = None;
    }
}

fn on_release(_release: On<Pointer<Release>>, mut dragging: ResMut<Dragging>) {
    if dragging.entity.is_some() {
        *dragging = Dragging::default();
    }
}

fn on_drag_start(
    start: On<Pointer<DragStart>>,
    draggable: Query<&GlobalTransform, With<Draggable>>,
    cameras: Query<&GlobalTransform>,
    mut dragging: ResMut<Dragging>,
) {
    let Ok(target) = draggable.get(start.entity) else {
        return;
    };
    let Ok(camera) = cameras.get(start.hit.camera) else {
        return;
    };
    let center = target.translation();
    let grab = start.hit.position.unwrap_or(center);
    dragging.entity = Some(start.entity);
    // The plane through the grab point, facing the camera.
    dragging.plane = Some((grab, camera.forward().as_vec3()));
    dragging.offset = center - grab;
    dragging.camera_hint = Some(start.hit.camera);
}

fn on_drag(
    drag: On<Pointer<Drag>>,
    dragging: Res<Dragging>,
    cameras: Query<(&GlobalTransform, &Projection)>,
    windows: Query<&Window>,
    mut transforms: Query<&mut Transform, With<Draggable>>,
) {
    if dragging.entity != Some(drag.entity) {
        return;
    }
    let (Some((point, normal)), Some(camera)) = (dragging.plane, dragging.camera_hint) else {
        return;
    };
    let Ok((camera, projection)) = cameras.get(camera) else {
        return;
    };
    let Some(viewport) = viewport_size(&drag.pointer_location, &windows) else {
        return;
    };
    let Some(ray) = pointer_ray(camera, projection, viewport, drag.pointer_location.position)
    else {
        return;
    };
    let Some(distance) = ray.intersect_plane(point, InfinitePlane3d::new(normal)) else {
        return;
    };
    if let Ok(mut transform) = transforms.get_mut(drag.entity) {
        transform.translation = ray.get_point(distance) + dragging.offset;
    }
}

fn viewport_size(location: &Location, windows: &Query<&Window>) -> Option<Vec2> {
    match &location.target {
        NormalizedRenderTarget::Window(window) => {
            let window = windows.get(window.entity()).ok()?;
            Some(Vec2::new(window.width(), window.height()))
        }
        _ => None,
    }
}
