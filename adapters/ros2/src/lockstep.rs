//! Lockstep between a simulator farm and the `spomp run` processes that drive its robots: the
//! farm's simulated time advances only when every driven robot has answered the step.
//!
//! DDS orders the samples of one writer on one reliable topic, and nothing across topics. So the
//! farm hands each robot everything of a step on one topic, `<ns>/lockstep/in`, in the order the
//! in-process simulator makes the same calls on a robot's seam (push inputs; exchange background
//! work; the radio's team-state messages out and in; maintain and tick), and the robot answers on
//! `<ns>/lockstep/out`. Inputs travel exactly (CDR of spomp's own types, not the lossy ROS images
//! and quaternions), so a robot in its own process decides bit for bit what the same robot decides
//! inside the simulator. A robot's step ends with a [`StepDone`]: its commands, what its tree did,
//! and its view of the goals — all the farm needs to move the body and keep the run's summary.

use std::time::{Duration, Instant};

use ros2_client::qos::{History, QosProfile};
use ros2_client::{Publisher, Subscription};
use serde::{Deserialize, Serialize};
use spomp_core::{FlightCommand, MapTile, Odometry, PanoramaFrame, PoseEstimate, RobotId, Time, Twist2};
use spomp_ros_msgs::RosMessage;
use spomp_teamstate::GoalView;

use crate::dds::{DdsError, DdsNode};
use crate::topics::TopicNames;

/// Version of the messages below; a farm and a robot of different versions refuse each other.
pub const PROTOCOL: u32 = 1;

/// Samples each lockstep topic keeps until they are acknowledged: far more than one step's
/// calls (a step is at most a few dozen), far fewer than would hold many panoramas in memory.
const LOCKSTEP_DEPTH: usize = 256;

/// Reliable, in order, nothing dropped while the reader keeps up (it answers every step).
pub fn lockstep_qos() -> QosProfile {
    QosProfile::publisher_default().history(History::KeepLast { depth: LOCKSTEP_DEPTH })
}

/// The farm's lockstep topic to a robot (robot `id` with its `ros2:` names).
pub fn in_topic(names: &TopicNames) -> String {
    format!("{}/lockstep/in", names.namespace())
}

/// The robot's lockstep topic back to the farm.
pub fn out_topic(names: &TopicNames) -> String {
    format!("{}/lockstep/out", names.namespace())
}

/// What a farm tells a robot once, before the first step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    /// [`PROTOCOL`] of the farm.
    pub protocol: u32,
    /// The run's seed: the robot's random stream must be seeded alike.
    pub seed: u64,
    /// The simulator's skill-latency model (perception, planner), seconds; `None`: the heavy
    /// skills run inline, within the robot's calls.
    pub skill_latency_s: Option<(f64, f64)>,
}

/// One call of a step, farm → robot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Op {
    /// Before the first step (repeated until answered).
    Hello(Hello),
    /// A step begins at this simulated time.
    Begin(Time),
    /// `on_odometry`.
    Odometry(Odometry),
    /// `on_external_pose` (GNSS, a surveyed position, or ground truth where the mission asks).
    ExternalPose(PoseEstimate),
    /// `on_panorama`.
    Panorama(PanoramaFrame),
    /// `on_camera_tiles` (a UAV's camera this step).
    CameraTiles(Vec<MapTile>),
    /// Background work: results due back by now, then the work the robot has due.
    ExchangeWork,
    /// `team_message_for(to, tiers, budget)`: the robot answers [`Reply::TeamOut`].
    TeamOut {
        /// Addressee.
        to: RobotId,
        /// Tiers the radio link allows, as bits (see `spomp_teamstate::TierSet::bits`).
        tiers: u8,
        /// Bytes the link may carry.
        budget_bytes: u64,
    },
    /// `on_team_message`: what the radio delivered.
    TeamIn {
        /// Sender.
        from: RobotId,
        /// The bytes.
        bytes: Vec<u8>,
    },
    /// Maintain and tick when due; the robot answers [`Reply::Done`].
    Tick,
    /// `halt`: the robot was killed.
    Halt,
    /// The run is over.
    End,
}

/// A farm's call with its number (consecutive from the first after [`Op::Hello`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LockstepIn {
    /// Call number: 0 for hellos, then 1, 2, … (a gap means a lost call).
    pub seq: u64,
    /// The call.
    pub op: Op,
}

/// A robot's answer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Reply {
    /// The hello was taken: the robot follows the farm's steps.
    Ready,
    /// The robot cannot follow the farm (a different seed or protocol): why.
    Refused(String),
    /// The answer to [`Op::TeamOut`].
    TeamOut(Option<Vec<u8>>),
    /// The step is done.
    Done(Box<StepDone>),
}

/// What a robot did in a step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepDone {
    /// The step's simulated time.
    pub now: Time,
    /// Whether the tree ticked (a tick was due).
    pub ticked: bool,
    /// `command()` after the step.
    pub command: Option<Twist2>,
    /// `flight()` after the step.
    pub flight: Option<FlightCommand>,
    /// The robot's estimate right after this step's panorama, if one came.
    pub estimate_after_panorama: Option<PoseEstimate>,
    /// The robot's estimate at the end of the step.
    pub estimate: Option<PoseEstimate>,
    /// The tree's status (`idle`, `running`, `success`, `failure`).
    pub tree: String,
    /// Nodes (depth-first ids) whose status changed in the tick.
    pub transitioned: Vec<u32>,
    /// Problems nodes and skills reported in the tick.
    pub problems: Vec<String>,
    /// The robot's view of the goals.
    pub goals: Vec<GoalView>,
}

/// A robot's answer with the call number it answers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LockstepOut {
    /// The robot.
    pub robot: String,
    /// Number of the call answered.
    pub seq: u64,
    /// The answer.
    pub reply: Reply,
}

impl RosMessage for LockstepIn {
    const TYPE_NAME: &'static str = "spomp_msgs/msg/LockstepIn";
    const DEFINITION: &'static str = "# spomp lockstep call (CDR of spomp_ros2::lockstep::LockstepIn)\n";
}

impl RosMessage for LockstepOut {
    const TYPE_NAME: &'static str = "spomp_msgs/msg/LockstepOut";
    const DEFINITION: &'static str = "# spomp lockstep answer (CDR of spomp_ros2::lockstep::LockstepOut)\n";
}

/// Why a robot left the lockstep.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LockstepError {
    /// No answer within the timeout.
    #[error("no answer to call {seq} within {timeout_s:.0} s")]
    Timeout {
        /// The call.
        seq: u64,
        /// Wall seconds waited.
        timeout_s: f64,
    },
    /// The robot refused the farm.
    #[error("refused the farm: {0}")]
    Refused(String),
    /// An answer that does not fit the call.
    #[error("answered call {seq} with {what}")]
    Unexpected {
        /// The call.
        seq: u64,
        /// What came.
        what: String,
    },
}

/// The farm's end of one robot's lockstep.
pub struct FarmLockstep {
    robot: String,
    ops: Publisher<LockstepIn>,
    replies: Subscription<LockstepOut>,
    next_seq: u64,
    /// The number of the step's tick call, until its answer is read.
    pending_tick: Option<u64>,
}

/// How long a lockstep wait sleeps between looks at the topic.
const POLL: Duration = Duration::from_micros(200);

impl FarmLockstep {
    /// The lockstep topics of robot `id` on `node`.
    pub fn new(node: &mut DdsNode, id: &str, names: &TopicNames) -> Result<Self, DdsError> {
        Ok(FarmLockstep {
            robot: id.to_string(),
            ops: node.publisher(&in_topic(names), &lockstep_qos())?,
            replies: node.subscription(&out_topic(names), &lockstep_qos())?,
            next_seq: 1,
            pending_tick: None,
        })
    }

    /// The robot's id.
    pub fn robot(&self) -> &str {
        &self.robot
    }

    /// Says hello (the farm repeats it until the robot answers: a call published before the
    /// robot's reader is matched is lost).
    pub fn say_hello(&mut self, hello: &Hello) {
        let _ = self.ops.publish(LockstepIn { seq: 0, op: Op::Hello(hello.clone()) });
    }

    /// The robot's answer to the hello, if one came: ready, or its refusal.
    pub fn hello_answer(&mut self) -> Option<Result<(), LockstepError>> {
        while let Ok(Some((msg, _))) = self.replies.take() {
            if msg.robot != self.robot || msg.seq != 0 {
                continue;
            }
            match msg.reply {
                Reply::Ready => return Some(Ok(())),
                Reply::Refused(why) => return Some(Err(LockstepError::Refused(why))),
                _ => {}
            }
        }
        None
    }

    /// Starts the calls from number 1 again: the robot's process answered a new hello (it
    /// restarted, or came back after it was dropped).
    pub fn restart(&mut self) {
        self.next_seq = 1;
        self.pending_tick = None;
    }

    /// Sends a call that needs no answer.
    pub fn send(&mut self, op: Op) {
        let seq = self.next_seq;
        self.next_seq += 1;
        if matches!(op, Op::Tick) {
            self.pending_tick = Some(seq);
        }
        let _ = self.ops.publish(LockstepIn { seq, op });
    }

    /// Asks the robot for its team-state message to `to` and waits for it.
    pub fn team_out(
        &mut self,
        to: &RobotId,
        tiers: u8,
        budget_bytes: u64,
        timeout: Duration,
    ) -> Result<Option<Vec<u8>>, LockstepError> {
        let seq = self.next_seq;
        self.send(Op::TeamOut { to: to.clone(), tiers, budget_bytes });
        match self.wait(seq, timeout)? {
            Reply::TeamOut(bytes) => Ok(bytes),
            other => Err(LockstepError::Unexpected { seq, what: reply_name(&other) }),
        }
    }

    /// Waits for the answer to this step's tick.
    pub fn wait_done(&mut self, timeout: Duration) -> Result<StepDone, LockstepError> {
        let Some(seq) = self.pending_tick.take() else {
            return Err(LockstepError::Unexpected { seq: self.next_seq, what: "no tick to answer".into() });
        };
        match self.wait(seq, timeout)? {
            Reply::Done(done) => Ok(*done),
            other => Err(LockstepError::Unexpected { seq, what: reply_name(&other) }),
        }
    }

    fn wait(&mut self, seq: u64, timeout: Duration) -> Result<Reply, LockstepError> {
        let deadline = Instant::now() + timeout;
        loop {
            while let Ok(Some((msg, _))) = self.replies.take() {
                // Late answers to hellos, or another farm's robot of the same name: not ours.
                if msg.robot != self.robot || msg.seq == 0 {
                    continue;
                }
                if msg.seq == seq {
                    return Ok(msg.reply);
                }
                if let Reply::Refused(why) = msg.reply {
                    return Err(LockstepError::Refused(why));
                }
            }
            if Instant::now() >= deadline {
                return Err(LockstepError::Timeout { seq, timeout_s: timeout.as_secs_f64() });
            }
            std::thread::sleep(POLL);
        }
    }
}

fn reply_name(reply: &Reply) -> String {
    match reply {
        Reply::Ready => "ready",
        Reply::Refused(_) => "a refusal",
        Reply::TeamOut(_) => "a team message",
        Reply::Done(_) => "a finished step",
    }
    .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use spomp_core::{Point2, Pose2};

    fn round_trip<T: Serialize + serde::de::DeserializeOwned>(value: &T) -> T {
        let bytes = cdr_encoding::to_vec::<_, byteorder::LittleEndian>(value).expect("encodes");
        cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(&bytes).expect("decodes").0
    }

    #[test]
    fn calls_and_answers_cross_the_wire_bit_for_bit() {
        let odom = Odometry {
            stamp: Time::from_nanos(1_234_567_891),
            pose: Pose2::new(1.0 / 3.0, -2.0e-9, std::f64::consts::PI / 7.0),
            twist: Twist2 { v: 0.1 + 0.2, omega: -1.0 / 9.0 },
        };
        for op in [
            Op::Hello(Hello { protocol: PROTOCOL, seed: 7, skill_latency_s: Some((0.05, 0.8)) }),
            Op::Begin(Time::from_nanos(100_000_000)),
            Op::Odometry(odom),
            Op::TeamOut { to: RobotId::new("ugv2"), tiers: 0b101, budget_bytes: 4000 },
            Op::TeamIn { from: RobotId::new("base"), bytes: vec![1, 2, 3] },
            Op::Tick,
            Op::End,
        ] {
            let call = LockstepIn { seq: 5, op };
            assert_eq!(round_trip(&call), call);
        }
        let done = StepDone {
            now: Time::from_nanos(3),
            ticked: true,
            command: Some(Twist2 { v: 0.7 / 3.0, omega: 1e-300 }),
            flight: Some(FlightCommand { target: Point2::new(1.0 / 7.0, 2.0), altitude_m: 60.0, speed_mps: 10.0 }),
            estimate_after_panorama: None,
            estimate: Some(PoseEstimate {
                stamp: Time::from_nanos(9),
                pose: Pose2::new(0.1, 0.2, 0.3),
                covariance: [1.0 / 3.0; 9],
                confidence: 0.5,
            }),
            tree: "running".into(),
            transitioned: vec![0, 4],
            problems: vec!["stuck".into()],
            goals: Vec::new(),
        };
        for reply in [Reply::Ready, Reply::TeamOut(None), Reply::TeamOut(Some(vec![9])), Reply::Done(Box::new(done))] {
            let out = LockstepOut { robot: "ugv1".into(), seq: 8, reply };
            assert_eq!(round_trip(&out), out);
        }
    }

    /// Regression (issue 37): goal views with operator fields left unset (an ordinary goal) and
    /// set (an operator's named, urgent, cancelled goal) must cross the farm's CDR as they are;
    /// fields left out of the encoding shifted every later one, the farm could not read the
    /// robots' answers and a lockstep run stalled at its first step.
    #[test]
    fn goal_views_with_and_without_operator_fields_cross_the_wire() {
        use spomp_teamstate::{OperatorAction, TeamState, TeamStateParams};
        let mut team = TeamState::new(RobotId::new("operator"), u32::MAX, TeamStateParams::default()).expect("state");
        team.add_mission_goal(0, Point2::new(10.0, 10.0)).expect("mission goal");
        let add = OperatorAction::AddGoal {
            position: Point2::new(60.0, 5.0),
            name: Some("east".into()),
            priority: 3,
            class: Some("car".into()),
        };
        let id = team.issue_command(add, Time::from_nanos(5)).expect("add");
        team.issue_command(OperatorAction::CancelGoal { goal: id.goal_id() }, Time::from_nanos(6)).expect("cancel");
        let goals = team.goals().to_vec();
        assert!(goals.iter().any(|g| g.priority == 0 && g.name.is_none()));
        assert!(goals.iter().any(|g| g.priority == 3 && g.cancelled.is_some()));
        let done = StepDone {
            now: Time::from_nanos(3),
            ticked: true,
            command: None,
            flight: None,
            estimate_after_panorama: None,
            estimate: None,
            tree: "running".into(),
            transitioned: vec![1],
            problems: Vec::new(),
            goals,
        };
        let out = LockstepOut { robot: "ugv1".into(), seq: 9, reply: Reply::Done(Box::new(done)) };
        assert_eq!(round_trip(&out), out);
    }
}
