//! Cloths from mesh assets: built when the asset is ready, welded along UV
//! seams for the simulation and written back unwelded.

use bevy::asset::{AssetPlugin, RenderAssetUsages};
use bevy::mesh::{Indices, PrimitiveTopology, VertexAttributeValues};
use bevy::prelude::*;
use bevy_cloth::prelude::*;
use bevy_cloth::render::ClothRenderPlugin;

use crate::common::{app_with, run_steps};
use crate::mesh_order::{grid_mesh_numbered, shuffled};

fn with_meshes(app: &mut App) {
    app.init_asset::<Mesh>();
}

fn mesh_app() -> App {
    app_with((
        AssetPlugin::default(),
        with_meshes,
        ClothPlugins::default(),
        ClothRenderPlugin,
    ))
}

/// An `n×n` grid over [0, n−1]² in the x–z plane whose middle column is
/// split in two along a UV seam (the right half uses copies of its
/// vertices, with other UVs).
fn seamed_grid(n: u32) -> Mesh {
    let mid = n / 2;
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut uvs: Vec<[f32; 2]> = Vec::new();
    for j in 0..n {
        for i in 0..n {
            positions.push([i as f32, 0.0, j as f32]);
            uvs.push([i as f32 / n as f32, 0.0]);
        }
    }
    for j in 0..n {
        positions.push([mid as f32, 0.0, j as f32]);
        uvs.push([0.9, 0.9]);
    }
    let at = |i: u32, j: u32, right: bool| {
        if right && i == mid {
            n * n + j
        } else {
            j * n + i
        }
    };
    let mut indices = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let r = i >= mid;
            indices.extend([at(i, j, r), at(i, j + 1, r), at(i + 1, j + 1, r)]);
            indices.extend([at(i, j, r), at(i + 1, j + 1, r), at(i + 1, j, r)]);
        }
    }
    let normals = vec![[0.0, 1.0, 0.0]; positions.len()];
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs)
    .with_inserted_indices(Indices::U32(indices))
}

fn float3(mesh: &Mesh, attribute: bevy::mesh::MeshVertexAttribute) -> Vec<Vec3> {
    match mesh.attribute(attribute) {
        Some(VertexAttributeValues::Float32x3(v)) => v.iter().map(|&p| Vec3::from(p)).collect(),
        other => panic!("{other:?}"),
    }
}

#[test]
fn a_cloth_waits_for_its_mesh_and_a_uv_seamed_mesh_stays_one_piece() {
    let n = 9;
    let mut app = mesh_app();
    let handle = app
        .world_mut()
        .resource_mut::<Assets<Mesh>>()
        .reserve_handle();
    let entity = app
        .world_mut()
        .spawn((
            ClothFromMesh::new(handle.clone()).with(|_, b| {
                // The edge z = 0 (mesh indices 0..n and its seam copy).
                Ok(b.with_pins((0..9).chain([81])))
            }),
            ImplicitSolver::chebyshev_auto(32),
            Mesh3d(handle.clone()),
        ))
        .id();
    run_steps(&mut app, 3);
    assert!(app.world().get::<Cloth>(entity).is_none(), "no mesh yet");
    app.world_mut()
        .resource_mut::<Assets<Mesh>>()
        .insert(handle.id(), seamed_grid(n))
        .unwrap();
    run_steps(&mut app, 40);
    let cloth = app.world().get::<Cloth>(entity).expect("built once loaded");
    assert!(app.world().get::<ClothFromMesh>(entity).is_none());
    assert_eq!(cloth.model().vertex_count(), (n * n) as usize);
    assert!(app.world().get::<ClothStats>(entity).unwrap().is_running());
    // It hangs from its pinned edge: the far edge fell.
    assert!(cloth.positions().iter().any(|p| p.y < -3.0));
    app.update();
    let meshes = app.world().resource::<Assets<Mesh>>();
    let mesh = meshes.get(&handle).unwrap();
    let x = float3(mesh, Mesh::ATTRIBUTE_POSITION);
    let normals = float3(mesh, Mesh::ATTRIBUTE_NORMAL);
    assert_eq!(x.len(), (n * n + n) as usize, "written back unwelded");
    assert!(x.iter().all(|p| p.is_finite()));
    let mid = (n / 2) as usize;
    for j in 0..n as usize {
        let (a, b) = (j * n as usize + mid, (n * n) as usize + j);
        // One piece: the seam's two copies sit together, with one normal.
        assert_eq!(x[a], x[b], "row {j}");
        assert_eq!(normals[a], normals[b], "row {j}");
    }
    assert!(x.iter().any(|p| p.y < -3.0), "the mesh shows the drape");
}

#[test]
fn a_mesh_that_cannot_be_a_cloth_is_reported_not_a_panic() {
    let mut app = mesh_app();
    let no_indices = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, vec![[0.0f32; 3]; 3]);
    let no_positions = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_indices(Indices::U32(vec![0, 1, 2]));
    let mut meshes = app.world_mut().resource_mut::<Assets<Mesh>>();
    let handles = [
        meshes.add(no_indices),
        meshes.add(no_positions),
        meshes.add(seamed_grid(5)),
    ];
    let entities: Vec<Entity> = handles
        .into_iter()
        .enumerate()
        .map(|(k, h)| {
            let source = ClothFromMesh::new(h).with(move |_, b| {
                // The third is valid but for a pin out of range.
                Ok(if k == 2 { b.with_pins([1000]) } else { b })
            });
            app.world_mut().spawn((source, PbdSolver::default())).id()
        })
        .collect();
    run_steps(&mut app, 3);
    for e in entities {
        assert!(app.world().get::<Cloth>(e).is_none());
        assert!(
            app.world().get::<ClothFromMesh>(e).is_none(),
            "reported once, removed"
        );
    }
}

#[test]
fn a_mesh_in_scattered_order_is_renumbered_and_written_back_in_its_own() {
    // A 12×12 grid mesh whose row-major vertex v is mesh vertex perm[v].
    let n = 12u32;
    let perm = shuffled(n * n);
    let (positions, mesh) = grid_mesh_numbered(n, |v| perm[v as usize]);
    let at = |i: u32, j: u32| perm[(j * n + i) as usize];
    // Pinned along z = 0, given as mesh indices.
    let edge: Vec<u32> = (0..n).map(|i| at(i, 0)).collect();
    let mut app = mesh_app();
    let handle = app.world_mut().resource_mut::<Assets<Mesh>>().add(mesh);
    let pins = edge.clone();
    let entity = app
        .world_mut()
        .spawn((
            ClothFromMesh::new(handle.clone()).with(move |_, b| Ok(b.with_pins(pins.clone()))),
            ImplicitSolver::chebyshev(32, 0.995),
            Mesh3d(handle.clone()),
        ))
        .id();
    run_steps(&mut app, 40);
    app.update();
    let cloth = app.world().get::<Cloth>(entity).expect("built");
    let map = cloth.model().welded_from().expect("renumbered").to_vec();
    let cloth_x = cloth.positions().to_vec();
    let meshes = app.world().resource::<Assets<Mesh>>();
    let x = float3(meshes.get(&handle).unwrap(), Mesh::ATTRIBUTE_POSITION);
    assert_eq!(
        x.len(),
        positions.len(),
        "written back in the mesh's numbering"
    );
    for (m, p) in x.iter().enumerate() {
        assert_eq!(*p, Vec3::from(cloth_x[map[m] as usize]), "mesh vertex {m}");
    }
    // The pinned edge (mesh indices) stayed; the far edge fell.
    for &m in &edge {
        assert_eq!(x[m as usize], Vec3::from(positions[m as usize]), "pin {m}");
    }
    assert!((0..n).all(|i| x[at(i, n - 1) as usize].y < -3.0));
}
