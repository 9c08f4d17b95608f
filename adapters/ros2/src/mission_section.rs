//! The robot's `ros2:` section of a mission, owned by this adapter: its settings with their
//! defaults and rules, registered with the mission language by [`Ros2Spec`]'s
//! [`MissionSection`] impl (see `docs/missions.md`; the fields are documented in this crate's
//! README).

use std::collections::BTreeMap;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_behaviors::mission::{MissionSection, SectionContext};
use spomp_core::GeoPoint;
use spomp_ros_msgs::{CmdVelType, DepthEncoding};

/// ROS 2 settings of a robot.
#[derive(Debug, Clone, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Ros2Spec {
    /// Topic namespace (default `/<id>`).
    #[serde(default)]
    pub namespace: Option<String>,
    /// DDS domain id (`spomp run --domain-id` and `ROS_DOMAIN_ID` override it).
    #[serde(default)]
    pub domain_id: u16,
    /// Topic names by role, replacing the defaults (`odom`, `panorama/depth`, `cmd_vel`, …; see
    /// `docs/robots.md`); a name without a leading `/` is under the namespace.
    #[serde(default)]
    pub topics: BTreeMap<String, String>,
    /// Only these local IPv4 addresses carry DDS discovery and data (e.g. `[127.0.0.1]`); empty:
    /// every interface.
    #[serde(default)]
    pub interfaces: Vec<String>,
    /// Stop (zero velocity) when odometry is older than this, seconds.
    #[serde(default = "default_odometry_timeout")]
    pub odometry_timeout_s: f64,
    /// Stop when the newest panorama is older than this, seconds.
    #[serde(default = "default_panorama_timeout")]
    pub panorama_timeout_s: f64,
    /// Encoding of the robot's depth images (`sensor_msgs/Image`): `32FC1` (default: REP-118's
    /// canonical metres), `16UC1` (REP-118's millimetres) or `mono16` (counts of 1/512 m,
    /// spomp's earlier form). A simulator farm publishes this one and logs record it; `spomp
    /// run` reads any of the three by the image's own `encoding` field.
    #[serde(default)]
    pub depth_encoding: DepthEncoding,
    /// Metres per count of a `16UC1`/`mono16` depth image (default: 0.001 for `16UC1`, 1/512
    /// for `mono16`; 0 counts mean no return). Only with an integer `depth_encoding`.
    #[serde(default)]
    pub depth_scale_m: Option<f64>,
    /// Vertical field of view of the panorama images, degrees (rows spread evenly over it,
    /// centred on the horizon).
    #[serde(default = "default_v_fov")]
    pub panorama_v_fov_deg: f64,
    /// Height of the panorama sensor above the ground, metres.
    #[serde(default = "default_sensor_height")]
    pub sensor_height_m: f64,
    /// Take time from `/clock` (a simulator's) instead of the wall clock.
    #[serde(default)]
    pub use_sim_time: bool,
    /// The GNSS reference: `sensor_msgs/NavSatFix` positions are converted to the map frame
    /// (east = +x, north = +y) around this point. Without it, NavSatFix input is refused.
    #[serde(default)]
    pub gps_origin: Option<GpsOrigin>,
    /// Type of the velocity command on `cmd_vel`: `twist_stamped` (default: what ros2_control's
    /// `diff_drive_controller` takes — on Jazzy only that — and Nav2's stamped default) or
    /// `twist` (Gazebo's diff-drive bridge, teleop tools, older drivers).
    #[serde(default)]
    pub cmd_vel_type: CmdVelType,
    /// Prefix of the default `odom`, `base_link` and sensor frame ids (never of `map`). Default:
    /// the namespace (`ugv1/`, `husky/`) while tf is the global `/tf`, none when the robot's tf
    /// topics are namespaced (each robot then has a tree of its own, as in Nav2's multi-robot
    /// bringup) or the namespace is the root.
    #[serde(default)]
    pub frame_prefix: Option<String>,
    /// Frame ids, each replacing its default (REP-105: `map`, `odom`, `base_link`; the panorama
    /// sensor's `lidar`), used as written (no prefix).
    #[serde(default)]
    pub frames: FramesSpec,
}

/// Frame ids of a robot, each replacing its default (see [`Ros2Spec::frames`]).
#[derive(Debug, Clone, Default, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FramesSpec {
    /// The world-fixed frame of the estimate, paths, goals and setpoints (default `map`).
    #[serde(default)]
    pub map: Option<String>,
    /// The odometry frame (default `<prefix>odom`).
    #[serde(default)]
    pub odom: Option<String>,
    /// The robot's body frame (default `<prefix>base_link`).
    #[serde(default)]
    pub base_link: Option<String>,
    /// The panorama sensor's frame (default `<prefix>lidar`).
    #[serde(default)]
    pub sensor: Option<String>,
}

impl FramesSpec {
    /// Every frame given, as (field, id).
    pub fn given(&self) -> impl Iterator<Item = (&'static str, &str)> {
        [("map", &self.map), ("odom", &self.odom), ("base_link", &self.base_link), ("sensor", &self.sensor)]
            .into_iter()
            .filter_map(|(k, v)| v.as_deref().map(|v| (k, v)))
    }
}

impl Default for Ros2Spec {
    fn default() -> Self {
        Ros2Spec {
            namespace: None,
            domain_id: 0,
            topics: Default::default(),
            interfaces: Vec::new(),
            odometry_timeout_s: default_odometry_timeout(),
            panorama_timeout_s: default_panorama_timeout(),
            depth_encoding: DepthEncoding::default(),
            depth_scale_m: None,
            panorama_v_fov_deg: default_v_fov(),
            sensor_height_m: default_sensor_height(),
            use_sim_time: false,
            gps_origin: None,
            cmd_vel_type: CmdVelType::default(),
            frame_prefix: None,
            frames: FramesSpec::default(),
        }
    }
}

/// A WGS 84 point: the map frame's origin for GNSS input.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GpsOrigin {
    /// Degrees, positive north.
    pub latitude_deg: f64,
    /// Degrees, positive east.
    pub longitude_deg: f64,
    /// Metres above the ellipsoid (of the map frame's z = 0).
    #[serde(default)]
    pub altitude_m: f64,
}

fn default_odometry_timeout() -> f64 {
    0.5
}

fn default_panorama_timeout() -> f64 {
    3.0
}

fn default_v_fov() -> f64 {
    90.0
}

fn default_sensor_height() -> f64 {
    0.4
}

/// Topic roles a robot's `ros2.topics` may rename (the ROS 2 adapter's inputs and outputs).
pub const ROS2_TOPIC_ROLES: &[&str] = &[
    "odom",
    "panorama/depth",
    "panorama/semantic",
    "gps",
    "pose_in",
    "camera/tiles",
    "cmd_vel",
    "setpoint",
    "setpoint_speed",
    "pose_estimate",
    "path",
    "goals",
    "reachability",
    "diagnostics",
    "estop",
    "team/in",
    "team/out",
    "tf",
    "tf_static",
];

impl MissionSection for Ros2Spec {
    const NAME: &'static str = "ros2";

    fn geo_reference(&self) -> Option<GeoPoint> {
        self.gps_origin.map(|o| GeoPoint::new(o.latitude_deg, o.longitude_deg))
    }

    fn check(&self, _: &SectionContext<'_>, bad: &mut dyn FnMut(&[&str], String)) {
        for (field, v) in
            [("odometry_timeout_s", self.odometry_timeout_s), ("panorama_timeout_s", self.panorama_timeout_s)]
        {
            if !(v.is_finite() && v > 0.0 && v <= 3600.0) {
                bad(&[field], format!("expected a time in (0, 3600] seconds, found {v}"));
            }
        }
        if !(self.panorama_v_fov_deg.is_finite() && self.panorama_v_fov_deg > 0.0 && self.panorama_v_fov_deg <= 180.0) {
            bad(&["panorama_v_fov_deg"], format!("expected (0, 180] degrees, found {}", self.panorama_v_fov_deg));
        }
        if !(self.sensor_height_m.is_finite() && (0.0..=100.0).contains(&self.sensor_height_m)) {
            bad(&["sensor_height_m"], format!("expected 0..100 m, found {}", self.sensor_height_m));
        }
        if let Some(scale) = self.depth_scale_m
            && !(scale.is_finite() && scale > 0.0 && scale <= 1.0)
        {
            bad(&["depth_scale_m"], format!("expected metres per count in (0, 1], found {scale}"));
        }
        if self.depth_scale_m.is_some() && self.depth_encoding.default_scale_m().is_none() {
            bad(
                &["depth_scale_m"],
                format!(
                    "a scale applies to integer depth images; depth_encoding is {} (metres): set depth_encoding: 16UC1 or mono16, or remove depth_scale_m",
                    self.depth_encoding.name()
                ),
            );
        }
        if let Some(o) = &self.gps_origin {
            if !(o.latitude_deg.is_finite() && o.latitude_deg.abs() <= 90.0) {
                bad(&["gps_origin", "latitude_deg"], format!("expected -90..90 degrees, found {}", o.latitude_deg));
            }
            if !(o.longitude_deg.is_finite() && o.longitude_deg.abs() <= 180.0) {
                bad(&["gps_origin", "longitude_deg"], format!("expected -180..180 degrees, found {}", o.longitude_deg));
            }
            if !o.altitude_m.is_finite() {
                bad(&["gps_origin", "altitude_m"], format!("expected a finite height, found {}", o.altitude_m));
            }
        }
        for (i, addr) in self.interfaces.iter().enumerate() {
            if addr.parse::<std::net::IpAddr>().is_err() {
                bad(&["interfaces", &i.to_string()], format!("expected an IP address, found `{addr}`"));
            }
        }
        for (role, name) in &self.topics {
            if !ROS2_TOPIC_ROLES.contains(&role.as_str()) {
                bad(
                    &["topics", role],
                    format!("unknown topic role `{role}`; roles are: {}", ROS2_TOPIC_ROLES.join(", ")),
                );
            } else if !valid_ros_name(name) {
                bad(
                    &["topics", role],
                    format!(
                        "`{name}` is not a ROS 2 topic name (letters, digits, `_` and `/` separators, not starting with a digit)"
                    ),
                );
            }
        }
        if let Some(ns) = &self.namespace
            && !(ns.is_empty() || ns == "/" || valid_ros_name(ns))
        {
            bad(&["namespace"], format!("`{ns}` is not a ROS 2 namespace"));
        }
        if let Some(prefix) = &self.frame_prefix
            && !(prefix.is_empty() || valid_frame_id(prefix.strip_suffix('/').unwrap_or(prefix)))
        {
            bad(
                &["frame_prefix"],
                format!("`{prefix}` is not a frame prefix (frame-id tokens, no leading `/`; empty for none)"),
            );
        }
        let mut seen: Vec<(&str, &str)> = Vec::new();
        for (field, id) in self.frames.given() {
            if !valid_frame_id(id) {
                bad(
                    &["frames", field],
                    format!("`{id}` is not a frame id (tf2: letters, digits, `_`, `/` separators, no leading `/`)"),
                );
            } else if let Some((other, _)) = seen.iter().find(|(_, o)| *o == id) {
                bad(
                    &["frames", field],
                    format!("`{id}` is also `frames.{other}`: each frame of the tf tree needs its own id"),
                );
            }
            seen.push((field, id));
        }
    }
}

/// A tf2 frame id: a ROS name without the leading `/` (tf2 refuses one).
pub fn valid_frame_id(id: &str) -> bool {
    !id.starts_with('/') && valid_ros_name(id)
}

/// A ROS 2 topic or namespace name: `/`-separated tokens of letters, digits and `_`, no token
/// starting with a digit, no empty token but an optional leading `/`.
pub fn valid_ros_name(name: &str) -> bool {
    let body = name.strip_prefix('/').unwrap_or(name);
    !body.is_empty()
        && body.split('/').all(|t| {
            !t.is_empty()
                && !t.starts_with(|c: char| c.is_ascii_digit())
                && t.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !t.contains("__")
        })
}
