//! `spomp sim --ros2`: the simulator as a ROS 2 robot farm. The simulator moves the bodies and
//! renders the sensors; `spomp run` processes (one per driven robot) decide what the robots do.

use std::net::IpAddr;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use spomp_behaviors::mission::MissionFile;
use spomp_core::{
    FlightCommand, GridSpec, MapTile, Odometry, PanoramaFrame, PoseEstimate, RobotId, RobotKind, Time, Twist2,
};
use spomp_ros2::{DdsSettings, FarmLink};
use spomp_sim::run::{DrivenTeamMessage, ExternalDrivers, RealTimePacer};
use spomp_teamstate::GoalView;

/// How the farm runs.
#[derive(Debug, Clone)]
pub struct FarmOptions {
    /// Simulated seconds per wall second.
    pub rate: f64,
    /// DDS domain (default: the first driven robot's `ros2.domain_id`).
    pub domain_id: Option<u16>,
    /// Interfaces DDS may use (empty: every one).
    pub interfaces: Vec<IpAddr>,
    /// Robots to drive (empty: every UGV and UAV).
    pub drive: Vec<String>,
    /// How long to wait for the `spomp run` processes before the clock starts, wall seconds.
    pub wait_s: f64,
}

/// The farm's side of the simulation.
pub struct FarmDrivers {
    link: FarmLink,
    driven: Vec<String>,
    /// Real time × rate, from the first step after every robot reported.
    pacer: RealTimePacer,
    started: bool,
    wait_s: f64,
}

impl FarmDrivers {
    /// A farm for `mission`: publishes the driven robots' sensors and `/clock`.
    pub fn new(mission: &MissionFile, options: &FarmOptions) -> Result<Self> {
        let driven: Vec<String> = if options.drive.is_empty() {
            mission.team.iter().filter(|r| r.kind != RobotKind::Basestation).map(|r| r.id.clone()).collect()
        } else {
            options.drive.clone()
        };
        let robots: Vec<(String, Option<spomp_behaviors::mission::schema::Ros2Spec>)> = driven
            .iter()
            .map(|id| (id.clone(), mission.team.iter().find(|r| &r.id == id).and_then(|r| r.ros2.clone())))
            .collect();
        let first = robots.first().and_then(|(_, s)| s.clone()).unwrap_or_default();
        let mut dds = DdsSettings::for_robot(&first).map_err(anyhow::Error::msg)?;
        if let Some(d) = options.domain_id {
            dds.domain_id = d;
        }
        if !options.interfaces.is_empty() {
            dds.interfaces = options.interfaces.clone();
        }
        let link = FarmLink::new(&dds, &robots).context("starting the farm's ROS 2 node")?;
        errln!(
            "spomp sim --ros2: driving {} over DDS domain {} at {}× real time; start `spomp run MISSION --robot ID --use-sim-time` for each",
            driven.join(", "),
            dds.domain_id,
            options.rate
        );
        Ok(FarmDrivers {
            link,
            driven,
            pacer: RealTimePacer::new(options.rate),
            started: false,
            wait_s: options.wait_s,
        })
    }

    /// Publishes `/clock` at zero until every driven robot reports its status (or the wait ends).
    fn wait_for_robots(&mut self) {
        let deadline = Instant::now() + Duration::from_secs_f64(self.wait_s);
        loop {
            self.link.publish_clock(Time::ZERO);
            self.link.poll(Time::ZERO);
            let missing: Vec<&str> =
                self.driven.iter().filter(|id| self.link.tree_status(id).is_empty()).map(String::as_str).collect();
            if missing.is_empty() {
                break;
            }
            if Instant::now() >= deadline {
                errln!(
                    "spomp sim --ros2: starting without {} (no status after {:.0} s)",
                    missing.join(", "),
                    self.wait_s
                );
                break;
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
}

impl ExternalDrivers for FarmDrivers {
    fn drives(&self, robot: &RobotId) -> bool {
        self.driven.iter().any(|d| d == robot.as_str())
    }

    fn begin_step(&mut self, now: Time) {
        if !self.started {
            self.wait_for_robots();
            self.started = true;
        }
        self.pacer.wait_until(now);
        self.link.publish_clock(now);
        self.link.poll(now);
    }

    fn odometry(&mut self, robot: &RobotId, odom: &Odometry) {
        self.link.publish_odometry(robot.as_str(), odom);
    }

    fn panorama(&mut self, robot: &RobotId, frame: &PanoramaFrame) {
        self.link.publish_panorama(robot.as_str(), frame);
    }

    fn pose(&mut self, robot: &RobotId, estimate: &PoseEstimate, z_m: f64) {
        self.link.publish_pose(robot.as_str(), estimate, z_m);
    }

    fn camera_tiles(&mut self, robot: &RobotId, now: Time, tiles: &[MapTile], grid: &GridSpec) {
        self.link.publish_camera_tiles(robot.as_str(), now, tiles, grid);
    }

    fn command(&mut self, robot: &RobotId, now: Time) -> Option<Twist2> {
        self.link.command(robot.as_str(), now)
    }

    fn flight(&mut self, robot: &RobotId, now: Time) -> Option<FlightCommand> {
        self.link.setpoint(robot.as_str(), now)
    }

    fn take_team_messages(&mut self) -> Vec<DrivenTeamMessage> {
        self.link
            .take_team_packets()
            .into_iter()
            .map(|p| DrivenTeamMessage { from: RobotId::new(&p.from), to: RobotId::new(&p.to), bytes: p.bytes })
            .collect()
    }

    fn deliver_team_message(&mut self, to: &RobotId, from: &RobotId, bytes: &[u8]) {
        self.link.deliver_team(to.as_str(), from.as_str(), bytes);
    }

    fn goals(&self, robot: &RobotId) -> &[GoalView] {
        self.link.goals(robot.as_str())
    }

    fn tree_done(&self, robot: &RobotId) -> bool {
        matches!(self.link.tree_status(robot.as_str()), "success" | "failure")
    }
}
