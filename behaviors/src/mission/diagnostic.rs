//! Mission diagnostics: file, line, column, node path, stage and message, rendered with the
//! source line.

use std::fmt;
use std::path::PathBuf;

use serde::Serialize;

use super::yaml::Loc;

/// The validation stage that found a problem (docs/design.md §3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// YAML syntax, unreadable file.
    Parse,
    /// Keys, types, ranges, units.
    Schema,
    /// Node types, ports, references, states.
    Wiring,
    /// Roles, priorities, ids, skills per robot kind.
    Team,
    /// The world a mission names: it loads, start poses are usable, goals can exist, waypoints
    /// stay in it (run by `spomp validate`, which can load worlds).
    World,
    /// The memory a simulated run of the mission needs, against what the machine has (run by
    /// `spomp validate`, which knows the simulator's world).
    Memory,
    /// Simulated dry run.
    DryRun,
}

impl Stage {
    /// Lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Stage::Parse => "parse",
            Stage::Schema => "schema",
            Stage::Wiring => "wiring",
            Stage::Team => "team",
            Stage::World => "world",
            Stage::Memory => "memory",
            Stage::DryRun => "dry_run",
        }
    }
}

/// How serious a problem is: an error makes a mission invalid, a warning does not (docs/design.md
/// §3: exit code 0 only when valid).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Severity {
    /// The mission is invalid.
    #[default]
    Error,
    /// The mission is valid but probably not what its author meant.
    Warning,
}

/// One problem in a mission.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Diagnostic {
    /// File it is in.
    pub file: PathBuf,
    /// Line, from 1 (0 if the problem concerns the whole file).
    pub line: u32,
    /// Column, from 1.
    pub column: u32,
    /// Path of the node or field: `roles.visitor.tree/sequence/claim_goal` or `team[1].priority`.
    pub node_path: String,
    /// Stage.
    pub stage: Stage,
    /// What was expected and what was found.
    pub message: String,
    /// Error or warning.
    pub severity: Severity,
    /// Byte span for rendering.
    #[serde(skip)]
    pub span: Option<(usize, usize)>,
}

impl Diagnostic {
    /// A diagnostic at a location.
    pub fn new(
        file: impl Into<PathBuf>,
        loc: Loc,
        node_path: impl Into<String>,
        stage: Stage,
        message: impl Into<String>,
    ) -> Self {
        Diagnostic {
            file: file.into(),
            line: loc.line,
            column: loc.column,
            node_path: node_path.into(),
            stage,
            message: message.into(),
            severity: Severity::Error,
            span: loc.offset.map(|o| (o, loc.len.max(1))),
        }
    }

    /// The same problem as a warning.
    pub fn into_warning(mut self) -> Self {
        self.severity = Severity::Warning;
        self
    }

    /// Whether it makes the mission invalid.
    pub fn is_error(&self) -> bool {
        self.severity == Severity::Error
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: [{}] ", self.file.display(), self.line, self.column, self.stage.as_str())?;
        if self.severity == Severity::Warning {
            f.write_str("warning: ")?;
        }
        if !self.node_path.is_empty() {
            write!(f, "at {}: ", self.node_path)?;
        }
        f.write_str(&self.message)
    }
}

/// A diagnostic with its source, for miette's graphical report.
#[derive(Debug)]
pub struct Rendered {
    diag: Diagnostic,
    src: miette::NamedSource<String>,
}

/// The longest source line a report quotes, bytes; a longer line is not quoted.
const MAX_QUOTED_LINE: usize = 300;

impl Rendered {
    /// Pairs a diagnostic with the text of its file. The report quotes at most the line the
    /// problem is on (never the rest of the file), and nothing when that line is very long or
    /// not printable text.
    pub fn new(mut diag: Diagnostic, source: String) -> Self {
        let name = diag.file.display().to_string();
        // The renderer sees only the offending line: the lines before it are left empty (so its
        // line number stays right) and the lines after it are cut.
        let mut shown = String::new();
        diag.span = diag.span.and_then(|(offset, len)| {
            let start = source.get(..offset)?.rfind('\n').map_or(0, |p| p + 1);
            let end = source.get(offset..)?.find('\n').map_or(source.len(), |p| offset + p);
            let line = source.get(start..end)?;
            let printable = line.chars().all(|c| !c.is_control() || c == '\t' || c == '\r');
            if end - start > MAX_QUOTED_LINE || !printable {
                return None;
            }
            let line_index = source[..start].matches('\n').count();
            shown = "\n".repeat(line_index);
            shown.push_str(line);
            Some((line_index + offset - start, len.min(end - offset).max(1)))
        });
        Rendered { diag, src: miette::NamedSource::new(name, shown) }
    }
}

impl fmt::Display for Rendered {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.diag.node_path.is_empty() {
            write!(f, "{}", self.diag.message)
        } else {
            write!(f, "{}: {}", self.diag.node_path, self.diag.message)
        }
    }
}

impl std::error::Error for Rendered {}

impl miette::Diagnostic for Rendered {
    fn severity(&self) -> Option<miette::Severity> {
        Some(match self.diag.severity {
            Severity::Error => miette::Severity::Error,
            Severity::Warning => miette::Severity::Warning,
        })
    }
    fn code<'a>(&'a self) -> Option<Box<dyn fmt::Display + 'a>> {
        Some(Box::new(format!("spomp::{}", self.diag.stage.as_str())))
    }
    fn source_code(&self) -> Option<&dyn miette::SourceCode> {
        self.diag.span.map(|_| &self.src as &dyn miette::SourceCode)
    }
    fn labels(&self) -> Option<Box<dyn Iterator<Item = miette::LabeledSpan> + '_>> {
        let (offset, len) = self.diag.span?;
        let label = format!("{}:{}:{}", self.diag.file.display(), self.diag.line, self.diag.column);
        Some(Box::new(std::iter::once(miette::LabeledSpan::new(Some(label), offset, len))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(line: u32) -> Loc {
        Loc { line, column: 3, offset: None, len: 0 }
    }

    #[test]
    fn warnings_are_marked_and_do_not_invalidate_a_mission() {
        let error = Diagnostic::new("m.yaml", at(4), "team[0].start", Stage::World, "off the map");
        let warning = Diagnostic::new("m.yaml", at(9), "goals.detect", Stage::World, "no goal").into_warning();
        assert!(error.is_error() && !warning.is_error());
        assert_eq!(error.to_string(), "m.yaml:4:3: [world] at team[0].start: off the map");
        assert_eq!(warning.to_string(), "m.yaml:9:3: [world] warning: at goals.detect: no goal");
        let json = serde_json::to_value(&warning).unwrap_or_default();
        assert_eq!((json["severity"].as_str(), json["stage"].as_str()), (Some("warning"), Some("world")));

        let mut loaded = crate::mission::LoadedMission {
            mission: serde_saphyr::from_str("mission: m\nteam: []\nroles: {}\ntime_limit_s: 10\n").ok(),
            ..Default::default()
        };
        assert!(loaded.mission.is_some());
        loaded.diagnostics.push(warning);
        assert!(loaded.is_valid(), "a warning leaves the mission valid");
        loaded.diagnostics.push(error);
        assert!(!loaded.is_valid());
    }
}
