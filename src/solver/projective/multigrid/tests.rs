use super::*;

/// A `side²` grid Laplacian with diagonal neighbours (the lab's
/// triangle grid), stiffness `k`, plus `mass` on the diagonal; its
/// first row pinned away (a Dirichlet row dropped).
pub(super) fn grid(side: usize, k: f64, mass: f64) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    let n = side * side;
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    let mut diag = vec![mass; n];
    for r in 0..side {
        for c in 0..side {
            let i = r * side + c;
            for (dr, dc) in [(0, 1), (1, 0), (1, 1)] {
                let (r2, c2) = (r + dr, c + dc);
                if r2 < side && c2 < side {
                    let j = r2 * side + c2;
                    rows[i].push((j, -k));
                    rows[j].push((i, -k));
                    diag[i] += k;
                    diag[j] += k;
                }
            }
        }
    }
    // Drop the first row of vertices (pinned): their links stay on
    // the diagonal of their neighbours.
    let keep = |i: usize| i >= side;
    let (mut ptr, mut idx, mut val) = (vec![0], Vec::new(), Vec::new());
    for i in (0..n).filter(|&i| keep(i)) {
        let mut row: Vec<(usize, f64)> = rows[i]
            .iter()
            .filter(|(j, _)| keep(*j))
            .map(|&(j, v)| (j - side, v))
            .collect();
        row.push((i - side, diag[i]));
        row.sort_by_key(|e| e.0);
        for (j, v) in row {
            idx.push(j);
            val.push(v);
        }
        ptr.push(idx.len());
    }
    (ptr, idx, val)
}

/// The residual's largest component, in `f64`.
pub(super) fn error(ptr: &[usize], idx: &[usize], val: &[f64], x: &[Vec3A], b: &[Vec3A]) -> f64 {
    let mut worst = 0.0f64;
    for i in 0..x.len() {
        let mut acc = DVec3::ZERO;
        for k in ptr[i]..ptr[i + 1] {
            acc += val[k] * x[idx[k]].as_dvec3();
        }
        worst = worst.max((acc - b[i].as_dvec3()).abs().max_element());
    }
    worst
}

/// `S x = b` by conjugate gradients in `f64`, to a relative residual
/// of 1e-13.
fn reference(ptr: &[usize], idx: &[usize], val: &[f64], b: &[Vec3A]) -> Vec<DVec3> {
    let apply = |x: &[DVec3]| -> Vec<DVec3> {
        (0..x.len())
            .map(|i| (ptr[i]..ptr[i + 1]).map(|k| val[k] * x[idx[k]]).sum())
            .collect()
    };
    let dot = |a: &[DVec3], b: &[DVec3]| a.iter().zip(b).map(|(a, b)| a.dot(*b)).sum::<f64>();
    let mut x = vec![DVec3::ZERO; b.len()];
    let mut r: Vec<DVec3> = b.iter().map(|v| v.as_dvec3()).collect();
    let mut p = r.clone();
    let target = 1e-26 * dot(&r, &r);
    let mut rr = dot(&r, &r);
    while rr > target {
        let ap = apply(&p);
        let alpha = rr / dot(&p, &ap);
        for i in 0..x.len() {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        let next = dot(&r, &r);
        for i in 0..x.len() {
            p[i] = r[i] + next / rr * p[i];
        }
        rr = next;
    }
    x
}

fn relative_error(x: &[Vec3A], exact: &[DVec3]) -> f64 {
    let e: f64 = x
        .iter()
        .zip(exact)
        .map(|(x, e)| (x.as_dvec3() - *e).length_squared())
        .sum();
    let n: f64 = exact.iter().map(|e| e.length_squared()).sum();
    (e / n).sqrt()
}

#[test]
fn v_cycles_converge_at_a_rate_independent_of_stiffness_and_size() {
    for (side, k) in [(41, 1e3), (41, 1e8), (101, 1e6)] {
        let (ptr, idx, val) = grid(side, k, 1.0);
        let mut mg = Multigrid::build(&ptr, &idx, &val, None).unwrap();
        assert!(mg.depth() >= 3, "{side}: {} levels", mg.depth());
        let m = ptr.len() - 1;
        let b: Vec<Vec3A> = (0..m)
            .map(|i| {
                let t = i as f32;
                Vec3A::new(t.sin(), (0.3 * t).cos(), 1.0) * k as f32
            })
            .collect();
        let exact = reference(&ptr, &idx, &val, &b);
        let mut errors = Vec::new();
        let mut x = vec![Vec3A::ZERO; m];
        for cycles in [1, 5, 20] {
            mg.solve(&mut x, &b, cycles);
            errors.push(relative_error(&x, &exact));
        }
        // A factor per cycle well below 1, whatever k and the size.
        assert!(
            errors[0] < 0.5 && errors[1] < 0.05 && errors[2] < 1e-4,
            "{side}, k {k}: {errors:?}"
        );
        let mut again = vec![Vec3A::ZERO; m];
        mg.solve(&mut again, &b, 20);
        assert_eq!(again, x, "the same bits run after run");
    }
}

#[test]
fn a_changed_diagonal_keeps_every_coarse_matrix_galerkin_and_the_cycle_converging() {
    // A penalty sphere's contacts: 1e4 on a disc of rows, then half of
    // them released and others added.
    let (side, k) = (41, 1e4);
    let (ptr, idx, mut val) = grid(side, k, 900.0);
    let m = ptr.len() - 1;
    let mut mg = Multigrid::build(&ptr, &idx, &val, None).unwrap();
    assert!(mg.depth() >= 3, "{} levels", mg.depth());
    // The same with its finest level on the stencil, whose diagonal
    // follows too.
    let mut on_stencil =
        Multigrid::build(&ptr, &idx, &val, Some(grid_stencil(side, k as f32))).unwrap();
    assert!(on_stencil.fine.is_some());
    let diag_at = |i: usize| (ptr[i]..ptr[i + 1]).find(|&p| idx[p] == i).unwrap();
    let base: Vec<f64> = (0..m).map(|i| val[diag_at(i)]).collect();
    let disc = |c: usize, r: usize| {
        (0..m).filter(move |&i| {
            let (x, y) = ((i + 1) % side, (i + 1) / side);
            x.abs_diff(c) * x.abs_diff(c) + y.abs_diff(c) * y.abs_diff(c) <= r * r
        })
    };
    let mut contact = vec![0.0; m];
    for (center, radius) in [(20, 6), (24, 5)] {
        let wanted: Vec<f64> = (0..m)
            .map(|i| {
                if disc(center, radius).any(|j| j == i) {
                    1e4
                } else {
                    0.0
                }
            })
            .collect();
        let changes: Vec<(usize, f64)> = (0..m)
            .filter(|&i| wanted[i] != contact[i])
            .map(|i| (i, base[i] + wanted[i]))
            .collect();
        assert!(!changes.is_empty());
        for &(i, d) in &changes {
            val[diag_at(i)] = d;
        }
        contact = wanted;
        assert_eq!(mg.set_diagonal(&changes), Ok(true));
        assert_eq!(on_stencil.set_diagonal(&changes), Ok(true));
        // Each coarser matrix is `Pᵀ S P` of the one above, to rounding.
        for (at, level) in mg.levels.iter().enumerate() {
            let galerkin = level.pt.mul(&level.a.mul(&level.p));
            let next = mg.levels.get(at + 1).map_or(&mg.coarsest, |l| &l.a);
            let scale = galerkin.val.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            for i in 0..galerkin.rows() {
                let (cols, vals) = galerkin.row(i);
                for (&j, &v) in cols.iter().zip(vals) {
                    let stored = next.position(i, j as usize).map_or(0.0, |p| next.val[p]);
                    assert!(
                        (stored - v).abs() <= 1e-12 * scale,
                        "level {at}: {stored} vs {v}"
                    );
                    if let Some(p) = next.position(i, j as usize) {
                        // The cycles' `f32` copy follows.
                        assert_eq!(
                            next.val32.get(p).copied().unwrap_or(stored as f32),
                            stored as f32
                        );
                    }
                }
            }
        }
        // The cycle still converges on the new matrix, a little slower
        // than a fresh hierarchy's, whose prolongation is smoothed with
        // the contacts (5 cycles: 3.7e-3 against 7.2e-4 here).
        let b: Vec<Vec3A> = (0..m)
            .map(|i| Vec3A::new((i as f32).sin(), 1.0, 0.5) * 1e4)
            .collect();
        let exact = reference(&ptr, &idx, &val, &b);
        let mut fresh = Multigrid::build(&ptr, &idx, &val, None).unwrap();
        let (mut x, mut y) = (vec![Vec3A::ZERO; m], vec![Vec3A::ZERO; m]);
        mg.solve(&mut x, &b, 5);
        fresh.solve(&mut y, &b, 5);
        let (updated, rebuilt) = (relative_error(&x, &exact), relative_error(&y, &exact));
        assert!(
            updated < 1e-2 && updated < 10.0 * rebuilt,
            "{updated} vs {rebuilt}"
        );
        let mut z = vec![Vec3A::ZERO; m];
        on_stencil.solve(&mut z, &b, 5);
        let stencil = relative_error(&z, &exact);
        assert!(
            (stencil - updated).abs() < 0.05 * updated,
            "{stencil} vs {updated}"
        );
    }
}

/// [`grid`]'s matrix as a stencil.
fn grid_stencil(side: usize, k: f32) -> FineStencil {
    let n = side * side;
    let offsets = vec![1, side, side + 1];
    let coeffs = [(0, 1), (1, 0), (1, 1)]
        .iter()
        .map(|&(dr, dc)| {
            (0..n)
                .map(|i| {
                    let (r, c) = (i / side, i % side);
                    // Both ends free (row ≥ 1) and inside the grid.
                    let inside = r + dr < side && c + dc < side && r >= 1;
                    if inside { k } else { 0.0 }
                })
                .collect()
        })
        .collect();
    FineStencil {
        offsets,
        coeffs,
        free: (side as u32..n as u32).collect(),
        n,
    }
}

#[test]
fn the_stencil_finest_level_is_the_matrix_at_every_simd_level() {
    let (side, k) = (61, 1e5);
    let (ptr, idx, val) = grid(side, k, 1.0);
    let m = ptr.len() - 1;
    let b: Vec<Vec3A> = (0..m)
        .map(|i| {
            let t = i as f32;
            Vec3A::new((0.7 * t).sin(), t.cos(), -1.0) * k as f32
        })
        .collect();
    let exact = reference(&ptr, &idx, &val, &b);
    let solve = |fine: Option<FineStencil>, simd: Simd| {
        let mut mg = Multigrid::build(&ptr, &idx, &val, fine).unwrap();
        mg.configure(simd);
        let mut x = vec![Vec3A::ZERO; m];
        mg.solve(&mut x, &b, 8);
        (x, mg.fine.is_some())
    };
    let (general, _) = solve(None, Simd::Auto);
    let (stencil, used) = solve(Some(grid_stencil(side, k as f32)), Simd::Auto);
    assert!(used);
    // The same cycle up to the order of each row's sums.
    let (e_general, e_stencil) = (
        relative_error(&general, &exact),
        relative_error(&stencil, &exact),
    );
    assert!(
        (e_general - e_stencil).abs() < 0.05 * e_general && e_stencil < 1e-2,
        "{e_general} vs {e_stencil}"
    );
    for simd in [Simd::Baseline, Simd::Avx2, Simd::Avx512] {
        let (at, _) = solve(Some(grid_stencil(side, k as f32)), simd);
        assert_eq!(at, stencil, "{simd:?}");
    }
}

#[test]
fn a_small_matrix_is_solved_densely() {
    let (ptr, idx, val) = grid(6, 100.0, 2.0);
    let mut mg = Multigrid::build(&ptr, &idx, &val, None).unwrap();
    assert_eq!(mg.depth(), 1);
    let b = vec![Vec3A::new(1.0, -2.0, 3.0); ptr.len() - 1];
    let mut x = vec![Vec3A::ZERO; b.len()];
    mg.solve(&mut x, &b, 1);
    assert!(error(&ptr, &idx, &val, &x, &b) < 1e-4);
}

#[test]
fn a_stalled_coarsening_is_solved_by_a_sparse_factor_not_a_dense_one() {
    // `M/h²` far above the springs (a heavy sheet in the guard's
    // sixteenth steps): no strong links, so the first aggregation
    // stalls and the finest level is the coarsest.
    for (side, k, mass) in [(41, 8000.0, 1e6), (61, 1.0, 100.0)] {
        let (ptr, idx, val) = grid(side, k, mass);
        let mut mg = Multigrid::build(&ptr, &idx, &val, None).unwrap();
        let m = ptr.len() - 1;
        assert_eq!(mg.depth(), 1, "{side}: stalled at the finest level");
        assert!(m > DENSE_MAX && mg.coarse.sparse.is_some() && mg.coarse.l.is_empty());
        let b: Vec<Vec3A> = (0..m)
            .map(|i| Vec3A::new((i as f32).sin(), 1.0, -2.0) * mass as f32)
            .collect();
        let exact = reference(&ptr, &idx, &val, &b);
        let mut x = vec![Vec3A::ZERO; m];
        mg.solve(&mut x, &b, 1);
        // Exact up to `f32`.
        assert!(relative_error(&x, &exact) < 1e-6, "{side}");
    }
}

#[test]
fn a_matrix_that_is_not_positive_definite_is_an_error() {
    let (ptr, idx, mut val) = grid(6, 100.0, 2.0);
    for v in &mut val {
        *v = -*v;
    }
    assert!(Multigrid::build(&ptr, &idx, &val, None).is_err());
}
