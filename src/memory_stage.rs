//! The memory stage of `spomp validate`, and the check `spomp sim` makes before it starts: how
//! much memory a simulated run of the mission needs — the world once, each robot by its kind —
//! against what the machine has (`MemAvailable` in `/proc/meminfo`, or a budget given on the
//! command line).
//!
//! The estimate is arithmetic over the sizes that matter (cells of the operating area, pixels
//! of a panorama, robots of each kind, pairs of robots for the team state), with per-unit costs
//! measured on release builds (see `adapters/sim/README.md`, "Memory"). A team that cannot
//! fit is an error located at the mission's `team`; one that fits with little room to spare is
//! a warning.

use std::path::{Path, PathBuf};

use spomp_behaviors::mission::MissionSection;
use spomp_behaviors::mission::schema::MissionFile;
use spomp_behaviors::mission::yaml::{self, Loc};
use spomp_behaviors::mission::{Diagnostic, LoadedMission, Stage};
use spomp_core::RobotKind;
use spomp_sim::SensorParams;
use spomp_world::{SimSpec, World, WorldSpec};

/// Cell size of generated worlds, metres (the aerial maps' 0.5 m).
const GENERATED_CELL_M: f64 = 0.5;

/// The process before any world or robot: code, its tables, the runtime, the threads' stacks
/// (calibrated on the 1-UGV bench mission, 300 s, with the parts below).
const PROCESS_BYTES: f64 = 26e6;

/// The world, per cell of the operating area, held once for the whole team: its class, colour
/// and elevation layers (8 B, shared as the prior map), the localizer's cost planes (≈ 12.5 B,
/// shared by the UGVs), the global planner's class-distance rasters (one byte per class,
/// shared), the goal detector's working rasters while it runs (≈ 26 B, one robot at a time)
/// and the UAV's published map versions, compressed and decoded (≈ 8 B).
const WORLD_BYTES_PER_CELL: f64 = 64.0;

/// A UGV's own rasters over the operating area, per cell: its global planner's coverage
/// (4 B), training votes (1.25 B) and its graph's edges with their packed features (≈ 3 B on
/// a generated city).
const UGV_BYTES_PER_CELL: f64 = 8.5;

/// What a UGV without a prior map adds per cell: its own copy of the map it receives (8 B),
/// since the robots' copies differ while versions arrive its own class-distance rasters (one
/// byte per class), and the version being decoded (8 B). Calibrated on the shipped mission.
const UGV_OWN_MAP_BYTES_PER_CELL: f64 = 25.0;

/// What a basestation or a UAV without a prior map adds per cell: its own map and the version
/// being decoded.
const OTHER_OWN_MAP_BYTES_PER_CELL: f64 = 16.0;

/// A UGV's panorama-sized buffers, per pixel: the simulator's last render kept for a still
/// robot (depth 4 B, classes 1 B), the terrain analysis' obstacle mask (1 B), the localizer's
/// projected observation and the frame in flight.
const UGV_BYTES_PER_PIXEL: f64 = 8.0;

/// A UGV's fixed part: particles, trees, controller, its own team-state records, allocator
/// slack (the remainder of the measured 9.2 MB per UGV, 300 s, on an 800 × 600 city).
const UGV_FIXED_BYTES: f64 = 3.0e6;

/// A UAV: its camera's reveal mask (1 B per cell), the map it publishes (shared with the
/// world's until it changes) and its compressed versions.
const UAV_BYTES_PER_CELL: f64 = 6.0;

/// A basestation or a UAV's fixed part.
const OTHER_FIXED_BYTES: f64 = 1.0e6;

/// What grows with the square of the team, per pair of robots and simulated second: every
/// robot's team-state records of the scans others shared (the scans themselves are held once;
/// a record is ≈ 150 B with its change-log entry) and what each robot tracks of what its peers
/// hold (a bit a scan), and each UGV's planner graph over the team's scans (calibrated on the
/// 50-UGV bench mission run for its full 1800 s: 734 MB; 650 B before the team state's records
/// and peer tables were shrunk).
const TEAM_STATE_BYTES_PER_PAIR_S: f64 = 90.0;

/// Terrain analysis (one analyzer lent in turn to the robots stepped) and the transient scratch
/// of the robot being stepped.
const STEP_SCRATCH_BYTES: f64 = 6e6;

/// Above this share of the memory available, the run is flagged as close to the limit.
const CLOSE_FRACTION: f64 = 0.8;

/// The size of what a run has to hold.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sizes {
    /// Cells of the operating area.
    pub cells: f64,
    /// Pixels of a UGV's panorama.
    pub panorama_pixels: f64,
    /// Robots of each kind.
    pub ugvs: usize,
    /// UAVs.
    pub uavs: usize,
    /// Basestations.
    pub basestations: usize,
    /// Whether the robots start with the whole map.
    pub prior_map: bool,
    /// Simulated seconds (the time limit).
    pub duration_s: f64,
}

/// The estimate, by part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// The process and the world, held once.
    pub world_bytes: f64,
    /// One UGV.
    pub per_ugv_bytes: f64,
    /// One UAV.
    pub per_uav_bytes: f64,
    /// One basestation.
    pub per_basestation_bytes: f64,
    /// The team state's pairwise part at the end of the run.
    pub team_state_bytes: f64,
    /// Everything.
    pub total_bytes: f64,
}

/// The memory a run of one trial of a team of these sizes needs at its peak.
pub fn estimate(sizes: &Sizes) -> Estimate {
    let world_bytes = PROCESS_BYTES + WORLD_BYTES_PER_CELL * sizes.cells + STEP_SCRATCH_BYTES;
    let own_map = if sizes.prior_map { 0.0 } else { UGV_OWN_MAP_BYTES_PER_CELL };
    let per_ugv_bytes =
        (UGV_BYTES_PER_CELL + own_map) * sizes.cells + UGV_BYTES_PER_PIXEL * sizes.panorama_pixels + UGV_FIXED_BYTES;
    let other_map = if sizes.prior_map { 0.0 } else { OTHER_OWN_MAP_BYTES_PER_CELL * sizes.cells };
    let per_uav_bytes = UAV_BYTES_PER_CELL * sizes.cells + other_map + OTHER_FIXED_BYTES;
    let per_basestation_bytes = other_map + OTHER_FIXED_BYTES;
    let robots = (sizes.ugvs + sizes.uavs + sizes.basestations) as f64;
    let pairs = robots * (robots - 1.0).max(0.0) / 2.0;
    let team_state_bytes = TEAM_STATE_BYTES_PER_PAIR_S * pairs * sizes.duration_s.max(0.0);
    let total_bytes = world_bytes
        + per_ugv_bytes * sizes.ugvs as f64
        + per_uav_bytes * sizes.uavs as f64
        + per_basestation_bytes * sizes.basestations as f64
        + team_state_bytes;
    Estimate { world_bytes, per_ugv_bytes, per_uav_bytes, per_basestation_bytes, team_state_bytes, total_bytes }
}

/// What the estimate is held against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Budget {
    /// Bytes the run may use.
    pub available_bytes: f64,
    /// The machine's total, when known (for the message).
    pub total_bytes: Option<f64>,
    /// Where the figure comes from, for the message.
    pub source: BudgetSource,
}

/// Where a [`Budget`] comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BudgetSource {
    /// `MemAvailable` of `/proc/meminfo`.
    Machine,
    /// `--memory-budget-mb`.
    CommandLine,
}

/// The machine's memory from the text of `/proc/meminfo`: `MemAvailable` (else `MemFree`) and
/// `MemTotal`; `None` when neither figure is there.
pub fn parse_meminfo(text: &str) -> Option<Budget> {
    let field = |name: &str| {
        text.lines().find_map(|line| {
            let rest = line.strip_prefix(name)?.strip_prefix(':')?;
            let mut words = rest.split_whitespace();
            let value: f64 = words.next()?.parse().ok()?;
            let unit = match words.next() {
                Some("kB") => 1024.0,
                None => 1.0,
                Some(_) => return None,
            };
            Some(value * unit)
        })
    };
    let available = field("MemAvailable").or_else(|| field("MemFree"))?;
    Some(Budget { available_bytes: available, total_bytes: field("MemTotal"), source: BudgetSource::Machine })
}

/// The machine's budget (Linux), or `None` where `/proc/meminfo` cannot be read.
pub fn machine_budget() -> Option<Budget> {
    std::fs::read_to_string("/proc/meminfo").ok().as_deref().and_then(parse_meminfo)
}

/// The sizes of a mission's run: its world's cells (a generated city's from its size, a world
/// folder's from its layers), the simulator's panorama, its team.
pub fn sizes_of(mission: &MissionFile, base_dir: &Path) -> Result<Sizes, String> {
    let sim = SimSpec::of_mission(mission).map_err(|e| e.to_string())?;
    let cells = match &sim.world {
        Some(WorldSpec::Dir(dir)) => {
            let world = World::load(base_dir.join(dir)).map_err(|e| e.to_string())?;
            world.spec().len() as f64
        }
        Some(WorldSpec::Generate(g)) => cells_of_generated(g.size_m),
        None => {
            let city = spomp_world::CityParams::default();
            cells_of_generated([city.width_m, city.height_m])
        }
    };
    let sensor = SensorParams::default();
    let count = |kind: RobotKind| mission.team.iter().filter(|r| r.kind == kind).count();
    Ok(Sizes {
        cells,
        panorama_pixels: (sensor.rows * sensor.cols) as f64,
        ugvs: count(RobotKind::Ugv),
        uavs: count(RobotKind::Uav),
        basestations: count(RobotKind::Basestation),
        prior_map: sim.prior_map,
        duration_s: mission.time_limit_s,
    })
}

fn cells_of_generated(size_m: [f64; 2]) -> f64 {
    (size_m[0] / GENERATED_CELL_M).ceil().max(0.0) * (size_m[1] / GENERATED_CELL_M).ceil().max(0.0)
}

/// Megabytes, for messages.
fn mb(bytes: f64) -> String {
    format!("{:.0} MB", bytes / 1e6)
}

/// The estimate in words: the total and its parts.
pub fn describe(sizes: &Sizes, e: &Estimate) -> String {
    let mut parts = vec![format!("world and process {}", mb(e.world_bytes))];
    if sizes.ugvs > 0 {
        parts.push(format!("{} UGV(s) × {}", sizes.ugvs, mb(e.per_ugv_bytes)));
    }
    if sizes.uavs > 0 {
        parts.push(format!("{} UAV(s) × {}", sizes.uavs, mb(e.per_uav_bytes)));
    }
    if sizes.basestations > 0 {
        parts.push(format!("{} basestation(s) × {}", sizes.basestations, mb(e.per_basestation_bytes)));
    }
    if e.team_state_bytes >= 1e6 {
        parts.push(format!("team state between robots {}", mb(e.team_state_bytes)));
    }
    format!("about {} ({})", mb(e.total_bytes), parts.join(", "))
}

/// Checks a run of `parallel_trials` trials side by side against the budget: an error when it
/// cannot fit, a warning when it comes within [`CLOSE_FRACTION`] of it; `Ok(None)` when it
/// fits with room.
pub fn judge(sizes: &Sizes, parallel_trials: usize, budget: &Budget) -> Result<Option<String>, String> {
    let e = estimate(sizes);
    let trials = parallel_trials.max(1) as f64;
    let need = e.total_bytes * trials;
    let what = if parallel_trials > 1 {
        format!(
            "{parallel_trials} trials side by side need {} in all; one trial needs {}",
            mb(need),
            describe(sizes, &e)
        )
    } else {
        format!("a simulated run needs {}", describe(sizes, &e))
    };
    let have = match budget.source {
        BudgetSource::Machine => match budget.total_bytes {
            Some(total) => format!("this machine has {} available of {}", mb(budget.available_bytes), mb(total)),
            None => format!("this machine has {} available", mb(budget.available_bytes)),
        },
        BudgetSource::CommandLine => format!("the budget given is {}", mb(budget.available_bytes)),
    };
    if need > budget.available_bytes {
        Err(format!(
            "{what}, but {have}: the team cannot fit (fewer robots, a smaller world or a shorter time limit would)"
        ))
    } else if need > CLOSE_FRACTION * budget.available_bytes {
        Ok(Some(format!("{what}, close to what is available: {have}")))
    } else {
        Ok(None)
    }
}

/// How the memory stage runs: against the machine or a given budget, or not at all.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MemoryCheck {
    /// Against `/proc/meminfo`.
    Machine,
    /// Against this many bytes.
    Budget(f64),
    /// Not at all (`--ignore-memory`).
    Off,
}

impl MemoryCheck {
    /// From the command line's `--memory-budget-mb` and `--ignore-memory`.
    pub fn from_args(budget_mb: Option<f64>, ignore: bool) -> Self {
        match (ignore, budget_mb) {
            (true, _) => MemoryCheck::Off,
            (false, Some(mb)) => MemoryCheck::Budget(mb * 1e6),
            (false, None) => MemoryCheck::Machine,
        }
    }

    fn budget(self) -> Option<Budget> {
        match self {
            MemoryCheck::Machine => machine_budget(),
            MemoryCheck::Budget(bytes) => {
                Some(Budget { available_bytes: bytes, total_bytes: None, source: BudgetSource::CommandLine })
            }
            MemoryCheck::Off => None,
        }
    }
}

/// Runs the memory stage on a mission that passed the earlier stages: one diagnostic at the
/// mission's `team` (an error or a warning), or none.
pub fn check(loaded: &LoadedMission, check: MemoryCheck) -> Vec<Diagnostic> {
    let Some(mission) = loaded.mission.as_ref().filter(|_| loaded.is_valid()) else { return Vec::new() };
    let Some(budget) = check.budget() else { return Vec::new() };
    let Some(file) = loaded.files.first().cloned() else { return Vec::new() };
    let base_dir = file.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
    // A world that does not load is the world stage's error.
    let Ok(sizes) = sizes_of(mission, &base_dir) else { return Vec::new() };
    let root = loaded.sources.first().and_then(|text| yaml::parse(text).ok());
    let at = root.as_ref().and_then(|r| r.get("team").map(|n| n.loc)).unwrap_or(Loc {
        line: 1,
        column: 1,
        offset: None,
        len: 0,
    });
    match judge(&sizes, 1, &budget) {
        Ok(None) => Vec::new(),
        Ok(Some(warning)) => vec![Diagnostic::new(&file, at, "team", Stage::Memory, warning).into_warning()],
        Err(error) => {
            let hint = "; --ignore-memory to accept it anyway, --memory-budget-mb to check for another machine";
            vec![Diagnostic::new(&file, at, "team", Stage::Memory, format!("{error}{hint}"))]
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    fn city_team(ugvs: usize) -> Sizes {
        Sizes {
            cells: 800.0 * 600.0,
            panorama_pixels: 256.0 * 1024.0,
            ugvs,
            uavs: 1,
            basestations: 1,
            prior_map: true,
            duration_s: 300.0,
        }
    }

    #[test]
    fn the_estimate_adds_the_world_once_and_each_robot_by_kind() {
        let one = estimate(&city_team(1));
        let ten = estimate(&city_team(10));
        assert!((ten.per_ugv_bytes - one.per_ugv_bytes).abs() < 1.0, "a UGV costs the same in any team");
        let growth = ten.total_bytes - one.total_bytes;
        assert!(growth >= 9.0 * one.per_ugv_bytes, "nine more UGVs add at least nine UGVs' worth");
        assert_eq!(one.world_bytes, ten.world_bytes, "the world is held once");
        let without_prior = estimate(&Sizes { prior_map: false, ..city_team(1) });
        assert!(
            (without_prior.per_ugv_bytes - one.per_ugv_bytes - 25.0 * 480_000.0).abs() < 1.0,
            "without a prior map each UGV holds its own copy of the received map and its rasters"
        );
        assert!(
            (without_prior.per_basestation_bytes - one.per_basestation_bytes - 16.0 * 480_000.0).abs() < 1.0,
            "and so does the basestation"
        );
    }

    #[test]
    fn the_estimate_is_near_the_measured_peaks() {
        // Peak RSS of release builds (`/usr/bin/time -v spomp sim
        // adapters/sim/benches/missions/team-1uav-{1,10,50}ugv.yaml --time-limit-s 300`, and
        // the full 1800 s for 50), 800 × 600 cells, prior map: the estimate may be above (it is
        // a bound for refusing) but within a sensible factor.
        for (ugvs, duration_s, measured_mb) in
            [(1, 300.0, 77.0), (10, 300.0, 165.0), (50, 300.0, 540.0), (50, 1800.0, 734.0)]
        {
            let e = estimate(&Sizes { duration_s, ..city_team(ugvs) }).total_bytes / 1e6;
            let ratio = e / measured_mb;
            assert!(
                (0.9..=1.5).contains(&ratio),
                "{ugvs} UGVs, {duration_s} s: estimate {e:.0} MB, measured {measured_mb} MB"
            );
        }
        // The shipped mission (`missions/visit-all-vehicle-clusters.yaml`, seed 1, 1800 s, no
        // prior map): 136 MB.
        let shipped = Sizes { ugvs: 3, prior_map: false, duration_s: 1800.0, ..city_team(3) };
        let e = estimate(&shipped).total_bytes / 1e6;
        assert!((0.9..=1.5).contains(&(e / 136.0)), "shipped mission: estimate {e:.0} MB, measured 136 MB");
    }

    #[test]
    fn a_team_that_cannot_fit_is_refused_with_the_figures() {
        let budget = Budget { available_bytes: 8e9, total_bytes: Some(16e9), source: BudgetSource::Machine };
        let huge = city_team(5000);
        let Err(message) = judge(&huge, 1, &budget) else { panic!("5000 UGVs fit in 8 GB?") };
        let need = estimate(&huge).total_bytes;
        assert!(message.contains(&mb(need)), "{message}");
        assert!(message.contains("8000 MB available of 16000 MB"), "{message}");
        assert!(message.contains("5000 UGV(s)"), "{message}");
        assert_eq!(judge(&city_team(3), 1, &budget), Ok(None));
        // Close to the limit: a warning.
        let need_3 = estimate(&city_team(3)).total_bytes;
        let tight = Budget { available_bytes: need_3 / 0.9, total_bytes: None, source: BudgetSource::CommandLine };
        assert!(matches!(judge(&city_team(3), 1, &tight), Ok(Some(w)) if w.contains("the budget given is")));
        // Trials side by side multiply it.
        let roomy = Budget { available_bytes: need_3 * 3.0, total_bytes: None, source: BudgetSource::CommandLine };
        assert!(judge(&city_team(3), 2, &roomy).is_ok_and(|w| w.is_none()));
        assert!(judge(&city_team(3), 4, &roomy).is_err());
    }

    #[test]
    fn meminfo_is_read_in_kilobytes_and_falls_back_to_free_memory() {
        let text = "MemTotal:       16318460 kB\nMemFree:         1234567 kB\nMemAvailable:    8123456 kB\n";
        let b = parse_meminfo(text).unwrap();
        assert_eq!(b.available_bytes, 8123456.0 * 1024.0);
        assert_eq!(b.total_bytes, Some(16318460.0 * 1024.0));
        let old_kernel = "MemTotal: 1000 kB\nMemFree: 500 kB\n";
        assert_eq!(parse_meminfo(old_kernel).unwrap().available_bytes, 500.0 * 1024.0);
        assert_eq!(parse_meminfo("nonsense"), None);
        assert_eq!(parse_meminfo("MemAvailable: lots kB"), None);
    }

    #[test]
    fn generated_worlds_count_half_metre_cells() {
        assert_eq!(cells_of_generated([400.0, 300.0]), 480_000.0);
        assert_eq!(cells_of_generated([10.2, 1.0]), 21.0 * 2.0);
    }
}
