//! Writes the error-against-run-time report: `docs/report/README.md` and SVG
//! charts, every method measured against the exact implicit-Euler step.
//!
//! ```text
//! cargo run --release --example report [-- --out docs/report] [--tiny] [--stability]
//! ```
//!
//! `--stability` writes the stability map (`stability.md`, `stability.svg`)
//! instead: every method × stiffness × time step, resolutions and the
//! extreme cases, classified against the exact method.

use std::process::ExitCode;

use bevy_cloth::report::stability::{self, StabilityConfig};
use bevy_cloth::report::{ReportConfig, run};

fn main() -> ExitCode {
    let mut out = String::from("docs/report");
    let mut tiny = false;
    let mut stability_map = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--out" => match args.next() {
                Some(o) => out = o,
                None => {
                    eprintln!("error: --out needs a folder");
                    return ExitCode::from(2);
                }
            },
            "--tiny" => tiny = true,
            "--stability" => stability_map = true,
            _ => {
                eprintln!("usage: report [--out FOLDER] [--tiny] [--stability]");
                return ExitCode::from(2);
            }
        }
    }
    if stability_map {
        let config = if tiny {
            StabilityConfig::tiny(&out)
        } else {
            StabilityConfig::full(&out)
        };
        return match stability::run(&config) {
            Ok(_) => {
                println!("wrote {out}/stability.md");
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("error: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let config = if tiny {
        ReportConfig::tiny(&out)
    } else {
        ReportConfig::full(&out)
    };
    match run(&config) {
        Ok(_) => {
            println!("wrote {out}/README.md");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}
