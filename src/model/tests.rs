use bevy::math::Vec3;
use bevy::math::primitives::Plane3d;
use bevy::mesh::{Mesh, Meshable};

use super::*;

#[test]
fn lab_grid_matches_the_lab() {
    let n = 21;
    let model = ClothBuilder::lab().build().unwrap();
    let topo = model.topology();
    assert_eq!(topo.vertex_count(), 441);
    for j in 0..n {
        for i in 0..n {
            let p = topo.rest_positions()[j * n + i];
            let expected = Vec3::new(
                5.0 - 10.0 * i as f32 / (n - 1) as f32,
                0.0,
                5.0 - 10.0 * j as f32 / (n - 1) as f32,
            );
            assert!((p - expected).length() < 1e-6, "vertex {}", j * n + i);
        }
    }
    // Two triangles per cell, as in the lab.
    assert_eq!(topo.triangles().len(), 2 * 20 * 20);
    assert_eq!(topo.triangles()[0], [0, 1, 22]);
    assert_eq!(topo.triangles()[1], [0, 22, 21]);
    // Unique edges: 20·21 along i, 20·21 along j, 20·20 diagonals.
    assert_eq!(topo.springs().len(), 420 + 420 + 400);
    assert_eq!(topo.spring_counts(), [1240, 0, 0]);
    // Sorted by (a, b) like the lab's edge list, each with a < b.
    for w in topo.springs().windows(2) {
        assert!((w[0].a, w[0].b) < (w[1].a, w[1].b));
    }
    for s in topo.springs() {
        let expected =
            topo.rest_positions()[s.a as usize].distance(topo.rest_positions()[s.b as usize]);
        assert_eq!(s.rest_length, expected);
    }
    assert_eq!(model.pins(), &[0, 20]);
    assert!(model.pinned()[0] && model.pinned()[20] && !model.pinned()[1]);
    assert!(model.masses().iter().all(|&m| m == 1.0));
}

#[test]
fn adjacency_lists_every_spring_from_both_ends() {
    let model = ClothBuilder::lab_grid(5).build().unwrap();
    let topo = model.topology();
    let adj = topo.adjacency();
    // Interior vertices of the lab's triangulation have 6 springs, corners 2 or 3.
    assert_eq!(adj.degree(12), 6);
    assert_eq!(adj.degree(0), 3);
    assert_eq!(adj.degree(4), 2);
    let mut seen = vec![0; topo.springs().len()];
    for i in 0..topo.vertex_count() {
        for inc in adj.of(i) {
            let s = topo.springs()[inc.spring as usize];
            let (me, other) = if inc.sign > 0.0 {
                (s.a, s.b)
            } else {
                (s.b, s.a)
            };
            assert_eq!(me as usize, i);
            assert_eq!(other, inc.other);
            seen[inc.spring as usize] += 1;
        }
    }
    assert!(seen.iter().all(|&c| c == 2));
}

#[test]
fn gathers_by_side_and_padded_list_the_same_springs() {
    // The lab's grid: at most 3 springs per side, so the padded rows exist.
    let model = ClothBuilder::lab_grid(7).build().unwrap();
    let topo = model.topology();
    let adjacency = topo.adjacency();
    let padded = adjacency.padded().expect("the lab grid pads to 4");
    let pad = topo.springs().len() as u32;
    for (i, rows) in padded.iter().enumerate() {
        let (starts, ends) = adjacency.by_side(i);
        assert_eq!(starts.len() + ends.len(), adjacency.degree(i));
        for &e in starts {
            assert_eq!(topo.springs()[e as usize].a as usize, i);
        }
        for &e in ends {
            assert_eq!(topo.springs()[e as usize].b as usize, i);
        }
        for (side, list) in [starts, ends].into_iter().enumerate() {
            let row = rows[side];
            assert_eq!(&row[..list.len()], list);
            assert!(row[list.len()..].iter().all(|&e| e == pad));
        }
    }
    // With shear and bending springs a vertex has up to 6 on a side: the
    // solvers use the unpadded rows.
    let assignment = ClothBuilder::assignment(6, 6).build().unwrap();
    assert!(assignment.topology().adjacency().padded().is_none());
}

#[test]
fn invalid_input_gets_typed_errors() {
    let tri = || vec![Vec3::ZERO, Vec3::X, Vec3::Y];
    assert_eq!(
        ClothBuilder::from_triangles(vec![], vec![]).build(),
        Err(ClothBuildError::NoVertices)
    );
    assert_eq!(
        ClothBuilder::from_triangles(tri(), vec![0, 1, 3]).build(),
        Err(ClothBuildError::IndexOutOfRange {
            index: 3,
            vertex_count: 3
        })
    );
    assert_eq!(
        ClothBuilder::from_triangles(tri(), vec![0, 1]).build(),
        Err(ClothBuildError::IndexCountNotMultipleOf3(2))
    );
    assert_eq!(
        ClothBuilder::from_triangles(tri(), vec![]).build(),
        Err(ClothBuildError::NoTriangles)
    );
    assert_eq!(
        ClothBuilder::from_triangles(tri(), vec![0, 1, 1]).build(),
        Err(ClothBuildError::DegenerateTriangle { triangle: 0 })
    );
    assert_eq!(
        ClothBuilder::from_triangles(vec![Vec3::ZERO, Vec3::NAN, Vec3::Y], vec![0, 1, 2]).build(),
        Err(ClothBuildError::NonFinitePosition { vertex: 1 })
    );
    assert_eq!(
        ClothBuilder::from_triangles(vec![Vec3::ZERO, Vec3::ZERO, Vec3::Y], vec![0, 1, 2]).build(),
        Err(ClothBuildError::ZeroLengthEdge { a: 0, b: 1 })
    );
    for mass in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert!(matches!(
            ClothBuilder::from_triangles(tri(), vec![0, 1, 2])
                .with_mass_per_vertex(mass)
                .build(),
            Err(ClothBuildError::InvalidMass { vertex: 0, .. })
        ));
    }
    assert_eq!(
        ClothBuilder::from_triangles(tri(), vec![0, 1, 2])
            .with_masses(vec![1.0, 2.0])
            .build(),
        Err(ClothBuildError::MassCountMismatch {
            got: 2,
            vertex_count: 3
        })
    );
    assert_eq!(
        ClothBuilder::from_triangles(tri(), vec![0, 1, 2])
            .with_masses(vec![1.0, -2.0, 1.0])
            .build(),
        Err(ClothBuildError::InvalidMass {
            vertex: 1,
            mass: -2.0
        })
    );
    assert_eq!(
        ClothBuilder::from_triangles(tri(), vec![0, 1, 2])
            .with_pins([7])
            .build(),
        Err(ClothBuildError::PinOutOfRange {
            index: 7,
            vertex_count: 3
        })
    );
    assert_eq!(
        ClothBuilder::lab_grid(1).build(),
        Err(ClothBuildError::GridTooSmall { rows: 1, cols: 1 })
    );
}

#[test]
fn total_mass_is_spread_and_duplicate_pins_refused() {
    let model = ClothBuilder::lab_grid(2)
        .with_total_mass(0.1)
        .with_pins([1, 0])
        .build()
        .unwrap();
    assert!(model.masses().iter().all(|&m| (m - 0.025).abs() < 1e-9));
    assert_eq!(model.pins(), &[1, 0]);
    assert_eq!(
        ClothBuilder::lab_grid(2).with_pins([1, 0, 1]).build(),
        Err(ClothBuildError::DuplicatePin { index: 1 })
    );
}

#[test]
fn the_size_is_the_rest_shapes_diagonal() {
    let model = ClothBuilder::lab_grid(21).build().unwrap();
    assert!(
        (model.size() - 200f32.sqrt()).abs() < 1e-4,
        "{}",
        model.size()
    );
}

#[test]
fn bevy_meshes_become_cloths() {
    let mesh: Mesh = Plane3d::default()
        .mesh()
        .size(2.0, 2.0)
        .subdivisions(3)
        .into();
    let model = ClothBuilder::from_mesh(&mesh).unwrap().build().unwrap();
    assert_eq!(model.topology().vertex_count(), 25);
    assert_eq!(model.topology().triangles().len(), 32);
    // 4×5 + 5×4 grid edges + 16 diagonals.
    assert_eq!(model.topology().springs().len(), 56);

    let points = Mesh::new(
        bevy::mesh::PrimitiveTopology::PointList,
        bevy::asset::RenderAssetUsages::default(),
    );
    assert_eq!(
        ClothBuilder::from_mesh(&points),
        Err(ClothBuildError::Mesh(MeshReadError::NotTriangleList))
    );
    let empty = Mesh::new(
        bevy::mesh::PrimitiveTopology::TriangleList,
        bevy::asset::RenderAssetUsages::default(),
    );
    assert_eq!(
        ClothBuilder::from_mesh(&empty),
        Err(ClothBuildError::Mesh(MeshReadError::MissingPositions))
    );
}

#[test]
fn the_assignment_grid_builds_each_spring_kind_only_when_asked() {
    let (rows, cols) = (4, 5);
    let stretch_only = ClothBuilder::spring_grid(
        rows,
        cols,
        Vec3::ZERO,
        Vec3::X,
        Vec3::NEG_Z,
        Vec3::new(1.0, 0.0, -1.0),
    )
    .build()
    .unwrap();
    let x = rows * (cols - 1);
    let y = cols * (rows - 1);
    assert_eq!(stretch_only.topology().spring_counts(), [x + y, 0, 0]);
    let full = ClothBuilder::assignment(rows, cols).build().unwrap();
    let shear = 2 * (rows - 1) * (cols - 1);
    let bend = rows * (cols - 2) + cols * (rows - 2);
    assert_eq!(full.topology().spring_counts(), [x + y, shear, bend]);
    // The assignment's layout: particle i*cols + j, row 0 at z = 0, fixed
    // corners of row 0, total mass spread evenly.
    let p = full.topology().rest_positions();
    assert_eq!(p[0], Vec3::new(-0.25, 0.5, 0.0));
    assert_eq!(p[cols - 1], Vec3::new(0.25, 0.5, 0.0));
    assert_eq!(p[(rows - 1) * cols], Vec3::new(-0.25, 0.5, -0.5));
    assert_eq!(full.pins(), &[0, cols as u32 - 1]);
    assert!((full.masses().iter().sum::<f32>() - 0.1).abs() < 1e-6);
    // Spring order follows the assignment: x springs first.
    let s = full.topology().springs()[0];
    assert_eq!((s.a, s.b, s.kind), (0, 1, SpringKind::Stretch));
    let bend_spring = full
        .topology()
        .springs()
        .iter()
        .find(|s| s.kind == SpringKind::Bend)
        .unwrap();
    assert_eq!((bend_spring.a, bend_spring.b), (0, 2));
}

#[test]
fn triangle_meshes_get_shear_and_bending_from_neighbouring_triangles() {
    let n = 5;
    let plain = ClothBuilder::lab_grid(n).build().unwrap();
    assert_eq!(
        plain.topology().spring_counts(),
        [2 * n * (n - 1) + (n - 1) * (n - 1), 0, 0]
    );
    let model = ClothBuilder::lab_grid(n)
        .with_shear_springs()
        .with_bending_springs()
        .build()
        .unwrap();
    let [stretch, shear, bend] = model.topology().spring_counts();
    assert_eq!(stretch, plain.topology().springs().len());
    // Every cell's diagonal is the longest edge of both its triangles: the
    // other diagonal becomes a shear spring.
    assert_eq!(shear, (n - 1) * (n - 1));
    // Every interior side edge (not a diagonal) gets a bending spring.
    assert_eq!(bend, 2 * (n - 1) * (n - 2));
    let topo = model.topology();
    for s in topo
        .springs()
        .iter()
        .filter(|s| s.kind == SpringKind::Shear)
    {
        let d = topo.rest_positions()[s.a as usize] - topo.rest_positions()[s.b as usize];
        assert!(
            (d.length() - 2.5 * 2f32.sqrt()).abs() < 1e-5,
            "shear is a cell diagonal"
        );
    }
    // Only the kind asked for.
    let only_bend = ClothBuilder::lab_grid(n)
        .with_bending_springs()
        .build()
        .unwrap();
    assert_eq!(only_bend.topology().spring_counts(), [stretch, 0, bend]);
}

#[test]
fn pins_are_replaced_at_run_time_and_selected_by_place() {
    let mut model = ClothBuilder::lab().build().unwrap();
    // The lab grid's edge at x = 5 is vertices 0, 21, 42, …
    let edge = model.vertices_where(|p| p.x > 4.99);
    assert_eq!(edge, (0..21).map(|j| 21 * j).collect::<Vec<u32>>());
    model.set_pins(edge.clone()).unwrap();
    assert_eq!(model.pins(), edge.as_slice());
    assert!(model.pinned()[21] && !model.pinned()[20]);
    // Bad pins are refused and leave the pins as they were.
    assert_eq!(
        model.set_pins(vec![3, 3]),
        Err(ClothBuildError::DuplicatePin { index: 3 })
    );
    assert!(matches!(
        model.set_pins(vec![441]),
        Err(ClothBuildError::PinOutOfRange { index: 441, .. })
    ));
    assert_eq!(model.pins(), edge.as_slice());
    model.set_pins(Vec::new()).unwrap();
    assert!(model.pinned().iter().all(|p| !p));
}

/// A 5×5 grid mesh over [0, 4]² in the x–z plane whose column x = 2 is
/// split in two (a UV seam: the right half's triangles use copies 25–29 of
/// vertices 2, 7, 12, 17, 22), with a colour attribute red on row z = 0.
fn seamed_mesh() -> Mesh {
    use bevy::asset::RenderAssetUsages;
    use bevy::mesh::{Indices, PrimitiveTopology};
    let mut positions: Vec<[f32; 3]> = Vec::new();
    for j in 0..5 {
        for i in 0..5 {
            positions.push([i as f32, 0.0, j as f32]);
        }
    }
    for j in 0..5 {
        positions.push([2.0, 0.0, j as f32]);
    }
    let colors: Vec<[f32; 4]> = positions
        .iter()
        .map(|p| {
            if p[2] == 0.0 {
                [1.0, 0.0, 0.0, 1.0]
            } else {
                [0.0, 0.0, 1.0, 1.0]
            }
        })
        .collect();
    let at = |i: u32, j: u32| if i == 2 { 25 + j } else { j * 5 + i };
    let left = |i: u32, j: u32| j * 5 + i;
    let mut indices = Vec::new();
    for j in 0..4 {
        for i in 0..4 {
            let v = if i < 2 { left } else { at };
            indices.extend([v(i, j), v(i, j + 1), v(i + 1, j + 1)]);
            indices.extend([v(i, j), v(i + 1, j + 1), v(i + 1, j)]);
        }
    }
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
    .with_inserted_attribute(Mesh::ATTRIBUTE_COLOR, colors)
    .with_inserted_indices(Indices::U32(indices))
}

#[test]
fn a_mesh_split_along_a_uv_seam_is_welded_into_one_cloth() {
    let mesh = seamed_mesh();
    let model = ClothBuilder::from_mesh(&mesh)
        .unwrap()
        .with_pins([2, 25, 0])
        .build()
        .unwrap();
    assert_eq!(model.vertex_count(), 25);
    assert_eq!(model.topology().triangles().len(), 32);
    let map = model.welded_from().unwrap();
    assert_eq!(map.len(), 30);
    for j in 0..5 {
        assert_eq!(map[25 + j], map[5 * j + 2], "seam copy {j} welded");
    }
    // Pins are mesh indices: 2 and its copy 25 are one cloth vertex.
    assert_eq!(model.pins(), &[0, 2]);
    // The same in cloth indices, for `Attachment` and the state.
    let pins = model.cloth_vertices([2, 25, 0, 99]);
    assert_eq!(
        pins,
        [map[2], map[0]],
        "welded copies once, past the mesh skipped"
    );
    let mut sorted = pins.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, model.pins());
    // Every vertex is joined to the rest: each column-2 vertex has springs
    // to both sides.
    let topo = model.topology();
    for j in 0..5u32 {
        let v = map[(5 * j + 2) as usize];
        let mut sides = topo.springs().iter().filter_map(|s| {
            let other = if s.a == v {
                s.b
            } else if s.b == v {
                s.a
            } else {
                return None;
            };
            Some(topo.rest_positions()[other as usize].x)
        });
        assert!(
            sides.clone().any(|x| x < 2.0) && sides.any(|x| x > 2.0),
            "row {j}"
        );
    }
    // Without welding, the copies stay apart.
    let split = ClothBuilder::from_mesh(&mesh)
        .unwrap()
        .with_welding(false)
        .build()
        .unwrap();
    assert_eq!(split.vertex_count(), 30);
    assert!(split.welded_from().is_none());
    assert_eq!(split.cloth_vertices([3, 3, 29, 30]), [3, 29]);
}

#[test]
fn pins_are_picked_by_a_painted_attribute() {
    let mesh = seamed_mesh();
    let red = mesh_vertices_where(&mesh, Mesh::ATTRIBUTE_COLOR, |c| c[0] > 0.5).unwrap();
    assert_eq!(red, vec![0, 1, 2, 3, 4, 25]);
    let model = ClothBuilder::from_mesh(&mesh)
        .unwrap()
        .with_pins(red)
        .build()
        .unwrap();
    assert_eq!(model.pins(), &[0, 1, 2, 3, 4]);
    assert_eq!(
        mesh_vertices_where(&mesh, Mesh::ATTRIBUTE_UV_0, |_| true),
        Err(MeshReadError::MissingAttribute("Vertex_Uv"))
    );
}

/// A `side`-metre square grid of `n×n` vertices in the `y = 0` plane.
fn square(n: usize, side: f32) -> ClothBuilder {
    ClothBuilder::grid(
        n,
        n,
        Vec3::ZERO,
        Vec3::new(side, 0.0, 0.0),
        Vec3::new(0.0, 0.0, side),
    )
}

#[test]
fn a_material_weighs_and_stretches_the_same_at_every_resolution() {
    let material = ClothMaterial::COTTON;
    for n in [16, 32, 64] {
        let model = square(n, 2.0).with_material(material).build().unwrap();
        // Masses: 4 m² of 0.25 kg/m², an edge vertex half an inner one.
        let masses = model.masses();
        let total: f32 = masses.iter().sum();
        assert!((total - 1.0).abs() < 1e-4, "{n}: {total}");
        let inner = masses[n + 1];
        assert!((masses[1] / inner - 0.5).abs() < 1e-4, "{n}");
        // Stiffness: a uniform strain ε along x stores ½·E·ε² per m² (the
        // grid's modulus along x is within a few per cent of the mean).
        let k = material.spring_stiffness(&model);
        let eps = 1e-3f32;
        let rest = model.topology().rest_positions();
        let energy: f64 = model
            .topology()
            .springs()
            .iter()
            .map(|s| {
                let [a, b] = [s.a, s.b].map(|i| rest[i as usize] * Vec3::new(1.0 + eps, 1.0, 1.0));
                let dl = f64::from(a.distance(b) - s.rest_length);
                0.5 * f64::from(k.of(s.kind)) * dl * dl
            })
            .sum();
        let modulus = energy / 4.0 / (0.5 * f64::from(eps) * f64::from(eps));
        let ratio = modulus / f64::from(material.stretch);
        assert!((0.97..1.03).contains(&ratio), "{n}: {ratio}");
    }
    // The lab's k = 8000 is a sheet of about 12 kN/m (within the border's
    // share at 21²).
    let lab = ClothBuilder::lab().build().unwrap();
    let k = material.spring_stiffness(&lab).stretch;
    assert!((k / 8000.0 - 1.0).abs() < 0.03, "{k}");
}

#[test]
fn bad_densities_and_masses_are_typed_errors() {
    assert!(matches!(
        square(4, 1.0).with_areal_density(f32::NAN).build(),
        Err(ClothBuildError::InvalidDensity(d)) if d.is_nan()
    ));
    assert!(matches!(
        square(4, 1.0).with_areal_density(-1.0).build(),
        Err(ClothBuildError::InvalidDensity(d)) if d == -1.0
    ));
    // A vertex in no triangle gets no mass from a density.
    let mut positions = vec![Vec3::ZERO, Vec3::X, Vec3::Z];
    positions.push(Vec3::ONE);
    assert!(matches!(
        ClothBuilder::from_triangles(positions, vec![0, 1, 2])
            .with_areal_density(1.0)
            .build(),
        Err(ClothBuildError::InvalidMass { vertex: 3, .. })
    ));
    let mut model = square(4, 1.0).build().unwrap();
    let before = model.masses().to_vec();
    assert!(matches!(
        model.set_masses(vec![1.0; 3]),
        Err(ClothBuildError::MassCountMismatch {
            got: 3,
            vertex_count: 16
        })
    ));
    assert!(matches!(
        model.set_masses(vec![0.0; 16]),
        Err(ClothBuildError::InvalidMass { vertex: 0, .. })
    ));
    assert_eq!(model.masses(), before);
    assert!(ClothMaterial::COTTON.with_density(0.0).validate().is_err());
    assert!(
        ClothMaterial::COTTON
            .with_stretch(f32::INFINITY)
            .validate()
            .is_err()
    );
    assert!(ClothMaterial::COTTON.validate().is_ok());
}
