//! Recovery behaviours for a UGV whose drive made no progress (as Nav2 has them): `back_up`
//! reverses a short straight distance over ground the latest panorama shows safe, `spin` turns
//! in place by an angle. The generic `wait` completes the set. A mission runs them when
//! `navigate_to` reports `no_progress` (see `missions/subtrees/goal-cycle.yaml`), then drives
//! again.
//!
//! Normal control never reverses (DWA samples forward speeds only, as the paper's controller);
//! backing up is a recovery motion only, and never blind: each tick the whole remaining line
//! behind the robot must lie in the safe region of the latest terrain analysis
//! (`Dwa::reverse_step`), else the node stops and fails.

use serde_json::json;
use spomp_core::{RobotKind, Time, Twist2, normalize_angle};

use super::Ctx;
use crate::runtime::RobotRuntime;
use spomp_behaviors::Status;
use spomp_behaviors::blackboard::{Binding, PortType};
use spomp_behaviors::node::Behavior;
use spomp_behaviors::registry::{Category, NodeError, NodeRegistry, NodeTypeSpec, PortBindings, PortSpec};

/// Registers `back_up` and `spin`.
pub fn register_recovery(r: &mut NodeRegistry<RobotRuntime>) {
    use Category::Action;
    use PortType::Float;
    use RobotKind::Ugv;
    r.register(
        NodeTypeSpec::leaf(
            "back_up",
            Action,
            "Recovery: reverses straight for `distance_m` (measured on odometry) at up to `speed_mps`, then stops and succeeds. Every tick the line from the robot to the rest of the distance behind it (plus the controller's look-ahead) must lie in the safe region of the latest panorama; when it does not (an obstacle behind, or no terrain analysis yet) the robot stops and the node fails, as it does after `timeout_s` (the motion refused, e.g. wedged against an obstacle behind too). Normal driving never reverses; only this node does.",
            vec![
                PortSpec::input("distance_m", Float, "How far to back up, metres.").with_default(json!(1.5)),
                PortSpec::input("speed_mps", Float, "Reverse speed, m/s (the controller's `max_speed_mps` caps it).")
                    .with_default(json!(0.3)),
                PortSpec::input("timeout_s", Float, "Give up after this long, seconds.").with_default(json!(15.0)),
            ],
            |p| Ok(Box::new(BackUp::new(p)?)),
        )
        .for_kinds(&[Ugv])
        .using_skills(&["local_planner"]),
    );
    r.register(
        NodeTypeSpec::leaf(
            "spin",
            Action,
            "Recovery: turns in place by `angle_deg` (positive: counter-clockwise, to the left; measured on odometry) at `turn_rate_radps`, then stops and succeeds; fails after `timeout_s`. A round footprint sweeps no new ground turning in place; for another footprint set `min_clearance_m` (half its diagonal): the node then fails at once, without moving, when the latest safe region shows an obstacle nearer than that to the robot.",
            vec![
                PortSpec::input("angle_deg", Float, "Angle to turn, degrees (positive: counter-clockwise).")
                    .with_default(json!(90.0)),
                PortSpec::input("turn_rate_radps", Float, "Turn rate, rad/s (the controller's `max_turn_rate_radps` caps it).")
                    .with_default(json!(0.5)),
                PortSpec::input("min_clearance_m", Float, "Clearance to obstacles needed to turn, metres; 0: no check (a round robot).")
                    .with_default(json!(0.0)),
                PortSpec::input("timeout_s", Float, "Give up after this long, seconds.").with_default(json!(20.0)),
            ],
            |p| Ok(Box::new(Spin::new(p)?)),
        )
        .for_kinds(&[Ugv])
        .using_skills(&["local_planner"]),
    );
}

/// A finite number from a port (its declared default is applied by the loader), or a report.
fn finite(binding: &Binding, ctx: &mut Ctx<'_>, node: &str, port: &str, positive: bool) -> Option<f64> {
    let v = binding.get::<f64>(ctx.blackboard);
    match v {
        Some(v) if v.is_finite() && (!positive || v > 0.0) => Some(v),
        _ => {
            let rule = if positive { "a finite positive number" } else { "a finite number" };
            ctx.blackboard.report(format!("{node}: `{port}` must be {rule}, got {v:?}"));
            None
        }
    }
}

/// Stops the robot and reports why the node failed.
fn give_up(ctx: &mut Ctx<'_>, node: &str, why: String) -> Status {
    ctx.env.command_velocity(Twist2::ZERO);
    ctx.blackboard.report(format!("{node}: {why}"));
    Status::Failure
}

struct BackUp {
    distance: Binding,
    speed: Binding,
    timeout: Binding,
    /// Odometry position at the start, and when the node gives up.
    from: Option<spomp_core::Point2>,
    until: Time,
}

impl BackUp {
    fn new(p: &PortBindings) -> Result<Self, NodeError> {
        Ok(BackUp {
            distance: p.get("distance_m")?,
            speed: p.get("speed_mps")?,
            timeout: p.get("timeout_s")?,
            from: None,
            until: Time::ZERO,
        })
    }
}

impl Behavior<RobotRuntime> for BackUp {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "back_up";
        let (Some(distance_m), Some(speed_mps), Some(timeout_s)) = (
            finite(&self.distance, ctx, NODE, "distance_m", true),
            finite(&self.speed, ctx, NODE, "speed_mps", true),
            finite(&self.timeout, ctx, NODE, "timeout_s", true),
        ) else {
            ctx.env.command_velocity(Twist2::ZERO);
            return Status::Failure;
        };
        let Some(odom) = ctx.env.odometry() else {
            return give_up(ctx, NODE, "no odometry".into());
        };
        if prev != Status::Running {
            self.from = Some(odom.pose.position());
            self.until = ctx.now + std::time::Duration::from_secs_f64(timeout_s);
        }
        let moved = self.from.map_or(0.0, |f| f.distance(odom.pose.position()));
        if moved >= distance_m {
            ctx.env.command_velocity(Twist2::ZERO);
            return Status::Success;
        }
        if ctx.now >= self.until {
            return give_up(ctx, NODE, format!("backed up only {moved:.2} of {distance_m:.2} m in {timeout_s:.0} s"));
        }
        let cmd = ctx.env.nav().and_then(|nav| {
            let view = nav.view()?;
            let robot = view.odom_pose.between(odom.pose);
            nav.dwa().reverse_step(odom.twist, robot, distance_m - moved, speed_mps, &view.region)
        });
        match cmd {
            Some(cmd) => {
                ctx.env.command_velocity(cmd);
                Status::Running
            }
            None => give_up(
                ctx,
                NODE,
                format!("the ground {:.1} m behind is not known safe; not backing up blind", distance_m - moved),
            ),
        }
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        ctx.env.command_velocity(Twist2::ZERO);
    }
}

struct Spin {
    angle: Binding,
    rate: Binding,
    clearance: Binding,
    timeout: Binding,
    /// Yaw turned so far (odometry), the last odometry yaw, and when the node gives up.
    turned: f64,
    last_yaw: Option<f64>,
    until: Time,
}

impl Spin {
    fn new(p: &PortBindings) -> Result<Self, NodeError> {
        Ok(Spin {
            angle: p.get("angle_deg")?,
            rate: p.get("turn_rate_radps")?,
            clearance: p.get("min_clearance_m")?,
            timeout: p.get("timeout_s")?,
            turned: 0.0,
            last_yaw: None,
            until: Time::ZERO,
        })
    }
}

impl Behavior<RobotRuntime> for Spin {
    fn tick(&mut self, prev: Status, ctx: &mut Ctx<'_>) -> Status {
        const NODE: &str = "spin";
        let (Some(angle_deg), Some(rate), Some(min_clearance_m), Some(timeout_s)) = (
            finite(&self.angle, ctx, NODE, "angle_deg", false),
            finite(&self.rate, ctx, NODE, "turn_rate_radps", true),
            finite(&self.clearance, ctx, NODE, "min_clearance_m", false),
            finite(&self.timeout, ctx, NODE, "timeout_s", true),
        ) else {
            ctx.env.command_velocity(Twist2::ZERO);
            return Status::Failure;
        };
        let Some(odom) = ctx.env.odometry() else {
            return give_up(ctx, NODE, "no odometry".into());
        };
        if prev != Status::Running {
            self.turned = 0.0;
            self.last_yaw = None;
            self.until = ctx.now + std::time::Duration::from_secs_f64(timeout_s);
            if min_clearance_m > 0.0 {
                let clearance = ctx.env.nav().and_then(|nav| {
                    let view = nav.view()?;
                    view.region.clearance_at(view.odom_pose.between(odom.pose).position())
                });
                if clearance.is_none_or(|c| f64::from(c) < min_clearance_m) {
                    return give_up(
                        ctx,
                        NODE,
                        format!("less than {min_clearance_m:.2} m of clearance to turn in place"),
                    );
                }
            }
        }
        if let Some(last) = self.last_yaw {
            self.turned += normalize_angle(odom.pose.yaw - last);
        }
        self.last_yaw = Some(odom.pose.yaw);
        let goal = angle_deg.to_radians();
        if self.turned.abs() >= goal.abs() {
            ctx.env.command_velocity(Twist2::ZERO);
            return Status::Success;
        }
        if ctx.now >= self.until {
            return give_up(
                ctx,
                NODE,
                format!("turned only {:.0} of {angle_deg:.0} degrees in {timeout_s:.0} s", self.turned.to_degrees()),
            );
        }
        let cap = ctx.env.nav().map_or(rate, |n| n.dwa().params().max_turn_rate_radps);
        ctx.env.command_velocity(Twist2 { v: 0.0, omega: rate.min(cap).copysign(goal) });
        Status::Running
    }

    fn halt(&mut self, ctx: &mut Ctx<'_>) {
        ctx.env.command_velocity(Twist2::ZERO);
    }
}
