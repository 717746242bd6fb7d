//! The performance page: time per step of every method as the cloth grows,
//! within-cloth and across-cloth parallelism, the sparse CG step against
//! its parts, and the machine's limits. Written as `perf.md` and
//! `perf-scaling.svg`.
//!
//! ```text
//! cargo run --release -p bevy_cloth_report -- --perf   # docs/perf.md
//! bash scripts/perf.sh                          # the bevy_silk table too, then the page
//! ```
//!
//! # Method
//!
//! Every method steps the lab's cloth, kept physically the same at every
//! resolution ([`scale_model`]): `n×n` vertices over 10×10 units, total mass
//! 441 (1 per vertex at the lab's 21²), corners `0` and `n − 1` pinned,
//! `k = 8000`, `dt = 0.0333`, damping 0.99. `k` stays constant: a row of
//! `n − 1` springs in series has stiffness `k/(n − 1)` and `n` rows act in
//! parallel, so the sheet's stiffness is about `k` at every `n`.
//!
//! The timed step starts each time from the same swinging state (20
//! Chebyshev steps from rest; state copy not timed), so every sample does
//! the same work. A case is warmed up, then sampled until it has run for
//! its time budget (at least [`PerfConfig::min_samples`] samples); the page
//! gives the median and the quartiles. After the last sample the
//! divergence guard's default check ([`GuardBounds::default`](bevy_cloth::solver::guard::GuardBounds::default)) runs on the
//! result: a timed step the guard would have rejected is marked.

mod character;
#[allow(unsafe_code)]
mod machine;
mod page;
mod sections;
mod self_collision;
mod sweep;

pub use character::{CapeRow, cape_rows};
pub use machine::{Caches, Limits, limits, work_per_iteration};
pub use page::run;
pub use sections::{SECTIONS, rerun_section};
pub use self_collision::{SelfCollisionRow, TwoSheetsRow, self_collision_rows, two_sheets_rows};
pub use sweep::{
    Case, CgParts, FrameCosts, SWEEP_ROUNDS, SimdRow, SphereRow, cg_parts, frame_costs,
    many_cloths, scale_model, simd_levels, sphere_steps, sweep, sweep_methods, warm_state,
};

use std::path::PathBuf;
use std::time::{Duration, Instant};

/// What the performance page measures.
#[derive(Clone, Debug)]
pub struct PerfConfig {
    /// Output folder (`perf.md`, `perf-scaling.svg`).
    pub out_dir: PathBuf,
    /// Grid sides of the scale sweep.
    pub sizes: Vec<usize>,
    /// Largest side at which the linearly implicit and exact methods run.
    pub max_side_sparse: usize,
    /// Wall time to sample each case for.
    pub budget: Duration,
    /// Fewest samples per case.
    pub min_samples: usize,
    /// Cloths in the many-cloths app.
    pub many: usize,
    /// Side of the CG comparison cloth (the assignment's).
    pub cg_side: usize,
    /// Sides at which `pd` is timed falling onto a penalty sphere.
    pub sphere_sides: Vec<usize>,
    /// Elements per array of the memory-bandwidth kernel.
    pub stream_len: usize,
    /// A table from `compare/silk` to include, if the file exists.
    pub silk_table: Option<PathBuf>,
    /// Columns of the character scene's capes (8/5 as many rows).
    pub cape_sizes: Vec<usize>,
    /// Fixed steps of each character-scene run (60 per second).
    pub cape_steps: usize,
    /// Sides of the folded sheet whose step is timed with and without
    /// self-collision.
    pub self_collision_sizes: Vec<usize>,
    /// Sides of the two sheets draped on each other whose frame is timed
    /// with and without their self-collision.
    pub two_sheet_sizes: Vec<usize>,
    /// Only the sweep's methods whose name starts with this (and nothing
    /// else: no page is written), for profiling one case.
    pub only: Option<String>,
}

impl PerfConfig {
    /// The committed page: 21² to 256², 100 cloths, CG at 100².
    pub fn full(out_dir: impl Into<PathBuf>) -> Self {
        let out_dir = out_dir.into();
        Self {
            silk_table: Some(out_dir.join("perf").join("silk.md")),
            out_dir,
            sizes: vec![21, 51, 101, 201, 256],
            max_side_sparse: 201,
            budget: Duration::from_millis(1500),
            min_samples: 7,
            many: 100,
            cg_side: 100,
            sphere_sides: vec![101, 201],
            stream_len: 1 << 24,
            cape_sizes: vec![20, 50],
            cape_steps: 600,
            self_collision_sizes: vec![64, 101, 201],
            two_sheet_sizes: vec![32, 64],
            only: None,
        }
    }

    /// A seconds-long run for tests and CI (not a measurement).
    pub fn tiny(out_dir: impl Into<PathBuf>) -> Self {
        Self {
            out_dir: out_dir.into(),
            sizes: vec![6, 11],
            max_side_sparse: 11,
            budget: Duration::from_millis(5),
            min_samples: 3,
            many: 3,
            cg_side: 6,
            sphere_sides: vec![11],
            stream_len: 1 << 12,
            cape_sizes: vec![4],
            cape_steps: 20,
            self_collision_sizes: vec![8],
            two_sheet_sizes: vec![6],
            silk_table: None,
            only: None,
        }
    }
}

/// Median and quartiles of repeated runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// Median, in seconds.
    pub median: f64,
    /// First quartile, in seconds.
    pub q1: f64,
    /// Third quartile, in seconds.
    pub q3: f64,
    /// Samples taken.
    pub samples: usize,
}

impl Timing {
    /// Median, q1 and q3 of `samples` (seconds; at least one).
    pub fn of(mut samples: Vec<f64>) -> Self {
        samples.sort_by(f64::total_cmp);
        let at = |q: f64| samples[((samples.len() - 1) as f64 * q).round() as usize];
        Self {
            median: at(0.5),
            q1: at(0.25),
            q3: at(0.75),
            samples: samples.len(),
        }
    }

    /// `median (q1–q3)` in a readable unit.
    pub fn cell(&self) -> String {
        format!(
            "{} ({}–{})",
            human(self.median),
            human(self.q1),
            human(self.q3)
        )
    }
}

/// Seconds as µs or ms, three significant digits.
fn human(s: f64) -> String {
    if s < 1e-3 {
        format!("{:.1} µs", s * 1e6)
    } else if s < 1.0 {
        format!("{:.2} ms", s * 1e3)
    } else {
        format!("{s:.2} s")
    }
}

/// Samples `sample` (which times what it measures and returns seconds):
/// two warm-up calls, then samples until `budget` has passed and there are
/// `min_samples`.
pub fn time_samples(
    budget: Duration,
    min_samples: usize,
    mut sample: impl FnMut() -> f64,
) -> Timing {
    for _ in 0..2 {
        sample();
    }
    let start = Instant::now();
    let mut samples = Vec::new();
    while samples.len() < min_samples.max(1) || start.elapsed() < budget {
        samples.push(sample());
    }
    Timing::of(samples)
}

/// [`time_samples`] of the whole of `run`.
pub fn time_runs(budget: Duration, min_samples: usize, mut run: impl FnMut()) -> Timing {
    time_samples(budget, min_samples, || {
        let t = Instant::now();
        run();
        t.elapsed().as_secs_f64()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_perf_page_runs_end_to_end_on_a_tiny_configuration() {
        let dir = std::env::temp_dir().join(format!("bevy_cloth_perf_{}", std::process::id()));
        let md = run(&PerfConfig::tiny(&dir), |_| {}).unwrap();
        for heading in [
            "## Time per step",
            "## Projective dynamics onto a penalty sphere",
            "## Many cloths",
            "## The frame",
            "## Sparse CG",
            "## Character cloth",
            "## Self-collision",
            "## The limit",
        ] {
            assert!(md.contains(heading), "{heading} missing:\n{md}");
        }
        // Every method ran at every tiny size, and the guard passed them.
        for (name, _, _) in sweep_methods() {
            assert!(md.contains(&format!("| {name} |")), "{name}");
        }
        assert!(!md.contains("⚠"), "{md}");
        // The sentences that name the lab step's case found it.
        assert!(md.contains("Chebyshev 32 at 11²:"), "{md}");
        assert!(md.contains("its cost − the bare step ("), "{md}");
        // The arithmetic limit is measured at the widest level this CPU
        // runs, and the triads at every level it runs.
        let levels = bevy_cloth::solver::Simd::supported();
        let widest = levels.last().unwrap();
        assert!(
            md.contains(&format!("at {}'s {} lanes", widest.name(), widest.lanes())),
            "{md}"
        );
        let names: Vec<_> = levels.iter().map(|l| l.name()).collect();
        assert!(md.contains(&format!("runs ({})", names.join(", "))), "{md}");
        let svg = std::fs::read_to_string(dir.join("perf-scaling.svg")).unwrap();
        assert!(svg.contains("<circle") && svg.contains("chebyshev 32"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn timing_takes_the_median_and_quartiles() {
        let t = Timing::of(vec![5.0, 1.0, 3.0, 2.0, 4.0]);
        assert_eq!((t.median, t.q1, t.q3, t.samples), (3.0, 2.0, 4.0, 5));
    }
}
