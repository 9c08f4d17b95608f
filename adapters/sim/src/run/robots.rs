//! One simulated robot (its body, sensors and `Robot`) and the per-robot work of a step:
//! sensing, ticking, the bookkeeping of its claims, localization error and problems. Each
//! touches only its robot, so robots may be stepped on several threads.

use super::*;

pub(super) enum Body {
    Ugv {
        ugv: Box<Ugv>,
        odometry: Box<OdometryModel>,
        sensor: Box<PanoramaSensor>,
        truth_source: Option<Box<NoisyPoseSource>>,
        last_scan_stamp: Option<Time>,
    },
    Uav {
        uav: Box<Uav>,
        camera: Box<OrthoCamera>,
        flying_to: Option<Point2>,
    },
    Fixed {
        pose: Pose2,
    },
}

/// Reports a UGV's newest reachability scan and terrain obstacles once each.
pub(super) fn observe_scan(
    id: &RobotId,
    robot: &Robot,
    last_scan_stamp: &mut Option<Time>,
    observer: &mut dyn SimObserver,
) {
    if let Some(scan) = robot.latest_scan()
        && *last_scan_stamp != Some(scan.stamp)
    {
        *last_scan_stamp = Some(scan.stamp);
        observer.on_scan(scan);
        if let Some((geometry, obstacle)) = robot.terrain_obstacles() {
            observer.on_terrain(id, scan.stamp, geometry, obstacle);
        }
    }
}

pub(super) struct SimRobot {
    pub(super) id: RobotId,
    pub(super) kind: RobotKind,
    pub(super) pose_input: PoseInput,
    pub(super) robot: Robot,
    pub(super) body: Body,
    pub(super) tick_period_ns: i64,
    pub(super) next_tick: Time,
    pub(super) kill_at: Option<Time>,
    pub(super) killed_s: Option<f64>,
    pub(super) command: Twist2,
    /// Node ids (depth-first) that ever changed status.
    pub(super) ticked: Vec<bool>,
    pub(super) node_paths: Vec<String>,
    /// Seconds holding a claim, per goal.
    pub(super) claim_time_s: BTreeMap<GoalId, f64>,
    pub(super) held: Option<GoalId>,
    pub(super) localization_errors: Vec<f64>,
    /// (simulated time s, position error m) of the robot's own estimate, at most once a second
    /// (sampled at panoramas).
    pub(super) localization_error_series: Vec<(f64, f64)>,
    pub(super) last_path_len: usize,
    pub(super) trajectory: Vec<Point2>,
    /// Driven from outside (see [`ExternalDrivers`]): its own `robot` is not ticked.
    pub(super) external: bool,
    /// Background work done and waiting for the step it is due back (skill latency).
    pub(super) work_out: Option<ModelledWork<FinishedWork>>,
    /// What its links may still carry this radio round.
    pub(super) link_credit: LinkCredit,
    /// The last map version this robot published that observers were shown.
    pub(super) map_shown: Option<u64>,
    /// The other UGVs' bodies this step, as obstacles for this one (a UGV's; reused).
    pub(super) other_bodies: Vec<Obstacle>,
    /// Since when every commanded motion of this UGV was refused (none moved it), and whether
    /// that stretch was counted as a stuck event yet.
    pub(super) refused_since: Option<Time>,
    pub(super) refusal_counted: bool,
    /// Times the simulator refused its commanded motion for [`STUCK_AFTER_S`] on end.
    pub(super) stuck_events: u64,
    /// Where and since when it has stood still (within [`MOTIONLESS_RADIUS_M`]) while its tree
    /// drove it (sampled once a second), and the longest such stretch, seconds.
    pub(super) still_since: Option<(Point2, Time)>,
    pub(super) longest_still_driving_s: f64,
}

impl SimRobot {
    pub(super) fn truth(&self) -> Pose2 {
        match &self.body {
            Body::Ugv { ugv, .. } => ugv.pose(),
            Body::Uav { uav, .. } => uav.pose(),
            Body::Fixed { pose } => *pose,
        }
    }

    pub(super) fn z_m(&self) -> f64 {
        match &self.body {
            Body::Ugv { ugv, .. } => ugv.base_elevation_m() as f64,
            Body::Uav { uav, .. } => uav.altitude_m(),
            Body::Fixed { .. } => 0.0,
        }
    }

    /// Whether this robot is a UGV whose panorama is due at `now`.
    pub(super) fn panorama_due(&self, now: Time) -> bool {
        matches!(&self.body, Body::Ugv { sensor, .. } if sensor.due(now))
    }

    pub(super) fn alive(&self) -> bool {
        self.killed_s.is_none()
    }
}

/// Claim bookkeeping for the "time heading to a goal" metric: events when the held goal
/// changes, time accumulated on the one held.
pub(super) fn note_claim(r: &mut SimRobot, held: Option<GoalId>, now: Time, dt: f64, observer: &mut dyn SimObserver) {
    let id = r.id.clone();
    if held != r.held {
        if let Some(old) = &r.held {
            observer.on_event(now, &SimEvent::GoalReleased { goal: old.to_string(), by: id.to_string() });
        }
        if let Some(new) = &held {
            observer.on_event(now, &SimEvent::GoalClaimed { goal: new.to_string(), by: id.to_string() });
        }
        r.held = held.clone();
    }
    if let Some(g) = held {
        *r.claim_time_s.entry(g).or_insert(0.0) += dt;
    }
}

/// Every UGV body but the `own`-th, into `out` (reused across steps).
pub(super) fn others_than(all: &[Obstacle], own: usize, out: &mut Vec<Obstacle>) {
    out.clear();
    out.extend(all.iter().enumerate().filter(|(k, _)| *k != own).map(|(_, o)| *o));
}

/// What a UGV's sensors gave its robot in one step, for the observers.
pub(super) struct SensedUgv {
    pub(super) odometry: Odometry,
    /// The panorama, when one was due.
    pub(super) panorama: Option<Arc<PanoramaFrame>>,
}

/// A live UGV's sensing of one step, fed to its own robot (nothing for other robots, dead ones
/// and those driven from outside). Touches only `r`: robots may be sensed in parallel.
pub(super) fn sense_ugv(r: &mut SimRobot, world: &World, now: Time) -> Option<SensedUgv> {
    if !r.alive() || r.external {
        return None;
    }
    let truth = r.truth();
    let Body::Ugv { ugv, odometry, sensor, truth_source, .. } = &mut r.body else { return None };
    let odom = odometry.update(now, truth, ugv.twist());
    r.robot.on_odometry(now, odom);
    if let Some(src) = truth_source.as_mut() {
        r.robot.on_external_pose(now, src.estimate(now, truth));
    }
    let panorama =
        sensor.poll_among(now, world, truth, ugv.base_elevation_m(), odom.pose, &r.other_bodies).map(Arc::new);
    if let Some(frame) = &panorama {
        r.robot.on_panorama(now, Arc::clone(frame));
        if let Some(est) = r.robot.pose() {
            note_localization(r, &est, truth, now);
        }
    }
    Some(SensedUgv { odometry: odom, panorama })
}

/// A UGV's estimate right after a panorama, against the truth: its localization error.
pub(super) fn note_localization(r: &mut SimRobot, est: &PoseEstimate, truth: Pose2, now: Time) {
    let error = est.pose.position().distance(truth.position());
    r.localization_errors.push(error);
    let t = now.as_secs_f64();
    if r.localization_error_series.last().is_none_or(|&(last, _)| t - last >= 1.0 - 1e-9) {
        r.localization_error_series.push((t, error));
    }
}

/// Counts a problem a robot reported (the first `MAX_PROBLEMS` distinct ones are kept).
pub(super) fn note_problem(
    problems: &mut BTreeMap<(String, String), ProblemCount>,
    robot: &RobotId,
    message: String,
    now: Time,
) {
    let key = (robot.to_string(), message);
    if let Some(p) = problems.get_mut(&key) {
        p.count += 1;
    } else if problems.len() < MAX_PROBLEMS {
        let p = ProblemCount { robot: key.0.clone(), message: key.1.clone(), count: 1, first_s: now.as_secs_f64() };
        problems.insert(key, p);
    }
}

/// What a robot's tick of one step left for the observers.
pub(super) struct TickedRobot {
    pub(super) transitions: Recorder,
}

/// Runs the robot's upkeep and tree tick if due (not for dead robots or those driven from
/// outside). Touches only `r`: robots may be ticked in parallel.
pub(super) fn tick_robot(r: &mut SimRobot, now: Time) -> Option<TickedRobot> {
    if !r.alive() || r.external || now < r.next_tick {
        return None;
    }
    r.next_tick = Time::from_nanos(now.nanos + r.tick_period_ns - 1);
    let mut transitions = Recorder::default();
    r.robot.tick(now, Some(&mut transitions));
    r.command = r.robot.command().unwrap_or(Twist2::ZERO);
    Some(TickedRobot { transitions })
}

/// `work` applied to every robot, in parallel (rayon's pool) when `parallel`, else in order;
/// the results in robot order. `work` must touch nothing but its robot, so that both ways give
/// the same robots and results.
pub(super) fn for_each_robot<T, F>(parallel: bool, robots: &mut [SimRobot], work: F) -> Vec<T>
where
    T: Send,
    F: Fn(&mut SimRobot) -> T + Sync + Send,
{
    if parallel && robots.len() > 1 && rayon::current_num_threads() > 1 {
        robots.par_iter_mut().map(work).collect()
    } else {
        robots.iter_mut().map(work).collect()
    }
}

/// A robot's localization update and terrain analysis side by side, when its perception already
/// runs on one of rayon's threads (robots stepped in parallel): a thread left idle while the
/// last robot's panorama is processed takes half of it. From any other thread, one after the
/// other.
pub(super) fn join_on_rayon(a: &mut (dyn FnMut() + Send), b: &mut (dyn FnMut() + Send)) {
    if rayon::current_thread_index().is_some() {
        rayon::join(a, b);
    } else {
        a();
        b();
    }
}
