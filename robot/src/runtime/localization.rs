//! Where a robot's map-frame pose comes from: outside (GPS, a surveyed basestation, simulator
//! truth where the mission asks for it) or the cross-view localizer run on the robot's own
//! panoramas and odometry.

use rand_chacha::ChaCha8Rng;
use spomp_core::{AerialMap, ClassTable, Odometry, PanoramaFrame, Pose2, PoseEstimate, Time};
use spomp_localization::{CrossViewLocalizer, LocalizationError, LocalizationParams, OdometryComposer, PosePrior};

use super::RuntimeError;

/// How a robot is localized (from the mission's per-robot `localization`).
#[derive(Clone, Debug)]
pub enum LocalizationSetup {
    /// The adapter supplies the pose ([`super::RobotRuntime::on_external_pose`]).
    External,
    /// The cross-view particle filter, started from the start pose with these spreads.
    CrossView {
        /// Filter parameters.
        params: Box<LocalizationParams>,
        /// Prior position spread (1σ), metres.
        prior_sigma_m: f64,
        /// Prior heading spread (1σ), radians.
        prior_sigma_rad: f64,
        /// When to run a measurement update.
        schedule: UpdateSchedule,
    },
}

/// When the localizer runs a measurement update on a panorama. As in AMCL, a robot standing
/// still learns nothing new from the same view: updating on it again only overweights one
/// observation (and costs time). Between updates the pose is odometry composed with the last
/// filtered pose, exactly as between panoramas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateSchedule {
    /// Update once the robot travelled this far since the last update, metres.
    pub min_travel_m: f64,
    /// Or turned this much, radians.
    pub min_turn_rad: f64,
    /// Or this long passed, seconds.
    pub max_interval_s: f64,
}

impl Default for UpdateSchedule {
    fn default() -> Self {
        UpdateSchedule { min_travel_m: 0.2, min_turn_rad: 0.1, max_interval_s: 10.0 }
    }
}

/// The running localization of one robot.
pub enum Localization {
    /// The pose comes from outside.
    External,
    /// The cross-view localizer.
    CrossView(Box<CrossView>),
    /// The cross-view localizer is away in a measurement update on another thread; odometry
    /// is composed onto its last estimate until it is back.
    InUpdate {
        /// The last estimate and the odometry pose it holds at.
        composer: OdometryComposer,
        /// Measurement updates run before it left.
        updates: u64,
    },
}

/// State of the cross-view localizer inside a runtime.
pub struct CrossView {
    filter: CrossViewLocalizer,
    prior: PosePrior,
    schedule: UpdateSchedule,
    /// Odometry pose at the last prediction (None: not initialised yet).
    last_odom: Option<Pose2>,
    /// Odometry pose, time and map version of the last measurement update.
    last_update: Option<(Pose2, Time, u64)>,
    /// Measurement updates run so far.
    updates: u64,
}

impl Localization {
    /// Sets up the mode; the filter is initialised from the prior at the first odometry or
    /// panorama (it needs their odometry pose as its anchor).
    pub fn from_setup(setup: &LocalizationSetup, start: Pose2) -> Result<Self, RuntimeError> {
        Ok(match setup {
            LocalizationSetup::External => Localization::External,
            LocalizationSetup::CrossView { params, prior_sigma_m, prior_sigma_rad, schedule } => {
                let filter = CrossViewLocalizer::new((**params).clone())
                    .map_err(|e| RuntimeError::Skill { skill: "localization", message: e.to_string() })?;
                let prior = PosePrior { pose: start, std_xy_m: *prior_sigma_m, std_yaw_rad: *prior_sigma_rad };
                Localization::CrossView(Box::new(CrossView {
                    filter,
                    prior,
                    schedule: *schedule,
                    last_odom: None,
                    last_update: None,
                    updates: 0,
                }))
            }
        })
    }

    /// The name of the mode, for summaries.
    pub fn mode_name(&self) -> &'static str {
        match self {
            Localization::External => "external",
            Localization::CrossView(_) | Localization::InUpdate { .. } => "cross_view",
        }
    }

    /// The pose at this odometry reading: the last filtered pose composed with the odometry
    /// since. `None` for externally localized robots.
    pub fn pose_at(&mut self, odom: &Odometry, rng: &mut ChaCha8Rng) -> Option<PoseEstimate> {
        match self {
            Localization::External => None,
            Localization::CrossView(cv) => {
                cv.ensure_initialized(odom.pose, odom.stamp, rng).ok()?;
                Some(cv.filter.pose_at_odometry(odom))
            }
            Localization::InUpdate { composer, .. } => Some(composer.pose_at_odometry(odom)),
        }
    }

    /// One panorama (see `CrossView::on_panorama`); `None` for externally localized robots
    /// and while the localizer is away.
    pub fn on_panorama(
        &mut self,
        frame: &PanoramaFrame,
        map: Option<(&AerialMap, u64)>,
        classes: &ClassTable,
        rng: &mut ChaCha8Rng,
    ) -> Result<Option<PoseEstimate>, LocalizationError> {
        match self {
            Localization::CrossView(cv) => cv.on_panorama(frame, map, classes, rng).map(Some),
            Localization::External | Localization::InUpdate { .. } => Ok(None),
        }
    }

    /// Takes the cross-view localizer out for a measurement update on `frame` elsewhere,
    /// initialised first (from the prior, at the frame's odometry pose, if nothing did yet);
    /// odometry keeps being composed onto its last estimate meanwhile. `None` when there is
    /// no localizer here.
    pub(crate) fn take_for_update(
        &mut self,
        frame: &PanoramaFrame,
        rng: &mut ChaCha8Rng,
    ) -> Result<Option<Box<CrossView>>, LocalizationError> {
        let Localization::CrossView(cv) = self else { return Ok(None) };
        cv.ensure_initialized(frame.odom_pose, frame.stamp, rng)?;
        let stand_in = Localization::InUpdate { composer: cv.filter.composer(), updates: cv.updates };
        Ok(match std::mem::replace(self, stand_in) {
            Localization::CrossView(cv) => Some(cv),
            other => {
                *self = other;
                None
            }
        })
    }

    /// Puts back a localizer taken with [`Self::take_for_update`].
    pub(crate) fn put_back(&mut self, cv: Box<CrossView>) {
        *self = Localization::CrossView(cv);
    }

    /// Measurement updates run so far (0 for external localization).
    pub fn updates(&self) -> u64 {
        match self {
            Localization::External => 0,
            Localization::CrossView(cv) => cv.updates,
            Localization::InUpdate { updates, .. } => *updates,
        }
    }
}

impl CrossView {
    /// One panorama: prediction from the odometry since the last one, and the measurement
    /// update against `map` (version `map_version`) when there is one and the update schedule
    /// calls for it (odometry only until the map arrives).
    pub fn on_panorama(
        &mut self,
        frame: &PanoramaFrame,
        map: Option<(&AerialMap, u64)>,
        classes: &ClassTable,
        rng: &mut ChaCha8Rng,
    ) -> Result<PoseEstimate, LocalizationError> {
        self.ensure_initialized(frame.odom_pose, frame.stamp, rng)?;
        let schedule = self.schedule;
        let due = |(odom, stamp, version): (Pose2, Time, u64), map_version: u64| {
            let moved = odom.between(frame.odom_pose);
            moved.x.hypot(moved.y) >= schedule.min_travel_m
                || moved.yaw.abs() >= schedule.min_turn_rad
                || frame.stamp.secs_since(stamp) >= schedule.max_interval_s
                || version != map_version
        };
        match map {
            Some((map, version)) if self.last_update.is_none_or(|last| due(last, version)) => {
                self.filter.process_frame(frame, map, classes, rng)?;
                self.last_update = Some((frame.odom_pose, frame.stamp, version));
                self.updates += 1;
            }
            _ => {
                if let Some(last) = self.last_odom {
                    self.filter.predict(last.between(frame.odom_pose), rng)?;
                }
            }
        }
        self.last_odom = Some(frame.odom_pose);
        Ok(self.filter.pose_at(frame.odom_pose))
    }

    fn ensure_initialized(
        &mut self,
        odom_pose: Pose2,
        stamp: Time,
        rng: &mut ChaCha8Rng,
    ) -> Result<(), LocalizationError> {
        if self.last_odom.is_none() {
            self.filter.initialize(&self.prior, odom_pose, stamp, rng)?;
            self.last_odom = Some(odom_pose);
        }
        Ok(())
    }

    /// The filter (for diagnostics).
    pub fn filter(&self) -> &CrossViewLocalizer {
        &self.filter
    }
}
