//! Errors of the global planner.

/// A planner could not be created or a map could not be taken in.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SetupError {
    /// `graph.class_order` names a class the table does not have.
    #[error("graph.class_order names unknown class `{name}` (known: {known})")]
    UnknownClass {
        /// The name given.
        name: String,
        /// The table's class names.
        known: String,
    },
    /// A parameter is out of range.
    #[error("parameter `{name}` is invalid: {reason}")]
    InvalidParameter {
        /// Dotted parameter path.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The map's layers do not match its grid.
    #[error("aerial map is inconsistent: {0}")]
    InvalidMap(String),
    /// The map's grid differs from the one the graph was built on.
    #[error("aerial map grid changed (graph built on {built}, got {got})")]
    MapGridChanged {
        /// Grid the graph was built on.
        built: String,
        /// Grid of the new map.
        got: String,
    },
}

/// A reachability scan was rejected.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScanError {
    /// The scan has no bins.
    #[error("reachability scan has no bins")]
    Empty,
    /// `range_m` and `obstacle` differ in length.
    #[error("reachability scan has {ranges} ranges but {obstacle} obstacle flags")]
    LengthMismatch {
        /// Length of `range_m`.
        ranges: usize,
        /// Length of `obstacle`.
        obstacle: usize,
    },
    /// The scan's pose is NaN or infinite.
    #[error("reachability scan pose is not finite")]
    NonFinitePose,
}

/// No path could be planned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// No aerial map has been given yet.
    #[error("no aerial map yet")]
    NoMap,
    /// A point is NaN or infinite.
    #[error("{which} point is not finite")]
    NonFinite {
        /// `start` or `goal`.
        which: &'static str,
    },
    /// A point is off the map.
    #[error("{which} point ({x:.1}, {y:.1}) is off the map")]
    OffMap {
        /// `start` or `goal`.
        which: &'static str,
        /// East, metres.
        x: f64,
        /// North, metres.
        y: f64,
    },
    /// No graph node covers a cell near the point.
    #[error("{which} point ({x:.1}, {y:.1}) is not near the traversability graph")]
    NotOnGraph {
        /// `start` or `goal`.
        which: &'static str,
        /// East, metres.
        x: f64,
        /// North, metres.
        y: f64,
    },
    /// The point lies in territory this planner's map has no data for yet (a goal found in a
    /// map version that has not reached this robot), and no graph node is near it.
    #[error("{which} point ({x:.1}, {y:.1}) is in territory this robot's map does not cover yet")]
    Unmapped {
        /// `start` or `goal`.
        which: &'static str,
        /// East, metres.
        x: f64,
        /// North, metres.
        y: f64,
    },
    /// The graph has no path between the two points.
    #[error("no path between start and goal")]
    NoPath,
}
