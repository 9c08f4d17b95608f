//! The heavy skills as work that may leave the tick thread.
//!
//! Two kinds of work take long enough to hold up a 10 Hz tree: processing a panorama (the
//! cross-view localizer's measurement update, terrain analysis) and the global planner's upkeep
//! (growing the graph on a new map version: the first takes most of a second; training rounds).
//!
//! A runtime runs them one of two ways, with the same code:
//! - inline (the simulator, tests): inside `on_panorama` and `maintain`, on the caller's thread,
//!   with the robot's own random stream — lockstep runs stay bit for bit what they were;
//! - in the background (`spomp run`): `on_panorama` only keeps the newest frame and `maintain`
//!   only the light upkeep; the adapter takes the due work with [`super::RobotRuntime::take_work`],
//!   runs each [`SkillWork`] where it likes (another thread) and hands the result back with
//!   [`super::RobotRuntime::finish_work`] between ticks. A job owns what it works on: the
//!   localizer and the terrain analyzer leave the runtime for it (odometry is composed onto the
//!   last estimate meanwhile), the global planner is copied (the tree keeps planning on the
//!   original until the copy is swapped in), the map is shared copy-on-write, and the job's
//!   randomness is a stream forked from the robot's when the work was taken. So a job's result
//!   depends only on when it was taken and when it was finished — both seam calls a log records
//!   — and a replay reproduces a background run exactly.

use std::sync::Arc;

use rand_chacha::ChaCha8Rng;
use spomp_core::{AerialMap, ClassTable, PanoramaFrame, PoseEstimate, ReachabilityScan, RobotId};
use spomp_local_planner::SafeRegion;
use spomp_localization::LocalizationError;

use super::localization::CrossView;
use super::navigation::{PlannerDone, PlannerJob, TerrainJob};

/// Runs two pieces of work, possibly at once, and returns when both have finished: how an
/// adapter with spare cores lets a panorama's localization update and terrain analysis run side
/// by side (the simulator passes `rayon::join`). The two touch disjoint state and neither draws
/// from the other's inputs, so the results are those of running them one after the other.
pub type JoinFn = fn(&mut (dyn FnMut() + Send), &mut (dyn FnMut() + Send));

/// Which skill a piece of work runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum WorkKind {
    /// Localization update and terrain analysis of one panorama.
    Perception,
    /// The global planner's graph growth and training.
    Planner,
}

impl WorkKind {
    /// The name used in logs and reports.
    pub fn name(self) -> &'static str {
        match self {
            WorkKind::Perception => "perception",
            WorkKind::Planner => "planner",
        }
    }
}

/// Work taken from a runtime: run it anywhere ([`SkillWork::run`]), then give the result back to
/// the runtime it came from.
pub struct SkillWork {
    id: u64,
    job: Job,
}

enum Job {
    Perception(Box<PerceptionJob>, Box<ChaCha8Rng>),
    Planner(Box<PlannerJob>),
}

/// The result of a [`SkillWork`], for [`super::RobotRuntime::finish_work`].
pub struct FinishedWork {
    id: u64,
    done: Done,
}

enum Done {
    Perception(Box<PerceptionJob>, Box<PerceptionResult>),
    Planner(Box<PlannerDone>),
}

impl std::fmt::Debug for SkillWork {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SkillWork").field("id", &self.id).field("kind", &self.kind()).finish_non_exhaustive()
    }
}

impl SkillWork {
    pub(super) fn perception(id: u64, job: PerceptionJob, rng: ChaCha8Rng) -> Self {
        SkillWork { id, job: Job::Perception(Box::new(job), Box::new(rng)) }
    }

    pub(super) fn planner(id: u64, job: PlannerJob) -> Self {
        SkillWork { id, job: Job::Planner(Box::new(job)) }
    }

    /// The work's number (per robot, in the order work was taken).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// What it runs.
    pub fn kind(&self) -> WorkKind {
        match self.job {
            Job::Perception(..) => WorkKind::Perception,
            Job::Planner(_) => WorkKind::Planner,
        }
    }

    /// Does the work (on any thread).
    pub fn run(self) -> FinishedWork {
        let done = match self.job {
            Job::Perception(mut job, mut rng) => {
                let result = job.run(&mut rng);
                Done::Perception(job, Box::new(result))
            }
            Job::Planner(job) => Done::Planner(Box::new(job.run())),
        };
        FinishedWork { id: self.id, done }
    }
}

impl FinishedWork {
    /// The number of the work it finished.
    pub fn id(&self) -> u64 {
        self.id
    }

    /// What it ran.
    pub fn kind(&self) -> WorkKind {
        match self.done {
            Done::Perception(..) => WorkKind::Perception,
            Done::Planner(_) => WorkKind::Planner,
        }
    }

    pub(super) fn into_parts(self) -> FinishedParts {
        match self.done {
            Done::Perception(job, result) => FinishedParts::Perception(job, result),
            Done::Planner(done) => FinishedParts::Planner(done),
        }
    }
}

/// A finished work's contents, for the runtime.
pub(super) enum FinishedParts {
    Perception(Box<PerceptionJob>, Box<PerceptionResult>),
    Planner(Box<PlannerDone>),
}

/// One panorama's processing: what it needs, owned.
pub(super) struct PerceptionJob {
    pub frame: Arc<PanoramaFrame>,
    /// The robot's map copy when the work was taken, and its version.
    pub map: Option<(Arc<AerialMap>, u64)>,
    pub classes: Arc<ClassTable>,
    /// The localizer, lent (cross-view robots).
    pub localizer: Option<Box<CrossView>>,
    /// Terrain analysis (UGVs with navigation), and why it could not be set up.
    pub terrain: Option<Result<TerrainJob, String>>,
    pub robot: RobotId,
    /// The pose when the work was taken: the scan's pose where no localizer gives one.
    pub pose_before: Option<PoseEstimate>,
    /// Runs localization and terrain analysis side by side; `None`: one after the other.
    pub join: Option<JoinFn>,
}

/// What processing a panorama gave.
pub(super) struct PerceptionResult {
    /// The localizer's estimate at the frame (`None`: no localizer here).
    pub estimate: Result<Option<PoseEstimate>, LocalizationError>,
    /// The pose the analysis was stamped with.
    pub scan_pose: Option<PoseEstimate>,
    /// The safe region and the scan (`None`: no analysis: no navigation, or no pose yet).
    pub analysis: Option<Result<(SafeRegion, ReachabilityScan), String>>,
}

impl PerceptionJob {
    /// Localization and terrain analysis (side by side with a [`JoinFn`]), the analysis then
    /// stamped with the pose the localization gave. Analysis never reads the pose, so only the
    /// stamp waits for it.
    pub(super) fn run(&mut self, rng: &mut ChaCha8Rng) -> PerceptionResult {
        let map = self.map.as_ref().map(|(m, v)| (&**m, *v));
        let (frame, classes, robot) = (&*self.frame, &*self.classes, &self.robot);
        let mut estimate = Ok(None);
        let mut analysis = None;
        let mut localize = || {
            if let Some(cv) = self.localizer.as_mut() {
                estimate = cv.on_panorama(frame, map, classes, rng).map(Some);
            }
        };
        let mut analyze = || {
            analysis = match self.terrain.as_mut() {
                Some(Ok(terrain)) => Some(terrain.analyze(robot, frame)),
                Some(Err(e)) => Some(Err(e.clone())),
                None => None,
            };
        };
        let pose_before = self.pose_before;
        let pose_of =
            |estimate: &Result<Option<PoseEstimate>, _>| estimate.as_ref().ok().copied().flatten().or(pose_before);
        match self.join {
            Some(join) => join(&mut localize, &mut analyze),
            None => {
                localize();
                // No pose to stamp a scan with: no analysis (it would be dropped).
                if pose_of(&estimate).is_some() {
                    analyze();
                }
            }
        }
        let scan_pose = pose_of(&estimate);
        let analysis = scan_pose.and_then(|pose| {
            analysis.map(|result| {
                result.map(|(region, mut scan)| {
                    scan.pose = pose.pose;
                    (region, scan)
                })
            })
        });
        PerceptionResult { estimate, scan_pose, analysis }
    }
}
