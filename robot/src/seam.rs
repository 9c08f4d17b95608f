//! The seam as data: every call an adapter makes on a [`crate::Robot`], with what it answered.
//!
//! [`SeamCall`] is the one description of the seam. [`crate::Robot::call`] makes a call and
//! returns it with its answers filled in (the bytes of a team message, the commands after a
//! tick, the numbers of the work taken); the robot's named methods (`on_odometry`, `tick`, …)
//! are thin wrappers over it. A robot asked to record ([`crate::Robot::record_seam`]) keeps
//! every call it answered, in order, until an adapter hands them to a [`RobotObserver`]
//! ([`crate::Robot::deliver_recorded`]): a log, a live view and a replay see exactly the calls
//! the robot saw, because the robot, not the adapter, writes them down. A replay makes each
//! recorded call on a fresh robot and compares the answers ([`SeamCall::same_answers`]).

use std::sync::Arc;

use spomp_behaviors::trace::TransitionRecord;
use spomp_core::{FlightCommand, MapTile, Odometry, PanoramaFrame, PoseEstimate, RobotId, Time, Twist2};
use spomp_teamstate::{ApplyReport, RestoreSummary, SyncError, TierSet};

use crate::ResumeError;
use crate::runtime::SkillWork;

/// One call on a robot's seam, with its answers once made (see [`crate::Robot::call`]).
#[derive(Clone, Debug, PartialEq)]
pub enum SeamCall {
    /// New odometry (robot frame).
    Odometry(Odometry),
    /// A new depth + semantic panorama.
    Panorama(Arc<PanoramaFrame>),
    /// A map-frame pose from outside (GPS, a surveyed position, simulator truth).
    ExternalPose(PoseEstimate),
    /// Aerial-map tiles from the robot's own camera (the UAV).
    CameraTiles(Vec<MapTile>),
    /// A team-state message from peer `from`, as bytes off the link.
    TeamIn {
        /// The sender.
        from: RobotId,
        /// The bytes as received.
        bytes: Vec<u8>,
    },
    /// The team-state message for peer `to`, limited to `tiers` and `budget_bytes`.
    TeamOut {
        /// The receiver.
        to: RobotId,
        /// The tiers the link allows.
        tiers: TierSet,
        /// The byte budget.
        budget_bytes: usize,
        /// Answer: the encoded message; `None`: nothing to send.
        sent: Option<Vec<u8>>,
    },
    /// Upkeep (team-state clock, global planner) then one tick of the tree.
    Tick(TickOutput),
    /// Halts the tree (mission end, robot killed, e-stop).
    Halt,
    /// Takes the background work due (see [`crate::Robot::set_background_skills`]).
    TakeWork(
        /// Answer: the numbers of the work taken, in order.
        Vec<u64>,
    ),
    /// Applies the result of work number `id`, handed over before with
    /// [`crate::Robot::deliver_work`].
    FinishWork(u64),
    /// Resumes from a state saved before a reboot ([`crate::Robot::resume_state`]).
    Resume(Vec<u8>),
}

/// The answer of a tick: the commands read back after it.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TickOutput {
    /// The velocity command (UGVs); `None`: stop.
    pub command: Option<Twist2>,
    /// The flight command (UAVs); `None`: hover.
    pub flight: Option<FlightCommand>,
}

/// What a call gives its caller beyond the answers it records: values a log does not keep.
#[derive(Debug)]
pub enum SeamReply {
    /// Nothing more.
    Done,
    /// A team message was taken (with what it changed) or refused whole (why).
    TeamIn(Result<ApplyReport, SyncError>),
    /// The tree's status after the tick.
    Tick(spomp_behaviors::Status),
    /// The work taken, to run anywhere and deliver back ([`crate::Robot::deliver_work`]).
    TakeWork(Vec<SkillWork>),
    /// The result was applied, or no result of that number was delivered.
    FinishWork(Result<(), UnknownWork>),
    /// The saved state was taken, or refused whole.
    Resume(Result<RestoreSummary, ResumeError>),
}

/// A `finish_work` named a work whose result was not delivered (or was applied already).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error("no result of work {0} was delivered")]
pub struct UnknownWork(pub u64);

impl SeamCall {
    /// Every call's name, as logs spell it, in declaration order.
    pub const NAMES: [&'static str; 11] = [
        "odometry",
        "panorama",
        "external_pose",
        "camera_tiles",
        "team_in",
        "team_out",
        "tick",
        "halt",
        "take_work",
        "finish_work",
        "resume",
    ];

    /// The call's name, as logs spell it (one of [`SeamCall::NAMES`]).
    pub fn name(&self) -> &'static str {
        let k = match self {
            SeamCall::Odometry(_) => 0,
            SeamCall::Panorama(_) => 1,
            SeamCall::ExternalPose(_) => 2,
            SeamCall::CameraTiles(_) => 3,
            SeamCall::TeamIn { .. } => 4,
            SeamCall::TeamOut { .. } => 5,
            SeamCall::Tick(_) => 6,
            SeamCall::Halt => 7,
            SeamCall::TakeWork(_) => 8,
            SeamCall::FinishWork(_) => 9,
            SeamCall::Resume(_) => 10,
        };
        Self::NAMES[k]
    }

    /// Whether `other`, the same call made again, answered as this one did: the same message
    /// bytes, the same commands bit for bit, the same work. Calls that answer nothing always
    /// match.
    pub fn same_answers(&self, other: &SeamCall) -> bool {
        match (self, other) {
            (SeamCall::TeamOut { sent: a, .. }, SeamCall::TeamOut { sent: b, .. }) => a == b,
            // Bit for bit: `-0.0` is not `0.0` and a NaN matches itself (as a log would).
            (SeamCall::Tick(a), SeamCall::Tick(b)) => format!("{a:?}") == format!("{b:?}"),
            (SeamCall::TakeWork(a), SeamCall::TakeWork(b)) => a == b,
            (a, b) => a.name() == b.name(),
        }
    }

    /// The call's answer in words, for a report of where a replay diverged; `other` (the same
    /// call answered again) points at the first byte that differs.
    pub fn describe_answer(&self, other: Option<&SeamCall>) -> String {
        match self {
            SeamCall::TeamOut { to, sent, .. } => {
                let other = match other {
                    Some(SeamCall::TeamOut { sent, .. }) => sent.as_deref(),
                    _ => None,
                };
                match sent {
                    None => format!("nothing to {to}"),
                    Some(b) => {
                        let first_diff = other
                            .map(|o| b.iter().zip(o).position(|(x, y)| x != y).unwrap_or(b.len().min(o.len())))
                            .map(|k| format!(", first difference at byte {k}"))
                            .unwrap_or_default();
                        format!("{} bytes to {to}{first_diff}", b.len())
                    }
                }
            }
            // `{:?}`: the shortest text that reads back as the same float.
            SeamCall::Tick(t) => match (t.command, t.flight) {
                (Some(c), _) => format!("cmd_vel v={:?} m/s omega={:?} rad/s", c.v, c.omega),
                (None, Some(f)) => format!(
                    "flight to ({:?}, {:?}) at {:?} m, {:?} m/s",
                    f.target.x, f.target.y, f.altitude_m, f.speed_mps
                ),
                (None, None) => "stop".into(),
            },
            SeamCall::TakeWork(ids) => format!("work {ids:?}"),
            other => other.name().to_string(),
        }
    }
}

/// Receives what a robot saw and did, in the order it did it: every seam call with its answers
/// and every node transition. Implemented by recorders (MCAP), live views and tests; the
/// adapters hand it the robot's record ([`crate::Robot::deliver_recorded`]). Every method has
/// an empty default.
pub trait RobotObserver {
    /// Whether the robot should record its seam calls for this observer (a recorder that keeps
    /// them: `--replayable`, `--record`); recording costs a copy of each call's data.
    fn wants_seam(&self) -> bool {
        false
    }
    /// A call on robot `robot`'s seam at `now`, with its answers.
    fn on_seam(&mut self, _robot: &RobotId, _now: Time, _call: &SeamCall) {}
    /// Node transitions of one tick, before that tick's seam call.
    fn on_transitions(&mut self, _robot: &RobotId, _records: &[TransitionRecord]) {}
    /// A problem a node or skill reported (or an input the adapter refused).
    fn on_problem(&mut self, _robot: &RobotId, _now: Time, _message: &str) {}
    /// A new reachability scan the robot computed.
    fn on_scan(&mut self, _scan: &spomp_core::ReachabilityScan) {}
    /// A new planned path (when it changes).
    fn on_path(&mut self, _robot: &RobotId, _now: Time, _path: &[spomp_core::Point2]) {}
    /// Odometry as the robot received it.
    fn on_odometry(&mut self, _robot: &RobotId, _odom: &Odometry) {}
    /// A panorama as the robot received it.
    fn on_panorama(&mut self, _robot: &RobotId, _frame: &PanoramaFrame) {}
}

/// An observer that keeps nothing.
pub struct NoObserver;

impl RobotObserver for NoObserver {}
