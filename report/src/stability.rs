//! The stability map: every method × stiffness × time step on the lab
//! cloth, every iterative method × resolution, and the extreme cases, each
//! classified as in [`stability`](crate::stability). Written as
//! `stability.md` and `stability.svg`.
//!
//! ```text
//! cargo run --release -p bevy_cloth_report -- --stability
//! ```

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use bevy::math::Affine3A;
use indicatif::ProgressBar;
use plotters::prelude::*;

use rayon::prelude::*;

pub use crate::contact::ContactSizes;
use crate::contact_map::contact_section;
pub use crate::contact_map::rerun_contact;
use crate::long_run::{self as long, Cell, Judged, Length, Scene, draped_start};
use crate::scenarios::{
    Outcome, Scenario, Verdict, explicit_limit, map_methods, measured_explicit_limit, sweep,
};
use bevy_cloth::methods::AnyMethod;
use bevy_cloth::model::ClothState;
use bevy_cloth::solver::exact::ExactSolver;
use bevy_cloth::solver::{CONVERGENCE_TOLERANCE, StepParams};

/// What the stability map sweeps.
#[derive(Clone, Debug)]
pub struct StabilityConfig {
    /// Output folder.
    pub out_dir: PathBuf,
    /// Stiffnesses of the long runs.
    pub stiffnesses: Vec<f32>,
    /// Time steps of the long runs.
    pub time_steps: Vec<f64>,
    /// How long each long run is.
    pub length: Length,
    /// How long the draped scene's start settles (see
    /// [`draped_start`]).
    pub settle_seconds: f64,
    /// Grid sides of the resolution sweep (iterative methods, lab k and dt).
    pub resolutions: Vec<usize>,
    /// Side of the large extreme case; `None` leaves the extreme cases out.
    pub large: Option<usize>,
    /// The contact cases' sizes; `None` leaves them out.
    pub contact: Option<ContactSizes>,
    /// Step counts over which the explicit limit is measured.
    pub limit_steps: Vec<usize>,
    /// Show progress.
    pub progress: bool,
}

impl StabilityConfig {
    /// The committed map: k from 1e1 to 1e8, dt from 1e-4 to 0.1 s (with a
    /// game's 60 Hz and the lab's 30 Hz), ten seconds per run in each of the
    /// three scenes, resolutions 11 to 101, the extreme cases with a 301×301
    /// cloth.
    pub fn full(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            stiffnesses: vec![1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8],
            time_steps: vec![1e-4, 1e-3, 1e-2, 1.0 / 60.0, 0.0333, 0.1],
            length: Length::MAP,
            settle_seconds: long::SETTLE_SECONDS,
            resolutions: vec![11, 21, 51, 101],
            large: Some(301),
            contact: Some(ContactSizes::FULL),
            limit_steps: vec![300, 1000, 3000],
            progress: true,
        }
    }

    /// A tiny map for tests.
    pub fn tiny(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            stiffnesses: vec![1e2, 1e6],
            time_steps: vec![1e-2, 0.1],
            length: Length {
                seconds: 0.3,
                max_steps: 20,
            },
            settle_seconds: 0.3,
            resolutions: vec![6],
            large: None,
            contact: Some(ContactSizes::TINY),
            limit_steps: vec![50],
            progress: false,
        }
    }
}

const CLASSES: [(&str, RGBColor); 5] = [
    ("correct", RGBColor(46, 160, 67)),
    ("wrong", RGBColor(240, 170, 40)),
    ("caught", RGBColor(70, 120, 220)),
    ("failed", RGBColor(210, 40, 40)),
    ("no reference", RGBColor(170, 170, 170)),
];

fn color(v: &Verdict) -> RGBColor {
    CLASSES
        .iter()
        .find(|(c, _)| *c == v.class())
        .map_or(BLACK, |&(_, c)| c)
}

/// A cell's text: the class and, for wrong and caught, by how much or when.
fn cell(o: &Outcome) -> String {
    let text = verdict_text(o);
    if o.run.flagged() {
        format!("{text} ⚑")
    } else {
        text
    }
}

fn verdict_text(o: &Outcome) -> String {
    match &o.verdict {
        Verdict::Correct => "✓".into(),
        Verdict::Wrong { lowest, stretch } => format!("wrong (low {lowest:.2}, str {stretch:.2})"),
        Verdict::Caught { step, reason } => format!("caught @{step} {reason:?}"),
        Verdict::Failed(why) => format!("FAILED: {why}"),
        Verdict::NoReference => "no ref".into(),
    }
}

/// The "Convergence" section: for every method that reports a relative
/// error, how the plugin's not-converged flag (⚑, some step beyond
/// [`CONVERGENCE_TOLERANCE`]) agrees with the lab sweep's verdicts.
fn convergence_section(
    md: &mut String,
    labels: &[String],
    config: &StabilityConfig,
    grid: &[Vec<Vec<Outcome>>],
) {
    writeln!(
        md,
        "## Convergence\n\n⚑ marks a run in which some step's estimated error exceeded {:.0} % of its \
         motion (`CONVERGENCE_TOLERANCE`): the plugin sets `ClothStats::converged = false` and sends \
         `ClothNotConverged`. Per method, over the hanging scene above: the flag against the verdict, and \
         the largest relative error of any step in the runs of each kind.\n",
        100.0 * CONVERGENCE_TOLERANCE
    )
    .ok();
    writeln!(
        md,
        "| method | wrong, flagged | wrong, not flagged | ✓, flagged | ✓, not flagged | largest error in ✓ runs | smallest largest error in wrong runs |"
    )
    .ok();
    writeln!(md, "|---|---|---|---|---|---|---|").ok();
    let mut misses = Vec::new();
    for (m, label) in labels.iter().enumerate() {
        let outcomes: Vec<(usize, usize, &Outcome)> = grid
            .iter()
            .enumerate()
            .flat_map(|(i, row)| row.iter().enumerate().map(move |(j, o)| (i, j, &o[m])))
            .filter(|(_, _, o)| o.run.max_relative_error.is_some())
            .collect();
        if outcomes.is_empty() {
            continue;
        }
        let mut counts = [0usize; 4];
        let (mut worst_correct, mut best_wrong) = (0.0f32, f32::INFINITY);
        for &(i, j, o) in &outcomes {
            let e = o.run.max_relative_error.unwrap_or(0.0);
            let wrong = matches!(o.verdict, Verdict::Wrong { .. });
            let correct = o.verdict == Verdict::Correct;
            let slot = match (wrong, correct, o.run.flagged()) {
                (true, _, true) => 0,
                (true, _, false) => 1,
                (_, true, true) => 2,
                (_, true, false) => 3,
                _ => continue,
            };
            counts[slot] += 1;
            if correct {
                worst_correct = worst_correct.max(e);
            } else {
                best_wrong = best_wrong.min(e);
            }
            if slot == 1 || slot == 2 {
                misses.push(format!(
                    "{label} at k = {:e}, dt = {}: {} with largest error {e:.3}",
                    config.stiffnesses[i],
                    step_label(config.time_steps[j]),
                    verdict_text(o)
                ));
            }
        }
        writeln!(
            md,
            "| {label} | {} | {} | {} | {} | {worst_correct:.3} | {} |",
            counts[0],
            counts[1],
            counts[2],
            counts[3],
            if best_wrong.is_finite() {
                format!("{best_wrong:.3}")
            } else {
                "–".into()
            }
        )
        .ok();
    }
    if misses.is_empty() {
        writeln!(md, "\nThe flag and the verdicts agree on every cell.\n").ok();
    } else {
        writeln!(md, "\nWhere they disagree:\n").ok();
        for miss in misses {
            writeln!(md, "- {miss}").ok();
        }
        writeln!(
            md,
            "\nA verdict judges the whole run against the exact one, the flag one step at a time: \
             a small error that repeats in the same direction for hundreds of steps (momentum lost \
             every step) can make a run wrong without any step crossing the tolerance, and a run \
             flagged on a few steps (at most 5 % more than its reference) can still be right.\n"
        )
        .ok();
    }
}

/// A scene's section: the windows and floors of its references per cell,
/// then per method its grid of verdicts (folded).
fn scene_section(
    md: &mut String,
    labels: &[String],
    config: &StabilityConfig,
    scene: Scene,
    cells: &[Vec<Cell>],
) {
    let slug = scene_slug(scene);
    writeln!(
        md,
        "## {}\n\n![{}]({})\n\n{}\n",
        scene.title(),
        scene.title(),
        svg_name(scene),
        scene_text(scene)
    )
    .ok();
    writeln!(
        md,
        "The references per cell: how long each agrees with its check (the window, in \
         simulated seconds; exact / physical), and the physical reference's floors (pointwise, \
         mean height, swing; relative to the drop).\n"
    )
    .ok();
    header(md, config);
    for (i, k) in config.stiffnesses.iter().enumerate() {
        write!(md, "| {k:e} |").ok();
        for c in &cells[i] {
            let f = c.physical_floor;
            write!(
                md,
                " {:.1} / {:.1} s; {:.3}, {:.3}, {:.3} |",
                c.exact_window, c.physical_window, f.pointwise, f.mean, f.swing
            )
            .ok();
        }
        writeln!(md).ok();
    }
    writeln!(md, "\n<details><summary>Per method ({slug})</summary>\n").ok();
    for (label, m) in rows(labels) {
        writeln!(md, "\n#### {label} ({slug})\n").ok();
        header(md, config);
        for (i, k) in config.stiffnesses.iter().enumerate() {
            write!(md, "| {k:e} |").ok();
            for c in &cells[i] {
                write!(md, " {} |", judged(c, m).text()).ok();
            }
            writeln!(md).ok();
        }
    }
    writeln!(md, "\n</details>\n").ok();
}

fn header(md: &mut String, config: &StabilityConfig) {
    write!(md, "| k \\ dt |").ok();
    for dt in &config.time_steps {
        write!(md, " {} |", step_label(*dt)).ok();
    }
    writeln!(md, "\n|---|{}", "---|".repeat(config.time_steps.len())).ok();
}

fn scene_slug(scene: Scene) -> &'static str {
    match scene {
        Scene::Hanging => "hanging",
        Scene::OntoSphere => "onto the sphere",
        Scene::Draped => "draped",
    }
}

fn svg_name(scene: Scene) -> &'static str {
    match scene {
        Scene::Hanging => "stability.svg",
        Scene::OntoSphere => "stability-onto-sphere.svg",
        Scene::Draped => "stability-draped.svg",
    }
}

fn scene_text(scene: Scene) -> &'static str {
    match scene {
        Scene::Hanging => {
            "The lab cloth (21×21, 1 kg per vertex, pinned at two corners) falls from flat and \
             swings until it hangs still."
        }
        Scene::OntoSphere => {
            "The lab cloth falls onto the lab's sphere (radius 2.7 at (0, −4, 4), projected \
             after every step as the plugin does, frictionless; `stiff` also projects it inside \
             its substeps) and comes to rest draped on it."
        }
        Scene::Draped => {
            "The lab cloth starts at rest draped on the sphere (the exact method's state after \
             sixty seconds onto the sphere at 60 Hz with damping 0.9 per step, when it moves \
             less than a millimetre in ten more; its velocities zeroed) and should stay there."
        }
    }
}

/// The rows of a scene's tables: each method (by its index in
/// [`Cell::judged`]), then the exact method against the physical reference
/// (`None`).
fn rows(labels: &[String]) -> impl Iterator<Item = (String, Option<usize>)> + '_ {
    labels
        .iter()
        .enumerate()
        .map(|(m, l)| (l.clone(), Some(m)))
        .chain([("exact, against the physical reference".to_owned(), None)])
}

/// Row `m` of [`rows`] in `cell`.
fn judged(cell: &Cell, m: Option<usize>) -> &Judged {
    m.map_or(&cell.exact_vs_physical, |m| &cell.judged[m])
}

/// The summary: per scene and method, how many cells are right.
fn summary(md: &mut String, labels: &[String], scenes: &[(Scene, Vec<Vec<Cell>>)]) {
    writeln!(md, "## Summary\n\nCells right (✓) of each scene's grid:\n").ok();
    write!(md, "| method |").ok();
    for (scene, _) in scenes {
        write!(md, " {} |", scene.title()).ok();
    }
    writeln!(md, "\n|---|{}", "---|".repeat(scenes.len())).ok();
    let count = |cells: &Vec<Vec<Cell>>, m: Option<usize>| {
        let all: Vec<&Judged> = cells.iter().flatten().map(|c| judged(c, m)).collect();
        let right = all
            .iter()
            .filter(|j| j.outcome.verdict == Verdict::Correct)
            .count();
        format!("{right}/{}", all.len())
    };
    for (label, m) in rows(labels) {
        write!(md, "| {label} |").ok();
        for (_, cells) in scenes {
            write!(md, " {} |", count(cells, m)).ok();
        }
        writeln!(md).ok();
    }
    writeln!(md).ok();
}

/// The map's column labels.
pub(crate) fn labels() -> Vec<String> {
    map_methods().iter().map(crate::variant).collect()
}

/// A time step as the map prints it: `1/60` for a game's 60 Hz, else the
/// number.
fn step_label(dt: f64) -> String {
    if (dt - 1.0 / 60.0).abs() < 1e-12 {
        "1/60".into()
    } else {
        format!("{dt}")
    }
}

/// Runs the map and writes `stability.md` and `stability.svg`. Returns the
/// markdown.
pub fn run(config: &StabilityConfig) -> std::io::Result<String> {
    std::fs::create_dir_all(&config.out_dir)?;
    crate::chart::register_chart_font();
    let methods = map_methods();
    let labels = labels();
    let long_cells = Scene::ALL.len() * config.stiffnesses.len() * config.time_steps.len();
    let total = long_cells
        + config.resolutions.len()
        + config.large.map_or(0, |n| Scenario::extreme_cases(n).len())
        + config.contact.map_or(0, |c| c.cases().len() + 1);
    let bar = if config.progress {
        ProgressBar::new(total as u64)
    } else {
        ProgressBar::hidden()
    };
    let started = Instant::now();
    let mut md = String::new();

    // 1. The long runs: three scenes × stiffness × time step, lab cloth
    // 21×21, every cell on its own (in parallel; each is deterministic).
    let draped: Vec<ClothState> = config
        .stiffnesses
        .par_iter()
        .map(|&k| draped_start(k, config.settle_seconds))
        .collect();
    let jobs: Vec<(Scene, usize, usize)> = Scene::ALL
        .iter()
        .flat_map(|&scene| {
            (0..config.stiffnesses.len())
                .flat_map(move |i| (0..config.time_steps.len()).map(move |j| (scene, i, j)))
        })
        .collect();
    let mut done: Vec<Cell> = jobs
        .par_iter()
        .map(|&(scene, i, j)| {
            let (k, dt) = (config.stiffnesses[i], config.time_steps[j]);
            let start = (scene == Scene::Draped).then(|| &draped[i]);
            let c = long::cell(scene, k, dt, config.length, start);
            bar.inc(1);
            c
        })
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    let scenes: Vec<(Scene, Vec<Vec<Cell>>)> = Scene::ALL
        .iter()
        .map(|&scene| {
            let rows = (0..config.stiffnesses.len())
                .map(|_| {
                    (0..config.time_steps.len())
                        .map(|_| done.pop().expect("one cell per job"))
                        .collect()
                })
                .collect();
            (scene, rows)
        })
        .collect();
    summary(&mut md, &labels, &scenes);
    for (scene, cells) in &scenes {
        scene_section(&mut md, &labels, config, *scene, cells);
        let grid: Vec<Vec<Vec<Outcome>>> = cells
            .iter()
            .map(|row| {
                row.iter()
                    .map(|c| c.judged.iter().map(|j| j.outcome.clone()).collect())
                    .collect()
            })
            .collect();
        chart(
            &config.out_dir.join(svg_name(*scene)),
            &format!(
                "{}, lab cloth 21×21 (rows: stiffness k; columns: time step dt in s):",
                scene.title()
            ),
            &labels,
            &config.stiffnesses,
            &config.time_steps,
            &grid,
        )
        .map_err(std::io::Error::other)?;
        if *scene == Scene::Hanging {
            convergence_section(&mut md, &labels, config, &grid);
        }
    }

    // 2. Resolution, iterative methods and Newton on a budget, lab k and dt,
    // mass 1 per vertex.
    let iterative: Vec<AnyMethod> = methods
        .iter()
        .copied()
        .filter(|m| {
            matches!(
                m,
                AnyMethod::Implicit(_) | AnyMethod::Projective(_) | AnyMethod::Pbd(_)
            ) || *m == AnyMethod::Exact(ExactSolver::BUDGET)
        })
        .collect();
    writeln!(
        md,
        "## Resolution (k = 8000, dt = 0.0333, mass 1 per vertex: heavier as n grows)\n"
    )
    .ok();
    write!(md, "| n |").ok();
    for m in &iterative {
        write!(md, " {} |", crate::variant(m)).ok();
    }
    writeln!(md, "\n|---|{}", "---|".repeat(iterative.len())).ok();
    for &n in &config.resolutions {
        bar.set_message(format!("{n}×{n}"));
        let outcomes = sweep(&Scenario::grid(n, 8000.0, StepParams::LAB.dt), &iterative);
        write!(md, "| {n}×{n} |").ok();
        for o in &outcomes {
            write!(md, " {} |", cell(o)).ok();
        }
        writeln!(md).ok();
        bar.inc(1);
    }

    // 3. The extreme cases.
    writeln!(md, "\n## Extreme cases (every method)\n").ok();
    writeln!(
        md,
        "Lab cloth at k = 8000, dt = 0.0333 unless named; `rise` is the largest energy above \
         the starting energy seen after any step.\n"
    )
    .ok();
    write!(md, "| case |").ok();
    for l in &labels {
        write!(md, " {l} |").ok();
    }
    writeln!(md, "\n|---|{}", "---|".repeat(labels.len())).ok();
    for scenario in config.large.map_or_else(Vec::new, Scenario::extreme_cases) {
        bar.set_message(scenario.name.clone());
        let outcomes = sweep(&scenario, &methods);
        write!(md, "| {} |", scenario.name).ok();
        for o in &outcomes {
            write!(md, " {}; rise {:.1e} |", cell(o), o.run.energy_rise).ok();
        }
        writeln!(md).ok();
        bar.inc(1);
    }

    // 3b. The contact cases, judged without a reference.
    if let Some(sizes) = config.contact {
        contact_section(&mut md, sizes, &bar, |_| None);
    }

    // 4. The explicit limit.
    let mut lab = Scenario::lab(8000.0, StepParams::LAB.dt);
    lab.params.damping = 1.0;
    let rest = ClothState::at_rest(&lab.model, &Affine3A::IDENTITY);
    let predicted = explicit_limit(&lab.model, &rest.positions, &lab.params.stiffness);
    writeln!(
        md,
        "\n## Symplectic Euler's step limit on the lab cloth\n\n\
         `2/ω_max` with `ω_max²` the largest eigenvalue of `M⁻¹K` at the rest shape (power \
         iteration, 500 products): **{predicted:.5} s**. Measured largest stable step (bisection \
         to 0.1 %, no damping, stable = inside the guard's bounds for N steps from rest):\n\n\
         | N steps | measured | measured / predicted |\n|---|---|---|"
    )
    .ok();
    for &steps in &config.limit_steps {
        let measured = measured_explicit_limit(&lab, 1e-4, 0.1, steps, 1e-3);
        writeln!(
            md,
            "| {steps} | {measured:.5} s | {:.3} |",
            measured / predicted
        )
        .ok();
    }
    writeln!(
        md,
        "\nThe longer the run, the lower the measured limit: as the cloth sags its springs \
         stretch and the tangential stiffness `k(1 − L/l)` raises `ω_max` a little above its \
         value at rest."
    )
    .ok();
    bar.finish_and_clear();
    let mut head = String::new();
    writeln!(head, "# Stability map\n").ok();
    writeln!(
        head,
        "Generated by `cargo run --release -p bevy_cloth_report -- --stability` on {} in {:.0} s \
         (see [the report](README.md) for error against run time).\n\n\
         ## How a cell is judged\n\n\
         Every method runs on the lab cloth (21×21, 1 kg per vertex: at 60 Hz `k·dt²/m` runs \
         from 2.8e-3 at k = 1e1 to 2.8e4 at k = 1e8, so the grid covers a game's cape masses) \
         under the divergence guard (pause policy, default bounds without the 10× cap: \
         stretch ≤ 0.5 + 10× the stretch the cloth's whole weight would give one spring, or \
         not growing; speed ≤ 10× a fall from the pins to the cloth's far end plus its size \
         per step and the sphere's own speed) \
         for {} s of simulated time, at most {} steps (so {} s at dt = 1e-4 and {} s at dt = 1e-3), \
         in three scenes: hanging free, falling onto the lab's sphere, and draped on it at rest. \
         A run is compared with its reference over the whole run (`long_run` in the report's \
         crate):\n\n\
         - **pointwise** (`pt`), inside the *window* where the reference agrees with its own check \
         to within {:.0} % of the drop: the largest root-mean-square distance of the vertices \
         from the reference's, relative to the drop (how far the reference's lowest point is \
         below the flat sheet's at the end, at least 1 % of the cloth's size);\n\
         - **mean height** (`mean`) and **swing** (`swing`, half the range of the cloth's mean \
         height) over the last {} s (the last fifth of a shorter run), relative to the drop;\n\
         - **max stretch** (`str`) over the whole run;\n\
         - **flagged** (⚑): the share of steps whose estimated error exceeds {:.0} % of their \
         motion (`CONVERGENCE_TOLERANCE`, what raises `ClothNotConverged`), measured as the \
         plugin measures it: after the sphere's projection, without what the projection undoes \
         (`ContactError`).\n\n\
         A hanging cloth without bending stiffness is chaotic: two runs that start 1e-5 m apart \
         part within seconds, so after the window only what chaos does not move is compared. \
         **Correct** (✓): each position measure within {:.2} of the reference's, the max \
         stretch within 0.02 + 10 % of the reference's, at most {:.0} % more steps flagged — each \
         tolerance plus the reference's *floor*, the same measure between the reference and its \
         check. **Wrong**: finite and inside the bounds but not close (the cell names the \
         measures that missed). **Caught**: the guard stopped it at step `@n` (`Stretch`, \
         `NonFinite` or `SolveFailed`). **Failed**: a panic, valid input refused, or a NaN that \
         passed the guard (never expected). A ✓ cell with ⚑ shows the share of its steps \
         flagged.\n\n\
         Two references:\n\n\
         - the **exact** implicit-Euler run at the case's step (Newton to a relative gradient \
         of 1e-9), which judges the specifications' methods; its check starts with the middle \
         vertex moved by 1e-5 m, so its floor is chaos alone. PBD has no stiffness, so its \
         reference is the exact run with `k = 1e6` per unit mass;\n\
         - the **physical** reference, which judges `stiff` (XPBD with small steps does not \
         solve implicit Euler, whose large steps damp stiff cloth; the physics is its target): \
         the exact method at the case's step split until it is at most 1/960 s (the lab's \
         damping per step spread so that it damps as much per second). Its check is the same at \
         twice that step (at half of it where the case's step is already that small): \
         implicit Euler's error is of first order, so what halving the reference's step would \
         still move is about half that floor. The row \"exact, against the physical \
         reference\" shows where implicit Euler at the case's step is itself physically \
         wrong.\n\n\
         Methods run at their interactive settings: 32 iterations (Jacobi, Chebyshev with the \
         lab's ρ = 0.995 or with ρ estimated, PBD), CG with 25 iterations, the linearly implicit \
         methods with compression-clamped and with exact (`exact K`) spring blocks, projective \
         dynamics with at most 10 Chebyshev iterations (stopping early at an estimated error of \
         1 % of the step's motion) or 20 Anderson iterations, Newton on a budget (`newton`: at \
         most 16 iterations to a relative gradient of 1e-5), `stiff` at its substep rate. The \
         resolution sweep and the extreme cases below judge one second (or the steps named) by \
         the final state against the exact run at the case's step: ✓ if the lowest point is \
         within 10 % of the drop (`low`) and the max stretch within 0.02 + 10 % of the exact \
         run's (`str`: the difference).\n",
        crate::chart::machine(),
        started.elapsed().as_secs_f64(),
        config.length.seconds,
        config.length.max_steps,
        (config.length.max_steps as f64 * 1e-4).min(config.length.seconds),
        (config.length.max_steps as f64 * 1e-3).min(config.length.seconds),
        100.0 * long::WINDOW,
        long::TAIL_SECONDS,
        100.0 * CONVERGENCE_TOLERANCE,
        long::POSITION_TOLERANCE,
        100.0 * long::FLAGGED_TOLERANCE,
    )
    .ok();
    let md = head + &md;
    std::fs::write(config.out_dir.join("stability.md"), &md)?;
    Ok(md)
}

/// One panel per method: stiffness (rows) × time step (columns), coloured
/// by class.
fn chart(
    path: &Path,
    title: &str,
    labels: &[String],
    stiffnesses: &[f32],
    time_steps: &[f64],
    grid: &[Vec<Vec<Outcome>>],
) -> Result<(), String> {
    let cols = 5;
    let rows = labels.len().div_ceil(cols);
    let root = SVGBackend::new(path, (1250, 300 * rows as u32 + 60)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (legend, body) = root.split_vertically(60);
    let mut x = 20;
    legend
        .draw_text(title, &("sans-serif", 18).into_text_style(&legend), (x, 8))
        .map_err(|e| e.to_string())?;
    for (name, c) in CLASSES {
        legend
            .draw(&Rectangle::new([(x, 34), (x + 16, 50)], c.filled()))
            .map_err(|e| e.to_string())?;
        legend
            .draw_text(
                name,
                &("sans-serif", 16).into_text_style(&legend),
                (x + 22, 34),
            )
            .map_err(|e| e.to_string())?;
        x += 150;
    }
    let panels = body.split_evenly((rows, cols));
    for (m, (panel, label)) in panels.iter().zip(labels).enumerate() {
        let mut chart = ChartBuilder::on(panel)
            .caption(label, ("sans-serif", 16))
            .margin(6)
            .x_label_area_size(28)
            .y_label_area_size(44)
            .build_cartesian_2d(
                -0.5..time_steps.len() as f64 - 0.5,
                -0.5..stiffnesses.len() as f64 - 0.5,
            )
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_labels(time_steps.len() + 1)
            .y_labels(stiffnesses.len() + 1)
            .x_label_formatter(&|v| cell_label(*v, time_steps, step_label))
            .y_label_formatter(&|v| cell_label(*v, stiffnesses, |k| format!("{k:e}")))
            .label_style(("sans-serif", 11))
            .draw()
            .map_err(|e| e.to_string())?;
        let mut cells = Vec::new();
        for (i, row) in grid.iter().enumerate() {
            for (j, outcomes) in row.iter().enumerate() {
                let c = color(&outcomes[m].verdict);
                let (x, y) = (j as f64, i as f64);
                let corners = [(x - 0.5, y - 0.5), (x + 0.5, y + 0.5)];
                cells.push(Rectangle::new(corners, c.filled()));
                cells.push(Rectangle::new(corners, WHITE.stroke_width(1)));
            }
        }
        chart.draw_series(cells).map_err(|e| e.to_string())?;
    }
    root.present().map_err(|e| e.to_string())?;
    Ok(())
}

/// The label of the cell centred at `v` (cells sit at whole numbers).
fn cell_label<T: Copy>(v: f64, values: &[T], text: impl Fn(T) -> String) -> String {
    let i = v.round();
    if (v - i).abs() > 1e-6 || i < 0.0 {
        return String::new();
    }
    values.get(i as usize).map_or(String::new(), |&t| text(t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_stability_map_runs_end_to_end_on_a_tiny_configuration() {
        let dir = std::env::temp_dir().join(format!("bevy_cloth_stability_{}", std::process::id()));
        let md = run(&StabilityConfig::tiny(&dir)).unwrap();
        for scene in Scene::ALL {
            let slug = scene_slug(scene);
            assert!(
                md.contains(&format!("#### chebyshev ({slug})\n"))
                    && md.contains(&format!("#### stiff ({slug})\n")),
                "{md}"
            );
            assert!(md.contains(&format!("## {}\n", scene.title())), "{md}");
            let svg = std::fs::read_to_string(dir.join(svg_name(scene))).unwrap();
            assert!(svg.contains("<rect") && svg.contains("symplectic"));
        }
        assert!(md.contains("| stiff | 4/4 | 4/4 | 4/4 |"), "{md}");
        assert!(md.contains("## Extreme cases"));
        assert!(md.contains("## Contact extreme cases"));
        assert!(md.contains("| 10² folded in 4, on the ground | "), "{md}");
        // The contact cases alone, written over their section: the same
        // page (every run is deterministic).
        let again = rerun_contact(&StabilityConfig::tiny(&dir), None).unwrap();
        assert_eq!(
            again,
            std::fs::read_to_string(dir.join("stability.md")).unwrap()
        );
        let strip = |page: &str| {
            page.lines()
                .filter(|l| !l.starts_with("Generated by"))
                .collect::<Vec<_>>()
                .join("\n")
        };
        assert_eq!(strip(&again), strip(&md));
        assert!(!md.contains("FAILED"), "{md}");
        // The two sheets' row (through the plugin), and `--only`: the row
        // named run again (to the same cells), the others kept as the page
        // has them, even when they differ from a run.
        let two = "| two 8² sheets on each other over a ball, 0.1 s | ";
        assert!(md.contains(two), "{md}");
        let folded = "| 10² folded in 4, on the ground |";
        let start = again.find(folded).unwrap();
        let end = start + again[start..].find('\n').unwrap();
        let edited = format!("{}{folded} kept |{}", &again[..start], &again[end..]);
        std::fs::write(dir.join("stability.md"), &edited).unwrap();
        let only = rerun_contact(&StabilityConfig::tiny(&dir), Some("two ")).unwrap();
        assert_eq!(only, edited);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
