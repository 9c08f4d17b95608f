//! What `spomp run` needs to know beyond the robot itself: names, DDS, input formats, limits.

use spomp_behaviors::mission::{MissionFile, MissionSection};
use spomp_robot::CommsSpec;
use spomp_ros_msgs::{CmdVelType, DepthEncoding, RobotFrames};

use crate::mission_section::Ros2Spec;

use crate::dds::DdsSettings;
use crate::topics::TopicNames;

/// Why the settings could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// The robot is not in the mission's team.
    #[error("robot `{0}` is not in the mission's team (team: {1})")]
    UnknownRobot(String, String),
    /// A bad value (the loader checks the mission's; this is for the environment).
    #[error("{0}")]
    Invalid(String),
}

/// Settings of one robot's ROS 2 side.
#[derive(Debug, Clone)]
pub struct RunSettings {
    /// Robot id.
    pub robot: String,
    /// Topic names.
    pub topics: TopicNames,
    /// Frame ids of the robot's messages and transforms.
    pub frames: RobotFrames,
    /// Type of the velocity command on `cmd_vel`.
    pub cmd_vel_type: CmdVelType,
    /// Where the robot's settings are in the mission (`team[1] (ugv1) ros2`), for diagnostics.
    pub setting_path: String,
    /// DDS domain and interfaces.
    pub dds: DdsSettings,
    /// Stop when odometry is older than this, seconds.
    pub odometry_timeout_s: f64,
    /// Stop when the newest panorama is older than this, seconds.
    pub panorama_timeout_s: f64,
    /// Encoding of the robot's depth images (what its logs record; any is read).
    pub depth_encoding: DepthEncoding,
    /// Metres per count of integer depth images (`None`: the encoding's default).
    pub depth_scale_m: Option<f64>,
    /// Vertical field of view of the panorama images, radians.
    pub v_fov_rad: f64,
    /// Sensor height above ground, metres.
    pub sensor_height_m: f64,
    /// Time from `/clock`.
    pub use_sim_time: bool,
    /// GNSS origin (latitude, longitude), degrees.
    pub gps_origin: Option<(f64, f64)>,
    /// Team-state messages to each peer at most this often, seconds.
    pub team_period_s: f64,
    /// What one round of team-state messages may carry to each peer, bytes: the mission's
    /// `comms.bandwidth_bytes_per_s` × `team_period_s`.
    pub team_budget_bytes: usize,
    /// Follow a simulator farm's lockstep (`spomp run --lockstep`) instead of `/clock`.
    pub lockstep: Option<LockstepSettings>,
}

/// A robot in a farm's lockstep (see [`crate::lockstep`]).
#[derive(Debug, Clone, PartialEq)]
pub struct LockstepSettings {
    /// The run seed this robot was set up with: the farm's must be the same.
    pub seed: u64,
    /// The farm is given up for gone when it sends nothing for this long, wall seconds.
    pub timeout_s: f64,
}

/// Team-state messages go to each peer at most this often, seconds.
const TEAM_PERIOD_S: f64 = 1.0;

impl RunSettings {
    /// Robot `id` of `mission` with its `ros2:` settings; `domain_id` (the command line's)
    /// overrides the mission's, and the ROS 2 environment (`ROS_DOMAIN_ID`,
    /// `ROS_AUTOMATIC_DISCOVERY_RANGE`) overrides both where set.
    pub fn from_mission(mission: &MissionFile, id: &str, domain_id: Option<u16>) -> Result<Self, SettingsError> {
        let (index, spec) = mission.team.iter().enumerate().find(|(_, r)| r.id == id).ok_or_else(|| {
            SettingsError::UnknownRobot(
                id.into(),
                mission.team.iter().map(|r| r.id.as_str()).collect::<Vec<_>>().join(", "),
            )
        })?;
        let ros = Ros2Spec::of_robot(spec).map_err(|e| SettingsError::Invalid(e.to_string()))?;
        let comms = CommsSpec::of_mission(mission).map_err(|e| SettingsError::Invalid(e.to_string()))?;
        // A robot without the section resolves its names as one with the defaults does.
        let given = Ros2Spec::given_for(spec).then_some(&ros);
        let mut dds = DdsSettings::for_robot(&ros).map_err(SettingsError::Invalid)?;
        if let Some(d) = domain_id {
            dds.domain_id = d;
        }
        let topics = TopicNames::resolve(id, given);
        let frames = crate::frames::resolve(given, &topics);
        let setting_path = format!("team[{index}] ({id}) ros2");
        if let Some((a, b, frame)) = crate::frames::collision(&frames) {
            return Err(SettingsError::Invalid(format!(
                "{setting_path}: frames `{a}` and `{b}` are both `{frame}` (set `frames.{b}` or `frame_prefix`)"
            )));
        }
        Ok(RunSettings {
            robot: id.into(),
            topics,
            frames,
            cmd_vel_type: ros.cmd_vel_type,
            setting_path,
            dds,
            odometry_timeout_s: ros.odometry_timeout_s,
            panorama_timeout_s: ros.panorama_timeout_s,
            depth_encoding: ros.depth_encoding,
            depth_scale_m: ros.depth_scale_m,
            v_fov_rad: ros.panorama_v_fov_deg.to_radians(),
            sensor_height_m: ros.sensor_height_m,
            use_sim_time: ros.use_sim_time,
            gps_origin: ros.gps_origin.map(|o| (o.latitude_deg, o.longitude_deg)),
            team_period_s: TEAM_PERIOD_S,
            team_budget_bytes: usize::try_from(comms.round_budget_bytes(TEAM_PERIOD_S)).unwrap_or(usize::MAX),
            lockstep: None,
        })
    }
}
