//! The error-against-run-time report: every method measured against the
//! exact implicit-Euler step, charted and tabulated.
//!
//! Run it with `cargo run --release -p bevy_cloth_report`; it writes
//! `docs/report/README.md` and SVG charts. [`run`] does the work, so a game
//! can also report on its own cloths. The methods are bevy_cloth's
//! [`PRESETS`], each iterative one at several iteration counts, named by
//! their preset names.
//!
//! # Measures
//!
//! - **Per-step error** of a method from a state `x_0`:
//!   `‖x_K − x*‖ / ‖x* − x_0‖` ([`step_error`]), with `x*` the exact
//!   implicit-Euler step (Newton to a relative gradient of 1e-9) from the
//!   same state. The linearly implicit methods converge to the linearised
//!   step, so their error levels off at the linearisation error.
//! - **Trajectory error** after `N` steps from rest: the same norm between
//!   the method's and the exact trajectory's positions, relative to how far
//!   the exact trajectory moved.
//! - **PBD** solves a different problem (constraints, no stiffness), so its
//!   step is not compared with `x*`; its constraint violation (max and mean
//!   edge strain after the step) is reported against run time instead.
//!
//! Times are medians of repeated runs of the step (state copy excluded).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use bevy::math::{Affine3A, Vec3, Vec3A};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;

use crate::chart::{log_log_chart, machine, register_chart_font};
use bevy_cloth::collision::PenaltySphere;
use bevy_cloth::methods::{AnyMethod, AnyWorkspace, PRESETS};
use bevy_cloth::model::{ClothBuilder, ClothModel, ClothState};
use bevy_cloth::solver::Method;
use bevy_cloth::solver::exact::{ExactSolver, ExactWorkspace};
use bevy_cloth::solver::implicit::{self, ImplicitSolver, ImplicitWorkspace};
use bevy_cloth::solver::linear::LinearSolver;
use bevy_cloth::solver::{SpringStiffness, StepParams, step_error};

/// One scene of the report.
#[derive(Clone, Debug)]
pub struct ReportScene {
    /// File-name stem.
    pub name: String,
    /// Heading.
    pub title: String,
    /// The cloth.
    pub model: ClothModel,
    /// Its parameters.
    pub params: StepParams,
    /// Penalty spheres acting on it (in the exact objective too).
    pub spheres: Vec<PenaltySphere>,
    /// Exact steps from rest before the per-step measurement.
    pub warmup: usize,
}

/// The sphere scene's sphere: the lab's, as a penalty sphere (stiffness
/// 1e4, stiffer than the cloth's inertia, `m/h²` ≈ 900).
pub fn penalty_sphere() -> PenaltySphere {
    PenaltySphere {
        center: Vec3A::new(0.0, -4.0, 4.0),
        radius: 2.7,
        stiffness: 1e4,
        surface: Default::default(),
    }
}

impl ReportScene {
    /// The lab's `n×n` cloth (10×10 units, total mass 441 as at 21×21,
    /// `k = 8000`, `dt = 0.0333`), hanging, optionally with the lab's sphere
    /// as a penalty sphere (stiffness 1e4) so that the exact step sees it.
    pub fn lab(n: usize, sphere: bool) -> Self {
        let model = ClothBuilder::lab_grid(n)
            .with_total_mass(441.0)
            .with_pins([0, n as u32 - 1])
            .build()
            .expect("valid lab cloth");
        let spheres = if sphere {
            vec![penalty_sphere()]
        } else {
            Vec::new()
        };
        Self {
            name: format!("lab{n}{}", if sphere { "-sphere" } else { "" }),
            title: format!(
                "Lab cloth {n}×{n}{}",
                if sphere {
                    " falling onto the sphere"
                } else {
                    ", hanging"
                }
            ),
            model,
            params: StepParams::LAB,
            spheres,
            warmup: 20,
        }
    }

    /// The assignment's `n×n` cloth with stretch, shear and bending springs
    /// (`E = 10`, `h = 5e-3`, total mass 0.1, no damping).
    pub fn assignment(n: usize) -> Self {
        Self {
            name: format!("assignment{n}"),
            title: format!("Assignment cloth {n}×{n} with bending springs"),
            model: ClothBuilder::assignment(n, n).build().expect("valid cloth"),
            params: StepParams {
                dt: 5e-3,
                stiffness: SpringStiffness::uniform(10.0),
                damping: 1.0,
                gravity: Vec3::new(0.0, -9.8, 0.0),
                ..StepParams::LAB
            },
            spheres: Vec::new(),
            warmup: 60,
        }
    }
}

/// What to measure.
#[derive(Clone, Debug)]
pub struct ReportConfig {
    /// Output folder (README.md and SVGs).
    pub out_dir: PathBuf,
    /// Scenes.
    pub scenes: Vec<ReportScene>,
    /// Iteration counts for the per-step sweep.
    pub iterations: Vec<u32>,
    /// Iteration counts for the trajectory sweep.
    pub trajectory_iterations: Vec<u32>,
    /// Steps of the trajectory comparison.
    pub trajectory_steps: usize,
    /// Timed repeats of each step (the median is reported).
    pub repeats: usize,
    /// Show progress bars.
    pub progress: bool,
}

impl ReportConfig {
    /// The full report: the lab at 21×21 (hanging, and with the sphere), the
    /// assignment at 30×30 and the lab cloth at 101×101; K from 1 to 512.
    pub fn full(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            scenes: vec![
                ReportScene::lab(21, false),
                ReportScene::lab(21, true),
                ReportScene::assignment(30),
                ReportScene::lab(101, false),
            ],
            iterations: (0..10).map(|p| 1 << p).collect(),
            trajectory_iterations: vec![4, 16, 64, 256],
            trajectory_steps: 300,
            repeats: 9,
            progress: true,
        }
    }

    /// A tiny configuration for tests: one small scene, few iterations.
    pub fn tiny(out_dir: impl Into<PathBuf>) -> Self {
        let mut scene = ReportScene::lab(6, false);
        scene.warmup = 3;
        Self {
            out_dir: out_dir.into(),
            scenes: vec![scene],
            iterations: vec![1, 4, 16],
            trajectory_iterations: vec![4],
            trajectory_steps: 5,
            repeats: 2,
            progress: false,
        }
    }
}

/// The report's setting of a method at `k` iterations: CG and projective
/// dynamics run exactly `k` iterations (tolerance 0), Newton at most `k`.
fn at_iterations(method: AnyMethod, k: u32) -> AnyMethod {
    match method.with_iterations(k) {
        AnyMethod::Linear(mut linear) => {
            if let LinearSolver::Cg(cg) = &mut linear.solver {
                cg.tolerance = 0.0;
            }
            AnyMethod::Linear(linear)
        }
        AnyMethod::Projective(pd) => AnyMethod::Projective(pd.with_tolerance(0.0)),
        other => other,
    }
}

/// The reference step: [`ExactSolver::REFERENCE`].
const EXACT: AnyMethod = AnyMethod::Exact(ExactSolver::REFERENCE);

/// One step of `method`; false if the method refused or failed.
fn step(
    method: AnyMethod,
    scene: &ReportScene,
    state: &mut ClothState,
    ws: &mut AnyWorkspace,
) -> bool {
    method
        .step(&scene.model, state, &scene.params, &scene.spheres, ws)
        .is_ok()
}

fn median(mut xs: Vec<Duration>) -> Duration {
    xs.sort();
    xs[xs.len() / 2]
}

/// One measured point.
#[derive(Clone, Copy, Debug)]
struct Point {
    method: AnyMethod,
    micros: f64,
    /// Relative spread of the repeats: (max − min)/median.
    spread: f64,
    error: f64,
}

/// Mean and max edge strain `|l − L|/L`.
fn strain(model: &ClothModel, x: &[Vec3A]) -> (f64, f64) {
    let mut sum = 0.0;
    let mut max = 0.0f64;
    for s in model.topology().springs() {
        let e = f64::from(
            (x[s.a as usize].distance(x[s.b as usize]) - s.rest_length).abs() / s.rest_length,
        );
        sum += e;
        max = max.max(e);
    }
    (sum / model.topology().springs().len() as f64, max)
}

/// Estimates the spectral radius of the Jacobi iteration on a step from
/// `state`: the geometric mean decay of successive update norms
/// `‖x_{k+1} − x_k‖` over iterations `k/2..k` (Wang 2015 suggests watching
/// this decay).
pub fn estimate_rho(
    model: &ClothModel,
    state: &ClothState,
    params: &StepParams,
    iterations: u32,
) -> f32 {
    let norms: Vec<f64> = (1..=iterations)
        .map(|k| {
            let mut a = state.clone();
            let mut b = state.clone();
            let mut ws = ImplicitWorkspace::default();
            let _ = Method::step(
                &ImplicitSolver::jacobi(k),
                model,
                &mut a,
                params,
                &[],
                &mut ws,
            );
            if k > 1 {
                let _ = Method::step(
                    &ImplicitSolver::jacobi(k - 1),
                    model,
                    &mut b,
                    params,
                    &[],
                    &mut ws,
                );
            }
            a.positions
                .iter()
                .zip(&b.positions)
                .map(|(p, q)| (p.as_dvec3() - q.as_dvec3()).length_squared())
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    implicit::rho_from_update_norms(&norms)
}

/// Runs the report and writes its files. Returns the markdown.
pub fn run(config: &ReportConfig) -> std::io::Result<String> {
    std::fs::create_dir_all(&config.out_dir)?;
    register_chart_font();
    let mut md = String::new();
    writeln!(md, "# Error against run time").ok();
    writeln!(md).ok();
    writeln!(
        md,
        "Generated by `cargo run --release -p bevy_cloth_report` on {} ({} logical cores); \
         times are medians of {} timed runs of one step (the state copy is not timed), \
         single-threaded. Every method starts from the same state; the reference is the \
         exact implicit-Euler step (Newton with sparse Cholesky and line search, relative \
         gradient 1e-9). The linearly implicit methods use the compression-clamped spring \
         blocks (the exact ones make `A` indefinite on the lab cloth). Lower-left is better. Where each method stays \
         stable, and where it is finite but wrong: [the stability map](stability.md) \
         (`--stability`).",
        machine(),
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        config.repeats
    )
    .ok();
    writeln!(md).ok();
    writeln!(
        md,
        "**Measures.** Per-step error `‖x_K − x*‖ / ‖x* − x_0‖` (x* the exact step, x_0 the state \
         before it; 1 means no closer than staying put). Trajectory error after {} steps from rest: \
         `‖x_N − x*_N‖ / ‖x*_N − x_rest‖` against the exact trajectory. PBD solves a different problem \
         (strain limiting, no stiffness), so it is reported by its constraint violation (edge strain), \
         stated as such.",
        config.trajectory_steps
    )
    .ok();
    for scene in &config.scenes {
        scene_report(config, scene, &mut md)?;
    }
    std::fs::write(config.out_dir.join("README.md"), &md)?;
    Ok(md)
}

fn scene_report(
    config: &ReportConfig,
    scene: &ReportScene,
    md: &mut String,
) -> std::io::Result<()> {
    let mut ws = AnyWorkspace::default();
    // A representative state: the exact trajectory after `warmup` steps.
    let rest = ClothState::at_rest(&scene.model, &Affine3A::IDENTITY);
    let mut start = rest.clone();
    for _ in 0..scene.warmup {
        step(EXACT, scene, &mut start, &mut ws);
    }
    let mut exact_state = start.clone();
    step(EXACT, scene, &mut exact_state, &mut ws);
    let exact_report = ws.get::<ExactWorkspace>().last_report();
    let projected = {
        let mut s = start.clone();
        let config = ExactSolver {
            projected_only: true,
            max_iterations: 1000,
            ..ExactSolver::REFERENCE
        };
        let _ = Method::step(
            &config,
            &scene.model,
            &mut s,
            &scene.params,
            &scene.spheres,
            ws.get::<ExactWorkspace>(),
        );
        ws.get::<ExactWorkspace>().last_report()
    };
    let rho = estimate_rho(&scene.model, &start, &scene.params, 64);

    // Every preset: the iterative ones at each iteration count (Newton up
    // to 16), the others once.
    let mut methods = Vec::new();
    for preset in PRESETS {
        let method = preset.method;
        match method.iterations() {
            Some(_) => methods.extend(
                config
                    .iterations
                    .iter()
                    .filter(|&&k| !matches!(method, AnyMethod::Exact(_)) || k <= 16)
                    .map(|&k| at_iterations(method, k)),
            ),
            None => methods.push(method),
        }
    }
    let bar = progress(config, methods.len() as u64, &scene.title);
    let mut points = Vec::new();
    let mut pbd_rows = Vec::new();
    for &method in &methods {
        let mut times = Vec::with_capacity(config.repeats);
        let mut result = start.clone();
        let mut ok = true;
        for _ in 0..config.repeats {
            result.copy_from(&start);
            let t = Instant::now();
            ok &= step(method, scene, &mut result, &mut ws);
            times.push(t.elapsed());
        }
        bar.inc(1);
        let (lo, hi) = (*times.iter().min().unwrap(), *times.iter().max().unwrap());
        let mid = median(times);
        let micros = mid.as_secs_f64() * 1e6;
        let spread = (hi - lo).as_secs_f64() / mid.as_secs_f64().max(1e-12);
        if let AnyMethod::Pbd(pbd) = method {
            let (mean, max) = strain(&scene.model, &result.positions);
            pbd_rows.push((pbd.iterations, micros, mean, max));
            continue;
        }
        let error = if ok && result.is_finite() {
            step_error(&result.positions, &exact_state.positions, &start.positions)
        } else {
            f64::INFINITY
        };
        points.push(Point {
            method,
            micros,
            spread,
            error,
        });
    }
    bar.finish_and_clear();

    // Trajectories from rest.
    // Every preset but PBD (a different problem) and the exact method (the
    // reference itself); Newton on a budget at its preset's setting.
    let mut trajectory_methods = Vec::new();
    for preset in PRESETS {
        let method = preset.method;
        if matches!(method, AnyMethod::Pbd(_)) || method == EXACT {
            continue;
        }
        match method.iterations() {
            Some(_) if matches!(method, AnyMethod::Exact(_)) => trajectory_methods.push(method),
            Some(_) => trajectory_methods.extend(
                config
                    .trajectory_iterations
                    .iter()
                    .map(|&k| at_iterations(method, k)),
            ),
            None => trajectory_methods.push(method),
        }
    }
    let bar = progress(
        config,
        trajectory_methods.len() as u64 + 1,
        &format!("{} (trajectories)", scene.title),
    );
    let mut exact_end = rest.clone();
    let t = Instant::now();
    for _ in 0..config.trajectory_steps {
        step(EXACT, scene, &mut exact_end, &mut ws);
    }
    let exact_micros = t.elapsed().as_secs_f64() * 1e6 / config.trajectory_steps as f64;
    bar.inc(1);
    let mut trajectory = Vec::new();
    for &method in &trajectory_methods {
        let mut s = rest.clone();
        let mut ok = true;
        let t = Instant::now();
        for _ in 0..config.trajectory_steps {
            ok &= step(method, scene, &mut s, &mut ws);
            if !ok || !s.is_finite() {
                break;
            }
        }
        let micros = t.elapsed().as_secs_f64() * 1e6 / config.trajectory_steps as f64;
        let error = if ok && s.is_finite() {
            step_error(&s.positions, &exact_end.positions, &rest.positions)
        } else {
            f64::INFINITY
        };
        trajectory.push(Point {
            method,
            micros,
            spread: 0.0,
            error,
        });
        bar.inc(1);
    }
    bar.finish_and_clear();

    // Charts.
    let step_chart = format!("{}-step.svg", scene.name);
    let trajectory_chart = format!("{}-trajectory.svg", scene.name);
    chart(
        &config.out_dir.join(&step_chart),
        &format!("{}: per-step error vs time", scene.title),
        &points,
        "time per step (µs)",
    )
    .map_err(std::io::Error::other)?;
    chart(
        &config.out_dir.join(&trajectory_chart),
        &format!(
            "{}: error after {} steps vs time",
            scene.title, config.trajectory_steps
        ),
        &trajectory,
        "time per step (µs, mean over the run)",
    )
    .map_err(std::io::Error::other)?;

    // Markdown.
    let n = scene.model.vertex_count();
    writeln!(md, "\n## {}\n", scene.title).ok();
    writeln!(
        md,
        "{n} vertices, {} springs, dt = {} s. State: the exact trajectory after {} steps from rest. \
         Exact step: {} Newton iterations with the true Hessian (+{} projected), relative gradient {:.1e}; \
         with the projected Hessian only: {} iterations (relative gradient {:.1e}){}. \
         Jacobi spectral radius on this step, estimated from the decay of 64 Jacobi updates: ρ ≈ {rho:.4} \
         (`ρ: Auto` estimates it from the first few iterations of each step).",
        scene.model.topology().springs().len(),
        scene.params.dt,
        scene.warmup,
        exact_report.true_hessian,
        exact_report.projected_hessian,
        exact_report.relative_gradient,
        projected.projected_hessian,
        projected.relative_gradient,
        if projected.converged { "" } else { ", not converged" },
    )
    .ok();
    writeln!(md, "\n![per-step error]({step_chart})\n").ok();
    writeln!(md, "Iterations and time to reach a per-step error:\n").ok();
    writeln!(
        md,
        "| method | ≤ 1e-1 | ≤ 1e-2 | ≤ 1e-3 | best error (time) |"
    )
    .ok();
    writeln!(md, "|---|---|---|---|---|").ok();
    let families: Vec<&str> = {
        let mut f: Vec<&str> = points.iter().map(|p| p.method.name()).collect();
        f.dedup();
        let mut unique = Vec::new();
        for x in f {
            if !unique.contains(&x) {
                unique.push(x);
            }
        }
        unique
    };
    let reach = |family: &str, threshold: f64| -> Option<Point> {
        points
            .iter()
            .filter(|p| p.method.name() == family && p.error <= threshold)
            .min_by(|a, b| a.micros.total_cmp(&b.micros))
            .copied()
    };
    let cell = |p: Option<Point>| match p {
        Some(p) => match p.method.iterations() {
            Some(k) => format!("K = {k}, {:.0} µs", p.micros),
            None => format!("{:.0} µs", p.micros),
        },
        None => "not reached".to_string(),
    };
    for family in &families {
        let best = points
            .iter()
            .filter(|p| p.method.name() == *family)
            .min_by(|a, b| a.error.total_cmp(&b.error))
            .copied();
        writeln!(
            md,
            "| {family} | {} | {} | {} | {} |",
            cell(reach(family, 1e-1)),
            cell(reach(family, 1e-2)),
            cell(reach(family, 1e-3)),
            best.map_or("-".into(), |b| format!(
                "{:.2e} ({:.0} µs)",
                b.error, b.micros
            ))
        )
        .ok();
    }
    let ratio = |threshold: f64| -> String {
        match (
            reach("jacobi", threshold).and_then(|p| p.method.iterations()),
            reach("chebyshev", threshold).and_then(|p| p.method.iterations()),
        ) {
            (Some(j), Some(c)) => format!("{:.1}", f64::from(j) / f64::from(c)),
            (None, Some(c)) => format!(
                "> {:.0} (Jacobi did not reach it in {} iterations)",
                f64::from(*config.iterations.last().unwrap()) / f64::from(c),
                config.iterations.last().unwrap()
            ),
            _ => "-".into(),
        }
    };
    writeln!(
        md,
        "\nJacobi/Chebyshev iteration ratio: {} at 1e-1, {} at 1e-2, {} at 1e-3.",
        ratio(1e-1),
        ratio(1e-2),
        ratio(1e-3)
    )
    .ok();
    let worst_spread = points.iter().map(|p| p.spread).fold(0.0, f64::max);
    let median_spread = {
        let mut s: Vec<f64> = points.iter().map(|p| p.spread).collect();
        s.sort_by(f64::total_cmp);
        s[s.len() / 2]
    };
    writeln!(
        md,
        "Timing spread over the repeats, (max − min)/median: median {:.0} %, worst {:.0} %.",
        median_spread * 100.0,
        worst_spread * 100.0
    )
    .ok();
    writeln!(md, "\nPBD (constraint violation, not error against x*):\n").ok();
    writeln!(md, "| K | µs | mean strain | max strain |").ok();
    writeln!(md, "|---|---|---|---|").ok();
    for (k, micros, mean, max) in &pbd_rows {
        writeln!(md, "| {k} | {micros:.0} | {mean:.2e} | {max:.2e} |").ok();
    }
    writeln!(md, "\n![trajectory error]({trajectory_chart})\n").ok();
    writeln!(
        md,
        "Trajectory error after {} steps (exact: {:.0} µs per step):\n",
        config.trajectory_steps, exact_micros
    )
    .ok();
    writeln!(md, "| method | K | µs per step | error |").ok();
    writeln!(md, "|---|---|---|---|").ok();
    for p in &trajectory {
        writeln!(
            md,
            "| {} | {} | {:.0} | {} |",
            p.method.name(),
            p.method.iterations().map_or("-".into(), |k| k.to_string()),
            p.micros,
            if p.error.is_finite() {
                format!("{:.2e}", p.error)
            } else {
                "diverged".into()
            }
        )
        .ok();
    }
    Ok(())
}

fn progress(config: &ReportConfig, len: u64, title: &str) -> ProgressBar {
    if !config.progress {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template("{msg:40} [{bar:30}] {pos}/{len} {elapsed}") {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(title.to_string());
    bar
}

/// A log–log chart of error against time, one series per method family.
fn chart(path: &Path, title: &str, points: &[Point], x_label: &str) -> Result<(), String> {
    let finite: Vec<&Point> = points
        .iter()
        .filter(|p| p.error.is_finite() && p.error > 0.0 && p.micros > 0.0)
        .collect();
    let (x_lo, x_hi) = finite.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
        (lo.min(p.micros), hi.max(p.micros))
    });
    let (y_lo, y_hi) = finite.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), p| {
        (lo.min(p.error), hi.max(p.error))
    });
    let (x_lo, x_hi) = if finite.is_empty() {
        (1.0, 10.0)
    } else {
        (x_lo / 1.5, x_hi * 1.5)
    };
    let (y_lo, y_hi) = if finite.is_empty() {
        (1e-6, 1.0)
    } else {
        (y_lo.max(1e-12) / 2.0, y_hi.max(1.0) * 2.0)
    };
    let mut families: Vec<&str> = Vec::new();
    for p in &finite {
        if !families.contains(&p.method.name()) {
            families.push(p.method.name());
        }
    }
    let series: Vec<(&str, Vec<(f64, f64)>)> = families
        .iter()
        .map(|family| {
            let mut points: Vec<(f64, f64)> = finite
                .iter()
                .filter(|p| p.method.name() == *family)
                .map(|p| (p.micros, p.error))
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            (*family, points)
        })
        .collect();
    log_log_chart(
        path,
        (900, 560),
        title,
        (x_label, "relative error"),
        (x_lo..x_hi, y_lo..y_hi),
        &series,
        SeriesLabelPosition::UpperRight,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_report_runs_end_to_end_on_a_tiny_configuration() {
        let dir = std::env::temp_dir().join(format!("bevy_cloth_report_{}", std::process::id()));
        let md = run(&ReportConfig::tiny(&dir)).unwrap();
        assert!(md.contains("## Lab cloth 6×6, hanging"));
        assert!(md.contains("Jacobi/Chebyshev iteration ratio"));
        assert!(md.contains("| chebyshev-auto |"), "{md}");
        // Every method ran: none failed on its first step.
        assert!(!md.contains("inf ("), "{md}");
        for file in ["README.md", "lab6-step.svg", "lab6-trajectory.svg"] {
            let text = std::fs::read_to_string(dir.join(file)).unwrap();
            assert!(text.len() > 500, "{file} is too short");
        }
        let svg = std::fs::read_to_string(dir.join("lab6-step.svg")).unwrap();
        assert!(svg.contains("jacobi") && svg.contains("<circle"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_estimated_rho_is_a_contraction_factor() {
        let model = ClothBuilder::lab().build().unwrap();
        let state = ClothState::at_rest(&model, &Affine3A::IDENTITY);
        let rho = estimate_rho(&model, &state, &StepParams::LAB, 32);
        assert!(rho > 0.5 && rho < 1.0, "{rho}");
    }
}
