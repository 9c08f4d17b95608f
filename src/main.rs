//! `spomp`: validate, inspect and run air–ground robot team missions.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;

/// Mission framework for air–ground robot teams.
#[derive(Parser, Debug)]
#[command(name = "spomp", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Check mission files: parse → schema → wiring → team. Exit 0 only when all are valid.
    Validate {
        /// Mission files.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Print the diagnostics as a JSON array of {file, line, column, node_path, stage, message}.
        #[arg(long)]
        json: bool,
    },
    /// Print the JSON Schema of the mission language (for editors' YAML language servers).
    Schema,
    /// List the node types with their ports.
    Nodes {
        /// Print the node manifest as JSON.
        #[arg(long)]
        json: bool,
        /// Show one node type only.
        name: Option<String>,
    },
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            // clap prints help and version to stdout with exit 0, usage errors to stderr with 2.
            let _ = e.print();
            return if e.use_stderr() { ExitCode::from(2) } else { ExitCode::SUCCESS };
        }
    };
    let result = match cli.command {
        Command::Validate { files, json } => commands::validate(&files, json),
        Command::Schema => commands::schema(),
        Command::Nodes { json, name } => commands::nodes(json, name.as_deref()),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
    }
}
