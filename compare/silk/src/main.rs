//! bevy_cloth against bevy_silk on the same cloths, in one process.
//!
//! The cloth is the lab's: `n×n` vertices over 10×10 units, two triangles
//! per cell, the corners `0` and `n − 1` fixed, gravity 9.8, velocity
//! damping 0.99 (bevy_silk's default friction 0.01 is the same factor) and
//! a fixed step of 1/30 s. bevy_silk gets its stick solver with 32
//! iterations (`update_points` then `update_sticks(32)`, what its `update`
//! system calls per frame, minus the anchor refresh, which does nothing for
//! a cloth that does not move); bevy_cloth gets its position-based method
//! (Jacobi strain limiting) and its implicit Chebyshev method, 32 iterations
//! each, with the total mass 441 and `k = 8000` of the lab.
//!
//! Every method runs `WARM` steps from rest; then the step from that state
//! is timed again and again (the state restored, untimed, before each) for
//! at least `BUDGET` and `MIN_SAMPLES` samples; the table gives the median
//! and the quartiles and the ratio of medians (bevy_silk / bevy_cloth).
//! Each side then runs `FURTHER` more steps from the warm state, and the
//! table gives its largest relative edge stretch `(l − L)/L` — how far each
//! is from satisfying its edges after the same simulated time.
//!
//!     cargo run --release --manifest-path compare/silk/Cargo.toml [-- --out FILE] [--sizes 21,51]

use std::hint::black_box;
use std::time::{Duration, Instant};

use bevy::math::Affine3A;
use bevy_017::math::{Mat4, Vec3 as Vec3Silk};
use bevy_017::platform::collections::HashMap;
use bevy_cloth::model::{ClothModel, ClothState};
use bevy_cloth::solver::Method;
use bevy_cloth_report::perf::{Timing, scale_model, time_samples};
use bevy_cloth::solver::implicit::{ImplicitSolver, ImplicitWorkspace};
use bevy_cloth::solver::pbd::{PbdSolver, PbdWorkspace};
use bevy_cloth::solver::{StepParams, max_stretch};
use bevy_silk::components::cloth::Cloth as SilkCloth;
use bevy_silk::prelude::{StickGeneration, StickLen, StickMode};
use bevy_silk::vertex_anchor::VertexAnchor;

const WARM: usize = 10;
const FURTHER: usize = 30;
const MIN_SAMPLES: usize = 15;
const BUDGET: f64 = 1.5;
const ITERATIONS: u32 = 32;

struct Ours {
    timing: Timing,
    stretch: f32,
    finite: bool,
}

/// Steps `state` `WARM` times from where it is; times the step from that
/// warm state again and again (`restore` puts the warm state back, untimed,
/// before each sample); then steps `state` `FURTHER` times on from it.
fn warm_timed<S: Clone>(
    state: &mut S,
    mut step: impl FnMut(&mut S),
    restore: impl Fn(&mut S, &S),
) -> Timing {
    for _ in 0..WARM {
        step(state);
    }
    let warm = state.clone();
    let mut timed = warm.clone();
    let timing = time_samples(Duration::from_secs_f64(BUDGET), MIN_SAMPLES, || {
        restore(&mut timed, &warm);
        let t = Instant::now();
        step(&mut timed);
        black_box(&timed);
        t.elapsed().as_secs_f64()
    });
    for _ in 0..FURTHER {
        step(state);
    }
    timing
}

fn ours(model: &ClothModel, step: impl FnMut(&mut ClothState)) -> Ours {
    let mut state = ClothState::at_rest(model, &Affine3A::IDENTITY);
    let timing = warm_timed(&mut state, step, |timed, warm| timed.copy_from(warm));
    Ours {
        timing,
        stretch: max_stretch(model, &state.positions),
        finite: state.is_finite(),
    }
}

/// bevy_silk's stick solver on the same vertices and triangles.
fn silk(model: &ClothModel, params: &StepParams) -> (Timing, f32) {
    let topology = model.topology();
    let positions: Vec<Vec3Silk> = topology
        .rest_positions()
        .iter()
        .map(|p| Vec3Silk::from_array(p.to_array()))
        .collect();
    let indices: Vec<u32> = topology.triangles().iter().flatten().copied().collect();
    let anchors: HashMap<usize, VertexAnchor> = model
        .pins()
        .iter()
        .map(|&i| (i as usize, VertexAnchor::default()))
        .collect();
    let mut cloth = SilkCloth::new(
        &positions,
        &indices,
        anchors,
        StickGeneration::Triangles,
        StickLen::Auto,
        StickMode::Fixed,
        &Mat4::IDENTITY,
    );
    let dt = params.dt as f32;
    let gravity = Vec3Silk::from_array(params.gravity.to_array()) * dt * dt;
    let step = |cloth: &mut SilkCloth| {
        cloth.update_points(params.damping, gravity);
        cloth.update_sticks(ITERATIONS as u8);
    };
    let timing = warm_timed(&mut cloth, step, |timed, warm| {
        timed
            .current_point_positions
            .copy_from_slice(&warm.current_point_positions);
        timed
            .previous_point_positions
            .copy_from_slice(&warm.previous_point_positions);
    });
    let x = &cloth.current_point_positions;
    let stretch = cloth
        .stick_lengths
        .iter()
        .map(|([a, b], rest)| (x[*a].distance(x[*b]) - rest) / rest)
        .fold(f32::NEG_INFINITY, f32::max);
    (timing, stretch)
}

fn ms(t: f64) -> String {
    format!("{:.3}", t * 1e3)
}

fn main() {
    let mut out = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/perf/silk.md").to_string();
    let mut sizes = vec![21, 51, 101, 201];
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match (arg.as_str(), args.next()) {
            ("--out", Some(path)) => out = path,
            ("--sizes", Some(list)) => {
                sizes = list
                    .split(',')
                    .map(|s| s.trim().parse().expect("--sizes takes numbers like 21,51"))
                    .collect()
            }
            _ => {
                eprintln!("usage: silk_compare [--out FILE] [--sizes 21,51,101,201]");
                std::process::exit(2);
            }
        }
    }
    // bevy_cloth's large-cloth loops use Bevy's compute pool when it has
    // more than one thread; this process has no pool, so both sides run on
    // one thread.
    let params = StepParams::LAB;
    let mut table = String::from(
        "| n² | vertices | bevy_silk (ms, q1–q3) | bevy_cloth PBD (ms, q1–q3) | ratio silk/PBD \
         | bevy_cloth Chebyshev (ms, q1–q3) | ratio silk/Chebyshev \
         | max stretch silk | max stretch PBD | max stretch Chebyshev |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    for n in sizes {
        let model = scale_model(n);
        let (silk_t, silk_stretch) = silk(&model, &params);
        let mut pbd_ws = PbdWorkspace::default();
        let config = PbdSolver {
            iterations: ITERATIONS,
        };
        let pbd = ours(&model, |state| {
            Method::step(&config, &model, state, &params, &[], &mut pbd_ws).expect("valid step");
        });
        let mut cheb_ws = ImplicitWorkspace::default();
        let config = ImplicitSolver::chebyshev(ITERATIONS, 0.995);
        let cheb = ours(&model, |state| {
            Method::step(&config, &model, state, &params, &[], &mut cheb_ws).expect("valid step");
        });
        assert!(pbd.finite && cheb.finite, "bevy_cloth diverged at {n}²");
        let line = format!(
            "| {n}² | {} | {} ({}–{}) | {} ({}–{}) | {:.1} | {} ({}–{}) | {:.1} | {:.3} | {:.3} | {:.3} |\n",
            n * n,
            ms(silk_t.median),
            ms(silk_t.q1),
            ms(silk_t.q3),
            ms(pbd.timing.median),
            ms(pbd.timing.q1),
            ms(pbd.timing.q3),
            silk_t.median / pbd.timing.median,
            ms(cheb.timing.median),
            ms(cheb.timing.q1),
            ms(cheb.timing.q3),
            silk_t.median / cheb.timing.median,
            silk_stretch,
            pbd.stretch,
            cheb.stretch,
        );
        print!("{line}");
        table.push_str(&line);
    }
    let doc = format!(
        "<!-- written by `cargo run --release --manifest-path compare/silk/Cargo.toml` -->\n\
         Per step, {ITERATIONS} iterations, single thread: the step from the state after \
         {WARM} steps from rest, timed for at least {BUDGET} s and {MIN_SAMPLES} samples; \
         stretch after {} steps.\n\n{table}",
        WARM + FURTHER
    );
    if let Some(dir) = std::path::Path::new(&out).parent() {
        std::fs::create_dir_all(dir).expect("create the output folder");
    }
    std::fs::write(&out, doc).expect("write the table");
    eprintln!("wrote {out}");
}
