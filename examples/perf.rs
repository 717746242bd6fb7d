//! Writes the performance page `docs/perf.md` and its chart: time per step
//! of every method from 21² to 256² vertices, many cloths in one app, the
//! sparse CG step against its parts, and the machine's limits. See
//! `bevy_cloth::report::perf`.
//!
//! ```text
//! cargo run --release --example perf -- [--out docs] [--tiny] \
//!     [--sizes 21,51] [--only METHOD --seconds S]
//! ```
//!
//! `--only` times the sweep's methods whose name starts with `METHOD` (for
//! example `Chebyshev`) for `S` seconds each and prints the times instead
//! of writing the page (for profiling).
//!
//! `bash scripts/perf.sh` also reruns the bevy_silk comparison first.

use std::process::ExitCode;

use bevy_cloth::report::perf::{PerfConfig, run};

fn main() -> ExitCode {
    let mut out = String::from("docs");
    let mut tiny = false;
    let mut sizes: Option<Vec<usize>> = None;
    let mut only = None;
    let mut seconds = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--out" => match args.next() {
                Some(dir) => out = dir,
                None => return usage(),
            },
            "--tiny" => tiny = true,
            "--sizes" => match args.next().map(|list| {
                list.split(',')
                    .map(|n| n.trim().parse::<usize>())
                    .collect::<Result<Vec<_>, _>>()
            }) {
                Some(Ok(list)) if list.iter().all(|&n| n >= 2) => sizes = Some(list),
                _ => return usage(),
            },
            "--only" => match args.next() {
                Some(name) => only = Some(name),
                None => return usage(),
            },
            "--seconds" => match args.next().and_then(|s| s.parse::<f64>().ok()) {
                Some(s) if s > 0.0 && s.is_finite() => seconds = Some(s),
                _ => return usage(),
            },
            _ => return usage(),
        }
    }
    let mut config = if tiny {
        PerfConfig::tiny(&out)
    } else {
        PerfConfig::full(&out)
    };
    if let Some(sizes) = sizes {
        config.sizes = sizes;
    }
    if let Some(s) = seconds {
        config.budget = std::time::Duration::from_secs_f64(s);
    }
    let profiling = only.is_some();
    config.only = only;
    let start = std::time::Instant::now();
    match run(&config, |what| {
        eprintln!("[{:>6.1} s] {what}", start.elapsed().as_secs_f64())
    }) {
        Ok(md) if profiling => {
            print!("{md}");
            ExitCode::SUCCESS
        }
        Ok(_) => {
            eprintln!("wrote {out}/perf.md and {out}/perf-scaling.svg");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn usage() -> ExitCode {
    eprintln!("usage: perf [--out DIR] [--tiny] [--sizes 21,51] [--only METHOD] [--seconds S]");
    ExitCode::from(2)
}
