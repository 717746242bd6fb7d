//! The examples' command lines, parsed with `lexopt`: `--help` (or `-h`)
//! prints the usage and exits with status 0; a bad argument prints what is
//! wrong and the usage, and exits with status 2.

#![allow(dead_code)] // Each example uses the helpers it needs.

use std::fmt::Display;
use std::process::ExitCode;
use std::str::FromStr;

pub use lexopt::Arg::{Long, Short};
pub use lexopt::Parser;

/// Why a command line was not run.
#[derive(Debug)]
pub enum CliError {
    /// `--help` was asked for.
    Help,
    /// The arguments are wrong: what is wrong.
    Bad(String),
}

impl From<lexopt::Error> for CliError {
    fn from(e: lexopt::Error) -> Self {
        Self::Bad(e.to_string())
    }
}

impl From<String> for CliError {
    fn from(e: String) -> Self {
        Self::Bad(e)
    }
}

impl From<&str> for CliError {
    fn from(e: &str) -> Self {
        Self::Bad(e.to_owned())
    }
}

impl From<bevy_cloth::methods::UnknownMethod> for CliError {
    fn from(e: bevy_cloth::methods::UnknownMethod) -> Self {
        Self::Bad(e.to_string())
    }
}

/// Runs `parse` over this process's arguments; on `--help` or a bad
/// argument prints as the module docs say and gives the exit code.
pub fn parse_args<T>(
    usage: &str,
    parse: impl FnOnce(Parser) -> Result<T, CliError>,
) -> Result<T, ExitCode> {
    parse_from(usage, Parser::from_env(), parse)
}

/// [`parse_args`] over a given parser (for tests).
pub fn parse_from<T>(
    usage: &str,
    parser: Parser,
    parse: impl FnOnce(Parser) -> Result<T, CliError>,
) -> Result<T, ExitCode> {
    match parse(parser) {
        Ok(parsed) => Ok(parsed),
        Err(CliError::Help) => {
            // Not `println!`, which panics when the reader has gone
            // (`--help | head`).
            use std::io::Write as _;
            let _ = writeln!(std::io::stdout(), "{usage}");
            Err(ExitCode::SUCCESS)
        }
        Err(CliError::Bad(e)) => {
            eprintln!("error: {e}\n{usage}");
            Err(ExitCode::from(2))
        }
    }
}

/// The value of the option just read, parsed as `T`; the error names the
/// option and the value.
pub fn value<T>(parser: &mut Parser, flag: &str) -> Result<T, CliError>
where
    T: FromStr,
    T::Err: Display,
{
    let raw = parser.value()?;
    let text = raw
        .to_str()
        .ok_or_else(|| format!("{flag}: the value is not valid UTF-8"))?;
    text.parse()
        .map_err(|e| CliError::Bad(format!("{flag}: cannot parse '{text}': {e}")))
}
