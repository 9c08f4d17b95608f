//! The lab's `spomp`: the built-in node types plus `teammates_heard`, and the same CLI
//! (`validate`, `sim`, `nodes`, `schema`, …).

use std::process::ExitCode;

fn main() -> ExitCode {
    match custom_node::lab_registry(custom_node::LabSettings::default()) {
        Ok(registry) => spomp::cli::main_with(registry),
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}
