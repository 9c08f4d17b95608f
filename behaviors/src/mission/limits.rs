//! The documented limits of the mission language, and safe reading of the files a mission names.
//!
//! Every limit here is a rule of the language (docs/missions.md lists them): a value past one is
//! a located load error, never a panic, an abort or a run that cannot end.
//!
//! - Durations (`delay_s`, `duration_s`, `after_s`, any `*_s` port) are at most
//!   [`MAX_DURATION_S`] seconds (1e9), and `time_limit_s` at most [`MAX_TIME_LIMIT_S`] (7 days).
//! - The mission name and robot ids are identifiers: 1 to [`MAX_IDENTIFIER_LEN`] characters of
//!   `A–Z a–z 0–9 _ -` (they name output folders, log topics and files).
//!   Robot ids in [`RESERVED_ROBOT_IDS`] (`mission`) are refused.
//! - A team has at most [`MAX_ROBOTS`] robots.
//! - A mission, an included file or a plan file is a regular file of at most
//!   [`MAX_SOURCE_BYTES`] bytes (no FIFO, device or directory), inside the mission's folder.

use std::io::Read;
use std::path::{Component, Path, PathBuf};

use crate::blackboard::BbValue;

use super::compile::{Ir, IrBinding, IrKind};
use super::diagnostic::{Diagnostic, Stage};

// The duration rule is the engine's (a node checks a duration bound to an entry the same way).
pub use crate::duration::{MAX_DURATION_S, duration_from_secs, number};

/// The longest mission time limit, seconds (7 days).
pub const MAX_TIME_LIMIT_S: f64 = 604_800.0;

/// Robot ids a team may not use: `mission` is the writer name the team state gives the goals
/// listed in the mission file (`spomp_teamstate::MISSION_WRITER`), so a robot of that name would
/// number its own goals in the same id space and one of each pair would be lost.
pub const RESERVED_ROBOT_IDS: &[&str] = &["mission"];

/// The longest mission name or robot id, characters.
pub const MAX_IDENTIFIER_LEN: usize = 64;

/// The most robots a team may have: a bound of the language. Whether a team fits the machine
/// is the memory stage's call (`spomp validate` estimates what a simulated run needs: about 10
/// MB per UGV on a generated city, and refuses a team that cannot fit).
pub const MAX_ROBOTS: usize = 1000;

/// The largest mission, include or plan file, bytes (4 MiB).
pub const MAX_SOURCE_BYTES: u64 = 4 * 1024 * 1024;

/// Checks a time limit: positive, finite and at most [`MAX_TIME_LIMIT_S`].
pub fn check_time_limit(secs: f64) -> Result<(), String> {
    if secs.is_finite() && secs > 0.0 && secs <= MAX_TIME_LIMIT_S {
        Ok(())
    } else {
        Err(format!(
            "expected a positive number of seconds, found {}; the most is {MAX_TIME_LIMIT_S} s (7 days)",
            number(secs)
        ))
    }
}

/// Checks an identifier (a mission name or a robot id): 1 to [`MAX_IDENTIFIER_LEN`] characters
/// of `A–Z a–z 0–9 _ -`. `what` names it in the message.
pub fn check_identifier(what: &str, s: &str) -> Result<(), String> {
    if s.is_empty() {
        return Err(format!("{what} is empty; it must be 1 to {MAX_IDENTIFIER_LEN} characters of A-Z a-z 0-9 _ -"));
    }
    if let Some(c) = s.chars().find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '-')) {
        return Err(format!(
            "{what} `{}` has the character {c:?}; it may use only A-Z a-z 0-9 _ - (it names folders and files)",
            shorten(s)
        ));
    }
    if s.chars().count() > MAX_IDENTIFIER_LEN {
        return Err(format!(
            "{what} is {} characters long; at most {MAX_IDENTIFIER_LEN} are allowed",
            s.chars().count()
        ));
    }
    Ok(())
}

/// The first 40 characters of `s` (for messages that quote user text).
fn shorten(s: &str) -> String {
    let mut out: String = s.chars().take(40).collect();
    if s.chars().count() > 40 {
        out.push('…');
    }
    out
}

/// Why a file a mission names could not be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SourceError {
    /// The path leaves the folder it must stay in.
    #[error("`{path}` is outside {root} (absolute paths and `..` out of the mission's folder are not allowed)")]
    Outside {
        /// The path as written.
        path: String,
        /// The folder.
        root: String,
    },
    /// Not a regular file (a FIFO, a device, a directory).
    #[error("`{0}` is not a regular file")]
    NotRegular(String),
    /// Larger than allowed.
    #[error("`{path}` is {bytes} bytes; at most {max} are allowed")]
    TooLarge {
        /// The file.
        path: String,
        /// Its size.
        bytes: u64,
        /// The limit.
        max: u64,
    },
    /// The operating system refused.
    #[error("cannot read `{path}`: {message}")]
    Io {
        /// The file.
        path: String,
        /// What the system said.
        message: String,
        /// The kind of error.
        kind: std::io::ErrorKind,
    },
    /// Not UTF-8 text.
    #[error(
        "`{path}` is not UTF-8 text (byte 0x{byte:02x} at line {line}, column {column}); expected a YAML text file"
    )]
    NotText {
        /// The file.
        path: String,
        /// The offending byte.
        byte: u8,
        /// Its line, from 1.
        line: u32,
        /// Its column, from 1.
        column: u32,
    },
}

impl SourceError {
    /// Line and column of the problem inside the file, when the problem is in its content.
    pub fn position(&self) -> Option<(u32, u32)> {
        match self {
            SourceError::NotText { line, column, .. } => Some((*line, *column)),
            _ => None,
        }
    }
}

/// Reads a regular file of at most `max` bytes as bytes, without blocking on FIFOs or reading
/// devices: the file's type and size are checked before it is opened, and the read stops past
/// `max` bytes whatever the size said.
pub fn read_regular(path: &Path, max: u64) -> Result<Vec<u8>, SourceError> {
    let shown = path.display().to_string();
    let io = |e: std::io::Error| SourceError::Io { path: shown.clone(), message: e.to_string(), kind: e.kind() };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        return Err(SourceError::NotRegular(shown));
    }
    if meta.len() > max {
        return Err(SourceError::TooLarge { path: shown, bytes: meta.len(), max });
    }
    let file = std::fs::File::open(path).map_err(io)?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(max + 1).read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > max {
        return Err(SourceError::TooLarge { path: shown, bytes: bytes.len() as u64, max });
    }
    Ok(bytes)
}

/// Reads a regular text file of at most `max` bytes (see [`read_regular`]); bytes that are not
/// UTF-8 are an error that names their line and column.
pub fn read_text(path: &Path, max: u64) -> Result<String, SourceError> {
    let bytes = read_regular(path, max)?;
    String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let bytes = e.as_bytes();
        let before = &bytes[..at];
        let line = before.iter().filter(|&&b| b == b'\n').count() as u32 + 1;
        let line_start = before.iter().rposition(|&b| b == b'\n').map_or(0, |p| p + 1);
        let column = String::from_utf8_lossy(&before[line_start..]).chars().count() as u32 + 1;
        SourceError::NotText { path: path.display().to_string(), byte: bytes[at], line, column }
    })
}

/// `rel` (a path written in a file of `dir`) joined to `dir`, if it lands inside one of
/// `roots` (the mission's folder first, then folders the user allowed with `--allow-dir`): no
/// `..` climbs out of them and an absolute path must point into one. Symbolic links are
/// followed when the target exists, so a link out of the roots is refused too.
pub fn resolve_inside(roots: &[PathBuf], dir: &Path, rel: &str) -> Result<PathBuf, SourceError> {
    let shown = match roots.first() {
        Some(r) if !r.as_os_str().is_empty() => r.display().to_string(),
        _ => ".".to_string(),
    };
    let outside = || SourceError::Outside { path: rel.to_string(), root: shown.clone() };
    let joined = dir.join(rel);
    let lexical = absolute_clean(&joined);
    let real = std::fs::canonicalize(&joined).ok();
    let inside = |root: &PathBuf| {
        lexical.starts_with(absolute_clean(root))
            // Follow links where the file exists: the real file must be inside the real root.
            && match (&real, std::fs::canonicalize(root)) {
                (Some(real), Ok(real_root)) => real.starts_with(real_root),
                _ => true,
            }
    };
    if roots.iter().any(inside) { Ok(joined) } else { Err(outside()) }
}

/// An absolute path with `.` and `..` folded lexically (no file system access).
fn absolute_clean(p: &Path) -> PathBuf {
    let abs = if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir().map(|d| d.join(p)).unwrap_or_else(|_| p.to_path_buf())
    };
    let mut out = PathBuf::new();
    for c in abs.components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

/// Checks the literal values of a compiled tree against the limits: every `*_s` number at most
/// [`MAX_DURATION_S`] and finite, every `*_file` path inside `folder` and a regular file of at
/// most [`MAX_SOURCE_BYTES`] bytes. Each problem is a located diagnostic. `roots` is not empty:
/// the mission's folder, then the folders the user allowed.
pub fn check_tree_literals(ir: &Ir, files: &[PathBuf], roots: &[PathBuf], diags: &mut Vec<Diagnostic>) {
    match &ir.kind {
        IrKind::Leaf { ports } => {
            let file = files.get(ir.file).cloned().unwrap_or_default();
            for port in ports {
                let IrBinding::Literal(value) = &port.binding else { continue };
                let name = &*port.spec.name;
                let problem = match value {
                    BbValue::Float(v) if name.ends_with("_s") && !(v.is_finite() && *v <= MAX_DURATION_S) => {
                        Some(format!(
                            "port `{name}` of `{}`: {}",
                            ir.type_name,
                            duration_from_secs(*v).err().unwrap_or_default()
                        ))
                    }
                    BbValue::Str(rel) if name.ends_with("_file") => resolve_inside(roots, &roots[0], rel)
                        .and_then(|p| read_regular(&p, MAX_SOURCE_BYTES).map(|_| ()))
                        .err()
                        // A file that cannot be read is reported by the node that reads it.
                        .filter(|e| !matches!(e, SourceError::Io { .. }))
                        .map(|e| format!("port `{name}` of `{}`: {e}", ir.type_name)),
                    _ => None,
                };
                if let Some(message) = problem {
                    diags.push(Diagnostic::new(&file, port.loc, ir.path.clone(), Stage::Schema, message));
                }
            }
        }
        IrKind::Control { children, .. } => {
            children.iter().for_each(|c| check_tree_literals(c, files, roots, diags));
        }
        IrKind::Decorator { child, .. } => check_tree_literals(child, files, roots, diags),
        IrKind::StateMachine { states, .. } => {
            for run in states.iter().filter_map(|s| s.run.as_ref()) {
                check_tree_literals(run, files, roots, diags);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;
    use std::time::Duration;

    #[test]
    fn durations_have_a_maximum() {
        assert_eq!(duration_from_secs(1.5).unwrap(), Duration::from_millis(1500));
        assert!(duration_from_secs(MAX_DURATION_S).is_ok());
        for bad in [-1.0, 1e308, f64::NAN, f64::INFINITY, MAX_DURATION_S + 1.0] {
            let e = duration_from_secs(bad).unwrap_err();
            assert!(e.contains("between 0 and 1e9 s"), "{e}");
        }
        assert!(duration_from_secs(1e308).unwrap_err().ends_with("found 1e308"));
        assert_eq!(number(-1.0), "-1");
        assert!(check_time_limit(600.0).is_ok());
        for bad in [0.0, -1.0, 1e12, f64::NAN] {
            assert!(check_time_limit(bad).is_err());
        }
    }

    #[test]
    fn identifiers() {
        for ok in ["ugv1", "visit-all", "A_b-9"] {
            assert!(check_identifier("robot id", ok).is_ok(), "{ok}");
        }
        for bad in ["", "../x", "a b", "/abs", "x.y", "é"] {
            assert!(check_identifier("robot id", bad).is_err(), "{bad}");
        }
        assert!(check_identifier("robot id", &"a".repeat(65)).unwrap_err().contains("at most 64"));
    }

    #[test]
    fn resolves_only_inside_the_root() {
        let dir = std::env::temp_dir().join(format!("spomp-limits-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        let roots = [dir.clone()];
        assert!(resolve_inside(&roots, &dir, "sub/x.yaml").is_ok());
        assert!(resolve_inside(&roots, &dir.join("sub"), "../x.yaml").is_ok());
        assert!(resolve_inside(&roots, &dir, "../x.yaml").is_err());
        assert!(resolve_inside(&roots, &dir, "sub/../../x.yaml").is_err());
        assert!(resolve_inside(&roots, &dir, "/etc/passwd").is_err());
        // A folder the user allowed.
        let allowed = [dir.join("sub"), PathBuf::from("/etc")];
        assert!(resolve_inside(&allowed, &dir.join("sub"), "/etc/passwd").is_ok());
        assert!(resolve_inside(&allowed, &dir.join("sub"), "../x.yaml").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn reads_only_small_regular_files() {
        assert!(matches!(read_regular(Path::new("/dev/zero"), 100), Err(SourceError::NotRegular(_))));
        assert!(matches!(read_regular(Path::new("/"), 100), Err(SourceError::NotRegular(_))));
        let f = std::env::temp_dir().join(format!("spomp-limits-{}.bin", std::process::id()));
        std::fs::write(&f, b"ab\ncd\xff").unwrap();
        assert!(matches!(read_regular(&f, 3), Err(SourceError::TooLarge { bytes: 6, max: 3, .. })));
        let e = read_text(&f, 100).unwrap_err();
        assert_eq!(e.position(), Some((2, 3)), "{e}");
        std::fs::remove_file(&f).unwrap();
    }
}
