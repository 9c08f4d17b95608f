//! The subcommands.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use spomp_behaviors::NodeRegistry;
use spomp_behaviors::mission::json_schema::mission_schema;
use spomp_behaviors::mission::yaml::Loc;
use spomp_behaviors::mission::{Diagnostic, LoadOptions, LoadedMission, Rendered, Stage, load_mission_with};
use spomp_behaviors::registry::PortDirection;
use spomp_robot::RobotRuntime;

/// Renders a mission's diagnostics with their source lines.
fn render_diagnostics(loaded: &LoadedMission) -> String {
    render_located(&loaded.diagnostics, &|f| loaded.source_of(f).unwrap_or_default().to_string())
}

/// Renders located diagnostics (of missions, experiment files) with their source lines;
/// `source_of` gives a file's text (empty when unknown).
pub(crate) fn render_located(diagnostics: &[Diagnostic], source_of: &dyn Fn(&std::path::Path) -> String) -> String {
    let mut human = String::new();
    // `Rendered` hands the renderer the offending line only, never the rest of a file.
    let handler = miette::GraphicalReportHandler::new_themed(miette::GraphicalTheme::unicode_nocolor());
    for d in diagnostics {
        human.push_str(&format!("{d}\n"));
        let src = source_of(&d.file);
        let rendered = Rendered::new(d.clone(), src);
        let mut out = String::new();
        if handler.render_report(&mut out, &rendered).is_ok() {
            human.push_str(&out);
            human.push('\n');
        }
    }
    human
}

/// Prints a mission's diagnostics (for commands that refuse an invalid mission).
pub fn print_diagnostics(loaded: &LoadedMission) {
    let mut out = render_diagnostics(loaded);
    if let Some(f) = loaded.files.first() {
        out.push_str(&format!("✘ {}: {} problem(s)\n", f.display(), loaded.diagnostics.len()));
    }
    let _ = write!(std::io::stdout().lock(), "{out}");
}

/// `spomp validate` (with `dry_run`, valid missions also run once in the simulator).
pub fn validate(
    files: &[PathBuf],
    json: bool,
    dry_run: Option<crate::sim_cmd::DryRunLimits>,
    memory: crate::memory_stage::MemoryCheck,
    options: &LoadOptions,
    registry: &NodeRegistry<RobotRuntime>,
) -> Result<ExitCode> {
    let mut all = Vec::new();
    let mut dry_runs = Vec::new();
    let mut failed_runs = 0;
    let mut human = String::new();
    for file in files {
        let mut loaded = load_mission_with(file, registry, options);
        // The world stage runs once the earlier stages pass (it needs a typed mission).
        let world = crate::world_stage::check(&loaded, options);
        loaded.diagnostics.extend(world);
        // Then the memory a simulated run needs, against what the machine has.
        let memory = crate::memory_stage::check(&loaded, memory);
        loaded.diagnostics.extend(memory);
        if loaded.is_valid() {
            // Warnings only: shown, and the mission is valid.
            human.push_str(&render_diagnostics(&loaded));
            if let Some(m) = &loaded.mission {
                let warnings = match loaded.diagnostics.len() {
                    0 => String::new(),
                    1 => ", 1 warning".to_string(),
                    n => format!(", {n} warnings"),
                };
                human.push_str(&format!(
                    "✔ {}: mission `{}` is valid ({} robots, {} roles{warnings})\n",
                    file.display(),
                    m.mission,
                    m.team.len(),
                    m.roles.len()
                ));
            }
            if let Some(limits) = dry_run {
                if !json {
                    let _ = write!(std::io::stdout().lock(), "{human}");
                    human.clear();
                }
                match crate::sim_cmd::dry_run(&loaded, json, limits, registry) {
                    Ok((ok, value)) => {
                        if !ok {
                            failed_runs += 1;
                        }
                        dry_runs.push(serde_json::json!({ "file": file, "dry_run": value }));
                    }
                    // The mission is valid but the simulator cannot set it up (its world, a
                    // start pose): a diagnostic of the dry-run stage, in JSON too.
                    Err(e) => {
                        let d = Diagnostic::new(
                            file,
                            Loc { line: 1, column: 1, offset: None, len: 0 },
                            "",
                            Stage::DryRun,
                            format!("{e:#}"),
                        );
                        human.push_str(&format!("{d}\n✘ {}: the dry run could not start\n", file.display()));
                        all.push(d);
                    }
                }
            }
        } else {
            human.push_str(&render_diagnostics(&loaded));
            human.push_str(&format!("✘ {}: {} problem(s)\n", file.display(), loaded.diagnostics.len()));
        }
        all.extend(loaded.diagnostics);
    }
    let errors = all.iter().filter(|d| d.is_error()).count();
    if json {
        if dry_run.is_some() {
            let v = serde_json::json!({ "diagnostics": all, "dry_runs": dry_runs });
            emit(&format!("{}\n", serde_json::to_string_pretty(&v)?));
        } else {
            emit(&format!("{}\n", serde_json::to_string_pretty(&all)?));
        }
    } else {
        emit(&human);
    }
    // Warnings do not fail validation (docs/design.md §3: exit 0 only when valid).
    Ok(if errors == 0 && failed_runs == 0 { ExitCode::SUCCESS } else { ExitCode::from(1) })
}

/// `spomp schema`.
pub fn schema(registry: &NodeRegistry<RobotRuntime>) -> Result<ExitCode> {
    let schema = mission_schema(registry);
    emit(&format!("{}\n", serde_json::to_string_pretty(&schema).context("serialising the schema")?));
    Ok(ExitCode::SUCCESS)
}

/// `spomp nodes`.
pub fn nodes(
    json: bool,
    markdown: bool,
    only: Option<&str>,
    registry: &NodeRegistry<RobotRuntime>,
) -> Result<ExitCode> {
    if markdown {
        emit(&registry.reference_markdown());
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(name) = only
        && registry.get(name).is_none()
    {
        errln!("error: unknown node type `{name}`; run `spomp nodes` for the list");
        return Ok(ExitCode::from(2));
    }
    let specs: Vec<_> = registry.iter().filter(|s| only.is_none_or(|n| n == s.name)).collect();
    if json {
        emit(&format!("{}\n", serde_json::to_string_pretty(&specs)?));
        return Ok(ExitCode::SUCCESS);
    }
    let mut out = String::new();
    for s in specs {
        let kinds = if s.robot_kinds.is_empty() {
            "any robot".to_string()
        } else {
            s.robot_kinds.iter().map(|k| k.as_str()).collect::<Vec<_>>().join(", ")
        };
        out.push_str(&format!("{}  [{:?}, {kinds}]\n", s.name, s.category));
        out.push_str(&format!("    {}\n", s.description));
        for p in &s.ports {
            let dir = match p.direction {
                PortDirection::Input => "in ",
                PortDirection::Output => "out",
                PortDirection::InOut => "i/o",
            };
            let default = match (&p.default, p.optional) {
                (Some(d), _) => format!(" = {d}"),
                (None, true) => " (optional)".into(),
                (None, false) => " (required)".into(),
            };
            out.push_str(&format!("    {dir} {:<24} {:<7}{default}  {}\n", p.name, p.ty.as_str(), p.description));
        }
        out.push('\n');
    }
    emit(&out);
    Ok(ExitCode::SUCCESS)
}

/// Writes to stdout; a closed stdout (output piped into `head`) ends the output quietly.
fn emit(text: &str) {
    let mut stdout = std::io::stdout().lock();
    let _ = stdout.write_all(text.as_bytes()).and_then(|()| stdout.flush());
}
