//! Writing.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::{Seek, Write};
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, Ordering};

use byteorder::LittleEndian;
use spomp_behaviors::Status;
use spomp_behaviors::trace::TransitionRecord;
use spomp_core::{AerialMap, ClassTable, DepthPanorama, Pose2, ReachabilityScan, SemanticPanorama, Time, Twist2};
use spomp_ros_msgs::{self as ros, CmdVelType, DepthEncoding, RobotFrames, RosMessage};

use crate::safe::{FLUSH_CHUNK, FLUSH_IGNORE, FLUSH_LAST, SafeFile};

/// CDR encapsulation header for little-endian plain CDR, as ROS 2 writes it.
pub(crate) const CDR_LE_HEADER: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Why recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The MCAP writer failed (I/O or format).
    #[error("mcap: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A message could not be encoded.
    #[error("cdr encoding of {type_name}: {message}")]
    Encode {
        /// Message type.
        type_name: &'static str,
        /// What failed.
        message: String,
    },
    /// JSON encoding failed.
    #[error("json: {0}")]
    Json(#[from] serde_json::Error),
    /// The log file could not be created or written.
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

/// Encodes a ROS 2 message as ROS 2 puts it on the wire: encapsulation header + CDR body.
pub fn encode_cdr<M: RosMessage>(msg: &M) -> Result<Vec<u8>, RecordError> {
    let body = cdr_encoding::to_vec::<M, LittleEndian>(msg)
        .map_err(|e| RecordError::Encode { type_name: M::TYPE_NAME, message: e.to_string() })?;
    let mut out = Vec::with_capacity(body.len() + 4);
    out.extend_from_slice(&CDR_LE_HEADER);
    out.extend_from_slice(&body);
    Ok(out)
}

/// Also receives every message a [`Recorder`] writes, encoded as in the log: what a live view
/// (the Foxglove WebSocket server of `spomp sim --live`) publishes, so it carries the log's
/// channels, built and encoded once.
pub trait MessageTap: Send {
    /// One message: its topic, its ROS 2 type and `ros2msg` definition, its log time
    /// (nanoseconds) and its CDR bytes (with the encapsulation header). `latched`: the message
    /// stays true until the next one on its topic (the map, the goals, a robot's active path),
    /// so a viewer that subscribes later should be given the last one.
    fn message(&mut self, topic: &str, message_type: &MessageType, log_time_ns: u64, cdr: &[u8], latched: bool);
}

/// A ROS 2 message type as a channel's schema names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MessageType {
    /// `package/msg/Type`.
    pub name: &'static str,
    /// The `ros2msg` definition.
    pub definition: &'static str,
}

impl MessageType {
    /// The type of `M`.
    pub fn of<M: RosMessage>() -> Self {
        MessageType { name: M::TYPE_NAME, definition: M::DEFINITION }
    }
}

/// Topics whose messages hold until the next one (see [`MessageTap::message`]).
const MAP_TOPIC: &str = "/map";
const GOALS_TOPIC: &str = "/goals";

/// How a robot's messages are named and typed in the log: as its ROS 2 side names them
/// (`spomp_ros2` resolves them from the mission's `ros2:` settings), so a bag recorded from DDS
/// and spomp's own log hold the same types under the same names, in the same frames.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotConventions {
    /// Frame ids.
    pub frames: RobotFrames,
    /// Type of `cmd_vel`.
    pub cmd_vel_type: CmdVelType,
    /// The tf topic.
    pub tf: String,
    /// The static tf topic.
    pub tf_static: String,
    /// Encoding of `/R/panorama/depth` (the robot's `ros2.depth_encoding`).
    pub depth_encoding: DepthEncoding,
    /// Metres per count of an integer depth encoding (`None`: the encoding's default).
    pub depth_scale_m: Option<f64>,
    /// The logger name of the robot's `/R/rosout` entries: its ROS 2 node's, in rcl's dotted
    /// form (`ugv1.spomp`), as on DDS `/rosout`.
    pub logger: String,
}

impl RobotConventions {
    /// The ROS 2 side's defaults for a robot in its own namespace: frames prefixed with its id,
    /// `TwistStamped` commands, the global `/tf` and `/tf_static`.
    pub fn defaults(robot: &str) -> Self {
        RobotConventions {
            frames: RobotFrames::prefixed(robot),
            cmd_vel_type: CmdVelType::default(),
            tf: "/tf".into(),
            tf_static: "/tf_static".into(),
            depth_encoding: DepthEncoding::default(),
            depth_scale_m: None,
            logger: ros::rcl_logger_name(&format!("/{robot}"), ros::ROBOT_NODE_NAME),
        }
    }
}

/// Recording options.
#[derive(Debug, Clone)]
pub struct RecorderOptions {
    /// Keep every n-th panorama row and column (1 = full size).
    pub panorama_downsample: usize,
    /// Compress chunks with zstd.
    pub compress: bool,
    /// A chunk is closed (and, for [`Recorder::create`], written to disk) once its messages
    /// reach this many bytes…
    pub chunk_bytes: u64,
    /// …or span this long in log time, seconds: a crash loses at most this much of the log.
    pub chunk_duration_s: f64,
}

impl Default for RecorderOptions {
    fn default() -> Self {
        RecorderOptions { panorama_downsample: 4, compress: true, chunk_bytes: 1 << 20, chunk_duration_s: 10.0 }
    }
}

/// Writes a run to MCAP.
pub struct Recorder<W: Write + Seek> {
    writer: mcap::Writer<W>,
    schemas: HashMap<&'static str, u16>,
    channels: HashMap<String, u16>,
    sequence: u32,
    options: RecorderOptions,
    messages: u64,
    /// Message bytes in the open chunk.
    chunk_bytes: u64,
    /// Log time of the open chunk's first message.
    chunk_start: Option<u64>,
    /// What a flush of the sink means (see [`SafeFile`]).
    flush_mode: Arc<AtomicU8>,
    /// Where every message also goes (a live view).
    tap: Option<Box<dyn MessageTap>>,
    /// Each robot's running behaviour nodes by path, from its transitions.
    running: HashMap<String, BTreeSet<String>>,
    /// Each robot's active path as last written.
    active_paths: HashMap<String, String>,
    /// Each robot's names and frames (defaults until set).
    conventions: HashMap<String, RobotConventions>,
    /// Each robot's newest odometry pose, for `map → odom`.
    odom_pose: HashMap<String, Pose2>,
    /// The sensor mounts written, by static tf topic (each write repeats them all: a latched
    /// topic keeps only its last message).
    mounts: BTreeMap<String, Vec<ros::TransformStamped>>,
}

impl Recorder<SafeFile> {
    /// A recorder writing a crash-safe log file at `path` (created or truncated): chunks are
    /// written whole, each followed by a provisional end, so the file is a complete MCAP file
    /// up to its last chunk at any moment (see [`SafeFile`]).
    pub fn create(path: &Path, options: RecorderOptions) -> Result<Self, RecordError> {
        let mode = Arc::new(AtomicU8::new(FLUSH_IGNORE));
        let file = SafeFile::create(path, mode.clone())?;
        let mut rec = Recorder::with_mode(file, options, mode)?;
        rec.end_chunk()?; // the header and a provisional end: a valid, empty log
        Ok(rec)
    }
}

impl<W: Write + Seek> Recorder<W> {
    /// A recorder writing to `w`.
    pub fn new(w: W, options: RecorderOptions) -> Result<Self, RecordError> {
        Recorder::with_mode(w, options, Arc::new(AtomicU8::new(FLUSH_IGNORE)))
    }

    fn with_mode(w: W, options: RecorderOptions, flush_mode: Arc<AtomicU8>) -> Result<Self, RecordError> {
        let compression = if options.compress { Some(mcap::Compression::Zstd) } else { None };
        // Chunks are built in memory and written whole (no seeking back to patch a header), and
        // closed by `log` on size or duration.
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library("spomp")
            .compression(compression)
            .chunk_size(None)
            .disable_seeking(true)
            .create(w)?;
        Ok(Recorder {
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            sequence: 0,
            options,
            messages: 0,
            chunk_bytes: 0,
            chunk_start: None,
            flush_mode,
            tap: None,
            running: HashMap::new(),
            active_paths: HashMap::new(),
            conventions: HashMap::new(),
            odom_pose: HashMap::new(),
            mounts: BTreeMap::new(),
        })
    }

    /// Closes the open chunk and writes it out (to disk, for [`Recorder::create`]).
    pub fn end_chunk(&mut self) -> Result<(), RecordError> {
        self.flush_mode.store(FLUSH_CHUNK, Ordering::Relaxed);
        let result = self.writer.flush();
        self.flush_mode.store(FLUSH_IGNORE, Ordering::Relaxed);
        self.chunk_bytes = 0;
        self.chunk_start = None;
        Ok(result?)
    }

    /// Sends every message written from now on to `tap` as well.
    pub fn set_tap(&mut self, tap: Box<dyn MessageTap>) {
        self.tap = Some(tap);
    }

    /// Messages written so far.
    pub fn message_count(&self) -> u64 {
        self.messages
    }

    fn channel<M: RosMessage>(&mut self, topic: &str) -> Result<u16, RecordError> {
        if let Some(&id) = self.channels.get(topic) {
            return Ok(id);
        }
        let schema = match self.schemas.get(M::TYPE_NAME) {
            Some(&id) => id,
            None => {
                let id = self.writer.add_schema(M::TYPE_NAME, "ros2msg", M::DEFINITION.as_bytes())?;
                self.schemas.insert(M::TYPE_NAME, id);
                id
            }
        };
        let id = self.writer.add_channel(schema, topic, "cdr", &BTreeMap::new())?;
        self.channels.insert(topic.to_string(), id);
        Ok(id)
    }

    /// Writes one message on a topic at a time.
    pub fn log<M: RosMessage>(&mut self, topic: &str, time: Time, msg: &M) -> Result<(), RecordError> {
        self.log_message(topic, time, msg, false)
    }

    fn log_message<M: RosMessage>(
        &mut self,
        topic: &str,
        time: Time,
        msg: &M,
        latched: bool,
    ) -> Result<(), RecordError> {
        let channel_id = self.channel::<M>(topic)?;
        let data = encode_cdr(msg)?;
        let t = time.nanos.max(0) as u64;
        if let Some(tap) = self.tap.as_mut() {
            tap.message(topic, &MessageType::of::<M>(), t, &data, latched);
        }
        self.sequence = self.sequence.wrapping_add(1);
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader { channel_id, sequence: self.sequence, log_time: t, publish_time: t },
            &data,
        )?;
        self.messages += 1;
        self.chunk_bytes += data.len() as u64;
        let start = *self.chunk_start.get_or_insert(t);
        let span_s = t.saturating_sub(start) as f64 * 1e-9;
        if self.chunk_bytes >= self.options.chunk_bytes || span_s >= self.options.chunk_duration_s {
            self.end_chunk()?;
        }
        Ok(())
    }

    /// Names and frames of `robot`'s messages from now on (default: [`RobotConventions::defaults`]).
    pub fn set_conventions(&mut self, robot: &str, conventions: RobotConventions) {
        self.conventions.insert(robot.to_string(), conventions);
    }

    /// The names and frames of `robot`'s messages.
    pub fn conventions(&self, robot: &str) -> RobotConventions {
        self.conventions.get(robot).cloned().unwrap_or_else(|| RobotConventions::defaults(robot))
    }

    /// A map-frame pose (`/R/pose`).
    pub fn pose(&mut self, robot: &str, time: Time, pose: Pose2, z: f64) -> Result<(), RecordError> {
        self.pose_on(robot, "pose", time, pose, z)
    }

    /// A map-frame pose input as the robot received it (`/R/pose_in`, its ROS 2 topic).
    pub fn pose_in(&mut self, robot: &str, time: Time, pose: Pose2, z: f64) -> Result<(), RecordError> {
        self.pose_on(robot, "pose_in", time, pose, z)
    }

    fn pose_on(&mut self, robot: &str, name: &str, time: Time, pose: Pose2, z: f64) -> Result<(), RecordError> {
        let map = self.conventions(robot).frames.map;
        let msg = ros::PoseStamped { header: ros::Header::new(time, map), pose: ros::Pose::from_pose2(pose, z) };
        self.log(&format!("/{robot}/{name}"), time, &msg)
    }

    /// The robot's pose estimate (`/R/pose_estimate`, PoseWithCovarianceStamped as on DDS).
    pub fn estimate(&mut self, robot: &str, estimate: &spomp_core::PoseEstimate) -> Result<(), RecordError> {
        let map = self.conventions(robot).frames.map;
        let msg = ros::PoseWithCovarianceStamped::from_estimate(estimate, &map, estimate.stamp.into());
        self.log(&format!("/{robot}/pose_estimate"), estimate.stamp, &msg)
    }

    /// Odometry (`/R/odom`) and the `odom → base_link` transform it gives on the robot's tf
    /// topic (what its driver broadcasts), so odometry and everything in the body frame can be
    /// placed.
    pub fn odometry(&mut self, robot: &str, odom: &spomp_core::Odometry) -> Result<(), RecordError> {
        let c = self.conventions(robot);
        let stamp = odom.stamp.into();
        self.log(&format!("/{robot}/odom"), odom.stamp, &ros::Odometry::from_odometry(&c.frames, odom, stamp))?;
        self.odom_pose.insert(robot.to_string(), odom.pose);
        let tf = ros::TransformStamped::planar(&c.frames.odom, &c.frames.base_link, odom.pose, 0.0, stamp);
        self.log(&c.tf, odom.stamp, &ros::TfMessage { transforms: vec![tf] })
    }

    /// The panorama sensor's mount (`base_link → sensor`, `height_m` above the body) on the
    /// robot's static tf topic, once per robot; each write repeats every mount of that topic.
    pub fn sensor_mount(&mut self, robot: &str, time: Time, height_m: f64) -> Result<(), RecordError> {
        let c = self.conventions(robot);
        let mounts = self.mounts.entry(c.tf_static.clone()).or_default();
        if mounts.iter().any(|m| m.child_frame_id == c.frames.sensor) {
            return Ok(());
        }
        let origin = Pose2::new(0.0, 0.0, 0.0);
        mounts.push(ros::TransformStamped::planar(
            &c.frames.base_link,
            &c.frames.sensor,
            origin,
            height_m,
            time.into(),
        ));
        let msg = ros::TfMessage { transforms: mounts.clone() };
        self.log_message(&c.tf_static, time, &msg, true)
    }

    /// A velocity command (`/R/cmd_vel`, of the robot's command type).
    pub fn command(&mut self, robot: &str, time: Time, cmd: Twist2) -> Result<(), RecordError> {
        let c = self.conventions(robot);
        let topic = format!("/{robot}/cmd_vel");
        match c.cmd_vel_type {
            CmdVelType::Twist => self.log(&topic, time, &ros::Twist::from_twist2(cmd)),
            CmdVelType::TwistStamped => {
                self.log(&topic, time, &ros::TwistStamped::from_twist2(cmd, &c.frames.base_link, time.into()))
            }
        }
    }

    /// A panorama, downsampled (`/R/panorama/depth` in the robot's depth encoding, `32FC1`
    /// metres by default; `/R/panorama/semantic` as mono8 labels).
    pub fn panorama(
        &mut self,
        robot: &str,
        time: Time,
        depth: &DepthPanorama,
        semantic: Option<&SemanticPanorama>,
    ) -> Result<(), RecordError> {
        let k = self.options.panorama_downsample.max(1);
        let c = self.conventions(robot);
        let frame = c.frames.sensor;
        let header = ros::Header::new(time, frame.clone());
        let img = ros::Image::from_depth(header, depth, c.depth_encoding, c.depth_scale_m, k);
        self.log(&format!("/{robot}/panorama/depth"), time, &img)?;
        if let Some(sem) = semantic {
            let sg = sem.geometry;
            let mut data = Vec::with_capacity(sg.rows.div_ceil(k) * sg.cols.div_ceil(k));
            for r in (0..sg.rows).step_by(k) {
                for c in (0..sg.cols).step_by(k) {
                    data.push(sem.class.get(r * sg.cols + c).copied().unwrap_or(spomp_core::UNKNOWN_CLASS));
                }
            }
            let img = ros::Image {
                header: ros::Header::new(time, frame),
                height: sg.rows.div_ceil(k) as u32,
                width: sg.cols.div_ceil(k) as u32,
                encoding: "mono8".into(),
                is_bigendian: 0,
                step: sg.cols.div_ceil(k) as u32,
                data,
            };
            self.log(&format!("/{robot}/panorama/semantic"), time, &img)?;
        }
        Ok(())
    }

    /// The obstacle mask of a terrain analysis (`/R/terrain/obstacles`, mono8 in the panorama's
    /// layout, 255 = obstacle), downsampled like the panoramas but keeping a block an obstacle
    /// if any of its pixels is one, so thin obstacles stay visible.
    pub fn obstacle_panorama(
        &mut self,
        robot: &str,
        time: Time,
        geometry: spomp_core::PanoramaGeometry,
        obstacle: &[bool],
    ) -> Result<(), RecordError> {
        let k = self.options.panorama_downsample.max(1);
        let (rows, cols) = (geometry.rows.div_ceil(k), geometry.cols.div_ceil(k));
        let mut data = vec![0u8; rows * cols];
        for (i, _) in obstacle.iter().enumerate().filter(|(_, o)| **o).take(geometry.len()) {
            let (r, c) = (i / geometry.cols.max(1), i % geometry.cols.max(1));
            if let Some(px) = data.get_mut((r / k) * cols + c / k) {
                *px = 255;
            }
        }
        let img = ros::Image {
            header: ros::Header::new(time, self.conventions(robot).frames.sensor),
            height: rows as u32,
            width: cols as u32,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: cols as u32,
            data,
        };
        self.log(&format!("/{robot}/terrain/obstacles"), time, &img)
    }

    /// A reachability scan (`/R/reachability`, LaserScan in the robot frame: bin i at angle
    /// −i·2π/N, intensity 1 where a known obstacle ends the bin; REP-117 limits).
    pub fn reachability(&mut self, scan: &ReachabilityScan) -> Result<(), RecordError> {
        let base_link = self.conventions(scan.robot.as_str()).frames.base_link;
        let msg = ros::LaserScan::from_reachability(scan, &base_link, scan.stamp.into());
        self.log(&format!("/{}/reachability", scan.robot), scan.stamp, &msg)
    }

    /// A planned path (`/R/path`).
    pub fn path(&mut self, robot: &str, time: Time, points: &[spomp_core::Point2]) -> Result<(), RecordError> {
        self.log(&format!("/{robot}/path"), time, &ros::Path::from_points(points, time.into()))
    }

    /// A problem a node or skill reported (`/R/rosout`, a warning under the robot's logger
    /// name, as its ROS 2 node logs it on `/rosout`).
    pub fn problem(&mut self, robot: &str, time: Time, message: &str) -> Result<(), RecordError> {
        let msg = ros::Log {
            stamp: time.into(),
            level: 30,
            name: self.conventions(robot).logger,
            msg: message.to_string(),
            ..Default::default()
        };
        self.log(&format!("/{robot}/rosout"), time, &msg)
    }

    /// Behaviour-node transitions (`/R/bt`, one Log each: name = node path, msg = `from -> to`).
    pub fn transitions(&mut self, robot: &str, records: &[TransitionRecord]) -> Result<(), RecordError> {
        let topic = format!("/{robot}/bt");
        for r in records {
            let msg = ros::Log {
                stamp: r.time.into(),
                level: 20,
                name: format!("{robot}/{}", r.path),
                msg: format!("{} -> {} (tick {}, node {})", r.from, r.to, r.tick, r.node_id),
                file: String::new(),
                function: String::new(),
                line: 0,
            };
            self.log(&topic, r.time, &msg)?;
        }
        self.active_path(robot, records)
    }

    /// A robot's body in the map frame on its tf topic, so 3D views place its scans, markers
    /// and model: `map → odom` where the robot has odometry (the transform that puts its newest
    /// odometry pose at `pose`; [`Recorder::odometry`] writes `odom → base_link`), otherwise
    /// `map → base_link` — one tree, each frame with one parent.
    pub fn tf(&mut self, robot: &str, time: Time, pose: Pose2, z: f64) -> Result<(), RecordError> {
        let c = self.conventions(robot);
        let msg = match self.odom_pose.get(robot) {
            Some(&odom) => {
                let mut tf = ros::TfMessage::map_to_odom(&c.frames, pose, odom, time.into());
                tf.transforms[0].transform.translation.z = z;
                tf
            }
            None => ros::TfMessage::base_in_map(&c.frames, pose, z, time.into()),
        };
        self.log(&c.tf, time, &msg)
    }

    /// A transform as the robot published it, on `topic`.
    pub fn transform(&mut self, topic: &str, time: Time, msg: &ros::TfMessage) -> Result<(), RecordError> {
        self.log(topic, time, msg)
    }

    /// The aerial map as it grows (`/map`, OccupancyGrid in `map`: class rank as cost 0–100,
    /// −1 unmapped), one message per published version.
    pub fn map(&mut self, time: Time, map: &AerialMap, classes: &ClassTable) -> Result<(), RecordError> {
        let grid = ros::OccupancyGrid::from_aerial_map(map, classes, time.into());
        self.log_message(MAP_TOPIC, time, &grid, true)
    }

    /// The goals, their claims and visits (`/goals`, MarkerArray in `map`: the whole set each
    /// time, replacing the previous one).
    pub fn goals<'a>(
        &mut self,
        time: Time,
        goals: impl IntoIterator<Item = ros::GoalMarkerInput<'a>>,
    ) -> Result<(), RecordError> {
        let markers = ros::MarkerArray::goals(goals, time.into());
        self.log_message(GOALS_TOPIC, time, &markers, true)
    }

    /// Keeps track of which nodes run from a robot's transitions and writes its active path
    /// (`/R/active_path`, String: the path of each running node none of whose children runs,
    /// joined by ` | ` when parallel branches run; empty when nothing runs) when it changes.
    fn active_path(&mut self, robot: &str, records: &[TransitionRecord]) -> Result<(), RecordError> {
        let Some(last) = records.last() else { return Ok(()) };
        let running = self.running.entry(robot.to_string()).or_default();
        for r in records {
            if r.to == Status::Running {
                running.insert(r.path.clone());
            } else {
                running.remove(&r.path);
            }
        }
        let path = active_leaves(running);
        if self.active_paths.get(robot) == Some(&path) {
            return Ok(());
        }
        self.active_paths.insert(robot.to_string(), path.clone());
        self.log_message(&format!("/{robot}/active_path"), last.time, &ros::StringMsg { data: path }, true)
    }

    /// A JSON document on a `std_msgs/String` topic (team-state changes, mission status).
    pub fn json<T: serde::Serialize>(&mut self, topic: &str, time: Time, value: &T) -> Result<(), RecordError> {
        let data = serde_json::to_string(value)?;
        self.log(topic, time, &ros::StringMsg { data })
    }

    /// Writes a metadata record (outside chunks).
    pub(crate) fn write_metadata(&mut self, name: &str, metadata: BTreeMap<String, String>) -> Result<(), RecordError> {
        self.writer.write_metadata(&mcap::records::Metadata { name: name.to_string(), metadata })?;
        Ok(())
    }

    /// Writes an attachment (outside chunks).
    pub(crate) fn write_attachment(&mut self, name: &str, media_type: &str, data: Vec<u8>) -> Result<(), RecordError> {
        self.writer.attach(&mcap::Attachment {
            log_time: 0,
            create_time: 0,
            name: name.to_string(),
            media_type: media_type.to_string(),
            data: std::borrow::Cow::Owned(data),
        })?;
        Ok(())
    }

    /// Writes the summary and index; the file is complete after this.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.writer.finish()?;
        self.flush_mode.store(FLUSH_LAST, Ordering::Relaxed);
        self.writer.into_inner().flush()?;
        Ok(())
    }
}

/// The running paths none of whose descendants runs, in path order, joined by ` | `. A node's
/// path is its parent's followed by `/name`, `[index]` (a control node's child) or `.state`
/// (a state machine's state), so its descendants are the paths that extend it with one of
/// those separators — and all paths extending it sort together right after it.
fn active_leaves(running: &BTreeSet<String>) -> String {
    use std::ops::Bound::{Excluded, Unbounded};
    let mut leaves: Vec<&str> = Vec::new();
    for p in running {
        let has_running_child = running
            .range::<String, _>((Excluded(p), Unbounded))
            .take_while(|q| q.starts_with(p.as_str()))
            .any(|q| matches!(q.as_bytes().get(p.len()), Some(b'/' | b'[' | b'.')));
        if !has_running_child {
            leaves.push(p);
        }
    }
    leaves.join(" | ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(paths: &[&str]) -> BTreeSet<String> {
        paths.iter().map(|p| p.to_string()).collect()
    }

    #[test]
    fn active_leaves_are_the_running_nodes_without_running_children() {
        assert_eq!(active_leaves(&set(&[])), "");
        // Paths as the mission compiler writes them: control children `[i]`, names `/`.
        let running = set(&[
            "visitor/repeat",
            "visitor/repeat/fallback",
            "visitor/repeat/fallback[0]/claim_and_visit/sequence",
            "visitor/repeat/fallback[0]/claim_and_visit/sequence[1]/navigate_to",
        ]);
        assert_eq!(active_leaves(&running), "visitor/repeat/fallback[0]/claim_and_visit/sequence[1]/navigate_to");
        // Parallel branches and a state machine's state; a sibling whose name extends another's
        // is not its child.
        let running = set(&["m/par", "m/par[0]/a", "m/par[0]/a-b", "m/par[1]/sm", "m/par[1]/sm.search/x"]);
        assert_eq!(active_leaves(&running), "m/par[0]/a | m/par[0]/a-b | m/par[1]/sm.search/x");
    }
}
