//! Experiment fixtures: every `tests/experiments/valid-*.yaml` loads with its configurations
//! resolved, and every `tests/experiments/invalid-*.yaml` yields the located problems its
//! `# expect: LINE:COL | field path | message fragment` header lines name — including problems
//! the mission language finds in a configuration's patched mission, which point at the
//! override that caused them.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};

use spomp::experiment::spec::load_experiment;

fn fixtures(prefix: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/experiments");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().starts_with(prefix))
        .collect();
    v.sort();
    assert!(!v.is_empty(), "no {prefix} fixtures");
    v
}

#[test]
fn valid_fixtures_and_shipped_experiments_load() {
    let registry = spomp::registry();
    let mut files = fixtures("valid-");
    for e in std::fs::read_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments")).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "yaml") {
            files.push(p);
        }
    }
    for f in files {
        let loaded = load_experiment(&f, &registry, &[]);
        assert!(loaded.is_valid(), "{}: {:#?}", f.display(), loaded.diagnostics);
        let file = loaded.file.as_ref().unwrap();
        assert_eq!(loaded.configurations.len(), file.configurations.len());
        // Every configuration × seed in-process, and again once per team channel it also runs
        // deployed over.
        let deployed_runs: usize = file.configurations.iter().map(|c| c.deployed.len()).sum();
        let seeds = file.seeds.values().len();
        assert_eq!(loaded.trials.len(), (file.configurations.len() + deployed_runs) * seeds);
        assert_eq!(loaded.trials.iter().filter(|t| t.deployed.is_some()).count(), deployed_runs * seeds);
    }
}

#[test]
fn overrides_reach_the_patched_mission() {
    let registry = spomp::registry();
    let f = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/experiments/valid-every-override.yaml");
    let loaded = load_experiment(&f, &registry, &[]);
    assert!(loaded.is_valid(), "{:#?}", loaded.diagnostics);
    assert_eq!(loaded.seeds(), vec![3, 4, 5]);
    let four = loaded.configurations.iter().find(|c| c.name == "four-ugvs").unwrap();
    let m = four.loaded.mission.as_ref().unwrap();
    let ugvs: Vec<_> = m.team.iter().filter(|r| r.kind == spomp_core::RobotKind::Ugv).collect();
    let ids: Vec<&str> = ugvs.iter().map(|r| r.id.as_str()).collect();
    assert_eq!(ids, ["ugv1", "ugv2", "ugv3", "ugv4"]);
    let priorities: Vec<_> = ugvs.iter().map(|r| r.priority.unwrap()).collect();
    assert_eq!(priorities, [1, 2, 3, 4]);
    // The given start first, then the grid beside the template (ugv1 at 5,0: 3 m behind it).
    assert_eq!((ugvs[2].start.x_m, ugvs[2].start.y_m), (5.0, 10.0));
    assert_eq!((ugvs[3].start.x_m, ugvs[3].start.y_m), (2.0, 0.0));
    // Team-wide navigation merged into each robot's own, key by key.
    let nav2 = ugvs[1].navigation.as_ref().unwrap();
    assert_eq!(nav2["global_planner"]["sharing"], "downsampled");
    assert_eq!(nav2["global_planner"]["learning"], false, "ugv2's own setting stays");
    assert_eq!(ugvs[2].navigation.as_ref().unwrap()["terrain"]["inflation_m"], 0.8);
    assert_eq!(m.roles["visitor"].navigation.as_ref().unwrap()["control"]["max_speed_mps"], 1.0);
    use spomp_behaviors::mission::schema::LocalizationMode;
    assert_eq!(ugvs[0].localization.as_ref().unwrap().mode, LocalizationMode::CrossView);
    assert_eq!(ugvs[2].localization.as_ref().unwrap().mode, LocalizationMode::GroundTruth);
    use spomp_behaviors::mission::MissionSection;
    let comms = spomp_robot::CommsSpec::of_mission(m).unwrap();
    assert_eq!((comms.data_range_m, comms.position_range_m), (20.0, 50.0));
    let sim = spomp_world::SimSpec::of_mission(m).unwrap();
    assert_eq!(sim.faults.len(), 2);
    assert!(sim.prior_map);
    assert_eq!(m.time_limit_s, 60.0, "the configuration's limit wins");
    let base = loaded.configurations.iter().find(|c| c.name == "base").unwrap();
    assert_eq!(base.loaded.mission.as_ref().unwrap().time_limit_s, 120.0, "the experiment's limit");
    let one = loaded.configurations.iter().find(|c| c.name == "one-ugv").unwrap();
    let team: Vec<&str> = one.loaded.mission.as_ref().unwrap().team.iter().map(|r| r.id.as_str()).collect();
    assert_eq!(team, ["base", "ugv1"]);
    // Trials: configuration-major, seeds in order; hashes differ by configuration and seed.
    let t = &loaded.trials[4];
    assert_eq!((t.index, t.configuration, t.seed), (4, 1, 4));
    let h = |c: usize, s: u64| spomp::experiment::spec::trial_hash(&loaded.configurations[c], s);
    assert_ne!(h(0, 3), h(0, 4));
    assert_ne!(h(0, 3), h(1, 3));
    assert_eq!(h(2, 5), h(2, 5));
}

#[test]
fn invalid_fixtures_report_located_problems() {
    let registry = spomp::registry();
    for f in fixtures("invalid-") {
        let text = std::fs::read_to_string(&f).unwrap();
        let loaded = load_experiment(&f, &registry, &[]);
        assert!(!loaded.is_valid(), "{} should be invalid", f.display());
        let expected: Vec<&str> = text.lines().filter_map(|l| l.strip_prefix("# expect: ")).collect();
        assert!(!expected.is_empty(), "{} has no `# expect:` line", f.display());
        for e in expected {
            let parts: Vec<&str> = e.splitn(3, " | ").collect();
            let (pos, path, fragment) = (parts[0], parts[1].trim(), parts[2].trim());
            let (line, column) = pos.split_once(':').unwrap();
            let (line, column): (u32, u32) = (line.parse().unwrap(), column.parse().unwrap());
            let found = loaded.diagnostics.iter().any(|d| {
                d.file == f
                    && d.line == line
                    && d.column == column
                    && d.node_path == path
                    && d.message.contains(fragment)
            });
            assert!(found, "{}: expected `{e}`, got {:#?}", f.display(), loaded.diagnostics);
        }
    }
}
