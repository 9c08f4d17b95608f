//! Hostile input on the command line (issue 21): each case is a clear error with exit 1 (bad
//! input) or 2 (bad usage), never a panic, an abort, a hang or a write outside the output folder;
//! and a run cut short by SIGINT or SIGKILL leaves summaries and logs that read.

#![allow(clippy::unwrap_used, clippy::expect_used)] // tests fail loudly by design

use std::path::{Path, PathBuf};
use std::process::{Command as StdCommand, Stdio};
use std::time::{Duration, Instant};

use crate::{root, spomp};

fn bin() -> PathBuf {
    assert_cmd::cargo::cargo_bin("spomp")
}

fn stdout_of(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn stderr_of(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A small valid mission (a base station waiting) written into `dir` as `name`, with `extra`
/// top-level YAML appended.
fn mission(dir: &Path, name: &str, extra: &str) -> PathBuf {
    let text = format!(
        "mission: small\nteam:\n  - {{ id: base, kind: basestation, role: base, start: {{ x_m: 10, y_m: 10 }} }}\n\
         roles:\n  base:\n    tree:\n      wait: {{ duration_s: 1e9 }}\ncomplete_when: time_limit\ntime_limit_s: 600\n{extra}"
    );
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn mkfifo(path: &Path) {
    let ok = StdCommand::new("mkfifo").arg(path).status().unwrap().success();
    assert!(ok, "mkfifo {}", path.display());
}

/// Runs the command with a deadline: a hang fails the test instead of blocking it.
fn run_with_deadline(cmd: &mut StdCommand, deadline: Duration) -> std::process::Output {
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let start = Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if start.elapsed() > deadline {
            let _ = child.kill();
            panic!("{cmd:?} did not end within {deadline:?}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn fifos_and_devices_are_refused_not_read() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo.yaml");
    mkfifo(&fifo);
    // The mission itself.
    let out = run_with_deadline(StdCommand::new(bin()).arg("validate").arg(&fifo), Duration::from_secs(20));
    assert_eq!(out.status.code(), Some(1), "{}", stderr_of(&out));
    assert!(stdout_of(&out).contains("is not a regular file"), "{}", stdout_of(&out));
    // An include inside the mission's folder.
    let m = mission(dir.path(), "m.yaml", "include: [fifo.yaml]\n");
    let out = run_with_deadline(StdCommand::new(bin()).arg("validate").arg(&m), Duration::from_secs(20));
    assert_eq!(out.status.code(), Some(1));
    assert!(stdout_of(&out).contains("is not a regular file"), "{}", stdout_of(&out));
    // --params of terrain and plan, and the panorama of terrain.
    let out = run_with_deadline(
        StdCommand::new(bin()).args(["terrain", "--params"]).arg(&fifo).arg(&fifo),
        Duration::from_secs(20),
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr_of(&out));
    assert!(stderr_of(&out).contains("not a regular file"), "{}", stderr_of(&out));
    let out = run_with_deadline(
        StdCommand::new(bin()).args(["terrain", "/dev/zero", "--params", "/dev/zero"]),
        Duration::from_secs(20),
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr_of(&out).contains("--params: `/dev/zero` is not a regular file"), "{}", stderr_of(&out));
}

#[test]
fn binary_missions_are_located_and_worded_for_the_user() {
    let dir = tempfile::tempdir().unwrap();
    let bin_file = dir.path().join("bin.yaml");
    std::fs::write(&bin_file, b"mission: x\nteam: \xff\xfe\x00\n").unwrap();
    let out = spomp().arg("validate").arg("--json").arg(&bin_file).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v[0]["line"], 2, "{v}");
    assert_eq!(v[0]["column"], 7, "{v}");
    assert!(v[0]["message"].as_str().unwrap().contains("not UTF-8 text (byte 0xff"), "{v}");
    // Nesting past the parser's budget: no parser internals in the message.
    let deep = dir.path().join("deep.yaml");
    std::fs::write(&deep, format!("mission: {}1{}\n", "[".repeat(200), "]".repeat(200))).unwrap();
    let out = spomp().arg("validate").arg(&deep).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = stdout_of(&out);
    assert!(!text.contains("budget breached") && !text.contains("Depth {"), "{text}");
    assert!(text.contains("nests too deeply"), "{text}");
}

#[test]
fn a_diagnostic_quotes_at_most_the_offending_line() {
    let dir = tempfile::tempdir().unwrap();
    // A text file inside the folder, included by mistake: the report must not print its lines.
    std::fs::write(dir.path().join("notes.txt"), "first line\nsecret-two\nsecret-three\n").unwrap();
    let m = mission(dir.path(), "m.yaml", "include: [notes.txt]\n");
    let out = spomp().arg("validate").arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = stdout_of(&out);
    assert!(text.contains("notes.txt"), "{text}");
    assert!(!text.contains("secret-two") && !text.contains("secret-three"), "{text}");
    // An error in the middle of a mission: its line is quoted, its neighbours are not.
    let out =
        spomp().current_dir(root()).args(["validate", "tests/missions/invalid-unknown-port.yaml"]).output().unwrap();
    let text = stdout_of(&out);
    assert!(text.contains(r#"- navigate_to: { target: "{goal_position}", speed: 3 }"#), "{text}");
    assert!(!text.contains("claim_goal") && !text.contains("mark_visited"), "{text}");
    // Out of the folder: refused before anything is read.
    let m = mission(dir.path(), "m2.yaml", "include: [/etc/passwd]\n");
    let out = spomp().arg("validate").arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = stdout_of(&out);
    assert!(text.contains("is outside") && !text.contains("root:"), "{text}");
}

#[test]
fn files_outside_the_mission_folder_need_allow_dir() {
    let shared = tempfile::tempdir().unwrap();
    std::fs::write(shared.path().join("lib.yaml"), "subtrees:\n  idle: { wait: { duration_s: 5 } }\n").unwrap();
    let dir = tempfile::tempdir().unwrap();
    let include = shared.path().join("lib.yaml");
    let m = mission(dir.path(), "m.yaml", &format!("include: [\"{}\"]\n", include.display()));
    let out = spomp().arg("validate").arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stdout_of(&out).contains("is outside"), "{}", stdout_of(&out));
    let out = spomp().arg("validate").arg("--allow-dir").arg(shared.path()).arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stdout_of(&out));
}

/// The pipe size `head_c_10` sets (the smallest Linux allows): an output longer than this cannot
/// all be written before the reader goes away.
const PIPE_CAPACITY: usize = 4096;

/// `spomp ARGS | head -c 10` through a pipe shrunk to [`PIPE_CAPACITY`] (Python's `fcntl`, as
/// std has no `F_SETPIPE_SZ`): reads 10 bytes, closes the pipe, and returns spomp's exit code, its
/// stderr and whether it was still running (so blocked writing) when the pipe closed.
fn head_c_10(args: &[&str]) -> (Option<i32>, String, bool) {
    const SCRIPT: &str = r#"
import fcntl, os, subprocess, sys
r, w = os.pipe()
fcntl.fcntl(w, 1031, int(sys.argv[1]))  # F_SETPIPE_SZ
p = subprocess.Popen(sys.argv[2:], stdout=w, stderr=subprocess.PIPE)
os.close(w)
got = b""
while len(got) < 10:
    chunk = os.read(r, 10 - len(got))
    if not chunk:
        break
    got += chunk
running = p.poll() is None
os.close(r)
err = p.stderr.read().decode("utf-8", "replace")
code = p.wait()
print(code, int(running), len(got))
sys.stderr.write(err)
"#;
    let out = StdCommand::new("python3")
        .arg("-c")
        .arg(SCRIPT)
        .arg(PIPE_CAPACITY.to_string())
        .arg(bin())
        .args(args)
        .output()
        .unwrap();
    let report = stdout_of(&out);
    let fields: Vec<i64> = report.split_whitespace().map(|f| f.parse().unwrap()).collect();
    assert_eq!(fields.len(), 3, "{report} {}", stderr_of(&out));
    assert_eq!(fields[2], 10, "{args:?}: fewer than 10 bytes of output");
    (i32::try_from(fields[0]).ok(), stderr_of(&out), fields[1] == 1)
}

/// Panics unless spomp ended on its own terms: no panic (exit 101), no signal (a negative code
/// from Python, none from std), nothing "panicked" on stderr.
fn assert_quiet_end(what: &str, code: Option<i32>, err: &str) {
    assert!(code.is_some_and(|c| c >= 0), "{what}: killed by a signal ({code:?}); {err}");
    assert_ne!(code, Some(101), "{what}: panicked: {err}");
    assert!(!err.contains("panicked"), "{what}: {err}");
}

#[test]
fn closed_stdout_ends_quietly() {
    let dir = tempfile::tempdir().unwrap();
    let world = dir.path().join("world");
    spomp().args(["world", "generate", "--seed", "1", "--size-m", "120,100", "--out"]).arg(&world).assert().code(0);
    let world = world.to_str().unwrap().to_string();
    let plan = ["plan", &world, "--random-pairs", "40", "--seed", "1", "--json"];
    let commands: [&[&str]; 5] =
        [&["schema"], &["nodes", "--json"], &["nodes", "--markdown"], &["world", "show", &world, "--json"], &plan];
    let mut exercised_while_writing = Vec::new();
    for args in commands {
        let full = spomp().args(args).output().unwrap();
        assert_eq!(full.status.code(), Some(0), "{args:?}: {}", stderr_of(&full));
        // The reading end is closed before spomp starts: its first write fails, whatever the
        // size of the output.
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = StdCommand::new(bin()).args(args).stdout(writer).stderr(Stdio::piped()).output().unwrap();
        assert_quiet_end(&format!("{args:?} into a closed pipe"), out.status.code(), &stderr_of(&out));
        // `| head -c 10`: the pipe closes while spomp is still writing when the output is larger
        // than the pipe holds.
        let (code, err, running) = head_c_10(args);
        assert_quiet_end(&format!("{args:?} | head -c 10"), code, &err);
        if full.stdout.len() > PIPE_CAPACITY + 10 {
            assert!(running, "{args:?}: a {} byte output cannot have been written whole", full.stdout.len());
            exercised_while_writing.push(args[0..2.min(args.len())].join(" "));
        }
    }
    // The schema (about 110 kB) and both node references were blocked in a write when `head`
    // went away.
    assert!(exercised_while_writing.len() >= 3, "only {exercised_while_writing:?} outlast the pipe");
}

#[test]
fn sim_flags_follow_the_mission_rules() {
    let m = "missions/visit-all-vehicle-clusters.yaml";
    for bad in ["NaN", "-1", "0", "1e12"] {
        let out = spomp().current_dir(root()).args(["sim", m, "--time-limit-s", bad]).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "--time-limit-s {bad}: {}", stderr_of(&out));
        assert!(stderr_of(&out).contains("positive number of seconds"), "{}", stderr_of(&out));
    }
    let out = spomp().current_dir(root()).args(["sim", m, "--trials", "0"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    let out = spomp().current_dir(root()).args(["sim", m, "--kill", "unknown@3"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_of(&out).contains("no robot `unknown` in the team"), "{}", stderr_of(&out));
    let out = spomp()
        .current_dir(root())
        .args(["sim", m, "--seed", "18446744073709551615", "--trials", "2"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_of(&out).contains("18446744073709551615"), "{}", stderr_of(&out));
    let out = spomp().current_dir(root()).args(["sim", m, "--trials", "100000"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_of(&out).contains("--force"), "{}", stderr_of(&out));
    let out = spomp().current_dir(root()).args(["sim", m, "--odometry-noise", "NaN"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn a_time_limit_mission_completes_at_its_time_limit() {
    let dir = tempfile::tempdir().unwrap();
    let m = mission(
        dir.path(),
        "m.yaml",
        "sim:\n  world: { generate: { size_m: [120, 100], vehicle_clusters: 1, roadblocks: 0 } }\n",
    );
    let out = spomp()
        .args(["sim", "--json", "--no-mcap", "--time-limit-s", "3", "--out"])
        .arg(dir.path().join("out"))
        .arg(&m)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stderr_of(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["completed"], 1, "{v}");
    assert_eq!(v["runs"][0]["outcome"], "complete", "{v}");
}

#[test]
fn stale_trial_folders_are_replaced_and_foreign_files_refused() {
    let dir = tempfile::tempdir().unwrap();
    let m = mission(
        dir.path(),
        "m.yaml",
        "sim:\n  world: { generate: { size_m: [120, 100], vehicle_clusters: 1, roadblocks: 0 } }\n",
    );
    let out_dir = dir.path().join("out");
    std::fs::create_dir_all(out_dir.join("trial-99/plots")).unwrap();
    std::fs::write(out_dir.join("trial-99/summary.json"), "{}").unwrap();
    let out =
        spomp().args(["sim", "--no-mcap", "--time-limit-s", "1", "--out"]).arg(&out_dir).arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stderr_of(&out));
    assert!(!out_dir.join("trial-99").exists(), "the previous run's trial folder is gone");
    assert!(out_dir.join("trial-1/summary.json").is_file());
    // A file spomp did not write: refused, and left alone.
    std::fs::write(out_dir.join("trial-1/notes.txt"), "mine").unwrap();
    let out =
        spomp().args(["sim", "--no-mcap", "--time-limit-s", "1", "--out"]).arg(&out_dir).arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_of(&out).contains("notes.txt"), "{}", stderr_of(&out));
    assert!(out_dir.join("trial-1/notes.txt").is_file());
}

#[test]
fn dry_runs_are_capped_and_report_setup_failures() {
    let dir = tempfile::tempdir().unwrap();
    let m = mission(
        dir.path(),
        "m.yaml",
        "sim:\n  world: { generate: { size_m: [120, 100], vehicle_clusters: 1, roadblocks: 0 } }\n",
    );
    // A simulated-time cap.
    let out = spomp().args(["validate", "--dry-run", "--json", "--time-limit-s", "2"]).arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stdout_of(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["dry_runs"][0]["dry_run"]["time_limit_s"], 2.0, "{v}");
    // A wall-time cap: a 1800 s mission of six robots stopped after half a second.
    let start = Instant::now();
    let out = spomp()
        .current_dir(root())
        .args(["validate", "--dry-run", "--json", "--max-wall-s", "0.5", "missions/visit-all-vehicle-clusters.yaml"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["dry_runs"][0]["dry_run"]["outcome"], "interrupted", "{v}");
    assert!(start.elapsed() < Duration::from_secs(60));
    // A world folder that is not there: the world stage finds it, at the mission's world field,
    // before any dry run.
    let m = mission(dir.path(), "m2.yaml", "sim:\n  world: { dir: no-such-world }\n");
    let out = spomp().args(["validate", "--dry-run", "--json"]).arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let d = &v["diagnostics"][0];
    assert_eq!(
        (d["stage"].as_str(), d["line"].as_u64(), d["node_path"].as_str()),
        (Some("world"), Some(11), Some("sim.world.dir")),
        "{v}"
    );
    assert!(d["message"].as_str().unwrap().contains("no-such-world"), "{v}");
    assert_eq!(v["dry_runs"], serde_json::json!([]), "{v}");
    // A generated world exists only per seed: a UGV off its map is found when the dry run sets
    // the simulation up, a diagnostic of the dry-run stage.
    let m = dir.path().join("m3.yaml");
    std::fs::write(
        &m,
        "mission: off-map\nteam:\n  - { id: ugv1, kind: ugv, role: r, priority: 1, start: { x_m: -50, y_m: 10 }, localization: { mode: ground_truth } }\n\
         roles:\n  r:\n    tree:\n      wait: { duration_s: 1e9 }\ncomplete_when: time_limit\ntime_limit_s: 60\n\
         sim:\n  world: { generate: { size_m: [120, 100], vehicle_clusters: 1, roadblocks: 0 } }\n",
    )
    .unwrap();
    let out = spomp().args(["validate", "--dry-run", "--json"]).arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let d = &v["diagnostics"][0];
    assert_eq!(d["stage"], "dry_run", "{v}");
    assert!(d["message"].as_str().unwrap().contains("ugv1"), "{v}");
}

/// Writes a world folder, then breaks one line of its `world.yaml`.
fn broken_world(dir: &Path, from: &str, to: &str) -> PathBuf {
    let w = dir.join(format!("w-{}", to.len() + from.len() + std::fs::read_dir(dir).unwrap().count()));
    spomp().args(["world", "generate", "--seed", "1", "--size-m", "120,100", "--out"]).arg(&w).assert().code(0);
    let path = w.join("world.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains(from), "{text}");
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
    w
}

#[test]
fn world_metadata_is_validated() {
    let dir = tempfile::tempdir().unwrap();
    for (from, to, expect) in [
        ("resolution_m: 0.5", "resolution_m: 1e-300", "resolution_m must be between 0.01 and 100"),
        ("resolution_m: 0.5", "resolution_m: 1e-8", "resolution_m must be between 0.01 and 100"),
        ("resolution_m: 0.5", "resolution_m: 1e308", "resolution_m must be between 0.01 and 100"),
        ("width: 240", "width: 100000", "at most 16000000 are allowed"),
    ] {
        let w = broken_world(dir.path(), from, to);
        let out = run_with_deadline(StdCommand::new(bin()).args(["world", "show"]).arg(&w), Duration::from_secs(60));
        assert_eq!(out.status.code(), Some(1), "{to}: {}", stderr_of(&out));
        assert!(stderr_of(&out).contains(expect), "{to}: {}", stderr_of(&out));
    }
    let w = broken_world(dir.path(), "origin:\n  x: 0.0", "origin:\n  x: .nan");
    let out = spomp().args(["world", "show"]).arg(&w).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    // NaN is refused where it is written: the file, line and column of the value.
    let err = stderr_of(&out);
    let line =
        std::fs::read_to_string(w.join("world.yaml")).unwrap().lines().position(|l| l == "  x: .nan").unwrap() + 1;
    assert!(
        err.contains(&format!("world.yaml:{line}:6: bad world description: `.nan` is not a finite number")),
        "{err}"
    );
}

fn python_mcap_available() -> bool {
    StdCommand::new("python3").args(["-c", "import mcap, mcap_ros2"]).status().is_ok_and(|s| s.success())
}

/// `scripts/check-mcap.py` (the Python reader in its default mode): the number of messages.
fn python_reads(log: &Path) -> u64 {
    let out = StdCommand::new("python3").arg(root().join("scripts/check-mcap.py")).arg(log).output().unwrap();
    assert!(out.status.success(), "python could not read {}: {}{}", log.display(), stdout_of(&out), stderr_of(&out));
    let text = stdout_of(&out);
    let line = text.lines().find(|l| l.starts_with("ok: ")).unwrap();
    line.trim_start_matches("ok: ").split(' ').next().unwrap().parse().unwrap()
}

fn start_sim(out_dir: &Path) -> std::process::Child {
    StdCommand::new(bin())
        .current_dir(root())
        .args(["sim", "missions/visit-all-vehicle-clusters.yaml", "--json", "--pano-every-s", "1", "--out"])
        .arg(out_dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn signal(child: &std::process::Child, sig: &str) {
    let ok = StdCommand::new("kill").args([sig, &child.id().to_string()]).status().unwrap().success();
    assert!(ok);
}

/// Waits until the log has at least `bytes` on disk (a few chunks written).
fn wait_for_log(log: &Path, bytes: u64) {
    let start = Instant::now();
    while std::fs::metadata(log).map_or(0, |m| m.len()) < bytes {
        assert!(start.elapsed() < Duration::from_secs(120), "the run wrote no log");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_killed_run_leaves_a_log_that_reads_to_its_last_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    let mut child = start_sim(&out_dir);
    let log = out_dir.join("trial-1/run.mcap");
    wait_for_log(&log, 200_000);
    // A random moment after the first chunks: 0 to 1.5 s later.
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().subsec_nanos();
    std::thread::sleep(Duration::from_millis(u64::from(nanos % 1500)));
    signal(&child, "-KILL");
    let _ = child.wait();
    let out = spomp().args(["log", "check", "--json"]).arg(&log).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}{}", stdout_of(&out), stderr_of(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["closed"], false, "{v}");
    let messages = v["messages"].as_u64().unwrap();
    assert!(messages > 1000, "{v}");
    assert!(v["topics"]["/ugv1/pose"].as_u64().unwrap() > 0, "{v}");
    // Recovered: a closed log with the same messages.
    let fixed = dir.path().join("fixed.mcap");
    spomp().args(["log", "recover"]).arg(&log).arg("--out").arg(&fixed).assert().code(0);
    let out = spomp().args(["log", "check", "--json"]).arg(&fixed).output().unwrap();
    let w: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(w["closed"], true, "{w}");
    assert_eq!(w["messages"].as_u64(), Some(messages));
    if python_mcap_available() {
        assert_eq!(python_reads(&log), messages, "the Python reader, default mode, reads the killed log");
        assert_eq!(python_reads(&fixed), messages);
    } else {
        eprintln!("note: python3 with mcap and mcap-ros2-support is not installed; the Python reader was not tried");
    }
}

#[test]
fn sigint_finishes_the_step_and_writes_summaries_marked_interrupted() {
    interrupted_by("-INT");
}

#[test]
fn sigterm_finishes_the_step_and_writes_summaries_marked_interrupted() {
    interrupted_by("-TERM");
}

fn interrupted_by(sig: &str) {
    let dir = tempfile::tempdir().unwrap();
    let out_dir = dir.path().join("out");
    let child = start_sim(&out_dir);
    wait_for_log(&out_dir.join("trial-1/run.mcap"), 100_000);
    signal(&child, sig);
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(130), "{}", stderr_of(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["interrupted"], true, "{v}");
    assert_eq!(v["runs"][0]["outcome"], "interrupted", "{v}");
    assert!(v["runs"][0]["end_s"].as_f64().unwrap() > 0.0);
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["interrupted"], true);
    let trial: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out_dir.join("trial-1/summary.json")).unwrap()).unwrap();
    assert_eq!(trial["outcome"], "interrupted");
    assert!(out_dir.join("trial-1/plots/map.png").is_file());
    let out = spomp().args(["log", "check", "--json"]).arg(out_dir.join("trial-1/run.mcap")).output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    let c: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(c["closed"], true, "the log was closed properly: {c}");
}

#[test]
fn log_check_rejects_what_is_not_a_log() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("x.mcap");
    std::fs::write(&f, "not a log").unwrap();
    let out = spomp().args(["log", "check"]).arg(&f).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(stderr_of(&out).contains("MCAP magic"), "{}", stderr_of(&out));
    spomp().args(["log", "check", "/dev/zero"]).assert().code(1);
    spomp().args(["log", "recover"]).arg(&f).arg("--out").arg(&f).assert().code(1);
}

#[test]
fn a_closed_stderr_never_turns_an_error_into_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.mcap");
    let missing = missing.to_str().unwrap();
    // Each goes down an `error:` path: a failed command, a usage error caught after parsing, a
    // replay of a missing log, an experiment that does not load.
    let commands: [&[&str]; 4] = [
        &["log", "check", missing],
        &["plan", "/nonexistent-world", "--from", "1,1"],
        &["replay", missing],
        &["experiment", "report", "/nonexistent-experiment"],
    ];
    for args in commands {
        let mut panics = 0;
        for _ in 0..10 {
            // The reading end is closed before spomp starts: every write to stderr fails (EPIPE).
            let (reader, writer) = std::io::pipe().unwrap();
            drop(reader);
            let status = StdCommand::new(bin()).args(args).stdout(Stdio::null()).stderr(writer).status().unwrap();
            assert!(status.code().is_some(), "{args:?}: killed by a signal");
            assert_ne!(status.code(), Some(0), "{args:?} succeeded");
            if status.code() == Some(101) {
                panics += 1;
            }
        }
        assert_eq!(panics, 0, "{args:?}: {panics} of 10 runs panicked with stderr a closed pipe");
    }
}

/// A file that is not a class table, given to `world import --classes`: the error says so and
/// quotes none of it.
#[test]
fn a_file_that_is_not_a_class_table_is_not_printed() {
    let dir = tempfile::tempdir().unwrap();
    let secrets: [(&str, &str); 4] = [
        (
            "passwd",
            "root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1:daemon:/usr/sbin:/usr/sbin/nologin\nsecretuser:x:1000:1000::/home/secretuser:/bin/sh\n",
        ),
        (
            "id_ed25519",
            "-----BEGIN OPENSSH PRIVATE KEY-----\nb3BlbnNzaC1rZXktdjEAAAAABG5vbmUAAAAEbm9uZQAAAAAAAAABAAAAMwAAAAtzc2gtZW\nQyNTUxOQAAACBsecretsecretsecretsecretsecretsecretAAAAJgAAAAtzc2gtZWQyNTUx\n-----END OPENSSH PRIVATE KEY-----\n",
        ),
        (".env", "DATABASE_URL=postgres://admin:hunter2secret@db/prod\nAPI_TOKEN=sk-live-secretsecretsecret\n"),
        // A mapping with the right key, holding the wrong kind: the value is not quoted either.
        ("nested.yaml", "classes: sk-live-secretsecretsecret-that-is-long-enough-to-matter\n"),
    ];
    for (name, text) in secrets {
        let file = dir.path().join(name);
        std::fs::write(&file, text).unwrap();
        let out = spomp()
            .args(["world", "import", "raster.png", "--classes"])
            .arg(&file)
            .args(["--resolution-m", "1", "--out"])
            .arg(dir.path().join("w"))
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(1), "{name}");
        let err = stderr_of(&out);
        assert!(err.contains(&format!("{}:1:", file.display())), "{name}: not located: {err}");
        for secret in ["secret", "hunter2", "b3BlbnNz", "daemon", "/bin/bash"] {
            assert!(!err.contains(secret), "{name}: the error quotes the file ({secret}): {err}");
        }
    }
}

/// An experiment output folder written by hand: two configurations and seeds 1 and 2, a row
/// each with the given configuration, seed, distance (metres) and end time (seconds).
fn experiment_folder(dir: &Path, rows: &[(&str, u64, f64, f64)]) {
    std::fs::create_dir_all(dir).unwrap();
    let meta = serde_json::json!({
        "experiment": "forged",
        "configurations": ["a", "b"],
        "seeds": [1, 2],
        "claims": [{ "name": "b goes further", "metric": "distance_m", "expect": "increasing", "over": ["a", "b"] }],
    });
    std::fs::write(dir.join("experiment.json"), meta.to_string()).unwrap();
    let mut jsonl = String::new();
    for (i, (configuration, seed, distance_m, end_s)) in rows.iter().enumerate() {
        let row = serde_json::json!({
            "trial": i, "configuration": configuration, "seed": seed, "config_hash": "0", "mission": "m",
            "outcome": "time_limit", "end_s": end_s, "time_limit_s": 600.0, "ugvs": 1, "goals_total": 2,
            "goals_visited": 1, "clusters_total": null, "clusters_visited": null, "visit_times_s": [10.0],
            "distance_m": distance_m, "heading_to_goal_fraction": 0.5, "collisions": 0,
            "localization_error_m": null, "bytes_sent": 10, "bytes_sent_full_links": 10,
            "bytes_sent_small_links": 0, "wall_s": 1.0, "robots": [],
        });
        jsonl.push_str(&format!("{row}\n"));
    }
    std::fs::write(dir.join("trials.jsonl"), jsonl).unwrap();
}

/// A row holding a value the plotting library cannot draw an axis for (≥ 1e200) made `experiment
/// report` loop for ever; the rows file was read without a size limit or a look at its type.
#[test]
fn experiment_report_survives_absurd_values_and_refuses_odd_rows_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("absurd");
    // Two seeds each: the spread of the absurd value is what sent the axis code into its loop.
    experiment_folder(&dir, &[("a", 1, 1e200, 30.0), ("a", 2, 5.0, 30.0), ("b", 1, 12.0, 1e250), ("b", 2, 13.0, 30.0)]);
    let out = run_with_deadline(
        StdCommand::new(bin()).args(["experiment", "report", "--json"]).arg(&dir),
        Duration::from_secs(60),
    );
    assert_eq!(out.status.code(), Some(0), "{}", stderr_of(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let left_out = v["left_out_of_plots"].as_array().unwrap();
    assert!(left_out.len() >= 2, "{v}");
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("## Left out of the plots") && md.contains("distance_m") && md.contains("end_s"), "{md}");
    assert!(std::fs::metadata(dir.join("plots/metrics.png")).unwrap().len() > 1000);

    // The rows file as a FIFO, a device, or larger than the limit: an error, never a hang.
    let fifo_dir = tmp.path().join("fifo");
    experiment_folder(&fifo_dir, &[]);
    std::fs::remove_file(fifo_dir.join("trials.jsonl")).unwrap();
    mkfifo(&fifo_dir.join("trials.jsonl"));
    let zero_dir = tmp.path().join("zero");
    experiment_folder(&zero_dir, &[]);
    std::fs::remove_file(zero_dir.join("trials.jsonl")).unwrap();
    std::os::unix::fs::symlink("/dev/zero", zero_dir.join("trials.jsonl")).unwrap();
    let big_dir = tmp.path().join("big");
    experiment_folder(&big_dir, &[]);
    let f = std::fs::File::create(big_dir.join("trials.jsonl")).unwrap();
    f.set_len(65 << 20).unwrap(); // sparse: no disk used
    for d in [&fifo_dir, &zero_dir, &big_dir] {
        let out =
            run_with_deadline(StdCommand::new(bin()).args(["experiment", "report"]).arg(d), Duration::from_secs(30));
        assert_eq!(out.status.code(), Some(1), "{}: {}", d.display(), stderr_of(&out));
        let err = stderr_of(&out);
        assert!(err.contains("not a regular file") || err.contains("at most"), "{err}");
    }
}

/// A closed, replayable-free log of a short simulated run (its bytes).
fn small_log(dir: &Path) -> Vec<u8> {
    let out_dir = dir.join("sim");
    let out = spomp()
        .current_dir(root())
        .args(["sim", "missions/visit-all-vehicle-clusters.yaml", "--time-limit-s", "8", "--out"])
        .arg(&out_dir)
        .output()
        .unwrap();
    assert!(out.status.code().is_some_and(|c| c <= 1), "{}", stderr_of(&out));
    std::fs::read(out_dir.join("trial-1/run.mcap")).unwrap()
}

/// Bit flips anywhere in a closed log: `log check` verified no CRC (19 of 30 flipped logs were
/// "closed properly"), and `log recover` turned a corrupted log into a checksum-valid one.
#[test]
fn log_check_verifies_every_crc_and_recover_keeps_what_checks_out() {
    let tmp = tempfile::tempdir().unwrap();
    let log = small_log(tmp.path());
    let clean = tmp.path().join("clean.mcap");
    std::fs::write(&clean, &log).unwrap();
    let out = spomp().args(["log", "check", "--json"]).arg(&clean).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stdout_of(&out));
    let c: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    // Every chunk, the data section and the summary carry a CRC, and each holds.
    assert!(c["crcs_verified"].as_u64().unwrap() >= c["chunks"].as_u64().unwrap() + 2, "{c}");
    assert_eq!(c["intact"], true);
    // 30 flips spread over the file past the leading magic: none may pass as intact.
    let mut passed = Vec::new();
    for k in 0..30u64 {
        let at = 8 + (k * 7919 * 104_729) as usize % (log.len() - 16);
        let mut bytes = log.clone();
        bytes[at] ^= 1 << (k % 8);
        let f = tmp.path().join(format!("flip{k}.mcap"));
        std::fs::write(&f, &bytes).unwrap();
        let out = spomp().args(["log", "check", "--json"]).arg(&f).output().unwrap();
        let v: Option<serde_json::Value> = serde_json::from_slice(&out.stdout).ok();
        // Exit 1 and a report, or an error (no longer an MCAP log).
        if out.status.code() == Some(0) || v.as_ref().is_some_and(|v| v["intact"] == true) {
            passed.push(at);
        }
        if k % 10 == 0 {
            // Recover keeps what checks out: its output is intact and says what it dropped.
            let fixed = tmp.path().join(format!("fixed{k}.mcap"));
            let out = spomp().args(["log", "recover", "--json"]).arg(&f).arg("--out").arg(&fixed).output().unwrap();
            if out.status.code() == Some(0) {
                let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
                let check = spomp().args(["log", "check", "--json"]).arg(&fixed).output().unwrap();
                let fc: serde_json::Value = serde_json::from_slice(&check.stdout).unwrap();
                assert_eq!(fc["intact"], true, "{fc}");
                assert_eq!(fc["messages"], r["messages"], "{fc} {r}");
                if r["corrupt"].is_object() {
                    assert!(!r["dropped"].as_array().unwrap().is_empty(), "{r}");
                }
            }
        }
    }
    assert!(passed.is_empty(), "flips at bytes {passed:?} passed as intact");
    // A chunk whose records do not match its recorded CRC (the CRC field flipped: a flip in
    // the compressed records mostly fails decompression first): it and all after are dropped.
    let mut bytes = log.clone();
    // The first chunk record: walk the records (opcode, u64 length, body) from the magic on.
    let mut chunk = 8;
    while log[chunk] != 0x06 {
        chunk += 9 + u64::from_le_bytes(log[chunk + 1..chunk + 9].try_into().unwrap()) as usize;
    }
    let last = bytes.len() - 1;
    let inside = chunk + 9 + 24; // the chunk's uncompressed_crc
    bytes[inside] ^= 0x10;
    let f = tmp.path().join("chunk.mcap");
    std::fs::write(&f, &bytes).unwrap();
    let out = spomp().args(["log", "check"]).arg(&f).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = stdout_of(&out);
    assert!(text.contains("CRC mismatch") && !text.contains("closed properly"), "{text}");
    let fixed = tmp.path().join("chunk-fixed.mcap");
    let out = spomp().args(["log", "recover"]).arg(&f).arg("--out").arg(&fixed).output().unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stderr_of(&out));
    assert!(stdout_of(&out).contains("dropped: "), "{}", stdout_of(&out));
    assert!(last > inside);
}

/// A robot named `mission` shares the ids of the mission file's goals: refused by validate.
#[test]
fn a_robot_named_mission_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let text = "mission: clash\nteam:\n  - { id: base, kind: basestation, role: base, start: { x_m: 10, y_m: 10 } }\n  \
                - { id: mission, kind: ugv, role: base, priority: 1, start: { x_m: 12, y_m: 10 } }\n\
                roles:\n  base:\n    tree:\n      wait: { duration_s: 1e9 }\ncomplete_when: time_limit\ntime_limit_s: 600\n";
    let m = dir.path().join("clash.yaml");
    std::fs::write(&m, text).unwrap();
    let out = spomp().arg("validate").arg("--json").arg(&m).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stdout_of(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!((v[0]["line"].as_u64(), v[0]["node_path"].as_str()), (Some(4), Some("team[1].id")), "{v}");
    assert!(v[0]["message"].as_str().unwrap().contains("reserved"), "{v}");
}

/// Links planted in output folders beforehand are never written through: world generate, show
/// and import, the simulator's summaries, plots and log, and the experiment report.
#[test]
fn links_planted_in_output_folders_are_not_written_through() {
    use std::os::unix::fs::symlink;
    let tmp = tempfile::tempdir().unwrap();
    let victim = tmp.path().join("victim.txt");
    std::fs::write(&victim, "precious").unwrap();
    let untouched = || assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");

    // world generate, into a folder holding a link named like an output.
    let world = tmp.path().join("world");
    std::fs::create_dir(&world).unwrap();
    symlink(&victim, world.join("class.png")).unwrap();
    let out = spomp()
        .args(["world", "generate", "--seed", "1", "--size-m", "120,100", "--out"])
        .arg(&world)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr_of(&out));
    assert!(stderr_of(&out).contains("symbolic link"), "{}", stderr_of(&out));
    untouched();
    std::fs::remove_file(world.join("class.png")).unwrap();
    spomp().args(["world", "generate", "--seed", "1", "--size-m", "120,100", "--out"]).arg(&world).assert().code(0);
    // world show's render.
    symlink(&victim, world.join("render.png")).unwrap();
    let out = spomp().args(["world", "show"]).arg(&world).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr_of(&out));
    untouched();
    // world import's record.
    let imported = tmp.path().join("imported");
    std::fs::create_dir(&imported).unwrap();
    symlink(&victim, imported.join("import.yaml")).unwrap();
    let campus = root().join("tests/worlds/campus");
    let out = spomp()
        .args(["world", "import"])
        .arg(campus.join("campus.png"))
        .arg("--classes")
        .arg(campus.join("campus-classes.yaml"))
        .args(["--resolution-m", "2", "--out"])
        .arg(&imported)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr_of(&out));
    untouched();

    // The simulator: a summary, a plot folder, the log.
    let m = mission(tmp.path(), "m.yaml", "");
    for (planted, is_dir) in
        [("summary.json", false), ("trial-1/summary.json", false), ("trial-1/plots", true), ("trial-1/run.mcap", false)]
    {
        let out_dir = tmp.path().join(format!("sim-{}", planted.replace('/', "-")));
        std::fs::create_dir_all(out_dir.join("trial-1")).unwrap();
        let target = if is_dir { tmp.path().to_path_buf() } else { victim.clone() };
        symlink(&target, out_dir.join(planted)).unwrap();
        let out = spomp().args(["sim", "--time-limit-s", "2"]).arg(&m).arg("--out").arg(&out_dir).output().unwrap();
        // 1: refused where the file is written; 2: a trial folder holding what the simulator
        // does not write is refused up front.
        assert!(matches!(out.status.code(), Some(1 | 2)), "{planted}: {}", stderr_of(&out));
        untouched();
        assert!(!tmp.path().join("map.png").exists(), "{planted}: a plot went through the folder link");
    }

    // The experiment report's files.
    let exp = tmp.path().join("exp");
    experiment_folder(&exp, &[("a", 1, 1.0, 30.0), ("b", 1, 2.0, 30.0)]);
    symlink(&victim, exp.join("report.md")).unwrap();
    let out = spomp().args(["experiment", "report"]).arg(&exp).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", stderr_of(&out));
    untouched();
}
