//! The local step of projective dynamics (each spring's projection onto its
//! rest length), and the objective's terms the Anderson safeguard weighs.

use bevy::math::{DVec3, Vec3A};

use super::{ProjectiveSolver, ProjectiveWorkspace, friction};
use crate::collision::PenaltySphere;
use crate::model::ClothModel;
use crate::solver::SolveError;
use crate::solver::engine::kernels::{Springs, spring_scales};
use crate::solver::engine::simd::spring_products;

impl ProjectiveWorkspace {
    /// One local step and one global solve from `x`, into `self.rhs`; or,
    /// with an early stop whose estimate at `x` is within its tolerance,
    /// the local step alone and `true`.
    pub(super) fn local_global(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        spheres: &[PenaltySphere],
    ) -> Result<bool, SolveError> {
        let stencil = model.topology().stencil().filter(|_| self.stencil_on);
        match stencil {
            // On the stencil kernels, summed per vertex: each spring's
            // `k_e·d_e` for the direct solve's right-hand side, or its
            // `k(1 − L/l)d` for the objective's gradient, which the
            // multigrid solves from for the correction.
            Some(stencil) => {
                if self.multigrid.is_some() {
                    self.stencil.load_springs(stencil, self.kinds_k, x);
                } else {
                    self.stencil.load_projection(stencil, self.kinds_k, x);
                }
                self.sums.resize(x.len(), Vec3A::ZERO);
                self.stencil
                    .spring_sums(self.simd, self.parallel, &mut self.sums);
                let sums = std::mem::take(&mut self.sums);
                let solved = self.global(model, x, spheres, Some(&sums));
                self.sums = sums;
                solved
            }
            None => {
                let d = &mut self.d;
                spring_products(self.simd, Springs::of(model), &self.coeffs, x, d);
                self.global(model, x, spheres, None)
            }
        }
    }

    /// The local step alone, returning the spring and penalty energy at `x`
    /// (the objective less its inertia and gravity terms).
    pub(super) fn local_with_energy(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        spheres: &[PenaltySphere],
    ) -> f64 {
        let springs = model.topology().springs();
        let (d, k) = (&mut self.d, &self.k);
        let mut energy = 0.0f64;
        spring_scales(springs, &self.coeffs, x, |e, dx, scale| {
            d[e] = dx * scale;
            let stretch = f64::from(dx.length() * (1.0 - scale));
            energy += 0.5 * k[e] * stretch * stretch;
        });
        if !spheres.is_empty() {
            for (f, &i) in self.free.iter().enumerate() {
                for sphere in spheres {
                    if let Some(contact) = sphere.contact(x[i as usize]) {
                        energy += 0.5 * f64::from(sphere.stiffness * contact.depth * contact.depth);
                    }
                }
                let terms = (&self.friction[..], &self.friction_at[..]);
                if let Some((term, c)) = friction::term_at(terms, &self.near, f) {
                    energy += term.energy(x[i as usize], c);
                }
            }
        }
        energy + self.pairs.energy(x)
    }

    /// Self-collision's pair forces at `x` into `pair_force` (left empty
    /// without pairs).
    pub(super) fn pair_forces(&mut self, x: &[Vec3A]) {
        self.pair_force.clear();
        if self.pairs.terms.is_empty() {
            return;
        }
        self.pair_force.resize(x.len(), Vec3A::ZERO);
        let force = &mut self.pair_force;
        self.pairs.gradient(x, |i, g| force[i] -= g.as_vec3a());
    }
}

impl ProjectiveSolver {
    /// The inertia and gravity terms of the objective at `x`.
    pub(super) fn inertia(
        model: &ClothModel,
        x: &[Vec3A],
        ws: &ProjectiveWorkspace,
        inv_h2: f64,
        gravity: DVec3,
    ) -> f64 {
        let masses = model.masses();
        ws.free
            .iter()
            .map(|&i| {
                let i = i as usize;
                let mass = f64::from(masses[i]);
                let x = x[i].as_dvec3();
                0.5 * mass * inv_h2 * x.distance_squared(ws.x_tilde[i].as_dvec3())
                    - mass * gravity.dot(x)
            })
            .sum()
    }
}
