//! Shared types of spomp.
//!
//! Everything here is plain data.
//! No algorithms, no I/O, no threads: skills, behaviours and adapters all agree on these types,
//! and nothing in this crate depends on another spomp crate.

pub mod aerial;
pub mod classes;
pub mod geo;
pub mod geometry;
pub mod grid;
pub mod ids;
pub mod motion;
pub mod panorama;
pub mod scan;
pub mod time;

pub use aerial::{AerialMap, MapTile};
pub use classes::{ClassId, ClassInfo, ClassTable, ClassTableError, UNKNOWN_CLASS};
pub use geo::GeoPoint;
pub use geometry::{Point2, Pose2, normalize_angle};
pub use grid::{Cell, Grid, GridSpec};
pub use ids::{DEFAULT_DECONFLICTION_RADIUS_M, GoalId, RobotId, RobotKind};
pub use motion::{FlightCommand, Odometry, OdometryCovariance, PoseEstimate, Twist2};
pub use panorama::{DepthPanorama, PanoramaFrame, PanoramaGeometry, SemanticPanorama};
pub use scan::ReachabilityScan;
pub use time::Time;
