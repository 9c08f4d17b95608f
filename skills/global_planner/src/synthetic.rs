//! Synthetic inputs for tests, benchmarks and demos: a procedural city orthomap and reachability
//! scans ray cast against a ground truth.

use spomp_core::{AerialMap, GridSpec, Point2, Pose2, ReachabilityScan, RobotId, Time};

/// Class indices of the default table used by the generator.
pub mod class {
    /// Road.
    pub const ROAD: u8 = 0;
    /// Vegetation.
    pub const VEGETATION: u8 = 1;
    /// Building.
    pub const BUILDING: u8 = 2;
    /// Grass / sidewalk.
    pub const SIDEWALK: u8 = 3;
    /// Vehicle.
    pub const VEHICLE: u8 = 4;
    /// Gravel.
    pub const GRAVEL: u8 = 6;
}

/// Colours of the generated map.
pub mod color {
    /// Road asphalt.
    pub const ROAD: [u8; 3] = [90, 90, 95];
    /// Sidewalk paving.
    pub const SIDEWALK: [u8; 3] = [185, 180, 170];
    /// Curb along a sidewalk (class sidewalk, not climbable).
    pub const CURB: [u8; 3] = [140, 140, 150];
    /// Ramp through a curb (class sidewalk, climbable).
    pub const RAMP: [u8; 3] = [210, 160, 110];
    /// Roof.
    pub const BUILDING: [u8; 3] = [150, 60, 50];
    /// Lawn.
    pub const GRASS: [u8; 3] = [70, 150, 60];
    /// Gravel lot.
    pub const GRAVEL: [u8; 3] = [160, 140, 110];
    /// Car.
    pub const VEHICLE: [u8; 3] = [30, 60, 200];
    /// Shrubs.
    pub const VEGETATION: [u8; 3] = [30, 100, 30];
}

/// Layout of the generated city, in cells of 0.5 m.
#[derive(Clone, Copy, Debug)]
pub struct CityLayout {
    /// Block pitch (road to road), cells.
    pub block_cells: usize,
    /// Road width, cells.
    pub road_cells: usize,
    /// Sidewalk width (curb included), cells.
    pub sidewalk_cells: usize,
    /// A ramp every this many cells along each curb (0 = none), cells.
    pub ramp_every_cells: usize,
    /// Ramp length, cells.
    pub ramp_cells: usize,
}

impl Default for CityLayout {
    fn default() -> Self {
        CityLayout { block_cells: 100, road_cells: 20, sidewalk_cells: 6, ramp_every_cells: 40, ramp_cells: 4 }
    }
}

fn hash(a: u64, b: u64, seed: u64) -> u64 {
    // SplitMix64 finaliser over the combined inputs: cheap, deterministic variation.
    let mut z = a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F) ^ seed;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A city of square blocks on a road grid: sidewalks with curbs and coloured ramps, and block
/// interiors that are buildings, parks (grass, shrubs) or gravel lots with cars. All cells known.
pub fn city_map(width: u32, height: u32, layout: CityLayout, seed: u64) -> AerialMap {
    let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, width, height);
    let mut map = AerialMap::unknown(spec);
    let p = layout.block_cells.max(layout.road_cells + 2 * layout.sidewalk_cells + 2);
    let road = layout.road_cells;
    let side = layout.sidewalk_cells;
    for row in 0..height as usize {
        for col in 0..width as usize {
            let (u, v) = (col % p, row % p);
            let (bx, by) = ((col / p) as u64, (row / p) as u64);
            let i = row * width as usize + col;
            let on_road = u < road || v < road;
            let (class, rgb, elev) = if on_road {
                (class::ROAD, color::ROAD, 0.0)
            } else {
                // Cells from the nearest road, per axis (the next road starts at u = p).
                let du = (u - road).min(p - 1 - u);
                let dv2 = (v - road).min(p - 1 - v);
                let edge = du.min(dv2);
                if edge < side {
                    let curb = edge == 0;
                    let along = if du <= dv2 { row } else { col };
                    let ramp =
                        layout.ramp_every_cells > 0 && curb && (along % layout.ramp_every_cells) < layout.ramp_cells;
                    let rgb = if ramp {
                        color::RAMP
                    } else if curb {
                        color::CURB
                    } else {
                        color::SIDEWALK
                    };
                    (class::SIDEWALK, rgb, 0.15)
                } else {
                    match hash(bx, by, seed) % 5 {
                        0 => {
                            let h = hash(col as u64 / 4, row as u64 / 4, seed ^ 1) % 10;
                            if h == 0 {
                                (class::VEGETATION, color::VEGETATION, 0.5)
                            } else {
                                (class::SIDEWALK, color::GRASS, 0.0)
                            }
                        }
                        1 => {
                            let car = (col / 5 + row / 10) % 3 == 0
                                && hash(col as u64 / 5, row as u64 / 10, seed).is_multiple_of(2);
                            if car {
                                (class::VEHICLE, color::VEHICLE, 1.5)
                            } else {
                                (class::GRAVEL, color::GRAVEL, 0.0)
                            }
                        }
                        _ => (class::BUILDING, color::BUILDING, 12.0),
                    }
                }
            };
            map.class[i] = class;
            map.rgb[i] = rgb;
            map.elevation[i] = elev;
        }
    }
    map.version = 1;
    map
}

/// What a ray finds at a point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Probe {
    /// Drivable.
    Free,
    /// A known obstacle.
    Obstacle,
    /// Nothing known (no return, occluded).
    Unknown,
}

/// A reachability scan by marching each bin's ray in `step_m` steps until `probe` reports an
/// obstacle (known obstacle), the unknown, or `max_range_m` (unknown beyond).
pub fn raycast_scan(
    robot: &str,
    stamp: Time,
    pose: Pose2,
    bins: usize,
    max_range_m: f64,
    step_m: f64,
    probe: impl Fn(Point2) -> Probe,
) -> ReachabilityScan {
    let step = if step_m > 0.0 { step_m } else { 0.25 };
    let mut range_m = Vec::with_capacity(bins);
    let mut obstacle = Vec::with_capacity(bins);
    for b in 0..bins {
        let a = pose.yaw - b as f64 * std::f64::consts::TAU / bins as f64;
        let dir = Point2::new(a.cos(), a.sin());
        let mut r = 0.0;
        let mut hit = false;
        while r + step <= max_range_m {
            match probe(pose.position() + dir * (r + step)) {
                Probe::Free => r += step,
                Probe::Obstacle => {
                    hit = true;
                    break;
                }
                Probe::Unknown => break,
            }
        }
        range_m.push(r as f32);
        obstacle.push(hit);
    }
    ReachabilityScan { robot: RobotId::new(robot), stamp, pose, range_m, obstacle }
}

/// Ground truth of a generated city: a curb without a ramp, buildings, cars and shrubs block; the
/// rest is drivable.
pub fn city_probe(map: &AerialMap) -> impl Fn(Point2) -> Probe + '_ {
    move |p| match map.spec.cell_at(p).map(|c| map.spec.index(c)) {
        None => Probe::Unknown,
        Some(i) => {
            let blocked = matches!(map.class[i], class::BUILDING | class::VEHICLE | class::VEGETATION | 7 | 8)
                || map.rgb[i] == color::CURB;
            if map.class[i] == spomp_core::UNKNOWN_CLASS {
                Probe::Unknown
            } else if blocked {
                Probe::Obstacle
            } else {
                Probe::Free
            }
        }
    }
}
