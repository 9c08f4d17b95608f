//! `spomp run`: one robot over ROS 2.
//!
//! One thread owns the [`Robot`]. Each pass of its loop takes what arrived (odometry, images,
//! a position, team-state bytes, the e-stop, `/clock`), feeds it to the robot, ticks the robot
//! when its period is due, and publishes what the robot wants done. The heavy skills
//! (localization and terrain analysis of each panorama, the global planner's graph and training)
//! run on worker threads ([`crate::workers`]): the loop hands them the work the robot gives and
//! the results back between ticks, so a graph rebuild never delays a tick. Commands are published at
//! the tick rate and are the safe ones whenever something is wrong: zero velocity (a UAV holds
//! its position) while odometry or panoramas are stale, while the e-stop is engaged, and once at
//! shutdown.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use ros2_client::{Publisher, Subscription};
use serde::Serialize;
use spomp_behaviors::trace::Recorder;
use spomp_core::{FlightCommand, PanoramaFrame, Point2, PoseEstimate, RobotId, RobotKind, Time, Twist2};
use spomp_robot::runtime::WorkKind;
use spomp_robot::{LinkCredit, ModelledWork, Robot, RobotObserver, RobotView, RoundShape, WorkLatency};
use spomp_ros_msgs as ros;
use spomp_ros_msgs::CmdVelType;
use spomp_teamstate::TierSet;

use crate::clock::{TimeBase, ros_nanos, wall_nanos};
use crate::convert;
use crate::dds::{DdsError, DdsNode, latched_qos, rosout_qos, sensor_qos, state_qos};
use crate::frames::{FrameCheck, FrameField};
use crate::lockstep::{self, LockstepIn, LockstepOut, Op, Reply, StepDone};
use crate::pairing::{OdometryHistory, PanoramaPairer};
use crate::settings::RunSettings;
use crate::team::{OperatorDesk, StateSink, TeamChannel};
use crate::topics::{CLOCK_TOPIC, ROSOUT_TOPIC};
use crate::workers::{SkillWorkers, WorkOutcome};

/// What a run produced, for the CLI's recorder (`--record`) and tests: what the robot saw and
/// did (the robot layer's [`RobotObserver`]: its seam calls, which `spomp run --record` logs
/// as `spomp sim --replayable` does, transitions, problems and refused inputs, scans, paths,
/// odometry and panoramas) and what only this adapter knows (below). Every method has an empty
/// default.
pub trait RunObserver: RobotObserver {
    /// A pose input (GNSS, local position) as the robot received it.
    fn on_external_pose(&mut self, _robot: &str, _estimate: &PoseEstimate) {}
    /// The velocity command published (UGV).
    fn on_command(&mut self, _robot: &str, _now: Time, _cmd: Twist2) {}
    /// The setpoint published (UAV).
    fn on_flight(&mut self, _robot: &str, _now: Time, _cmd: Option<&FlightCommand>) {}
    /// The pose estimate.
    fn on_estimate(&mut self, _robot: &str, _estimate: &PoseEstimate) {}
    /// A transform the robot published on `topic` (its tf topic), at robot time `time`.
    fn on_tf(&mut self, _topic: &str, _time: Time, _msg: &ros::TfMessage) {}
    /// An input named a frame other than the configured one (once per topic, field and frame
    /// found): the tf tree it implies would not connect. Also an `on_problem`.
    fn on_frame_mismatch(&mut self, _robot: &str, _message: &str) {}
    /// A lockstep farm's hello was taken, before any call of its run: the heavy skills run in the
    /// background (`true`, under the farm's latency model) or inline.
    fn on_lockstep(&mut self, _background_skills: bool) {}
    /// The robot's team state newly holds an operator command or an acknowledgement of one.
    fn on_operator(&mut self, _robot: &str, _now: Time, _event: &spomp_robot::operator_log::OperatorEvent) {}
}

/// An observer that ignores everything.
pub struct NoRunObserver;
impl RunObserver for NoRunObserver {}
impl RobotObserver for NoRunObserver {}

/// Why the robot stopped itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StopReason {
    /// Nothing: driving.
    None,
    /// No odometry yet, or it is older than the limit.
    OdometryStale,
    /// No panorama yet, or the newest is older than the limit.
    PanoramaStale,
    /// No position yet (a UAV's GNSS fix or local pose), or it is older than the odometry
    /// limit.
    PositionStale,
    /// The e-stop is engaged.
    EStop,
    /// `/clock` stopped advancing (use_sim_time).
    ClockStalled,
    /// A skill failed on its worker thread: the robot cannot go on.
    SkillFailed,
}

/// Figures of a run (also published on `/diagnostics`).
#[derive(Debug, Clone, Default, Serialize)]
pub struct RunReport {
    /// Robot id.
    pub robot: String,
    /// Robot time at the end, seconds.
    pub robot_time_s: f64,
    /// Wall time of the loop, seconds.
    pub wall_s: f64,
    /// Tree ticks.
    pub ticks: u64,
    /// Ticks that started later than one period after they were due.
    pub tick_overruns: u64,
    /// Ticks per wall second, measured.
    pub tick_rate_hz: f64,
    /// Tree tick rate the role asks for.
    pub target_tick_hz: f64,
    /// Longest tick (maintain + tree), milliseconds.
    pub max_tick_ms: f64,
    /// Longest panorama processing (localization, terrain analysis, on its worker thread),
    /// milliseconds.
    pub max_panorama_ms: f64,
    /// Longest global-planner upkeep (graph growth, training, on its worker thread),
    /// milliseconds.
    pub max_planner_ms: f64,
    /// Heavy-skill jobs run on the worker threads.
    pub skill_jobs: u64,
    /// Odometry receipt → next command published, milliseconds: median.
    pub odometry_to_command_p50_ms: f64,
    /// Same, 99th percentile.
    pub odometry_to_command_p99_ms: f64,
    /// Panorama receipt → first command published after it was processed, milliseconds: median.
    pub panorama_to_command_p50_ms: f64,
    /// Same, 99th percentile.
    pub panorama_to_command_p99_ms: f64,
    /// Inputs received, by kind.
    pub received: InputCounts,
    /// Inputs refused (malformed), all kinds.
    pub malformed_inputs: u64,
    /// Inputs dropped (superseded before use — a panorama that arrived while the previous one
    /// was still being processed, say — or no odometry at their stamp).
    pub dropped_inputs: u64,
    /// Commands published.
    pub commands: u64,
    /// Commands published as a safety stop.
    pub safety_stops: u64,
    /// Final status of the tree.
    pub tree_status: String,
    /// Team-state messages refused (unsigned, forged, replayed, malformed), by the teammate the
    /// transport named: one entry per robot of the team at most. Senders outside the team are
    /// counted in `team_rejected_unknown_sender`, never by name.
    pub team_rejected: std::collections::BTreeMap<String, u64>,
    /// Why the last refused message of each teammate was refused (clipped to
    /// [`MAX_WHY_CHARS`] characters).
    pub team_rejected_why: std::collections::BTreeMap<String, String>,
    /// Refused messages of every sender by kind: the team state's reasons
    /// (`spomp_teamstate::SyncError::kind`) and the link's own (`unknown_sender`, `oversized`,
    /// `inbox_full`). A fixed, small set of keys.
    pub team_rejected_by_kind: std::collections::BTreeMap<&'static str, u64>,
    /// Refused messages that named a sender outside the team (by the link or the robot).
    pub team_rejected_unknown_sender: u64,
    /// Refused messages that carried a forged operator command (signed by a key other than the
    /// operator's, or written by a robot; issue 37), also counted by kind above.
    pub team_rejected_operator: u64,
    /// The team link's figures (bytes per link and tier), when one is plugged in.
    pub team_link: Option<serde_json::Value>,
    /// Resume states written.
    pub states_saved: u64,
    /// Messages on the ROS 2 `team/in` topic ignored because the team state goes over the
    /// team link.
    pub team_in_ignored: u64,
    /// Clicked points refused (another frame, or the operator desk said no).
    pub operator_points_refused: u64,
    /// Inputs that named a frame other than the configured one: `topic field` → the frame id
    /// last found (a `/diagnostics` warning while any is here).
    pub frame_mismatches: std::collections::BTreeMap<String, String>,
}

/// The longest reason kept in `team_rejected_why`, characters (a refusal quotes names a sender
/// chose, which may be megabytes long).
pub const MAX_WHY_CHARS: usize = 240;

/// `text` cut to `max` characters, with `…` where it was cut.
fn clip(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        Some((end, _)) => format!("{}…", &text[..end]),
        None => text.to_string(),
    }
}

impl RunReport {
    /// Counts a refused message: by kind always, and by sender only for a teammate
    /// (`member`), so the tables stay as small as the team whatever names a flood invents.
    fn note_rejected(&mut self, from: &RobotId, member: bool, why: &spomp_teamstate::SyncError) {
        *self.team_rejected_by_kind.entry(why.kind()).or_default() += 1;
        if member {
            *self.team_rejected.entry(from.to_string()).or_default() += 1;
            self.team_rejected_why.insert(from.to_string(), clip(&why.to_string(), MAX_WHY_CHARS));
        } else {
            self.team_rejected_unknown_sender += 1;
        }
    }

    /// Adds the refusals a team link made itself (`TeamChannel::refused`).
    fn add_link_refusals(&mut self, refused: &[(&'static str, u64)]) {
        for &(kind, n) in refused {
            if n > 0 {
                *self.team_rejected_by_kind.entry(kind).or_default() += n;
            }
            if kind == "unknown_sender" {
                self.team_rejected_unknown_sender += n;
            }
        }
    }
}

/// Inputs received, by kind.
#[derive(Debug, Clone, Default, Serialize)]
pub struct InputCounts {
    /// Odometry messages.
    pub odometry: u64,
    /// Panoramas (depth + labels paired).
    pub panoramas: u64,
    /// Pose inputs.
    pub poses: u64,
    /// Aerial-map tiles from the camera (UAVs).
    pub camera_tiles: u64,
    /// Team-state messages.
    pub team: u64,
    /// `/clock` messages.
    pub clock: u64,
    /// Points taken from the clicked-point topic (rviz's "Publish Point"), when it is read.
    pub operator_points: u64,
}

/// Why a run could not start.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// DDS.
    #[error(transparent)]
    Dds(#[from] DdsError),
    /// The skill worker threads.
    #[error("cannot start the skill worker threads: {0}")]
    Workers(#[from] std::io::Error),
}

struct Inputs {
    odom: Subscription<ros::Odometry>,
    depth: Subscription<ros::Image>,
    semantic: Subscription<ros::Image>,
    gps: Subscription<ros::NavSatFix>,
    pose_in: Subscription<ros::PoseStamped>,
    tiles: Subscription<ros::GridMap>,
    estop: Subscription<ros::BoolMsg>,
    team_in: Subscription<ros::BytesMsg>,
    clock: Option<Subscription<ros::Clock>>,
}

/// The velocity command's writer, of the type the robot's settings choose.
enum CmdVelWriter {
    Twist(Publisher<ros::Twist>),
    Stamped(Publisher<ros::TwistStamped>),
}

struct Outputs {
    cmd_vel: CmdVelWriter,
    setpoint: Publisher<ros::PoseStamped>,
    setpoint_speed: Publisher<ros::Float64Msg>,
    estimate: Publisher<ros::PoseWithCovarianceStamped>,
    tf: Publisher<ros::TfMessage>,
    path: Publisher<ros::Path>,
    goals: Publisher<ros::MarkerArray>,
    scan: Publisher<ros::LaserScan>,
    rosout: Publisher<ros::Log>,
    diagnostics: Publisher<ros::DiagnosticArray>,
    team_out: Publisher<ros::BytesMsg>,
    status: Publisher<ros::StringMsg>,
}

/// One robot on ROS 2.
pub struct RobotNode {
    robot: Robot,
    workers: SkillWorkers,
    settings: RunSettings,
    peers: Vec<RobotId>,
    /// The team link, when messages go between processes rather than over ROS 2 topics.
    team_channel: Option<Box<dyn TeamChannel>>,
    /// Unused team-state budget per peer, carried from period to period while the peer stays
    /// reachable (the robot layer's rule, [`LinkCredit`]).
    team_credit: LinkCredit,
    /// Where the resume state goes, and how often (seconds).
    state_sink: Option<(StateSink, f64)>,
    /// The operator's tools wired to this robot.
    operator: Option<Operator>,
    // Entities before the node: they are dropped first.
    /// A farm's lockstep calls and this robot's answers (`--lockstep`).
    lockstep: Option<(Subscription<LockstepIn>, Publisher<LockstepOut>)>,
    inputs: Inputs,
    outputs: Outputs,
    node: DdsNode,
}

/// The operator's tools wired to a robot: the desk, and the clicked-point topic when it is read.
struct Operator {
    desk: Box<dyn OperatorDesk>,
    clicked_point: Option<Subscription<ros::PointStamped>>,
}

/// Wall-clock budget of one pass when nothing arrives: the loop sleeps this long at most.
const IDLE_SLEEP: Duration = Duration::from_millis(2);
/// `/clock` not advancing for this long (wall) counts as a stalled simulator.
const CLOCK_STALL: Duration = Duration::from_secs(2);
/// Diagnostics, goal markers and mission status are published this often (robot time), seconds.
const STATUS_PERIOD_S: f64 = 1.0;

impl RobotNode {
    /// Creates the ROS 2 node of `robot` with `settings`; `peers` are the other robots of the
    /// team (team-state messages go to each of them).
    pub fn new(mut robot: Robot, settings: RunSettings, peers: Vec<RobotId>) -> Result<Self, RunError> {
        // In lockstep the farm's hello says (turning background work on builds a prior map's
        // graph at once, which cannot be undone).
        if settings.lockstep.is_none() {
            robot.set_background_skills(true);
        }
        let workers = SkillWorkers::start(robot.id().as_str())?;
        let mut node = DdsNode::new(&settings.dds, settings.topics.namespace(), ros::ROBOT_NODE_NAME)?;
        let t = &settings.topics;
        let inputs = Inputs {
            odom: node.subscription(t.get("odom"), &sensor_qos(20))?,
            depth: node.subscription(t.get("panorama/depth"), &sensor_qos(2))?,
            semantic: node.subscription(t.get("panorama/semantic"), &sensor_qos(2))?,
            gps: node.subscription(t.get("gps"), &sensor_qos(5))?,
            pose_in: node.subscription(t.get("pose_in"), &sensor_qos(5))?,
            // Every tile matters to the map: reliable, with room for a burst.
            tiles: node.subscription(t.get("camera/tiles"), &state_qos(256))?,
            estop: node.subscription(t.get("estop"), &sensor_qos(5))?,
            team_in: node.subscription(t.get("team/in"), &sensor_qos(64))?,
            clock: if settings.use_sim_time { Some(node.subscription(CLOCK_TOPIC, &sensor_qos(1))?) } else { None },
        };
        let outputs = Outputs {
            cmd_vel: match settings.cmd_vel_type {
                CmdVelType::Twist => CmdVelWriter::Twist(node.publisher(t.get("cmd_vel"), &state_qos(1))?),
                CmdVelType::TwistStamped => CmdVelWriter::Stamped(node.publisher(t.get("cmd_vel"), &state_qos(1))?),
            },
            setpoint: node.publisher(t.get("setpoint"), &state_qos(1))?,
            setpoint_speed: node.publisher(t.get("setpoint_speed"), &state_qos(1))?,
            estimate: node.publisher(t.get("pose_estimate"), &state_qos(1))?,
            tf: node.publisher(t.get("tf"), &state_qos(100))?,
            path: node.publisher(t.get("path"), &latched_qos(1))?,
            goals: node.publisher(t.get("goals"), &latched_qos(1))?,
            scan: node.publisher(t.get("reachability"), &state_qos(1))?,
            // The only `/rosout` writer of the process, with rcl's QoS (see `rosout_qos`).
            rosout: node.publisher(ROSOUT_TOPIC, &rosout_qos())?,
            diagnostics: node.publisher(t.get("diagnostics"), &state_qos(10))?,
            team_out: node.publisher(t.get("team/out"), &state_qos(64))?,
            status: node.publisher(&settings.topics.status(), &latched_qos(1))?,
        };
        let lockstep = match settings.lockstep {
            Some(_) => Some((
                node.subscription(&lockstep::in_topic(t), &lockstep::lockstep_qos())?,
                node.publisher(&lockstep::out_topic(t), &lockstep::lockstep_qos())?,
            )),
            None => None,
        };
        check_topic_types(&settings, node.topics()).map_err(DdsError::Create)?;
        Ok(RobotNode {
            robot,
            workers,
            settings,
            peers,
            lockstep,
            inputs,
            outputs,
            team_channel: None,
            team_credit: LinkCredit::default(),
            state_sink: None,
            operator: None,
            node,
        })
    }

    /// Every topic the node publishes or takes, with its message type.
    pub fn topic_types(&self) -> &[(String, &'static str)] {
        self.node.topics()
    }

    /// The robot, read-only.
    pub fn robot(&self) -> RobotView<'_> {
        self.robot.view()
    }

    /// Sends and receives team-state messages over `channel` instead of the ROS 2 topics.
    pub fn set_team_channel(&mut self, channel: Box<dyn TeamChannel>) {
        self.team_channel = Some(channel);
    }

    /// Hands the robot's resume state ([`Robot::resume_state`]) to `sink` every `period_s` of
    /// robot time and once at shutdown.
    pub fn set_state_sink(&mut self, sink: StateSink, period_s: f64) {
        self.state_sink = Some((sink, period_s.max(0.1)));
    }

    /// Wires the operator's tools: `desk` is polled every pass (every lockstep step) before the
    /// robot ticks, and, with `clicked_point` (rviz's `/clicked_point`), each
    /// `geometry_msgs/PointStamped` there in the robot's map frame is handed to it; a point in
    /// another frame is refused (no transform is looked up) and logged on `/rosout`, as is
    /// what the desk answers.
    pub fn set_operator_desk(
        &mut self,
        desk: Box<dyn OperatorDesk>,
        clicked_point: Option<&str>,
    ) -> Result<(), DdsError> {
        // Reliable, as rviz publishes: a click is a command, not a sample.
        let sub = match clicked_point {
            Some(topic) => Some(self.node.subscription(topic, &state_qos(16))?),
            None => None,
        };
        self.operator = Some(Operator { desk, clicked_point: sub });
        Ok(())
    }

    /// Takes the clicked points and polls the desk (see [`RobotNode::set_operator_desk`]).
    fn serve_operator(&mut self, state: &mut LoopState, now: Time) {
        let Some(Operator { desk, clicked_point }) = self.operator.as_mut() else { return };
        let mut answers = Vec::new();
        if let Some(sub) = clicked_point.as_ref() {
            while let Some(msg) = take(sub, &mut state.report.malformed_inputs) {
                state.report.received.operator_points += 1;
                let answer = if msg.header.frame_id != self.settings.frames.map {
                    Err(format!(
                        "a point in frame `{}`; only points in `{}` are taken (no transform is looked up)",
                        msg.header.frame_id, self.settings.frames.map
                    ))
                } else {
                    desk.on_clicked_point(&mut self.robot, now, &msg)
                };
                answers.push(answer);
            }
        }
        desk.poll(&mut self.robot, now);
        for answer in answers {
            match answer {
                Ok(done) => self.log(now, 20, format!("clicked point: {done}")),
                Err(why) => {
                    state.report.operator_points_refused += 1;
                    self.log(now, 30, format!("clicked point refused: {why}"));
                }
            }
        }
    }

    fn save_state(&mut self, state: &mut LoopState) {
        if let Some((sink, _)) = self.state_sink.as_mut() {
            sink(self.robot.resume_state());
            state.report.states_saved += 1;
        }
    }

    /// Runs until `stop` is set (SIGINT/SIGTERM) or, when given, until robot time `until_s`;
    /// publishes a safety stop before returning.
    pub fn run(&mut self, stop: &AtomicBool, until_s: Option<f64>, observer: &mut dyn RunObserver) -> RunReport {
        if self.lockstep.is_some() {
            return self.run_lockstep(stop, until_s, observer);
        }
        let mut state = LoopState::new(&self.settings, self.robot.tick_hz());
        state.flies = self.robot.kind() == RobotKind::Uav;
        state.sensorless = self.robot.kind() == RobotKind::Basestation;
        let started = Instant::now();
        let id = self.robot.id().clone();
        let mut transitions = Recorder::default();
        self.robot.record_seam(observer.wants_seam());
        while !stop.load(Ordering::SeqCst) {
            let got = self.take_inputs(&mut state, observer);
            let Some(now) = state.now() else {
                // use_sim_time and no /clock yet: nothing to time anything by.
                std::thread::sleep(IDLE_SLEEP);
                continue;
            };
            if until_s.is_some_and(|u| now.as_secs_f64() >= u) {
                break;
            }
            self.serve_operator(&mut state, now);
            if let Some(frame) = state.pending_frame(&self.settings) {
                let frame = Arc::new(frame);
                observer.on_panorama(&id, &frame);
                self.robot.on_panorama(now, frame);
                self.robot.deliver_recorded(observer);
                state.frame_rx = state.panorama_rx;
            }
            self.exchange_work(&mut state, now, observer);
            let stop_reason = state.stop_reason(now, &self.settings);
            if stop_reason == StopReason::EStop && !state.halted {
                // Unobserved, like every halt a replay makes: the e-stop is logged on /rosout.
                self.robot.halt(now);
                self.robot.deliver_recorded(observer);
                state.halted = true;
            }
            if now >= state.next_tick {
                let tick_start = Instant::now();
                let overrun = now.nanos - state.next_tick.nanos > state.period.nanos;
                state.report.tick_overruns += u64::from(overrun && state.report.ticks > 0);
                state.next_tick = if overrun { now } else { state.next_tick };
                state.next_tick = Time::from_nanos(state.next_tick.nanos + state.period.nanos);
                if stop_reason != StopReason::EStop {
                    state.halted = false;
                    state.status = self.robot.tick(now, Some(&mut transitions));
                    state.report.ticks += 1;
                    // Transitions before the tick's seam record, as the simulator logs them: a
                    // replay compares them when it reaches the tick.
                    self.publish_transitions(&mut transitions, observer);
                    self.robot.deliver_recorded(observer);
                }
                state.report.max_tick_ms = state.report.max_tick_ms.max(ms(tick_start.elapsed()));
                self.publish_command(&mut state, now, stop_reason, observer);
                self.publish_transitions(&mut transitions, observer);
                for p in self.robot.take_problems() {
                    observer.on_problem(&id, now, &p);
                    state.last_problem = Some(p);
                }
                self.publish_state(&mut state, now, observer);
            }
            if now >= state.next_team {
                state.next_team = Time::from_nanos(now.nanos + Time::from_secs_f64(self.settings.team_period_s).nanos);
                self.send_team(now);
                self.robot.deliver_recorded(observer);
            }
            if let Some((_, period)) = self.state_sink.as_ref()
                && now >= state.next_save
            {
                state.next_save = Time::from_nanos(now.nanos + Time::from_secs_f64(*period).nanos);
                self.save_state(&mut state);
            }
            if now >= state.next_status {
                state.next_status = Time::from_nanos(now.nanos + Time::from_secs_f64(STATUS_PERIOD_S).nanos);
                self.publish_status(&mut state, now, stop_reason, started.elapsed());
            }
            if !got {
                std::thread::sleep(IDLE_SLEEP);
            }
        }
        self.shut_down(state, observer, started)
    }

    /// Shutdown, paced or in lockstep: one last safe command whatever the state, the state file
    /// saved, and the run's report.
    fn shut_down(&mut self, mut state: LoopState, observer: &mut dyn RunObserver, started: Instant) -> RunReport {
        if let Some(now) = state.now() {
            self.robot.halt(now);
            self.robot.deliver_recorded(observer);
            self.publish_command(&mut state, now, StopReason::EStop, observer);
            state.report.robot_time_s = now.as_secs_f64();
        }
        self.save_state(&mut state);
        self.with_link_figures(state.snapshot(&self.robot, started.elapsed()))
    }

    /// `report` with the team link's figures and the refusals the link made itself (senders
    /// that are no members, oversized messages), which never reach the robot.
    fn with_link_figures(&self, mut report: RunReport) -> RunReport {
        if let Some(channel) = self.team_channel.as_ref() {
            report.team_link = Some(channel.stats());
            report.add_link_refusals(&channel.refused());
        }
        report
    }

    /// `run` in a farm's lockstep ([`crate::lockstep`]): the farm's calls, in the order it sends
    /// them, are made on the robot as the simulator makes them on its own robots, and each step
    /// is answered. Ends when the farm ends the run, when `stop` is set, at robot time `until_s`,
    /// or when the farm, once it said hello, sends nothing for the settings' timeout.
    fn run_lockstep(&mut self, stop: &AtomicBool, until_s: Option<f64>, observer: &mut dyn RunObserver) -> RunReport {
        let mut state = LoopState::new(&self.settings, self.robot.tick_hz());
        state.flies = self.robot.kind() == RobotKind::Uav;
        state.sensorless = self.robot.kind() == RobotKind::Basestation;
        let started = Instant::now();
        let timeout = Duration::from_secs_f64(self.settings.lockstep.as_ref().map_or(60.0, |l| l.timeout_s));
        let mut step = LockstepStep::new(self.robot.tick_hz());
        let mut last_call = Instant::now();
        self.robot.record_seam(observer.wants_seam());
        while !stop.load(Ordering::SeqCst) {
            let call = match self.lockstep.as_ref().map(|(calls, _)| calls.take()) {
                Some(Ok(Some((call, _)))) => call,
                Some(Ok(None)) | Some(Err(_)) | None => {
                    if step.hello.is_some() && last_call.elapsed() > timeout {
                        let what =
                            format!("lockstep: the farm sent nothing for {:.0} s; stopping", timeout.as_secs_f64());
                        observer.on_problem(self.robot.id(), state.now().unwrap_or(Time::ZERO), &what);
                        eprintln!("{}: {what}", self.robot.id());
                        break;
                    }
                    std::thread::sleep(LOCKSTEP_POLL);
                    continue;
                }
            };
            last_call = Instant::now();
            if let Op::Hello(hello) = &call.op {
                let reply = self.take_hello(hello, &mut step, observer);
                self.answer(0, reply);
                continue;
            }
            if step.hello.is_none() {
                // Calls of an earlier run of the farm, or before our hello was answered.
                continue;
            }
            if call.seq != step.next_seq {
                let what = format!("lockstep: call {} arrived where {} was due; stopping", call.seq, step.next_seq);
                observer.on_problem(self.robot.id(), state.now().unwrap_or(Time::ZERO), &what);
                eprintln!("{}: {what}", self.robot.id());
                break;
            }
            step.next_seq += 1;
            if matches!(call.op, Op::End) {
                break;
            }
            if let Op::Begin(now) = call.op
                && until_s.is_some_and(|u| now.as_secs_f64() >= u)
            {
                break;
            }
            let reply = self.lockstep_call(call.op, &mut state, &mut step, observer, started);
            self.robot.deliver_recorded(observer);
            if let Some(reply) = reply {
                self.answer(call.seq, reply);
            }
        }
        self.shut_down(state, observer, started)
    }

    fn answer(&self, seq: u64, reply: Reply) {
        if let Some((_, answers)) = self.lockstep.as_ref() {
            let _ = answers.publish(LockstepOut { robot: self.robot.id().to_string(), seq, reply });
        }
    }

    /// The farm's hello: the same seed, or the runs would differ from the first random draw.
    fn take_hello(
        &mut self,
        hello: &lockstep::Hello,
        step: &mut LockstepStep,
        observer: &mut dyn RunObserver,
    ) -> Reply {
        let seed = self.settings.lockstep.as_ref().map_or(0, |l| l.seed);
        if hello.protocol != lockstep::PROTOCOL {
            return Reply::Refused(format!(
                "{}: lockstep protocol {} here, {} at the farm (run the same spomp version)",
                self.robot.id(),
                lockstep::PROTOCOL,
                hello.protocol
            ));
        }
        if hello.seed != seed {
            return Reply::Refused(format!(
                "{}: the farm runs seed {} and this robot was set up with seed {seed}: start it with --seed {}",
                self.robot.id(),
                hello.seed,
                hello.seed
            ));
        }
        if step.hello.is_none() {
            // As the simulator sets its robots up: background work only under a latency model.
            self.robot.set_background_skills(hello.skill_latency_s.is_some());
            observer.on_lockstep(hello.skill_latency_s.is_some());
            step.hello = Some(hello.clone());
        }
        // Every hello starts the calls again: the farm says hello once before the first step,
        // and again to a robot it dropped, which then rejoins.
        step.next_seq = 1;
        Reply::Ready
    }

    /// One call of a step; the answer when the call wants one.
    fn lockstep_call(
        &mut self,
        op: Op,
        state: &mut LoopState,
        step: &mut LockstepStep,
        observer: &mut dyn RunObserver,
        started: Instant,
    ) -> Option<Reply> {
        let id = self.robot.id().clone();
        let now = state.sim_now.unwrap_or(Time::ZERO);
        match op {
            Op::Hello(_) | Op::End => {}
            Op::Begin(t) => {
                state.sim_now = Some(t);
                state.clock_rx = Some(Instant::now());
                state.report.received.clock += 1;
                step.estimate_after_panorama = None;
            }
            Op::Odometry(odom) => {
                state.report.received.odometry += 1;
                state.odom_rx = Some((now, Instant::now()));
                state.history.push(odom);
                observer.on_odometry(&id, &odom);
                self.robot.on_odometry(now, odom);
            }
            Op::ExternalPose(est) => self.external_pose(state, est, observer),
            Op::Panorama(frame) => {
                state.report.received.panoramas += 1;
                state.panorama_stamp = Some(frame.stamp);
                let frame = Arc::new(frame);
                observer.on_panorama(&id, &frame);
                self.robot.on_panorama(now, frame);
                step.estimate_after_panorama = self.robot.pose();
                self.publish_perception(state, observer);
            }
            Op::CameraTiles(tiles) => {
                state.report.received.camera_tiles += tiles.len() as u64;
                self.robot.on_camera_tiles(now, tiles);
            }
            Op::ExchangeWork => self.exchange_work_at_modelled_time(state, step, now, observer),
            Op::TeamOut { to, tiers, budget_bytes } => {
                if self.team_channel.is_some() {
                    // The team state goes over the team link, not the farm's radio.
                    return Some(Reply::TeamOut(None));
                }
                let tiers = TierSet::from_bits(tiers);
                let budget_bytes = usize::try_from(budget_bytes).unwrap_or(usize::MAX);
                return Some(Reply::TeamOut(self.robot.team_message_for(now, &to, tiers, budget_bytes)));
            }
            Op::TeamIn { from, bytes } => {
                if self.team_channel.is_some() {
                    state.report.team_in_ignored += 1;
                } else {
                    state.report.received.team += 1;
                    if let Err(e) = self.robot.on_team_message(now, &from, bytes) {
                        state.report.note_rejected(&from, self.peers.contains(&from), &e);
                    }
                }
            }
            Op::Halt => self.robot.halt(now),
            Op::Tick => return Some(Reply::Done(Box::new(self.lockstep_tick(state, step, now, observer, started)))),
        }
        None
    }

    /// Background work under the simulator's latency model: each result is handed back at the
    /// first step its modelled time has passed (waiting for its thread if it is not done yet),
    /// then the work due now goes to the threads.
    fn exchange_work_at_modelled_time(
        &mut self,
        state: &mut LoopState,
        step: &mut LockstepStep,
        now: Time,
        observer: &mut dyn RunObserver,
    ) {
        let Some((perception_s, planner_s)) = step.hello.as_ref().and_then(|h| h.skill_latency_s) else { return };
        let latency = WorkLatency { perception_s, planner_s };
        let due = match step.work_out.as_mut() {
            Some(w) => w.due(now),
            None => Vec::new(),
        };
        for work_id in due {
            let Some((work, took)) = self.wait_for_work(state, step, work_id, now, observer) else { continue };
            let kind = work.kind();
            self.robot.finish_work(now, work);
            state.report.skill_jobs += 1;
            match kind {
                WorkKind::Perception => {
                    state.report.max_panorama_ms = state.report.max_panorama_ms.max(ms(took));
                    self.publish_perception(state, observer);
                }
                WorkKind::Planner => state.report.max_planner_ms = state.report.max_planner_ms.max(ms(took)),
            }
        }
        let workers = &mut self.workers;
        step.work_out.get_or_insert_with(|| ModelledWork::new(latency)).take(&mut self.robot, now, |w| {
            let id = w.id();
            workers.submit(w);
            id
        });
    }

    /// Work number `work_id` from the threads, waiting for it; `None` if a skill failed.
    fn wait_for_work(
        &mut self,
        state: &mut LoopState,
        step: &mut LockstepStep,
        work_id: u64,
        now: Time,
        observer: &mut dyn RunObserver,
    ) -> Option<(spomp_robot::runtime::FinishedWork, Duration)> {
        loop {
            if let Some(done) = step.finished.remove(&work_id) {
                return Some(done);
            }
            if state.skill_failed {
                return None;
            }
            match self.workers.wait_finished(Duration::from_secs(1)) {
                Some(WorkOutcome::Done { work, took }) => {
                    step.finished.insert(work.id(), (work, took));
                }
                Some(WorkOutcome::Panicked { kind, message }) => {
                    let what = format!("{} failed on its worker thread: {message}; the robot stops", kind.name());
                    observer.on_problem(self.robot.id(), now, &what);
                    self.log(now, 50, what.clone());
                    state.last_problem = Some(what);
                    state.skill_failed = true;
                }
                None => {}
            }
        }
    }

    /// Upkeep and tick when due (as the simulator ticks its robots), the outputs published, and
    /// the step's answer.
    fn lockstep_tick(
        &mut self,
        state: &mut LoopState,
        step: &mut LockstepStep,
        now: Time,
        observer: &mut dyn RunObserver,
        started: Instant,
    ) -> StepDone {
        let id = self.robot.id().clone();
        if let Some(channel) = self.team_channel.as_mut() {
            for (from, bytes) in channel.receive() {
                state.report.received.team += 1;
                if let Err(e) = self.robot.on_team_message(now, &from, bytes) {
                    state.report.note_rejected(&from, self.peers.contains(&from), &e);
                }
            }
        }
        self.serve_operator(state, now);
        while let Some(msg) = take(&self.inputs.estop, &mut state.report.malformed_inputs) {
            if msg.data != state.estop {
                let what = if msg.data { "e-stop engaged: tree halted" } else { "e-stop released" };
                observer.on_problem(&id, now, what);
                self.log(now, if msg.data { 30 } else { 20 }, what.into());
            }
            state.estop = msg.data;
        }
        let mut transitions = Recorder::default();
        let mut transitioned = Vec::new();
        let mut problems = Vec::new();
        let mut ticked = false;
        if state.estop || state.skill_failed {
            if !state.halted {
                self.robot.halt(now);
                state.halted = true;
            }
        } else if now >= step.next_tick {
            let tick_start = Instant::now();
            step.next_tick = Time::from_nanos(now.nanos + step.tick_period_ns - 1);
            state.halted = false;
            state.status = self.robot.tick(now, Some(&mut transitions));
            state.report.ticks += 1;
            ticked = true;
            transitioned = transitions.records.iter().map(|r| r.node_id).collect();
            self.publish_transitions(&mut transitions, observer);
            // After the transitions, as the simulator logs them.
            self.robot.deliver_recorded(observer);
            state.report.max_tick_ms = state.report.max_tick_ms.max(ms(tick_start.elapsed()));
            problems = self.robot.take_problems();
            for p in &problems {
                observer.on_problem(&id, now, p);
                state.last_problem = Some(p.clone());
            }
        }
        let reason = if state.estop {
            StopReason::EStop
        } else if state.skill_failed {
            StopReason::SkillFailed
        } else {
            StopReason::None
        };
        if ticked || reason != StopReason::None {
            self.publish_command(state, now, reason, observer);
            self.publish_state(state, now, observer);
        }
        if self.team_channel.is_some() && now >= state.next_team {
            state.next_team = Time::from_nanos(now.nanos + Time::from_secs_f64(self.settings.team_period_s).nanos);
            self.send_team(now);
        }
        if let Some((_, period)) = self.state_sink.as_ref()
            && now >= state.next_save
        {
            state.next_save = Time::from_nanos(now.nanos + Time::from_secs_f64(*period).nanos);
            self.save_state(state);
        }
        if now >= state.next_status {
            state.next_status = Time::from_nanos(now.nanos + Time::from_secs_f64(STATUS_PERIOD_S).nanos);
            self.publish_status(state, now, reason, started.elapsed());
        }
        let stopped = reason != StopReason::None;
        StepDone {
            now,
            ticked: ticked || stopped,
            command: if stopped { Some(Twist2::ZERO) } else { self.robot.command() },
            flight: if stopped { None } else { self.robot.flight() },
            estimate_after_panorama: step.estimate_after_panorama.take(),
            estimate: self.robot.pose(),
            tree: format!("{:?}", self.robot.tree().status()).to_lowercase(),
            transitioned,
            problems,
            goals: self.robot.team().goals().to_vec(),
        }
    }

    /// Hands finished skill work back to the robot (publishing a new scan), then the work the
    /// robot has due to the worker threads; both are seam calls a replay repeats.
    fn exchange_work(&mut self, state: &mut LoopState, now: Time, observer: &mut dyn RunObserver) {
        while let Some(outcome) = self.workers.try_finished() {
            match outcome {
                WorkOutcome::Done { work, took } => {
                    let (id, kind) = (work.id(), work.kind());
                    self.robot.finish_work(now, work);
                    state.report.skill_jobs += 1;
                    match kind {
                        WorkKind::Perception => {
                            state.report.max_panorama_ms = state.report.max_panorama_ms.max(ms(took));
                            state.panorama_processed = state.work_rx.remove(&id).or(Some(Instant::now()));
                            self.publish_perception(state, observer);
                        }
                        WorkKind::Planner => state.report.max_planner_ms = state.report.max_planner_ms.max(ms(took)),
                    }
                }
                WorkOutcome::Panicked { kind, message } => {
                    let what = format!("{} failed on its worker thread: {message}; the robot stops", kind.name());
                    observer.on_problem(self.robot.id(), now, &what);
                    self.log(now, 50, what.clone());
                    state.last_problem = Some(what);
                    state.skill_failed = true;
                }
            }
        }
        for w in self.robot.take_work(now) {
            if w.kind() == WorkKind::Perception {
                state.work_rx.insert(w.id(), state.frame_rx.take().unwrap_or_else(Instant::now));
            }
            self.workers.submit(w);
        }
    }

    /// Takes every pending input; true if anything arrived.
    fn take_inputs(&mut self, state: &mut LoopState, observer: &mut dyn RunObserver) -> bool {
        let id = self.robot.id().clone();
        let mut got = false;
        if let Some(clock) = &self.inputs.clock {
            while let Ok(Some((msg, _))) = clock.take() {
                got = true;
                state.report.received.clock += 1;
                let t = Time::from_nanos(ros_nanos(msg.clock));
                if state.sim_now.is_none_or(|n| t > n) {
                    state.sim_now = Some(t);
                    state.clock_rx = Some(Instant::now());
                }
            }
        }
        let base = state.base;
        while let Some(msg) = take(&self.inputs.odom, &mut state.report.malformed_inputs) {
            got = true;
            let topic = self.settings.topics.get("odom");
            self.check_frame(state, observer, topic, "header.frame_id", &msg.header.frame_id, FrameField::Odom);
            self.check_frame(state, observer, topic, "child_frame_id", &msg.child_frame_id, FrameField::BaseLink);
            match convert::odometry_from_ros(&msg, &base) {
                Ok(odom) => {
                    state.report.received.odometry += 1;
                    state.odom_rx = Some((state.now().unwrap_or(odom.stamp), Instant::now()));
                    state.history.push(odom);
                    observer.on_odometry(&id, &odom);
                    self.robot.on_odometry(state.now().unwrap_or(odom.stamp), odom);
                }
                Err(e) => state.refuse(&id, observer, &e.to_string()),
            }
        }
        while let Some(msg) = take(&self.inputs.depth, &mut state.report.malformed_inputs) {
            got = true;
            let topic = self.settings.topics.get("panorama/depth");
            self.check_frame(state, observer, topic, "header.frame_id", &msg.header.frame_id, FrameField::Sensor);
            match convert::depth_from_ros(&msg, self.settings.v_fov_rad, self.settings.depth_scale_m) {
                Ok(d) => {
                    if let Some(pair) = state.pairer.push_depth(base.to_robot(msg.header.stamp), d) {
                        state.set_pair(pair);
                    }
                }
                Err(e) => state.refuse(&id, observer, &e.to_string()),
            }
        }
        while let Some(msg) = take(&self.inputs.semantic, &mut state.report.malformed_inputs) {
            got = true;
            let topic = self.settings.topics.get("panorama/semantic");
            self.check_frame(state, observer, topic, "header.frame_id", &msg.header.frame_id, FrameField::Sensor);
            let classes = self.robot.classes().classes.len();
            match convert::semantic_from_ros(&msg, self.settings.v_fov_rad, classes) {
                Ok(s) => {
                    if let Some(pair) = state.pairer.push_semantic(base.to_robot(msg.header.stamp), s) {
                        state.set_pair(pair);
                    }
                }
                Err(e) => state.refuse(&id, observer, &e.to_string()),
            }
        }
        while let Some(msg) = take(&self.inputs.gps, &mut state.report.malformed_inputs) {
            got = true;
            let Some(origin) = self.settings.gps_origin else {
                state.refuse(&id, observer, "gps: a NavSatFix arrived but the mission gives no ros2.gps_origin");
                continue;
            };
            match convert::navsat_to_estimate(&msg, origin, &base) {
                Ok(est) => self.external_pose(state, est, observer),
                Err(e) => state.refuse(&id, observer, &e.to_string()),
            }
        }
        while let Some(msg) = take(&self.inputs.pose_in, &mut state.report.malformed_inputs) {
            got = true;
            let topic = self.settings.topics.get("pose_in");
            self.check_frame(state, observer, topic, "header.frame_id", &msg.header.frame_id, FrameField::Map);
            match convert::pose_from_ros(&msg, &base) {
                Ok(est) => self.external_pose(state, est, observer),
                Err(e) => state.refuse(&id, observer, &e.to_string()),
            }
        }
        let mut tiles = Vec::new();
        while let Some(msg) = take(&self.inputs.tiles, &mut state.report.malformed_inputs) {
            got = true;
            let Some(grid) = self.robot.aerial_map().map(|m| m.map().spec) else {
                state.refuse(&id, observer, "camera/tiles: a tile arrived but this robot keeps no aerial map");
                continue;
            };
            match msg.to_tile(&grid) {
                Ok(tile) => tiles.push(tile),
                Err(e) => state.refuse(&id, observer, &format!("camera/tiles: {}", e.0)),
            }
        }
        if !tiles.is_empty() {
            state.report.received.camera_tiles += tiles.len() as u64;
            let now = state.now().unwrap_or(Time::ZERO);
            self.robot.on_camera_tiles(now, tiles);
        }
        while let Some(msg) = take(&self.inputs.estop, &mut state.report.malformed_inputs) {
            got = true;
            if msg.data != state.estop {
                let now = state.now().unwrap_or(Time::ZERO);
                let what = if msg.data { "e-stop engaged: tree halted" } else { "e-stop released" };
                observer.on_problem(&id, now, what);
                self.log(now, if msg.data { 30 } else { 20 }, what.into());
            }
            state.estop = msg.data;
        }
        while let Some(msg) = take(&self.inputs.team_in, &mut state.report.malformed_inputs) {
            got = true;
            if self.team_channel.is_some() {
                // With a team link, the team state comes only over it: `team/in` is a
                // simulator farm's radio (whose simulated robots are not the team's processes)
                // or anyone on the DDS domain.
                state.report.team_in_ignored += 1;
                continue;
            }
            let Some(from) = msg.layout.dim.first().map(|d| d.label.clone()).filter(|f| !f.is_empty()) else {
                state.refuse(&id, observer, "team/in: a message without its sender (layout.dim[0].label)");
                continue;
            };
            state.report.received.team += 1;
            let now = state.now().unwrap_or(Time::ZERO);
            let from = RobotId::new(&from);
            if let Err(e) = self.robot.on_team_message(now, &from, msg.data) {
                state.report.note_rejected(&from, self.peers.contains(&from), &e);
            }
        }
        if let Some(channel) = self.team_channel.as_mut() {
            for (from, bytes) in channel.receive() {
                got = true;
                state.report.received.team += 1;
                let now = state.now().unwrap_or(Time::ZERO);
                if let Err(e) = self.robot.on_team_message(now, &from, bytes) {
                    state.report.note_rejected(&from, self.peers.contains(&from), &e);
                }
            }
        }
        self.robot.deliver_recorded(observer);
        got
    }

    /// Checks a frame id an input names (see [`FrameCheck`]): a mismatch is a warning on
    /// `/rosout`, on `/diagnostics` (from then on) and to the observer, once per value.
    fn check_frame(
        &self,
        state: &mut LoopState,
        observer: &mut dyn RunObserver,
        topic: &str,
        field: &'static str,
        found: &str,
        expected: FrameField,
    ) {
        let Some(why) = state.frame_check.check(topic, field, found, expected) else { return };
        let id = self.robot.id().as_str();
        let now = state.now().unwrap_or(Time::ZERO);
        state.report.frame_mismatches.insert(format!("{topic} {field}"), found.to_string());
        observer.on_frame_mismatch(id, &why);
        observer.on_problem(self.robot.id(), now, &why);
        self.log(now, 30, why.clone());
        state.last_problem = Some(why);
    }

    fn external_pose(&mut self, state: &mut LoopState, est: PoseEstimate, observer: &mut dyn RunObserver) {
        state.report.received.poses += 1;
        state.position_rx = state.now();
        observer.on_external_pose(self.robot.id().as_str(), &est);
        self.robot.on_external_pose(state.now().unwrap_or(est.stamp), est);
    }

    fn publish_command(
        &mut self,
        state: &mut LoopState,
        now: Time,
        reason: StopReason,
        observer: &mut dyn RunObserver,
    ) {
        let id = self.robot.id().clone();
        let safe = reason != StopReason::None;
        state.report.commands += 1;
        state.report.safety_stops += u64::from(safe);
        match self.robot.kind() {
            RobotKind::Uav => {
                let cmd = if safe { None } else { self.robot.flight() };
                let here = self.robot.pose().map(|p| p.pose);
                let msg = match (&cmd, here) {
                    (Some(c), _) => Some(convert::setpoint_to_ros(
                        c,
                        here.map(|p| p.position()),
                        &self.settings.frames.map,
                        now,
                        &state.base,
                    )),
                    // Hover: hold where it is (a setpoint stream must not stop in offboard mode).
                    (None, Some(p)) => {
                        let alt = state.last_altitude_m.unwrap_or(0.0);
                        Some(convert::pose_to_ros(p, alt, &self.settings.frames.map, now, &state.base))
                    }
                    (None, None) => None,
                };
                if let Some(c) = &cmd {
                    state.last_altitude_m = Some(c.altitude_m);
                    // Before the setpoint, so a reader that takes both in one pass flies it at
                    // the mission's speed (a position setpoint carries none).
                    if c.speed_mps.is_finite() {
                        let _ = self.outputs.setpoint_speed.publish(ros::Float64Msg { data: c.speed_mps });
                    }
                }
                if let Some(m) = msg {
                    let _ = self.outputs.setpoint.publish(m);
                }
                observer.on_flight(id.as_str(), now, cmd.as_ref());
            }
            _ => {
                let cmd = if safe { Twist2::ZERO } else { self.robot.command().unwrap_or(Twist2::ZERO) };
                match &self.outputs.cmd_vel {
                    CmdVelWriter::Twist(w) => {
                        let _ = w.publish(convert::twist_to_ros(cmd));
                    }
                    CmdVelWriter::Stamped(w) => {
                        let _ = w.publish(convert::twist_stamped_to_ros(cmd, &self.settings.frames, now, &state.base));
                    }
                }
                observer.on_command(id.as_str(), now, cmd);
            }
        }
        let published = Instant::now();
        if let Some((_, rx)) = state.odom_rx {
            state.odom_latency.push(ms(published.duration_since(rx)));
        }
        if let Some(rx) = state.panorama_processed.take() {
            state.panorama_latency.push(ms(published.duration_since(rx)));
        }
    }

    fn publish_transitions(&mut self, transitions: &mut Recorder, observer: &mut dyn RunObserver) {
        if transitions.records.is_empty() {
            return;
        }
        let id = self.robot.id().clone();
        observer.on_transitions(&id, &transitions.records);
        for r in &transitions.records {
            let msg = ros::Log {
                stamp: r.time.into(),
                level: 20,
                name: self.logger_name(),
                msg: format!("{}: {} -> {} (tick {}, node {})", r.path, r.from, r.to, r.tick, r.node_id),
                ..Default::default()
            };
            let _ = self.outputs.rosout.publish(msg);
        }
        transitions.records.clear();
    }

    /// The node's logger name as rcl forms it: namespace and node name joined by `.`
    /// (`ugv1.spomp`).
    fn logger_name(&self) -> String {
        ros::rcl_logger_name(self.settings.topics.namespace(), ros::ROBOT_NODE_NAME)
    }

    fn log(&self, now: Time, level: u8, msg: String) {
        let _ = self.outputs.rosout.publish(ros::Log {
            stamp: now.into(),
            level,
            name: self.logger_name(),
            msg,
            ..Default::default()
        });
    }

    /// After a panorama: the scan.
    fn publish_perception(&mut self, state: &mut LoopState, observer: &mut dyn RunObserver) {
        if let Some(scan) = self.robot.latest_scan()
            && state.last_scan != Some(scan.stamp)
        {
            state.last_scan = Some(scan.stamp);
            observer.on_scan(scan);
            let _ = self.outputs.scan.publish(convert::scan_to_ros(scan, &self.settings.frames, &state.base));
        }
    }

    /// After a tick: estimate and transform, path.
    fn publish_state(&mut self, state: &mut LoopState, now: Time, observer: &mut dyn RunObserver) {
        let id = self.robot.id().clone();
        if let Some(est) = self.robot.pose()
            && state.last_estimate != Some(est.stamp)
        {
            state.last_estimate = Some(est.stamp);
            observer.on_estimate(id.as_str(), &est);
            let frames = &self.settings.frames;
            let _ = self.outputs.estimate.publish(convert::estimate_to_ros(&est, &frames.map, &state.base));
            if let Some(odom) = state.history.pose_at(est.stamp) {
                let tf = convert::map_to_odom(frames, est.pose, odom, est.stamp, &state.base);
                observer.on_tf(self.settings.topics.get("tf"), est.stamp, &tf);
                let _ = self.outputs.tf.publish(tf);
            }
        }
        for event in state.operator_log.poll(self.robot.team()) {
            observer.on_operator(id.as_str(), now, &event);
        }
        let path = self.robot.planned_path().unwrap_or(&[]);
        if path.len() != state.last_path_len || path.first() != state.last_path_start.as_ref() {
            state.last_path_len = path.len();
            state.last_path_start = path.first().copied();
            observer.on_path(&id, now, path);
            let _ = self.outputs.path.publish(convert::path_to_ros(path, &self.settings.frames.map, now, &state.base));
        }
    }

    fn send_team(&mut self, now: Time) {
        let budget = self.settings.team_budget_bytes as u64;
        if let Some(channel) = self.team_channel.as_mut() {
            // One message per tier, highest first, within the link's credit; only to peers the
            // link reaches now.
            let reachable = channel.reachable();
            self.team_credit.begin_round(self.peers.iter().filter(|p| reachable.contains(*p)).map(|p| (p, budget)));
            for peer in self.peers.iter().filter(|p| reachable.contains(*p)) {
                for (tiers, bytes) in
                    self.robot.team_round(now, peer, TierSet::ALL, RoundShape::PerTier, &mut self.team_credit)
                {
                    if let Some(tier) = spomp_robot::team_round::single_tier(tiers) {
                        channel.send(peer, tier, bytes);
                    }
                }
            }
            return;
        }
        // Over ROS 2 topics the farm's radio decides what arrives; this side cannot tell when a
        // link drops, so the credit is kept for every peer (within the cap).
        self.team_credit.begin_round(self.peers.iter().map(|p| (p, budget)));
        for peer in &self.peers {
            for (_, bytes) in
                self.robot.team_round(now, peer, TierSet::ALL, RoundShape::OneMessage, &mut self.team_credit)
            {
                let _ = self.outputs.team_out.publish(ros::BytesMsg::labelled(peer.as_str(), bytes));
            }
        }
    }

    fn publish_status(&mut self, state: &mut LoopState, now: Time, reason: StopReason, wall: Duration) {
        let id = self.robot.id().clone();
        let goals = self.robot.team().goals();
        let _ = self.outputs.goals.publish(convert::goals_to_ros(goals, &self.settings.frames.map, now, &state.base));
        let status = MissionStatus {
            robot: id.as_str(),
            time_s: now.as_secs_f64(),
            tree: state.status.to_string(),
            stop: reason,
            goals: goals.to_vec(),
        };
        if let Ok(data) = serde_json::to_string(&status) {
            let _ = self.outputs.status.publish(ros::StringMsg { data });
        }
        let report = self.with_link_figures(state.snapshot(&self.robot, wall));
        let level = match reason {
            StopReason::None if state.last_problem.is_none() && report.frame_mismatches.is_empty() => 0,
            StopReason::None | StopReason::EStop => 1,
            _ => 2,
        };
        let message = match reason {
            StopReason::None => state.last_problem.take().unwrap_or_else(|| match report.frame_mismatches.len() {
                0 => "running".into(),
                n => format!("running; {n} input frame id(s) differ from the configured frames (see frame_mismatches)"),
            }),
            other => format!("stopped: {}", serde_json::to_string(&other).unwrap_or_default().trim_matches('"')),
        };
        let mut values = vec![kv("tree", &report.tree_status)];
        if let Ok(serde_json::Value::Object(fields)) = serde_json::to_value(&report) {
            for (k, v) in fields {
                if !matches!(k.as_str(), "robot" | "tree_status") {
                    values.push(kv(&k, &v.to_string()));
                }
            }
        }
        let msg = ros::DiagnosticArray {
            header: ros::Header { stamp: state.base.to_ros(now), frame_id: String::new() },
            status: vec![ros::DiagnosticStatus {
                level,
                name: format!("spomp/{id}"),
                message,
                hardware_id: id.to_string(),
                values,
            }],
        };
        let _ = self.outputs.diagnostics.publish(msg);
    }
}

/// Checks every topic the node created against the one topic table
/// ([`spomp_ros_msgs::ROBOT_TOPICS`], which the recorder names and types its channels from):
/// one type per topic name on DDS and in logs. `cmd_vel` is of the type the settings choose.
pub fn check_topic_types(settings: &RunSettings, created: &[(String, &'static str)]) -> Result<(), String> {
    for t in spomp_ros_msgs::ROBOT_TOPICS {
        let expected = match (t.role, settings.cmd_vel_type) {
            ("cmd_vel", CmdVelType::Twist) => <ros::Twist as ros::RosMessage>::TYPE_NAME,
            _ => t.type_name,
        };
        let name = settings.topics.get(t.role);
        if let Some((_, found)) = created.iter().find(|(topic, ty)| topic == name && *ty != expected) {
            return Err(format!("topic {name} ({}) created as {found}, the topic table says {expected}", t.role));
        }
    }
    Ok(())
}

fn kv(key: &str, value: &str) -> ros::KeyValue {
    ros::KeyValue { key: key.into(), value: value.into() }
}

/// The mission status a robot publishes (JSON on `<ns>/team/status`): its view of the team's
/// goals, claims and visits — what an operator's console or the simulator farm reads.
#[derive(Debug, Serialize, serde::Deserialize)]
pub struct MissionStatus<'a> {
    /// Robot id.
    #[serde(borrow)]
    pub robot: &'a str,
    /// Robot time, seconds.
    pub time_s: f64,
    /// Root status of its tree.
    pub tree: String,
    /// Why it is stopped, if it is.
    pub stop: StopReason,
    /// Its view of the goals.
    pub goals: Vec<spomp_teamstate::GoalView>,
}

/// Takes one message; a message that does not decode is counted and skipped.
fn take<M: serde::de::DeserializeOwned + 'static>(sub: &Subscription<M>, malformed: &mut u64) -> Option<M> {
    loop {
        match sub.take() {
            Ok(Some((msg, _))) => return Some(msg),
            Ok(None) => return None,
            Err(_) => *malformed += 1,
        }
    }
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

struct LoopState {
    base: TimeBase,
    use_sim_time: bool,
    sim_now: Option<Time>,
    clock_rx: Option<Instant>,
    period: Time,
    next_tick: Time,
    next_team: Time,
    next_save: Time,
    next_status: Time,
    status: spomp_behaviors::Status,
    history: OdometryHistory,
    pairer: PanoramaPairer,
    pair: Option<crate::pairing::PanoramaPair>,
    pair_seq: u64,
    /// Robot time of the newest odometry's receipt, and its wall instant.
    odom_rx: Option<(Time, Instant)>,
    /// Robot time of the newest panorama's stamp.
    panorama_stamp: Option<Time>,
    panorama_rx: Option<Instant>,
    /// Receipt of the newest panorama handed to the robot, until work takes it.
    frame_rx: Option<Instant>,
    /// Receipt of the panorama each perception job processes, by work number.
    work_rx: std::collections::HashMap<u64, Instant>,
    panorama_processed: Option<Instant>,
    skill_failed: bool,
    /// The operator's commands and acknowledgements reported to the observer so far.
    operator_log: spomp_robot::operator_log::OperatorLog,
    /// Robot time of the newest position input.
    position_rx: Option<Time>,
    /// A UAV: it needs a fresh position, not odometry and panoramas.
    flies: bool,
    /// A basestation: no inputs to watch.
    sensorless: bool,
    estop: bool,
    halted: bool,
    last_altitude_m: Option<f64>,
    last_scan: Option<Time>,
    last_estimate: Option<Time>,
    last_path_len: usize,
    last_path_start: Option<Point2>,
    last_problem: Option<String>,
    odom_latency: VecDeque<f64>,
    panorama_latency: VecDeque<f64>,
    report: RunReport,
    frame_check: FrameCheck,
}

/// How long the lockstep loop sleeps when no call is waiting.
const LOCKSTEP_POLL: Duration = Duration::from_micros(200);

/// Where a robot is in a farm's lockstep.
struct LockstepStep {
    /// The farm's hello, once taken.
    hello: Option<lockstep::Hello>,
    /// Number of the next call.
    next_seq: u64,
    /// Period of the tree's ticks, nanoseconds (rounded as the simulator rounds it).
    tick_period_ns: i64,
    next_tick: Time,
    /// Work on the threads by work number, under the farm's latency model (once it is known).
    work_out: Option<ModelledWork<u64>>,
    /// Results the threads finished before they were due.
    finished: std::collections::HashMap<u64, (spomp_robot::runtime::FinishedWork, Duration)>,
    /// The estimate right after this step's panorama.
    estimate_after_panorama: Option<PoseEstimate>,
}

impl LockstepStep {
    fn new(tick_hz: f64) -> Self {
        LockstepStep {
            hello: None,
            next_seq: 1,
            tick_period_ns: ((1e9 / tick_hz).round() as i64).max(1),
            next_tick: Time::ZERO,
            work_out: None,
            finished: std::collections::HashMap::new(),
            estimate_after_panorama: None,
        }
    }
}

/// Latency samples kept for the percentiles.
const LATENCY_SAMPLES: usize = 4096;

trait PushBounded {
    fn push(&mut self, v: f64);
}
impl PushBounded for VecDeque<f64> {
    fn push(&mut self, v: f64) {
        if self.len() == LATENCY_SAMPLES {
            self.pop_front();
        }
        self.push_back(v);
    }
}

impl LoopState {
    fn new(settings: &RunSettings, tick_hz: f64) -> Self {
        let base = if settings.use_sim_time { TimeBase::SIMULATED } else { TimeBase::wall_now() };
        LoopState {
            base,
            use_sim_time: settings.use_sim_time,
            sim_now: None,
            clock_rx: None,
            period: Time::from_secs_f64(1.0 / tick_hz),
            next_tick: Time::ZERO,
            next_team: Time::ZERO,
            next_save: Time::ZERO,
            next_status: Time::ZERO,
            status: spomp_behaviors::Status::Idle,
            history: OdometryHistory::new(400),
            pairer: PanoramaPairer::default(),
            pair: None,
            pair_seq: 0,
            odom_rx: None,
            panorama_stamp: None,
            panorama_rx: None,
            frame_rx: None,
            work_rx: std::collections::HashMap::new(),
            panorama_processed: None,
            skill_failed: false,
            operator_log: Default::default(),
            position_rx: None,
            flies: false,
            sensorless: false,
            estop: false,
            halted: false,
            last_altitude_m: None,
            last_scan: None,
            last_estimate: None,
            last_path_len: 0,
            last_path_start: None,
            last_problem: None,
            odom_latency: VecDeque::new(),
            panorama_latency: VecDeque::new(),
            report: RunReport::default(),
            frame_check: FrameCheck::new(settings.frames.clone(), settings.setting_path.clone()),
        }
    }

    /// Robot time now: `/clock`'s, or the wall clock's since the start.
    fn now(&self) -> Option<Time> {
        if self.use_sim_time { self.sim_now } else { Some(Time::from_nanos(wall_nanos() - self.base.epoch_nanos())) }
    }

    fn refuse(&mut self, robot: &RobotId, observer: &mut dyn RunObserver, why: &str) {
        self.report.malformed_inputs += 1;
        observer.on_problem(robot, self.now().unwrap_or(Time::ZERO), why);
        self.last_problem = Some(why.to_string());
    }

    fn set_pair(&mut self, pair: crate::pairing::PanoramaPair) {
        if self.pair.replace(pair).is_some() {
            self.report.dropped_inputs += 1;
        }
        self.panorama_rx = Some(Instant::now());
    }

    /// The paired panorama once odometry reaches its stamp.
    fn pending_frame(&mut self, settings: &RunSettings) -> Option<PanoramaFrame> {
        let stamp = self.pair.as_ref()?.0;
        let odom_pose = match self.history.pose_at(stamp) {
            Some(p) => p,
            None => {
                // Odometry has not reached the stamp yet: wait, unless it is already past it
                // (then the panorama is older than the history and can never be placed).
                if self.history.latest().is_some_and(|o| o.stamp > stamp) {
                    self.pair = None;
                    self.report.dropped_inputs += 1;
                }
                return None;
            }
        };
        let (t, depth, semantic) = self.pair.take()?;
        self.pair_seq += 1;
        self.panorama_stamp = Some(t);
        self.report.received.panoramas += 1;
        Some(convert::frame(self.pair_seq, t, odom_pose, settings.sensor_height_m, depth, semantic))
    }

    fn stop_reason(&self, now: Time, settings: &RunSettings) -> StopReason {
        if self.estop {
            return StopReason::EStop;
        }
        if self.skill_failed {
            return StopReason::SkillFailed;
        }
        if self.use_sim_time && self.clock_rx.is_none_or(|rx| rx.elapsed() > CLOCK_STALL) {
            return StopReason::ClockStalled;
        }
        let age = |t: Time| (now.nanos - t.nanos) as f64 * 1e-9;
        if self.sensorless {
            // A basestation has no sensors to go stale and nothing to drive.
            return StopReason::None;
        }
        if self.flies {
            return match self.position_rx {
                Some(t) if age(t) <= settings.odometry_timeout_s => StopReason::None,
                _ => StopReason::PositionStale,
            };
        }
        match self.odom_rx {
            Some((t, _)) if age(t) <= settings.odometry_timeout_s => {}
            _ => return StopReason::OdometryStale,
        }
        match self.panorama_stamp {
            Some(t) if age(t) <= settings.panorama_timeout_s => StopReason::None,
            _ => StopReason::PanoramaStale,
        }
    }

    /// The figures so far; `robot` adds its own count of panoramas it replaced before processing.
    fn snapshot(&self, robot: &Robot, wall: Duration) -> RunReport {
        let mut r = self.report.clone();
        r.robot = robot.id().to_string();
        r.wall_s = wall.as_secs_f64();
        r.target_tick_hz = robot.tick_hz();
        r.tick_rate_hz = if r.wall_s > 0.0 { r.ticks as f64 / r.wall_s } else { 0.0 };
        r.dropped_inputs += self.pairer.dropped() + robot.superseded_panoramas();
        r.tree_status = self.status.to_string();
        r.team_rejected_operator = robot.team().refused_operator_records();
        r.robot_time_s = self.now().map_or(0.0, |t| t.as_secs_f64());
        (r.odometry_to_command_p50_ms, r.odometry_to_command_p99_ms) = percentiles(&self.odom_latency);
        (r.panorama_to_command_p50_ms, r.panorama_to_command_p99_ms) = percentiles(&self.panorama_latency);
        r
    }
}

/// Median and 99th percentile.
fn percentiles(samples: &VecDeque<f64>) -> (f64, f64) {
    if samples.is_empty() {
        return (0.0, 0.0);
    }
    let mut v: Vec<f64> = samples.iter().copied().collect();
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.99))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Periods of one robot's team sync towards a peer over a link of `budget` bytes per
    /// period, with (`carry`) or without the unused budget carried: how many periods until the
    /// peer holds a map version larger than one period's budget (None: not within 20).
    fn periods_until_map_arrives(budget: usize, carry: bool) -> Option<usize> {
        use spomp_teamstate::{TeamState, TeamStateParams};
        let (a, b) = (RobotId::new("uav1"), RobotId::new("ugv1"));
        let mut sender = TeamState::new(a.clone(), 0, TeamStateParams::default()).expect("sender");
        let mut receiver = TeamState::new(b.clone(), 1, TeamStateParams::default()).expect("receiver");
        // 2.5 budgets of bytes that do not compress, as a PNG map layer.
        let blob: Vec<u8> =
            (0..budget * 5 / 2).map(|i| (i as u32).wrapping_mul(2_654_435_761).to_le_bytes()[3]).collect();
        sender.add_map_version(1, Time::from_secs_f64(1.0), blob).expect("map version");
        let mut credit = LinkCredit::default();
        for period in 1..=20 {
            if !carry {
                credit = LinkCredit::default();
            }
            credit.begin_round([(&b, budget as u64)]);
            let sent = spomp_robot::team_round::round(RoundShape::PerTier, TierSet::ALL, credit.left(&b), |t, left| {
                sender.make_sync(&b, t, left).map(|m| m.encode())
            });
            for (_, bytes) in sent {
                credit.spend(&b, bytes.len());
                receiver.apply_bytes(&a, &bytes).expect("a good message");
            }
            if receiver.newest_map().is_some() {
                return Some(period);
            }
        }
        None
    }

    #[test]
    fn a_map_version_larger_than_one_periods_budget_goes_out_after_enough_periods() {
        // Regression: `spomp run` gave every period a fresh budget, so over the Zenoh link a map
        // version above 1 MB (the shipped mission's bandwidth) never went out, the UAV's syncs
        // never completed and the UGVs never saw the map's later clusters.
        assert_eq!(periods_until_map_arrives(100_000, false), None);
        assert_eq!(periods_until_map_arrives(100_000, true), Some(3));
    }

    #[test]
    fn the_node_refuses_a_topic_whose_type_is_not_the_tables() {
        let yaml = include_str!("../../../tests/missions/ros2/interop.yaml");
        let mut mission: spomp_behaviors::mission::schema::MissionFile =
            serde_saphyr::from_str(yaml).expect("the fixture parses");
        let settings = RunSettings::from_mission(&mission, "ugv1", None).expect("settings");
        let created = |pairs: &[(&str, &'static str)]| -> Vec<(String, &'static str)> {
            pairs.iter().map(|(t, ty)| (t.to_string(), *ty)).collect()
        };
        let right = created(&[
            ("/ugv1/cmd_vel", "geometry_msgs/msg/TwistStamped"),
            ("/ugv1/pose_estimate", "geometry_msgs/msg/PoseWithCovarianceStamped"),
            ("/tf", "tf2_msgs/msg/TFMessage"),
        ]);
        assert_eq!(check_topic_types(&settings, &right), Ok(()));
        let wrong = created(&[("/ugv1/pose_estimate", "geometry_msgs/msg/PoseStamped")]);
        let why = check_topic_types(&settings, &wrong).expect_err("a second type for pose_estimate");
        assert!(why.contains("/ugv1/pose_estimate") && why.contains("PoseWithCovarianceStamped"), "{why}");
        // The command type the settings choose.
        let spec = mission.team.iter_mut().find(|r| r.id == "ugv1").and_then(|r| r.ros2.as_mut()).expect("ros2");
        spec.0["cmd_vel_type"] = serde_json::json!("twist");
        let twist = RunSettings::from_mission(&mission, "ugv1", None).expect("settings");
        assert!(check_topic_types(&twist, &right).is_err());
        assert_eq!(check_topic_types(&twist, &created(&[("/ugv1/cmd_vel", "geometry_msgs/msg/Twist")])), Ok(()));
    }

    #[test]
    fn percentiles_of_a_known_series() {
        let s: VecDeque<f64> = (1..=100).map(f64::from).collect();
        let (p50, p99) = percentiles(&s);
        assert!((p50 - 50.0).abs() <= 1.0 && (p99 - 99.0).abs() <= 1.0, "{p50} {p99}");
        assert_eq!(percentiles(&VecDeque::new()), (0.0, 0.0));
    }
}
