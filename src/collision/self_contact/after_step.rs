//! The pass after the step: self-collision for the methods that do not
//! hold the pairs inside their step, Gauss–Seidel over the step's pairs in
//! a few passes ([`SelfContacts::resolve_after_step`]).

use super::{SelfCollisionInput, SelfContacts};
use crate::model::{ClothModel, ClothState};

/// The most Gauss–Seidel passes self-collision makes after the step of a
/// method that does not handle it inside: contacts found in one pass
/// disturb their neighbours, and a few more settle a fold.
pub const AFTER_STEP_PASSES: u32 = 4;

/// The passes after the step end early once one pushed no pair apart by
/// more than this share of its least distance: what the next would do is
/// smaller still. A resting fold's second pass pushes its pairs by about
/// a ten-thousandth of the thickness (a 64² sheet folded in four, 1.5 cm
/// thick: 2 µm), where its last two passes cost a third of self-collision.
pub const SETTLED: f32 = 1e-3;

/// The share of a pair's least distance that the pass after the step holds
/// after Anderson-accelerated projective dynamics took the pairs into its
/// objective as penalty terms ([`StepReport::lenient_pairs`](crate::solver::StepReport::lenient_pairs)):
/// what the penalty left pressed a little closer is its equilibrium under
/// the layers' weight, and pushing it the whole way fought the springs
/// (`pd-anderson`: the drape, 600 steps, 7.7 % stretch with the whole pass,
/// 6.2 % with this floor, none through either way; issue N's 64² fold for
/// 10 s, 4.0 % → 2.2 %, none through).
/// The guarantee of the [module docs](super) holds above about 0.71 of the
/// edge, and [`SelfCollision::for_model`](crate::SelfCollision::for_model)'s
/// 0.9 of it floored at 0.9 is 0.81 (0.8 would have left 0.72, no margin).
/// The other methods keep the whole pass. With this floor `newton` left two
/// edges through a sheet in the drape (622 summed over 600 steps; 0 with
/// the whole pass), and plain `pd`, whose 10 iterations do not settle the
/// pairs where a stack lands, 130 edges through the 64² fold (23 with the
/// whole pass; its drape 11.9 % → 8.7 %).
pub const PAIR_FLOOR: f32 = 0.9;

/// What one pass over the pairs did.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Pass {
    /// Pairs found touching (and pushed apart).
    pub(crate) touching: u32,
    /// The deepest push, as a share of its pair's least distance.
    pub(crate) deepest: f32,
}

/// Up to [`AFTER_STEP_PASSES`] passes, until one finds nothing touching or
/// pushes nothing deeper than [`SETTLED`]; the first pass's count of
/// touching pairs (what the step left too close).
pub(crate) fn settle(mut pass: impl FnMut() -> Pass) -> u32 {
    let mut first = None;
    for _ in 0..AFTER_STEP_PASSES {
        let now = pass();
        first.get_or_insert(now.touching);
        if now.touching == 0 || now.deepest < SETTLED {
            break;
        }
    }
    first.unwrap_or(0)
}

impl SelfContacts {
    /// Self-collision after a step from `before` to `state` (and against the
    /// other cloths' vertices where they were before it):
    /// the pairs found from the step's start and its motion, pushed apart in
    /// [`AFTER_STEP_PASSES`] passes, and the velocities changed by what that
    /// moved. Returns the pairs the step left too close (the first pass's).
    /// With `lenient` (the step's
    /// [`lenient_pairs`](crate::solver::StepReport::lenient_pairs)), each
    /// pair is held at [`PAIR_FLOOR`] of its least distance.
    pub fn resolve_after_step(
        &mut self,
        model: &ClothModel,
        state: &mut ClothState,
        before: &ClothState,
        params: &crate::solver::StepParams,
        sc: SelfCollisionInput<'_>,
        lenient: bool,
    ) -> u32 {
        let n = model.vertex_count();
        if before.positions.len() < n || state.positions.len() < n {
            return 0;
        }
        let dt = params.dt as f32;
        let inv_dt = 1.0 / dt;
        // The step's motion as a velocity, for the swept boxes.
        // Scratch kept from step to step: the step's motion as a velocity
        // (for the swept boxes) and where the step left the positions.
        let (mut moved, mut solved) = core::mem::take(&mut self.after_step);
        moved.clear();
        moved.extend(
            state.positions[..n]
                .iter()
                .zip(&before.positions)
                .map(|(&x, &b)| (x - b) * inv_dt),
        );
        solved.clear();
        solved.extend_from_slice(&state.positions[..n]);
        self.find_or_keep(model, &before.positions[..n], &moved, dt, sc, 0.0, true);
        // The pairs the step left too close (the first pass's count; the
        // later passes settle what it disturbed).
        self.after_step_floor = lenient.then_some(PAIR_FLOOR);
        let touching = settle(|| {
            self.resolve_weighted(
                self.pairs.iter(),
                &mut state.positions[..n],
                |i| before.positions[i],
                1.0,
                |i| self.weight(model, i),
            )
        });
        for ((v, &x), &s) in state
            .velocities
            .iter_mut()
            .zip(&state.positions)
            .zip(&solved)
        {
            *v += (x - s) * inv_dt;
        }
        self.after_step = (moved, solved);
        self.after_step_floor = None;
        touching
    }
}
