//! A tree and its blackboard, ticked against a clock: the engine's executor. It knows nothing
//! of missions; the mission language builds one from a compiled role
//! (`mission::build_executor`).

use spomp_core::Time;

use crate::blackboard::Blackboard;
use crate::node::{Slot, TickContext, TreeObserver};
use crate::status::Status;

/// A tree acting on an environment `E` (a robot runtime), with its blackboard.
pub struct TreeExecutor<E = ()> {
    root: Slot<E>,
    blackboard: Blackboard,
    ticks: u64,
    last_status: Status,
}

impl<E> TreeExecutor<E> {
    /// An executor over a built tree and the blackboard its ports were bound to.
    pub fn from_root(root: Slot<E>, blackboard: Blackboard) -> Self {
        TreeExecutor { root, blackboard, ticks: 0, last_status: Status::Idle }
    }

    /// Ticks the root once at `now`.
    pub fn tick(&mut self, now: Time, env: &mut E, mut observer: Option<&mut dyn TreeObserver>) -> Status {
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

    /// Halts the whole tree (mission end, robot killed); afterwards [`TreeExecutor::status`]
    /// is `Idle`, like the root.
    pub fn halt(&mut self, now: Time, env: &mut E, mut observer: Option<&mut dyn TreeObserver>) {
        let mut ctx = TickContext {
            now,
            tick: self.ticks,
            blackboard: &mut self.blackboard,
            env,
            observer: shorten(&mut observer),
        };
        self.root.halt(&mut ctx);
        self.last_status = self.root.status();
    }

    /// The root's status: after the last tick, or `Idle` after a halt.
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
    pub fn root(&self) -> &Slot<E> {
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
