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
    /// Stiffnesses of the lab sweep.
    pub stiffnesses: Vec<f32>,
    /// Time steps of the lab sweep.
    pub time_steps: Vec<f64>,
    /// Grid sides of the resolution sweep (iterative methods, lab k and dt).
    pub resolutions: Vec<usize>,
    /// Side of the large extreme case; `None` leaves the extreme cases out.
    pub large: Option<usize>,
    /// Step counts over which the explicit limit is measured.
    pub limit_steps: Vec<usize>,
    /// Stiffnesses of the sphere sweep (the cloth falling onto the lab's
    /// sphere and resting there).
    pub sphere_stiffnesses: Vec<f32>,
    /// Time steps of the sphere sweep.
    pub sphere_time_steps: Vec<f64>,
    /// Simulated seconds of each sphere run.
    pub sphere_seconds: f64,
    /// Show progress.
    pub progress: bool,
}

impl StabilityConfig {
    /// The committed map: k from 1e1 to 1e8, dt from 1e-4 to 0.1 s (with a
    /// game's 60 Hz and the lab's 30 Hz),
    /// resolutions 11 to 101, the extreme cases with a 301×301 cloth.
    pub fn full(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            stiffnesses: vec![1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8],
            time_steps: vec![1e-4, 1e-3, 1e-2, 1.0 / 60.0, 0.0333, 0.1],
            resolutions: vec![11, 21, 51, 101],
            large: Some(301),
            limit_steps: vec![300, 1000, 3000],
            sphere_stiffnesses: vec![1e4, 1e6, 1e8],
            sphere_time_steps: vec![1.0 / 60.0, 0.0333],
            sphere_seconds: 10.0,
            progress: true,
        }
    }

    /// A tiny map for tests.
    pub fn tiny(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            stiffnesses: vec![1e2, 1e6],
            time_steps: vec![1e-2, 0.1],
            resolutions: vec![6],
            large: None,
            limit_steps: vec![50],
            sphere_stiffnesses: vec![1e6],
            sphere_time_steps: vec![0.1],
            sphere_seconds: 1.0,
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
         `ClothNotConverged`. Per method, over the lab sweep above: the flag against the verdict, and \
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
            "\nA verdict judges the whole run against the exact one (at least 1 % of the cloth's \
             size, whatever the run's length), the flag one step at a time: a small error that \
             repeats in the same direction for hundreds of steps (momentum lost every step) can make \
             a run wrong without any step crossing the tolerance, and a large error on a very short \
             run can stay inside the map's floor.\n"
        )
        .ok();
    }
}

/// The sphere section: every method on the cloth that falls onto the lab's
/// sphere and rests there, per cell its verdict, its share of steps
/// flagged as not converged and its max stretch.
fn sphere_section(
    md: &mut String,
    labels: &[String],
    seconds: f64,
    cells: &[(f32, f64, usize, Vec<Outcome>)],
) {
    writeln!(
        md,
        "## Onto the sphere, and resting there ({seconds} s)\n\nThe lab cloth falls onto the \
         lab's sphere (radius 2.7 at (0, −4, 4), projected after every step as the plugin \
         does, frictionless; `stiff` also projects it inside every substep) and comes to rest \
         draped on it: {seconds} s of simulated time, judged at the end as above (against the \
         exact method with the same projection at the same step; `stiff` against the physical \
         reference). Per cell: the verdict, the share of steps the plugin flags as not \
         converged (methods with a convergence measure), the max stretch at the end, and for \
         `stiff` its reference's floor.\n"
    )
    .ok();
    write!(md, "| method |").ok();
    for (k, dt, _, _) in cells {
        write!(md, " k = {k:e}, dt = {} |", step_label(*dt)).ok();
    }
    writeln!(md, "\n|---|{}", "---|".repeat(cells.len())).ok();
    for (m, label) in labels.iter().enumerate() {
        write!(md, "| {label} |").ok();
        for (_, _, steps, outcomes) in cells {
            let o = &outcomes[m];
            let flagged = if o.run.max_relative_error.is_some() {
                format!(
                    "; ⚑ {:.0} %",
                    100.0 * o.run.unconverged_steps as f64 / (*steps).max(1) as f64
                )
            } else {
                String::new()
            };
            let floor = o.floor.map_or_else(String::new, |f| {
                format!("; floor low {:.2}, str {:.3}", f.lowest, f.stretch)
            });
            write!(
                md,
                " {}{flagged}; str {:.3}{floor} |",
                verdict_text(o),
                o.max_stretch
            )
            .ok();
        }
        writeln!(md).ok();
    }
    writeln!(md).ok();
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

/// The "Physical reference" section: per cell of the lab sweep, the floor
/// of the physical reference (how far it moves when its step is halved),
/// which the `stiff` verdicts allow for.
fn physical_section(
    md: &mut String,
    labels: &[String],
    config: &StabilityConfig,
    grid: &[Vec<Vec<Outcome>>],
) {
    let Some(m) = grid
        .first()
        .and_then(|row| row.first())
        .and_then(|o| o.iter().position(|o| o.floor.is_some()))
    else {
        return;
    };
    writeln!(
        md,
        "## Physical reference\n\n`{}` is judged against the exact method at the case's step \
         halved until it is at most 1/960 s. Its floor per cell: the lowest point (relative to \
         the drop) and the max stretch of that reference against the same at half its step, \
         after the whole run. Where the floor is large the trajectory is chaotic (a hanging \
         cloth without bending stiffness): two fine runs part, and the verdict allows for it.\n",
        labels[m]
    )
    .ok();
    write!(md, "| k \\ dt |").ok();
    for dt in &config.time_steps {
        write!(md, " {} |", step_label(*dt)).ok();
    }
    writeln!(md, "\n|---|{}", "---|".repeat(config.time_steps.len())).ok();
    for (i, k) in config.stiffnesses.iter().enumerate() {
        write!(md, "| {k:e} |").ok();
        for outcomes in &grid[i] {
            match outcomes[m].floor {
                Some(f) => write!(md, " low {:.3}, str {:.4} |", f.lowest, f.stretch).ok(),
                None => write!(md, " – |").ok(),
            };
        }
        writeln!(md).ok();
    }
    writeln!(md).ok();
}

/// Runs the map and writes `stability.md` and `stability.svg`. Returns the
/// markdown.
pub fn run(config: &StabilityConfig) -> std::io::Result<String> {
    std::fs::create_dir_all(&config.out_dir)?;
    crate::chart::register_chart_font();
    let methods = map_methods();
    let labels: Vec<String> = methods.iter().map(crate::variant).collect();
    let total = config.stiffnesses.len() * config.time_steps.len()
        + config.sphere_stiffnesses.len() * config.sphere_time_steps.len()
        + config.resolutions.len()
        + config.large.map_or(0, |n| Scenario::extreme_cases(n).len());
    let bar = if config.progress {
        ProgressBar::new(total as u64)
    } else {
        ProgressBar::hidden()
    };
    let started = Instant::now();
    let mut md = String::new();

    // 1. Method × stiffness × time step, lab cloth 21×21.
    let mut grid: Vec<Vec<Vec<Outcome>>> = Vec::new();
    for &k in &config.stiffnesses {
        let mut row = Vec::new();
        for &dt in &config.time_steps {
            bar.set_message(format!("k={k:e} dt={dt}"));
            row.push(sweep(&Scenario::lab(k, dt), &methods));
            bar.inc(1);
        }
        grid.push(row);
    }
    writeln!(md, "\n![stability map](stability.svg)\n").ok();
    writeln!(md, "## Lab cloth 21×21: stiffness × time step\n").ok();
    for (m, label) in labels.iter().enumerate() {
        writeln!(md, "### {label}\n").ok();
        write!(md, "| k \\ dt |").ok();
        for dt in &config.time_steps {
            write!(md, " {} |", step_label(*dt)).ok();
        }
        writeln!(md).ok();
        writeln!(md, "|---|{}", "---|".repeat(config.time_steps.len())).ok();
        for (i, k) in config.stiffnesses.iter().enumerate() {
            write!(md, "| {k:e} |").ok();
            for outcomes in &grid[i] {
                write!(md, " {} |", cell(&outcomes[m])).ok();
            }
            writeln!(md).ok();
        }
        writeln!(md).ok();
    }

    convergence_section(&mut md, &labels, config, &grid);
    physical_section(&mut md, &labels, config, &grid);

    // 1b. Onto the sphere, and resting there.
    let mut cells = Vec::new();
    for &k in &config.sphere_stiffnesses {
        for &dt in &config.sphere_time_steps {
            bar.set_message(format!("sphere k={k:e} dt={dt}"));
            let scenario = Scenario::on_sphere(k, dt, config.sphere_seconds);
            cells.push((k, dt, scenario.steps, sweep(&scenario, &methods)));
            bar.inc(1);
        }
    }
    sphere_section(&mut md, &labels, config.sphere_seconds, &cells);

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
         (see [the report](README.md) for error against run time). Each cell runs one method \
         from rest under the divergence guard (pause policy, default bounds: stretch ≤ 10, \
         or not growing) and compares the final state with the exact implicit-Euler run of the \
         same case (Newton to a relative gradient of 1e-9):\n\n\
         - **correct** (✓): the lowest point within 10 % of how far the exact run's lowest point \
         moved (at least 1 % of the cloth's size), the max stretch within 0.02 + 10 % of the exact \
         run's;\n\
         - **wrong**: finite and inside the bounds, but not close: `low` is the lowest point's \
         error relative to that drop, `str` the max-stretch difference;\n\
         - **caught**: the guard stopped it at step `@n` (reason `Stretch`, `NonFinite` or \
         `SolveFailed`) at its last good state;\n\
         - **failed**: a panic, valid input refused, or a NaN that passed the guard (never \
         expected).\n\n\
         ⚑ after a cell: the plugin would have flagged the run as not converged (see \
         [Convergence](#convergence)).\n\n\
         PBD has no stiffness, so its reference is the exact run with `k = 1e6` per unit mass. \
         `stiff` (XPBD with small steps) does not solve implicit Euler, whose large steps damp \
         stiff cloth; it is judged against the *physical* reference: the exact method at the \
         case's step halved until it is at most 1/960 s, on cloths of at most 51×51 (larger ones \
         against the exact run at the case's step, as the others), with that reference's own \
         floor — how far it moves when its step is halved once more — added to both \
         tolerances (the floors are listed under [Physical reference](#physical-reference)). \
         Each case runs `min(⌈1 s/dt⌉, 300)` steps. Methods run at their interactive settings: \
         32 iterations (Jacobi, Chebyshev with the lab's ρ = 0.995 or with ρ estimated, PBD), CG \
         with 25 iterations, the linearly implicit methods with compression-clamped and with exact \
         (`exact K`) spring blocks, projective dynamics with at most 10 Chebyshev iterations (stopping \
         early at an estimated error of 1 % of the step's motion) or 20 Anderson iterations, Newton on a budget (`newton`: at most 16 iterations to a relative gradient \
         of 1e-5).",
        crate::chart::machine(),
        started.elapsed().as_secs_f64()
    )
    .ok();
    let md = head + &md;
    std::fs::write(config.out_dir.join("stability.md"), &md)?;
    chart(
        &config.out_dir.join("stability.svg"),
        &labels,
        &config.stiffnesses,
        &config.time_steps,
        &grid,
    )
    .map_err(std::io::Error::other)?;
    Ok(md)
}

/// One panel per method: stiffness (rows) × time step (columns), coloured
/// by class.
fn chart(
    path: &Path,
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
        .draw_text(
            "Stability map, lab cloth 21×21 (rows: stiffness k; columns: time step dt in s):",
            &("sans-serif", 18).into_text_style(&legend),
            (x, 8),
        )
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
        assert!(
            md.contains("### chebyshev\n") && md.contains("### chebyshev-auto\n"),
            "{md}"
        );
        assert!(md.contains("## Extreme cases"));
        assert!(!md.contains("FAILED"), "{md}");
        let svg = std::fs::read_to_string(dir.join("stability.svg")).unwrap();
        assert!(svg.contains("<rect") && svg.contains("symplectic"));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
