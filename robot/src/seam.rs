//! Every call an adapter makes on a robot's seam ([`crate::Robot`]), for observers that record
//! them: a replay feeds a fresh robot the same calls in the same order and compares what it
//! answers. The simulator and `spomp run` report the same calls.

use spomp_core::{FlightCommand, MapTile, Odometry, PanoramaFrame, PoseEstimate, RobotId, Twist2};
use spomp_teamstate::{Tier, TierSet};

/// One call on a robot's seam (`spomp_robot::Robot`), with what it returned where it returns
/// something.
#[derive(Clone, Copy, Debug)]
pub enum SeamInput<'a> {
    /// `on_odometry`.
    Odometry(&'a Odometry),
    /// `on_panorama`.
    Panorama(&'a PanoramaFrame),
    /// `on_external_pose`.
    ExternalPose(&'a PoseEstimate),
    /// `on_camera_tiles`.
    CameraTiles(&'a [MapTile]),
    /// `on_team_message` from `from`.
    TeamIn {
        /// The sender.
        from: &'a RobotId,
        /// The bytes as received.
        bytes: &'a [u8],
    },
    /// `team_message_for(to, tiers, budget_bytes)` and its answer.
    TeamOut {
        /// The receiver.
        to: &'a RobotId,
        /// The tiers the link allowed.
        tiers: TierSet,
        /// The byte budget.
        budget_bytes: usize,
        /// What the robot returned.
        sent: Option<&'a [u8]>,
    },
    /// `maintain` then `tick`, and the commands read back after it.
    Tick {
        /// `command()` after the tick.
        command: Option<Twist2>,
        /// `flight()` after the tick.
        flight: Option<FlightCommand>,
    },
    /// `halt` (the robot was killed).
    Halt,
    /// `take_work`, and the numbers of the work it gave.
    TakeWork(&'a [u64]),
    /// `finish_work` with the result of work number `id`.
    FinishWork(u64),
    /// `resume` with a state saved before a reboot (before the first tick).
    Resume(&'a [u8]),
}

/// A tier set as bits (bit k = tier k), the way logs store it.
pub fn tier_bits(tiers: TierSet) -> u8 {
    [Tier::Coordination, Tier::Scans, Tier::Maps]
        .iter()
        .filter(|t| tiers.contains(**t))
        .fold(0, |bits, t| bits | 1 << *t as u8)
}
