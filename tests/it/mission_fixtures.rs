//! Mission fixtures: every `tests/missions/valid-*.yaml` validates cleanly, and every
//! `tests/missions/invalid-*.yaml` yields the diagnostics its `# expect:` header lines name:
//! `# expect: [FILE:]LINE:COL | node path | message fragment`.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use spomp_behaviors::mission::load_mission;

fn fixtures(prefix: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/missions");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name().unwrap().to_string_lossy().starts_with(prefix) && p.extension().is_some_and(|e| e == "yaml")
        })
        .collect();
    v.sort();
    v
}

struct Expect {
    file: Option<String>,
    line: u32,
    column: u32,
    path: String,
    message: String,
}

fn expectations(text: &str) -> Vec<Expect> {
    text.lines()
        .filter_map(|l| l.strip_prefix("# expect: "))
        .map(|rest| {
            let parts: Vec<&str> = rest.splitn(3, " | ").collect();
            assert_eq!(parts.len(), 3, "bad expectation `{rest}`");
            let pos: Vec<&str> = parts[0].rsplitn(3, ':').collect();
            Expect {
                file: pos.get(2).map(|s| s.to_string()),
                column: pos[0].parse().unwrap(),
                line: pos[1].parse().unwrap(),
                path: parts[1].trim().to_string(),
                message: parts[2].trim().to_string(),
            }
        })
        .collect()
}

#[test]
fn valid_fixtures_and_shipped_missions_validate() {
    let registry = spomp_robot::registry();
    let mut files = fixtures("valid-");
    let missions = Path::new(env!("CARGO_MANIFEST_DIR")).join("missions");
    for e in std::fs::read_dir(missions).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "yaml") {
            files.push(p);
        }
    }
    assert!(files.len() >= 6);
    for f in files {
        let loaded = load_mission(&f, &registry);
        assert!(loaded.diagnostics.is_empty(), "{}: {:#?}", f.display(), loaded.diagnostics);
        assert!(loaded.mission.is_some());
    }
}

#[test]
fn invalid_fixtures_report_the_right_place_and_field() {
    let registry = spomp_robot::registry();
    let files = fixtures("invalid-");
    assert!(files.len() >= 25, "at least 25 invalid fixtures, found {}", files.len());
    for f in files {
        let text = std::fs::read_to_string(&f).unwrap();
        let expects = expectations(&text);
        assert!(!expects.is_empty(), "{} has no `# expect:` line", f.display());
        let loaded = load_mission(&f, &registry);
        assert!(!loaded.is_valid(), "{} should be invalid", f.display());
        for e in &expects {
            let found = loaded.diagnostics.iter().any(|d| {
                let file_ok = match &e.file {
                    Some(name) => d.file.ends_with(name),
                    None => d.file == f,
                };
                file_ok
                    && d.line == e.line
                    && d.column == e.column
                    && d.node_path == e.path
                    && d.message.contains(&e.message)
            });
            assert!(
                found,
                "{}: expected {}:{} `{}` containing `{}`, got:\n{:#?}",
                f.display(),
                e.line,
                e.column,
                e.path,
                e.message,
                loaded.diagnostics.iter().map(|d| d.to_string()).collect::<Vec<_>>()
            );
        }
    }
}

/// Issue 37: a UGV role that ignores the operator's holds and recalls is valid, with a warning
/// that names the role and the missing nodes.
#[test]
fn a_role_that_ignores_the_operator_is_valid_with_a_warning() {
    let registry = spomp_robot::registry();
    let f = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/missions/warn-ignores-operator.yaml");
    let loaded = load_mission(&f, &registry);
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    assert_eq!(loaded.diagnostics.len(), 1, "{:#?}", loaded.diagnostics);
    let d = &loaded.diagnostics[0];
    assert!(!d.is_error());
    assert_eq!((d.line, d.column, d.node_path.as_str()), (9, 7, "roles.visitor.tree"));
    assert!(d.message.contains("`operator_hold` or `operator_recall`"), "{}", d.message);
}

#[test]
fn several_errors_are_reported_in_one_run() {
    let registry = spomp_robot::registry();
    let f = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/missions/invalid-several-errors.yaml");
    let loaded = load_mission(&f, &registry);
    assert_eq!(loaded.diagnostics.len(), 3, "{:#?}", loaded.diagnostics);
}
