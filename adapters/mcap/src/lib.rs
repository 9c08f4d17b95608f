//! MCAP recording and reading for spomp.
//!
//! Every message is a ROS 2 type from [`spomp_ros_msgs`], CDR-encoded (little endian, with the
//! 4-byte encapsulation header ROS 2 uses) on a channel whose schema is the type's `ros2msg`
//! definition, so `ros2 bag`, Foxglove and the Python `mcap-ros2-support` decoder read the files
//! as they are.
//!
//! Topics (per robot `R`), each with the type its ROS 2 topic has (`spomp_ros_msgs::ROBOT_TOPICS`):
//! `/R/pose` (PoseStamped, map frame: the simulator's truth), `/R/pose_in` (PoseStamped: a pose
//! input as received), `/R/pose_estimate` (PoseWithCovarianceStamped), `/R/odom` (Odometry),
//! `/R/cmd_vel` (TwistStamped, or Twist where the robot's `ros2.cmd_vel_type` says so),
//! `/R/panorama/depth` (Image in the robot's depth encoding, REP-118's `32FC1` metres by
//! default), `/R/panorama/semantic` (Image mono8
//! class labels), `/R/reachability` (LaserScan, REP-117 limits), `/R/path` (Path), `/R/bt`
//! (Log: node transitions), `/R/active_path` (String: the running nodes without a running
//! child, when that changes), `/team/state` (String: JSON team-state changes), `/mission/status`
//! (String: JSON). What a person watching needs: the whole tf tree — `/tf` (TFMessage: `map →
//! R/odom`, `R/odom → R/base_link`; `map → R/base_link` for a robot without odometry) and
//! `/tf_static` (`R/base_link → R/lidar`), in the robot's frames and tf topics
//! ([`RobotConventions`]) — `/map` (OccupancyGrid: the aerial map as it grows), `/goals`
//! (MarkerArray: goals, claims, visits). A [`MessageTap`] receives every message as written
//! (the live view).
//!
//! For replay (see [`read_replay_log`]): `/R/seam` (`spomp_msgs/msg/SeamCall`: every call made on
//! the robot's seam, in order, lossless) and the run's setup in the metadata record
//! [`RUN_METADATA`] and the attachment [`AREA_ATTACHMENT`].

mod read;
mod record;
pub mod replay;
mod safe;
mod seam;

pub use read::{LogCheck, LogMessage, McapLog, ReadError, check_log, decode_cdr, recover_log};
pub use record::{MessageTap, MessageType, RecordError, Recorder, RecorderOptions, RobotConventions, encode_cdr};
pub use safe::SafeFile;
pub use seam::{
    AREA_ATTACHMENT, AreaRecord, OpenLog, RUN_METADATA, ReplayLog, RunInfo, SeamCallMsg, TeamOut, call_from_msg,
    call_to_msg, open_replay_log, read_replay_log,
};
