//! The page: `perf.md` and `perf-scaling.svg` from the sweep and the probe.

use std::fmt::Write as _;
use std::path::Path;

use bevy::tasks::{ComputeTaskPool, TaskPoolBuilder};
use plotters::prelude::*;

use super::*;

/// The sweep's name for the lab step, Chebyshev 32.
const LAB_CASE: &str = "chebyshev 32";

/// Runs the page and writes its files. Returns the markdown.
pub fn run(config: &PerfConfig, progress: impl Fn(&str)) -> std::io::Result<String> {
    std::fs::create_dir_all(&config.out_dir)?;
    crate::chart::register_chart_font();
    // Two compute threads for the parallel columns (Bevy's default plugin
    // would give this 2-core machine one).
    let pool = ComputeTaskPool::get_or_init(|| TaskPoolBuilder::new().num_threads(2).build());
    let threads = pool.thread_num();

    if config.only.is_some() {
        let cases = sweep(config, &progress);
        let mut md = String::new();
        for c in cases {
            write!(md, "{} {}²: {}", c.method, c.n, c.serial.cell()).ok();
            if let Some(p) = c.parallel {
                write!(md, "; parallel {}", p.cell()).ok();
            }
            writeln!(md, "; guard {}", c.guard.as_deref().unwrap_or("silent")).ok();
        }
        return Ok(md);
    }
    progress("limits");
    let limits = limits(config);
    let cases = sweep(config, &progress);
    progress("onto a sphere");
    let sphere = sphere_steps(config);
    progress("SIMD levels");
    let levels = simd_levels(config);
    progress("many cloths");
    let frame = frame_costs(config);
    let one_app = frame.one;
    let many_app = many_cloths(config, config.many);
    progress("CG parts");
    let cg = cg_parts(config);
    progress("character cloth");
    let capes = cape_rows(config);
    progress("self-collision");
    let self_collision = self_collision_rows(config);
    progress("two sheets");
    let two_sheets = two_sheets_rows(config);

    let mut md = String::new();
    let w = &mut md;
    writeln!(w, "# Performance").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "Written by `cargo run --release -p bevy_cloth_report -- --perf` ({}). Machine: {}, {} logical cores; \
         compute pool for the parallel columns: {threads} threads. Build: release, baseline \
         x86-64 target (SSE2, 4-lane packed `f32`); the spring pass runs at the fastest SIMD \
         level the CPU has, chosen at run time: here {} (every level gives the same bits; see \
         \"SIMD levels\").",
        std::env::consts::ARCH,
        crate::chart::machine(),
        std::thread::available_parallelism().map_or(0, |n| n.get()),
        bevy_cloth::solver::Simd::Auto.resolve().name(),
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "Method: each case starts every sample from the same swinging state (20 Chebyshev \
         steps from rest; the state copy is not timed) and warms up twice. The cases of a \
         size take turns, {} rounds of a slice each, {:.1} s and at least {} samples per case \
         in all: a slow phase of this shared machine falls on every method of the size alike, \
         so ratios within a column are fair. Cells are `median (first–third quartile)`. The cloth \
         is the lab's, physically the same at every size: 10×10 units, total mass 441, \
         corners pinned, k = 8000 at every resolution (a row of n − 1 springs in series has \
         stiffness k/(n − 1) and n rows act in parallel, so the sheet's stiffness stays about \
         k), dt = 0.0333, damping 0.99. \"guard\" is the divergence guard's default check on \
         the timed step's result: silent means it would have accepted it.",
        SWEEP_ROUNDS,
        config.budget.as_secs_f64(),
        config.min_samples
    )
    .ok();
    writeln!(w).ok();

    writeln!(w, "## Time per step against cloth size").ok();
    writeln!(w).ok();
    writeln!(w, "![time per step against vertices](perf-scaling.svg)").ok();
    writeln!(w).ok();
    write!(w, "| method |").ok();
    for n in &config.sizes {
        write!(w, " {n}² ({} vertices) |", n * n).ok();
    }
    writeln!(w).ok();
    write!(w, "|---|").ok();
    for _ in &config.sizes {
        write!(w, "---|").ok();
    }
    writeln!(w).ok();
    for (name, _, _) in sweep_methods() {
        write!(w, "| {name} |").ok();
        for &n in &config.sizes {
            match cases.iter().find(|c| c.method == name && c.n == n) {
                Some(c) => {
                    write!(w, " {}", c.serial.cell()).ok();
                    if let Some(p) = c.parallel {
                        write!(w, "; {threads} threads: {}", p.cell()).ok();
                    }
                    match &c.guard {
                        None => write!(w, " |").ok(),
                        Some(why) => write!(w, " ⚠ guard: {why} |").ok(),
                    };
                }
                None => {
                    write!(w, " – |").ok();
                }
            }
        }
        writeln!(w).ok();
    }
    writeln!(w).ok();
    let silent = cases.iter().filter(|c| c.guard.is_none()).count();
    writeln!(
        w,
        "{silent} of {} timed steps pass the guard's check. Sparse methods stop at {}².",
        cases.len(),
        config.max_side_sparse
    )
    .ok();
    writeln!(w).ok();
    if let Some(big) = cases
        .iter()
        .filter(|c| c.method == LAB_CASE)
        .max_by_key(|c| c.n)
    {
        let best = big
            .parallel
            .map_or(big.serial.median, |p| p.median.min(big.serial.median));
        writeln!(
            w,
            "Chebyshev 32 at {}²: {:.1} steps per second ({}).",
            big.n,
            1.0 / best,
            human(best)
        )
        .ok();
        writeln!(w).ok();
    }

    writeln!(w, "## Projective dynamics onto a penalty sphere").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "`pd` (its preset, one thread) on the same cloth falling from rest onto the report's \
         penalty sphere (the lab's sphere, stiffness 1e4): {} consecutive steps after 20, each \
         timed. Each step whose set of vertices near the sphere changed updates the global \
         solve (the multigrid's coarse matrices take the change, `Pᵀ ΔS P`).",
        sphere.first().map_or(0, |r| r.steps)
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "| side | per step | iterations per step (mean) | steps whose contacts changed |"
    )
    .ok();
    writeln!(w, "|---|---|---|---|").ok();
    for row in &sphere {
        writeln!(
            w,
            "| {}² | {} | {:.1} | {} of {} |",
            row.n,
            row.step.cell(),
            row.iterations,
            row.changes,
            row.steps
        )
        .ok();
    }
    writeln!(w).ok();

    if let Some(base) = levels.first() {
        writeln!(w, "## SIMD levels").ok();
        writeln!(w).ok();
        writeln!(
            w,
            "Every SIMD level this CPU runs, one thread: the lab step (Chebyshev 32) at 21² and at \
             the largest size on the stencil kernels (`solver::engine::stencil`, the default for a grid \
             numbered row by row, as every builder's: structure-of-arrays spring and vertex \
             passes, both compiled for each level); for comparison the same step at 21² on the \
             general kernels (`solver::engine::simd`: only their spring pass is compiled per level, the \
             vertex gather is the baseline's) and their 32 spring passes alone. Each kind of \
             kernel gives the same bits at every level (tested); the two kinds agree within \
             `f32` rounding (a vertex sums its springs in another order). `auto` runs AVX2 \
             where the CPU has it."
        )
        .ok();
        writeln!(w).ok();
        let large_n = base.large.as_ref().map(|(n, _)| *n);
        let large_head = large_n.map_or(String::new(), |n| format!(" step at {n}² |"));
        writeln!(
            w,
            "| level | lanes | step at 21² |{large_head} step time / {}'s | general kernels: step at 21² | their 32 spring passes |",
            base.level.name()
        )
        .ok();
        writeln!(
            w,
            "|---|---|---|{}---|---|---|",
            if large_n.is_some() { "---|" } else { "" }
        )
        .ok();
        for row in &levels {
            let large = row
                .large
                .as_ref()
                .map_or(String::new(), |(_, t)| format!(" {} |", t.cell()));
            writeln!(
                w,
                "| {} | {} | {} |{large} {:.2}× | {} | {} |",
                row.level.name(),
                row.level.lanes(),
                row.step.cell(),
                row.step.median / base.step.median,
                row.general.cell(),
                row.springs.cell(),
            )
            .ok();
        }
        writeln!(w).ok();
        writeln!(w, "The lab step's target was 40 µs.").ok();
        writeln!(w).ok();
    }

    writeln!(w, "## Many cloths").ok();
    writeln!(w).ok();
    let single = cases
        .iter()
        .find(|c| c.method == LAB_CASE && c.n == 21)
        .map(|c| c.serial.median);
    writeln!(
        w,
        "One `App::update` (one fixed step of every cloth, guard and stats included; \
         `MinimalPlugins` + `ClothPlugins`, the compute pool at {threads} threads) with lab \
         cloths of 21², Chebyshev 32:"
    )
    .ok();
    writeln!(w).ok();
    writeln!(w, "| cloths | per update | per cloth |").ok();
    writeln!(w, "|---|---|---|").ok();
    for (count, t) in [(1, one_app), (config.many, many_app)] {
        writeln!(
            w,
            "| {count} | {} | {} |",
            t.cell(),
            human(t.median / count as f64)
        )
        .ok();
    }
    writeln!(w).ok();
    if let Some(single) = single {
        writeln!(
            w,
            "{} cloths take {:.2}× the time of {} bare solver steps of one cloth ({} each): the \
             systems run the cloths with `par_iter_mut` on the compute pool.",
            config.many,
            many_app.median / (config.many as f64 * single),
            config.many,
            human(single)
        )
        .ok();
        writeln!(w).ok();
    }

    writeln!(w, "## The frame").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "One `App::update` of `MinimalPlugins` alone (Bevy's own frame) and with \
         `ClothPlugins` and one lab cloth (21², Chebyshev 32), timed in turns, under Bevy's \
         default multi-threaded executor and with every schedule single-threaded:"
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "| executor | Bevy's frame | with one cloth | the cloth's cost | its cost − the bare step ({}) |",
        human(frame.step.median)
    )
    .ok();
    writeln!(w, "|---|---|---|---|---|").ok();
    for (name, bare, one) in [
        ("multi-threaded (default)", frame.bare, frame.one),
        ("single-threaded", frame.bare_single, frame.one_single),
    ] {
        let cost = one.median - bare.median;
        let over = human(cost - frame.step.median);
        writeln!(
            w,
            "| {name} | {} | {} | {} | {over} |",
            bare.cell(),
            one.cell(),
            human(cost)
        )
        .ok();
    }
    writeln!(w).ok();
    writeln!(
        w,
        "The cloth's cost is what the cloth plugins and the cloth add to Bevy's frame: the \
         step, the guard's backup and checks, the stats and the scheduling. The cloth systems \
         run in `ClothSchedule`, whose executor is single-threaded, from one exclusive system, \
         and the `PostUpdate` system that makes pins follow a moved entity is skipped by its \
         run condition while no cloth's entity moves: under the multi-threaded executor every \
         system that runs is handed to another thread, which costs tens of µs on this machine \
         (Bevy's own frame of empty schedules is that cost over and over). The issue's target \
         was the bare step + 20 µs."
    )
    .ok();
    writeln!(w).ok();

    writeln!(w, "## Sparse CG against its parts").ok();
    writeln!(w).ok();
    let parts = cg.spmv25.median + cg.assembly.median;
    writeln!(
        w,
        "The assignment's cloth at {0}×{0} (stretch, shear and bending springs; `A` of order \
         {1} with {2} stored nonzeros), one linearly implicit step with 25 CG iterations \
         (tolerance 0, so all 25 run; {3} ran):",
        cg.side, cg.dimension, cg.nonzeros, cg.iterations
    )
    .ok();
    writeln!(w).ok();
    writeln!(w, "| part | time |").ok();
    writeln!(w, "|---|---|").ok();
    writeln!(w, "| whole step (CG 25) | {} |", cg.step.cell()).ok();
    writeln!(w, "| one assembly of `A`, `b` | {} |", cg.assembly.cell()).ok();
    writeln!(w, "| 25 products `A·v` (faer) | {} |", cg.spmv25.cell()).ok();
    writeln!(w, "| assembly + 25 products | {} |", human(parts)).ok();
    writeln!(w).ok();
    writeln!(
        w,
        "The step takes **{:.2}×** its assembly and 25 bare products (target: within 2×).",
        cg.step.median / parts
    )
    .ok();
    writeln!(w).ok();

    character_section(w, &capes, config.cape_steps);
    self_collision_section(w, &self_collision);
    two_sheets_section(w, &two_sheets);

    writeln!(w, "## The limit").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "One core, simple kernels. A triad `a = b + s·c`, at the fastest of the SIMD levels \
         this CPU runs ({}) and with its three arrays half the size of the cache it measures, \
         streams {:.1} GB/s from memory (3 × {} MiB), {:.1} GB/s from the last-level cache, \
         {:.1} GB/s from L2 ({} KiB) and {:.1} GB/s from L1 ({} KiB; {:.1} GB/s in the \
         baseline build's 4-lane code alone). Multiply–adds in 8 independent chains run at \
         {:.2} GFLOP/s scalar, {:.2} GFLOP/s in 4-lane `Vec4` and {:.2} GFLOP/s at {}'s {} \
         lanes (the widest level).",
        bevy_cloth::solver::Simd::supported()
            .iter()
            .map(|l| l.name())
            .collect::<Vec<_>>()
            .join(", "),
        limits.memory_gbs,
        (4 * config.stream_len) >> 20,
        limits.l3_gbs,
        limits.l2_gbs,
        limits.caches.l2 >> 10,
        limits.l1_gbs,
        limits.caches.l1 >> 10,
        limits.baseline_l1_gbs,
        limits.scalar_gflops,
        limits.simd_gflops,
        limits.widest_gflops,
        limits.level.name(),
        limits.level.lanes(),
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "Per step, a spring-loop method must at least move, per iteration, 40 B per spring \
         (its record, coefficients and term), 20 B per incidence (an index and a term; two per \
         spring) and 88 B per vertex, and do about 14 flops per spring, 3 per incidence and 21 \
         per vertex. Its limit is the larger of bytes / bandwidth and flops / the widest SIMD \
         rate, with the bandwidth of where one iteration's working set fits (L1 up to {} KiB, \
         L2 up to {} KiB, the last level up to {} MiB, else memory); the table gives the limit \
         as a fraction of the measured single-thread median (100 % would be at the limit). \
         A fraction above 100 % means the model is too pessimistic at that size, not that the \
         step beats the machine: it picks the bandwidth by the bytes an iteration moves, while \
         part of them still hit the faster cache.",
        limits.caches.l1 >> 10,
        limits.caches.l2 >> 10,
        limits.caches.last >> 20,
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "| method | size | bytes/step | flops/step | limit | measured | fraction of limit |"
    )
    .ok();
    writeln!(w, "|---|---|---|---|---|---|---|").ok();
    for c in &cases {
        let model = scale_model(c.n);
        if let Some((iterations, per_iteration, flops)) = work_per_iteration(&c.solver, &model) {
            let (bytes, flops) = (
                per_iteration * f64::from(iterations),
                flops * f64::from(iterations),
            );
            let bandwidth = limits.bandwidth_for(per_iteration);
            let limit = (bytes / (bandwidth * 1e9)).max(flops / (limits.widest_gflops * 1e9));
            writeln!(
                w,
                "| {} | {}² | {:.2} MB | {:.2} Mflop | {} | {} | {:.0} % |",
                c.method,
                c.n,
                bytes / 1e6,
                flops / 1e6,
                human(limit),
                human(c.serial.median),
                100.0 * limit / c.serial.median
            )
            .ok();
        }
    }
    writeln!(w).ok();
    writeln!(
        w,
        "The sparse CG step's limit is its 25 products: each streams the {} nonzeros (8 B \
         value + 8 B row index) = {:.1} MB, {:.2} ms at memory bandwidth for 25; measured \
         {}: {:.0} % of the limit.",
        cg.nonzeros,
        16.0 * cg.nonzeros as f64 / 1e6,
        25.0 * 16.0 * cg.nonzeros as f64 / (limits.memory_gbs * 1e9) * 1e3,
        human(cg.step.median),
        100.0 * 25.0 * 16.0 * cg.nonzeros as f64 / (limits.memory_gbs * 1e9) / cg.step.median
    )
    .ok();
    writeln!(w).ok();

    if let Some(path) = &config.silk_table {
        writeln!(w, "## Side by side with bevy_silk").ok();
        writeln!(w).ok();
        match std::fs::read_to_string(path) {
            Ok(table) => {
                writeln!(
                    w,
                    "From `cargo run --release --manifest-path compare/silk/Cargo.toml` (a crate \
                     outside the workspace, so bevy_silk's Bevy 0.17 stays out of our lock \
                     file). Same cloth, same vertices and triangles, 32 iterations, one thread, \
                     one process. bevy_silk's solver is Gauss–Seidel over a hash map of sticks; \
                     ours is Jacobi (PBD) or Chebyshev-accelerated Jacobi (implicit)."
                )
                .ok();
                writeln!(w).ok();
                writeln!(w, "{}", table.trim()).ok();
            }
            Err(_) => {
                writeln!(
                    w,
                    "Not run: {} is missing (run `bash scripts/perf.sh`).",
                    path.display()
                )
                .ok();
            }
        }
        writeln!(w).ok();
    }

    writeln!(w, "## Rerun").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "`bash scripts/perf.sh` (about 15 minutes on this machine, the first time longer: it \
         builds bevy_silk's Bevy) reruns the bevy_silk comparison and then this page; \
         `cargo run --release -p bevy_cloth_report -- --perf` reruns this page alone, and \
         `-- --perf --section character` (or `self-collision`) one section of it, in place, \
         marked as rerun on its own. The criterion \
         benchmarks (`cargo bench`) time the same steps at 21² and 101²."
    )
    .ok();

    std::fs::write(config.out_dir.join("perf.md"), &md)?;
    chart(&config.out_dir.join("perf-scaling.svg"), &cases).map_err(std::io::Error::other)?;
    Ok(md)
}

fn chart(path: &Path, cases: &[Case]) -> Result<(), String> {
    let point = |c: &Case| ((c.n * c.n) as f64, c.serial.median * 1e3);
    let (x_lo, x_hi, y_lo, y_hi) = cases.iter().map(point).fold(
        (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64),
        |(x_lo, x_hi, y_lo, y_hi), (x, y)| (x_lo.min(x), x_hi.max(x), y_lo.min(y), y_hi.max(y)),
    );
    if cases.is_empty() {
        return Ok(());
    }
    let methods = sweep_methods();
    let series: Vec<(&str, Vec<(f64, f64)>)> = methods
        .iter()
        .map(|(name, _, _)| {
            let points = cases.iter().filter(|c| c.method == *name).map(point);
            (name.as_str(), points.collect::<Vec<_>>())
        })
        .filter(|(_, points)| !points.is_empty())
        .collect();
    crate::chart::log_log_chart(
        path,
        (900, 600),
        "Time per step against vertex count (single thread, log–log)",
        ("vertices", "ms per step"),
        (x_lo / 1.3..x_hi * 1.3, y_lo / 2.0..y_hi * 2.0),
        &series,
        SeriesLabelPosition::UpperLeft,
    )
}

/// The character scene's table (see [`cape_rows`]).
pub(super) fn character_section(w: &mut String, rows: &[CapeRow], steps: usize) {
    writeln!(w, "## Character cloth").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "The cape example's scene without a window (`headless --scene cape`): a character \
         made in code gets up to speed, jumps, turns about and is teleported 100 m at 6 s, \
         {steps} steps at 60 Hz, one thread, in a cape (tethers at 1 %, max distance, \
         backstop) and a 480-vertex skirt, both feeling half of its velocity and a quarter of \
         its acceleration. The time is the cape's step (solver only; median, quartiles over \
         the run's steps); stretch is each garment's largest at any step; \"inside\" counts \
         garment vertices found inside a body capsule after a step, over the run."
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "| cape vertices | method | cape step | cape stretch | skirt stretch | inside | clean |"
    )
    .ok();
    writeln!(w, "|---|---|---|---|---|---|---|").ok();
    for r in rows {
        writeln!(
            w,
            "| {} | {} | {} | {:.1} % | {:.1} % | {} | {} |",
            r.vertices,
            r.method,
            r.step.cell(),
            100.0 * r.stretch.0,
            100.0 * r.stretch.1,
            r.penetrations,
            if r.clean { "yes" } else { "no" }
        )
        .ok();
    }
    writeln!(w).ok();
    writeln!(
        w,
        "Issue O's target for a 4,000-vertex cape is 0.5 ms per step and 2 % stretch with \
         nothing inside the body; \"stiff\" keeps the body clear, and its cost is its \
         refinement near colliders (the body is always near: up to 16× its substeps in the \
         preset, at most 4× in the rows that say so, none in the rows without). With chains \
         (`XpbdSolver::chains`) each substep solves the cape's rows, columns and diagonal \
         lines of stretch springs whole before its sweep, eight chains that share no \
         vertex at a time, so a pull passes along them at once (a 64² grid's step, 16 \
         substeps: 0.66 ms without chains, 2.73 ms with them, medians of twelve rounds \
         of 100 steps)."
    )
    .ok();
    writeln!(w).ok();
    character_reading(w, rows);
}

/// What the character table says about the refinement's cap and issue O's
/// budget, read off its rows (so a rerun keeps it true).
fn character_reading(w: &mut String, rows: &[CapeRow]) {
    let row = |vertices: usize, method: &str| {
        rows.iter()
            .find(|r| r.vertices == vertices && r.method == method)
    };
    let percent = |s: f32| format!("{:.1} %", 100.0 * s);
    let mut sizes: Vec<usize> = rows.iter().map(|r| r.vertices).collect();
    sizes.dedup();
    let mut parts = Vec::new();
    for &v in &sizes {
        if let (Some(p), Some(g)) = (row(v, "stiff"), row(v, "stiff, refinement ≤ 4")) {
            parts.push(format!(
                "at {v} vertices to {:.2} of the preset's step ({} against {}), its stretch \
                 {} in the cape and {} in the skirt against {} and {}",
                g.step.median / p.step.median,
                human(g.step.median),
                human(p.step.median),
                percent(g.stretch.0),
                percent(g.stretch.1),
                percent(p.stretch.0),
                percent(p.stretch.1),
            ));
        }
    }
    if !parts.is_empty() {
        writeln!(
            w,
            "Capping the refinement near colliders at 4× (`XpbdSolver::GARMENT`, the cape \
             example's garments and the settings panel's refinement slider) takes the cape {}.",
            parts.join("; ")
        )
        .ok();
        writeln!(w).ok();
    }
    let stiff = bevy_cloth::XpbdSolver::STIFF;
    let most = stiff.substeps(1.0 / 60.0) * stiff.max_refinement;
    if let Some(p) = sizes.last().and_then(|&v| row(v, "stiff")) {
        let per = p.step.median / (p.vertices as f64 * f64::from(most));
        writeln!(
            w,
            "Issue O's 0.5 ms at 4,000 vertices: the preset's row at {} vertices takes at \
             least {:.0} ns per vertex and substep (at most {most} substeps a step, {} refined \
             up to {}×), so 0.5 ms buys about {:.0} substeps a step of that cape, where every \
             row within 5 % stretch refines.",
            p.vertices,
            per * 1e9,
            stiff.substeps(1.0 / 60.0),
            stiff.max_refinement,
            0.5e-3 / (per * p.vertices as f64),
        )
        .ok();
        writeln!(w).ok();
    }
}

/// The self-collision table (see [`self_collision_rows`]).
pub(super) fn self_collision_section(w: &mut String, rows: &[SelfCollisionRow]) {
    writeln!(w, "## Self-collision").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "A cotton sheet (1 m × 1 m, n×n vertices) folded in four and dropped 5 cm onto the \
         ground (`contact::folded` in the report's crate; the stability map's \"folded\" \
         case), one step at 60 Hz on one thread, with and without `SelfCollision::for_model` \
         (thickness 0.9 of the shortest edge): `stiff` resolves the pairs in every substep, \
         PBD after each of its strain-limiting iterations, `pd` as penalty terms of its \
         objective (then after its step), Chebyshev after its step (up to \
         four passes, ending once one has settled, with the pair list kept while the cloth moves \
         less than an eighth of the thickness, `SKIN`). The step includes the ground's swept \
         projection. **Resting**: every sample from the same state, after the layers have \
         landed on each other (40 steps of `stiff` with self-collision), median and quartiles; \
         \"added\" is the difference of the medians, also as a share of the step without. \
         **Landing**: the 40 steps of the fall from the drop, each timed once, median. A row \
         whose last resting sample was refused by the guard, or left edges through the \
         sheet's own triangles (the exact check), says so after its share."
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "| n | method | resting, without | resting, with | added | added / without | landing, without | landing, with |"
    )
    .ok();
    writeln!(w, "|---|---|---|---|---|---|---|---|").ok();
    for r in rows {
        writeln!(
            w,
            "| {}² | {} | {} | {} | {} | {:.0} %{} | {} | {} |",
            r.n,
            r.method,
            r.without.cell(),
            r.with.cell(),
            human(r.added().max(0.0)),
            100.0 * r.added() / r.without.median,
            r.broken
                .as_deref()
                .map_or(String::new(), |b| format!(" ⚠ {b}")),
            human(r.landing.0.median),
            human(r.landing.1.median),
        )
        .ok();
    }
    writeln!(w).ok();
    writeln!(
        w,
        "Issue N's targets: self-collision adds at most 50 % to a 64² cloth's Chebyshev step \
         and at most 1 ms at 101² (one thread)."
    )
    .ok();
    writeln!(w).ok();
}

/// The cloth-against-cloth table (see [`two_sheets_rows`]).
pub(super) fn two_sheets_section(w: &mut String, rows: &[TwoSheetsRow]) {
    writeln!(w, "### Cloth against cloth").ok();
    writeln!(w).ok();
    writeln!(
        w,
        "The stability map's two sheets (`two_sheets::TwoSheets` in the report's crate: two \
         n×n cotton sheets of 1 m dropped from 0.65 and 0.9 m onto a 30 cm ball on the \
         ground), in the plugin's app as a game runs it (`MinimalPlugins` + `ClothPlugins`, \
         the compute pool's threads, one fixed step per `App::update`), with and without \
         `SelfCollision::for_model` on both: with it, each sheet's own pairs, the other \
         sheet's vertices in its step, and the pass between the cloths after the steps. \
         Each update from 1 s to 2 s (the sheets lying on each other and sliding off the \
         ball) timed once, median and quartiles; without self-collision the sheets pass \
         through each other, so the two columns are of different scenes after the landing. \
         A row whose run the guard stopped, or left edges through (either sheet through the \
         other or through itself, the exact check after every timed step), says so."
    )
    .ok();
    writeln!(w).ok();
    writeln!(
        w,
        "| n | method | frame, without | frame, with | added | added / without |"
    )
    .ok();
    writeln!(w, "|---|---|---|---|---|---|").ok();
    for r in rows {
        let added = r.with.median - r.without.median;
        writeln!(
            w,
            "| 2 × {}² | {} | {} | {} | {} | {:.0} %{} |",
            r.n,
            r.method,
            r.without.cell(),
            r.with.cell(),
            human(added.max(0.0)),
            100.0 * added / r.without.median,
            r.broken
                .as_deref()
                .map_or(String::new(), |b| format!(" ⚠ {b}")),
        )
        .ok();
    }
    writeln!(w).ok();
}
