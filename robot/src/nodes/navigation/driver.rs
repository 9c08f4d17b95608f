//! The local machinery: a local goal per panorama, DWA at every tick, the progress watchdog.

#[allow(clippy::wildcard_imports)]
use super::*;

// ---------------------------------------------------------------------------------------------
// The driving core

/// Why a drive ended badly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Reason {
    NoPath,
    Stuck,
    TimeLimit,
    /// The robot came no nearer its target within the no-progress bound, or did not move at all
    /// for the stuck timeout: what recovery behaviours (`back_up`, `spin`) are for.
    NoProgress,
    NoNavigation,
}

impl Reason {
    pub(super) fn as_str(self) -> &'static str {
        match self {
            Reason::NoPath => "no_path",
            Reason::Stuck => "stuck",
            Reason::TimeLimit => "time_limit",
            Reason::NoProgress => "no_progress",
            Reason::NoNavigation => "no_navigation",
        }
    }
}

/// Outcome of one tick of a drive.
pub(super) enum Step {
    Running,
    Arrived,
    Failed(Reason, String),
}

/// The local machinery shared by every driving node: local goal per panorama, DWA per tick,
/// progress watchdog.
pub(super) struct Driver {
    pub(super) overrides: Overrides,
    pub(super) tuning: Option<Tuning>,
    /// Stamp of the panorama the local goal was chosen in.
    pub(super) view_stamp: Option<Time>,
    /// Map-frame pose of that panorama.
    pub(super) view_pose: Pose2,
    /// The local goal, in the robot frame at that panorama.
    pub(super) local_goal: Option<Point2>,
    /// Smallest remaining distance seen, and when it last dropped by the margin.
    pub(super) best_remaining: f64,
    pub(super) best_at: Time,
    /// Where the robot was when it last got [`PINNED_RADIUS_M`] away from the previous such
    /// point, and when: a robot that stays near one point is stuck, whatever its route says.
    pub(super) pinned_at: Option<Point2>,
    pub(super) pinned_since: Time,
    /// Nearest the robot came to the target (straight line), lowered by [`PROGRESS_MARGIN_M`]
    /// steps: the no-progress bound's first measure, which replans do not reset.
    pub(super) closest_m: f64,
    /// Least path length left seen on the routes the robot followed, since the last detour
    /// ([`Driver::take_detour`]): getting [`PROGRESS_MARGIN_M`] below it is progress too.
    pub(super) route_best_m: f64,
    /// Detours this drive may still take, each a new, longer path-length baseline.
    pub(super) detours_left: u32,
    /// When the robot last made progress of either kind (straight line or along its path).
    pub(super) progress_at: Time,
    /// Odometry position the robot has stayed within [`MOTIONLESS_RADIUS_M`] of, and since when.
    pub(super) still_at: Option<Point2>,
    pub(super) still_since: Time,
}

impl Driver {
    pub(super) fn new(overrides: Overrides) -> Self {
        Driver {
            overrides,
            tuning: None,
            view_stamp: None,
            view_pose: Pose2::default(),
            local_goal: None,
            best_remaining: f64::INFINITY,
            best_at: Time::ZERO,
            pinned_at: None,
            pinned_since: Time::ZERO,
            closest_m: f64::INFINITY,
            route_best_m: f64::INFINITY,
            detours_left: DETOURS_PER_DRIVE,
            progress_at: Time::ZERO,
            still_at: None,
            still_since: Time::ZERO,
        }
    }

    /// Starts a drive: builds the tuning on first use, forgets the last drive.
    pub(super) fn start(&mut self, rt: &RobotRuntime, now: Time) -> Result<(), String> {
        let Some(nav) = rt.nav() else {
            return Err("the robot has no navigation stack (not a UGV, or its runtime was set up without `nav`)".into());
        };
        if self.tuning.is_none() {
            self.tuning = Some(Tuning::build(nav, &self.overrides)?);
        }
        self.view_stamp = None;
        self.local_goal = None;
        self.best_remaining = f64::INFINITY;
        self.best_at = now;
        self.pinned_at = None;
        self.pinned_since = now;
        self.closest_m = f64::INFINITY;
        self.route_best_m = f64::INFINITY;
        self.detours_left = DETOURS_PER_DRIVE;
        self.progress_at = now;
        self.still_at = None;
        self.still_since = now;
        Ok(())
    }

    /// The no-progress check of a drive toward a target `distance_m` away (straight line), with
    /// the robot's odometry position `odom`: why the drive makes no progress, if it does not.
    /// Two signs: for `bound_s` the robot has come neither [`PROGRESS_MARGIN_M`] nearer the
    /// target than its best nor that much further along its path than its best
    /// ([`Driver::route_progress`]), whatever the replans did meanwhile; or its odometry has
    /// stayed within [`MOTIONLESS_RADIUS_M`] for `still_s` (wedged: commands are given, nothing
    /// moves).
    pub(super) fn no_progress(
        &mut self,
        now: Time,
        distance_m: f64,
        odom: Option<Point2>,
        bound_s: f64,
        still_s: f64,
    ) -> Option<String> {
        if distance_m.is_finite() && (distance_m < self.closest_m - PROGRESS_MARGIN_M || !self.closest_m.is_finite()) {
            self.closest_m = distance_m;
            self.progress_at = now;
        }
        if let Some(p) = odom
            && self.still_at.is_none_or(|a| a.distance(p) > MOTIONLESS_RADIUS_M)
        {
            self.still_at = Some(p);
            self.still_since = now;
        }
        if now.secs_since(self.progress_at) > bound_s {
            let along = if self.route_best_m.is_finite() {
                format!(" nor less than {:.1} m of path left", self.route_best_m)
            } else {
                String::new()
            };
            return Some(format!(
                "no progress: no nearer than {:.1} m to the target{along} for {bound_s:.0} s",
                self.closest_m
            ));
        }
        if now.secs_since(self.still_since) > still_s {
            return Some(format!("no progress: the robot has not moved for {still_s:.0} s"));
        }
        None
    }

    /// Feeds the no-progress check the path length left on the route being followed: getting
    /// [`PROGRESS_MARGIN_M`] below the least seen is progress, so a detour that first leads
    /// away from the target (round a block whose road is cut) is not given up while the robot
    /// gains on it. Replans do not lower the bar: a new, longer route counts only as a detour.
    pub(super) fn route_progress(&mut self, now: Time, remaining_m: f64) {
        if remaining_m.is_finite()
            && (remaining_m < self.route_best_m - PROGRESS_MARGIN_M || !self.route_best_m.is_finite())
        {
            self.route_best_m = remaining_m;
            self.progress_at = now;
        }
    }

    /// A route forced by something the robot learnt (an edge gone or costlier, an edge it
    /// could not drive) is longer than the path it had left: its length becomes the baseline
    /// of [`Driver::route_progress`], at most [`DETOURS_PER_DRIVE`] times a drive, so that
    /// routes flipping back and forth cannot keep a drive alive for ever.
    pub(super) fn take_detour(&mut self, length_m: f64) {
        if length_m.is_finite() && length_m > self.route_best_m && self.detours_left > 0 {
            self.detours_left -= 1;
            self.route_best_m = length_m;
        }
    }

    /// Feeds the watchdog the remaining distance and the robot's position; true when no
    /// progress was made for `timeout_s`, or the robot stayed within [`PINNED_RADIUS_M`] of one
    /// point for [`PINNED_TIMEOUTS`] of them (wiggling in a corner while replans keep changing
    /// the route, so that the remaining distance alone would not tell).
    pub(super) fn stuck(&mut self, now: Time, here: Option<Point2>, remaining: f64, timeout_s: f64) -> bool {
        if remaining.is_finite()
            && (remaining < self.best_remaining - PROGRESS_MARGIN_M || !self.best_remaining.is_finite())
        {
            self.best_remaining = remaining;
            self.best_at = now;
        }
        now.secs_since(self.best_at) > timeout_s || self.pinned(now, here, timeout_s)
    }

    /// Whether the robot stayed near one point for [`PINNED_TIMEOUTS`] × `timeout_s`.
    pub(super) fn pinned(&mut self, now: Time, here: Option<Point2>, timeout_s: f64) -> bool {
        if let Some(p) = here
            && self.pinned_at.is_none_or(|a| a.distance(p) > PINNED_RADIUS_M)
        {
            self.pinned_at = Some(p);
            self.pinned_since = now;
        }
        now.secs_since(self.pinned_since) > PINNED_TIMEOUTS * timeout_s
    }

    /// A fresh stuck window from now, measured against `remaining` (a new route after being
    /// stuck on the old one).
    pub(super) fn restart_watchdog(&mut self, now: Time, remaining: f64) {
        self.best_remaining = if remaining.is_finite() { remaining } else { f64::INFINITY };
        self.best_at = now;
        self.pinned_since = now;
    }

    /// Lets the watchdog measure against a new remaining distance (after a replan changed the
    /// route) without granting extra time.
    pub(super) fn rebase(&mut self, remaining: f64) {
        if remaining.is_finite() {
            self.best_remaining = remaining;
        }
    }

    /// One control step toward `goal` (map frame): a new local goal if a new panorama arrived,
    /// then DWA. Writes `rt.command` (zero without a view or a local goal).
    pub(super) fn drive(&mut self, rt: &mut RobotRuntime, goal: Point2) {
        let Some(tuning) = self.tuning.as_mut() else {
            rt.command_velocity(Twist2::ZERO);
            return;
        };
        let odometry = rt.odometry();
        let Some((view, rng)) = rt.nav_and_rng().and_then(|(n, rng)| Some((n.view()?, rng))) else {
            rt.command_velocity(Twist2::ZERO);
            return;
        };
        if self.view_stamp != Some(view.stamp) {
            let at = view.pose.pose;
            let target = at.inverse_transform_point(goal);
            let previous = self.local_goal.map(|g| at.inverse_transform_point(self.view_pose.transform_point(g)));
            self.local_goal = select_local_goal(&view.region, target, previous, &tuning.goal, rng);
            self.view_stamp = Some(view.stamp);
            self.view_pose = at;
        }
        let Some(local_goal) = self.local_goal else {
            rt.command_velocity(Twist2::ZERO);
            return;
        };
        let (robot, current) = match odometry {
            Some(odom) => (view.odom_pose.between(odom.pose), odom.twist),
            None => (Pose2::default(), Twist2::ZERO),
        };
        let cmd = tuning.dwa.step_in_region(current, robot, local_goal, &view.region);
        rt.command_velocity(cmd);
    }
}
