//! Mesh write-back (cargo feature `render`, on by default): cloth meshes
//! that follow the simulation.
//!
//! [`ClothRenderPlugin`] writes each cloth's positions and normals into the
//! [`Mesh`] of its [`Mesh3d`] once per rendered frame (in `PostUpdate`,
//! after transform propagation), not once per fixed step. Positions are
//! converted from world space to the entity's local space, so the mesh
//! renders where the simulation is. Build the mesh with [`cloth_mesh`].
//!
//! This needs only Bevy's mesh and camera crates, not its renderer: a game
//! brings its own rendering features.

use bevy::asset::RenderAssetUsages;
use bevy::camera::visibility::NoFrustumCulling;
use bevy::math::Affine3A;
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;

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
                .after(TransformSystems::Propagate)
                .after(crate::ecs::ClothFollowSystems),
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
        // A welded mesh: each mesh vertex shows its cloth vertex.
        let map = cloth.model().welded_from();
        let mesh_len = map.map_or(x.len(), <[u32]>::len);
        let source = |k: usize| map.map_or(k, |m| m[k] as usize);
        if let Ok(Some(VertexAttributeValues::Float32x3(positions))) =
            mesh.try_attribute_mut_option(Mesh::ATTRIBUTE_POSITION)
        {
            if positions.len() != mesh_len {
                continue;
            }
            for (k, out) in positions.iter_mut().enumerate() {
                *out = to_local.transform_point3a(x[source(k)]).to_array();
            }
        }
        if let Ok(Some(VertexAttributeValues::Float32x3(normals))) =
            mesh.try_attribute_mut_option(Mesh::ATTRIBUTE_NORMAL)
            && normals.len() == mesh_len
        {
            let triangles = cloth.model().topology().triangles();
            match map {
                None => fill_normals(triangles, x, &to_local, normals),
                Some(map) => {
                    // Normals of the welded cloth, so smooth across seams.
                    let mut welded = vec![[0.0; 3]; x.len()];
                    fill_normals(triangles, x, &to_local, &mut welded);
                    for (out, &m) in normals.iter_mut().zip(map) {
                        *out = welded[m as usize];
                    }
                }
            }
        }
    }
}
