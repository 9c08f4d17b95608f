//! Where a robot's team-state messages travel. By default over ROS 2 topics (`team/out`,
//! `team/in`: the simulator farm relays them through its modelled radio); on robots over a team
//! link between processes, which the CLI plugs in (`spomp-zenoh`; adapters never depend on
//! each other, so the node knows the link only through this trait).

use std::collections::BTreeSet;

use spomp_core::RobotId;
use spomp_teamstate::Tier;

/// A team link between robot processes, as the node drives it: it must never block.
pub trait TeamChannel: Send {
    /// The peers reachable now; messages go only to them.
    fn reachable(&self) -> BTreeSet<RobotId>;
    /// Queues a message for `to` at `tier`'s priority.
    fn send(&mut self, to: &RobotId, tier: Tier, bytes: Vec<u8>);
    /// Messages received since the last call: (sender the transport names, bytes).
    fn receive(&mut self) -> Vec<(RobotId, Vec<u8>)>;
    /// Figures for diagnostics (bytes per link and tier, drops), as JSON.
    fn stats(&self) -> serde_json::Value;
    /// Messages the link itself refused before handing them on, by reason (e.g.
    /// `unknown_sender`, `oversized`): counted with the robot's own refusals.
    fn refused(&self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }
}

/// Where a robot's resume state goes (the CLI writes it to a file atomically).
pub type StateSink = Box<dyn FnMut(Vec<u8>) + Send>;

/// The operator's tools as a robot's node serves them (the CLI implements it: it signs each
/// request as the operator's command and writes it into the robot's team state). Called on the
/// node's loop thread with the robot, so whatever it does happens between ticks.
pub trait OperatorDesk: Send {
    /// A point clicked in the robot's map frame (rviz's "Publish Point" on `/clicked_point`):
    /// what was done (`Ok`) or why not (`Err`), which the node logs on `/rosout`.
    fn on_clicked_point(
        &mut self,
        robot: &mut spomp_robot::Robot,
        now: spomp_core::Time,
        point: &spomp_ros_msgs::PointStamped,
    ) -> Result<String, String>;
    /// Once per pass of the loop (every lockstep step), before the robot ticks: requests that
    /// arrived by other ways (the live view's published points) are applied here.
    fn poll(&mut self, robot: &mut spomp_robot::Robot, now: spomp_core::Time);
}
