//! The aerial robot: straight-line waypoint flight at a fixed altitude, and the nadir camera
//! whose ground footprint reveals the orthomap tile by tile.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{ClassId, MapTile, Point2, Pose2, UNKNOWN_CLASS};

use crate::error::SimError;
use spomp_world::World;

/// Parameters of the aerial robot and its camera.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct UavParams {
    /// Flight altitude above the world's datum, metres (paper's simulation: 60 m).
    pub altitude_m: f64,
    /// Cruise speed, m/s.
    pub speed_mps: f64,
    /// Side of the square the camera sees on the ground, metres.
    pub footprint_size_m: f64,
    /// Side of the tiles the revealed map is cut into, cells (tiles align to a grid of this size).
    pub tile_cells: u32,
    /// Probability that a revealed cell carries a wrong class label (segmentation noise).
    pub label_noise_probability: f64,
}

impl Default for UavParams {
    fn default() -> Self {
        UavParams {
            altitude_m: 60.0,
            speed_mps: 5.0,
            footprint_size_m: 40.0,
            tile_cells: 64,
            label_noise_probability: 0.0,
        }
    }
}

/// An aerial robot flying a route of waypoints in straight lines at constant speed.
#[derive(Clone, Debug, PartialEq)]
pub struct Uav {
    params: UavParams,
    pose: Pose2,
    route: Vec<Point2>,
    next: usize,
    distance_m: f64,
}

impl Uav {
    /// A UAV hovering at `start` with no route.
    pub fn new(params: UavParams, start: Pose2) -> Result<Self, SimError> {
        if !(params.speed_mps.is_finite() && params.speed_mps > 0.0 && params.altitude_m.is_finite()) {
            return Err(SimError::invalid("UAV parameters", "speed_mps must be positive and altitude_m finite"));
        }
        Ok(Uav { params, pose: start, route: Vec::new(), next: 0, distance_m: 0.0 })
    }

    /// Replaces the route; the UAV flies to its first point next. Non-finite points are dropped.
    pub fn set_route(&mut self, route: Vec<Point2>) {
        self.route = route.into_iter().filter(|p| p.x.is_finite() && p.y.is_finite()).collect();
        self.next = 0;
    }

    /// Sets the cruise speed (a flight command's cap); non-positive or non-finite values are
    /// ignored.
    pub fn set_speed_mps(&mut self, speed_mps: f64) {
        if speed_mps.is_finite() && speed_mps > 0.0 {
            self.params.speed_mps = speed_mps;
        }
    }

    /// Flies straight to one point (seeking a robot, returning to a waypoint).
    pub fn go_to(&mut self, target: Point2) {
        self.set_route(vec![target]);
    }

    /// The point it is flying to, if any.
    pub fn target(&self) -> Option<Point2> {
        self.route.get(self.next).copied()
    }

    /// Index of the route point it is flying to (the route's length when done).
    pub fn next_waypoint(&self) -> usize {
        self.next
    }

    /// Whether every route point has been reached.
    pub fn route_done(&self) -> bool {
        self.next >= self.route.len()
    }

    /// Map-frame pose (yaw = direction of flight).
    pub fn pose(&self) -> Pose2 {
        self.pose
    }

    /// Altitude, metres.
    pub fn altitude_m(&self) -> f64 {
        self.params.altitude_m
    }

    /// Distance flown so far, metres.
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    /// The parameters.
    pub fn params(&self) -> &UavParams {
        &self.params
    }

    /// Flies for `dt_s` seconds; passes through as many waypoints as the time allows.
    /// Returns the distance flown.
    pub fn step(&mut self, dt_s: f64) -> f64 {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return 0.0;
        }
        let mut budget = self.params.speed_mps * dt_s;
        let mut flown = 0.0;
        while budget > 0.0 {
            let Some(target) = self.target() else { break };
            let here = self.pose.position();
            let d = here.distance(target);
            if d > 1e-9 {
                self.pose.yaw = (target - here).angle();
            }
            if d <= budget {
                self.pose.x = target.x;
                self.pose.y = target.y;
                budget -= d;
                flown += d;
                self.next += 1;
            } else {
                let p = here + (target - here) * (budget / d);
                self.pose.x = p.x;
                self.pose.y = p.y;
                flown += budget;
                budget = 0.0;
            }
        }
        self.distance_m += flown;
        flown
    }
}

/// The UAV's nadir camera: reveals the world's layers under its square footprint, once per cell.
#[derive(Clone, Debug)]
pub struct OrthoCamera {
    footprint_size_m: f64,
    tile_cells: u32,
    noise_probability: f64,
    revealed: Vec<bool>,
    revealed_count: usize,
    labels: Vec<ClassId>,
    rng: ChaCha8Rng,
}

impl OrthoCamera {
    /// A camera over `world` that has seen nothing yet; `seed` drives the label noise.
    pub fn new(params: &UavParams, world: &World, seed: u64) -> Result<Self, SimError> {
        if !(params.footprint_size_m.is_finite() && params.footprint_size_m > 0.0) || params.tile_cells == 0 {
            return Err(SimError::invalid("UAV camera", "footprint_size_m and tile_cells must be positive"));
        }
        if !(0.0..=1.0).contains(&params.label_noise_probability) {
            return Err(SimError::invalid("UAV camera", "label_noise_probability must be in [0, 1]"));
        }
        let labels = world.classes().classes.iter().filter(|c| !c.ignored).map(|c| c.index).collect();
        Ok(OrthoCamera {
            footprint_size_m: params.footprint_size_m,
            tile_cells: params.tile_cells,
            noise_probability: params.label_noise_probability,
            revealed: vec![false; world.spec().len()],
            revealed_count: 0,
            labels,
            rng: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    /// Number of cells revealed so far.
    pub fn revealed_cells(&self) -> usize {
        self.revealed_count
    }

    /// Whether a cell (row-major index) has been revealed.
    pub fn is_revealed(&self, index: usize) -> bool {
        self.revealed.get(index).copied().unwrap_or(false)
    }

    /// The tiles of cells under the footprint (an axis-aligned square centred below `pose`)
    /// that were not revealed before. Tiles follow a fixed grid of `tile_cells`; within a
    /// tile, cells revealed earlier are left unknown so they are not applied again.
    pub fn reveal(&mut self, world: &World, pose: Pose2) -> Vec<MapTile> {
        let spec = *world.spec();
        if self.revealed.len() != spec.len() || !(pose.x.is_finite() && pose.y.is_finite()) {
            return Vec::new();
        }
        let half = self.footprint_size_m / 2.0 / spec.resolution_m;
        let (fx, fy) = ((pose.x - spec.origin.x) / spec.resolution_m, (pose.y - spec.origin.y) / spec.resolution_m);
        let clamp_w = |v: f64| v.round().clamp(0.0, spec.width as f64) as u32;
        let clamp_h = |v: f64| v.round().clamp(0.0, spec.height as f64) as u32;
        let (c0, c1) = (clamp_w(fx - half), clamp_w(fx + half));
        let (r0, r1) = (clamp_h(fy - half), clamp_h(fy + half));
        let mut tiles = Vec::new();
        if c0 >= c1 || r0 >= r1 {
            return tiles;
        }
        let ts = self.tile_cells;
        for tr in (r0 / ts)..=((r1 - 1) / ts) {
            for tc in (c0 / ts)..=((c1 - 1) / ts) {
                let (tc0, tc1) = ((tc * ts).max(c0), ((tc + 1) * ts).min(c1));
                let (tr0, tr1) = ((tr * ts).max(r0), ((tr + 1) * ts).min(r1));
                if let Some(tile) = self.cut_tile(world, tc0, tc1, tr0, tr1) {
                    tiles.push(tile);
                }
            }
        }
        tiles
    }

    fn cut_tile(&mut self, world: &World, c0: u32, c1: u32, r0: u32, r1: u32) -> Option<MapTile> {
        let spec = world.spec();
        let (tw, th) = (c1 - c0, r1 - r0);
        let n = tw as usize * th as usize;
        let mut tile = MapTile {
            col0: c0,
            row0: r0,
            width: tw,
            height: th,
            class: vec![UNKNOWN_CLASS; n],
            rgb: vec![[0, 0, 0]; n],
            elevation: vec![f32::NAN; n],
        };
        let mut any = false;
        for row in r0..r1 {
            for col in c0..c1 {
                let wi = row as usize * spec.width as usize + col as usize;
                if self.revealed[wi] {
                    continue;
                }
                self.revealed[wi] = true;
                self.revealed_count += 1;
                any = true;
                let ti = (row - r0) as usize * tw as usize + (col - c0) as usize;
                // The camera sees the world from above (its aerial view, where that differs).
                let seen = world.aerial_map();
                let mut label = seen.class[wi];
                if self.noise_probability > 0.0
                    && !self.labels.is_empty()
                    && self.rng.random_bool(self.noise_probability)
                {
                    label = self.labels[self.rng.random_range(0..self.labels.len())];
                }
                tile.class[ti] = label;
                tile.rgb[ti] = seen.rgb[wi];
                tile.elevation[ti] = seen.elevation[wi];
            }
        }
        any.then_some(tile)
    }
}
