//! The one MCAP recorder of a run, for `spomp sim` (and its live view) and `spomp run
//! --record`: what each robot saw and did (the robot layer's `RobotObserver`, seam calls
//! included, so `spomp replay` reads either log the same way) and what only the simulator or
//! the ROS 2 node knows (states, team events and the map; commands, setpoints and transforms).

use std::collections::HashMap;
use std::io::{Seek, Write};
use std::path::PathBuf;

use anyhow::Result;
use indicatif::ProgressBar;
use spomp_behaviors::trace::TransitionRecord;
use spomp_core::panorama::DEFAULT_RANGE_SCALE_M;
use spomp_core::{
    AerialMap, ClassTable, Odometry, PanoramaFrame, PanoramaGeometry, Point2, PoseEstimate, ReachabilityScan, RobotId,
    RobotKind, Time,
};
use spomp_mcap::{RecordError, Recorder};
use spomp_robot::{RobotObserver, SeamCall};
use spomp_ros_msgs::GoalMarkerInput;
use spomp_sim::run::{RobotSnapshot, SimEvent, SimObserver};

use crate::sim_cmd::output_path;

// What `spomp run` records besides: a build with the `deploy` feature.
#[cfg(feature = "deploy")]
mod robot_node;

/// How a run is recorded (everything but the recorder itself).
pub(crate) struct ObserverSettings {
    /// At most one panorama per robot this often, nanoseconds (0: none; 1: every one).
    pub pano_every_ns: i64,
    /// Also save the recorded panoramas as depth PNGs here.
    pub panos_dir: Option<PathBuf>,
    /// The progress bar to move with simulated time.
    pub bar: Option<ProgressBar>,
    /// Print every node transition.
    pub trace: bool,
    /// Record every seam call (`spomp sim --replayable`; `spomp run --record` always).
    pub replayable: bool,
    /// The world's class table (the map's traversability), for the map layers.
    pub classes: Option<ClassTable>,
}

/// A goal as the team-level events tell it, for the goal markers.
struct GoalState {
    id: String,
    position: Point2,
    claimed_by: Option<String>,
    visited_by: Option<String>,
    cancelled: bool,
}

/// Records a run to MCAP (and through it the live view) and drives the progress bar.
pub(crate) struct LogObserver<W: Write + Seek> {
    recorder: Option<Recorder<W>>,
    error: Option<anyhow::Error>,
    settings: ObserverSettings,
    last_pano: HashMap<RobotId, i64>,
    last_second: i64,
    /// The goals in the order they were identified.
    goals: Vec<GoalState>,
    /// The run's setup, written once a lockstep farm said how the heavy skills run.
    #[cfg(feature = "deploy")]
    pending_info: Option<spomp_mcap::RunInfo>,
}

impl<W: Write + Seek> LogObserver<W> {
    /// Records into `recorder` (none: only the progress bar and the trace).
    pub fn new(recorder: Option<Recorder<W>>, settings: ObserverSettings) -> Self {
        LogObserver {
            recorder,
            error: None,
            settings,
            last_pano: HashMap::new(),
            last_second: -1,
            goals: Vec::new(),
            #[cfg(feature = "deploy")]
            pending_info: None,
        }
    }

    /// The recorder, to be finished; the first error met while recording, if any.
    pub fn finish(self) -> Result<Option<Recorder<W>>> {
        match self.error {
            Some(e) => Err(e),
            None => Ok(self.recorder),
        }
    }

    fn record(&mut self, f: impl FnOnce(&mut Recorder<W>) -> Result<(), RecordError>) {
        if self.error.is_some() {
            return;
        }
        if let Some(rec) = self.recorder.as_mut()
            && let Err(e) = f(rec)
        {
            self.error = Some(e.into());
        }
    }

    /// Follows a goal event; true if the goals changed.
    fn follow_goals(&mut self, event: &SimEvent) -> bool {
        fn find(goals: &[GoalState], id: &str) -> Option<usize> {
            goals.iter().position(|g| g.id == id)
        }
        match event {
            SimEvent::GoalIdentified { goal, position, .. } => {
                if find(&self.goals, goal).is_some() {
                    return false;
                }
                self.goals.push(GoalState {
                    id: goal.clone(),
                    position: Point2::new(position[0], position[1]),
                    claimed_by: None,
                    visited_by: None,
                    cancelled: false,
                });
            }
            SimEvent::GoalClaimed { goal, by } => {
                let Some(k) = find(&self.goals, goal) else { return false };
                self.goals[k].claimed_by = Some(by.clone());
            }
            SimEvent::GoalReleased { goal, by } => {
                let Some(k) = find(&self.goals, goal) else { return false };
                if self.goals[k].claimed_by.as_ref() != Some(by) {
                    return false;
                }
                self.goals[k].claimed_by = None;
            }
            SimEvent::GoalVisited { goal, by } => {
                let Some(k) = find(&self.goals, goal) else { return false };
                self.goals[k].visited_by = Some(by.clone());
            }
            SimEvent::GoalCancelled { goal, .. } => {
                let Some(k) = find(&self.goals, goal) else { return false };
                self.goals[k].cancelled = true;
            }
            SimEvent::RobotKilled { .. }
            | SimEvent::RobotStuck { .. }
            | SimEvent::MissionEnded { .. }
            | SimEvent::OperatorCommand { .. }
            | SimEvent::OperatorAcknowledged { .. } => return false,
        }
        true
    }
}

impl<W: Write + Seek> RobotObserver for LogObserver<W> {
    fn wants_seam(&self) -> bool {
        self.settings.replayable && self.recorder.is_some()
    }

    fn on_seam(&mut self, robot: &RobotId, now: Time, call: &SeamCall) {
        if self.settings.replayable {
            self.record(|r| r.seam(robot.as_str(), now, call));
        }
    }

    fn on_odometry(&mut self, robot: &RobotId, odom: &Odometry) {
        self.record(|r| r.odometry(robot.as_str(), odom));
    }

    fn on_panorama(&mut self, robot: &RobotId, frame: &PanoramaFrame) {
        if self.settings.pano_every_ns <= 0 {
            return;
        }
        let last = self.last_pano.get(robot).copied();
        if last.is_some_and(|t| frame.stamp.nanos - t < self.settings.pano_every_ns) {
            return;
        }
        self.last_pano.insert(robot.clone(), frame.stamp.nanos);
        self.record(|r| {
            r.sensor_mount(robot.as_str(), frame.stamp, frame.sensor_height_m)?;
            r.panorama(robot.as_str(), frame.stamp, &frame.depth, Some(&frame.semantic))
        });
        if let Some(dir) = &self.settings.panos_dir {
            let saved = output_path(dir, &format!("{robot}-{:06}.png", frame.stamp.nanos / 1_000_000_000))
                .and_then(|path| crate::world_cmd::save_depth_png(&frame.depth, DEFAULT_RANGE_SCALE_M, &path));
            if let Err(e) = saved {
                self.error.get_or_insert(e);
            }
        }
    }

    fn on_scan(&mut self, scan: &ReachabilityScan) {
        self.record(|r| r.reachability(scan));
    }

    fn on_path(&mut self, robot: &RobotId, now: Time, path: &[Point2]) {
        self.record(|r| r.path(robot.as_str(), now, path));
    }

    fn on_transitions(&mut self, robot: &RobotId, records: &[TransitionRecord]) {
        if self.settings.trace {
            for t in records {
                let print = || out!("{:>9.1}s {robot} {} {} -> {}", t.time.as_secs_f64(), t.path, t.from, t.to);
                match &self.settings.bar {
                    Some(bar) => bar.suspend(print),
                    None => print(),
                }
            }
        }
        self.record(|r| r.transitions(robot.as_str(), records));
    }

    fn on_problem(&mut self, robot: &RobotId, now: Time, message: &str) {
        self.record(|r| r.problem(robot.as_str(), now, message));
    }
}

impl<W: Write + Seek> SimObserver for LogObserver<W> {
    fn on_state(&mut self, robot: &RobotId, now: Time, state: &RobotSnapshot) {
        let second = now.nanos / 1_000_000_000;
        if second != self.last_second {
            self.last_second = second;
            if let Some(bar) = &self.settings.bar {
                bar.set_position(second.max(0) as u64);
            }
        }
        self.record(|r| {
            r.pose(robot.as_str(), now, state.truth, state.z_m)?;
            r.tf(robot.as_str(), now, state.truth, state.z_m)?;
            if let Some(est) = state.estimate {
                r.estimate(robot.as_str(), &PoseEstimate { stamp: now, ..est })?;
            }
            if state.kind == RobotKind::Ugv {
                r.command(robot.as_str(), now, state.command)?;
            }
            Ok(())
        });
    }

    fn on_terrain(&mut self, robot: &RobotId, stamp: Time, geometry: PanoramaGeometry, obstacle: &[bool]) {
        // Same rate as the panoramas: only for the frame just recorded.
        if self.settings.pano_every_ns > 0 && self.last_pano.get(robot) == Some(&stamp.nanos) {
            self.record(|r| r.obstacle_panorama(robot.as_str(), stamp, geometry, obstacle));
        }
    }

    fn on_event(&mut self, now: Time, event: &SimEvent) {
        self.record(|r| r.json("/team/events", now, event));
        if self.follow_goals(event) {
            let goals = std::mem::take(&mut self.goals);
            self.record(|r| {
                r.goals(
                    now,
                    goals.iter().map(|g| GoalMarkerInput {
                        id: &g.id,
                        position: g.position,
                        claimed_by: g.claimed_by.as_deref(),
                        visited_by: g.visited_by.as_deref(),
                        cancelled: g.cancelled,
                        priority: 0,
                    }),
                )
            });
            self.goals = goals;
        }
    }

    fn on_map(&mut self, _robot: &RobotId, now: Time, map: &AerialMap) {
        let Some(classes) = self.settings.classes.as_ref() else { return };
        if self.error.is_some() {
            return;
        }
        if let Some(rec) = self.recorder.as_mut()
            && let Err(e) = rec.map(now, map, classes)
        {
            self.error = Some(e.into());
        }
    }
}
