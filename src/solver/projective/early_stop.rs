//! The early stop of projective dynamics ([`ProjectiveSolver::tolerance`](super::ProjectiveSolver::tolerance)):
//! an estimate of the step's error from the right-hand sides the iteration
//! makes anyway.

use bevy::math::{DVec3, Vec3A};

use crate::model::ClothModel;
use crate::solver::ConvergenceSums;

/// The error estimate behind [`ProjectiveSolver::tolerance`](super::ProjectiveSolver::tolerance), made each
/// iteration from what the iteration computes anyway.
///
/// The objective's gradient at an iterate `x_j` is `S x_j − b_j`, where
/// `b_j` is the right-hand side the local step at `x_j` gives (the
/// projections' and spheres' terms are the gradient's non-quadratic part,
/// pins and inertia its constant part). `S x_j` needs no product with `S`:
/// the direct solve gives `S x̂_{j+1} = b_j`, and Chebyshev's iterate is
/// `x_{j+1} = ω_j x̂_{j+1} + (1 − ω_j) x_{j−1}`, so `q_{j+1} = S x_{j+1} =
/// ω_j b_j + (1 − ω_j) q_{j−1}`. The first iterations are plain (`ω = 1`), so
/// `q` is known from the first solve on: `q_1 = b_0` (with a fixed `ρ`, whose
/// second iteration is already accelerated, only every other iterate has
/// it). The multigrid's right-hand side is that gradient itself. The
/// estimate is then [`ConvergenceSums`]' over free vertices, as the step's
/// reported [`relative_error`](crate::solver::StepReport::relative_error), which is still
/// computed afresh in `f64` at the final iterate.
#[derive(Debug, Default)]
pub(super) struct EarlyStop {
    /// The tolerance, or 0 (off), and the step's `h`.
    pub(super) tolerance: f64,
    pub(super) dt: f64,
    /// Iterations estimated so far this step, and this iteration's `ω`
    /// (set before its local step).
    pub(super) iteration: u32,
    pub(super) omega: f64,
    /// `S x` at the last two iterates by position of the right-hand side
    /// (the lanes' order for the simplicial factor, else free order):
    /// `q1` the latest, and whether each is known.
    pub(super) q1: Vec<DVec3>,
    pub(super) q2: Vec<DVec3>,
    pub(super) known: [bool; 2],
    /// Per free vertex `h²/m` (in `f64` and `f32`, made with the
    /// factorisation); per vertex its position at the start of the step.
    pub(super) h2_over_m: Vec<f64>,
    pub(super) h2_over_m32: Vec<f32>,
    pub(super) x_start: Vec<Vec3A>,
    /// By position: the vertex, its `h²/m` and start (made at the first
    /// iteration, which has no estimate).
    pub(super) vertex: Vec<u32>,
    pub(super) weight: Vec<f64>,
    pub(super) start: Vec<Vec3A>,
}

impl EarlyStop {
    /// Starts a step with `tolerance` (0: off).
    pub(super) fn start(&mut self, tolerance: f64, dt: f64, vertices: usize) {
        (self.tolerance, self.dt) = (tolerance, dt);
        self.iteration = 0;
        self.omega = 1.0;
        self.known = [false; 2];
        if tolerance > 0.0 {
            self.x_start.resize(vertices, Vec3A::ZERO);
        }
    }

    #[inline]
    pub(super) fn on(&self) -> bool {
        self.tolerance > 0.0
    }

    /// Takes the right-hand side `b_j` at iterate `x` (`len` positions:
    /// `free_at(p)` is position `p`'s free index, `b_at(p)` its value). True
    /// if the estimated relative error at `x` is within the tolerance.
    #[inline(always)]
    pub(super) fn converged(
        &mut self,
        model: &ClothModel,
        x: &[Vec3A],
        free: &[u32],
        len: usize,
        free_at: impl Fn(usize) -> usize,
        b_at: impl FnMut(usize) -> DVec3,
    ) -> bool {
        if self.iteration == 0 {
            self.q1.resize(len, DVec3::ZERO);
            self.q2.resize(len, DVec3::ZERO);
            self.vertex.clear();
            self.weight.clear();
            self.start.clear();
            for p in 0..len {
                let f = free_at(p);
                let i = free[f];
                self.vertex.push(i);
                self.weight.push(self.h2_over_m[f]);
                self.start.push(self.x_start[i as usize]);
            }
        }
        let (omega, known) = (self.omega, self.known[0]);
        // `q_{j+1}` into `q2`'s place (`q_{j−1}`); the estimate from `q_j`.
        let sums = match (known, omega == 1.0) {
            (true, true) => self.pass::<true, true>(x, len, omega, b_at),
            (true, false) => self.pass::<true, false>(x, len, omega, b_at),
            (false, true) => self.pass::<false, true>(x, len, omega, b_at),
            (false, false) => self.pass::<false, false>(x, len, omega, b_at),
        };
        core::mem::swap(&mut self.q1, &mut self.q2);
        self.known = [omega == 1.0 || self.known[1], known];
        self.iteration += 1;
        known && f64::from(sums.relative_error(model, self.dt)) <= self.tolerance
    }

    /// [`converged`](Self::converged)'s loop: with `KNOWN` the estimate,
    /// and `q_{j+1}` plainly `b_j` if `PLAIN` (`ω = 1`).
    #[inline(always)]
    pub(super) fn pass<const KNOWN: bool, const PLAIN: bool>(
        &mut self,
        x: &[Vec3A],
        len: usize,
        omega: f64,
        mut b_at: impl FnMut(usize) -> DVec3,
    ) -> ConvergenceSums {
        let mut sums = ErrorSlots::default();
        let (q1, q2) = (&self.q1[..len], &mut self.q2[..len]);
        let (vertex, weight, start) =
            (&self.vertex[..len], &self.weight[..len], &self.start[..len]);
        for (p, (q2, (q1, ((&i, &w), &start)))) in q2
            .iter_mut()
            .zip(q1.iter().zip(vertex.iter().zip(weight).zip(start)))
            .enumerate()
        {
            let b = b_at(p);
            if KNOWN {
                let error = ((*q1 - b) * w).length_squared();
                sums.add(p, error, (x[i as usize] - start).length_squared());
            }
            *q2 = if PLAIN {
                b
            } else {
                omega * b + (1.0 - omega) * *q2
            };
        }
        sums.sums(len)
    }
}

/// Squared errors and motions summed in 8 interleaved slots, so that one
/// vertex's sum does not wait on the last one's; in `f64`, or in `f32` for
/// the multigrid's `f32` gradient.
#[derive(Default)]
pub(super) struct ErrorSlots([[f64; 2]; 8], [[f32; 2]; 8]);

impl ErrorSlots {
    /// Adds the vertex at position `at`, in `f32`.
    #[inline(always)]
    pub(super) fn add32(&mut self, at: usize, error: f32, motion: f32) {
        let slot = &mut self.1[at % 8];
        slot[0] += error;
        slot[1] += motion;
    }

    /// Adds the vertex at position `at`.
    #[inline(always)]
    pub(super) fn add(&mut self, at: usize, error: f64, motion: f32) {
        let slot = &mut self.0[at % 8];
        slot[0] += error;
        slot[1] += f64::from(motion);
    }

    /// The sums over `count` free vertices.
    pub(super) fn sums(&self, count: usize) -> ConvergenceSums {
        let (mut error, mut motion) = (0.0, 0.0);
        for ([e, m], [e32, m32]) in self.0.into_iter().zip(self.1) {
            error += e + f64::from(e32);
            motion += m + f64::from(m32);
        }
        ConvergenceSums::from_parts(error, motion, count)
    }
}
