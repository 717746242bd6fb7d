//! Self-collision's share of the step (issue N): one step of a cotton sheet
//! folded in four and landed on the ground ([`contact::folded`]), with and
//! without its self-collision, one thread.

use std::time::Instant;

use bevy_cloth::AnyMethod;
use bevy_cloth::XpbdSolver;
use bevy_cloth::collision::self_contact::{IntersectionCheck, count_intersections};
use bevy_cloth::model::ClothState;
use bevy_cloth::solver::guard::GuardError;

use super::{PerfConfig, Timing, time_samples};
use crate::contact::{self, ContactCase, Stepper};

/// Steps the folded sheet falls and settles for before it is timed.
const SETTLE: usize = 40;

/// One row: a size and method, its step without and with self-collision.
#[derive(Clone, Debug)]
pub struct SelfCollisionRow {
    /// The method's label.
    pub method: String,
    /// The grid's side.
    pub n: usize,
    /// The step without self-collision.
    pub without: Timing,
    /// The step with it.
    pub with: Timing,
    /// The steps of the sheet's fall and landing ([`SETTLE`] steps from
    /// the drop), without and with self-collision.
    pub landing: (Timing, Timing),
    /// Whether a timed step with self-collision left the sheet through
    /// itself (the exact check after the last sample) or was refused by the
    /// guard.
    pub broken: Option<String>,
}

impl SelfCollisionRow {
    /// What self-collision adds to the median step (seconds).
    pub fn added(&self) -> f64 {
        self.with.median - self.without.median
    }
}

/// The methods of the table: the lab's Chebyshev (self-collision after its
/// step), PBD (after each of its iterations), `pd` (terms of its objective)
/// and `stiff` (inside its substeps).
fn methods() -> Vec<(String, AnyMethod)> {
    let mut m: Vec<(String, AnyMethod)> = bevy_cloth::methods::preset("chebyshev")
        .map(|p| vec![(crate::label(&p.method), p.method)])
        .unwrap_or_default();
    for name in ["pbd", "pd"] {
        m.extend(bevy_cloth::methods::preset(name).map(|p| (crate::label(&p.method), p.method)));
    }
    m.push(("stiff".into(), AnyMethod::Xpbd(XpbdSolver::STIFF)));
    m
}

/// The folded sheet at `n²`, on one thread.
fn case(n: usize) -> ContactCase {
    let mut case = contact::folded(n, 4, 1.0);
    case.params.parallel = false;
    case
}

/// The folded sheet at `n²` after [`SETTLE`] steps of `stiff` with
/// self-collision.
fn settled(n: usize) -> (ContactCase, ClothState) {
    let case = case(n);
    let mut state = case.start.clone();
    let mut solids = case.solids.clone();
    let mut stepper = Stepper::default();
    let stiff = AnyMethod::Xpbd(XpbdSolver::STIFF);
    for _ in 0..SETTLE {
        if stepper
            .step(&case, &stiff, &mut state, &mut solids, false)
            .is_err()
        {
            break;
        }
    }
    (case, state)
}

/// Times one step from the settled state, sample after sample; returns the
/// timing and what went wrong with the last sample, if anything.
fn time_step(
    config: &PerfConfig,
    case: &ContactCase,
    warm: &ClothState,
    method: &AnyMethod,
) -> (Timing, Option<String>) {
    let mut stepper = Stepper::default();
    let mut state = warm.clone();
    let mut last = Ok(());
    let timing = time_samples(config.budget, config.min_samples, || {
        state.clone_from(warm);
        let mut solids = case.solids.clone();
        let t = Instant::now();
        last = stepper.step(case, method, &mut state, &mut solids, false);
        t.elapsed().as_secs_f64()
    });
    let broken = match last {
        Err(GuardError::Diverged { reason, .. }) => Some(format!("guard: {reason:?}")),
        Err(GuardError::Refused(e)) => Some(format!("refused: {e}")),
        Ok(()) if case.self_collision.is_some() => {
            let through = count_intersections(
                &case.model,
                &state.positions,
                &mut IntersectionCheck::default(),
            );
            (through > 0).then(|| format!("{through} through"))
        }
        Ok(()) => None,
    };
    (timing, broken)
}

/// Each step of the fall and landing from the drop, timed (until the
/// guard stops it, if it does).
fn landing(case: &ContactCase, method: &AnyMethod) -> Timing {
    let mut stepper = Stepper::default();
    let mut state = case.start.clone();
    let mut solids = case.solids.clone();
    let mut times = Vec::with_capacity(SETTLE);
    for _ in 0..SETTLE {
        let t = Instant::now();
        let done = stepper.step(case, method, &mut state, &mut solids, false);
        times.push(t.elapsed().as_secs_f64());
        if done.is_err() {
            break;
        }
    }
    Timing::of(times)
}

/// Every size of [`PerfConfig::self_collision_sizes`] with every method.
pub fn self_collision_rows(config: &PerfConfig) -> Vec<SelfCollisionRow> {
    let mut rows = Vec::new();
    for &n in &config.self_collision_sizes {
        let (case, warm) = settled(n);
        let bare = case.clone().without_self_collision();
        for (label, method) in methods() {
            let (without, _) = time_step(config, &bare, &warm, &method);
            let (with, broken) = time_step(config, &case, &warm, &method);
            rows.push(SelfCollisionRow {
                method: label,
                n,
                without,
                with,
                landing: (landing(&bare, &method), landing(&case, &method)),
                broken,
            });
        }
    }
    rows
}
