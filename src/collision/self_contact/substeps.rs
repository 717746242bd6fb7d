//! The step's pairs that can touch within the next substeps: a method that
//! resolves the same pairs in each of many substeps (`stiff`) passes over
//! those only, until some vertex has moved far enough for another pair to
//! reach its least distance (a Verlet list within the step).

use bevy::math::Vec3A;

use super::{SelfContacts, edges, faces};
use crate::model::ClothModel;

/// How far beyond its least distance, as a share of the thickness, a pair
/// counts as able to touch in [`SelfContacts::resolve_substep`]: the list is
/// made again once some vertex has moved half this far since it was made.
pub const SUBSTEP_SKIN: f32 = 0.25;

/// The pairs of [`SelfContacts::resolve_substep`].
#[derive(Clone, Debug, Default)]
pub(super) struct Active {
    /// Indices of the step's pairs that can touch.
    pairs: Vec<u32>,
    /// Indices of the step's vertex–triangle and edge–edge pairs that can
    /// touch.
    faces: Vec<u32>,
    edges: Vec<u32>,
    /// The cloth's vertices when `pairs` was made (empty: to be made).
    at: Vec<Vec3A>,
    /// How far beyond its least distance a pair is kept.
    skin: f32,
}

impl Active {
    /// Forgets the list (the step's pairs are found anew), for a
    /// self-collision of `thickness`.
    pub(super) fn reset(&mut self, thickness: f32) {
        self.at.clear();
        self.skin = SUBSTEP_SKIN * thickness;
    }
}

impl SelfContacts {
    /// [`resolve`](Self::resolve) for a method that resolves the step's
    /// pairs in each of many substeps: the same result, bit for bit, from a
    /// pass over the pairs that can touch. A pair further apart than its
    /// least distance plus [`SUBSTEP_SKIN`] of the thickness cannot touch
    /// while neither of its vertices has moved half that far, and the list
    /// is made again as soon as any of the cloth's vertices has (the other
    /// cloths' stand still through the step). A push in the pass that moves
    /// a vertex that far goes on over every pair after it, of every kind and
    /// in order, as `resolve` does.
    ///
    /// The pass covers the step from `progress[0]` to `progress[1]` (0 at
    /// the step's start, 1 at its end), and `start` has the vertices where
    /// they were at `progress[0]`: a pass that does not begin with the step
    /// parts its overlapping vertex–triangle and edge pairs by at most its
    /// share of [`UNTANGLE`](super::UNTANGLE) (a substep; a PBD iteration
    /// passes `[0, done]` with the step's start).
    pub fn resolve_substep(
        &mut self,
        model: &ClothModel,
        x: &mut [Vec3A],
        start: impl Fn(usize) -> Vec3A,
        progress: [f32; 2],
    ) -> u32 {
        let [_, to] = progress;
        self.refresh_active(x);
        let weight = |i| self.weight(model, i);
        let at = &self.active.at;
        let limit = 0.49 * self.active.skin;
        let far = |x: &[Vec3A], i: u32| {
            at.get(i as usize)
                .is_some_and(|&at| x[i as usize].distance_squared(at) > limit * limit)
        };
        // Once a push has moved a vertex beyond the lists' reach, every
        // pair after it is passed over, of every kind, as `resolve` does.
        let mut beyond = false;
        let mut touching = listed_pass(
            &self.pairs,
            &self.active.pairs,
            x,
            &mut beyond,
            |x, p| far(x, p.a) || far(x, p.b),
            |p, x| self.resolve_pair(p, x, &start, to, &weight),
        );
        touching += listed_pass(
            &self.faces.pairs,
            &self.active.faces,
            x,
            &mut beyond,
            |x, p| far(x, p.vertex) || p.triangle.iter().any(|&j| far(x, j)),
            |p, x| faces::resolve_pair(p, x, &start, progress, &weight),
        );
        touching += listed_pass(
            &self.edges.pairs,
            &self.active.edges,
            x,
            &mut beyond,
            |x, p| p.ends.iter().any(|&j| far(x, j)),
            |p, x| edges::resolve_pair(p, x, &start, progress, &weight),
        );
        if beyond {
            // Made again at the next substep.
            self.active.at.clear();
        }
        touching
    }

    /// How many pairs [`resolve_substep`](Self::resolve_substep) last
    /// passed over.
    #[cfg(test)]
    pub(crate) fn active_pairs(&self) -> usize {
        self.active.pairs.len()
    }

    /// Makes the list of pairs that can touch again if it is gone or some
    /// vertex has moved half the skin since it was made.
    fn refresh_active(&mut self, x: &[Vec3A]) {
        let own = self.own.min(x.len());
        let active = &mut self.active;
        // Just under half: a pair kept out at `min + skin` is still at least
        // `min` apart after both ends moved that far, rounding included.
        let limit = 0.49 * active.skin;
        let still = active.at.len() == own
            && x[..own]
                .iter()
                .zip(&active.at)
                .all(|(x, at)| x.distance_squared(*at) <= limit * limit);
        if still {
            return;
        }
        active.at.clear();
        active.at.extend_from_slice(&x[..own]);
        active.faces.clear();
        self.faces.near(&x[..own], active.skin, &mut active.faces);
        active.edges.clear();
        self.edges.near(&x[..own], active.skin, &mut active.edges);
        active.pairs.clear();
        for (k, p) in self.pairs.iter().enumerate() {
            let (a, b) = (p.a as usize, p.b as usize);
            let Some(&xa) = x.get(a) else {
                continue;
            };
            let xb = if b < self.own {
                match x.get(b) {
                    Some(&xb) => xb,
                    None => continue,
                }
            } else {
                self.others[b - self.own].position
            };
            let reach = p.min + active.skin;
            if xa.distance_squared(xb) < reach * reach {
                active.pairs.push(k as u32);
            }
        }
    }
}

/// One kind's pass of [`SelfContacts::resolve_substep`]: `push` over the
/// pairs numbered in `listed`, in order, until one leaves a vertex `far`
/// from where the lists were made; from then on (`beyond`, set here or by
/// an earlier kind's pass) over every pair after it, as the full pass
/// does. Returns the pairs found touching.
fn listed_pass<P>(
    pairs: &[P],
    listed: &[u32],
    x: &mut [Vec3A],
    beyond: &mut bool,
    far: impl Fn(&[Vec3A], &P) -> bool,
    mut push: impl FnMut(&P, &mut [Vec3A]) -> Option<f32>,
) -> u32 {
    let mut touching = 0;
    let mut from = 0;
    if !*beyond {
        from = pairs.len();
        for &k in listed {
            let p = &pairs[k as usize];
            if push(p, x).is_some() {
                touching += 1;
                if far(x, p) {
                    *beyond = true;
                    from = k as usize + 1;
                    break;
                }
            }
        }
    }
    for p in &pairs[from..] {
        if push(p, x).is_some() {
            touching += 1;
        }
    }
    touching
}
