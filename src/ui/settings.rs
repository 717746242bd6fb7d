//! The panel's controls for each method's settings: one `match` arm per
//! method, and the widgets they share.

use bevy_egui::egui;

use crate::methods::AnyMethod;
use crate::solver::chebyshev::Rho;
use crate::solver::linear::{LinearSolver, PenaltyJacobian, Preconditioner, SpringJacobian};
use crate::solver::projective::{
    GlobalSolve, MULTIGRID_CYCLES, MULTIGRID_FROM, PD_ANDERSON_WINDOW, PD_TOLERANCE,
};

/// The checkbox for an implicit method's contacts in its solve.
fn contacts_ui(ui: &mut egui::Ui, contacts: &mut bool) {
    ui.checkbox(contacts, "colliders inside the solve")
        .on_hover_text(
            "the colliders projected after the step also act as penalty terms of the step's \
             objective, so stiff cloth in contact is not strained by the projection",
        );
}

/// The controls of a method's settings.
pub(super) fn settings_ui(ui: &mut egui::Ui, method: &mut AnyMethod) {
    match method {
        AnyMethod::Implicit(i) => {
            iterations_ui(ui, &mut i.iterations, "iterations");
            chebyshev_ui(ui, &mut i.chebyshev);
        }
        AnyMethod::Projective(p) => {
            // With the early stop the count is a budget.
            let label = if p.tolerance > 0.0 {
                "local–global iterations (at most)"
            } else {
                "local–global iterations"
            };
            iterations_ui(ui, &mut p.iterations, label);
            let mut anderson = p.anderson > 0;
            if ui
                .checkbox(&mut anderson, "Anderson acceleration (stiff cloth)")
                .changed()
            {
                p.anderson = if anderson { PD_ANDERSON_WINDOW } else { 0 };
                // One acceleration at a time; Anderson has no early stop.
                p.chebyshev = if anderson { None } else { Some(Rho::Auto) };
                p.tolerance = if anderson { 0.0 } else { PD_TOLERANCE };
            }
            if p.anderson > 0 {
                ui.add(egui::Slider::new(&mut p.anderson, 1..=16).text("Anderson window"));
            } else {
                chebyshev_ui(ui, &mut p.chebyshev);
                early_stop_ui(ui, &mut p.tolerance);
            }
            global_solve_ui(ui, &mut p.global);
            contacts_ui(ui, &mut p.contacts);
        }
        AnyMethod::Pbd(p) => iterations_ui(ui, &mut p.iterations, "iterations"),
        AnyMethod::Symplectic(_) => {}
        AnyMethod::Xpbd(x) => {
            ui.add(
                egui::Slider::new(&mut x.substep_rate, 30..=15360)
                    .text("substeps per second")
                    .logarithmic(true),
            )
            .on_hover_text("each substep is one sweep over the springs; 960: 32 per 30 Hz step");
            ui.add(
                egui::Slider::new(&mut x.max_refinement, 1..=64)
                    .text("most substeps ×, near a collider")
                    .logarithmic(true),
            )
            .on_hover_text(
                "a step near a collider multiplies its substeps by the power of two at or above \
                 k·h²/m, up to this: stiff cloth then keeps its length on impact and does not \
                 creep off a frictionless collider; 1 never does",
            );
            ui.checkbox(&mut x.tethers, "tethers to the pins")
                .on_hover_text(
                    "each vertex no further from its nearest pin than at rest, plus the stretch \
                     the cloth's weight allows: takes back the sag of long hanging cloth",
                );
            ui.checkbox(&mut x.chains, "chains solved whole")
                .on_hover_text(
                    "each substep first solves the cloth's rows and columns of stretch springs \
                     whole, so a pull passes along them at once: less stretch in fine cloth, \
                     about twice the step",
                );
        }
        AnyMethod::Exact(x) => {
            let mut exponent = x.tolerance.log10();
            if ui
                .add(
                    egui::Slider::new(&mut exponent, -12.0..=-2.0)
                        .text("gradient tolerance (log10)"),
                )
                .changed()
            {
                x.tolerance = 10f64.powf(exponent);
            }
            ui.add(
                egui::Slider::new(&mut x.max_iterations, 1..=200).text("Newton iterations (max)"),
            );
            ui.checkbox(&mut x.projected_only, "projected Hessian only");
            contacts_ui(ui, &mut x.contacts);
        }
        AnyMethod::Linear(l) => {
            if let LinearSolver::Cg(cg) = &mut l.solver {
                iterations_ui(ui, &mut cg.max_iterations, "CG iterations");
                let mut exponent = cg.tolerance.log10();
                if ui
                    .add(egui::Slider::new(&mut exponent, -12.0..=-1.0).text("tolerance (log10)"))
                    .changed()
                {
                    cg.tolerance = 10f64.powf(exponent);
                }
                let mut jacobi = cg.preconditioner == Preconditioner::Jacobi;
                if ui.checkbox(&mut jacobi, "Jacobi preconditioner").changed() {
                    cg.preconditioner = if jacobi {
                        Preconditioner::Jacobi
                    } else {
                        Preconditioner::None
                    };
                }
            }
            let mut clamp = l.springs == SpringJacobian::ClampCompression;
            if ui
                .checkbox(&mut clamp, "drop compressive spring stiffness")
                .changed()
            {
                l.springs = if clamp {
                    SpringJacobian::ClampCompression
                } else {
                    SpringJacobian::Exact
                };
            }
            egui::ComboBox::from_label("penalty stiffness in A")
                .selected_text(format!("{:?}", l.penalty))
                .show_ui(ui, |ui| {
                    for p in [
                        PenaltyJacobian::Normal,
                        PenaltyJacobian::Isotropic,
                        PenaltyJacobian::Exact,
                    ] {
                        ui.selectable_value(&mut l.penalty, p, format!("{p:?}"));
                    }
                });
        }
    }
}

/// Projective dynamics' early stop: on or off, and its tolerance.
fn early_stop_ui(ui: &mut egui::Ui, tolerance: &mut f64) {
    let mut on = *tolerance > 0.0;
    if ui
        .checkbox(&mut on, "stop early (estimated error per motion)")
        .changed()
    {
        *tolerance = if on { PD_TOLERANCE } else { 0.0 };
    }
    if on {
        let mut exponent = tolerance.log10();
        if ui
            .add(egui::Slider::new(&mut exponent, -4.0..=-1.0).text("tolerance (log10)"))
            .changed()
        {
            *tolerance = 10f64.powf(exponent);
        }
    }
}

/// Projective dynamics' global solve: automatic, direct, or multigrid with
/// its V-cycles per iteration.
fn global_solve_ui(ui: &mut egui::Ui, global: &mut GlobalSolve) {
    let name = |g: GlobalSolve| match g {
        GlobalSolve::Auto => format!("auto (multigrid from {MULTIGRID_FROM} free vertices)"),
        GlobalSolve::Direct => "direct (sparse Cholesky)".to_owned(),
        GlobalSolve::Multigrid { .. } => "multigrid".to_owned(),
    };
    egui::ComboBox::from_label("global solve")
        .selected_text(name(*global))
        .show_ui(ui, |ui| {
            let multigrid = GlobalSolve::Multigrid {
                cycles: MULTIGRID_CYCLES,
            };
            for g in [GlobalSolve::Auto, GlobalSolve::Direct, multigrid] {
                let selected = core::mem::discriminant(global) == core::mem::discriminant(&g);
                if ui.selectable_label(selected, name(g)).clicked() && !selected {
                    *global = g;
                }
            }
        });
    if let GlobalSolve::Multigrid { cycles } = global {
        ui.add(egui::Slider::new(cycles, 1..=8).text("V-cycles per iteration"));
    }
}

fn chebyshev_ui(ui: &mut egui::Ui, chebyshev: &mut Option<Rho>) {
    let mut on = chebyshev.is_some();
    if ui.checkbox(&mut on, "Chebyshev acceleration").changed() {
        *chebyshev = on.then(Rho::default);
    }
    if let Some(rho) = chebyshev {
        let mut auto = *rho == Rho::Auto;
        if ui.checkbox(&mut auto, "estimate rho each step").changed() {
            *rho = if auto { Rho::Auto } else { Rho::default() };
        }
        if let Rho::Fixed(r) = rho {
            ui.add(egui::Slider::new(r, 0.5..=0.9999).text("rho"));
        }
    }
}

fn iterations_ui(ui: &mut egui::Ui, iterations: &mut u32, text: &str) {
    ui.add(
        egui::Slider::new(iterations, 1..=512)
            .text(text)
            .logarithmic(true),
    );
}
