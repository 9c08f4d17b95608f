//! What `spomp run --record` records besides what every robot records: the ROS 2 node's
//! commands, setpoints, transforms and external poses (the `deploy` feature).

use std::io::{Seek, Write};

use spomp_core::{FlightCommand, PoseEstimate, Time, Twist2};
use spomp_mcap::{Recorder, RunInfo};

use super::LogObserver;

impl<W: Write + Seek> LogObserver<W> {
    /// Writes `info` when a lockstep farm's hello says how the heavy skills run.
    pub fn with_pending_info(mut self, info: Option<RunInfo>) -> Self {
        self.pending_info = info;
        self
    }

    /// Writes the run's setup now.
    pub fn run_info(&mut self, info: &RunInfo) {
        self.record(|r| r.run_info(info));
    }

    /// The recorder and the first error met while recording, if any.
    pub fn into_parts(self) -> (Option<Recorder<W>>, Option<anyhow::Error>) {
        (self.recorder, self.error)
    }
}

impl<W: Write + Seek> spomp_ros2::RunObserver for LogObserver<W> {
    fn on_lockstep(&mut self, background_skills: bool) {
        if let Some(info) = self.pending_info.take() {
            let info = RunInfo { background_skills, ..info };
            self.run_info(&info);
        }
    }

    fn on_external_pose(&mut self, robot: &str, estimate: &PoseEstimate) {
        self.record(|r| r.pose_in(robot, estimate.stamp, estimate.pose, 0.0));
    }

    fn on_tf(&mut self, topic: &str, time: Time, msg: &spomp_ros_msgs::TfMessage) {
        self.record(|r| r.transform(topic, time, msg));
    }

    fn on_frame_mismatch(&mut self, robot: &str, message: &str) {
        errln!("warning: robot {robot}: {message}");
    }

    fn on_operator(&mut self, _robot: &str, now: Time, event: &spomp_robot::operator_log::OperatorEvent) {
        self.record(|r| r.json("/team/events", now, event));
    }

    fn on_command(&mut self, robot: &str, now: Time, cmd: Twist2) {
        self.record(|r| r.command(robot, now, cmd));
    }

    fn on_flight(&mut self, robot: &str, now: Time, cmd: Option<&FlightCommand>) {
        let topic = format!("/{robot}/setpoint");
        self.record(|r| r.json(&topic, now, &cmd));
    }

    fn on_estimate(&mut self, robot: &str, estimate: &PoseEstimate) {
        self.record(|r| r.estimate(robot, estimate));
    }
}
