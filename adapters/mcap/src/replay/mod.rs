//! Replay: a field failure debugged on a laptop.
//!
//! A log recorded with its seam calls (`/R/seam`, see [`spomp_robot::SeamCall`]) and the run's
//! setup ([`crate::RunInfo`]) holds everything one robot consumed. [`replay`] builds a
//! fresh robot from the mission, area and seed stored in the log, makes on it the recorded calls
//! in the recorded order — odometry, panoramas, external poses, camera tiles, team-state bytes
//! as received, sync requests, ticks, halts — and compares, message by message, what it
//! produces with what was recorded: the command or flight command after every tick, every node
//! transition (`/R/bt`) and every team-state message it sends. The first difference is the
//! divergence; none means the replay is identical.
//!
//! It does not matter what recorded the log: the simulator and a robot both drive the same seam
//! (`spomp_robot::Robot`), so one code path replays both.

mod setup;

use std::collections::VecDeque;
use std::time::Instant;

use crate::{LogMessage, ReadError, RunInfo, SeamCallMsg, call_from_msg, decode_cdr, open_replay_log};
use serde::Serialize;
use spomp_behaviors::TreeObserver;
use spomp_behaviors::trace::{Recorder, TransitionRecord};
use spomp_core::Time;
use spomp_mapping::CompressionParams;
use spomp_robot::{OperatingArea, Robot, RobotSetup, SeamCall, SeamReply, SetupOptions};

pub use setup::{area_record, mission_files, png_level_name, run_info};

/// Why a log could not be replayed (a divergence is no error: see [`ReplayReport`]).
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The log does not read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The log lacks what a replay needs, or holds something wrong.
    #[error("{0}")]
    Log(String),
    /// The recorded mission does not load here.
    #[error("{0}")]
    Mission(String),
    /// The robot could not be built.
    #[error("building the robot: {0}")]
    Robot(String),
    /// A `--set` does not apply.
    #[error("--set {0}")]
    Set(String),
    /// Scratch files for the mission.
    #[error("{0}")]
    Io(String),
}

/// What to replay.
#[derive(Clone, Debug, Default)]
pub struct ReplayOptions {
    /// The robot's id.
    pub robot: String,
    /// Stop after the calls at this log time, seconds.
    pub until_s: Option<f64>,
    /// Settings changed on replay: (`navigation.…` path, value as YAML/JSON scalar or text),
    /// applied as the robot's own `navigation` overrides.
    pub sets: Vec<(String, String)>,
    /// The robot's signing key and its team's public keys, for a robot that signed its team
    /// state (`spomp run --keys`): its messages are then the same bytes, signatures included.
    pub security: Option<std::sync::Arc<spomp_teamstate::TeamSecurity>>,
}

/// Where the replay first differed from the log.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Divergence {
    /// Log time, seconds.
    pub time_s: f64,
    /// What differed: `/R/bt` (a node transition), `/R/seam:tick` (the command after a tick) or
    /// `/R/seam:team_out` (a team-state message the robot sent).
    pub channel: String,
    /// What the log holds.
    pub recorded: String,
    /// What the replay produced.
    pub replayed: String,
    /// The node path that differed (a transition's node, or the running leaves at a tick).
    pub node_path: String,
}

/// What a replay found.
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    /// The robot replayed.
    pub robot: String,
    /// What recorded the log (`sim`, `run`) and with which spomp.
    pub source: String,
    /// spomp version of the recording.
    pub recorded_with: String,
    /// The run's seed.
    pub seed: u64,
    /// Nothing differed (up to where the replay stopped).
    pub identical: bool,
    /// The first difference, if any.
    pub divergence: Option<Divergence>,
    /// The log was not closed properly: it was replayed up to its last whole chunk.
    pub truncated: bool,
    /// Log time of the last readable message, seconds.
    pub log_end_s: f64,
    /// Log time of the last call replayed, seconds.
    pub replayed_to_s: f64,
    /// Calls made on the robot.
    pub calls: u64,
    /// Ticks compared.
    pub ticks: u64,
    /// Node transitions compared.
    pub transitions: u64,
    /// Team-state messages compared.
    pub team_messages: u64,
    /// Heavy-skill jobs replayed (`take_work` … `finish_work`: logs of `spomp run`).
    pub skill_jobs: u64,
    /// Wall-clock seconds the replay took (building the robot included).
    pub wall_s: f64,
    /// Simulated seconds replayed per wall-clock second.
    pub speed: f64,
}

/// A recorded transition: log time, `robot/path`, `from -> to (tick t, node n)`.
struct Recorded {
    time_ns: i64,
    name: String,
    msg: String,
}

/// Replays robot `options.robot` of a log (its bytes), its tree built from `registry` (the one
/// the run used: `spomp_robot::registry()`, or a lab's with more node types); `trace` sees every
/// node transition the replayed robot makes.
pub fn replay(
    bytes: &[u8],
    options: &ReplayOptions,
    registry: &spomp_behaviors::NodeRegistry<spomp_robot::RobotRuntime>,
    trace: &mut dyn FnMut(&TransitionRecord),
) -> Result<ReplayReport, ReplayError> {
    let wall = Instant::now();
    let log = open_replay_log(bytes)?;
    let info = log.info.as_ref().ok_or_else(|| {
        ReplayError::Log(
            "the log holds no run setup (metadata `spomp.run`): record it with `spomp sim --replayable`".into(),
        )
    })?;
    let id = options.robot.as_str();
    let seam_topic = format!("/{id}/seam");
    let bt_topic = format!("/{id}/bt");
    if !info.robot_seeds.contains_key(id) {
        let robots: Vec<&String> = info.robot_seeds.keys().collect();
        return Err(ReplayError::Log(format!("no robot `{id}` in the log; robots in the run: {robots:?}")));
    }
    let mut robot = build_robot(info, id, &options.sets, registry)?;
    match (&options.security, info.team_secured) {
        (Some(security), _) => {
            robot.secure_team(security.clone()).map_err(|e| ReplayError::Robot(e.to_string()))?;
        }
        (None, true) => {
            return Err(ReplayError::Robot(format!(
                "{id} signed its team state (spomp run --keys): give the team's key folder with --keys DIR to replay it"
            )));
        }
        (None, false) => {}
    }
    let until_ns = options.until_s.map(|s| Time::from_secs_f64(s).nanos);
    let mut state = State {
        id: id.to_string(),
        recorded: VecDeque::new(),
        report: ReplayReport {
            robot: id.to_string(),
            source: info.source.clone(),
            recorded_with: info.spomp_version.clone(),
            seed: info.run_seed,
            identical: true,
            divergence: None,
            truncated: log.truncated,
            log_end_s: log.end_ns as f64 * 1e-9,
            replayed_to_s: 0.0,
            calls: 0,
            ticks: 0,
            transitions: 0,
            team_messages: 0,
            skill_jobs: 0,
            wall_s: 0.0,
            speed: 0.0,
        },
    };
    let mut error = None;
    let keep = |t: &str| t == seam_topic || t == bt_topic;
    log.stream(&keep, &mut |m| match state.step(&mut robot, &m, &bt_topic, until_ns, trace) {
        Ok(go_on) => go_on,
        Err(e) => {
            error = Some(e);
            false
        }
    })?;
    if let Some(e) = error {
        return Err(e);
    }
    if state.report.calls == 0 {
        return Err(ReplayError::Log(format!(
            "the log holds no seam calls of `{id}` ({seam_topic}): record it with `spomp sim --replayable`"
        )));
    }
    let mut report = state.report;
    report.wall_s = wall.elapsed().as_secs_f64();
    report.speed = if report.wall_s > 0.0 { report.replayed_to_s / report.wall_s } else { 0.0 };
    Ok(report)
}

/// A fresh robot `id` from the run's setup, with `sets` applied to its navigation settings.
fn build_robot(
    info: &RunInfo,
    id: &str,
    sets: &[(String, String)],
    registry: &spomp_behaviors::NodeRegistry<spomp_robot::RobotRuntime>,
) -> Result<Robot, ReplayError> {
    let dir = tempfile::tempdir().map_err(|e| ReplayError::Io(format!("a scratch folder for the mission: {e}")))?;
    let loaded = setup::load_from_info(info, dir.path(), registry)?;
    let mut mission = loaded.mission.clone().ok_or_else(|| ReplayError::Mission("the mission did not load".into()))?;
    let spec = mission
        .team
        .iter_mut()
        .find(|r| r.id == id)
        .ok_or_else(|| ReplayError::Robot(format!("no robot `{id}` in the recorded mission's team")))?;
    for (path, value) in sets {
        apply_set(&mut spec.navigation, path, value)?;
    }
    let area = OperatingArea {
        classes: info.area.classes.clone(),
        grid: info.area.grid,
        prior_map: info.area.prior_map.clone(),
        map_origin: info.area.map_origin,
    };
    let inputs = SetupOptions {
        map_publish_period_s: info.map_publish_period_s,
        map_compression: CompressionParams { level: setup::png_level(&info.map_compression)? },
        robot_seed: info.robot_seeds.get(id).copied(),
    };
    let setup = RobotSetup::from_mission_with(&mission, id, &area, info.run_seed, &inputs).map_err(|e| match e {
        spomp_robot::SetupError::Settings(s) if !sets.is_empty() => ReplayError::Set(s.to_string()),
        other => ReplayError::Robot(other.to_string()),
    })?;
    let mut robot = Robot::from_setup(&loaded, setup, registry).map_err(|e| ReplayError::Robot(e.to_string()))?;
    robot.set_background_skills(info.background_skills);
    robot.set_team_session(info.team_session);
    drop(dir);
    Ok(robot)
}

/// Sets `navigation.a.b=value` in a robot's own navigation overrides: the value as a patch
/// `{a: {b: value}}` merged by the workspace's one JSON patcher (`spomp_robot::settings::merge`:
/// a mapping merges field by field, anything else replaces). A key under a value that is not a
/// section is refused, not replaced.
fn apply_set(navigation: &mut Option<serde_json::Value>, path: &str, value: &str) -> Result<(), ReplayError> {
    let Some(rest) = path.strip_prefix("navigation.") else {
        return Err(ReplayError::Set(format!(
            "`{path}`: only the robot's navigation settings can be changed on replay (`navigation.…`)"
        )));
    };
    let keys: Vec<&str> = rest.split('.').collect();
    if keys.iter().any(|k| k.is_empty()) {
        return Err(ReplayError::Set(format!("`{path}` has an empty key")));
    }
    let parsed = serde_json::from_str::<serde_json::Value>(value.trim())
        .unwrap_or_else(|_| serde_json::Value::String(value.to_string()));
    let base = navigation.get_or_insert_with(|| serde_json::Value::Object(Default::default()));
    let mut at = &*base;
    for (k, key) in keys.iter().enumerate() {
        let serde_json::Value::Object(map) = at else {
            return Err(ReplayError::Set(format!("`{path}`: `{}` is not a section", keys[..k].join("."))));
        };
        match map.get(*key) {
            Some(next) if k + 1 < keys.len() => at = next,
            _ => break,
        }
    }
    let patch = keys
        .iter()
        .rev()
        .fold(parsed, |v, key| serde_json::Value::Object(serde_json::Map::from_iter([((*key).to_string(), v)])));
    spomp_robot::settings::merge(base, &patch);
    Ok(())
}

fn recorded_transition(m: &LogMessage) -> Result<Recorded, ReplayError> {
    let log: spomp_ros_msgs::Log = decode_cdr(&m.topic, &m.data)?;
    let time_ns = i64::from(log.stamp.sec) * 1_000_000_000 + i64::from(log.stamp.nanosec);
    Ok(Recorded { time_ns, name: log.name, msg: log.msg })
}

struct State {
    id: String,
    recorded: VecDeque<Recorded>,
    report: ReplayReport,
}

impl State {
    /// One message of the robot's channels; false once the replay is to stop.
    fn step(
        &mut self,
        robot: &mut Robot,
        m: &LogMessage,
        bt_topic: &str,
        until_ns: Option<i64>,
        trace: &mut dyn FnMut(&TransitionRecord),
    ) -> Result<bool, ReplayError> {
        if m.topic == bt_topic {
            self.recorded.push_back(recorded_transition(m)?);
            return Ok(true);
        }
        let msg: SeamCallMsg = decode_cdr(&m.topic, &m.data)?;
        if until_ns.is_some_and(|u| msg.stamp_ns > u) {
            return Ok(false);
        }
        let call = call_from_msg(&m.topic, &msg)?;
        let now = Time::from_nanos(msg.stamp_ns);
        self.report.calls += 1;
        self.report.replayed_to_s = now.as_secs_f64();
        if let Some(d) = self.apply(robot, now, call, trace) {
            self.report.identical = false;
            self.report.divergence = Some(d);
            return Ok(false);
        }
        Ok(true)
    }

    /// Makes one recorded call; a divergence if what the robot answered differs from the log.
    fn apply(
        &mut self,
        robot: &mut Robot,
        now: Time,
        recorded: SeamCall,
        trace: &mut dyn FnMut(&TransitionRecord),
    ) -> Option<Divergence> {
        let channel = format!("/{}/seam:{}", self.id, recorded.name());
        let mut rec = Recorder::default();
        let tick = matches!(recorded, SeamCall::Tick(_));
        let tree = if tick { Some(&mut rec as &mut dyn TreeObserver) } else { None };
        let (replayed, reply) = robot.call_observed(now, recorded.clone(), tree);
        let diverged = |recorded: String, replayed: String, node_path: String| Divergence {
            time_s: now.as_secs_f64(),
            channel: channel.clone(),
            recorded,
            replayed,
            node_path,
        };
        match reply {
            SeamReply::Tick(_) => {
                // Problems go to the log's `/R/rosout`; drained here as the recorder does.
                let _ = robot.take_problems();
                self.report.ticks += 1;
                for t in &rec.records {
                    trace(t);
                }
                if let Some(d) = self.compare_transitions(&rec.records, now) {
                    return Some(d);
                }
            }
            // The recorded robot took it, or it would not have been logged: it must take here
            // too (a secured robot's needs the keys, `--keys`).
            SeamReply::Resume(Err(e)) => {
                return Some(diverged(
                    "resumed from its saved state".into(),
                    format!("refused the saved state: {e}"),
                    String::new(),
                ));
            }
            // Done now; the robot applies each when the log says it had it back.
            SeamReply::TakeWork(work) => {
                for w in work {
                    robot.deliver_work(w.run());
                }
            }
            SeamReply::FinishWork(Ok(())) => self.report.skill_jobs += 1,
            SeamReply::FinishWork(Err(e)) => {
                return Some(diverged(recorded.describe_answer(None), e.to_string(), String::new()));
            }
            SeamReply::Done | SeamReply::TeamIn(_) | SeamReply::Resume(Ok(_)) => {}
        }
        if matches!(replayed, SeamCall::TeamOut { .. }) {
            self.report.team_messages += 1;
        }
        if !recorded.same_answers(&replayed) {
            let node_path = if tick { running_leaves(robot) } else { String::new() };
            return Some(diverged(
                recorded.describe_answer(Some(&replayed)),
                replayed.describe_answer(Some(&recorded)),
                node_path,
            ));
        }
        None
    }

    fn compare_transitions(&mut self, replayed: &[TransitionRecord], now: Time) -> Option<Divergence> {
        let id = self.id.clone();
        let bt = format!("/{id}/bt");
        for t in replayed {
            let name = format!("{id}/{}", t.path);
            let msg = format!("{} -> {} (tick {}, node {})", t.from, t.to, t.tick, t.node_id);
            let at = |time_ns: i64| Time::from_nanos(time_ns).as_secs_f64();
            match self.recorded.pop_front() {
                Some(r) if r.time_ns == t.time.nanos && r.name == name && r.msg == msg => {
                    self.report.transitions += 1;
                }
                Some(r) => {
                    return Some(Divergence {
                        time_s: at(r.time_ns.min(t.time.nanos)),
                        channel: bt,
                        recorded: format!("{:.3} s {}: {}", at(r.time_ns), r.name, r.msg),
                        replayed: format!("{:.3} s {name}: {msg}", t.time.as_secs_f64()),
                        node_path: t.path.clone(),
                    });
                }
                None => {
                    return Some(Divergence {
                        time_s: t.time.as_secs_f64(),
                        channel: bt,
                        recorded: "no transition".into(),
                        replayed: format!("{:.3} s {name}: {msg}", t.time.as_secs_f64()),
                        node_path: t.path.clone(),
                    });
                }
            }
        }
        // A transition the log holds for this tick or earlier that the replay did not make.
        if let Some(r) = self.recorded.front().filter(|r| r.time_ns <= now.nanos) {
            let path = r.name.strip_prefix(&format!("{id}/")).unwrap_or(&r.name).to_string();
            return Some(Divergence {
                time_s: Time::from_nanos(r.time_ns).as_secs_f64(),
                channel: bt,
                recorded: format!("{:.3} s {}: {}", Time::from_nanos(r.time_ns).as_secs_f64(), r.name, r.msg),
                replayed: "no transition".into(),
                node_path: path,
            });
        }
        None
    }
}

/// The paths of the leaves running after the last tick, `;`-separated.
fn running_leaves(robot: &Robot) -> String {
    let mut running = Vec::new();
    robot.tree().root().visit(0, &mut |slot, _| {
        if slot.status() == spomp_behaviors::Status::Running && slot.behavior().children().is_empty() {
            running.push(slot.info().path.to_string());
        }
    });
    running.join("; ")
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    #[test]
    fn sets_go_into_the_robots_navigation_overrides() {
        let mut nav = Some(serde_json::json!({ "terrain": { "slope_threshold": 0.3 } }));
        apply_set(&mut nav, "navigation.terrain.inflation_m", "0.9").unwrap();
        apply_set(&mut nav, "navigation.global_planner.learning", "false").unwrap();
        apply_set(&mut nav, "navigation.profile", "simulation").unwrap();
        assert_eq!(
            nav.unwrap(),
            serde_json::json!({
                "terrain": { "slope_threshold": 0.3, "inflation_m": 0.9 },
                "global_planner": { "learning": false },
                "profile": "simulation"
            })
        );
        let mut none = None;
        assert!(apply_set(&mut none, "priority", "3").is_err());
        assert!(apply_set(&mut none, "navigation..x", "3").is_err());
        let mut scalar = Some(serde_json::json!({ "profile": "simulation" }));
        assert!(apply_set(&mut scalar, "navigation.profile.x", "1").is_err());
        // A section set whole merges as every other patch of the workspace does.
        let mut nav = Some(serde_json::json!({ "terrain": { "slope_threshold": 0.3 } }));
        apply_set(&mut nav, "navigation.terrain", r#"{ "inflation_m": 1.2 }"#).unwrap();
        assert_eq!(nav.unwrap(), serde_json::json!({ "terrain": { "slope_threshold": 0.3, "inflation_m": 1.2 } }));
    }

    #[test]
    fn a_log_without_run_setup_is_refused_with_a_hint() {
        let mut buf = std::io::Cursor::new(Vec::new());
        let rec = crate::Recorder::new(&mut buf, crate::RecorderOptions::default()).unwrap();
        rec.finish().unwrap();
        let e = replay(
            &buf.into_inner(),
            &ReplayOptions { robot: "ugv1".into(), ..Default::default() },
            &spomp_robot::registry(),
            &mut |_| {},
        )
        .err()
        .unwrap();
        assert!(e.to_string().contains("--replayable"), "{e}");
    }
}
