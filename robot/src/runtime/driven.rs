//! A runtime with the inputs an adapter drives, for a harness that ticks a tree over a runtime
//! without a [`crate::Robot`] (tests, benches, tools).
//!
//! The inputs (odometry, panoramas, external poses, camera tiles, upkeep, background work)
//! are not methods a node can reach: the nodes get `&mut RobotRuntime`, where they are
//! crate-private, and only [`crate::Robot`] (through its seam) or this wrapper, which owns the
//! runtime, calls them.

use std::ops::{Deref, DerefMut};
use std::sync::Arc;

use spomp_core::{MapTile, Odometry, PanoramaFrame, PoseEstimate, Time};

use super::{FinishedWork, JoinFn, RobotRuntime, SkillWork};

/// A [`RobotRuntime`] owned with its adapter inputs; reads and node calls go through to it.
pub struct DrivenRuntime(RobotRuntime);

impl From<RobotRuntime> for DrivenRuntime {
    fn from(runtime: RobotRuntime) -> Self {
        DrivenRuntime(runtime)
    }
}

impl Deref for DrivenRuntime {
    type Target = RobotRuntime;
    fn deref(&self) -> &RobotRuntime {
        &self.0
    }
}

impl DerefMut for DrivenRuntime {
    fn deref_mut(&mut self) -> &mut RobotRuntime {
        &mut self.0
    }
}

impl DrivenRuntime {
    /// The whole team database, as a link and the mission set-up change it (sync messages,
    /// mission goals, the robot's published path end): what `Robot` does through its seam, for
    /// a harness without one. Nodes get `RobotRuntime::team_mut` only.
    pub fn team_state_mut(&mut self) -> &mut spomp_teamstate::TeamState {
        self.0.team_state_mut()
    }

    /// Clears this tick's outputs; call before the tree is ticked.
    pub fn begin_tick(&mut self) {
        self.0.begin_tick();
    }

    /// A pose from outside (GPS, a surveyed position, simulator truth).
    pub fn on_external_pose(&mut self, estimate: PoseEstimate) {
        self.0.on_external_pose(estimate);
    }

    /// New odometry (robot frame).
    pub fn on_odometry(&mut self, odom: Odometry) {
        self.0.on_odometry(odom);
    }

    /// A new depth + semantic panorama.
    pub fn on_panorama(&mut self, frame: Arc<PanoramaFrame>) {
        self.0.on_panorama(frame);
    }

    /// Aerial-map tiles from the robot's own camera at `now`.
    pub fn on_camera_tiles(&mut self, tiles: &[MapTile], now: Time) {
        self.0.on_camera_tiles(tiles, now);
    }

    /// Background upkeep at `now` (team-state clock, global planner).
    pub fn maintain(&mut self, now: Time) {
        self.0.maintain(now);
    }

    /// Runs the heavy skills as work taken with [`Self::take_work`] instead of inline.
    pub fn set_background_skills(&mut self, on: bool) {
        self.0.set_background_skills(on);
    }

    /// Runs a panorama's localization and terrain analysis side by side through `join`.
    pub fn set_perception_join(&mut self, join: Option<JoinFn>) {
        self.0.set_perception_join(join);
    }

    /// The work due now (background skills).
    pub fn take_work(&mut self, now: Time) -> Vec<SkillWork> {
        self.0.take_work(now)
    }

    /// A finished work back from wherever it ran.
    pub fn finish_work(&mut self, work: FinishedWork) {
        self.0.finish_work(work);
    }

    /// The runtime, to hand to a tree's tick.
    pub fn runtime_mut(&mut self) -> &mut RobotRuntime {
        &mut self.0
    }
}
