//! The team link under an insider's flood, whole process (issue 36): a `spomp run` basestation
//! on the Zenoh team link with the team's keys, and a flooder that has the transport password
//! (a leaked one) but no member's signing key. It sends every message under a new invented
//! sender name, forgeries in a member's name and a message over the size limit. The robot
//! refuses and counts them all, and keeps no record per invented name: its rejection tables and
//! the link's per-sender figures hold the team's members at most.
//!
//! Also the start-up refusals of the link's files: a `--state-file` that is some other file,
//! and a secret key file others may read.
//!
//! DDS stays on 127.0.0.1 (`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, a domain id per test);
//! Zenoh listens and connects on 127.0.0.1 ports only, multicast scouting off.
#![allow(clippy::unwrap_used, clippy::expect_used)] // tests may unwrap

mod processes;

use std::io::Read;
use std::net::TcpListener;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use processes::{Reap, output, spomp, wait_with_timeout};
use spomp_core::RobotId;
use spomp_teamstate::{Record, RecordBody, RecordKey, SyncMessage, VisitRecord};
use spomp_zenoh::KeyDir;
use zenoh::Wait;

const MISSION: &str = "tests/missions/ros2/team-link-flood.yaml";
const TEAM: &str = "team-link-flood";
/// Messages under invented sender names, one name each.
const INVENTED: usize = 20_000;
/// Forgeries in ugv1's name (a member: they reach the team state and fail its signature check).
const FORGED: usize = 200;

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

fn domain() -> String {
    (140 + std::process::id() % 50).to_string()
}

/// A scratch folder with the team's keys.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Scratch {
        let dir = std::env::temp_dir().join(format!("spomp-flood-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let keys = spomp().args(["keys", "generate", MISSION, "--out"]).arg(dir.join("keys")).output().unwrap();
        assert!(keys.status.success(), "{}", String::from_utf8_lossy(&keys.stderr));
        Scratch(dir)
    }

    fn keys(&self) -> PathBuf {
        self.0.join("keys")
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn run_base(keys: &Path, port: u16, extra: &[&str]) -> Command {
    let mut cmd = spomp();
    cmd.args(["run", MISSION, "--robot", "base", "--json", "--domain-id", &domain()]);
    cmd.arg("--keys").arg(keys).args(["--listen", &format!("tcp/127.0.0.1:{port}")]).args(extra);
    cmd
}

/// The flooder's Zenoh session: ugv1's transport password, connected to the robot.
fn flooder_session(keys: &KeyDir, port: u16) -> zenoh::Session {
    let credentials = keys.credentials(&RobotId::new("ugv1")).unwrap();
    let mut config = zenoh::Config::default();
    let mut set = |key: &str, value: String| config.insert_json5(key, &value).unwrap();
    set("mode", "\"peer\"".into());
    set("listen/endpoints", "[]".into());
    set("connect/endpoints", format!("[\"tcp/127.0.0.1:{port}\"]"));
    set("scouting/multicast/enabled", "false".into());
    set("transport/auth/usrpwd/user", serde_json::to_string(&credentials.user).unwrap());
    set("transport/auth/usrpwd/password", serde_json::to_string(&credentials.password).unwrap());
    set(
        "transport/auth/usrpwd/dictionary_file",
        serde_json::to_string(&credentials.dictionary_file.display().to_string()).unwrap(),
    );
    zenoh::open(config).wait().unwrap()
}

/// A well-formed message from `from` to the basestation claiming a visit, signed with a key no
/// member holds (`signed`) or not at all.
fn message(from: &str, seq: u32, signed: bool) -> Vec<u8> {
    let record = Record {
        key: RecordKey::Visit {
            goal: spomp_core::GoalId { origin: RobotId::new("mission"), seq: 0 },
            robot: RobotId::new(from),
        },
        dot: 1,
        body: RecordBody::Visit(VisitRecord { stamp: spomp_core::Time::from_secs_f64(1.0) }),
        sig: signed.then(|| Box::new(spomp_teamstate::Signature([7; 64]))),
    };
    let msg = SyncMessage {
        from: RobotId::new(from),
        to: RobotId::new("base"),
        seq,
        ack: Default::default(),
        peer_has_all: true,
        wants_ack: true,
        records: vec![record],
        session: 1,
        signature: signed.then_some(spomp_teamstate::Signature([7; 64])),
    };
    msg.encode()
}

fn put(session: &zenoh::Session, from: &str, bytes: Vec<u8>) {
    session
        .put(format!("spomp/{TEAM}/team/base/{from}/coordination"), bytes)
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait()
        .unwrap();
}

/// Resident and peak memory of a process, kB (Linux).
fn memory_kb(pid: u32) -> (u64, u64) {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

#[test]
fn an_insider_flood_under_invented_names_is_refused_counted_and_kept_nowhere() {
    let scratch = Scratch::new("names");
    let keys = KeyDir::load(&scratch.keys()).unwrap();
    let port = free_port();
    let mut base =
        Reap(run_base(&scratch.keys(), port, &[]).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap());
    let session = flooder_session(&keys, port);

    // Until the robot's liveliness token is visible, the link is not up yet.
    let start = Instant::now();
    loop {
        assert!(start.elapsed() < Duration::from_secs(60), "the robot's team link never came up");
        assert!(base.0.try_wait().unwrap().is_none(), "the robot exited: {:?}", output(&mut base.0));
        let replies = session.liveliness().get(format!("spomp/{TEAM}/alive/base")).wait().unwrap();
        if replies.recv_timeout(Duration::from_secs(1)).ok().flatten().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    // A put before the robot's subscription has reached the flooder's session goes nowhere:
    // wait until a publisher on the flood's key expressions has a match (this was a 1 s sleep).
    let probe = session.declare_publisher(format!("spomp/{TEAM}/team/base/ugv1/coordination")).wait().unwrap();
    let start = Instant::now();
    while !probe.matching_status().wait().unwrap().matching() {
        assert!(start.elapsed() < Duration::from_secs(60), "the robot's subscription never reached the flooder");
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = probe.undeclare().wait();
    let before = memory_kb(base.0.id());

    for k in 0..INVENTED {
        let name = format!("intruder-{k}");
        put(&session, &name, message(&name, 1, k % 2 == 0));
    }
    for k in 0..FORGED {
        put(&session, "ugv1", message("ugv1", k as u32 + 1, true));
    }
    // Over the link's 16 MiB limit, in a member's name.
    put(&session, "ugv1", vec![0u8; 17 * 1024 * 1024]);
    // Let the robot take what arrived (the assertions below count, they do not time).
    std::thread::sleep(Duration::from_secs(3));
    let after = memory_kb(base.0.id());
    let _ = session.close().wait();

    let _ = Command::new("kill").args(["-INT", &base.0.id().to_string()]).status();
    // Read while it exits: a report larger than the pipe's buffer would block it otherwise.
    let readers: Vec<_> = [
        base.0.stdout.take().map(|s| Box::new(s) as Box<dyn std::io::Read + Send>),
        base.0.stderr.take().map(|s| Box::new(s) as _),
    ]
    .into_iter()
    .map(|pipe| {
        std::thread::spawn(move || {
            let mut text = String::new();
            if let Some(mut pipe) = pipe {
                let _ = pipe.read_to_string(&mut text);
            }
            text
        })
    })
    .collect();
    let status = wait_with_timeout(&mut base.0, Duration::from_secs(60));
    let _ = base.0.kill();
    let mut texts = readers.into_iter().map(|r| r.join().unwrap_or_default());
    let (stdout, stderr) = (texts.next().unwrap_or_default(), texts.next().unwrap_or_default());
    assert!(status.is_some_and(|s| s.success()), "{status:?}\n{stderr}");
    let report: serde_json::Value =
        serde_json::from_str(&stdout).unwrap_or_else(|_| panic!("no report:\n{stdout}\n{stderr}"));
    eprintln!(
        "memory of the robot: {} kB resident before the flood, {} kB after; peak {} kB",
        before.0, after.0, after.1
    );
    eprintln!(
        "rejections by kind: {}; unknown senders: {}",
        report["team_rejected_by_kind"], report["team_rejected_unknown_sender"]
    );

    // Kept nowhere: the per-sender tables hold members only.
    let names = |v: &serde_json::Value| -> Vec<String> {
        v.as_object().map(|o| o.keys().cloned().collect()).unwrap_or_default()
    };
    for table in [&report["team_rejected"], &report["team_rejected_why"], &report["team_link"]["received"]] {
        let names = names(table);
        assert!(
            names.iter().all(|n| n == "ugv1"),
            "a per-sender table holds {} names, non-members among them: {:?}…",
            names.len(),
            &names[..names.len().min(5)]
        );
    }
    // Counted: every invented name as one number, never by name.
    let unknown = report["team_rejected_unknown_sender"].as_u64().unwrap();
    assert!(unknown >= INVENTED as u64 / 2, "only {unknown} of {INVENTED} invented senders counted:\n{report:#}");
    let link = &report["team_link"];
    assert_eq!(link["refused"]["unknown_sender"].as_u64(), Some(unknown), "{link:#}");
    // The forgeries in ugv1's name reached the team state and failed its signature check; the
    // oversized message was refused by the link and counted.
    assert!(report["team_rejected"]["ugv1"].as_u64().unwrap_or(0) > 0, "{report:#}");
    assert!(report["team_rejected_by_kind"]["bad_signature"].as_u64().unwrap_or(0) > 0, "{report:#}");
    assert_eq!(report["team_rejected_by_kind"]["oversized"].as_u64(), Some(1), "{report:#}");
    let kinds = names(&report["team_rejected_by_kind"]);
    let known: Vec<&str> =
        spomp_teamstate::SyncError::KINDS.iter().copied().chain(["unknown_sender", "inbox_full"]).collect();
    assert!(kinds.iter().all(|k| known.contains(&k.as_str())), "{kinds:?}");
}

/// Regression (issue 36): `--state-file` naming some other file was reported as ignored, and
/// the robot's first save overwrote it.
#[test]
fn a_state_file_that_is_some_other_file_stops_the_start_and_is_left_alone() {
    let scratch = Scratch::new("state");
    let notes = scratch.0.join("notes.txt");
    std::fs::write(&notes, "my notes\n").unwrap();
    let mut cmd = run_base(&scratch.keys(), free_port(), &["--until-s", "1", "--state-period-s", "0.2"]);
    let mut child =
        Reap(cmd.arg("--state-file").arg(&notes).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap());
    let status = wait_with_timeout(&mut child.0, Duration::from_secs(60)).expect("spomp run ends");
    let (_, stderr) = output(&mut child.0);
    assert!(!status.success(), "started with a state file that is not one:\n{stderr}");
    assert!(stderr.contains("not a spomp state file") && stderr.contains("not overwritten"), "{stderr}");
    assert_eq!(std::fs::read_to_string(&notes).unwrap(), "my notes\n");
}

/// Regression (issue 36): a key file anyone could read was taken without a word.
#[cfg(unix)]
#[test]
fn a_key_file_others_may_read_stops_the_start_with_the_fix() {
    use std::os::unix::fs::PermissionsExt;
    let scratch = Scratch::new("mode");
    let key = scratch.keys().join("base.key.json");
    assert_eq!(std::fs::metadata(&key).unwrap().permissions().mode() & 0o777, 0o600, "written 0600");
    std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).unwrap();
    let mut child = Reap(
        run_base(&scratch.keys(), free_port(), &["--until-s", "1"])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let status = wait_with_timeout(&mut child.0, Duration::from_secs(60)).expect("spomp run ends");
    let (_, stderr) = output(&mut child.0);
    assert!(!status.success(), "started with a key file others may read:\n{stderr}");
    assert!(stderr.contains("base.key.json") && stderr.contains("chmod 600"), "{stderr}");
}
