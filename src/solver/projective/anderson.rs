//! Anderson acceleration of the local–global iteration (type II, Peng et
//! al. 2018, "Anderson acceleration for geometry processing and physics
//! simulation"), with its energy safeguard.

use bevy::math::Vec3A;

use super::global::Solution;
use super::{ProjectiveSolver, ProjectiveWorkspace};
use crate::collision::PenaltySphere;
use crate::model::ClothModel;
use crate::solver::engine::kernels::dot;
use crate::solver::{SolveError, StepParams};

impl ProjectiveSolver {
    /// Anderson-accelerated local–global iterations (type II, Peng et al.
    /// 2018) with their energy safeguard; leaves the last plain iterate in
    /// `x`.
    pub(super) fn anderson_iterations(
        &self,
        model: &ClothModel,
        x: &mut [Vec3A],
        params: &StepParams,
        spheres: &[PenaltySphere],
        ws: &mut ProjectiveWorkspace,
    ) -> Result<(), SolveError> {
        let m = ws.free.len();
        let inv_h2 = 1.0 / (params.dt * params.dt);
        let gravity = params.gravity.as_dvec3();
        let window = self.anderson as usize;
        ws.aa_g.resize(3 * m, 0.0);
        ws.aa_f.resize(3 * m, 0.0);
        let mut history = 0usize;
        let mut next = 0usize;
        let mut accepted = f64::INFINITY;
        let mut extrapolated = false;
        // ΔFᵀΔF by ring slot (slots 0..history hold the history), kept
        // row by row as slots are rewritten, and a copy to solve in.
        ws.aa_gram.resize(window * window, 0.0);
        ws.aa_system.resize(window * window, 0.0);
        ws.aa_gamma.resize(window, 0.0);
        let (mut gram, mut system, mut rhs) = (
            std::mem::take(&mut ws.aa_gram),
            std::mem::take(&mut ws.aa_system),
            std::mem::take(&mut ws.aa_gamma),
        );
        for k in 0..self.iterations {
            let mut energy = ws.local_with_energy(model, x, spheres)
                + Self::inertia(model, x, ws, inv_h2, gravity);
            if extrapolated && energy.partial_cmp(&accepted) != Some(core::cmp::Ordering::Less) {
                // The extrapolation raised the objective: take the plain
                // iterate G(x) of the last accepted x and restart.
                for (f, &i) in ws.free.iter().enumerate() {
                    x[i as usize] = Vec3A::new(
                        ws.aa_g[f] as f32,
                        ws.aa_g[m + f] as f32,
                        ws.aa_g[2 * m + f] as f32,
                    );
                }
                history = 0;
                next = 0;
                energy = ws.local_with_energy(model, x, spheres)
                    + Self::inertia(model, x, ws, inv_h2, gravity);
            }
            accepted = energy;
            // (Anderson takes no tolerance: `validate`.)
            ws.global(model, x, spheres, None)?;
            // g = G(x) in ws.rhs, f = g − x.
            let first = k == 0;
            if ws.aa_dg.len() < window {
                ws.aa_dg.resize(window, Vec::new());
                ws.aa_df.resize(window, Vec::new());
            }
            let mut dg = std::mem::take(&mut ws.aa_dg[next]);
            let mut df = std::mem::take(&mut ws.aa_df[next]);
            dg.resize(3 * m, 0.0);
            df.resize(3 * m, 0.0);
            let solved = Solution::of(&ws.multigrid, &ws.cholesky, &ws.rhs);
            for (f, &i) in ws.free.iter().enumerate() {
                let xi = x[i as usize];
                let gi = solved.at_f64(f, i as usize, xi).to_array();
                for (c, &xc) in xi.to_array().iter().enumerate() {
                    let j = c * m + f;
                    let g = gi[c];
                    let fx = g - f64::from(xc);
                    dg[j] = g - ws.aa_g[j];
                    df[j] = fx - ws.aa_f[j];
                    ws.aa_g[j] = g;
                    ws.aa_f[j] = fx;
                }
            }
            (ws.aa_dg[next], ws.aa_df[next]) = (dg, df);
            if !first {
                let written = next;
                history = (history + 1).min(window);
                next = (next + 1) % window;
                for b in 0..history {
                    let dot = dot(&ws.aa_df[written], &ws.aa_df[b]);
                    gram[written * window + b] = dot;
                    gram[b * window + written] = dot;
                }
            }
            extrapolated = false;
            let last = k + 1 == self.iterations;
            if history > 0 && !last {
                // γ = argmin ‖f − ΔF γ‖ by its normal equations (at most
                // `window`² entries, solved in place: Gaussian elimination
                // with a small Tikhonov term for a rank-deficient history).
                system.copy_from_slice(&gram);
                for (a, r) in rhs.iter_mut().enumerate().take(history) {
                    *r = dot(&ws.aa_df[a], &ws.aa_f);
                }
                let trace: f64 = (0..history).map(|a| gram[a * window + a]).sum();
                for a in 0..history {
                    system[a * window + a] += 1e-10 * trace + f64::MIN_POSITIVE;
                }
                if solve_small(&mut system, &mut rhs, history, window) {
                    for (f, &i) in ws.free.iter().enumerate() {
                        let mut p = [ws.aa_g[f], ws.aa_g[m + f], ws.aa_g[2 * m + f]];
                        for (h, &gamma) in rhs.iter().enumerate().take(history) {
                            let s = &ws.aa_dg[h];
                            p[0] -= gamma * s[f];
                            p[1] -= gamma * s[m + f];
                            p[2] -= gamma * s[2 * m + f];
                        }
                        x[i as usize] = Vec3A::new(p[0] as f32, p[1] as f32, p[2] as f32);
                    }
                    extrapolated = x.iter().all(|p| p.is_finite());
                }
                if !extrapolated {
                    history = 0;
                    next = 0;
                }
            }
            if !extrapolated {
                for (f, &i) in ws.free.iter().enumerate() {
                    x[i as usize] = Vec3A::new(
                        ws.aa_g[f] as f32,
                        ws.aa_g[m + f] as f32,
                        ws.aa_g[2 * m + f] as f32,
                    );
                }
            }
        }
        // Kept for the next step (an early error return just drops them).
        (ws.aa_gram, ws.aa_system, ws.aa_gamma) = (gram, system, rhs);
        Ok(())
    }
}

/// Solves the `n×n` system in the top-left of the row-major `stride`-wide
/// `a` for `b` in place, by Gaussian elimination with partial pivoting
/// (hand-written: `n` is Anderson's window, a handful, where a dense
/// library's setup costs more than the solve). False if singular.
fn solve_small(a: &mut [f64], b: &mut [f64], n: usize, stride: usize) -> bool {
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&p, &q| {
                a[p * stride + col]
                    .abs()
                    .total_cmp(&a[q * stride + col].abs())
            })
            .unwrap_or(col);
        if a[pivot * stride + col].abs().partial_cmp(&0.0) != Some(core::cmp::Ordering::Greater) {
            return false;
        }
        if pivot != col {
            for c in 0..n {
                a.swap(col * stride + c, pivot * stride + c);
            }
            b.swap(col, pivot);
        }
        for row in col + 1..n {
            let factor = a[row * stride + col] / a[col * stride + col];
            for c in col..n {
                a[row * stride + c] -= factor * a[col * stride + c];
            }
            b[row] -= factor * b[col];
        }
    }
    for row in (0..n).rev() {
        let mut v = b[row];
        for c in row + 1..n {
            v -= a[row * stride + c] * b[c];
        }
        b[row] = v / a[row * stride + row];
    }
    b[..n].iter().all(|v| v.is_finite())
}
