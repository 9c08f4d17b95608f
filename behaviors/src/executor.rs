//! One robot's behaviour tree, ticked against its clock.

use std::any::Any;

use spomp_core::{Point2, Pose2, RobotId, Time};

use crate::blackboard::{BbValue, Blackboard};
use crate::mission::{BuildError, BuildOptions, CompiledRole, build_tree};
use crate::node::{Slot, TickContext, TreeObserver};
use crate::registry::NodeRegistry;
use crate::status::Status;

/// A robot's tree and blackboard.
pub struct RobotExecutor {
    root: Slot,
    blackboard: Blackboard,
    ticks: u64,
    last_status: Status,
}

impl RobotExecutor {
    /// Builds a robot's tree from its compiled role and fills the provided blackboard entries.
    pub fn new(
        role: &CompiledRole,
        registry: &NodeRegistry,
        robot: &RobotId,
        start: Pose2,
        opts: BuildOptions,
    ) -> Result<Self, BuildError> {
        let mut blackboard = Blackboard::new();
        let root = build_tree(&role.tree, registry, &mut blackboard, opts)?;
        blackboard.set_by_name("robot_id", BbValue::Robot(robot.clone()));
        blackboard.set_by_name("start_pose", BbValue::Pose(start));
        blackboard.set_by_name("home", BbValue::Point(Point2::new(start.x, start.y)));
        for (name, value) in &role.initial {
            blackboard.set_by_name(name, value.clone());
        }
        Ok(RobotExecutor { root, blackboard, ticks: 0, last_status: Status::Idle })
    }

    /// An executor over an already built tree (tests, benchmarks).
    pub fn from_root(root: Slot, blackboard: Blackboard) -> Self {
        RobotExecutor { root, blackboard, ticks: 0, last_status: Status::Idle }
    }

    /// Ticks the root once at `now`.
    pub fn tick(&mut self, now: Time, env: &mut dyn Any, mut observer: Option<&mut dyn TreeObserver>) -> Status {
        self.ticks += 1;
        let s = {
            let mut ctx = TickContext {
                now,
                tick: self.ticks,
                blackboard: &mut self.blackboard,
                env,
                observer: shorten(&mut observer),
            };
            self.root.tick(&mut ctx)
        };
        self.blackboard.end_tick();
        self.last_status = s;
        s
    }

    /// Halts the whole tree (mission end, robot killed).
    pub fn halt(&mut self, now: Time, env: &mut dyn Any, mut observer: Option<&mut dyn TreeObserver>) {
        let mut ctx = TickContext {
            now,
            tick: self.ticks,
            blackboard: &mut self.blackboard,
            env,
            observer: shorten(&mut observer),
        };
        self.root.halt(&mut ctx);
    }

    /// Root status after the last tick.
    pub fn status(&self) -> Status {
        self.last_status
    }

    /// The blackboard.
    pub fn blackboard(&self) -> &Blackboard {
        &self.blackboard
    }

    /// The blackboard, mutable (adapters inject entries and events).
    pub fn blackboard_mut(&mut self) -> &mut Blackboard {
        &mut self.blackboard
    }

    /// The root node.
    pub fn root(&self) -> &Slot {
        &self.root
    }

    /// Ticks so far.
    pub fn ticks(&self) -> u64 {
        self.ticks
    }
}

/// Reborrows an observer for a shorter time (trait-object lifetimes behind `&mut` only shorten
/// through an explicit cast).
fn shorten<'s>(o: &'s mut Option<&mut dyn TreeObserver>) -> Option<&'s mut dyn TreeObserver> {
    o.as_deref_mut().map(|o| o as &mut dyn TreeObserver)
}
