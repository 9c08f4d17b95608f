//! The world stage of `spomp validate` on the fixtures in `tests/missions/world/` (missions in the
//! small `town` world folder): each fixture's `# expect: LINE:COL | node path | message fragment`
//! lines are the errors it must report and its `# warn: …` lines the warnings, no more; a fixture
//! with an error exits 1, one with warnings only exits 0 (warnings do not fail validation).

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use assert_cmd::Command;

struct Expect {
    severity: &'static str,
    line: u64,
    column: u64,
    path: String,
    message: String,
}

fn expectations(text: &str) -> Vec<Expect> {
    let mut out = Vec::new();
    for line in text.lines() {
        let (severity, rest) = if let Some(r) = line.strip_prefix("# expect: ") {
            ("error", r)
        } else if let Some(r) = line.strip_prefix("# warn: ") {
            ("warning", r)
        } else {
            continue;
        };
        let parts: Vec<&str> = rest.splitn(3, " | ").collect();
        assert_eq!(parts.len(), 3, "bad expectation `{rest}`");
        let (l, c) = parts[0].split_once(':').unwrap();
        out.push(Expect {
            severity,
            line: l.parse().unwrap(),
            column: c.parse().unwrap(),
            path: parts[1].trim().to_string(),
            message: parts[2].trim().to_string(),
        });
    }
    out
}

fn fixtures() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/missions/world");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "yaml"))
        .collect();
    v.sort();
    v
}

#[test]
fn world_stage_fixtures_report_located_errors_and_warnings() {
    let files = fixtures();
    assert!(files.len() >= 4, "{files:?}");
    let mut seen = (0, 0);
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let expects = expectations(&text);
        let out = Command::cargo_bin("spomp").unwrap().args(["validate", "--json"]).arg(&f).output().unwrap();
        let diags: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout)
            .unwrap_or_else(|e| panic!("{}: {e}: {}", f.display(), String::from_utf8_lossy(&out.stdout)));
        let shown: Vec<String> = diags.iter().map(|d| d.to_string()).collect();
        assert_eq!(diags.len(), expects.len(), "{}: {shown:#?}", f.display());
        for e in &expects {
            let found = diags.iter().any(|d| {
                d["stage"] == "world"
                    && d["severity"] == e.severity
                    && d["line"] == e.line
                    && d["column"] == e.column
                    && d["node_path"] == e.path.as_str()
                    && d["message"].as_str().unwrap().contains(&e.message)
            });
            assert!(
                found,
                "{}: expected {} at {}:{} `{}` containing `{}`, got {shown:#?}",
                f.display(),
                e.severity,
                e.line,
                e.column,
                e.path,
                e.message
            );
        }
        let errors = expects.iter().filter(|e| e.severity == "error").count();
        seen.0 += errors;
        seen.1 += expects.len() - errors;
        let code = if errors > 0 { 1 } else { 0 };
        assert_eq!(out.status.code(), Some(code), "{}: {shown:#?}", f.display());
    }
    assert!(seen.0 >= 4 && seen.1 >= 4, "errors and warnings both covered: {seen:?}");
}

#[test]
fn warnings_are_shown_and_the_mission_is_still_valid() {
    let f = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/missions/world/warn-no-goal-class.yaml");
    let out = Command::cargo_bin("spomp").unwrap().arg("validate").arg(&f).output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("[world] warning: at goals.detect.class"), "{text}");
    assert!(text.contains("can never complete"), "{text}");
    assert!(text.contains("is valid (3 robots, 3 roles, 1 warning)"), "{text}");
}

/// The shipped missions name generated worlds: the world stage leaves them alone, and a
/// mission in an imported world passes it (covered end to end in `cli_world_import`).
#[test]
fn missions_with_generated_worlds_get_no_world_diagnostics() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::cargo_bin("spomp")
        .unwrap()
        .args(["validate", "--json"])
        .arg(root.join("missions/visit-all-vehicle-clusters.yaml"))
        .arg(root.join("missions/manual-goals.yaml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0));
    let diags: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    assert!(diags.is_empty(), "{diags:?}");
}
