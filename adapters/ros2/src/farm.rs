//! The simulator's side of a robot farm: it publishes the simulated robots' sensors and
//! `/clock`, and takes their commands, team-state messages and mission status from the
//! `spomp run` processes that drive them. Everything here is in spomp's types, so the simulator
//! needs no ROS 2 knowledge (the CLI connects the two).

use std::collections::{BTreeMap, VecDeque};

use crate::mission_section::Ros2Spec;
use ros2_client::{Publisher, Subscription};
use spomp_core::{
    FlightCommand, GridSpec, MapTile, Odometry, OdometryCovariance, PanoramaFrame, Point2, PoseEstimate, Time, Twist2,
};
use spomp_ros_msgs as ros;
use spomp_ros_msgs::{CmdVelType, DepthEncoding, RobotFrames};
use spomp_teamstate::GoalView;

use crate::clock::TimeBase;
use crate::convert;
use crate::dds::{DdsError, DdsNode, DdsSettings, latched_qos, sensor_qos, state_qos};
use crate::lockstep::{FarmLockstep, Hello, LockstepError, Op, StepDone};
use crate::run::MissionStatus;
use crate::topics::{CLOCK_TOPIC, TopicNames};

/// A team-state message one driven robot sent to another.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TeamPacket {
    /// Sender.
    pub from: String,
    /// Addressee.
    pub to: String,
    /// The sync message, as encoded by the sender.
    pub bytes: Vec<u8>,
}

/// What the farm knows of one driven robot.
struct FarmRobot {
    id: String,
    odom: Publisher<ros::Odometry>,
    depth: Publisher<ros::Image>,
    semantic: Publisher<ros::Image>,
    pose_in: Publisher<ros::PoseStamped>,
    tiles: Publisher<ros::GridMap>,
    team_in: Publisher<ros::BytesMsg>,
    cmd_vel: CmdVelReader,
    frames: RobotFrames,
    /// The robot's tf topic (a key of `FarmLink::tf`).
    tf_topic: String,
    setpoint: Subscription<ros::PoseStamped>,
    setpoint_speed: Subscription<ros::Float64Msg>,
    /// The newest commanded speed toward the setpoint, m/s (`None`: none heard).
    speed_mps: Option<f64>,
    team_out: Subscription<ros::BytesMsg>,
    status: Subscription<ros::StringMsg>,
    depth_encoding: DepthEncoding,
    depth_scale_m: Option<f64>,
    /// Newest velocity command and the simulated time it arrived.
    command: Option<(Twist2, Time)>,
    /// Newest setpoint and the simulated time it arrived.
    setpoint_cmd: Option<(FlightCommand, Time)>,
    goals: Vec<GoalView>,
    tree: String,
    /// The robot's lockstep topics, in a lockstep farm.
    lockstep: Option<FarmLockstep>,
}

/// A robot's velocity commands, of the type its settings choose.
enum CmdVelReader {
    Twist(Subscription<ros::Twist>),
    Stamped(Subscription<ros::TwistStamped>),
}

impl CmdVelReader {
    /// The next command (`Ok(None)`: none waiting; `Err`: one that did not decode).
    fn take(&self) -> Result<Option<ros::Twist>, ()> {
        match self {
            CmdVelReader::Twist(s) => s.take().map(|m| m.map(|(t, _)| t)).map_err(|_| ()),
            CmdVelReader::Stamped(s) => s.take().map(|m| m.map(|(t, _)| t.twist)).map_err(|_| ()),
        }
    }
}

/// The ROS 2 link of a simulator whose robots are driven by `spomp run` processes.
pub struct FarmLink {
    robots: Vec<FarmRobot>,
    clock: Publisher<ros::Clock>,
    /// `odom → base_link` of the robots, one writer per tf topic.
    tf: BTreeMap<String, Publisher<ros::TfMessage>>,
    /// The sensor mounts (`base_link → sensor`), one latched writer per tf_static topic.
    _tf_static: BTreeMap<String, Publisher<ros::TfMessage>>,
    outbox: VecDeque<TeamPacket>,
    malformed: u64,
    // Entities before the node: they are dropped first.
    _node: DdsNode,
}

/// A robot's command older than this (simulated time) is stale: the simulator stops the robot.
pub const COMMAND_TIMEOUT_S: f64 = 0.5;

impl FarmLink {
    /// A link for `robots` (id and `ros2:` settings each) in `dds`'s domain; with `lockstep`,
    /// each robot's lockstep topics too ([`crate::lockstep`]).
    pub fn new(dds: &DdsSettings, robots: &[(String, Option<Ros2Spec>)], lockstep: bool) -> Result<Self, DdsError> {
        let mut node = DdsNode::new(dds, "/", "spomp_sim")?;
        let clock = node.publisher(CLOCK_TOPIC, &state_qos(1))?;
        let mut out = Vec::new();
        let mut tf = BTreeMap::new();
        let mut mounts: BTreeMap<String, Vec<ros::TransformStamped>> = BTreeMap::new();
        for (id, spec) in robots {
            let t = TopicNames::resolve(id, spec.as_ref());
            let frames = crate::frames::resolve(spec.as_ref(), &t);
            let ros_spec = spec.clone().unwrap_or_default();
            if !tf.contains_key(t.get("tf")) {
                tf.insert(t.get("tf").to_string(), node.publisher(t.get("tf"), &state_qos(100))?);
            }
            let mount = convert::sensor_mount(&frames, ros_spec.sensor_height_m, Time::ZERO, &TimeBase::SIMULATED);
            mounts.entry(t.get("tf_static").to_string()).or_default().extend(mount.transforms);
            let cmd_vel = match ros_spec.cmd_vel_type {
                CmdVelType::Twist => CmdVelReader::Twist(node.subscription(t.get("cmd_vel"), &sensor_qos(1))?),
                CmdVelType::TwistStamped => CmdVelReader::Stamped(node.subscription(t.get("cmd_vel"), &sensor_qos(1))?),
            };
            out.push(FarmRobot {
                id: id.clone(),
                cmd_vel,
                frames,
                tf_topic: t.get("tf").to_string(),
                odom: node.publisher(t.get("odom"), &state_qos(20))?,
                depth: node.publisher(t.get("panorama/depth"), &state_qos(2))?,
                semantic: node.publisher(t.get("panorama/semantic"), &state_qos(2))?,
                pose_in: node.publisher(t.get("pose_in"), &state_qos(5))?,
                tiles: node.publisher(t.get("camera/tiles"), &state_qos(64))?,
                team_in: node.publisher(t.get("team/in"), &state_qos(64))?,
                setpoint: node.subscription(t.get("setpoint"), &sensor_qos(1))?,
                setpoint_speed: node.subscription(t.get("setpoint_speed"), &sensor_qos(1))?,
                speed_mps: None,
                team_out: node.subscription(t.get("team/out"), &sensor_qos(64))?,
                // Reliable and latched like the robot's writer: the status a robot published
                // before discovery matched the two is still delivered (with a volatile, best-effort
                // reader a robot that reported once at time zero, while the clock waited for it,
                // was never seen).
                status: node.subscription(&t.status(), &latched_qos(1))?,
                depth_encoding: ros_spec.depth_encoding,
                depth_scale_m: ros_spec.depth_scale_m,
                command: None,
                setpoint_cmd: None,
                goals: Vec::new(),
                tree: String::new(),
                lockstep: if lockstep { Some(FarmLockstep::new(&mut node, id, &t)?) } else { None },
            });
        }
        // As tf2's static broadcaster: every mount of a topic in one latched message, so a
        // late reader gets them all (a writer keeps only its last message).
        let mut tf_static = BTreeMap::new();
        for (topic, transforms) in mounts {
            let w: Publisher<ros::TfMessage> = node.publisher(&topic, &latched_qos(1))?;
            let _ = w.publish(ros::TfMessage { transforms });
            tf_static.insert(topic, w);
        }
        Ok(FarmLink {
            robots: out,
            clock,
            tf,
            _tf_static: tf_static,
            outbox: VecDeque::new(),
            malformed: 0,
            _node: node,
        })
    }

    fn robot(&self, id: &str) -> Option<&FarmRobot> {
        self.robots.iter().find(|r| r.id == id)
    }

    fn lockstep_of(&mut self, id: &str) -> Option<&mut FarmLockstep> {
        self.robots.iter_mut().find(|r| r.id == id).and_then(|r| r.lockstep.as_mut())
    }

    /// Says `hello` to every robot in lockstep, again and again, until each answers or `wait`
    /// passes: each robot with its answer (ready, refused, or no answer).
    pub fn connect_lockstep(
        &mut self,
        hello: &Hello,
        wait: std::time::Duration,
    ) -> Vec<(String, Result<(), LockstepError>)> {
        use std::time::{Duration, Instant};
        let deadline = Instant::now() + wait;
        let mut answers: Vec<Option<Result<(), LockstepError>>> = self.robots.iter().map(|_| None).collect();
        let mut next_hello = Instant::now();
        loop {
            let say = Instant::now() >= next_hello;
            if say {
                next_hello = Instant::now() + Duration::from_millis(250);
            }
            for (r, answer) in self.robots.iter_mut().zip(answers.iter_mut()) {
                let Some(l) = r.lockstep.as_mut().filter(|_| answer.is_none()) else { continue };
                if say {
                    l.say_hello(hello);
                }
                *answer = l.hello_answer();
            }
            if answers.iter().all(Option::is_some) || Instant::now() >= deadline {
                break;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        self.robots
            .iter()
            .zip(answers)
            .map(|(r, a)| {
                let timeout = LockstepError::Timeout { seq: 0, timeout_s: wait.as_secs_f64() };
                (r.id.clone(), a.unwrap_or(Err(timeout)))
            })
            .collect()
    }

    /// Says `hello` to a robot that left the lockstep (or never joined); true once its process
    /// answered ready: its calls start again from the first.
    pub fn lockstep_rejoin(&mut self, id: &str, hello: &Hello) -> bool {
        let Some(l) = self.lockstep_of(id) else { return false };
        if let Some(Ok(())) = l.hello_answer() {
            l.restart();
            return true;
        }
        l.say_hello(hello);
        false
    }

    /// Sends a lockstep call to a robot (nothing if it is not in lockstep).
    pub fn lockstep_call(&mut self, id: &str, op: Op) {
        if let Some(l) = self.lockstep_of(id) {
            l.send(op);
        }
    }

    /// Asks a robot in lockstep for its team-state message to `to`, waiting for it.
    pub fn lockstep_team_out(
        &mut self,
        id: &str,
        to: &spomp_core::RobotId,
        tiers: u8,
        budget_bytes: u64,
        timeout: std::time::Duration,
    ) -> Result<Option<Vec<u8>>, LockstepError> {
        match self.lockstep_of(id) {
            Some(l) => l.team_out(to, tiers, budget_bytes, timeout),
            None => Ok(None),
        }
    }

    /// Waits for a robot's answer to this step's tick.
    pub fn lockstep_done(&mut self, id: &str, timeout: std::time::Duration) -> Result<StepDone, LockstepError> {
        match self.lockstep_of(id) {
            Some(l) => l.wait_done(timeout),
            None => Err(LockstepError::Unexpected { seq: 0, what: format!("`{id}` is not in lockstep") }),
        }
    }

    /// Whether `id` is driven over this link.
    pub fn drives(&self, id: &str) -> bool {
        self.robot(id).is_some()
    }

    /// Publishes the simulated time.
    pub fn publish_clock(&self, now: Time) {
        let _ = self.clock.publish(ros::Clock { clock: now.into() });
    }

    /// Publishes a robot's odometry, and `odom → base_link` on its tf topic as its driver
    /// would (covariances zero: see [`FarmLink::publish_odometry_with_covariance`]).
    pub fn publish_odometry(&self, id: &str, odom: &Odometry) {
        self.publish_odom(id, odom, None);
    }

    /// Publishes a robot's odometry with the covariances of the simulator's noise model, and
    /// `odom → base_link` on its tf topic, as its driver would.
    pub fn publish_odometry_with_covariance(&self, id: &str, odom: &Odometry, covariance: &OdometryCovariance) {
        self.publish_odom(id, odom, Some(covariance));
    }

    fn publish_odom(&self, id: &str, odom: &Odometry, covariance: Option<&OdometryCovariance>) {
        if let Some(r) = self.robot(id) {
            let base = TimeBase::SIMULATED;
            let msg = convert::odometry_to_ros(&r.frames, odom, &base);
            let _ = r.odom.publish(match covariance {
                Some(c) => msg.with_covariance(c),
                None => msg,
            });
            if let Some(w) = self.tf.get(&r.tf_topic) {
                let _ = w.publish(convert::odom_to_base(&r.frames, odom, &base));
            }
        }
    }

    /// Publishes a robot's panorama: depth (in its `ros2.depth_encoding`, `32FC1` metres by
    /// default) and labels (`mono8`), same stamp.
    pub fn publish_panorama(&self, id: &str, frame: &PanoramaFrame) {
        if let Some(r) = self.robot(id) {
            let base = TimeBase::SIMULATED;
            let sensor = &r.frames.sensor;
            let _ = r.depth.publish(convert::depth_to_ros(
                sensor,
                &frame.depth,
                r.depth_encoding,
                r.depth_scale_m,
                frame.stamp,
                &base,
            ));
            let _ = r.semantic.publish(convert::semantic_to_ros(sensor, &frame.semantic, frame.stamp, &base));
        }
    }

    /// Publishes a map-frame pose for a robot (a UAV's position, or truth where the mission
    /// asks for it).
    pub fn publish_pose(&self, id: &str, est: &PoseEstimate, z_m: f64) {
        if let Some(r) = self.robot(id) {
            let msg = convert::pose_to_ros(est.pose, z_m, &r.frames.map, est.stamp, &TimeBase::SIMULATED);
            let _ = r.pose_in.publish(msg);
        }
    }

    /// Publishes what a UAV's camera mapped: each tile as a `grid_map_msgs/GridMap` in `map`.
    pub fn publish_camera_tiles(&self, id: &str, now: Time, tiles: &[MapTile], grid: &GridSpec) {
        if let Some(r) = self.robot(id) {
            let stamp = TimeBase::SIMULATED.to_ros(now);
            for tile in tiles {
                let _ = r.tiles.publish(ros::GridMap::from_tile(tile, grid, &r.frames.map, stamp));
            }
        }
    }

    /// Takes everything the robots sent; `now` is the simulated time of arrival.
    pub fn poll(&mut self, now: Time) {
        for r in &mut self.robots {
            loop {
                match r.cmd_vel.take() {
                    Ok(Some(msg)) => match convert::twist_from_ros(&msg) {
                        Ok(cmd) => r.command = Some((cmd, now)),
                        Err(_) => self.malformed += 1,
                    },
                    Ok(None) => break,
                    Err(_) => self.malformed += 1,
                }
            }
            // The speed first: a setpoint taken in this pass flies at the speed sent with it.
            loop {
                match r.setpoint_speed.take() {
                    Ok(Some((msg, _))) if msg.data.is_finite() && msg.data > 0.0 => r.speed_mps = Some(msg.data),
                    Ok(Some(_)) | Err(_) => self.malformed += 1,
                    Ok(None) => break,
                }
            }
            loop {
                match r.setpoint.take() {
                    Ok(Some((msg, _))) => {
                        let p = msg.pose.position;
                        if [p.x, p.y, p.z].iter().all(|v| v.is_finite()) {
                            let cmd = FlightCommand {
                                target: Point2::new(p.x, p.y),
                                altitude_m: p.z,
                                // Without a speed the simulated UAV keeps the one it has.
                                speed_mps: r.speed_mps.unwrap_or(f64::INFINITY),
                            };
                            r.setpoint_cmd = Some((cmd, now));
                        } else {
                            self.malformed += 1;
                        }
                    }
                    Ok(None) => break,
                    Err(_) => self.malformed += 1,
                }
            }
            loop {
                match r.team_out.take() {
                    Ok(Some((msg, _))) => match msg.layout.dim.first() {
                        Some(d) if !d.label.is_empty() => {
                            self.outbox.push_back(TeamPacket {
                                from: r.id.clone(),
                                to: d.label.clone(),
                                bytes: msg.data,
                            });
                        }
                        _ => self.malformed += 1,
                    },
                    Ok(None) => break,
                    Err(_) => self.malformed += 1,
                }
            }
            loop {
                match r.status.take() {
                    Ok(Some((msg, _))) => match serde_json::from_str::<MissionStatus<'_>>(&msg.data) {
                        Ok(status) if status.robot == r.id => {
                            r.goals = status.goals;
                            r.tree = status.tree;
                        }
                        _ => self.malformed += 1,
                    },
                    Ok(None) => break,
                    Err(_) => self.malformed += 1,
                }
            }
        }
    }

    /// The robot's velocity command if a fresh one arrived (within [`COMMAND_TIMEOUT_S`] of
    /// `now`); `None` means stop.
    pub fn command(&self, id: &str, now: Time) -> Option<Twist2> {
        let (cmd, at) = self.robot(id)?.command?;
        ((now.nanos - at.nanos) as f64 * 1e-9 <= COMMAND_TIMEOUT_S).then_some(cmd)
    }

    /// The robot's setpoint if a fresh one arrived; `None` means hover.
    pub fn setpoint(&self, id: &str, now: Time) -> Option<FlightCommand> {
        let (cmd, at) = self.robot(id)?.setpoint_cmd?;
        ((now.nanos - at.nanos) as f64 * 1e-9 <= COMMAND_TIMEOUT_S).then_some(cmd)
    }

    /// Team-state messages sent since the last call, oldest first.
    pub fn take_team_packets(&mut self) -> Vec<TeamPacket> {
        self.outbox.drain(..).collect()
    }

    /// Delivers a team-state message to a driven robot.
    pub fn deliver_team(&self, to: &str, from: &str, bytes: &[u8]) {
        if let Some(r) = self.robot(to) {
            let _ = r.team_in.publish(ros::BytesMsg::labelled(from, bytes.to_vec()));
        }
    }

    /// The goals as a driven robot last reported them.
    pub fn goals(&self, id: &str) -> &[GoalView] {
        self.robot(id).map_or(&[], |r| r.goals.as_slice())
    }

    /// The root status a driven robot last reported (`""` before its first report).
    pub fn tree_status(&self, id: &str) -> &str {
        self.robot(id).map_or("", |r| r.tree.as_str())
    }

    /// Messages that could not be used.
    pub fn malformed(&self) -> u64 {
        self.malformed
    }
}
