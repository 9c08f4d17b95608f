//! # spomp-global-planner
//!
//! The global ground planner of the SPOMP paper (§Global Ground Planner):
//!
//! - a sparse **traversability graph** over the aerial orthomap, built by greedy farthest-point
//!   coverage with ray-traced visibility regions, class by class from easiest to hardest, and
//!   grown (never rebuilt) as the map grows;
//! - a **learned traversability** model T(p) (an MLP over colour, distance to each class and
//!   elevation) trained online from reachability scans; edge cost Σ −log T along the edge;
//! - **experience**: every edge near a reachability scan is judged trav / not_trav / unk_trav;
//!   repeated consistent observations mark it; the robot's own not_trav observations lock and
//!   remove it, other robots' never do;
//! - **sharing**: [`ScanSharer`] picks which scans to send to the team;
//! - **search**: A* on the graph, and [`GlobalPlanner::path_status`] to know when to replan.
//!
//! The crate is a pure library: time and randomness come in as arguments.

mod coverage;
mod error;
mod experience;
mod features;
mod mlp;
mod params;
mod planner;
mod routing;
mod sharing;
mod star;
pub mod synthetic;
mod teammates;

pub use error::{PlanError, ScanError, SetupError};
pub use experience::EdgeState;
pub use params::{
    ExperienceParams, GlobalPlannerParams, GraphParams, LearningParams, SearchParams, SharingMode, SharingParams,
};
pub use planner::{
    EdgeId, EdgeView, GlobalPath, GlobalPlanner, GraphStats, MapUpdate, NodeId, PathStatus, ScanUpdate, TrainOutcome,
};
pub use routing::forget_shared_routes;
pub use sharing::ScanSharer;
pub use star::EdgeObservation;
pub use teammates::bins_ending_at_teammates;
