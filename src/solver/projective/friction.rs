//! Lagged Coulomb friction as a projective term.
//!
//! A free vertex that ended the last step in contact with a collider of
//! friction `μ` (normal force `λ = c·depth`, normal `n`, both lagged as in
//! the exact method's friction) gets the term `H(u)`, `u = (I − nnᵀ)(x − x₀)`
//! its tangential slip from its step-start position `x₀`, where `H` is the
//! Huber function of slope `w` capped at `μλ`: `w/2‖u‖²` while
//! `w‖u‖ ≤ μλ` (static: the vertex holds), `μλ‖u‖ − (μλ)²/(2w)` beyond
//! (sliding, against a force of `μλ`). The slope is the exact method's:
//! the force reaches `μλ` at a slip of `ε`, its `STICK_SPEED` (a held
//! vertex creeps at most a thousandth of the cloth's size per second), so
//! `w = μλ/ε`, at most the collider's penalty stiffness `c`. (At `w = c`
//! on every term, static friction froze in the strain Anderson's
//! unconverged steps left on a cloth landing on a table: 2.5 % where the
//! exact step has 0.5 %.) It is convex, and its gradient is `w`-Lipschitz
//! with `w ≤ c`, so it rides on the contact's own weight `c` on the
//! diagonal of the global matrix: the local step adds the friction force
//! `−∇H` at the iterate to the contact's `c·p` (a majorise–minimise step,
//! so each iteration still lowers the objective), and the matrix is not
//! refactorised for it.

use bevy::math::{DVec3, Vec3A};

use crate::collision::{PenaltyContact, PenaltySphere, PenaltySurface};

/// No friction at this free vertex.
pub(super) const NONE: u32 = u32::MAX;

/// One free vertex's friction this step (see the module docs).
#[derive(Clone, Copy, Debug)]
pub(super) struct Friction {
    /// The penalty (index in the step's penalties) it slides on.
    pub(super) penalty: u32,
    /// The vertex at the step's start.
    pub(super) start: Vec3A,
    /// The contact's normal at the last step's end.
    pub(super) normal: Vec3A,
    /// `μλ`.
    pub(super) bound: f32,
    /// The Huber function's slope `w`.
    pub(super) slope: f32,
}

impl Friction {
    /// The tangential slip `u` at `x`.
    fn slip(&self, x: Vec3A) -> Vec3A {
        let d = x - self.start;
        d - self.normal * self.normal.dot(d)
    }

    /// The friction force `−∇H` at `x`, for the slope `c`.
    #[inline]
    pub(super) fn force(&self, x: Vec3A, c: f32) -> Vec3A {
        let u = self.slip(x);
        let y = u.length();
        if c * y <= self.bound {
            -c * u
        } else {
            -u * (self.bound / y)
        }
    }

    /// `H(u)` at `x` (the Anderson safeguard's objective).
    pub(super) fn energy(&self, x: Vec3A, c: f32) -> f64 {
        let y = f64::from(self.slip(x).length());
        let (c, bound) = (f64::from(c), f64::from(self.bound));
        if c * y <= bound {
            0.5 * c * y * y
        } else {
            bound * y - bound * bound / (2.0 * c)
        }
    }

    /// Whether the vertex sticks at `x` for the slope `c` (the term's
    /// Hessian is then `c` across the normal, else about nothing).
    pub(super) fn sticks(&self, x: Vec3A, c: f32) -> bool {
        c * self.slip(x).length() <= self.bound
    }

    /// The tangential part of `g`.
    pub(super) fn tangential(&self, g: DVec3) -> DVec3 {
        let n = self.normal.as_dvec3();
        g - n * n.dot(g)
    }
}

/// The contacts a step ended in, with friction, for the next step's terms:
/// per contact `(vertex, penalty, μλ, normal)`, and the penalty count.
#[derive(Clone, Debug, Default)]
pub(super) struct EndedIn {
    contacts: Vec<(u32, u32, f32, Vec3A)>,
    penalties: usize,
}

/// A vertex's contact with friction pressed hardest so far, as
/// [`EndedIn`] keeps it: `(vertex, penalty, μλ, normal)`.
pub(super) type Pressed = Option<(u32, u32, f32, Vec3A)>;

impl EndedIn {
    /// Forgets the last step's contacts: this step's, against `penalties`
    /// colliders, are [`offer`](Self::offer)ed vertex by vertex and
    /// [`keep`](Self::keep)-ed.
    pub(super) fn clear(&mut self, penalties: usize) {
        self.contacts.clear();
        self.penalties = penalties;
    }

    /// Vertex `i`'s contact `c` with penalty `k`: into `best` if that
    /// collider has friction and presses harder (`μλ`) than what `best`
    /// holds. Only the first 64 penalties count (as the global step's near
    /// sets).
    pub(super) fn offer(
        best: &mut Pressed,
        i: u32,
        k: usize,
        penalty: &PenaltySphere,
        c: &PenaltyContact,
    ) {
        let PenaltySurface::Shape(shape) = penalty.surface else {
            return;
        };
        let mu = shape.friction();
        if k >= 64 || mu.is_nan() || mu <= 0.0 {
            return;
        }
        let bound = mu * penalty.stiffness * c.depth;
        if bound.is_finite() && best.is_none_or(|b| bound > b.2) {
            *best = Some((i, k as u32, bound, c.normal));
        }
    }

    /// Keeps a vertex's contact pressed hardest (the free vertices in
    /// order), if any.
    pub(super) fn keep(&mut self, best: Pressed) {
        self.contacts.extend(best);
    }

    /// This step's terms from the last step's contacts, where the same
    /// penalties are there (their count the same), into `terms`, with each
    /// free vertex's term in `at` (by free index, [`NONE`] for none);
    /// `dof_of` gives a vertex's free index, `x` the step's start.
    /// `eps` is the slip at which the force reaches its bound (see the
    /// module docs).
    pub(super) fn terms(
        &self,
        (penalties, eps): (&[PenaltySphere], f32),
        (dof_of, x): (&[u32], &[Vec3A]),
        terms: &mut Vec<Friction>,
        at: &mut Vec<u32>,
        free: usize,
    ) {
        terms.clear();
        at.clear();
        at.resize(free, NONE);
        if self.penalties != penalties.len() {
            return;
        }
        for &(i, penalty, bound, normal) in &self.contacts {
            let Some(&f) = dof_of.get(i as usize) else {
                continue;
            };
            if (f as usize) < free {
                at[f as usize] = terms.len() as u32;
                let c = penalties[penalty as usize].stiffness;
                let slope = if eps > 0.0 { (bound / eps).min(c) } else { c };
                terms.push(Friction {
                    penalty,
                    start: x[i as usize],
                    normal,
                    bound,
                    slope,
                });
            }
        }
    }
}

/// Free vertex `f`'s friction term and its slope, if it has one on a
/// penalty it is near this step (whose `c ≥` the slope is on its diagonal:
/// see the module docs).
#[inline]
pub(super) fn term_at<'a>(
    (terms, at): (&'a [Friction], &[u32]),
    near: &[u64],
    f: usize,
) -> Option<(&'a Friction, f32)> {
    let term = terms.get(*at.get(f)? as usize)?;
    let s = term.penalty as usize;
    (s < 64 && near[f] & (1 << s) != 0).then_some((term, term.slope))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_force_holds_up_to_the_bound_then_slides_against_it() {
        let term = Friction {
            penalty: 0,
            start: Vec3A::ZERO,
            normal: Vec3A::Y,
            bound: 2.0,
            slope: 100.0,
        };
        let c = 100.0;
        // A slip of 1 cm sticks: the force is −c·u, and no normal part.
        let held = term.force(Vec3A::new(0.01, 0.5, 0.0), c);
        assert!(
            (held - Vec3A::new(-1.0, 0.0, 0.0)).length() < 1e-6,
            "{held}"
        );
        assert!(term.sticks(Vec3A::new(0.01, 0.5, 0.0), c));
        // A slip of 10 cm slides: the force is μλ against it.
        let slid = term.force(Vec3A::new(0.0, -0.3, 0.1), c);
        assert!(
            (slid - Vec3A::new(0.0, 0.0, -2.0)).length() < 1e-6,
            "{slid}"
        );
        assert!(!term.sticks(Vec3A::new(0.0, -0.3, 0.1), c));
        // The energy is the Huber function: continuous at the bound.
        let at = |y: f32| term.energy(Vec3A::new(y, 0.0, 0.0), c);
        assert!((at(0.02) - 0.02).abs() < 1e-9);
        assert!((at(0.02 + 1e-4) - at(0.02) - 2.0 * 1e-4).abs() < 1e-6);
    }
}
