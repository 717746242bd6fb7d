//! The character scene's cost (issue O): the cape example's scene run
//! without a window — the character gets up to speed, jumps, turns about
//! and is teleported 100 m at 6 s — for each cape size and method, the
//! cape's step time (median and quartiles over the run's steps), both
//! garments' largest stretch, and the garment vertices ever found inside a
//! body capsule.

use bevy_cloth::AnyMethod;
use bevy_cloth::XpbdSolver;

use super::{PerfConfig, Timing};

// The scene itself, shared with `examples/cape.rs`, `headless --scene cape`
// and the integration tests.
#[path = "../../../examples/character/mod.rs"]
#[allow(dead_code)]
mod scene;

/// One row: a cape size and method, and what its run measured.
#[derive(Clone, Debug)]
pub struct CapeRow {
    /// The method's label.
    pub method: String,
    /// The cape's vertices.
    pub vertices: usize,
    /// The cape's step time.
    pub step: Timing,
    /// The cape's and the skirt's largest stretch.
    pub stretch: (f32, f32),
    /// Garment vertices found inside a body capsule over the run.
    pub penetrations: u64,
    /// Whether both garments ran cleanly (no retry, running, finite).
    pub clean: bool,
}

/// The methods of the table: `stiff` as a game gets it (refined up to 16×
/// near colliders), with its refinement capped at 4× and without it, the
/// same three with chains solved whole ([`XpbdSolver::chains`]), and `pd`.
fn methods() -> Vec<(String, AnyMethod)> {
    let pd = bevy_cloth::methods::preset("pd").map(|p| p.method);
    let mut m = Vec::new();
    for chains in [false, true] {
        let stiff = XpbdSolver::STIFF.with_chains(chains);
        let name = if chains { "stiff, chains" } else { "stiff" };
        m.push((name.to_string(), AnyMethod::Xpbd(stiff)));
        m.push((
            format!("{name}, refinement ≤ 4"),
            AnyMethod::Xpbd(stiff.with_max_refinement(4)),
        ));
        m.push((
            format!("{name}, no refinement"),
            AnyMethod::Xpbd(stiff.with_max_refinement(1)),
        ));
    }
    m.extend(pd.map(|pd| ("pd".to_string(), pd)));
    m
}

/// Runs every cape size of `config` with every method of the table.
pub fn cape_rows(config: &PerfConfig) -> Vec<CapeRow> {
    let mut rows = Vec::new();
    for &cols in &config.cape_sizes {
        for (label, method) in methods() {
            let settings = scene::CapeSettings {
                method,
                cape_cols: cols,
                ..Default::default()
            };
            let run = scene::run_headless(settings, config.cape_steps, Some(6.0));
            let Some(cape) = run
                .garments
                .iter()
                .find(|g| g.name == "cape" && !g.step_times.is_empty())
            else {
                continue;
            };
            let skirt = run
                .garments
                .iter()
                .find(|g| g.name == "skirt")
                .map_or(f32::NAN, |g| g.max_stretch);
            rows.push(CapeRow {
                method: label,
                vertices: cape.vertices,
                step: Timing::of(cape.step_times.iter().map(|t| t.as_secs_f64()).collect()),
                stretch: (cape.max_stretch, skirt),
                penetrations: run.penetrations.count,
                clean: run.garments.iter().all(|g| g.clean()),
            });
        }
    }
    rows
}
