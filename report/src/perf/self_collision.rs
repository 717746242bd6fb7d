//! Self-collision's share of the step (issue N): one step of a cotton sheet
//! folded in four and landed on the ground ([`contact::folded`]), with and
//! without its self-collision, one thread; and a frame of the plugin's app
//! with two sheets draped on each other ([`TwoSheets`]), with and without
//! theirs.

use std::time::Instant;

use bevy_cloth::AnyMethod;
use bevy_cloth::XpbdSolver;
use bevy_cloth::collision::self_contact::{IntersectionCheck, count_intersections};
use bevy_cloth::model::ClothState;
use bevy_cloth::solver::guard::GuardError;
use bevy_cloth::{Cloth, ClothStats};

use super::{PerfConfig, Timing, time_samples};
use crate::contact::{self, ContactCase, Stepper};
use crate::two_sheets::{TwoSheets, edges_through};

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
    let mut last = Ok(None);
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
        Ok(_) if case.self_collision.is_some() => {
            let through = count_intersections(
                &case.model,
                &state.positions,
                &mut IntersectionCheck::default(),
            );
            (through > 0).then(|| format!("{through} through"))
        }
        Ok(_) => None,
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

/// One row of the cloth-against-cloth table: the map's two sheets
/// ([`TwoSheets`]) at one size and method, a frame of the app without and
/// with their self-collision.
#[derive(Clone, Debug)]
pub struct TwoSheetsRow {
    /// The method's label.
    pub method: String,
    /// Each sheet's side.
    pub n: usize,
    /// One `App::update` (a fixed step of both sheets) without
    /// self-collision.
    pub without: Timing,
    /// The same with it (each sheet's own pairs, the other's vertices in
    /// its step and the pass between the cloths).
    pub with: Timing,
    /// The most edges through (either sheet through the other or itself)
    /// after any timed step with self-collision, or the guard's stop.
    pub broken: Option<String>,
}

/// Steps the two sheets fall, land and drape for before they are timed,
/// and the steps timed after.
const TWO_SETTLE: usize = 60;
const TWO_TIMED: usize = 60;

/// Each update from [`TWO_SETTLE`] on, timed once, and what the exact
/// check found wrong after them (with self-collision).
fn time_two(n: usize, method: &AnyMethod, self_collision: bool) -> (Timing, Option<String>) {
    let scene = TwoSheets {
        cols: n,
        seconds: 0.0,
    };
    let (mut app, sheets) = scene.app(method, self_collision);
    let mut check = IntersectionCheck::default();
    let mut times = Vec::with_capacity(TWO_TIMED);
    let mut through = 0;
    // The first update runs no fixed step.
    for k in 0..=TWO_SETTLE + TWO_TIMED {
        let t = Instant::now();
        app.update();
        let elapsed = t.elapsed().as_secs_f64();
        let world = app.world();
        let cloth = |e| world.get::<Cloth>(e).expect("a sheet");
        let stats = |e| world.get::<ClothStats>(e).expect("a sheet's stats");
        if let Some(e) = sheets.iter().find(|&&e| !stats(e).is_running()) {
            // (Stopped before the timed steps: the stopping update alone.)
            if times.is_empty() {
                times.push(elapsed);
            }
            let why = format!("stopped at update {k}: {:?}", stats(*e).status);
            return (Timing::of(times), Some(why));
        }
        if k > TWO_SETTLE {
            times.push(elapsed);
            if self_collision {
                let (a, b) = (cloth(sheets[0]), cloth(sheets[1]));
                through = through.max(edges_through(a, b, &mut check));
            }
        }
    }
    (
        Timing::of(times),
        (through > 0).then(|| format!("{through} through")),
    )
}

/// Every size of [`PerfConfig::two_sheet_sizes`] with every method.
pub fn two_sheets_rows(config: &PerfConfig) -> Vec<TwoSheetsRow> {
    let mut rows = Vec::new();
    for &n in &config.two_sheet_sizes {
        for (label, method) in methods() {
            let (without, _) = time_two(n, &method, false);
            let (with, broken) = time_two(n, &method, true);
            rows.push(TwoSheetsRow {
                method: label,
                n,
                without,
                with,
                broken,
            });
        }
    }
    rows
}
