//! Writes the error-against-run-time report: `docs/report/README.md` and SVG
//! charts, every method measured against the exact implicit-Euler step.
//!
//! ```text
//! cargo run --release --example report [-- --out docs/report] [--tiny]
//! ```

use std::process::ExitCode;

use bevy_cloth::report::{ReportConfig, run};

fn main() -> ExitCode {
    let mut out = String::from("docs/report");
    let mut tiny = false;
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
            _ => {
                eprintln!("usage: report [--out FOLDER] [--tiny]");
                return ExitCode::from(2);
            }
        }
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
