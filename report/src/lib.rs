//! Measurement tooling for [`bevy_cloth`]: what the crate's pages are made
//! of, kept out of the library that games depend on.
//!
//! - [`accuracy`]: the error-against-run-time report (`docs/report/README.md`):
//!   every method's per-step and trajectory error against the exact
//!   implicit-Euler step, as a function of its run time.
//! - [`scenarios`] and [`stability`]: stiff and extreme cases run under the
//!   divergence guard and classified against the exact method, and the
//!   stability map (`docs/report/stability.md`).
//! - [`contact`], [`two_sheets`] and [`contact_map`]: the contact cases
//!   (a sheet folded onto itself, a ball thrown through a sheet, two
//!   sheets on each other through the plugin) and the map's section of
//!   them.
//! - [`perf`]: the performance page (`docs/perf.md`): every method from 21²
//!   to 256², many cloths, the sparse CG step against its parts, the
//!   machine's limits.
//!
//! The methods come from bevy_cloth's method table
//! ([`bevy_cloth::methods::PRESETS`]), named as everywhere else.
//!
//! ```text
//! cargo run --release -p bevy_cloth_report [-- --out docs/report] [--tiny]
//! cargo run --release -p bevy_cloth_report -- --stability [--tiny]
//! cargo run --release -p bevy_cloth_report -- --perf [--out docs] [--tiny] [--sizes 21,51] [--only NAME] [--seconds S]
//! ```

// Only the machine-limit probes (`perf::machine`: a STREAM triad and an FMA
// peak at each SIMD level) may use `unsafe`; the library's own rule is the
// same, with its engine room (`bevy_cloth::solver::engine`).
#![deny(unsafe_code)]

pub mod accuracy;
pub mod chart;
pub mod contact;
pub mod contact_map;
pub mod long_run;
pub mod perf;
pub mod scenarios;
pub mod stability;
pub mod two_sheets;

use bevy_cloth::methods::AnyMethod;
use bevy_cloth::solver::linear::SpringJacobian;
use bevy_cloth::solver::projective::GlobalSolve;

/// A method's name with its iteration count, as the pages' tables and
/// charts name a setting: `chebyshev 32`, `linear-cg 25`, `exact`.
pub fn label(method: &AnyMethod) -> String {
    match (method, method.iterations()) {
        // Newton's count is a cap, not the work done: the name alone.
        (AnyMethod::Exact(_), _) | (_, None) => variant(method),
        // Projective dynamics with an early stop: its count is a budget.
        (AnyMethod::Projective(pd), Some(k)) if pd.tolerance > 0.0 => {
            format!("{} ≤{k}", variant(method))
        }
        (_, Some(k)) => format!("{} {k}", variant(method)),
    }
}

/// A method's name, with `exact-k` after a linearly implicit one that uses
/// the assignment's exact spring blocks (the presets clamp compression).
pub fn variant(method: &AnyMethod) -> String {
    match method {
        AnyMethod::Linear(l) if l.springs == SpringJacobian::Exact => {
            format!("{} exact-k", method.name())
        }
        // Projective dynamics' global solve, when it is not the automatic
        // choice.
        AnyMethod::Projective(p) => match p.global {
            GlobalSolve::Auto => method.name().to_owned(),
            GlobalSolve::Direct => format!("{} direct", method.name()),
            GlobalSolve::Multigrid { cycles } => format!("{} mg{cycles}", method.name()),
        },
        AnyMethod::Xpbd(x) if x.chains => format!("{} chains", method.name()),
        _ => method.name().to_owned(),
    }
}
