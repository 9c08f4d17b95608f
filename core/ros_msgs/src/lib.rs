//! ROS 2 message types as plain serde data, with their interface definitions.
//!
//! The MCAP recorder writes them CDR-encoded under `ros2msg` schemas and the ROS 2 adapter
//! publishes the same types, so a recorded run and a live robot look identical to ROS 2 tools
//! and Foxglove. Field order matches the ROS 2 interface definitions exactly: CDR has no field
//! names, only order.

use serde::ser::SerializeTuple;
use serde::{Deserialize, Serialize, Serializer};

use spomp_core::geometry::Pose2;
use spomp_core::time::Time;

/// A ROS 2 message type: its full name and its definition as ROS 2 tools expect in a `ros2msg`
/// schema (the type's own fields, then each dependency after a separator line).
pub trait RosMessage: Serialize {
    /// `package/msg/Type`.
    const TYPE_NAME: &'static str;
    /// The concatenated definition.
    const DEFINITION: &'static str;
}

/// One of a robot's ROS 2 topics: what spomp's ROS 2 side publishes or takes, and what its logs
/// and live view carry under the same name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RobotTopic {
    /// The role: the key a mission's `ros2.topics` renames it by.
    pub role: &'static str,
    /// Default name, relative to the robot's namespace (`/<id>` by default); absolute names are
    /// global.
    pub name: &'static str,
    /// Its message type (`package/msg/Type`), on DDS, in logs and in the live view alike.
    pub type_name: &'static str,
}

const fn topic(role: &'static str, name: &'static str, type_name: &'static str) -> RobotTopic {
    RobotTopic { role, name, type_name }
}

/// Every robot topic, in one table: the ROS 2 adapter names and types its publishers and
/// subscriptions from it, the recorder its channels (a test compares what each creates).
/// `cmd_vel` has the default command type (`ros2.cmd_vel_type` may choose `Twist`).
pub const ROBOT_TOPICS: &[RobotTopic] = &[
    topic("odom", "odom", Odometry::TYPE_NAME),
    topic("panorama/depth", "panorama/depth", Image::TYPE_NAME),
    topic("panorama/semantic", "panorama/semantic", Image::TYPE_NAME),
    topic("gps", "gps/fix", NavSatFix::TYPE_NAME),
    topic("pose_in", "pose_in", PoseStamped::TYPE_NAME),
    topic("camera/tiles", "camera/tiles", GridMap::TYPE_NAME),
    topic("cmd_vel", "cmd_vel", TwistStamped::TYPE_NAME),
    topic("setpoint", "setpoint_position/local", PoseStamped::TYPE_NAME),
    topic("setpoint_speed", "setpoint_position/speed", Float64Msg::TYPE_NAME),
    topic("pose_estimate", "pose_estimate", PoseWithCovarianceStamped::TYPE_NAME),
    topic("path", "path", Path::TYPE_NAME),
    topic("goals", "goals", MarkerArray::TYPE_NAME),
    topic("reachability", "reachability", LaserScan::TYPE_NAME),
    topic("diagnostics", "/diagnostics", DiagnosticArray::TYPE_NAME),
    topic("estop", "estop", BoolMsg::TYPE_NAME),
    topic("team/in", "team/in", BytesMsg::TYPE_NAME),
    topic("team/out", "team/out", BytesMsg::TYPE_NAME),
    // Global by default (one tree, frames prefixed); `tf`/`tf_static` without the `/` give each
    // robot a tree of its own (Nav2's multi-robot bringup), with unprefixed frames.
    topic("tf", "/tf", TfMessage::TYPE_NAME),
    topic("tf_static", "/tf_static", TfMessage::TYPE_NAME),
];

/// The name of a robot's ROS 2 node (in the robot's namespace: `/ugv1/spomp`).
pub const ROBOT_NODE_NAME: &str = "spomp";

/// A node's logger name as rcl forms it, and so its `/rosout` entries' `name`: the namespace
/// without its leading `/`, then the node name, joined by `.` (`/ugv1` + `spomp` →
/// `ugv1.spomp`, `/team/ugv1` → `team.ugv1.spomp`, the root → `spomp`).
pub fn rcl_logger_name(namespace: &str, node: &str) -> String {
    let ns = namespace.trim_matches('/').replace('/', ".");
    if ns.is_empty() { node.to_string() } else { format!("{ns}.{node}") }
}

/// The row of `role` in [`ROBOT_TOPICS`].
pub fn robot_topic(role: &str) -> Option<&'static RobotTopic> {
    ROBOT_TOPICS.iter().find(|t| t.role == role)
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

/// `geometry_msgs/PointStamped`: what rviz's "Publish Point" tool sends on `/clicked_point`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PointStamped {
    /// Header: the frame the point is in (rviz's fixed frame).
    pub header: Header,
    /// The point.
    pub point: Vector3,
}

/// `geometry_msgs/Twist`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    /// Linear velocity.
    pub linear: Vector3,
    /// Angular velocity.
    pub angular: Vector3,
}

/// `geometry_msgs/TwistStamped`: a velocity command with its time and body frame (what
/// ros2_control's `diff_drive_controller` takes).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistStamped {
    /// Header (stamp, the robot's body frame).
    pub header: Header,
    /// The command.
    pub twist: Twist,
}

/// The frame ids of one robot's tf tree (REP-105): what its messages name and its transforms
/// join. The ROS 2 adapter resolves them from the mission's `ros2:` settings; logs of robots
/// without them use [`RobotFrames::prefixed`] (the adapter's default for a robot in its own
/// namespace), so a log and a live robot name the same frames.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RobotFrames {
    /// The world-fixed frame.
    pub map: String,
    /// The odometry frame.
    pub odom: String,
    /// The body frame.
    pub base_link: String,
    /// The panorama sensor's frame.
    pub sensor: String,
}

impl RobotFrames {
    /// `map`, `<prefix>odom`, `<prefix>base_link`, `<prefix>lidar`.
    pub fn with_prefix(prefix: &str) -> Self {
        RobotFrames {
            map: "map".into(),
            odom: format!("{prefix}odom"),
            base_link: format!("{prefix}base_link"),
            sensor: format!("{prefix}lidar"),
        }
    }

    /// Frames prefixed with the robot's id: `map`, `<robot>/odom`, `<robot>/base_link`,
    /// `<robot>/lidar`.
    pub fn prefixed(robot: &str) -> Self {
        RobotFrames::with_prefix(&format!("{robot}/"))
    }
}

/// A fixed `float64[36]` covariance (serde derives stop at 32 elements).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Covariance36(pub [f64; 36]);

impl Default for Covariance36 {
    fn default() -> Self {
        Covariance36([0.0; 36])
    }
}

impl<'de> Deserialize<'de> for Covariance36 {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visit;
        impl<'de> serde::de::Visitor<'de> for Visit {
            type Value = Covariance36;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("36 float64 values")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Covariance36, A::Error> {
                let mut out = [0.0; 36];
                for (i, slot) in out.iter_mut().enumerate() {
                    *slot = seq.next_element()?.ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                Ok(Covariance36(out))
            }
        }
        d.deserialize_tuple(36, Visit)
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
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovariance {
    /// Pose.
    pub pose: Pose,
    /// Row-major 6 × 6 covariance (x, y, z, roll, pitch, yaw).
    pub covariance: Covariance36,
}

/// `geometry_msgs/TwistWithCovariance`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TwistWithCovariance {
    /// Twist.
    pub twist: Twist,
    /// Row-major 6 × 6 covariance.
    pub covariance: Covariance36,
}

/// `nav_msgs/Odometry`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
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

/// `geometry_msgs/PoseWithCovarianceStamped`: the robot's pose estimate.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PoseWithCovarianceStamped {
    /// Header (the map frame).
    pub header: Header,
    /// Pose and covariance.
    pub pose: PoseWithCovariance,
}

/// `geometry_msgs/Transform`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Transform {
    /// Translation.
    pub translation: Vector3,
    /// Rotation.
    pub rotation: Quaternion,
}

/// `geometry_msgs/TransformStamped`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TransformStamped {
    /// Header: the parent frame.
    pub header: Header,
    /// The child frame.
    pub child_frame_id: String,
    /// Child in parent.
    pub transform: Transform,
}

/// `tf2_msgs/TFMessage`: what `/tf` carries.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    /// Transforms.
    pub transforms: Vec<TransformStamped>,
}

/// `sensor_msgs/NavSatStatus`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NavSatStatus {
    /// -1 no fix, 0 fix, 1 SBAS fix, 2 GBAS fix.
    pub status: i8,
    /// Bit mask of the satellite systems used.
    pub service: u16,
}

/// `sensor_msgs/NavSatFix`: a GNSS position.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct NavSatFix {
    /// Header.
    pub header: Header,
    /// Fix status.
    pub status: NavSatStatus,
    /// Degrees, positive north.
    pub latitude: f64,
    /// Degrees, positive east.
    pub longitude: f64,
    /// Metres above the WGS 84 ellipsoid.
    pub altitude: f64,
    /// East-north-up covariance, m², row-major.
    pub position_covariance: [f64; 9],
    /// 0 unknown, 1 approximated, 2 diagonal known, 3 known.
    pub position_covariance_type: u8,
}

/// `std_msgs/ColorRGBA`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRgba {
    /// Red, 0–1.
    pub r: f32,
    /// Green, 0–1.
    pub g: f32,
    /// Blue, 0–1.
    pub b: f32,
    /// Opacity, 0–1.
    pub a: f32,
}

/// `builtin_interfaces/Duration`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RosDuration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds within the second.
    pub nanosec: u32,
}

/// `sensor_msgs/CompressedImage` (only as a part of [`Marker`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Header.
    pub header: Header,
    /// `png`, `jpeg`, …
    pub format: String,
    /// Encoded image.
    pub data: Vec<u8>,
}

/// `visualization_msgs/UVCoordinate`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UvCoordinate {
    /// u.
    pub u: f32,
    /// v.
    pub v: f32,
}

/// `visualization_msgs/MeshFile`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshFile {
    /// File name.
    pub filename: String,
    /// File contents.
    pub data: Vec<u8>,
}

/// `visualization_msgs/Marker` (ROS 2 Humble and later layout): goals and claims.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    /// Header.
    pub header: Header,
    /// Namespace.
    pub ns: String,
    /// Id within the namespace.
    pub id: i32,
    /// Shape: 0 arrow, 1 cube, 2 sphere, 3 cylinder, 9 text, …
    pub r#type: i32,
    /// 0 add/modify, 2 delete, 3 delete all.
    pub action: i32,
    /// Pose.
    pub pose: Pose,
    /// Size, metres.
    pub scale: Vector3,
    /// Colour.
    pub color: ColorRgba,
    /// How long it stays (0 = forever).
    pub lifetime: RosDuration,
    /// Re-transform every frame.
    pub frame_locked: bool,
    /// Points (lines, point lists).
    pub points: Vec<Vector3>,
    /// Per-point colours.
    pub colors: Vec<ColorRgba>,
    /// Texture resource.
    pub texture_resource: String,
    /// Texture.
    pub texture: CompressedImage,
    /// Texture coordinates.
    pub uv_coordinates: Vec<UvCoordinate>,
    /// Text (text markers).
    pub text: String,
    /// Mesh resource.
    pub mesh_resource: String,
    /// Mesh file.
    pub mesh_file: MeshFile,
    /// Use the mesh's materials.
    pub mesh_use_embedded_materials: bool,
}

/// `visualization_msgs/MarkerArray`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    /// Markers.
    pub markers: Vec<Marker>,
}

/// `nav_msgs/MapMetaData`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapMetaData {
    /// When the map was loaded.
    pub map_load_time: RosTime,
    /// Edge length of a cell, metres.
    pub resolution: f32,
    /// Columns.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// Map-frame pose of the corner of cell (0, 0).
    pub origin: Pose,
}

/// `nav_msgs/OccupancyGrid`: the aerial map as traversability, for 3D views.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct OccupancyGrid {
    /// Header (the map frame).
    pub header: Header,
    /// Placement and size.
    pub info: MapMetaData,
    /// Row-major from cell (0, 0), rows along +y: 0–100, −1 unknown.
    pub data: Vec<i8>,
}

/// `diagnostic_msgs/KeyValue`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    /// Key.
    pub key: String,
    /// Value.
    pub value: String,
}

/// `diagnostic_msgs/DiagnosticStatus`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// 0 OK, 1 WARN, 2 ERROR, 3 STALE.
    pub level: u8,
    /// What is reported on.
    pub name: String,
    /// Summary.
    pub message: String,
    /// Hardware.
    pub hardware_id: String,
    /// Figures.
    pub values: Vec<KeyValue>,
}

/// `diagnostic_msgs/DiagnosticArray`: the robot's health.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Header.
    pub header: Header,
    /// Statuses.
    pub status: Vec<DiagnosticStatus>,
}

/// `std_msgs/Bool`: the e-stop.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BoolMsg {
    /// Value.
    pub data: bool,
}

/// `std_msgs/Float64`: a UAV's commanded horizontal speed toward its setpoint, m/s (a position
/// setpoint carries none; as Nav2's `speed_limit`, the limit travels beside the goal).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Float64Msg {
    /// Value.
    pub data: f64,
}

/// `rosgraph_msgs/Clock`: simulated time on `/clock`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Clock {
    /// The time.
    pub clock: RosTime,
}

/// `std_msgs/MultiArrayDimension`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayDimension {
    /// Label.
    pub label: String,
    /// Size.
    pub size: u32,
    /// Stride.
    pub stride: u32,
}

/// `std_msgs/MultiArrayLayout`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MultiArrayLayout {
    /// Dimensions.
    pub dim: Vec<MultiArrayDimension>,
    /// Offset of the first element.
    pub data_offset: u32,
}

/// `std_msgs/UInt8MultiArray`: opaque bytes (team-state sync messages between robots).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BytesMsg {
    /// Layout: one flat dimension; between robots its label names the peer robot.
    pub layout: MultiArrayLayout,
    /// Bytes.
    pub data: Vec<u8>,
}

impl BytesMsg {
    /// Team-state bytes `data` as one dimension labelled `peer` (the robot they go to on the
    /// farm's outgoing topic, the robot they came from on a robot's incoming one).
    pub fn labelled(peer: &str, data: Vec<u8>) -> Self {
        let len = data.len() as u32;
        Self {
            layout: MultiArrayLayout {
                dim: vec![MultiArrayDimension { label: peer.to_string(), size: len, stride: len }],
                data_offset: 0,
            },
            data,
        }
    }
}

/// `std_msgs/Float32MultiArray`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Float32MultiArray {
    /// Layout.
    pub layout: MultiArrayLayout,
    /// Values.
    pub data: Vec<f32>,
}

/// `grid_map_msgs/GridMapInfo`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GridMapInfo {
    /// Cell size, metres.
    pub resolution: f64,
    /// Extent along x, metres.
    pub length_x: f64,
    /// Extent along y, metres.
    pub length_y: f64,
    /// The grid's centre in the header's frame.
    pub pose: Pose,
}

/// `grid_map_msgs/GridMap` (ANYbotics grid_map, the ROS 2 layout): named layers over one grid,
/// each a column-major matrix whose index (0, 0) is the cell at the largest x and y. spomp's
/// aerial-map tiles travel as one: layers `class`, `color` (RGB packed into a float's bits, as
/// grid_map packs it) and `elevation` (NaN: unknown).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GridMap {
    /// Stamp and frame.
    pub header: Header,
    /// Size, resolution, placement.
    pub info: GridMapInfo,
    /// Layer names.
    pub layers: Vec<String>,
    /// Layers a cell must have a value in to be valid.
    pub basic_layers: Vec<String>,
    /// One matrix per layer, in the order of `layers`.
    pub data: Vec<Float32MultiArray>,
    /// Circular-buffer start (always 0 here).
    pub outer_start_index: u16,
    /// Circular-buffer start (always 0 here).
    pub inner_start_index: u16,
}

/// Why a grid map cannot be read as an aerial-map tile.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("grid map: {0}")]
pub struct GridMapError(pub String);

impl GridMap {
    /// The layer names of a tile.
    pub const TILE_LAYERS: [&'static str; 3] = ["class", "color", "elevation"];

    /// `tile` of the map over `spec`, in `frame` at `stamp`.
    pub fn from_tile(
        tile: &spomp_core::aerial::MapTile,
        spec: &spomp_core::grid::GridSpec,
        frame: &str,
        stamp: RosTime,
    ) -> Self {
        let (nx, ny) = (tile.width as usize, tile.height as usize);
        let res = spec.resolution_m;
        let centre_x = spec.origin.x + (f64::from(tile.col0) + nx as f64 / 2.0) * res;
        let centre_y = spec.origin.y + (f64::from(tile.row0) + ny as f64 / 2.0) * res;
        let mut layers = [vec![0f32; nx * ny], vec![0f32; nx * ny], vec![0f32; nx * ny]];
        for row in 0..ny {
            for col in 0..nx {
                let k = row * nx + col;
                // grid_map index (i, j): i runs down x, j down y; stored column-major.
                let at = (ny - 1 - row) * nx + (nx - 1 - col);
                let [r, g, b] = tile.rgb.get(k).copied().unwrap_or_default();
                layers[0][at] = f32::from(tile.class.get(k).copied().unwrap_or(spomp_core::classes::UNKNOWN_CLASS));
                layers[1][at] = f32::from_bits(u32::from(r) << 16 | u32::from(g) << 8 | u32::from(b));
                layers[2][at] = tile.elevation.get(k).copied().unwrap_or(f32::NAN);
            }
        }
        let layout = MultiArrayLayout {
            dim: vec![
                MultiArrayDimension { label: "column_index".into(), size: ny as u32, stride: (nx * ny) as u32 },
                MultiArrayDimension { label: "row_index".into(), size: nx as u32, stride: nx as u32 },
            ],
            data_offset: 0,
        };
        GridMap {
            header: Header { stamp, frame_id: frame.to_string() },
            info: GridMapInfo {
                resolution: res,
                length_x: nx as f64 * res,
                length_y: ny as f64 * res,
                pose: Pose::from_pose2(spomp_core::geometry::Pose2::new(centre_x, centre_y, 0.0), 0.0),
            },
            layers: Self::TILE_LAYERS.iter().map(|l| (*l).to_string()).collect(),
            basic_layers: vec!["class".into()],
            data: layers.into_iter().map(|data| Float32MultiArray { layout: layout.clone(), data }).collect(),
            outer_start_index: 0,
            inner_start_index: 0,
        }
    }

    /// The tile of the map over `spec` this grid map carries: it must be aligned with the
    /// map's cells, at its resolution, unrotated, inside it, with the three tile layers.
    pub fn to_tile(&self, spec: &spomp_core::grid::GridSpec) -> Result<spomp_core::aerial::MapTile, GridMapError> {
        let bad = |m: String| GridMapError(m);
        let res = spec.resolution_m;
        let info = &self.info;
        if !(info.resolution.is_finite() && (info.resolution - res).abs() <= res * 1e-6) {
            return Err(bad(format!("resolution {} m, the map's is {res} m", info.resolution)));
        }
        let q = &info.pose.orientation;
        if !(q.x.abs() < 1e-6 && q.y.abs() < 1e-6 && q.z.abs() < 1e-6) {
            return Err(bad("a rotated grid cannot be applied to the aerial map".into()));
        }
        if self.outer_start_index != 0 || self.inner_start_index != 0 {
            return Err(bad("circular-buffer start indices are not supported".into()));
        }
        let cells = |len: f64| -> Result<usize, GridMapError> {
            let n = len / res;
            if n.is_finite() && n >= 1.0 && (n - n.round()).abs() < 1e-6 && n <= 1e6 {
                Ok(n.round() as usize)
            } else {
                Err(bad(format!("length {len} m is not a whole number of {res} m cells")))
            }
        };
        let (nx, ny) = (cells(info.length_x)?, cells(info.length_y)?);
        let p = &info.pose.position;
        let first = |centre: f64, origin: f64, n: usize| -> Result<u32, GridMapError> {
            let c = (centre - origin) / res - n as f64 / 2.0;
            if c.is_finite() && (c - c.round()).abs() < 1e-3 && c.round() >= 0.0 {
                Ok(c.round() as u32)
            } else {
                Err(bad(format!("not aligned with the map's cells (first cell at {c:.3})")))
            }
        };
        let (col0, row0) = (first(p.x, spec.origin.x, nx)?, first(p.y, spec.origin.y, ny)?);
        if u64::from(col0) + nx as u64 > u64::from(spec.width) || u64::from(row0) + ny as u64 > u64::from(spec.height) {
            return Err(bad("the grid reaches outside the map".into()));
        }
        let layer = |name: &str| -> Result<&[f32], GridMapError> {
            let k = self.layers.iter().position(|l| l == name).ok_or_else(|| bad(format!("no `{name}` layer")))?;
            let data = self.data.get(k).map(|d| d.data.as_slice()).unwrap_or_default();
            if data.len() == nx * ny {
                Ok(data)
            } else {
                Err(bad(format!("layer `{name}` has {} values, not {}", data.len(), nx * ny)))
            }
        };
        let (class, color, elevation) = (layer("class")?, layer("color")?, layer("elevation")?);
        let n = nx * ny;
        let mut tile = spomp_core::aerial::MapTile {
            col0,
            row0,
            width: nx as u32,
            height: ny as u32,
            class: Vec::with_capacity(n),
            rgb: Vec::with_capacity(n),
            elevation: Vec::with_capacity(n),
        };
        for row in 0..ny {
            for col in 0..nx {
                let at = (ny - 1 - row) * nx + (nx - 1 - col);
                let c = class[at];
                let class = if c.is_finite() && (0.0..=255.0).contains(&c) {
                    c as u8
                } else {
                    spomp_core::classes::UNKNOWN_CLASS
                };
                let bits = color[at].to_bits();
                tile.class.push(class);
                tile.rgb.push([(bits >> 16) as u8, (bits >> 8) as u8, bits as u8]);
                tile.elevation.push(elevation[at]);
            }
        }
        Ok(tile)
    }
}

/// Messages of spomp's own data, built once here for every adapter that speaks ROS 2 (the MCAP
/// recorder and the ROS 2 adapter), so a log and a live robot carry the same bytes.
impl Odometry {
    /// A robot's odometry: pose in `frames.odom`, twist in `frames.base_link`; `pose_sigma`
    /// (x, y, yaw) and `twist_sigma` (v, ω) are the 1σ uncertainties placed on the covariance
    /// diagonals (z, roll, pitch: a large variance — planar odometry does not measure them).
    pub fn from_odometry(frames: &RobotFrames, odom: &spomp_core::motion::Odometry, stamp: RosTime) -> Self {
        let mut msg = Odometry {
            header: Header { stamp, frame_id: frames.odom.clone() },
            child_frame_id: frames.base_link.clone(),
            ..Default::default()
        };
        msg.pose.pose = Pose::from_pose2(odom.pose, 0.0);
        msg.twist.twist.linear.x = odom.twist.v;
        msg.twist.twist.angular.z = odom.twist.omega;
        msg
    }

    /// Sets the covariance diagonals from 1σ uncertainties: pose (x, y, yaw) and twist
    /// (linear x, angular z); the axes planar odometry does not measure get [`UNMEASURED_VARIANCE`].
    pub fn with_sigmas(self, pose: [f64; 3], twist: [f64; 2]) -> Self {
        let mut planar = [0.0; 9];
        for (k, s) in pose.iter().enumerate() {
            planar[k * 3 + k] = s * s;
        }
        self.with_covariance(&spomp_core::motion::OdometryCovariance {
            pose: planar,
            twist: [twist[0] * twist[0], twist[1] * twist[1]],
        })
    }

    /// Sets both covariances from a planar one: the pose's (x, y, yaw) block, correlations
    /// included, into rows and columns x, y, yaw (0, 1, 5) of the 6 × 6 matrix, the twist's
    /// variances into linear x and angular z; the axes planar odometry does not measure (z,
    /// roll, pitch; lateral and vertical velocity, roll and pitch rates) get
    /// [`UNMEASURED_VARIANCE`].
    pub fn with_covariance(mut self, cov: &spomp_core::motion::OdometryCovariance) -> Self {
        const AXES: [usize; 3] = [0, 1, 5];
        let mut p = [0.0; 36];
        let mut t = [0.0; 36];
        for k in 0..6 {
            p[k * 6 + k] = UNMEASURED_VARIANCE;
            t[k * 6 + k] = UNMEASURED_VARIANCE;
        }
        for (i, &a) in AXES.iter().enumerate() {
            for (j, &b) in AXES.iter().enumerate() {
                p[a * 6 + b] = cov.pose[i * 3 + j];
            }
        }
        t[0] = cov.twist[0];
        t[5 * 6 + 5] = cov.twist[1];
        self.pose.covariance = Covariance36(p);
        self.twist.covariance = Covariance36(t);
        self
    }
}

/// Variance of an axis a message does not measure (z, roll, pitch of planar motion), as
/// robot_localization and Nav2 read it: large, not zero (zero claims certainty).
pub const UNMEASURED_VARIANCE: f64 = 1e6;

impl Twist {
    /// A planar velocity command (`linear.x`, `angular.z`).
    pub fn from_twist2(cmd: spomp_core::motion::Twist2) -> Self {
        let mut msg = Twist::default();
        msg.linear.x = cmd.v;
        msg.angular.z = cmd.omega;
        msg
    }
}

impl TwistStamped {
    /// A planar velocity command at `stamp` in the body frame `base_link`.
    pub fn from_twist2(cmd: spomp_core::motion::Twist2, base_link: &str, stamp: RosTime) -> Self {
        TwistStamped { header: Header { stamp, frame_id: base_link.into() }, twist: Twist::from_twist2(cmd) }
    }
}

impl LaserScan {
    /// A reachability scan in the body frame `base_link`: bin i at angle −i·2π/N, range = safe
    /// distance, intensity 1 where a known obstacle ends the bin. Per REP-117 `range_max` is
    /// fixed ([`spomp_core::scan::REACHABILITY_RANGE_MAX_M`], above any reach) and `range_min` is the
    /// floor, 0, so every bin is a valid reading (laser_geometry and rviz keep
    /// `range_min ≤ r < range_max`); a range that would reach `range_max` is held just below it.
    pub fn from_reachability(scan: &spomp_core::scan::ReachabilityScan, base_link: &str, stamp: RosTime) -> Self {
        let n = scan.bins().max(1);
        let step = -(std::f64::consts::TAU / n as f64) as f32;
        let max = spomp_core::scan::REACHABILITY_RANGE_MAX_M;
        let below_max = max * (1.0 - f32::EPSILON);
        LaserScan {
            header: Header { stamp, frame_id: base_link.into() },
            angle_min: 0.0,
            angle_max: step * (n as f32 - 1.0),
            angle_increment: step,
            time_increment: 0.0,
            scan_time: 0.0,
            range_min: 0.0,
            range_max: max,
            ranges: scan.range_m.iter().map(|&r| if r.is_finite() { r.clamp(0.0, below_max) } else { 0.0 }).collect(),
            intensities: scan.obstacle.iter().map(|&o| if o { 1.0 } else { 0.0 }).collect(),
        }
    }
}

/// How a depth panorama travels as a `sensor_msgs/Image` (`ros2.depth_encoding`).
///
/// The default is REP-118's canonical form, `32FC1` in metres: the one form every depth
/// consumer must read (depth_image_proc, rviz's DepthCloud, Foxglove's colour maps), with no
/// range ceiling — a `16UC1` millimetre image stops at 65.535 m, short of a lidar panorama's
/// reach. `16UC1` (REP-118's raw OpenNI form, millimetres) and `mono16` (spomp's earlier form,
/// counts of 1/512 m up to 128 m, half the bytes of `32FC1`) stay available for drivers that
/// produce them. Each pixel is the range along its ray (a panorama has no optical axis).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
pub enum DepthEncoding {
    /// `32FC1`: metres as 32-bit floats; no return is +∞ (REP-117's "nothing within range").
    #[default]
    #[serde(rename = "32FC1")]
    Float32Metres,
    /// `16UC1`: unsigned counts, millimetres unless `depth_scale_m` says otherwise; 0 = no
    /// return.
    #[serde(rename = "16UC1")]
    Uint16,
    /// `mono16`: unsigned counts of `depth_scale_m`, 1/512 m unless set; 0 = no return.
    #[serde(rename = "mono16")]
    Mono16,
}

impl DepthEncoding {
    /// Every encoding, the default first.
    pub const ALL: [DepthEncoding; 3] = [DepthEncoding::Float32Metres, DepthEncoding::Uint16, DepthEncoding::Mono16];

    /// The `sensor_msgs/Image` encoding string.
    pub fn name(self) -> &'static str {
        match self {
            DepthEncoding::Float32Metres => "32FC1",
            DepthEncoding::Uint16 => "16UC1",
            DepthEncoding::Mono16 => "mono16",
        }
    }

    /// The encoding an image's `encoding` field names, if it is a depth encoding.
    pub fn from_name(name: &str) -> Option<Self> {
        DepthEncoding::ALL.into_iter().find(|e| e.name() == name)
    }

    /// Metres per count when no scale is configured: 1 mm for `16UC1` (REP-118), 1/512 m for
    /// `mono16`; `None` for `32FC1` (metres as they are).
    pub fn default_scale_m(self) -> Option<f64> {
        match self {
            DepthEncoding::Float32Metres => None,
            DepthEncoding::Uint16 => Some(0.001),
            DepthEncoding::Mono16 => Some(spomp_core::panorama::DEFAULT_RANGE_SCALE_M),
        }
    }

    /// Bytes of one pixel.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            DepthEncoding::Float32Metres => 4,
            DepthEncoding::Uint16 | DepthEncoding::Mono16 => 2,
        }
    }
}

impl Image {
    /// A depth panorama as an image in `encoding` (`scale_m`: metres per count of the integer
    /// encodings, `None` for the encoding's default), keeping every `every`-th row and column
    /// (1 = full size). Little-endian; no return (0, negative, not finite) becomes +∞ in
    /// `32FC1` and count 0 otherwise.
    pub fn from_depth(
        header: Header,
        depth: &spomp_core::panorama::DepthPanorama,
        encoding: DepthEncoding,
        scale_m: Option<f64>,
        every: usize,
    ) -> Self {
        let k = every.max(1);
        let g = depth.geometry;
        let (rows, cols) = (g.rows.div_ceil(k), g.cols.div_ceil(k));
        let scale = scale_m.or(encoding.default_scale_m()).unwrap_or(1.0);
        let mut data = Vec::with_capacity(rows * cols * encoding.bytes_per_pixel());
        for r in (0..g.rows).step_by(k) {
            for c in (0..g.cols).step_by(k) {
                let m = depth.range_m.get(r * g.cols + c).copied().unwrap_or(0.0);
                match encoding {
                    DepthEncoding::Float32Metres => {
                        let v = if m.is_finite() && m > 0.0 { m } else { f32::INFINITY };
                        data.extend_from_slice(&v.to_le_bytes());
                    }
                    DepthEncoding::Uint16 | DepthEncoding::Mono16 => {
                        data.extend_from_slice(&spomp_core::panorama::range_to_count(m, scale).to_le_bytes());
                    }
                }
            }
        }
        Image {
            header,
            height: rows as u32,
            width: cols as u32,
            encoding: encoding.name().into(),
            is_bigendian: 0,
            step: (cols * encoding.bytes_per_pixel()) as u32,
            data,
        }
    }
}

impl Path {
    /// A planned path in `map`.
    pub fn from_points(points: &[spomp_core::geometry::Point2], stamp: RosTime) -> Self {
        let header = Header { stamp, frame_id: "map".into() };
        let poses = points
            .iter()
            .map(|p| PoseStamped { header: header.clone(), pose: Pose::from_pose2(Pose2::new(p.x, p.y, 0.0), 0.0) })
            .collect();
        Path { header, poses }
    }
}

impl OccupancyGrid {
    /// The aerial map's traversability in `map`: each known cell's class rank scaled to 0–100
    /// (rank 0 = 0, impassable = 100, [`spomp_core::classes::IMPASSABLE_RANK`]), −1 where unmapped.
    pub fn from_aerial_map(
        map: &spomp_core::aerial::AerialMap,
        classes: &spomp_core::classes::ClassTable,
        stamp: RosTime,
    ) -> Self {
        let ranks = classes.rank_lut();
        let scale = 100 / i16::from(spomp_core::classes::IMPASSABLE_RANK.max(1));
        let data = map
            .class
            .iter()
            .map(|&c| {
                if c == spomp_core::classes::UNKNOWN_CLASS {
                    -1
                } else {
                    (i16::from(ranks[usize::from(c)]) * scale).min(100) as i8
                }
            })
            .collect();
        let spec = map.spec;
        OccupancyGrid {
            header: Header { stamp, frame_id: "map".into() },
            info: MapMetaData {
                map_load_time: stamp,
                resolution: spec.resolution_m as f32,
                width: spec.width,
                height: spec.height,
                origin: Pose::from_pose2(Pose2::new(spec.origin.x, spec.origin.y, 0.0), 0.0),
            },
            data,
        }
    }
}

/// What a goal marker shows of one goal; the caller's goal type lends it (the team state's
/// goal views, the simulator's goal events), so the markers are built in one place.
#[derive(Clone, Copy)]
pub struct GoalMarkerInput<'a> {
    /// The goal's id, as the label shows it.
    pub id: &'a dyn std::fmt::Display,
    /// Map-frame position.
    pub position: spomp_core::geometry::Point2,
    /// Who claims it.
    pub claimed_by: Option<&'a str>,
    /// Who visited it.
    pub visited_by: Option<&'a str>,
    /// The operator cancelled it (issue 37): drawn dark red, labelled `cancelled`.
    pub cancelled: bool,
    /// Its operator priority (0 ordinary): labelled when not 0.
    pub priority: i32,
}

impl MarkerArray {
    /// Goals and claims in `map`: one cylinder per goal (grey open, orange claimed, green
    /// visited, dark red cancelled by the operator) and a text label with its id, holder and
    /// operator priority. The first marker deletes all earlier
    /// ones, so goals that merged disappear.
    pub fn goals<'a>(goals: impl IntoIterator<Item = GoalMarkerInput<'a>>, stamp: RosTime) -> Self {
        let header = Header { stamp, frame_id: "map".into() };
        let mut markers = vec![Marker { header: header.clone(), ns: "goals".into(), action: 3, ..Default::default() }];
        for (k, g) in goals.into_iter().enumerate() {
            let color = match (g.visited_by, g.claimed_by) {
                _ if g.cancelled => ColorRgba { r: 0.5, g: 0.05, b: 0.05, a: 0.6 },
                (Some(_), _) => ColorRgba { r: 0.2, g: 0.8, b: 0.2, a: 0.9 },
                (None, Some(_)) => ColorRgba { r: 1.0, g: 0.6, b: 0.0, a: 0.9 },
                (None, None) => ColorRgba { r: 0.6, g: 0.6, b: 0.6, a: 0.9 },
            };
            let pose = Pose::from_pose2(Pose2::new(g.position.x, g.position.y, 0.0), 1.0);
            markers.push(Marker {
                header: header.clone(),
                ns: "goals".into(),
                id: k as i32,
                r#type: 3,
                pose,
                scale: Vector3 { x: 3.0, y: 3.0, z: 2.0 },
                color,
                ..Default::default()
            });
            let mut holder = g
                .visited_by
                .map(|r| format!(" visited by {r}"))
                .or_else(|| g.claimed_by.map(|r| format!(" claimed by {r}")));
            if g.cancelled {
                holder = Some(format!("{} cancelled", holder.unwrap_or_default()));
            }
            if g.priority != 0 {
                holder = Some(format!("{} priority {}", holder.unwrap_or_default(), g.priority));
            }
            let mut text_pose = pose;
            text_pose.position.z = 3.5;
            markers.push(Marker {
                header: header.clone(),
                ns: "goal_labels".into(),
                id: k as i32,
                r#type: 9,
                pose: text_pose,
                scale: Vector3 { x: 0.0, y: 0.0, z: 1.5 },
                color: ColorRgba { r: 1.0, g: 1.0, b: 1.0, a: 1.0 },
                text: format!("{}{}", g.id, holder.unwrap_or_default()),
                ..Default::default()
            });
        }
        MarkerArray { markers }
    }
}

impl TfMessage {
    /// `frames.base_link` in `frames.map` at `pose`, `z` metres up.
    pub fn base_in_map(frames: &RobotFrames, pose: Pose2, z: f64, stamp: RosTime) -> Self {
        TfMessage { transforms: vec![TransformStamped::planar(&frames.map, &frames.base_link, pose, z, stamp)] }
    }
}

impl TfMessage {
    /// The `map → odom` transform that puts the odometry pose `odom` at the map pose
    /// `estimate`: T(map←odom) = T(map←base) · T(odom←base)⁻¹.
    pub fn map_to_odom(frames: &RobotFrames, estimate: Pose2, odom: Pose2, stamp: RosTime) -> Self {
        let yaw = estimate.yaw - odom.yaw;
        let (s, c) = yaw.sin_cos();
        let x = estimate.x - (c * odom.x - s * odom.y);
        let y = estimate.y - (s * odom.x + c * odom.y);
        TfMessage {
            transforms: vec![TransformStamped::planar(&frames.map, &frames.odom, Pose2::new(x, y, yaw), 0.0, stamp)],
        }
    }
}

impl PoseWithCovarianceStamped {
    /// A pose estimate in `map`: x, y, yaw variances placed in the 6 × 6 matrix; z, roll,
    /// pitch unknown ([`UNMEASURED_VARIANCE`]).
    pub fn from_estimate(est: &spomp_core::motion::PoseEstimate, map: &str, stamp: RosTime) -> Self {
        let mut cov = [0.0; 36];
        let axes = [0usize, 1, 5];
        for (i, &a) in axes.iter().enumerate() {
            for (j, &b) in axes.iter().enumerate() {
                cov[a * 6 + b] = est.covariance[i * 3 + j];
            }
        }
        for k in [2usize, 3, 4] {
            cov[k * 6 + k] = UNMEASURED_VARIANCE;
        }
        PoseWithCovarianceStamped {
            header: Header { stamp, frame_id: map.into() },
            pose: PoseWithCovariance { pose: Pose::from_pose2(est.pose, 0.0), covariance: Covariance36(cov) },
        }
    }
}

impl TransformStamped {
    /// `child` in `parent` at the planar pose `pose`, `z` metres up.
    pub fn planar(parent: &str, child: &str, pose: Pose2, z: f64, stamp: RosTime) -> Self {
        TransformStamped {
            header: Header { stamp, frame_id: parent.into() },
            child_frame_id: child.into(),
            transform: Transform {
                translation: Vector3 { x: pose.x, y: pose.y, z },
                rotation: Quaternion::from_yaw(pose.yaw),
            },
        }
    }
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
macro_rules! multi_array_layout_deps {
    () => {
        concat!(
            dependency!("std_msgs/MultiArrayLayout", "MultiArrayDimension[] dim\nuint32 data_offset\n"),
            dependency!("std_msgs/MultiArrayDimension", "string label\nuint32 size\nuint32 stride\n")
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

impl RosMessage for PointStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PointStamped";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nPoint point\n",
        header_deps!(),
        dependency!("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n")
    );
}

impl RosMessage for Twist {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/Twist";
    const DEFINITION: &'static str = concat!(
        "Vector3 linear\nVector3 angular\n",
        dependency!("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n")
    );
}

impl RosMessage for TwistStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/TwistStamped";
    const DEFINITION: &'static str = concat!("std_msgs/Header header\nTwist twist\n", header_deps!(), twist_deps!());
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

impl RosMessage for PoseWithCovarianceStamped {
    const TYPE_NAME: &'static str = "geometry_msgs/msg/PoseWithCovarianceStamped";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nPoseWithCovariance pose\n",
        header_deps!(),
        dependency!("geometry_msgs/PoseWithCovariance", "Pose pose\nfloat64[36] covariance\n"),
        pose_deps!()
    );
}

impl RosMessage for TfMessage {
    const TYPE_NAME: &'static str = "tf2_msgs/msg/TFMessage";
    const DEFINITION: &'static str = concat!(
        "geometry_msgs/TransformStamped[] transforms\n",
        dependency!(
            "geometry_msgs/TransformStamped",
            "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"
        ),
        header_deps!(),
        dependency!("geometry_msgs/Transform", "Vector3 translation\nQuaternion rotation\n"),
        dependency!("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
        dependency!("geometry_msgs/Quaternion", "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n")
    );
}

impl RosMessage for NavSatFix {
    const TYPE_NAME: &'static str = "sensor_msgs/msg/NavSatFix";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nNavSatStatus status\nfloat64 latitude\nfloat64 longitude\nfloat64 altitude\nfloat64[9] position_covariance\nuint8 COVARIANCE_TYPE_UNKNOWN=0\nuint8 COVARIANCE_TYPE_APPROXIMATED=1\nuint8 COVARIANCE_TYPE_DIAGONAL_KNOWN=2\nuint8 COVARIANCE_TYPE_KNOWN=3\nuint8 position_covariance_type\n",
        header_deps!(),
        dependency!(
            "sensor_msgs/NavSatStatus",
            "int8 STATUS_NO_FIX=-1\nint8 STATUS_FIX=0\nint8 STATUS_SBAS_FIX=1\nint8 STATUS_GBAS_FIX=2\nint8 status\nuint16 SERVICE_GPS=1\nuint16 SERVICE_GLONASS=2\nuint16 SERVICE_COMPASS=4\nuint16 SERVICE_GALILEO=8\nuint16 service\n"
        )
    );
}

impl RosMessage for MarkerArray {
    const TYPE_NAME: &'static str = "visualization_msgs/msg/MarkerArray";
    const DEFINITION: &'static str = concat!(
        "Marker[] markers\n",
        dependency!(
            "visualization_msgs/Marker",
            "std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\ngeometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\nbuiltin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\nstring texture_resource\nsensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\nstring text\nstring mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials\n"
        ),
        header_deps!(),
        pose_deps!(),
        dependency!("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
        dependency!("std_msgs/ColorRGBA", "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n"),
        dependency!("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n"),
        dependency!("sensor_msgs/CompressedImage", "std_msgs/Header header\nstring format\nuint8[] data\n"),
        dependency!("visualization_msgs/UVCoordinate", "float32 u\nfloat32 v\n"),
        dependency!("visualization_msgs/MeshFile", "string filename\nuint8[] data\n")
    );
}

impl RosMessage for OccupancyGrid {
    const TYPE_NAME: &'static str = "nav_msgs/msg/OccupancyGrid";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
        header_deps!(),
        dependency!(
            "nav_msgs/MapMetaData",
            "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\ngeometry_msgs/Pose origin\n"
        ),
        pose_deps!()
    );
}

impl RosMessage for DiagnosticArray {
    const TYPE_NAME: &'static str = "diagnostic_msgs/msg/DiagnosticArray";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\nDiagnosticStatus[] status\n",
        header_deps!(),
        dependency!(
            "diagnostic_msgs/DiagnosticStatus",
            "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n"
        ),
        dependency!("diagnostic_msgs/KeyValue", "string key\nstring value\n")
    );
}

impl RosMessage for BoolMsg {
    const TYPE_NAME: &'static str = "std_msgs/msg/Bool";
    const DEFINITION: &'static str = "bool data\n";
}

impl RosMessage for Float64Msg {
    const TYPE_NAME: &'static str = "std_msgs/msg/Float64";
    const DEFINITION: &'static str = "float64 data\n";
}

impl RosMessage for Clock {
    const TYPE_NAME: &'static str = "rosgraph_msgs/msg/Clock";
    const DEFINITION: &'static str = concat!("builtin_interfaces/Time clock\n", time_dep!());
}

impl RosMessage for GridMap {
    const TYPE_NAME: &'static str = "grid_map_msgs/msg/GridMap";
    const DEFINITION: &'static str = concat!(
        "std_msgs/Header header\ngrid_map_msgs/GridMapInfo info\nstring[] layers\nstring[] basic_layers\n",
        "std_msgs/Float32MultiArray[] data\nuint16 outer_start_index\nuint16 inner_start_index\n",
        header_deps!(),
        dependency!(
            "grid_map_msgs/GridMapInfo",
            "float64 resolution\nfloat64 length_x\nfloat64 length_y\ngeometry_msgs/Pose pose\n"
        ),
        pose_deps!(),
        dependency!("std_msgs/Float32MultiArray", "MultiArrayLayout layout\nfloat32[] data\n"),
        multi_array_layout_deps!()
    );
}

impl RosMessage for BytesMsg {
    const TYPE_NAME: &'static str = "std_msgs/msg/UInt8MultiArray";
    const DEFINITION: &'static str = concat!("MultiArrayLayout layout\nuint8[] data\n", multi_array_layout_deps!());
}

// A robot's `ros2.cmd_vel_type`: what the ROS 2 adapter publishes and the MCAP recorder logs.
/// Type of a robot's velocity command on `cmd_vel`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum CmdVelType {
    /// `geometry_msgs/Twist`.
    Twist,
    /// `geometry_msgs/TwistStamped` (stamp and `base_link` frame in the header).
    #[default]
    TwistStamped,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn planar_covariance_lands_on_x_y_yaw_with_its_correlations() {
        let cov = spomp_core::motion::OdometryCovariance {
            pose: [0.04, 0.01, 0.002, 0.01, 0.09, -0.003, 0.002, -0.003, 0.0004],
            twist: [0.0001, 0.0009],
        };
        let m = Odometry::default().with_covariance(&cov);
        let p = m.pose.covariance.0;
        let at = |r: usize, c: usize| p[r * 6 + c];
        assert_eq!([at(0, 0), at(0, 1), at(0, 5)], [0.04, 0.01, 0.002]);
        assert_eq!([at(1, 0), at(1, 1), at(1, 5)], [0.01, 0.09, -0.003]);
        assert_eq!([at(5, 0), at(5, 1), at(5, 5)], [0.002, -0.003, 0.0004]);
        for k in [2, 3, 4] {
            assert_eq!(at(k, k), UNMEASURED_VARIANCE, "z, roll, pitch are not measured");
            assert_eq!(at(k, 0), 0.0);
        }
        let t = m.twist.covariance.0;
        assert_eq!((t[0], t[35]), (0.0001, 0.0009));
        assert_eq!(t[7], UNMEASURED_VARIANCE, "lateral velocity is not measured");
        // with_sigmas is the diagonal case.
        let d = Odometry::default().with_sigmas([0.2, 0.3, 0.02], [0.01, 0.03]).pose.covariance.0;
        assert!((d[0] - 0.04).abs() < 1e-15 && (d[7] - 0.09).abs() < 1e-15 && (d[35] - 0.0004).abs() < 1e-15);
        assert_eq!(d[1], 0.0);
    }

    #[test]
    fn logger_names_are_dotted_as_rcl_makes_them() {
        assert_eq!(rcl_logger_name("/ugv1", ROBOT_NODE_NAME), "ugv1.spomp");
        assert_eq!(rcl_logger_name("/team/ugv1/", "spomp"), "team.ugv1.spomp");
        assert_eq!(rcl_logger_name("/", "spomp"), "spomp");
        assert_eq!(rcl_logger_name("", "spomp"), "spomp");
    }

    #[test]
    fn depth_encodings_name_themselves_as_images_do() {
        for e in DepthEncoding::ALL {
            assert_eq!(DepthEncoding::from_name(e.name()), Some(e));
        }
        assert_eq!(DepthEncoding::default().name(), "32FC1", "REP-118's canonical form by default");
        assert_eq!(DepthEncoding::from_name("mono8"), None);
    }

    #[test]
    fn time_converts_to_sec_and_nanosec() {
        assert_eq!(RosTime::from(Time::from_nanos(1_500_000_000)), RosTime { sec: 1, nanosec: 500_000_000 });
        assert_eq!(RosTime::from(Time::from_nanos(-1)), RosTime { sec: -1, nanosec: 999_999_999 });
    }

    #[test]
    fn definitions_name_every_dependency_once() {
        for def in [
            GridMap::DEFINITION,
            PoseStamped::DEFINITION,
            Odometry::DEFINITION,
            TwistStamped::DEFINITION,
            Path::DEFINITION,
            Image::DEFINITION,
            PoseWithCovarianceStamped::DEFINITION,
            TfMessage::DEFINITION,
            NavSatFix::DEFINITION,
            MarkerArray::DEFINITION,
            OccupancyGrid::DEFINITION,
            DiagnosticArray::DEFINITION,
            Clock::DEFINITION,
            BytesMsg::DEFINITION,
        ] {
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
    fn the_aerial_map_becomes_a_traversability_grid_with_unknown_cells_minus_one() {
        use spomp_core::{AerialMap, ClassTable, GridSpec, Point2, UNKNOWN_CLASS};
        let classes = ClassTable::default_table();
        let rank_of = |name: &str| classes.by_name(name).map(|c| (c.index, c.rank)).unwrap_or_default();
        let (road, road_rank) = rank_of("road");
        let (building, building_rank) = rank_of("building");
        let (grass, grass_rank) = rank_of("grass_sidewalk");
        assert_eq!((road_rank, building_rank, grass_rank), (0, 5, 2), "the paper's ranks");
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(-10.0, 5.0), 0.5, 2, 2));
        map.class = vec![road, building, UNKNOWN_CLASS, grass];
        let grid = OccupancyGrid::from_aerial_map(&map, &classes, RosTime { sec: 3, nanosec: 0 });
        assert_eq!(grid.data, vec![0, 100, -1, 40]);
        assert_eq!((grid.info.width, grid.info.height, grid.info.resolution), (2, 2, 0.5));
        assert_eq!((grid.info.origin.position.x, grid.info.origin.position.y), (-10.0, 5.0));
        assert_eq!(grid.header.frame_id, "map");
        assert_eq!(grid.info.map_load_time.sec, 3);
    }

    #[test]
    fn goal_markers_clear_the_old_set_then_show_each_goal_coloured_by_its_state() {
        let (a, b, c) = ("uav1-1".to_string(), "uav1-2".to_string(), "uav1-3".to_string());
        let d = "operator/4".to_string();
        let goals = [
            GoalMarkerInput {
                id: &a,
                position: spomp_core::Point2::new(1.0, 2.0),
                claimed_by: None,
                visited_by: None,
                cancelled: false,
                priority: 0,
            },
            GoalMarkerInput {
                id: &b,
                position: spomp_core::Point2::new(3.0, 4.0),
                claimed_by: Some("ugv1"),
                visited_by: None,
                cancelled: false,
                priority: 0,
            },
            GoalMarkerInput {
                id: &c,
                position: spomp_core::Point2::new(5.0, 6.0),
                claimed_by: Some("ugv1"),
                visited_by: Some("ugv2"),
                cancelled: false,
                priority: 0,
            },
            GoalMarkerInput {
                id: &d,
                position: spomp_core::Point2::new(7.0, 8.0),
                claimed_by: None,
                visited_by: None,
                cancelled: true,
                priority: 2,
            },
        ];
        let array = MarkerArray::goals(goals, RosTime::default());
        assert_eq!(array.markers.len(), 1 + 2 * goals.len());
        assert_eq!(array.markers[0].action, 3, "delete all first");
        let cylinders: Vec<&Marker> = array.markers.iter().filter(|m| m.ns == "goals" && m.r#type == 3).collect();
        let colours: Vec<(f32, f32, f32)> = cylinders.iter().map(|m| (m.color.r, m.color.g, m.color.b)).collect();
        assert_eq!(
            colours,
            vec![(0.6, 0.6, 0.6), (1.0, 0.6, 0.0), (0.2, 0.8, 0.2), (0.5, 0.05, 0.05)],
            "open, claimed, visited, cancelled"
        );
        assert_eq!((cylinders[1].pose.position.x, cylinders[1].pose.position.y), (3.0, 4.0));
        let labels: Vec<&str> = array.markers.iter().filter(|m| m.r#type == 9).map(|m| m.text.as_str()).collect();
        assert_eq!(
            labels,
            vec!["uav1-1", "uav1-2 claimed by ugv1", "uav1-3 visited by ugv2", "operator/4 cancelled priority 2"]
        );
    }

    #[test]
    fn a_robot_body_transform_is_its_pose_in_map() {
        let tf =
            TfMessage::base_in_map(&RobotFrames::prefixed("ugv1"), Pose2::new(1.0, -2.0, 0.5), 0.3, RosTime::default());
        let t = &tf.transforms[0];
        assert_eq!((t.header.frame_id.as_str(), t.child_frame_id.as_str()), ("map", "ugv1/base_link"));
        assert_eq!((t.transform.translation.x, t.transform.translation.y, t.transform.translation.z), (1.0, -2.0, 0.3));
        assert_eq!(t.transform.rotation, Quaternion::from_yaw(0.5));
    }

    #[test]
    fn yaw_quaternion_is_unit() {
        let q = Quaternion::from_yaw(1.2);
        assert!((q.z * q.z + q.w * q.w - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_map_tile_travels_as_a_grid_map_and_back_cell_for_cell() {
        use spomp_core::aerial::MapTile;
        use spomp_core::geometry::Point2;
        use spomp_core::grid::GridSpec;
        let spec = GridSpec::new(Point2::new(-10.0, 5.0), 0.5, 40, 30);
        let (w, h) = (3u32, 2u32);
        let n = (w * h) as usize;
        let tile = MapTile {
            col0: 7,
            row0: 4,
            width: w,
            height: h,
            class: (0..n as u8).collect(),
            rgb: (0..n as u8).map(|k| [k, 255 - k, k.wrapping_mul(37)]).collect(),
            elevation: (0..n).map(|k| if k == 2 { f32::NAN } else { k as f32 * 0.25 }).collect(),
        };
        let msg = GridMap::from_tile(&tile, &spec, "map", RosTime::default());
        // The centre of the tile: cells 7..10 and 4..6 of 0.5 m from (-10, 5).
        assert_eq!((msg.info.pose.position.x, msg.info.pose.position.y), (-10.0 + 8.5 * 0.5, 5.0 + 5.0 * 0.5));
        // grid_map's index (0, 0) is the cell at the largest x and y: the tile's last cell.
        assert_eq!(msg.data[0].data[0], f32::from(tile.class[n - 1]));
        let back = msg.to_tile(&spec).unwrap();
        assert_eq!((back.col0, back.row0, back.width, back.height), (7, 4, w, h));
        assert_eq!((back.class.clone(), back.rgb.clone()), (tile.class.clone(), tile.rgb.clone()));
        let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.elevation), bits(&tile.elevation));

        // A grid map the aerial map cannot take is refused with the reason.
        let mut shifted = msg.clone();
        shifted.info.pose.position.x += 0.2;
        assert!(shifted.to_tile(&spec).unwrap_err().0.contains("aligned"));
        let mut coarse = msg.clone();
        coarse.info.resolution = 1.0;
        assert!(coarse.to_tile(&spec).unwrap_err().0.contains("resolution"));
        let mut outside = msg.clone();
        outside.info.pose.position.x += 100.0;
        assert!(outside.to_tile(&spec).is_err());
        let mut short = msg;
        short.data[2].data.pop();
        assert!(short.to_tile(&spec).unwrap_err().0.contains("elevation"));
    }
}
