//! The assembled system `A v⁺ = b`: a sparsity pattern built once per
//! cloth and values refilled in place each step.

use bevy::math::{DMat3, DVec3, Vec3A};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};

use super::{LinearImplicitSolver, PenaltyJacobian, SpringJacobian};
use crate::collision::PenaltySphere;
use crate::model::ClothModel;
use crate::solver::StepParams;

const FIXED: u32 = u32::MAX;

/// Where a 3×3 block lives in the CSC values: entry `(r, c)` at
/// `base + c·stride + r`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Slot {
    base: u32,
    stride: u32,
}

const NO_SLOT: Slot = Slot {
    base: u32::MAX,
    stride: 0,
};

/// The assembled system `A v⁺ = b` of one step: a fixed sparsity pattern and
/// values refilled in place.
#[derive(Clone, Debug, Default)]
pub struct LinearSystem {
    pub(super) key: (usize, Vec<u32>),
    dof_of: Vec<u32>,
    dofs: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    diag: Vec<Slot>,
    /// Per spring: blocks (a,a), (b,b), (a,b), (b,a).
    springs: Vec<[Slot; 4]>,
    /// The block rows of each block column (sorted) and where each
    /// column's start in them: for [`add_block_at`](Self::add_block_at).
    blk_ptr: Vec<usize>,
    blk_rows: Vec<u32>,
    /// The vertex pairs coupled beyond the springs (each `(i, j)` with
    /// `i < j`, sorted): see [`with_couplings`](Self::with_couplings).
    couplings: Vec<(u32, u32)>,
    values: Vec<f64>,
    rhs: Vec<f64>,
}

/// Where block `(r, c)` of unknowns' blocks lives, given each block
/// column's sorted block rows (`None`: not in the pattern).
fn slot_of(blk_ptr: &[usize], blk_rows: &[u32], r: u32, c: u32) -> Option<Slot> {
    let c = c as usize;
    let rows = &blk_rows[blk_ptr[c]..blk_ptr[c + 1]];
    let k = rows.binary_search(&r).ok()?;
    Some(Slot {
        base: (9 * blk_ptr[c] + 3 * k) as u32,
        stride: (3 * rows.len()) as u32,
    })
}

/// Puts vertex pairs in the form [`LinearSystem::with_couplings`] keeps:
/// each `(i, j)` as `i < j`, sorted, without repeats or a vertex paired with
/// itself.
pub(crate) fn normalise(couplings: &mut Vec<(u32, u32)>) {
    for c in couplings.iter_mut() {
        *c = (c.0.min(c.1), c.0.max(c.1));
    }
    couplings.retain(|&(i, j)| i != j);
    couplings.sort_unstable();
    couplings.dedup();
}

pub(super) fn pattern_key(model: &ClothModel) -> (usize, Vec<u32>) {
    (
        std::sync::Arc::as_ptr(model.topology_arc()) as usize,
        model.pins().to_vec(),
    )
}

impl LinearSystem {
    /// Builds the sparsity pattern of `model`'s system (allocates).
    pub fn new(model: &ClothModel) -> Self {
        Self::with_couplings(model, Vec::new())
    }

    /// Builds the sparsity pattern of `model`'s system with blocks between
    /// the vertex pairs `couplings` beyond its springs' (allocates): the
    /// terms of a step's self-collision pairs couple vertices no spring
    /// joins. `couplings` is sorted and its repeats dropped; a pair with a
    /// pinned end adds nothing.
    pub(crate) fn with_couplings(model: &ClothModel, mut couplings: Vec<(u32, u32)>) -> Self {
        normalise(&mut couplings);
        let topo = model.topology();
        let n = topo.vertex_count();
        let mut dof_of = vec![FIXED; n];
        let mut dofs = 0u32;
        for (i, d) in dof_of.iter_mut().enumerate() {
            if !model.pinned()[i] {
                *d = dofs;
                dofs += 1;
            }
        }
        let dofs = dofs as usize;
        // Each vertex's partners beyond its springs, as (vertex, partner)
        // sorted by vertex.
        let mut beyond: Vec<(u32, u32)> = couplings
            .iter()
            .flat_map(|&(i, j)| [(i, j), (j, i)])
            .filter(|&(i, j)| (i as usize) < n && (j as usize) < n)
            .collect();
        beyond.sort_unstable();
        let mut beyond = beyond.as_slice();
        // Block rows of each block column, sorted.
        let mut blk_ptr = vec![0usize; dofs + 1];
        let mut blk_rows: Vec<u32> = Vec::new();
        let mut c = 0;
        for i in 0..n {
            let di = dof_of[i];
            if di == FIXED {
                continue;
            }
            let start = blk_rows.len();
            blk_rows.push(di);
            for inc in topo.adjacency().of(i) {
                let dj = dof_of[inc.other as usize];
                if dj != FIXED {
                    blk_rows.push(dj);
                }
            }
            let own = beyond.partition_point(|&(v, _)| v as usize <= i);
            let (mine, rest) = beyond.split_at(own);
            beyond = rest;
            for &(_, j) in mine.iter().filter(|&&(v, _)| v as usize == i) {
                let dj = dof_of[j as usize];
                if dj != FIXED {
                    blk_rows.push(dj);
                }
            }
            blk_rows[start..].sort_unstable();
            let mut w = start;
            for r in start..blk_rows.len() {
                if r == start || blk_rows[r] != blk_rows[w - 1] {
                    blk_rows[w] = blk_rows[r];
                    w += 1;
                }
            }
            blk_rows.truncate(w);
            c += 1;
            blk_ptr[c] = blk_rows.len();
        }
        let mut col_ptr = Vec::with_capacity(3 * dofs + 1);
        let mut row_idx = Vec::with_capacity(9 * blk_rows.len());
        for c in 0..dofs {
            let rows = &blk_rows[blk_ptr[c]..blk_ptr[c + 1]];
            for _ in 0..3 {
                col_ptr.push(row_idx.len());
                for &r in rows {
                    let r = 3 * r as usize;
                    row_idx.extend([r, r + 1, r + 2]);
                }
            }
        }
        col_ptr.push(row_idx.len());
        let slot = |r: u32, c: u32| slot_of(&blk_ptr, &blk_rows, r, c).expect("block in pattern");
        let diag = (0..dofs as u32).map(|c| slot(c, c)).collect();
        let springs = topo
            .springs()
            .iter()
            .map(|s| {
                let (da, db) = (dof_of[s.a as usize], dof_of[s.b as usize]);
                let free_a = da != FIXED;
                let free_b = db != FIXED;
                [
                    if free_a { slot(da, da) } else { NO_SLOT },
                    if free_b { slot(db, db) } else { NO_SLOT },
                    if free_a && free_b {
                        slot(da, db)
                    } else {
                        NO_SLOT
                    },
                    if free_a && free_b {
                        slot(db, da)
                    } else {
                        NO_SLOT
                    },
                ]
            })
            .collect();
        let nnz = row_idx.len();
        Self {
            key: pattern_key(model),
            dof_of,
            dofs,
            col_ptr,
            row_idx,
            diag,
            springs,
            values: vec![0.0; nnz],
            rhs: vec![0.0; 3 * dofs],
            blk_ptr,
            blk_rows,
            couplings,
        }
    }

    /// True if this system's pattern is `model`'s and holds the blocks of
    /// every pair of `couplings` (sorted, without repeats: see
    /// [`normalise`]); it may hold more.
    pub(crate) fn covers(&self, model: &ClothModel, couplings: &[(u32, u32)]) -> bool {
        self.matches(model)
            && couplings
                .iter()
                .all(|c| self.couplings.binary_search(c).is_ok())
    }

    /// Adds `block` to `A`'s block `(i, j)` of vertices `i` and `j` (the
    /// diagonal block for `i == j`; nothing for a pinned vertex). The block
    /// must be in the pattern: a spring's, or one of the
    /// [couplings](Self::with_couplings).
    pub(crate) fn add_block_at(&mut self, i: usize, j: usize, block: &DMat3) {
        let (di, dj) = (self.dof_of[i], self.dof_of[j]);
        if di == FIXED || dj == FIXED {
            return;
        }
        let Some(slot) = slot_of(&self.blk_ptr, &self.blk_rows, di, dj) else {
            debug_assert!(false, "block ({i}, {j}) is not in the pattern");
            return;
        };
        self.add_block(slot, block, 1.0);
    }

    /// Writes `A`'s diagonal into `out` (one entry per unknown).
    pub fn diagonal(&self, out: &mut [f64]) {
        for (c, d) in out.iter_mut().enumerate() {
            *d = (self.col_ptr[c]..self.col_ptr[c + 1])
                .find(|&k| self.row_idx[k] == c)
                .map_or(0.0, |k| self.values[k]);
        }
    }

    /// Number of unknowns (3 per free particle).
    pub fn dimension(&self) -> usize {
        3 * self.dofs
    }

    /// Stored nonzeros of `A` (both triangles).
    pub fn nonzeros(&self) -> usize {
        self.values.len()
    }

    /// The right-hand side `b`.
    pub fn rhs(&self) -> &[f64] {
        &self.rhs
    }

    /// The first unknown of vertex `i`, or `None` for a fixed particle.
    pub fn dof(&self, i: usize) -> Option<usize> {
        (self.dof_of[i] != FIXED).then(|| 3 * self.dof_of[i] as usize)
    }

    /// Adds `block` to vertex `i`'s diagonal block of `A` (nothing for a
    /// fixed particle).
    pub(crate) fn add_to_diagonal(&mut self, i: usize, block: &DMat3) {
        let d = self.dof_of[i];
        if d != FIXED {
            let slot = self.diag[d as usize];
            self.add_block(slot, block, 1.0);
        }
    }

    /// `A` as a sparse matrix view.
    pub fn matrix(&self) -> SparseColMatRef<'_, usize, f64> {
        let n = self.dimension();
        SparseColMatRef::new(
            SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx),
            &self.values,
        )
    }

    /// `A` as a dense row-major matrix (for tests and small systems).
    pub fn to_dense(&self) -> Vec<f64> {
        let n = self.dimension();
        let mut dense = vec![0.0; n * n];
        for c in 0..n {
            for k in self.col_ptr[c]..self.col_ptr[c + 1] {
                dense[self.row_idx[k] * n + c] += self.values[k];
            }
        }
        dense
    }

    /// `out = A·v`.
    pub fn multiply(&self, v: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for (c, &vc) in v.iter().enumerate() {
            for k in self.col_ptr[c]..self.col_ptr[c + 1] {
                out[self.row_idx[k]] += self.values[k] * vc;
            }
        }
    }

    #[inline]
    fn add_block(&mut self, slot: Slot, m: &DMat3, sign: f64) {
        if slot.stride == 0 {
            return;
        }
        for (c, col) in [m.x_axis, m.y_axis, m.z_axis].into_iter().enumerate() {
            let at = (slot.base + c as u32 * slot.stride) as usize;
            self.values[at] += sign * col.x;
            self.values[at + 1] += sign * col.y;
            self.values[at + 2] += sign * col.z;
        }
    }

    #[inline]
    fn add_rhs(&mut self, vertex: usize, f: DVec3) {
        let d = self.dof_of[vertex];
        if d != FIXED {
            let at = 3 * d as usize;
            self.rhs[at] += f.x;
            self.rhs[at + 1] += f.y;
            self.rhs[at + 2] += f.z;
        }
    }

    /// True if this system's pattern is `model`'s.
    pub(crate) fn matches(&self, model: &ClothModel) -> bool {
        self.key == pattern_key(model)
    }

    /// [`assemble`](Self::assemble) at `f64` positions.
    pub(crate) fn assemble_at(
        &mut self,
        model: &ClothModel,
        positions: &[DVec3],
        velocities: &[Vec3A],
        params: &StepParams,
        config: &LinearImplicitSolver,
        spheres: &[PenaltySphere],
    ) {
        self.assemble_impl(model, |i| positions[i], velocities, params, config, spheres);
    }

    /// Fills `A = M − h²K` and `b = Mv + hf` at `positions` and
    /// `velocities` (no allocation). Velocities are used as given: damp them
    /// first.
    pub fn assemble(
        &mut self,
        model: &ClothModel,
        positions: &[Vec3A],
        velocities: &[Vec3A],
        params: &StepParams,
        config: &LinearImplicitSolver,
        spheres: &[PenaltySphere],
    ) {
        self.assemble_impl(
            model,
            |i| positions[i].as_dvec3(),
            velocities,
            params,
            config,
            spheres,
        );
    }

    fn assemble_impl(
        &mut self,
        model: &ClothModel,
        position: impl Fn(usize) -> DVec3,
        velocities: &[Vec3A],
        params: &StepParams,
        config: &LinearImplicitSolver,
        spheres: &[PenaltySphere],
    ) {
        debug_assert_eq!(self.key, pattern_key(model));
        let h = params.dt;
        let h2 = h * h;
        let gravity = params.gravity.as_dvec3();
        self.values.fill(0.0);
        self.rhs.fill(0.0);
        for (i, &m) in model.masses().iter().enumerate() {
            let d = self.dof_of[i];
            if d == FIXED {
                continue;
            }
            let m = f64::from(m);
            let slot = self.diag[d as usize];
            self.add_block(slot, &(DMat3::IDENTITY * m), 1.0);
            let v = velocities[i].as_dvec3();
            self.add_rhs(i, m * v + h * m * gravity);
            let x = position(i);
            for sphere in spheres {
                if let Some(contact) = sphere.contact_f64(x) {
                    let c = f64::from(sphere.stiffness);
                    let n = contact.normal;
                    let nn = DMat3::from_cols(n * n.x, n * n.y, n * n.z);
                    let lhs = match config.penalty {
                        PenaltyJacobian::Normal => nn * c,
                        PenaltyJacobian::Isotropic => DMat3::IDENTITY * (c * contact.depth),
                        PenaltyJacobian::Exact => {
                            let tangential = if contact.distance > 0.0 {
                                contact.depth / contact.distance
                            } else {
                                0.0
                            };
                            nn * c - (DMat3::IDENTITY - nn) * (c * tangential)
                        }
                    };
                    self.add_block(slot, &(lhs * h2), 1.0);
                    self.add_rhs(i, h * contact.force);
                }
            }
        }
        let stiffness = params.stiffness;
        for (e, s) in model.topology().springs().iter().enumerate() {
            let x0 = position(s.a as usize);
            let x1 = position(s.b as usize);
            let dx = x1 - x0;
            let l = dx.length();
            if l == 0.0 {
                continue;
            }
            let big_e = f64::from(stiffness.of(s.kind));
            let rest = f64::from(s.rest_length);
            let strain = (l - rest) / l;
            let fs = dx * (big_e * strain);
            self.add_rhs(s.a as usize, h * fs);
            self.add_rhs(s.b as usize, -h * fs);
            let across = match config.springs {
                SpringJacobian::Exact => strain,
                SpringJacobian::ClampCompression => strain.max(0.0),
            };
            let outer = DMat3::from_cols(dx * dx.x, dx * dx.y, dx * dx.z);
            let ks =
                (outer * (1.0 - strain) + DMat3::IDENTITY * (across * l * l)) * (big_e / (l * l));
            let h2ks = ks * h2;
            let [aa, bb, ab, ba] = self.springs[e];
            self.add_block(aa, &h2ks, 1.0);
            self.add_block(bb, &h2ks, 1.0);
            self.add_block(ab, &h2ks, -1.0);
            self.add_block(ba, &h2ks, -1.0);
        }
    }
}
