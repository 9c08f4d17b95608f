//! ROS 2 message types as plain serde data, with their interface definitions.
//!
//! The MCAP recorder writes them CDR-encoded under `ros2msg` schemas and the ROS 2 adapter
//! publishes the same types, so a recorded run and a live robot look identical to ROS 2 tools
//! and Foxglove. Field order matches the ROS 2 interface definitions exactly: CDR has no field
//! names, only order.

use serde::ser::SerializeTuple;
use serde::{Deserialize, Serialize, Serializer};

use crate::geometry::Pose2;
use crate::time::Time;

/// A ROS 2 message type: its full name and its definition as ROS 2 tools expect in a `ros2msg`
/// schema (the type's own fields, then each dependency after a separator line).
pub trait RosMessage: Serialize {
    /// `package/msg/Type`.
    const TYPE_NAME: &'static str;
    /// The concatenated definition.
    const DEFINITION: &'static str;
}

/// `builtin_interfaces/Time`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RosTime {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

impl From<Time> for RosTime {
    fn from(t: Time) -> Self {
        let sec = t.nanos.div_euclid(1_000_000_000);
        let nanosec = t.nanos.rem_euclid(1_000_000_000) as u32;
        RosTime { sec: sec.clamp(i32::MIN as i64, i32::MAX as i64) as i32, nanosec }
    }
}

/// `std_msgs/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Time stamp.
    pub stamp: RosTime,
    /// Frame.
    pub frame_id: String,
}

impl Header {
    /// A header.
    pub fn new(stamp: Time, frame_id: impl Into<String>) -> Self {
        Header { stamp: stamp.into(), frame_id: frame_id.into() }
    }
}

/// `geometry_msgs/Point` (also used for `Vector3`, same layout).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
}

/// `geometry_msgs/Quaternion`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    /// x.
    pub x: f64,
    /// y.
    pub y: f64,
    /// z.
    pub z: f64,
    /// w.
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion { x: 0.0, y: 0.0, z: 0.0, w: 1.0 }
    }
}

impl Quaternion {
    /// A rotation about +z.
    pub fn from_yaw(yaw: f64) -> Self {
        let (s, c) = (yaw / 2.0).sin_cos();
        Quaternion { x: 0.0, y: 0.0, z: s, w: c }
    }
}

/// `geometry_msgs/Pose`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position.
    pub position: Vector3,
    /// Orientation.
    pub orientation: Quaternion,
}

impl Pose {
    /// A planar pose at height `z`.
    pub fn from_pose2(p: Pose2, z: f64) -> Self {
        Pose { position: Vector3 { x: p.x, y: p.y, z }, orientation: Quaternion::from_yaw(p.yaw) }
    }
}

/// `geometry_msgs/PoseStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseStamped {
    /// Header.
    pub header: Header,
    /// Pose.
    pub pose: Pose,
}

/// `geometry_msgs/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity.
    pub linear: Vector3,
    /// Angular velocity.
    pub angular: Vector3,
}

/// A fixed `float64[36]` covariance (serde derives stop at 32 elements).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Covariance36(pub [f64; 36]);

impl Default for Covariance36 {
    fn default() -> Self {
        Covariance36([0.0; 36])
    }
}

impl Serialize for Covariance36 {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut t = s.serialize_tuple(36)?;
        for v in &self.0 {
            t.serialize_element(v)?;
        }
        t.end()
    }
}

/// `geometry_msgs/PoseWithCovariance`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PoseWithCovariance {
    /// Pose.
    pub pose: Pose,
    /// Row-major 6 × 6 covariance (x, y, z, roll, pitch, yaw).
    pub covariance: Covariance36,
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TwistWithCovariance {
    /// Twist.
    pub twist: Twist,
    /// Row-major 6 × 6 covariance.
    pub covariance: Covariance36,
}

/// `nav_msgs/Odometry`.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Odometry {
    /// Header (frame of the pose).
    pub header: Header,
    /// Frame of the twist.
    pub child_frame_id: String,
    /// Pose.
    pub pose: PoseWithCovariance,
    /// Twist.
    pub twist: TwistWithCovariance,
}

/// `nav_msgs/Path`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Path {
    /// Header.
    pub header: Header,
    /// Poses along the path.
    pub poses: Vec<PoseStamped>,
}

/// `sensor_msgs/Image`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// Header.
    pub header: Header,
    /// Rows.
    pub height: u32,
    /// Columns.
    pub width: u32,
    /// `mono16`, `mono8`, `rgb8`, `32FC1`, …
    pub encoding: String,
    /// 1 if big-endian.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// Pixels.
    pub data: Vec<u8>,
}

/// `sensor_msgs/LaserScan`: carries a reachability scan (ranges = safe distance per bin,
/// intensities = 1 where a known obstacle ends the bin).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LaserScan {
    /// Header.
    pub header: Header,
    /// First angle, radians.
    pub angle_min: f32,
    /// Last angle, radians.
    pub angle_max: f32,
    /// Angle step, radians.
    pub angle_increment: f32,
    /// Time between measurements.
    pub time_increment: f32,
    /// Time between scans.
    pub scan_time: f32,
    /// Minimum range.
    pub range_min: f32,
    /// Maximum range.
    pub range_max: f32,
    /// Ranges.
    pub ranges: Vec<f32>,
    /// Intensities.
    pub intensities: Vec<f32>,
}

/// `rcl_interfaces/Log`: behaviour-node transitions and mission events.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Log {
    /// Time stamp.
    pub stamp: RosTime,
    /// 10 debug, 20 info, 30 warn, 40 error, 50 fatal.
    pub level: u8,
    /// Logger name (robot id / node path).
    pub name: String,
    /// Text.
    pub msg: String,
    /// Source file.
    pub file: String,
    /// Function.
    pub function: String,
    /// Line.
    pub line: u32,
}

/// `std_msgs/String`: JSON payloads (team-state changes, mission status).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StringMsg {
    /// Text.
    pub data: String,
}

// ROS 2 interface definitions as `ros2msg` schemas expect them: the type's own fields, then
// each dependency after a separator line and `MSG: pkg/Type`. The fragments are macros because
// `concat!` only takes literals.
macro_rules! dependency {
    ($name:literal, $def:expr) => {
        concat!(
            "================================================================================\n",
            "MSG: ",
            $name,
            "\n",
            $def
        )
    };
}
macro_rules! time_dep {
    () => {
        dependency!("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n")
    };
}
macro_rules! header_deps {
    () => {
        concat!(dependency!("std_msgs/Header", "builtin_interfaces/Time stamp\nstring frame_id\n"), time_dep!())
    };
}
macro_rules! pose_deps {
    () => {
        concat!(
            dependency!("geometry_msgs/Pose", "Point position\nQuaternion orientation\n"),
            dependency!("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
            dependency!("geometry_msgs/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n")
        )
    };
}
macro_rules! twist_deps {
    () => {
        concat!(
            dependency!("geometry_msgs/Twist", "Vector3 linear\nVector3 angular\n"),
            dependency!("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n")
        )
    };
}

impl RosMessage for PoseStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseStamped";
    const DEFINITION: &'static str = concat!("std_msgs/Header header\nPose pose\n", header_deps!(), pose_deps!());
}

impl RosMessage for Twist {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Twist";
    const DEFINITION: &'static str = concat!(
        "Vector3 linear\nVector3 angular\n",
        dependency!("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n")
    );
}

impl RosMessage for Odometry {
    const TYPE_NAME: &'static str = "nav_msgs/msg/Odometry";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
        header_deps!(),
        dependency!("geometry_msgs/PoseWithCovariance", "Pose pose\nfloat64[36] covariance\n"),
        pose_deps!(),
        dependency!("geometry_msgs/TwistWithCovariance", "Twist twist\nfloat64[36] covariance\n"),
        twist_deps!()
    );
}

impl RosMessage for Path {
    const TYPE_NAME: &'static str = "nav_msgs/msg/Path";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\ngeometry_msgs/PoseStamped[] poses\n",
        header_deps!(),
        dependency!("geometry_msgs/PoseStamped", "std_msgs/Header header\nPose pose\n"),
        pose_deps!()
    );
}

impl RosMessage for Image {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/Image";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\nuint32 step\nuint8[] data\n",
        header_deps!()
    );
}

impl RosMessage for LaserScan {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/LaserScan";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\nfloat32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\nfloat32[] ranges\nfloat32[] intensities\n",
        header_deps!()
    );
}

impl RosMessage for Log {
    const TYPE_NAME: &'static str = "rcl_interfaces/msg/Log";
    const DEFINITION: &'static str = concat!(
        "byte DEBUG=10\nbyte INFO=20\nbyte WARN=30\nbyte ERROR=40\nbyte FATAL=50\nbuiltin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\nstring function\nuint32 line\n",
        time_dep!()
    );
}

impl RosMessage for StringMsg {
    const TYPE_NAME: &'static str = "std_msgs/msg/String";
    const DEFINITION: &'static str = "string data\n";
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_converts_to_sec_and_nanosec() {
        assert_eq!(RosTime::from(Time::from_nanos(1_500_000_000)), RosTime { sec: 1, nanosec: 500_000_000 });
        assert_eq!(RosTime::from(Time::from_nanos(-1)), RosTime { sec: -1, nanosec: 999_999_999 });
    }

    #[test]
    fn definitions_name_every_dependency_once() {
        for def in [PoseStamped::DEFINITION, Odometry::DEFINITION, Path::DEFINITION, Image::DEFINITION] {
            let deps: Vec<&str> = def.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
            let mut sorted = deps.clone();
            sorted.sort();
            sorted.dedup();
            assert_eq!(deps.len(), sorted.len(), "{def}");
        }
        assert!(
            Odometry::DEFINITION
                .contains("MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n")
        );
    }

    #[test]
    fn yaw_quaternion_is_unit() {
        let q = Quaternion::from_yaw(1.2);
        assert!((q.z * q.z + q.w * q.w - 1.0).abs() < 1e-12);
    }
}
