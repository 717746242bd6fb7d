//! Vertex order for locality: a mesh whose vertex order scatters its edges
//! is renumbered by `ClothBuilder::from_mesh` (reverse Cuthill–McKee), and
//! everything a user gives or reads in the mesh's numbering maps through
//! `ClothModel::welded_from`.

use bevy::asset::RenderAssetUsages;
use bevy::math::Affine3A;
use bevy::mesh::{Indices, Mesh, PrimitiveTopology};
use bevy_cloth::methods::{AnyMethod, AnyWorkspace};
use bevy_cloth::model::{ClothBuilder, ClothModel, ClothState};
use bevy_cloth::solver::StepParams;
use bevy_cloth::solver::implicit::ImplicitSolver;

/// A `side×side` grid mesh on the XZ plane, its vertices numbered by
/// `number(row-major index)`.
pub fn grid_mesh_numbered(side: u32, number: impl Fn(u32) -> u32) -> (Vec<[f32; 3]>, Mesh) {
    let n = side * side;
    let mut positions = vec![[0.0f32; 3]; n as usize];
    for j in 0..side {
        for i in 0..side {
            positions[number(j * side + i) as usize] = [i as f32, 0.0, j as f32];
        }
    }
    let at = |i: u32, j: u32| number(j * side + i);
    let mut indices = Vec::new();
    for j in 0..side - 1 {
        for i in 0..side - 1 {
            indices.extend([at(i, j), at(i, j + 1), at(i + 1, j + 1)]);
            indices.extend([at(i, j), at(i + 1, j + 1), at(i + 1, j)]);
        }
    }
    let mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions.clone())
    .with_inserted_indices(Indices::U32(indices));
    (positions, mesh)
}

/// A fixed shuffle of `0..n` (new number of each row-major index).
pub fn shuffled(n: u32) -> Vec<u32> {
    let mut perm: Vec<u32> = (0..n).collect();
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    for i in (1..n as usize).rev() {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        perm.swap(i, (seed % (i as u64 + 1)) as usize);
    }
    perm
}

/// Mean `|a − b|` over the springs.
fn mean_span(model: &ClothModel) -> f64 {
    let springs = model.topology().springs();
    springs
        .iter()
        .map(|s| f64::from(s.a.abs_diff(s.b)))
        .sum::<f64>()
        / springs.len() as f64
}

#[test]
fn a_shuffled_mesh_is_renumbered_for_locality_and_maps_back() {
    let side = 24;
    let perm = shuffled(side * side);
    let (positions, mesh) = grid_mesh_numbered(side, |v| perm[v as usize]);
    // Pins and masses in the mesh's numbering: the two far corners, and a
    // mass that grows with x.
    let corners = [perm[0], perm[(side - 1) as usize]];
    let masses: Vec<f32> = positions.iter().map(|p| 1.0 + p[0]).collect();
    let model = ClothBuilder::from_mesh(&mesh)
        .unwrap()
        .with_pins(corners)
        .with_masses(masses.clone())
        .build()
        .unwrap();
    let map = model.welded_from().expect("renumbered");
    assert_eq!(map.len(), positions.len());
    let rest = model.topology().rest_positions();
    for (m, p) in positions.iter().enumerate() {
        let v = map[m] as usize;
        assert_eq!(rest[v].to_array(), *p, "mesh vertex {m}");
        assert_eq!(model.masses()[v], masses[m], "mass of mesh vertex {m}");
    }
    let mut pins = model.pins().to_vec();
    pins.sort_unstable();
    let mut want = corners.map(|c| map[c as usize]).to_vec();
    want.sort_unstable();
    assert_eq!(pins, want);
    // Every spring now joins vertices about a row apart, as a grid built in
    // row order does (the shuffled numbering: about a third of the mesh).
    let ordered = grid_mesh_numbered(side, |v| v).1;
    let ordered = ClothBuilder::from_mesh(&ordered).unwrap().build().unwrap();
    let without = ClothBuilder::from_mesh(&mesh)
        .unwrap()
        .with_welding(false)
        .build()
        .unwrap();
    assert!(without.welded_from().is_none());
    assert!(mean_span(&without) > 100.0, "{}", mean_span(&without));
    assert!(
        mean_span(&model) <= 1.5 * mean_span(&ordered),
        "{} against {}",
        mean_span(&model),
        mean_span(&ordered)
    );
    assert_eq!(
        model.topology().triangles().len(),
        ordered.topology().triangles().len()
    );
}

#[test]
fn a_mesh_in_row_order_keeps_its_numbering() {
    let (_, mesh) = grid_mesh_numbered(24, |v| v);
    let model = ClothBuilder::from_mesh(&mesh).unwrap().build().unwrap();
    assert!(model.welded_from().is_none());
}

#[test]
fn a_renumbered_mesh_moves_as_the_mesh_in_row_order() {
    let side = 16;
    let perm = shuffled(side * side);
    let build = |number: &dyn Fn(u32) -> u32| {
        let (_, mesh) = grid_mesh_numbered(side, number);
        let corners = [number(0), number(side - 1)];
        ClothBuilder::from_mesh(&mesh)
            .unwrap()
            .with_pins(corners)
            .build()
            .unwrap()
    };
    let ordered = build(&|v| v);
    let renumbered = build(&|v| perm[v as usize]);
    let map = renumbered.welded_from().unwrap();
    let method = AnyMethod::Implicit(ImplicitSolver::chebyshev(32, 0.995));
    let run = |model: &ClothModel| {
        let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
        let mut ws = AnyWorkspace::default();
        for _ in 0..10 {
            method
                .step(model, &mut state, &StepParams::LAB, &[], &mut ws)
                .unwrap();
        }
        state.positions
    };
    let (a, b) = (run(&ordered), run(&renumbered));
    let mut worst = 0.0f32;
    for v in 0..(side * side) as usize {
        // Row-major vertex v is mesh vertex perm[v] of the shuffled mesh.
        let there = b[map[perm[v] as usize] as usize];
        worst = worst.max((a[v] - there).length());
    }
    // The same cloth: only the order of additions differs.
    assert!(worst < 1e-4 * ordered.size(), "{worst}");
    assert!(a.iter().map(|p| p.y).sum::<f32>() < -1.0, "the cloth fell");
}
