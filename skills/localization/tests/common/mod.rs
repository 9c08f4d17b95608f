//! A small synthetic world (aerial class map with roads, grass, gravel lots, buildings,
//! vegetation and vehicles) and a renderer of the semantic + depth panoramas a ground robot
//! would see in it, following the core panorama convention exactly. Shared by the integration
//! tests and the benchmark.
#![allow(dead_code)]
#![allow(clippy::unwrap_used)] // test support code may unwrap (house rule)

use std::sync::Arc;

use rand::Rng;
use spomp_core::{
    AerialMap, DepthPanorama, GridSpec, PanoramaFrame, PanoramaGeometry, Point2, Pose2, SemanticPanorama, Time,
    UNKNOWN_CLASS,
};

pub const ROAD: u8 = 0;
pub const VEGETATION: u8 = 1;
pub const BUILDING: u8 = 2;
pub const GRASS: u8 = 3;
pub const VEHICLE: u8 = 4;
pub const GRAVEL: u8 = 6;

/// Height of the classes that stand up from the ground, metres (0 = flat).
pub fn class_height_m(class: u8) -> f64 {
    match class {
        BUILDING => 8.0,
        VEGETATION => 3.0,
        VEHICLE => 1.5,
        _ => 0.0,
    }
}

/// The world: an aerial class map that is also the ground truth.
pub struct World {
    pub map: AerialMap,
}

fn fill_rect(map: &mut AerialMap, x0: f64, y0: f64, x1: f64, y1: f64, class: u8) {
    let spec = map.spec;
    for row in 0..spec.height {
        for col in 0..spec.width {
            let c = spec.center(spomp_core::Cell::new(col, row));
            if c.x >= x0 && c.x < x1 && c.y >= y0 && c.y < y1 {
                let i = spec.index(spomp_core::Cell::new(col, row));
                map.class[i] = class;
            }
        }
    }
}

fn fill_segment(map: &mut AerialMap, a: Point2, b: Point2, half_width: f64, class: u8) {
    let spec = map.spec;
    let ab = b - a;
    let len2 = ab.dot(ab);
    for row in 0..spec.height {
        for col in 0..spec.width {
            let c = spec.center(spomp_core::Cell::new(col, row));
            let t = ((c - a).dot(ab) / len2).clamp(0.0, 1.0);
            if c.distance(a + ab * t) <= half_width {
                let i = spec.index(spomp_core::Cell::new(col, row));
                map.class[i] = class;
            }
        }
    }
}

impl World {
    /// A 120 m × 120 m town at 0.5 m per cell: a road grid with one diagonal, buildings of
    /// different sizes, gravel lots with parked vehicles and patches of vegetation on grass.
    pub fn town() -> Self {
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 240, 240);
        let mut map = AerialMap::unknown(spec);
        map.class.iter_mut().for_each(|c| *c = GRASS);
        fill_rect(&mut map, 60.0, 38.0, 78.0, 50.0, GRAVEL);
        fill_rect(&mut map, 28.0, 62.0, 44.0, 70.0, GRAVEL);
        fill_rect(&mut map, 5.0, 28.0, 115.0, 34.0, ROAD);
        fill_rect(&mut map, 20.0, 53.0, 70.0, 59.0, ROAD);
        fill_rect(&mut map, 20.0, 5.0, 26.0, 90.0, ROAD);
        fill_rect(&mut map, 50.0, 28.0, 56.0, 100.0, ROAD);
        fill_rect(&mut map, 20.0, 85.0, 100.0, 90.0, ROAD);
        fill_segment(&mut map, Point2::new(56.0, 59.0), Point2::new(100.0, 20.0), 2.5, ROAD);
        fill_rect(&mut map, 30.0, 38.0, 45.0, 49.0, BUILDING);
        fill_rect(&mut map, 60.0, 63.0, 74.0, 80.0, BUILDING);
        fill_rect(&mut map, 5.0, 40.0, 16.0, 62.0, BUILDING);
        fill_rect(&mut map, 90.0, 40.0, 112.0, 52.0, BUILDING);
        fill_rect(&mut map, 32.0, 10.0, 44.0, 22.0, BUILDING);
        fill_rect(&mut map, 62.0, 4.0, 80.0, 16.0, BUILDING);
        fill_rect(&mut map, 92.0, 62.0, 104.0, 78.0, VEGETATION);
        fill_rect(&mut map, 30.0, 92.0, 44.0, 104.0, VEGETATION);
        fill_rect(&mut map, 5.0, 70.0, 14.0, 80.0, VEGETATION);
        fill_rect(&mut map, 28.0, 36.0, 29.0, 37.0, VEGETATION); // a lone tree by the road
        fill_rect(&mut map, 62.0, 40.0, 66.5, 42.0, VEHICLE);
        fill_rect(&mut map, 70.0, 44.0, 74.5, 46.0, VEHICLE);
        fill_rect(&mut map, 32.0, 64.0, 36.5, 66.0, VEHICLE);
        map.version = 1;
        World { map }
    }

    /// A bigger world for the benchmark: the town tiled over `width × height` cells.
    pub fn tiled(width: u32, height: u32) -> Self {
        let town = World::town();
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, width, height);
        let mut map = AerialMap::unknown(spec);
        let ts = town.map.spec;
        for row in 0..height {
            for col in 0..width {
                let src = spomp_core::Cell::new(col % ts.width, row % ts.height);
                map.class[spec.index(spomp_core::Cell::new(col, row))] = town.map.class_at(src);
            }
        }
        map.version = 1;
        World { map }
    }

    /// Class at a map point (unknown off the map).
    pub fn class_at(&self, p: Point2) -> u8 {
        self.map.spec.cell_at(p).map_or(UNKNOWN_CLASS, |c| self.map.class_at(c))
    }
}

/// Renders what a robot at `pose` sees: per column a horizontal ray is marched to the first
/// standing cell (a wall of that class's height); each row below the horizon hits the flat
/// ground at range h / sin(−elevation) unless the wall is nearer; rows above see the wall up to
/// its height. `label_noise` is the fraction of pixels given a random wrong label.
pub fn render<R: Rng>(
    world: &World,
    pose: Pose2,
    geometry: PanoramaGeometry,
    sensor_height_m: f64,
    label_noise: f64,
    rng: &mut R,
) -> (DepthPanorama, SemanticPanorama) {
    const MAX_RANGE_M: f64 = 40.0;
    const STEP_M: f64 = 0.1;
    let mut depth = DepthPanorama::empty(geometry);
    let mut class = vec![UNKNOWN_CLASS; geometry.len()];
    let origin = pose.position();
    for col in 0..geometry.cols {
        let heading = pose.yaw + geometry.azimuth_of_col(col);
        let dir = Point2::new(heading.cos(), heading.sin());
        // First standing cell along the ray.
        let mut wall: Option<(f64, u8)> = None;
        let mut r = STEP_M;
        while r <= MAX_RANGE_M {
            let c = world.class_at(origin + dir * r);
            if class_height_m(c) > 0.0 {
                wall = Some((r, c));
                break;
            }
            r += STEP_M;
        }
        for row in 0..geometry.rows {
            let el = geometry.elevation_of_row(row);
            let ground_r = if el < 0.0 { sensor_height_m / (-el).tan() } else { f64::INFINITY };
            let hit = match wall {
                Some((wr, wc)) if wr < ground_r => {
                    let z = sensor_height_m + wr * el.tan();
                    (z <= class_height_m(wc)).then(|| (wr / el.cos(), wc))
                }
                _ if ground_r <= MAX_RANGE_M => {
                    let c = world.class_at(origin + dir * ground_r);
                    (c != UNKNOWN_CLASS).then(|| (sensor_height_m / (-el).sin(), c))
                }
                _ => None,
            };
            if let Some((range, c)) = hit {
                let i = row * geometry.cols + col;
                depth.range_m[i] = range as f32;
                class[i] = if label_noise > 0.0 && rng.random::<f64>() < label_noise {
                    [ROAD, GRASS, BUILDING, GRAVEL, VEGETATION][rng.random_range(0..5)]
                } else {
                    c
                };
            }
        }
    }
    (depth, SemanticPanorama { geometry, class })
}

/// A panorama frame as the robot receives it.
pub fn frame(
    seq: u64,
    stamp_s: f64,
    odom_pose: Pose2,
    sensor_height_m: f64,
    (depth, semantic): (DepthPanorama, SemanticPanorama),
) -> PanoramaFrame {
    PanoramaFrame {
        seq,
        stamp: Time::from_secs_f64(stamp_s),
        odom_pose,
        sensor_height_m,
        depth: Arc::new(depth),
        semantic: Arc::new(semantic),
    }
}

/// Poses every `step_m` metres along a closed polyline (heading along the path), starting at
/// its first vertex, for `laps` laps.
pub fn loop_route(corners: &[Point2], step_m: f64, laps: f64) -> Vec<Pose2> {
    let n = corners.len();
    let lengths: Vec<f64> = (0..n).map(|i| corners[i].distance(corners[(i + 1) % n])).collect();
    let perimeter: f64 = lengths.iter().sum();
    let total = perimeter * laps;
    let mut poses = Vec::new();
    let mut s = 0.0;
    while s <= total + 1e-9 {
        let mut along = s % perimeter;
        let mut i = 0;
        while along > lengths[i] {
            along -= lengths[i];
            i = (i + 1) % n;
        }
        let a = corners[i];
        let b = corners[(i + 1) % n];
        let d = (b - a) * (1.0 / lengths[i]);
        poses.push(Pose2::new(a.x + d.x * along, a.y + d.y * along, d.angle()));
        s += step_m;
    }
    poses
}

/// The relative motions between consecutive poses.
pub fn steps(truth: &[Pose2]) -> Vec<Pose2> {
    truth.windows(2).map(|w| w[0].between(w[1])).collect()
}

/// Noisy odometry of a sequence of true relative motions: each gets a scale error, lateral
/// noise, heading noise and a heading bias, so the odometry frame drifts.
pub fn noisy_odometry<R: Rng>(motions: &[Pose2], rng: &mut R, heading_bias_rad_per_step: f64) -> Vec<Pose2> {
    use rand_distr::{Distribution, Normal};
    let unit = Normal::new(0.0, 1.0).unwrap();
    let mut odom = vec![Pose2::new(7.0, -3.0, 0.4)]; // an arbitrary odometry frame
    for &d in motions {
        let noisy = Pose2::new(
            d.x * (1.0 + 0.02 * unit.sample(rng)),
            d.y + 0.02 * unit.sample(rng),
            d.yaw + 0.01 * unit.sample(rng) + heading_bias_rad_per_step,
        );
        let last = *odom.last().unwrap();
        odom.push(last.compose(noisy));
    }
    odom
}

/// Position error between two poses, metres.
pub fn position_error(a: Pose2, b: Pose2) -> f64 {
    a.position().distance(b.position())
}

/// Median of a list.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
