//! One spomp robot, the same for every adapter.
//!
//! - [`Robot`]: the seam. An adapter (the simulator, the ROS 2 node, log replay) owns one per
//!   robot and drives it through a small push API: inputs ([`Robot::on_odometry`],
//!   [`Robot::on_panorama`], [`Robot::on_external_pose`], [`Robot::on_camera_tiles`],
//!   [`Robot::on_team_message`]), [`Robot::tick`], then outputs ([`Robot::command`] or
//!   [`Robot::flight`], [`Robot::team_message_for`], [`Robot::take_problems`]).
//! - [`seam`]: the same calls as data ([`SeamCall`], made by [`Robot::call`]), which the robot
//!   records for one [`RobotObserver`] (logs, live views, replay checks).
//! - [`team_round`]: the team link's send round ([`Robot::team_round`] within a
//!   [`LinkCredit`]) and the background work's modelled latency ([`ModelledWork`]), written once
//!   for every adapter; the adapters only move bytes and work.
//! - [`operator_log`]: the operator's commands and acknowledgements a robot's team state
//!   comes to hold, reported once each for its log.
//! - [`RobotView`]: what observers and tools may read of a robot, read-only.
//! - [`RobotSetup`]: the one translation from a mission, a robot id and the [`OperatingArea`]
//!   to a robot's configuration, with its [`NavigationSettings`] from the mission's
//!   `navigation:` sections.
//! - [`runtime`]: the robot's state and continuous skills (localization, terrain analysis, the
//!   global planner kept current, the team state, the map copy) — what the domain nodes act on,
//!   typed, through methods.
//! - [`nodes`]: the domain behaviour nodes (navigation, UAV time-sharing, goal coordination) and
//!   [`registry`], the engine's node types plus these.

pub mod checks;
pub mod class_names;
pub mod mission_section;
pub mod nodes;
pub mod operator_log;
mod robot;
pub mod runtime;
pub mod seam;
pub mod settings;
pub mod setup;
pub mod team_round;

pub use checks::MissionRobotChecks;
pub use mission_section::CommsSpec;
pub use nodes::registry;
pub use robot::{ResumeError, Robot, RobotError, RobotView, TeamTraffic};
pub use runtime::{JoinFn, RobotRuntime};
pub use seam::{RobotObserver, SeamCall, SeamReply, TickOutput};
pub use settings::{NavigationProfile, NavigationSettings, SettingsError, WatchdogParams};
pub use setup::{OperatingArea, PoseInput, RobotSetup, SetupError, SetupOptions, robot_seed};
pub use team_round::{LinkCredit, ModelledWork, RoundShape, WorkLatency};
