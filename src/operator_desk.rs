//! `spomp run`'s operator interfaces (opt-in): rviz's "Publish Point" on `/clicked_point`
//! (`--clicked-point`) and Foxglove's 3-D panel "Publish point" on the live view
//! (`--live-operator`). Each point becomes the operator's "add goal" command, signed with the
//! operator's key (`operator.key.json` of `--keys`) and written into this robot's team state,
//! from where it travels to the team like any record.
//!
//! The live server hands points over on its own threads: they wait in a bounded queue until
//! the robot's loop takes them, so the team state is only ever changed between ticks.
//!
//! The command is made by an operator member of the process's own (a team state under the
//! reserved id `operator`, signed with the operator's key, as `spomp operator` makes it) and
//! handed to the robot as a sync message from the operator (`Robot::on_team_message`): the robot
//! checks and applies it exactly as one that came over the link, and the call is a seam call, so
//! a `--record` log of the robot replays with it.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

use anyhow::{Context, Result, bail};
use spomp_core::{Point2, RobotId, Time};
use spomp_robot::Robot;
use spomp_ros2::OperatorDesk;
use spomp_teamstate::{OPERATOR_ID, OperatorAction, TeamSecurity, TeamState, TeamStateParams, TierSet};
use spomp_zenoh::KeyDir;

/// Points from the live view waiting for the robot's loop, at most.
const QUEUE: usize = 64;

/// The operator's signing key, loaded for a robot that serves an operator interface; refuses
/// clearly when the key folder lacks it.
pub(crate) fn operator_key(keys: Option<&std::path::Path>, flag: &str) -> Result<Arc<TeamSecurity>> {
    let Some(dir) = keys else {
        bail!(
            "{flag} needs --keys DIR with the operator's key (operator.key.json): a goal added from a viewer is an operator command, signed with the operator's key"
        );
    };
    let keys = KeyDir::load(dir)?;
    let security = keys.operator_security().with_context(|| {
        format!("{flag}: {} holds no usable operator key (operator.key.json from `spomp keys generate`)", dir.display())
    })?;
    Ok(Arc::new(security))
}

/// A point the live view took, waiting for the loop.
pub(crate) struct Pending {
    at: Point2,
    from: String,
}

/// The desk the node polls.
pub(crate) struct Desk {
    /// The operator member: its own commands number the next one.
    member: TeamState,
    inbox: Option<Receiver<Pending>>,
}

/// Wall-clock time since the Unix epoch.
fn wall_now() -> std::time::Duration {
    std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default()
}

/// The live view's side: a handler that checks a point's frame and queues it for the desk.
pub(crate) fn live_handler(map_frame: String, queue: SyncSender<Pending>) -> spomp_live::PointHandler {
    Arc::new(move |p: &spomp_live::PublishedPoint| {
        if p.frame_id != map_frame {
            return Err(format!(
                "a point in frame `{}`; set the 3-D panel's display frame to `{map_frame}` (no transform is looked up)",
                p.frame_id
            ));
        }
        let pending = Pending { at: Point2::new(p.x, p.y), from: format!("live view {}", p.topic) };
        match queue.try_send(pending) {
            Ok(()) => Ok(format!("goal at ({:.1}, {:.1}) goes to the robot, signed as the operator's", p.x, p.y)),
            Err(TrySendError::Full(_)) => Err(format!("{QUEUE} points are waiting already; try again")),
            Err(TrySendError::Disconnected(_)) => Err("the robot has stopped".into()),
        }
    })
}

impl Desk {
    /// A desk signing with `security`, its member's team state with the mission's parameters
    /// (`spomp_robot::setup::team_params`, as the robots'); with `live`, also the queue the live
    /// view's handler ([`live_handler`]) fills.
    pub(crate) fn new(
        security: Arc<TeamSecurity>,
        live: bool,
        params: TeamStateParams,
    ) -> Result<(Desk, Option<SyncSender<Pending>>)> {
        let mut member =
            TeamState::new(RobotId::new(OPERATOR_ID), u32::MAX, params).context("the operator's team state")?;
        member.set_security(security).context("securing the operator's team state")?;
        let (queue, inbox) = if live {
            let (tx, rx) = sync_channel(QUEUE);
            (Some(tx), Some(rx))
        } else {
            (None, None)
        };
        Ok((Desk { member, inbox }, queue))
    }

    fn add_goal(&mut self, robot: &mut Robot, now: Time, at: Point2, from: &str) -> Result<String, String> {
        let action = OperatorAction::AddGoal { position: at, name: None, priority: 0, class: None };
        // Numbered above any command the robot holds and the wall clock's seconds, as
        // `spomp operator` numbers its commands (numbers order commands; a later one wins).
        let operator = RobotId::new(OPERATOR_ID);
        let held = robot.team().commands().iter().filter(|c| c.id.operator == operator).map(|c| c.id.seq).max();
        let wall = wall_now();
        let floor = u32::try_from(wall.as_secs()).unwrap_or(u32::MAX).max(held.unwrap_or(0));
        self.member.set_command_seq_floor(floor);
        // A new session per message: the robot takes each session's messages once, and a
        // `spomp operator` run in between (a session of its own) does not make ours look old.
        self.member.set_session(wall.as_nanos() as u64);
        self.member.reset_peer(robot.id());
        let id = self.member.issue_command(action, now).map_err(|e| e.to_string())?;
        let message = self
            .member
            .make_sync(robot.id(), TierSet::ALL, usize::MAX)
            .ok_or_else(|| "the operator member had nothing to send".to_string())?;
        robot
            .on_team_message(now, &operator, message.encode())
            .map_err(|e| format!("the robot refused the operator's command: {e}"))?;
        Ok(format!("goal {} added at ({:.1}, {:.1}) from {from} (operator command {id})", id.goal_id(), at.x, at.y))
    }
}

impl OperatorDesk for Desk {
    fn on_clicked_point(
        &mut self,
        robot: &mut Robot,
        now: Time,
        point: &spomp_ros_msgs::PointStamped,
    ) -> Result<String, String> {
        let at = Point2::new(point.point.x, point.point.y);
        if !(at.x.is_finite() && at.y.is_finite()) {
            return Err(format!("point ({}, {}) is not finite", at.x, at.y));
        }
        self.add_goal(robot, now, at, "the clicked-point topic")
    }

    fn poll(&mut self, robot: &mut Robot, now: Time) {
        let Some(inbox) = &self.inbox else { return };
        let pending: Vec<Pending> = inbox.try_iter().collect();
        for p in pending {
            match self.add_goal(robot, now, p.at, &p.from) {
                Ok(done) => errln!("{}: {done}", robot.id()),
                Err(why) => errln!("{}: a goal from the {} refused: {why}", robot.id(), p.from),
            }
        }
    }
}
