//! `spomp`: validate, inspect and run air–ground robot team missions.

use std::process::ExitCode;

fn main() -> ExitCode {
    spomp::cli::main()
}
