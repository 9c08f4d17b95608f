//! Declarations of the domain nodes of the paper's missions: goal coordination for UGVs,
//! navigation, and the UAV's explore/relay time-sharing.
//!
//! Their ports are declared here, once, so missions validate and the catalogue documents them.
//! The implementations live with the skills they call and replace these entries in the registry
//! when a build has them; until then ticking one fails loudly ("not implemented in this build"),
//! never a fake success.

use serde_json::json;
use spomp_core::RobotKind;

use crate::blackboard::PortType;
use crate::node::{Behavior, TickContext};
use crate::registry::{Category, NodeRegistry, NodeTypeSpec, PortSpec};
use crate::status::Status;

/// Names of the domain nodes declared here (not yet implemented in this build).
pub const DOMAIN_NODE_NAMES: &[&str] =
    &["navigate_to", "navigate_local", "return_home", "follow_waypoints", "seek_robot", "wait_for_sync"];

struct NotImplemented(&'static str);

impl Behavior for NotImplemented {
    fn tick(&mut self, _prev: Status, ctx: &mut TickContext<'_>) -> Status {
        ctx.blackboard.report(format!("node `{}` is not implemented in this build", self.0));
        Status::Failure
    }
}

macro_rules! declared {
    ($name:literal, $cat:expr, $desc:literal, $ports:expr) => {
        NodeTypeSpec::leaf($name, $cat, $desc, $ports, |_| Ok(Box::new(NotImplemented($name)))).unimplemented()
    };
}

/// Registers the domain node declarations (all unimplemented until a skill build replaces them).
pub fn register_domain_declarations(r: &mut NodeRegistry) {
    use Category::Action;
    use PortType::{Bool, Float, Int, Params, Point, Points, Robot, String as Str};
    use RobotKind::{Uav, Ugv};

    r.register(
        declared!(
            "navigate_to",
            Action,
            "Plans a path on the traversability graph from the robot's pose to `target`, follows it with the local planner, updates graph edges from every reachability scan and replans when the path's cost rises. Success within `tolerance_m`; Failure (reason in `failure_reason`) when there is no path, when stuck, or past the time limit (`time_limit_s`, or `time_per_m_s` × planned path length).",
            vec![
                PortSpec::input("target", Point, "Where to go (map frame)."),
                PortSpec::input("tolerance_m", Float, "Arrival radius.").with_default(json!(2.0)),
                PortSpec::optional("time_limit_s", Float, "Fixed time limit; overrides `time_per_m_s`."),
                PortSpec::input("time_per_m_s", Float, "Time limit per metre of planned path.").with_default(json!(2.0)),
                PortSpec::optional("global_planner", Params, "Global planner parameters (spomp-global-planner)."),
                PortSpec::optional("local_planner", Params, "Local planner parameters (spomp-local-planner)."),
                PortSpec::output("failure_reason", Str, "Why it failed: no_path, stuck or time_limit."),
            ]
        )
        .for_kinds(&[Ugv])
        .using_skills(&["global_planner", "local_planner", "localization"]),
    );
    r.register(
        declared!(
            "navigate_local",
            Action,
            "Drives to `target` using only panoramas and odometry (terrain analysis, local goal, DWA). Success within `tolerance_m`; Failure when no safe progress was possible for `stuck_timeout_s`; halting stops the robot.",
            vec![
                PortSpec::input("target", Point, "Where to go (map frame)."),
                PortSpec::input("tolerance_m", Float, "Arrival radius.").with_default(json!(1.0)),
                PortSpec::input("stuck_timeout_s", Float, "Give up after this long without progress.").with_default(json!(30.0)),
                PortSpec::optional("local_planner", Params, "Local planner parameters (spomp-local-planner)."),
            ]
        )
        .for_kinds(&[Ugv])
        .using_skills(&["local_planner"]),
    );
    r.register(
        declared!(
            "return_home",
            Action,
            "Drives back to the robot's start pose if it is farther than `min_distance_m`; succeeds there (or at once if already close).",
            vec![
                PortSpec::input("min_distance_m", Float, "Only move if farther than this from home.").with_default(json!(5.0)),
                PortSpec::input("tolerance_m", Float, "Arrival radius.").with_default(json!(2.0)),
            ]
        )
        .for_kinds(&[Ugv])
        .using_skills(&["global_planner", "local_planner", "localization"]),
    );
    r.register(
        declared!(
            "follow_waypoints",
            Action,
            "Flies the waypoint list (from `waypoints` or a QGroundControl `plan_file`) at `altitude_m` and `speed_mps`, resuming where it left off when halted and restarted; transfers avoid `no_fly` polygons. Succeeds when the list is exhausted.",
            vec![
                PortSpec::optional("waypoints", Points, "Waypoints (map frame)."),
                PortSpec::optional("plan_file", Str, "QGroundControl .plan file, relative to the mission."),
                PortSpec::input("altitude_m", Float, "Flight altitude.").with_default(json!(60.0)),
                PortSpec::input("speed_mps", Float, "Cruise speed.").with_default(json!(5.0)),
                PortSpec::optional("no_fly", Params, "No-fly polygons: `{zones: [[{x, y}, …], …]}`."),
                PortSpec::in_out("progress", Int, "Index of the next waypoint; share one entry between states so exploring resumes where it left off."),
            ]
        )
        .for_kinds(&[Uav])
        .using_skills(&["mapping"]),
    );
    r.register(
        declared!(
            "seek_robot",
            Action,
            "Picks the next target round-robin over alive UGVs and the basestation and flies to its last known pose (or the end of its last known path when the pose is older than `stale_after_s`), re-targeting on newer information. Succeeds on arrival within `arrive_radius_m`; writes the target.",
            vec![
                PortSpec::input("stale_after_s", Float, "A pose older than this is stale.").with_default(json!(30.0)),
                PortSpec::input("arrive_radius_m", Float, "Arrival radius (radio range for full sync).").with_default(json!(20.0)),
                PortSpec::input("speed_mps", Float, "Cruise speed.").with_default(json!(5.0)),
                PortSpec::output("target", Robot, "The robot sought."),
            ]
        )
        .for_kinds(&[Uav])
        .using_skills(&["teamstate"]),
    );
    r.register(
        declared!(
            "wait_for_sync",
            Action,
            "Hovers near (or tracks) `robot` until the team state reports sync complete with it, then succeeds; fails after `timeout_s`.",
            vec![
                PortSpec::input("robot", Robot, "Peer to sync with."),
                PortSpec::input("timeout_s", Float, "Give up after this long.").with_default(json!(45.0)),
                PortSpec::input("track", Bool, "Follow the robot while waiting.").with_default(json!(true)),
            ]
        )
        .for_kinds(&[Uav])
        .using_skills(&["teamstate"]),
    );
}
