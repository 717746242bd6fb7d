//! The map's long runs (issue M): every method for at least ten simulated
//! seconds in three scenes, judged over the whole run by measures that do
//! not depend on chaos.
//!
//! A hanging cloth without bending stiffness is chaotic: two exact runs that
//! start a hundred-thousandth of a metre apart part within seconds. So a run
//! is compared with its reference pointwise only inside the **window** where
//! the reference agrees with a second run of itself (its *check*), and over
//! the whole run by what chaos does not move:
//!
//! - **pointwise** (inside the window): the root-mean-square distance of the
//!   vertices from the reference's, at every step;
//! - **mean height** and **swing** over the run's last two seconds (its last
//!   fifth when it is shorter than ten): the mean, and half the range, of the
//!   cloth's mean height;
//! - **max stretch** over the whole run;
//! - **flagged**: the share of steps whose estimated error exceeds
//!   [`CONVERGENCE_TOLERANCE`](bevy_cloth::solver::CONVERGENCE_TOLERANCE),
//!   after the projection as the plugin measures it
//!   ([`ContactError`](bevy_cloth::solver::ContactError)).
//!
//! Distances and heights are relative to the reference's drop (how far its
//! lowest point is below the flat sheet's at the end, at least 1 % of the
//! cloth's size). Each measure's **floor** is the same measure between the
//! reference and its check, and is added to the measure's tolerance.
//!
//! Two references:
//!
//! - the **exact** implicit-Euler run at the case's step, which judges the
//!   specifications' methods; its check is the same run started with one
//!   vertex moved by [`NUDGE`], so its floor is chaos alone;
//! - the **physical** reference, which judges the `stiff` preset (it does not
//!   solve implicit Euler, whose large steps damp stiff cloth): the exact
//!   method at the case's step split until it is at most
//!   [`PHYSICAL_STEP`](crate::scenarios::PHYSICAL_STEP); its check is the same
//!   at twice that step (at half of it where the case's own step is already
//!   that small), so its floor bounds what its own step still moves.

use bevy::math::{Affine3A, Vec3A};

use crate::scenarios::{
    Floor, Outcome, Run, Scenario, Verdict, extent, judged_physically, map_methods, reference_for,
    run,
};
use bevy_cloth::collision::{Capsule, Shape};
use bevy_cloth::methods::AnyMethod;
use bevy_cloth::model::ClothState;
use bevy_cloth::solver::exact::ExactSolver;

/// How long the long runs are.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Length {
    /// Simulated seconds of every run.
    pub seconds: f64,
    /// The most steps a run takes: where the case's step is tiny, its run
    /// is shorter than `seconds`.
    pub max_steps: usize,
}

/// How long the map's draped start settles: after ten seconds a stiff
/// cloth still slid off the frictionless sphere by 0.3 m over the next ten
/// (and a soft one still swung); after sixty it moves less than a
/// millimetre.
pub const SETTLE_SECONDS: f64 = 60.0;

impl Length {
    /// The map's: ten seconds, at most 1000 steps (so 0.1 s at a step of
    /// 1e-4 s and 1 s at 1e-3 s).
    pub const MAP: Self = Self {
        seconds: 10.0,
        max_steps: 1000,
    };

    /// Steps of a run at `dt`.
    pub fn steps(self, dt: f64) -> usize {
        ((self.seconds / dt).round() as usize).clamp(1, self.max_steps)
    }
}

/// The tail over which the mean height and the swing are measured: the
/// last this many seconds of a run that lasts at least five times as long,
/// else its last fifth.
pub const TAIL_SECONDS: f64 = 2.0;

/// How far the exact reference's check starts from it: one vertex in the
/// middle of the cloth moved this far (m) across the sheet.
pub const NUDGE: f32 = 1e-5;

/// The window closes at the first step at which the reference and its
/// check are further apart than this (root-mean-square, relative to the
/// drop).
pub const WINDOW: f64 = 0.05;

/// Tolerance of the position measures (pointwise, mean height, swing),
/// relative to the drop, before the floor.
pub const POSITION_TOLERANCE: f64 = 0.1;

/// Tolerance of the share of flagged steps, before the floor.
pub const FLAGGED_TOLERANCE: f64 = 0.05;

/// The scenes of the long runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scene {
    /// The lab cloth, pinned at two corners, falls from flat and hangs.
    Hanging,
    /// It falls onto the lab's sphere and comes to rest draped on it.
    OntoSphere,
    /// It starts at rest draped on the sphere and should stay there.
    Draped,
}

impl Scene {
    /// All three, in the map's order.
    pub const ALL: [Self; 3] = [Self::Hanging, Self::OntoSphere, Self::Draped];

    /// The scene's title on the map.
    pub fn title(self) -> &'static str {
        match self {
            Self::Hanging => "Hanging free",
            Self::OntoSphere => "Falling onto the sphere",
            Self::Draped => "Draped on the sphere, at rest",
        }
    }
}

/// The lab's sphere (radius 2.7 at (0, −4, 4)), projected, frictionless.
fn lab_sphere() -> Shape {
    Shape::Capsule(Capsule {
        a: Vec3A::new(0.0, -4.0, 4.0),
        b: Vec3A::new(0.0, -4.0, 4.0),
        radius: 2.7,
        friction: 0.0,
    })
}

/// Where the draped scene starts for stiffness `k`: the lab cloth after
/// falling onto the sphere with the exact method at 60 Hz and damping 0.9
/// per step for `seconds` (the map's: [`SETTLE_SECONDS`]), its velocities
/// zeroed.
pub fn draped_start(k: f32, seconds: f64) -> ClothState {
    let dt = 1.0 / 60.0;
    let steps = (seconds / dt).round().max(1.0) as usize;
    let mut s = Scenario::grid(21, k, dt).with_steps(steps);
    s.params.damping = 0.9;
    s.contacts.push(lab_sphere());
    let mut state = run(&s, &AnyMethod::Exact(ExactSolver::REFERENCE)).state;
    state.velocities.iter_mut().for_each(|v| *v = Vec3A::ZERO);
    state
}

/// The long run of `scene` at stiffness `k` and step `dt`, recorded after
/// every step; `draped` is [`draped_start`]`(k)` for [`Scene::Draped`].
pub fn scenario(
    scene: Scene,
    k: f32,
    dt: f64,
    length: Length,
    draped: Option<&ClothState>,
) -> Scenario {
    let mut s = Scenario::grid(21, k, dt)
        .named(format!("{} k={k:e} dt={dt}", scene.title()))
        .with_steps(length.steps(dt))
        .recorded();
    // The lab's 441 kg on springs of 10–100 N/m stretch past ten times
    // their length within ten seconds, the exact method's too: the guard
    // judges them by their load alone (its `load_factor`), as a game's
    // does, so that those cells are judged rather than all caught.
    s.bounds.max_stretch = None;
    if scene != Scene::Hanging {
        s.contacts.push(lab_sphere());
    }
    if scene == Scene::Draped {
        s.start = draped.cloned();
    }
    s
}

/// The scenario started with the middle vertex moved by [`NUDGE`].
fn nudged(scenario: &Scenario) -> Scenario {
    let mut s = scenario.clone();
    let mut start = s
        .start
        .take()
        .unwrap_or_else(|| ClothState::at_rest(&s.model, &Affine3A::IDENTITY));
    let mid = start.positions.len() / 2;
    if let Some(p) = start.positions.get_mut(mid) {
        p.x += NUDGE;
    }
    s.start = Some(start);
    s
}

/// The measures of one run against a reference: see the [module docs](self).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Errors {
    /// Largest root-mean-square distance inside the window, over the drop.
    pub pointwise: f64,
    /// Mean height over the tail, difference over the drop.
    pub mean: f64,
    /// Swing (half the range of the mean height) over the tail, difference
    /// over the drop.
    pub swing: f64,
    /// Max stretch over the run, difference.
    pub stretch: f64,
    /// Share of steps flagged, difference (the run's minus the reference's,
    /// at least 0).
    pub flagged: f64,
}

/// A reference, its check and what they give: the window, the drop and the
/// floor.
#[derive(Clone, Debug)]
pub struct Reference {
    /// The reference's run (recorded at the case's steps).
    pub run: Run,
    /// Samples of the window (leading steps where the check agrees).
    pub window: usize,
    /// The drop that distances are divided by.
    pub drop: f64,
    /// The check against the reference: the floor of every measure.
    pub floor: Errors,
    /// True if the reference or its check was stopped by the guard.
    pub broken: bool,
}

fn rms(a: &[Vec3A], b: &[Vec3A]) -> f64 {
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(p, q)| f64::from((*p - *q).length_squared()))
        .sum();
    (sum / a.len().max(1) as f64).sqrt()
}

/// Samples in the tail (see [`TAIL_SECONDS`]).
fn tail(samples: usize, dt: f64) -> usize {
    let n = if samples as f64 * dt >= 5.0 * TAIL_SECONDS - 1e-9 {
        (TAIL_SECONDS / dt).round() as usize
    } else {
        samples / 5
    };
    n.clamp(1, samples.max(1))
}

/// Mean and half the range of the mean height over the tail.
fn mean_and_swing(run: &Run, dt: f64) -> (f64, f64) {
    let n = tail(run.samples.len(), dt);
    let heights: Vec<f64> = run.samples[run.samples.len().saturating_sub(n)..]
        .iter()
        .map(|s| s.mean_height())
        .collect();
    let mean = heights.iter().sum::<f64>() / heights.len().max(1) as f64;
    let (lo, hi) = heights
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
            (lo.min(h), hi.max(h))
        });
    (mean, if hi >= lo { 0.5 * (hi - lo) } else { 0.0 })
}

fn max_stretch_over(run: &Run) -> f64 {
    run.samples
        .iter()
        .map(|s| f64::from(s.stretch))
        .fold(0.0, f64::max)
}

fn flagged_share(run: &Run) -> f64 {
    run.unconverged_steps as f64 / run.steps.max(1) as f64
}

/// The measures of `run` against `reference` over the first `window`
/// samples and the tail; `drop` divides distances and heights.
fn errors(run: &Run, reference: &Run, window: usize, drop: f64, dt: f64) -> Errors {
    let pointwise = run
        .samples
        .iter()
        .zip(&reference.samples)
        .take(window)
        .map(|(a, b)| rms(&a.positions, &b.positions))
        .fold(0.0, f64::max)
        / drop;
    let (mean, swing) = mean_and_swing(run, dt);
    let (ref_mean, ref_swing) = mean_and_swing(reference, dt);
    Errors {
        pointwise,
        mean: (mean - ref_mean).abs() / drop,
        swing: (swing - ref_swing).abs() / drop,
        stretch: (max_stretch_over(run) - max_stretch_over(reference)).abs(),
        flagged: (flagged_share(run) - flagged_share(reference)).max(0.0),
    }
}

impl Reference {
    /// The reference `run` with its `check`, on `scenario` at its step `dt`.
    pub fn new(scenario: &Scenario, run: Run, check: &Run, dt: f64) -> Self {
        let broken = run.caught.is_some()
            || run.failed.is_some()
            || check.caught.is_some()
            || check.failed.is_some();
        let flat = scenario
            .model
            .topology()
            .rest_positions()
            .iter()
            .map(|p| f64::from(p.y))
            .fold(f64::INFINITY, f64::min);
        let size = extent(&scenario.model);
        let lowest = run
            .samples
            .last()
            .map(|s| {
                s.positions
                    .iter()
                    .map(|p| f64::from(p.y))
                    .fold(f64::INFINITY, f64::min)
            })
            .unwrap_or(flat);
        let drop = (lowest - flat).abs().max(0.01 * size);
        let window = run
            .samples
            .iter()
            .zip(&check.samples)
            .take_while(|(a, b)| rms(&a.positions, &b.positions) / drop <= WINDOW)
            .count();
        let floor = errors(check, &run, window, drop, dt);
        Self {
            run,
            window,
            drop,
            floor,
            broken,
        }
    }

    /// The exact reference at the scenario's step (for PBD, at `k = 1e6`
    /// per unit mass), and its nudged check.
    pub fn exact(scenario: &Scenario, method: &AnyMethod) -> Self {
        let reference = reference_for(scenario, method);
        let check = reference_for(&nudged(scenario), method);
        Self::new(scenario, reference, &check, scenario.params.dt)
    }

    /// The physical reference: the exact method at the scenario's step split
    /// to at most [`PHYSICAL_STEP`](crate::scenarios::PHYSICAL_STEP), checked
    /// against the same at twice that step (at half of it if the split is 1).
    pub fn physical(scenario: &Scenario) -> Self {
        let exact = AnyMethod::Exact(ExactSolver::REFERENCE);
        let m = scenario.physical_split();
        let reference = run(&scenario.refined(m), &exact);
        let check_split = if m >= 2 { m / 2 } else { 2 };
        let check = run(&scenario.refined(check_split), &exact);
        Self::new(scenario, reference, &check, scenario.params.dt)
    }

    /// The reference's step count per sample is the scenario's: how many
    /// simulated seconds its window spans.
    pub fn window_seconds(&self, dt: f64) -> f64 {
        self.window as f64 * dt
    }

    /// Judges `run` of `method` against this reference.
    pub fn judge(&self, scenario: &Scenario, method: &AnyMethod, run: Run) -> Judged {
        let dt = scenario.params.dt;
        let e = errors(&run, &self.run, self.window, self.drop, dt);
        let f = self.floor;
        let stretch_tolerance = 0.02 + 0.1 * max_stretch_over(&self.run) + f.stretch;
        let mut misses = Vec::new();
        for (name, value, floor) in [
            ("pt", e.pointwise, f.pointwise),
            ("mean", e.mean, f.mean),
            ("swing", e.swing, f.swing),
        ] {
            if value > POSITION_TOLERANCE + floor {
                misses.push(format!("{name} {value:.2}"));
            }
        }
        if e.stretch > stretch_tolerance {
            misses.push(format!("str {:+.3}", e.stretch));
        }
        if e.flagged > FLAGGED_TOLERANCE + f.flagged {
            misses.push(format!("⚑ {:.0} %", 100.0 * flagged_share(&run)));
        }
        let verdict = if let Some(why) = &run.failed {
            Verdict::Failed(why.clone())
        } else if let Some((step, reason)) = run.caught {
            Verdict::Caught { step, reason }
        } else if self.broken {
            Verdict::NoReference
        } else if misses.is_empty() {
            Verdict::Correct
        } else {
            Verdict::Wrong {
                lowest: (e.pointwise - f.pointwise)
                    .max(e.mean - f.mean)
                    .max(e.swing - f.swing)
                    .max(0.0),
                stretch: e.stretch,
            }
        };
        Judged {
            outcome: Outcome {
                method: crate::variant(method),
                verdict,
                max_stretch: max_stretch_over(&run) as f32,
                floor: Some(Floor {
                    lowest: f.pointwise.max(f.mean).max(f.swing),
                    stretch: f.stretch,
                }),
                run: Run {
                    samples: Vec::new(),
                    ..run.clone()
                },
            },
            errors: e,
            flagged: flagged_share(&run),
            misses,
        }
    }
}

/// One long run judged.
#[derive(Clone, Debug)]
pub struct Judged {
    /// The verdict and the run (its samples dropped).
    pub outcome: Outcome,
    /// Its measures against the reference.
    pub errors: Errors,
    /// Its share of steps flagged as not converged.
    pub flagged: f64,
    /// The measures beyond their tolerances, as text.
    pub misses: Vec<String>,
}

impl Judged {
    /// The verdict's text: `✓` (with the share of steps flagged, if any),
    /// or what missed and by how much.
    pub fn text(&self) -> String {
        match &self.outcome.verdict {
            Verdict::Correct if self.flagged > 0.0 => {
                format!("✓ ⚑ {:.0} %", 100.0 * self.flagged)
            }
            Verdict::Correct => "✓".to_owned(),
            Verdict::Wrong { .. } => format!("wrong ({})", self.misses.join(", ")),
            Verdict::Caught { step, reason } => format!("caught @{step} {reason:?}"),
            Verdict::Failed(why) => format!("FAILED: {why}"),
            Verdict::NoReference => "no ref".to_owned(),
        }
    }
}

/// One cell of a scene: every method judged, and the exact method at the
/// case's step judged against the physical reference.
#[derive(Clone, Debug)]
pub struct Cell {
    /// Stiffness.
    pub k: f32,
    /// Time step.
    pub dt: f64,
    /// Steps run.
    pub steps: usize,
    /// Per method of [`map_methods`], in order.
    pub judged: Vec<Judged>,
    /// The exact method at the case's step against the physical reference.
    pub exact_vs_physical: Judged,
    /// The exact reference's window, in seconds.
    pub exact_window: f64,
    /// The physical reference's window, in seconds.
    pub physical_window: f64,
    /// The physical reference's floors.
    pub physical_floor: Errors,
}

/// Runs and judges every method of [`map_methods`] on one cell.
pub fn cell(scene: Scene, k: f32, dt: f64, length: Length, draped: Option<&ClothState>) -> Cell {
    let scenario = scenario(scene, k, dt, length, draped);
    let methods = map_methods();
    let exact = AnyMethod::Exact(ExactSolver::REFERENCE);
    let exact_ref = Reference::exact(&scenario, &exact);
    let physical = Reference::physical(&scenario);
    let mut stiff_ref: Option<Reference> = None;
    let judged = methods
        .iter()
        .map(|m| {
            let run_m = if *m == exact {
                exact_ref.run.clone()
            } else {
                run(&scenario, m)
            };
            if judged_physically(&scenario, m) {
                physical.judge(&scenario, m, run_m)
            } else if matches!(m, AnyMethod::Pbd(_)) {
                stiff_ref
                    .get_or_insert_with(|| Reference::exact(&scenario, m))
                    .judge(&scenario, m, run_m)
            } else {
                exact_ref.judge(&scenario, m, run_m)
            }
        })
        .collect();
    let exact_vs_physical = physical.judge(&scenario, &exact, exact_ref.run.clone());
    Cell {
        k,
        dt,
        steps: scenario.steps,
        judged,
        exact_vs_physical,
        exact_window: exact_ref.window_seconds(dt),
        physical_window: physical.window_seconds(dt),
        physical_floor: physical.floor,
    }
}
