//! `spomp-ros2`: a spomp robot over ROS 2, and the simulator as a ROS 2 robot farm.
//!
//! Built on `ros2-client` (RustDDS): no ROS installation is needed. The robot side
//! ([`run::RobotNode`]) drives the same [`spomp_robot::Robot`] every adapter drives: it turns
//! ROS 2 inputs (odometry, panorama images, a GNSS fix or a local pose, team-state bytes, an
//! e-stop) into the robot's inputs, ticks it at its rate, and publishes its outputs (velocity
//! commands or position setpoints, the pose estimate and `map → odom` on `/tf`, the path,
//! goals and claims as markers, the reachability scan, node transitions on `/rosout`, health
//! on `/diagnostics`), with watchdogs that stop the robot when its inputs go stale.
//!
//! The farm side ([`farm::FarmLink`]) is what a simulator needs to let separate `spomp run`
//! processes drive its robots: it publishes their sensors and `/clock`, and takes their commands
//! and team-state messages. This crate depends on no other adapter; the CLI wires them.

//!
//! Without the `dds` feature (on by default) the crate is what reading a mission needs: the
//! `ros2:` section, topic names, frames, run settings and the message conversions. The node, the
//! farm link and the lockstep protocol speak DDS and need the feature (RustDDS and its
//! dependencies are about a fifth of a release build of `spomp`).

pub mod clock;
pub mod convert;
pub mod dds;
#[cfg(feature = "dds")]
pub mod farm;
pub mod frames;
#[cfg(feature = "dds")]
pub mod lockstep;
pub mod mission_section;

pub mod pairing;
#[cfg(feature = "dds")]
pub mod run;
pub mod settings;
pub mod team;
pub mod topics;
pub mod workers;

pub use clock::TimeBase;
pub use dds::{DdsError, DdsSettings};
#[cfg(feature = "dds")]
pub use farm::FarmLink;
pub use mission_section::Ros2Spec;

#[cfg(feature = "dds")]
pub use run::{RobotNode, RunObserver, RunReport};
pub use settings::{RunSettings, SettingsError};
pub use team::{OperatorDesk, StateSink, TeamChannel};
pub use topics::TopicNames;
