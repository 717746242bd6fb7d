//! Writes bevy_cloth's measured pages.
//!
//! ```text
//! cargo run --release -p bevy_cloth_report [-- --out docs/report] [--tiny]
//! cargo run --release -p bevy_cloth_report -- --stability [--out docs/report] [--tiny]
//! cargo run --release -p bevy_cloth_report -- --contact [--out docs/report] [--tiny] [--only NAME]
//! cargo run --release -p bevy_cloth_report -- --perf [--out docs] [--tiny] [--sizes 21,51] [--only NAME] [--seconds S]
//! cargo run --release -p bevy_cloth_report -- --perf --section character|self-collision [--out docs] [--tiny]
//! ```
//!
//! With no mode: the error-against-run-time report (`README.md` and SVG
//! charts), every method measured against the exact implicit-Euler step.
//! `--stability`: the stability map (`stability.md`, `stability.svg`), every
//! method × stiffness × time step, resolutions and extreme cases, classified
//! against the exact method. `--contact`: the stability map's contact
//! extreme cases alone, rewritten in place in an existing `stability.md`
//! (they take minutes where the whole map takes an hour; with `--only`,
//! just the rows whose name contains NAME). `--perf`: the
//! performance page (`perf.md`, `perf-scaling.svg`).

use std::process::ExitCode;
use std::time::{Duration, Instant};

use bevy_cloth_report::accuracy::{self, ReportConfig};
use bevy_cloth_report::perf::{self, PerfConfig};
use bevy_cloth_report::stability::{self, StabilityConfig};

const USAGE: &str = "usage: bevy_cloth_report [--stability | --contact | --perf] [--out DIR] [--tiny] \
                     [--sizes 21,51] [--only NAME] [--seconds S] [--section character|self-collision] \
                     (--only: --perf or --contact; --section: --perf)";

#[derive(PartialEq)]
enum Mode {
    Accuracy,
    Stability,
    Contact,
    Perf,
}

struct Options {
    mode: Mode,
    out: Option<String>,
    tiny: bool,
    sizes: Option<Vec<usize>>,
    only: Option<String>,
    seconds: Option<f64>,
    section: Option<String>,
}

/// Why the command line was not run: `--help`, or what is wrong.
enum Stop {
    Help,
    Bad(String),
}

impl From<lexopt::Error> for Stop {
    fn from(e: lexopt::Error) -> Self {
        Self::Bad(e.to_string())
    }
}

impl From<String> for Stop {
    fn from(e: String) -> Self {
        Self::Bad(e)
    }
}

fn parse(mut parser: lexopt::Parser) -> Result<Options, Stop> {
    use lexopt::prelude::*;
    let mut o = Options {
        mode: Mode::Accuracy,
        out: None,
        tiny: false,
        sizes: None,
        only: None,
        seconds: None,
        section: None,
    };
    while let Some(arg) = parser.next()? {
        match arg {
            Long("stability") => o.mode = Mode::Stability,
            Long("contact") => o.mode = Mode::Contact,
            Long("perf") => o.mode = Mode::Perf,
            Long("out") => o.out = Some(parser.value()?.string()?),
            Long("tiny") => o.tiny = true,
            Long("sizes") => {
                let list = parser
                    .value()?
                    .string()?
                    .split(',')
                    .map(|n| n.trim().parse::<usize>())
                    .collect::<Result<Vec<_>, _>>()
                    .map_err(|e| format!("--sizes: {e}"))?;
                if list.iter().any(|&n| n < 2) {
                    return Err(Stop::Bad("--sizes: every size must be at least 2".into()));
                }
                o.sizes = Some(list);
            }
            Long("only") => o.only = Some(parser.value()?.string()?),
            Long("section") => {
                let name = parser.value()?.string()?;
                if !perf::SECTIONS.iter().any(|(n, _)| *n == name) {
                    let names: Vec<_> = perf::SECTIONS.iter().map(|(n, _)| *n).collect();
                    return Err(Stop::Bad(format!("--section: one of {}", names.join(", "))));
                }
                o.section = Some(name);
            }
            Long("seconds") => match parser.value()?.parse::<f64>() {
                Ok(s) if s > 0.0 && s.is_finite() => o.seconds = Some(s),
                _ => return Err(Stop::Bad("--seconds needs a positive number".into())),
            },
            Long("help") | Short('h') => return Err(Stop::Help),
            _ => return Err(arg.unexpected().into()),
        }
    }
    if o.mode != Mode::Perf && (o.sizes.is_some() || o.seconds.is_some()) {
        return Err(Stop::Bad("--sizes and --seconds go with --perf".into()));
    }
    if o.only.is_some() && !matches!(o.mode, Mode::Perf | Mode::Contact) {
        return Err(Stop::Bad("--only goes with --perf or --contact".into()));
    }
    if o.section.is_some() && (o.mode != Mode::Perf || o.only.is_some() || o.sizes.is_some()) {
        return Err(Stop::Bad(
            "--section goes with --perf, without --only or --sizes".into(),
        ));
    }
    Ok(o)
}

fn main() -> ExitCode {
    let o = match parse(lexopt::Parser::from_env()) {
        Ok(o) => o,
        Err(Stop::Help) => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(Stop::Bad(e)) => {
            eprintln!("error: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    let result = match o.mode {
        Mode::Accuracy => {
            let out = o.out.unwrap_or_else(|| "docs/report".into());
            let config = if o.tiny {
                ReportConfig::tiny(&out)
            } else {
                ReportConfig::full(&out)
            };
            accuracy::run(&config).map(|_| format!("wrote {out}/README.md"))
        }
        Mode::Stability => {
            let out = o.out.unwrap_or_else(|| "docs/report".into());
            let config = if o.tiny {
                StabilityConfig::tiny(&out)
            } else {
                StabilityConfig::full(&out)
            };
            stability::run(&config).map(|_| format!("wrote {out}/stability.md"))
        }
        Mode::Contact => {
            let out = o.out.unwrap_or_else(|| "docs/report".into());
            let config = if o.tiny {
                StabilityConfig::tiny(&out)
            } else {
                StabilityConfig::full(&out)
            };
            stability::rerun_contact(&config, o.only.as_deref())
                .map(|_| format!("rewrote the contact cases in {out}/stability.md"))
        }
        Mode::Perf => {
            let out = o.out.unwrap_or_else(|| "docs".into());
            let mut config = if o.tiny {
                PerfConfig::tiny(&out)
            } else {
                PerfConfig::full(&out)
            };
            if let Some(sizes) = o.sizes {
                config.sizes = sizes;
            }
            if let Some(s) = o.seconds {
                config.budget = Duration::from_secs_f64(s);
            }
            if let Some(name) = o.section {
                return finish(
                    perf::rerun_section(&config, &name)
                        .map(|_| format!("rewrote the {name} section of {out}/perf.md")),
                );
            }
            let profiling = o.only.is_some();
            config.only = o.only;
            let start = Instant::now();
            perf::run(&config, |what| {
                eprintln!("[{:>6.1} s] {what}", start.elapsed().as_secs_f64())
            })
            .map(|md| {
                if profiling {
                    md
                } else {
                    format!("wrote {out}/perf.md and {out}/perf-scaling.svg")
                }
            })
        }
    };
    finish(result)
}

/// Prints what a run wrote, or its error, and the exit code.
fn finish(result: std::io::Result<String>) -> ExitCode {
    match result {
        Ok(message) => {
            println!("{message}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
