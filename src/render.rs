//! Rendering (cargo feature `render`): cloth meshes that follow the
//! simulation, and mouse dragging of entities through Bevy's picking.
//!
//! - [`ClothRenderPlugin`] writes each cloth's positions and normals into the
//!   [`Mesh`] of its [`Mesh3d`] once per rendered frame (in `PostUpdate`,
//!   after transform propagation), not once per fixed step. Positions are
//!   converted from world space to the entity's local space, so the mesh
//!   renders where the simulation is. Build the mesh with [`cloth_mesh`].
//! - [`DragPlugin`] lets the mouse drag any entity marked [`Draggable`] in the
//!   plane through it that faces the camera (press on it and move). While an
//!   entity is held, [`Dragging`] names it, so a camera controller can stop
//!   orbiting.

use bevy::asset::RenderAssetUsages;
use bevy::camera::NormalizedRenderTarget;
use bevy::camera::visibility::NoFrustumCulling;
use bevy::math::Affine3A;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::picking::events::{Drag, DragStart, Pointer, Press, Release};
use bevy::picking::pointer::Location;
use bevy::prelude::*;
use bevy::render::render_resource::{Extent3d, TextureDimension, TextureFormat};

use crate::ecs::Cloth;
use crate::model::ClothModel;

/// Writes cloth positions and normals into their meshes once per frame.
#[derive(Debug, Default, Clone, Copy)]
pub struct ClothRenderPlugin;

impl Plugin for ClothRenderPlugin {
    fn build(&self, app: &mut App) {
        app.add_systems(
            PostUpdate,
            (no_culling_for_cloths, write_cloth_meshes)
                .chain()
                .after(TransformSystems::Propagate),
        );
    }
}

/// A mesh of the cloth's rest shape: positions, area-weighted normals,
/// planar UVs over the rest shape's two largest extents, and the triangles.
/// Kept in the main world so [`ClothRenderPlugin`] can update it.
pub fn cloth_mesh(model: &ClothModel) -> Mesh {
    let topo = model.topology();
    let positions: Vec<[f32; 3]> = topo.rest_positions().iter().map(|p| p.to_array()).collect();
    let (min, max) = topo
        .rest_positions()
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
            (lo.min(p), hi.max(p))
        });
    let extent = max - min;
    // The two axes with the largest extent span the UVs.
    let mut axes = [0usize, 1, 2];
    axes.sort_by(|&a, &b| extent[b].total_cmp(&extent[a]));
    let uvs: Vec<[f32; 2]> = topo
        .rest_positions()
        .iter()
        .map(|p| {
            let uv = |axis: usize| {
                if extent[axis] > 0.0 {
                    (p[axis] - min[axis]) / extent[axis]
                } else {
                    0.0
                }
            };
            [uv(axes[0]), uv(axes[1])]
        })
        .collect();
    let mut normals = vec![[0.0, 1.0, 0.0]; positions.len()];
    let rest: Vec<Vec3A> = topo.rest_positions().iter().map(|&p| p.into()).collect();
    fill_normals(topo.triangles(), &rest, &Affine3A::IDENTITY, &mut normals);
    let indices = topo.triangles().iter().flatten().copied().collect();
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
    .with_inserted_indices(Indices::U32(indices))
}

/// A checkerboard texture (`cells×cells`, two colours) that makes folds
/// readable on a cloth.
pub fn checker_image(cells: u32, a: Color, b: Color) -> Image {
    let size = cells * 16;
    let (a, b) = (a.to_srgba().to_u8_array(), b.to_srgba().to_u8_array());
    let mut data = Vec::with_capacity((size * size * 4) as usize);
    for y in 0..size {
        for x in 0..size {
            let odd = ((x / 16) + (y / 16)) % 2 == 1;
            data.extend_from_slice(if odd { &a } else { &b });
        }
    }
    Image::new(
        Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: 1,
        },
        TextureDimension::D2,
        data,
        TextureFormat::Rgba8UnormSrgb,
        RenderAssetUsages::default(),
    )
}

/// Area-weighted vertex normals of `positions` mapped by `to_local`.
fn fill_normals(
    triangles: &[[u32; 3]],
    positions: &[Vec3A],
    to_local: &Affine3A,
    out: &mut [[f32; 3]],
) {
    let mut sums = vec![Vec3A::ZERO; out.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| positions[i as usize]);
        let n = (b - a).cross(c - a);
        for &i in t {
            sums[i as usize] += n;
        }
    }
    for (o, n) in out.iter_mut().zip(sums) {
        let n = to_local.transform_vector3a(n).normalize_or(Vec3A::Y);
        *o = n.to_array();
    }
}

/// Rendered cloths not yet exempt from frustum culling.
type UnculledCloth = (With<Cloth>, With<Mesh3d>, Without<NoFrustumCulling>);

/// Meshes deform beyond their initial bounds: do not cull them by it.
fn no_culling_for_cloths(mut commands: Commands, cloths: Query<Entity, UnculledCloth>) {
    for entity in &cloths {
        commands.entity(entity).insert(NoFrustumCulling);
    }
}

fn write_cloth_meshes(
    cloths: Query<(&Cloth, &Mesh3d, &GlobalTransform), Changed<Cloth>>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    for (cloth, mesh3d, global) in &cloths {
        let x = cloth.positions();
        // Never put a NaN into a mesh (the guard restores bad states, but a
        // user may have written one by hand).
        if x.is_empty() || !x.iter().all(|p| p.is_finite()) {
            continue;
        }
        let Some(mut mesh) = meshes.get_mut(&mesh3d.0) else {
            continue;
        };
        let to_local = global.affine().inverse();
        if let Ok(Some(VertexAttributeValues::Float32x3(positions))) =
            mesh.try_attribute_mut_option(Mesh::ATTRIBUTE_POSITION)
        {
            if positions.len() != x.len() {
                continue;
            }
            for (out, p) in positions.iter_mut().zip(x) {
                *out = to_local.transform_point3a(*p).to_array();
            }
        }
        if let Ok(Some(VertexAttributeValues::Float32x3(normals))) =
            mesh.try_attribute_mut_option(Mesh::ATTRIBUTE_NORMAL)
            && normals.len() == x.len()
        {
            fill_normals(cloth.model().topology().triangles(), x, &to_local, normals);
        }
    }
}

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
