//! Linearly implicit Euler with sparse matrices — the assignment.
//!
//! One step solves for the new velocities `v⁺`
//!
//! `A v⁺ = b`, `A = M − h²K`, `b = M v + h f`,
//!
//! then `x ← x + h v⁺`, where `M` is the diagonal mass matrix, `f` the spring,
//! gravity and penalty forces at the current positions and `K = ∂f/∂x`.
//! Fixed (pinned) particles carry no degrees of freedom: only free particles
//! get rows and columns. For a spring between particles 0 and 1 with
//! `Δx = x₁ − x₀`, `l = ‖Δx‖`, rest length `L`, stiffness `E`:
//!
//! - force on particle 0: `f_s = E (l − L) Δx/l` (particle 1 gets `−f_s`);
//! - `K_s = E/l² ((1 − (l−L)/l) ΔxΔxᵀ + ((l−L)/l) (ΔxᵀΔx) I)` and the
//!   spring's `K = [[−K_s, K_s], [K_s, −K_s]]`, so `A` gains `h²K_s` on both
//!   diagonal blocks and `−h²K_s` on both off-diagonal blocks (the latter
//!   only when both particles are free).
//!
//! `K_s` has eigenvalue `E` along `Δx` and `E (l − L)/l` across it, which is
//! negative for a compressed spring: `A` can then lose positive
//! definiteness. [`SpringJacobian::ClampCompression`] drops that term for
//! compressed springs (the standard remedy), keeping every block positive
//! semi-definite.
//!
//! The sparsity pattern (CSC, full symmetric, 3×3 blocks) is built once per
//! cloth and rebuilt only when the topology or the pins change; each step
//! refills the values in place. The system is solved by conjugate gradients
//! (`faer::matrix_free::conjugate_gradient`, warm-started with the previous
//! velocities) or by a sparse LDLᵀ factorisation (`faer`, AMD ordering,
//! symbolic analysis done once per pattern).

use bevy::math::{DMat3, DVec3, Vec3A};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::matrix_free::conjugate_gradient::{
    CgError, CgParams, conjugate_gradient, conjugate_gradient_scratch,
};
use faer::matrix_free::{IdentityPrecond, InitialGuessStatus};
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, MatRef, Par, Side};

use super::{SolveError, StepError, StepParams, StepReport, check_state};
use crate::collision::PenaltySphere;
use crate::model::{ClothModel, ClothState, ParamError};

/// Preconditioner of the conjugate gradient solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Preconditioner {
    /// None (the assignment's Eigen default is a diagonal one; the spec
    /// does not say, so both are offered).
    #[default]
    None,
    /// Jacobi: the inverse of `A`'s diagonal.
    Jacobi,
}

/// Conjugate gradient settings (defaults: the assignment's).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CgConfig {
    /// Iteration cap (25).
    pub max_iterations: u32,
    /// Relative residual `‖b − Av‖/‖b‖` at which to stop (1e-6).
    pub tolerance: f64,
    /// Preconditioner.
    pub preconditioner: Preconditioner,
}

impl Default for CgConfig {
    fn default() -> Self {
        Self {
            max_iterations: 25,
            tolerance: 1e-6,
            preconditioner: Preconditioner::None,
        }
    }
}

/// How the linear system is solved.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LinearSolver {
    /// Conjugate gradients, warm-started with the previous velocities.
    Cg(CgConfig),
    /// Sparse LDLᵀ factorisation (exact up to round-off).
    Direct,
}

impl Default for LinearSolver {
    fn default() -> Self {
        Self::Cg(CgConfig::default())
    }
}

/// Which spring stiffness blocks enter `A`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SpringJacobian {
    /// The assignment's `K_s` exactly (may make `A` indefinite when springs
    /// compress).
    #[default]
    Exact,
    /// `K_s` with the `(l − L)/l` term clamped at zero for compressed
    /// springs, so `A` stays positive definite.
    ClampCompression,
}

/// Which stiffness a penalty contact adds to `A`.
///
/// The true Jacobian of `f_c = c·d·n` is
/// `∂f_c/∂x = −c nnᵀ + c(d/l)(I − nnᵀ)`. With `A = M − h²K` its normal part
/// adds `h²c nnᵀ` to `A` (positive semi-definite, good) and its tangential
/// part subtracts `h²c(d/l)(I − nnᵀ)` (can make `A` indefinite). The
/// assignment writes `K_c = c·d·I`; read literally into `A = M − h²K` that
/// subtracts `h²c·d·I` and also loses definiteness, so the sign that keeps
/// `A` symmetric positive definite is the one offered as
/// [`Isotropic`](Self::Isotropic).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PenaltyJacobian {
    /// `A += h²c nnᵀ`: the positive semi-definite (normal) part of the true
    /// Jacobian. Keeps `A` SPD.
    #[default]
    Normal,
    /// `A += h²c·d·I`: the assignment's `K_c = c·d·I` with the sign that keeps
    /// `A` SPD. Weak at first contact (`d → 0`), and it also stiffens
    /// tangential motion.
    Isotropic,
    /// The true Jacobian, `A −= h²∂f_c/∂x`. Not always positive definite.
    Exact,
}

/// Settings of the linearly implicit solver.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LinearConfig {
    /// How `A v⁺ = b` is solved.
    pub solver: LinearSolver,
    /// Which spring blocks enter `A`.
    pub springs: SpringJacobian,
    /// Which penalty stiffness enters `A`.
    pub penalty: PenaltyJacobian,
}

impl LinearConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), ParamError> {
        if let LinearSolver::Cg(cg) = self.solver {
            if cg.max_iterations == 0 {
                return Err(ParamError::Iterations);
            }
            if !(cg.tolerance.is_finite() && cg.tolerance >= 0.0) {
                return Err(ParamError::Tolerance(cg.tolerance));
            }
        }
        Ok(())
    }
}

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
    key: (usize, Vec<u32>),
    dof_of: Vec<u32>,
    dofs: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    diag: Vec<Slot>,
    /// Per spring: blocks (a,a), (b,b), (a,b), (b,a).
    springs: Vec<[Slot; 4]>,
    values: Vec<f64>,
    rhs: Vec<f64>,
}

fn pattern_key(model: &ClothModel) -> (usize, Vec<u32>) {
    (
        std::sync::Arc::as_ptr(model.topology_arc()) as usize,
        model.pins().to_vec(),
    )
}

impl LinearSystem {
    /// Builds the sparsity pattern of `model`'s system (allocates).
    pub fn new(model: &ClothModel) -> Self {
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
        let slot = |r: u32, c: u32| -> Slot {
            let (r, c) = (r as usize, c as usize);
            let rows = &blk_rows[blk_ptr[c]..blk_ptr[c + 1]];
            let k = rows.binary_search(&(r as u32)).expect("block in pattern");
            Slot {
                base: (9 * blk_ptr[c] + 3 * k) as u32,
                stride: (3 * rows.len()) as u32,
            }
        };
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
        config: &LinearConfig,
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
        config: &LinearConfig,
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
        config: &LinearConfig,
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

/// Scratch of the linearly implicit solver: the system, the symbolic
/// factorisation and solver memory, kept from step to step.
#[derive(Default)]
pub struct LinearWorkspace {
    system: Option<LinearSystem>,
    cholesky: SparseCholesky,
    solution: Vec<f64>,
    scratch: Vec<f64>,
    inv_diag: Vec<f64>,
    memory: Option<MemBuffer>,
    damped: Vec<Vec3A>,
    /// Pattern builds so far (for tests: rebuilt only when needed).
    pattern_builds: u32,
}

impl core::fmt::Debug for LinearWorkspace {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("LinearWorkspace")
            .field(
                "dimension",
                &self.system.as_ref().map(LinearSystem::dimension),
            )
            .field("pattern_builds", &self.pattern_builds)
            .finish_non_exhaustive()
    }
}

impl LinearWorkspace {
    /// The system assembled by the last step.
    pub fn system(&self) -> Option<&LinearSystem> {
        self.system.as_ref()
    }

    /// How many times the sparsity pattern was built.
    pub fn pattern_builds(&self) -> u32 {
        self.pattern_builds
    }

    fn prepare(&mut self, model: &ClothModel) {
        if self
            .system
            .as_ref()
            .is_none_or(|s| s.key != pattern_key(model))
        {
            let system = LinearSystem::new(model);
            let n = system.dimension();
            self.solution = vec![0.0; n];
            self.scratch = vec![0.0; n];
            self.inv_diag = vec![0.0; n];
            self.system = Some(system);
            self.cholesky.reset();
            self.memory = None;
            self.pattern_builds += 1;
        }
    }
}

/// Advances `state` by one linearly implicit Euler step (see the module
/// docs). Reports solver iterations (0 for the direct solve) and the final
/// relative residual `‖b − Av⁺‖/‖b‖`.
pub fn step(
    model: &ClothModel,
    state: &mut ClothState,
    params: &StepParams,
    config: &LinearConfig,
    spheres: &[PenaltySphere],
    ws: &mut LinearWorkspace,
) -> Result<StepReport, StepError> {
    params.validate()?;
    config.validate()?;
    check_state(model, state)?;
    ws.prepare(model);
    let pinned = model.pinned();
    ws.damped.clear();
    ws.damped.extend(
        state.velocities.iter().enumerate().map(
            |(i, &v)| {
                if pinned[i] { v } else { v * params.damping }
            },
        ),
    );
    let LinearWorkspace {
        system,
        cholesky,
        solution,
        scratch,
        inv_diag,
        memory,
        damped,
        ..
    } = ws;
    let system = system.as_mut().expect("prepared");
    system.assemble(model, &state.positions, damped, params, config, spheres);
    let n = system.dimension();
    let result = if n == 0 {
        Ok((0, 0.0))
    } else {
        match config.solver {
            LinearSolver::Cg(cg) => {
                for (i, v) in damped.iter().enumerate() {
                    if let Some(d) = system.dof(i) {
                        solution[d..d + 3].copy_from_slice(&v.as_dvec3().to_array());
                    }
                }
                solve_cg(system, &cg, solution, inv_diag, memory)
            }
            LinearSolver::Direct => solve_direct(system, cholesky, solution, scratch),
        }
    };
    let (iterations, residual) = result.map_err(StepError::Solve)?;
    let h = params.dt as f32;
    for i in 0..state.positions.len() {
        if let Some(d) = system.dof(i) {
            let v = Vec3A::new(
                solution[d] as f32,
                solution[d + 1] as f32,
                solution[d + 2] as f32,
            );
            state.velocities[i] = v;
            state.positions[i] += h * v;
        }
    }
    Ok(StepReport {
        iterations,
        residual: Some(residual as f32),
    })
}

fn solve_cg(
    system: &LinearSystem,
    cg: &CgConfig,
    solution: &mut [f64],
    inv_diag: &mut [f64],
    memory: &mut Option<MemBuffer>,
) -> Result<(u32, f64), SolveError> {
    let n = system.dimension();
    let a = system.matrix();
    let params = CgParams {
        initial_guess: InitialGuessStatus::MaybeNonZero,
        abs_tolerance: 0.0,
        rel_tolerance: cg.tolerance,
        max_iters: cg.max_iterations as usize,
        ..Default::default()
    };
    let identity = IdentityPrecond { dim: n };
    let memory = memory.get_or_insert_with(|| {
        MemBuffer::new(StackReq::any_of(&[
            conjugate_gradient_scratch(identity, a, 1, Par::Seq),
            conjugate_gradient_scratch(
                faer::diag::DiagRef::from_slice(&inv_diag[..]),
                a,
                1,
                Par::Seq,
            ),
        ]))
    });
    let stack = MemStack::new(memory);
    let out = MatMut::from_column_major_slice_mut(solution, n, 1);
    let rhs = MatRef::from_column_major_slice(system.rhs(), n, 1);
    let result = match cg.preconditioner {
        Preconditioner::None => {
            conjugate_gradient(out, identity, a, rhs, params, |_| {}, Par::Seq, stack)
        }
        Preconditioner::Jacobi => {
            for (c, d) in inv_diag.iter_mut().enumerate() {
                let k = (system.col_ptr[c]..system.col_ptr[c + 1])
                    .find(|&k| system.row_idx[k] == c)
                    .expect("diagonal in pattern");
                *d = 1.0 / system.values[k];
            }
            let precond = faer::diag::DiagRef::from_slice(&inv_diag[..]);
            conjugate_gradient(out, precond, a, rhs, params, |_| {}, Par::Seq, stack)
        }
    };
    match result {
        Ok(info) => Ok((info.iter_count as u32, info.rel_residual)),
        Err(CgError::NoConvergence { rel_residual, .. }) => Ok((cg.max_iterations, rel_residual)),
        Err(CgError::NonPositiveDefiniteOperator)
        | Err(CgError::NonPositiveDefinitePreconditioner) => Err(SolveError::NotPositiveDefinite),
    }
}

fn solve_direct(
    system: &LinearSystem,
    cholesky: &mut SparseCholesky,
    solution: &mut [f64],
    scratch: &mut [f64],
) -> Result<(u32, f64), SolveError> {
    solution.copy_from_slice(system.rhs());
    cholesky.solve_ldlt(system.matrix(), solution)?;
    // Relative residual ‖b − Av‖/‖b‖.
    system.multiply(solution, scratch);
    let (mut r2, mut b2) = (0.0, 0.0);
    for (ax, b) in scratch.iter().zip(system.rhs()) {
        r2 += (b - ax) * (b - ax);
        b2 += b * b;
    }
    Ok((
        0,
        if b2 > 0.0 {
            (r2 / b2).sqrt()
        } else {
            r2.sqrt()
        },
    ))
}

/// A sparse Cholesky factorisation (faer, AMD ordering) whose symbolic
/// analysis is done once for a sparsity pattern and reused by every
/// numeric factorisation.
#[derive(Default)]
pub(crate) struct SparseCholesky {
    symbolic: Option<SymbolicCholesky<usize>>,
    factor: Vec<f64>,
    memory: Option<MemBuffer>,
}

impl SparseCholesky {
    /// Forgets the symbolic analysis (the pattern changed).
    pub(crate) fn reset(&mut self) {
        *self = Self::default();
    }

    fn analyse(&mut self, a: SparseColMatRef<'_, usize, f64>) -> Result<(), SolveError> {
        if self.symbolic.is_none() {
            let sym = factorize_symbolic_cholesky(
                a.symbolic(),
                Side::Lower,
                SymmetricOrdering::Amd,
                CholeskySymbolicParams::default(),
            )
            .map_err(|_| SolveError::Factorization)?;
            self.factor.resize(sym.len_val(), 0.0);
            self.memory = Some(MemBuffer::new(StackReq::any_of(&[
                sym.factorize_numeric_ldlt_scratch::<f64>(Par::Seq, Default::default()),
                sym.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
                sym.solve_in_place_scratch::<f64>(1, Par::Seq),
            ])));
            self.symbolic = Some(sym);
        }
        Ok(())
    }

    /// Solves `A x = rhs` in place by LDLᵀ (any symmetric `A` without a zero
    /// pivot; like the assignment's `A.ldlt().solve(b)`).
    pub(crate) fn solve_ldlt(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        rhs: &mut [f64],
    ) -> Result<(), SolveError> {
        self.solve(a, rhs, false)
    }

    /// Solves `A x = rhs` in place by LLᵀ; fails with
    /// [`SolveError::NotPositiveDefinite`] when `A` is not positive definite.
    pub(crate) fn solve_llt(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        rhs: &mut [f64],
    ) -> Result<(), SolveError> {
        self.solve(a, rhs, true)
    }

    fn solve(
        &mut self,
        a: SparseColMatRef<'_, usize, f64>,
        rhs: &mut [f64],
        llt: bool,
    ) -> Result<(), SolveError> {
        self.analyse(a)?;
        let n = rhs.len();
        let (Some(sym), Some(memory)) = (self.symbolic.as_ref(), self.memory.as_mut()) else {
            return Err(SolveError::Factorization);
        };
        let rhs_mat = MatMut::from_column_major_slice_mut(rhs, n, 1);
        let (lower, par) = (Side::Lower, Par::Seq);
        if llt {
            sym.factorize_numeric_llt(
                &mut self.factor,
                a,
                lower,
                Default::default(),
                par,
                MemStack::new(memory),
                Default::default(),
            )
            .map_err(|_| SolveError::NotPositiveDefinite)?
            .solve_in_place_with_conj(Conj::No, rhs_mat, par, MemStack::new(memory));
        } else {
            sym.factorize_numeric_ldlt(
                &mut self.factor,
                a,
                lower,
                Default::default(),
                par,
                MemStack::new(memory),
                Default::default(),
            )
            .map_err(|_| SolveError::Factorization)?
            .solve_in_place_with_conj(Conj::No, rhs_mat, par, MemStack::new(memory));
        }
        if rhs.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(SolveError::Factorization)
        }
    }
}

#[cfg(test)]
#[path = "linear_tests.rs"]
mod tests;
