//! The procedural city (the paper's simulation environment, rebuilt as a 2.5D grid): a road
//! grid, raised blocks behind a curb with sidewalks and coloured ramps, buildings, grass, trees,
//! light poles, parking lots holding vehicle clusters, and roadblocks that stay labelled road.

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{AerialMap, ClassId, ClassTable, GridSpec, Point2, Pose2};

use crate::error::WorldError;
use crate::terrain::UgvLimits;
use crate::world::{World, WorldMeta};

/// Parameters of the city generator.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CityParams {
    /// World extent east–west, metres.
    pub width_m: f64,
    /// World extent north–south, metres.
    pub height_m: f64,
    /// Cell size, metres.
    pub resolution_m: f64,
    /// Target distance between neighbouring road centre lines, metres (stretched to fit).
    pub block_pitch_m: f64,
    /// Road width, metres.
    pub road_width_m: f64,
    /// Sidewalk width along every block edge, metres.
    pub sidewalk_width_m: f64,
    /// Height of the curb between road and block, metres.
    pub curb_height_m: f64,
    /// Probability that a block corner has ramps (one on each of its two sidewalks).
    pub ramp_probability: f64,
    /// Width of a ramp along the curb, metres.
    pub ramp_width_m: f64,
    /// Ramp colour: differs from the sidewalk although the class is the same.
    pub ramp_color: [u8; 3],
    /// Lowest building, metres.
    pub building_min_height_m: f64,
    /// Tallest building, metres.
    pub building_max_height_m: f64,
    /// Gap between a building and the sidewalk, metres.
    pub building_setback_m: f64,
    /// Number of vehicle clusters (one parking lot each).
    pub vehicle_clusters: usize,
    /// Fewest vehicles in a cluster.
    pub vehicles_per_cluster_min: usize,
    /// Most vehicles in a cluster.
    pub vehicles_per_cluster_max: usize,
    /// Vehicle length, metres.
    pub vehicle_length_m: f64,
    /// Vehicle width, metres.
    pub vehicle_width_m: f64,
    /// Vehicle height, metres.
    pub vehicle_height_m: f64,
    /// Fraction of parking lots surfaced with gravel instead of asphalt.
    pub parking_gravel_fraction: f64,
    /// Trees per block (trunk plus vegetation around it).
    pub trees_per_block: usize,
    /// Trunk height, metres.
    pub tree_trunk_height_m: f64,
    /// Radius of the vegetation around a trunk, metres.
    pub tree_canopy_radius_m: f64,
    /// Height of vegetation above the ground it grows on, metres.
    pub vegetation_height_m: f64,
    /// Distance between light poles along a sidewalk, metres.
    pub light_pole_spacing_m: f64,
    /// Light pole height, metres.
    pub light_pole_height_m: f64,
    /// Number of roadblocks (each across a whole road, between two crossings).
    pub roadblocks: usize,
    /// Roadblock height, metres.
    pub roadblock_height_m: f64,
    /// Roadblock thickness along the road, metres.
    pub roadblock_thickness_m: f64,
    /// Roadblock colour (labelled road all the same).
    pub roadblock_color: [u8; 3],
    /// Number of start poses to report (on the road at the south-west crossing).
    pub team_start_poses: usize,
    /// Distance between start poses, metres.
    pub start_spacing_m: f64,
    /// Uniform per-channel colour noise, ± counts.
    pub color_noise: u8,
}

impl Default for CityParams {
    fn default() -> Self {
        CityParams {
            width_m: 400.0,
            height_m: 300.0,
            resolution_m: 0.5,
            block_pitch_m: 60.0,
            road_width_m: 10.0,
            sidewalk_width_m: 3.0,
            curb_height_m: 0.15,
            ramp_probability: 0.5,
            ramp_width_m: 3.0,
            ramp_color: [214, 180, 70],
            building_min_height_m: 8.0,
            building_max_height_m: 30.0,
            building_setback_m: 2.0,
            vehicle_clusters: 15,
            vehicles_per_cluster_min: 3,
            vehicles_per_cluster_max: 6,
            vehicle_length_m: 4.5,
            vehicle_width_m: 2.0,
            vehicle_height_m: 1.5,
            parking_gravel_fraction: 0.3,
            trees_per_block: 4,
            tree_trunk_height_m: 5.0,
            tree_canopy_radius_m: 1.5,
            vegetation_height_m: 1.0,
            light_pole_spacing_m: 30.0,
            light_pole_height_m: 6.0,
            roadblocks: 6,
            roadblock_height_m: 1.2,
            roadblock_thickness_m: 1.0,
            roadblock_color: [190, 190, 185],
            team_start_poses: 10,
            start_spacing_m: 3.0,
            color_noise: 8,
        }
    }
}

/// What a cell is made of, while generating (decides colour and what may be painted over).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Surface {
    Road,
    Sidewalk,
    Ramp,
    Grass,
    Building,
    Asphalt,
    Gravel,
    Vehicle,
    Trunk,
    Vegetation,
    Pole,
    Roadblock,
}

/// Class ids of the default table, looked up by name once.
struct Classes {
    road: ClassId,
    sidewalk: ClassId,
    building: ClassId,
    vegetation: ClassId,
    vehicle: ClassId,
    gravel: ClassId,
    trunk: ClassId,
    pole: ClassId,
}

impl Classes {
    fn from_table(t: &ClassTable) -> Result<Self, WorldError> {
        let id = |name: &str| {
            t.by_name(name)
                .map(|c| c.index)
                .ok_or_else(|| WorldError::invalid("class table", format!("the city needs class `{name}`")))
        };
        Ok(Classes {
            road: id("road")?,
            sidewalk: id("grass_sidewalk")?,
            building: id("building")?,
            vegetation: id("vegetation")?,
            vehicle: id("vehicle")?,
            gravel: id("gravel")?,
            trunk: id("tree_trunk")?,
            pole: id("light_pole")?,
        })
    }
}

/// An axis-aligned rectangle in metres.
#[derive(Clone, Copy, Debug)]
struct Rect {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Rect {
    fn inset(self, d: f64) -> Rect {
        Rect { x0: self.x0 + d, y0: self.y0 + d, x1: self.x1 - d, y1: self.y1 - d }
    }
    fn w(&self) -> f64 {
        self.x1 - self.x0
    }
    fn h(&self) -> f64 {
        self.y1 - self.y0
    }
    fn center(&self) -> Point2 {
        Point2::new(0.5 * (self.x0 + self.x1), 0.5 * (self.y0 + self.y1))
    }
}

/// The canvas the generator paints on: a surface and an elevation per cell.
struct Canvas {
    spec: GridSpec,
    surface: Vec<Surface>,
    elevation: Vec<f64>,
    /// Per-cell colour override (buildings and vehicles get one colour each).
    tint: Vec<Option<[u8; 3]>>,
}

impl Canvas {
    /// Cells whose centres lie inside `r`, as (col, row) ranges.
    fn cells(&self, r: Rect) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        let res = self.spec.resolution_m;
        let to_col = |x: f64| ((x - self.spec.origin.x) / res - 0.5).ceil().clamp(0.0, self.spec.width as f64) as usize;
        let to_row =
            |y: f64| ((y - self.spec.origin.y) / res - 0.5).ceil().clamp(0.0, self.spec.height as f64) as usize;
        (to_col(r.x0)..to_col(r.x1), to_row(r.y0)..to_row(r.y1))
    }

    fn fill(&mut self, r: Rect, s: Surface, elevation_m: f64, tint: Option<[u8; 3]>) {
        let (cols, rows) = self.cells(r);
        for row in rows {
            for col in cols.clone() {
                let i = row * self.spec.width as usize + col;
                self.surface[i] = s;
                self.elevation[i] = elevation_m;
                self.tint[i] = tint;
            }
        }
    }

    /// Whether every cell of `r` has one of the surfaces in `allowed`.
    fn all_of(&self, r: Rect, allowed: &[Surface]) -> bool {
        let (cols, rows) = self.cells(r);
        rows.flat_map(|row| cols.clone().map(move |col| (row, col)))
            .all(|(row, col)| allowed.contains(&self.surface[row * self.spec.width as usize + col]))
    }

    /// Whether no cell of `r` has one of the surfaces in `banned`.
    fn none_of(&self, r: Rect, banned: &[Surface]) -> bool {
        let (cols, rows) = self.cells(r);
        rows.flat_map(|row| cols.clone().map(move |col| (row, col)))
            .all(|(row, col)| !banned.contains(&self.surface[row * self.spec.width as usize + col]))
    }

    fn center_of(&self, col: usize, row: usize) -> Point2 {
        self.spec.center(spomp_core::Cell::new(col as u32, row as u32))
    }
}

/// Millimetre-rounded elevation: keeps the 16-bit elevation file exact.
fn mm(e: f64) -> f64 {
    (e * 1000.0).round() / 1000.0
}

fn check(p: &CityParams) -> Result<(), WorldError> {
    let bad = |m: String| Err(WorldError::invalid("city parameters", m));
    let positive = [
        ("width_m", p.width_m),
        ("height_m", p.height_m),
        ("resolution_m", p.resolution_m),
        ("block_pitch_m", p.block_pitch_m),
        ("road_width_m", p.road_width_m),
        ("vehicle_length_m", p.vehicle_length_m),
        ("vehicle_width_m", p.vehicle_width_m),
        ("light_pole_spacing_m", p.light_pole_spacing_m),
        ("start_spacing_m", p.start_spacing_m),
    ];
    for (name, v) in positive {
        if !(v.is_finite() && v > 0.0) {
            return bad(format!("{name} must be positive, got {v}"));
        }
    }
    let cells = (p.width_m / p.resolution_m) * (p.height_m / p.resolution_m);
    if cells > 16e6 {
        return bad(format!("the world would have {cells:.0} cells; at most 16 million are allowed"));
    }
    let block = p.block_pitch_m - p.road_width_m - 2.0 * p.sidewalk_width_m;
    if block < 20.0 {
        return bad(format!("block_pitch_m leaves {block:.1} m inside a block; at least 20 m are needed"));
    }
    if p.width_m < p.block_pitch_m + p.road_width_m || p.height_m < p.block_pitch_m + p.road_width_m {
        return bad("the world must hold at least one block between two roads".into());
    }
    if p.vehicles_per_cluster_min == 0 || p.vehicles_per_cluster_min > p.vehicles_per_cluster_max {
        return bad("need 1 <= vehicles_per_cluster_min <= vehicles_per_cluster_max".into());
    }
    if !(0.0..=1.0).contains(&p.ramp_probability) || !(0.0..=1.0).contains(&p.parking_gravel_fraction) {
        return bad("ramp_probability and parking_gravel_fraction are fractions in [0, 1]".into());
    }
    let non_negative = [
        ("sidewalk_width_m", p.sidewalk_width_m),
        ("curb_height_m", p.curb_height_m),
        ("ramp_width_m", p.ramp_width_m),
        ("building_setback_m", p.building_setback_m),
        ("building_min_height_m", p.building_min_height_m),
        ("vehicle_height_m", p.vehicle_height_m),
        ("tree_trunk_height_m", p.tree_trunk_height_m),
        ("tree_canopy_radius_m", p.tree_canopy_radius_m),
        ("vegetation_height_m", p.vegetation_height_m),
        ("light_pole_height_m", p.light_pole_height_m),
        ("roadblock_height_m", p.roadblock_height_m),
        ("roadblock_thickness_m", p.roadblock_thickness_m),
    ];
    for (name, v) in non_negative {
        if !(v.is_finite() && v >= 0.0) {
            return bad(format!("{name} must be zero or more, got {v}"));
        }
    }
    if !(p.building_max_height_m.is_finite() && p.building_max_height_m >= p.building_min_height_m) {
        return bad("building_max_height_m must be at least building_min_height_m".into());
    }
    Ok(())
}

/// Road centre lines along one axis: the pitch is stretched (never shrunk) so the outermost
/// roads sit on the edges.
fn road_lines(extent_m: f64, pitch_m: f64, road_w: f64) -> Vec<f64> {
    let n = ((extent_m - road_w) / pitch_m).floor().max(1.0) as usize;
    let step = (extent_m - road_w) / n as f64;
    (0..=n).map(|i| road_w / 2.0 + i as f64 * step).collect()
}

/// Generates a city. Deterministic for a seed; the class table is the one shipped with spomp.
pub fn generate_city(p: &CityParams, seed: u64) -> Result<World, WorldError> {
    check(p)?;
    let table = ClassTable::default_table();
    let ids = Classes::from_table(&table)?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let width = (p.width_m / p.resolution_m).round() as u32;
    let height = (p.height_m / p.resolution_m).round() as u32;
    let spec = GridSpec::new(Point2::new(0.0, 0.0), p.resolution_m, width, height);
    let mut cv = Canvas {
        spec,
        surface: vec![Surface::Road; spec.len()],
        elevation: vec![0.0; spec.len()],
        tint: vec![None; spec.len()],
    };
    let (wm, hm) = spec.size_m();
    let xs = road_lines(wm, p.block_pitch_m, p.road_width_m);
    let ys = road_lines(hm, p.block_pitch_m, p.road_width_m);
    let half_road = p.road_width_m / 2.0;
    let curb = mm(p.curb_height_m);
    let sw = p.sidewalk_width_m;

    // Blocks: raised behind the curb, a sidewalk ring around grass.
    let mut blocks = Vec::new();
    for j in 0..ys.len() - 1 {
        for i in 0..xs.len() - 1 {
            let b = Rect {
                x0: xs[i] + half_road,
                y0: ys[j] + half_road,
                x1: xs[i + 1] - half_road,
                y1: ys[j + 1] - half_road,
            };
            cv.fill(b, Surface::Sidewalk, curb, None);
            cv.fill(b.inset(sw), Surface::Grass, curb, None);
            blocks.push(b);
        }
    }

    // Ramps at block corners, rising from the road to the curb across the sidewalk.
    for b in &blocks {
        for (cx, cy) in [(false, false), (true, false), (false, true), (true, true)] {
            if !rng.random_bool(p.ramp_probability) {
                continue;
            }
            // Along the southern/northern sidewalk, next to the corner square.
            let rx = if cx { b.x1 - sw - p.ramp_width_m } else { b.x0 + sw };
            let ry = if cy { b.y1 - sw } else { b.y0 };
            paint_ramp(
                &mut cv,
                Rect { x0: rx, y0: ry, x1: rx + p.ramp_width_m, y1: ry + sw },
                curb,
                if cy { RampRise::South } else { RampRise::North },
            );
            // Along the western/eastern sidewalk.
            let rx = if cx { b.x1 - sw } else { b.x0 };
            let ry = if cy { b.y1 - sw - p.ramp_width_m } else { b.y0 + sw };
            paint_ramp(
                &mut cv,
                Rect { x0: rx, y0: ry, x1: rx + sw, y1: ry + p.ramp_width_m },
                curb,
                if cx { RampRise::West } else { RampRise::East },
            );
        }
    }

    // Parking lots with vehicle clusters in some blocks, buildings in the others.
    let mut order: Vec<usize> = (0..blocks.len()).collect();
    order.shuffle(&mut rng);
    let lots = p.vehicle_clusters.min(blocks.len());
    let mut clusters = Vec::with_capacity(lots);
    for (k, &bi) in order.iter().enumerate() {
        let inner = blocks[bi].inset(sw);
        if k < lots {
            let (centre, rest) = parking_lot(&mut cv, &mut rng, p, blocks[bi], inner);
            clusters.push(centre);
            // The rest of the block gets a building most of the time.
            if rng.random_bool(0.7) {
                buildings(&mut cv, &mut rng, p, rest.inset(p.building_setback_m), curb);
            }
        } else {
            buildings(&mut cv, &mut rng, p, inner.inset(p.building_setback_m), curb);
        }
    }

    // Light poles along the outer edge of every sidewalk, clear of ramps and driveways.
    for b in &blocks {
        let d = 0.75;
        let n_x = (b.w() / p.light_pole_spacing_m).floor() as usize;
        let n_y = (b.h() / p.light_pole_spacing_m).floor() as usize;
        let mut spots = Vec::new();
        for k in 0..n_x {
            let x = b.x0 + (k as f64 + 0.5) * b.w() / n_x as f64;
            spots.push(Point2::new(x, b.y0 + d));
            spots.push(Point2::new(x, b.y1 - d));
        }
        for k in 0..n_y {
            let y = b.y0 + (k as f64 + 0.5) * b.h() / n_y as f64;
            spots.push(Point2::new(b.x0 + d, y));
            spots.push(Point2::new(b.x1 - d, y));
        }
        let h = mm(curb + p.light_pole_height_m);
        for s in spots {
            let cell = Rect { x0: s.x - 0.25, y0: s.y - 0.25, x1: s.x + 0.25, y1: s.y + 0.25 };
            if cv.all_of(cell, &[Surface::Sidewalk])
                && cv.none_of(cell.inset(-1.5), &[Surface::Ramp, Surface::Asphalt, Surface::Gravel])
            {
                cv.fill(cell, Surface::Pole, h, None);
            }
        }
    }

    // Trees on grass: a trunk with vegetation around it.
    for b in &blocks {
        let inner = b.inset(sw + 1.0);
        for _ in 0..p.trees_per_block {
            if inner.w() <= 0.0 || inner.h() <= 0.0 {
                break;
            }
            let c = Point2::new(rng.random_range(inner.x0..inner.x1), rng.random_range(inner.y0..inner.y1));
            let r = p.tree_canopy_radius_m;
            let area = Rect { x0: c.x - r, y0: c.y - r, x1: c.x + r, y1: c.y + r };
            if !cv.all_of(area.inset(-0.5), &[Surface::Grass]) {
                continue;
            }
            let (cols, rows) = cv.cells(area);
            for row in rows {
                for col in cols.clone() {
                    if cv.center_of(col, row).distance(c) <= r {
                        let i = row * width as usize + col;
                        cv.surface[i] = Surface::Vegetation;
                        cv.elevation[i] = mm(curb + p.vegetation_height_m);
                    }
                }
            }
            cv.fill(
                Rect { x0: c.x - 0.25, y0: c.y - 0.25, x1: c.x + 0.25, y1: c.y + 0.25 },
                Surface::Trunk,
                mm(curb + p.tree_trunk_height_m),
                None,
            );
        }
    }

    // Roadblocks across whole roads, halfway between two crossings, away from the start crossing.
    let mut segments: Vec<Rect> = Vec::new();
    for (j, &y) in ys.iter().enumerate() {
        for i in 0..xs.len() - 1 {
            if !(i == 0 && j == 0) {
                let x = 0.5 * (xs[i] + xs[i + 1]);
                let t = p.roadblock_thickness_m / 2.0;
                segments.push(Rect { x0: x - t, y0: y - half_road, x1: x + t, y1: y + half_road });
            }
        }
    }
    for (i, &x) in xs.iter().enumerate() {
        for j in 0..ys.len() - 1 {
            if !(i == 0 && j == 0) {
                let y = 0.5 * (ys[j] + ys[j + 1]);
                let t = p.roadblock_thickness_m / 2.0;
                segments.push(Rect { x0: x - half_road, y0: y - t, x1: x + half_road, y1: y + t });
            }
        }
    }
    segments.shuffle(&mut rng);
    let mut roadblocks = Vec::new();
    for r in segments.into_iter().take(p.roadblocks) {
        // The outermost roads run along the world's edge: clip to the world.
        let r = Rect { x0: r.x0.max(0.0), y0: r.y0.max(0.0), x1: r.x1.min(wm), y1: r.y1.min(hm) };
        cv.fill(r, Surface::Roadblock, mm(p.roadblock_height_m), None);
        roadblocks.push(r.center());
    }

    // Paint the layers.
    let mut map = AerialMap::unknown(spec);
    let noise = p.color_noise as i32;
    for i in 0..spec.len() {
        let (class, base) = match cv.surface[i] {
            Surface::Road => (ids.road, [72, 72, 76]),
            Surface::Sidewalk => (ids.sidewalk, [168, 168, 162]),
            Surface::Ramp => (ids.sidewalk, p.ramp_color),
            Surface::Grass => (ids.sidewalk, [86, 140, 60]),
            Surface::Building => (ids.building, [120, 110, 100]),
            Surface::Asphalt => (ids.road, [58, 58, 62]),
            Surface::Gravel => (ids.gravel, [160, 145, 120]),
            Surface::Vehicle => (ids.vehicle, [40, 60, 160]),
            Surface::Trunk => (ids.trunk, [90, 60, 30]),
            Surface::Vegetation => (ids.vegetation, [40, 100, 35]),
            Surface::Pole => (ids.pole, [200, 200, 40]),
            Surface::Roadblock => (ids.road, p.roadblock_color),
        };
        let base = cv.tint[i].unwrap_or(base);
        let rgb = if noise > 0 {
            base.map(|v| (v as i32 + rng.random_range(-noise..=noise)).clamp(0, 255) as u8)
        } else {
            base
        };
        map.class[i] = class;
        map.rgb[i] = rgb;
        map.elevation[i] = cv.elevation[i] as f32;
    }
    map.version = 1;
    let mut world = World::new(
        map,
        table,
        WorldMeta { vehicle_clusters: clusters, roadblocks, start_poses: Vec::new(), gps_origin: None },
    )?;
    world.meta.start_poses = start_poses(&world, p, xs[0], ys[0]);
    Ok(world)
}

/// Which way a ramp rises (towards the block).
#[derive(Clone, Copy)]
enum RampRise {
    North,
    South,
    East,
    West,
}

fn paint_ramp(cv: &mut Canvas, r: Rect, curb: f64, rise: RampRise) {
    let (cols, rows) = cv.cells(r);
    for row in rows {
        for col in cols.clone() {
            let c = cv.center_of(col, row);
            let frac = match rise {
                RampRise::North => (c.y - r.y0) / r.h(),
                RampRise::South => (r.y1 - c.y) / r.h(),
                RampRise::East => (c.x - r.x0) / r.w(),
                RampRise::West => (r.x1 - c.x) / r.w(),
            };
            let i = row * cv.spec.width as usize + col;
            if cv.surface[i] == Surface::Sidewalk {
                cv.surface[i] = Surface::Ramp;
                cv.elevation[i] = mm(curb * frac.clamp(0.0, 1.0));
            }
        }
    }
}

/// A road-level parking lot against one side of a block, reached through a driveway cut in the
/// sidewalk, with a cluster of vehicles parked in a row at the back. Returns the cluster centre
/// and the part of the block interior beyond the lot.
fn parking_lot(cv: &mut Canvas, rng: &mut ChaCha8Rng, p: &CityParams, block: Rect, inner: Rect) -> (Point2, Rect) {
    let surface = if rng.random_bool(p.parking_gravel_fraction) { Surface::Gravel } else { Surface::Asphalt };
    let side = rng.random_range(0..4);
    // The lot runs along the side it opens to: `span` is the room along that side.
    let (span, depth) = if side < 2 { (inner.w(), inner.h()) } else { (inner.h(), inner.w()) };
    let (vl, vw) = (p.vehicle_length_m, p.vehicle_width_m);
    let gap = 1.0;
    let fit = (((span - 2.0) + gap) / (vw + gap)).floor().max(1.0) as usize;
    let n = rng.random_range(p.vehicles_per_cluster_min..=p.vehicles_per_cluster_max).min(fit);
    let row_len = n as f64 * vw + (n as f64 - 1.0) * gap;
    // Lot: wide enough for the row plus 3 m each side, deep enough for a car and 10 m of aisle.
    let lot_w = (row_len + 6.0).min(span);
    let lot_d = (vl + 10.0).min(depth);
    let lo_x = inner.x0 + lot_w / 2.0;
    let lo_y = inner.y0 + lot_w / 2.0;
    let x_mid = rng.random_range(lo_x..=(inner.x1 - lot_w / 2.0).max(lo_x));
    let y_mid = rng.random_range(lo_y..=(inner.y1 - lot_w / 2.0).max(lo_y));
    let sw = p.sidewalk_width_m;
    let drive = 6.0_f64.min(lot_w);
    let (lot, driveway) = match side {
        0 => (
            Rect { x0: x_mid - lot_w / 2.0, y0: inner.y0, x1: x_mid + lot_w / 2.0, y1: inner.y0 + lot_d },
            Rect { x0: x_mid - drive / 2.0, y0: block.y0, x1: x_mid + drive / 2.0, y1: block.y0 + sw },
        ),
        1 => (
            Rect { x0: x_mid - lot_w / 2.0, y0: inner.y1 - lot_d, x1: x_mid + lot_w / 2.0, y1: inner.y1 },
            Rect { x0: x_mid - drive / 2.0, y0: block.y1 - sw, x1: x_mid + drive / 2.0, y1: block.y1 },
        ),
        2 => (
            Rect { x0: inner.x0, y0: y_mid - lot_w / 2.0, x1: inner.x0 + lot_d, y1: y_mid + lot_w / 2.0 },
            Rect { x0: block.x0, y0: y_mid - drive / 2.0, x1: block.x0 + sw, y1: y_mid + drive / 2.0 },
        ),
        _ => (
            Rect { x0: inner.x1 - lot_d, y0: y_mid - lot_w / 2.0, x1: inner.x1, y1: y_mid + lot_w / 2.0 },
            Rect { x0: block.x1 - sw, y0: y_mid - drive / 2.0, x1: block.x1, y1: y_mid + drive / 2.0 },
        ),
    };
    cv.fill(lot, surface, 0.0, None);
    cv.fill(driveway, surface, 0.0, None);
    let mut sum = Point2::new(0.0, 0.0);
    for k in 0..n {
        let along = -row_len / 2.0 + vw / 2.0 + k as f64 * (vw + gap);
        // Cars park nose-in at the back of the lot, across the side the lot opens to.
        let (cx, cy, hx, hy) = match side {
            0 => (x_mid + along, lot.y1 - 0.5 - vl / 2.0, vw / 2.0, vl / 2.0),
            1 => (x_mid + along, lot.y0 + 0.5 + vl / 2.0, vw / 2.0, vl / 2.0),
            2 => (lot.x1 - 0.5 - vl / 2.0, y_mid + along, vl / 2.0, vw / 2.0),
            _ => (lot.x0 + 0.5 + vl / 2.0, y_mid + along, vl / 2.0, vw / 2.0),
        };
        let tint = [rng.random_range(20..230), rng.random_range(20..230), rng.random_range(20..230)];
        cv.fill(
            Rect { x0: cx - hx, y0: cy - hy, x1: cx + hx, y1: cy + hy },
            Surface::Vehicle,
            mm(p.vehicle_height_m),
            Some(tint),
        );
        sum = sum + Point2::new(cx, cy);
    }
    let rest = match side {
        0 => Rect { y0: lot.y1, ..inner },
        1 => Rect { y1: lot.y0, ..inner },
        2 => Rect { x0: lot.x1, ..inner },
        _ => Rect { x1: lot.x0, ..inner },
    };
    (sum * (1.0 / n as f64), rest)
}

/// One or two buildings filling part of a block's interior.
fn buildings(cv: &mut Canvas, rng: &mut ChaCha8Rng, p: &CityParams, area: Rect, curb: f64) {
    if area.w() < 4.0 || area.h() < 4.0 {
        return;
    }
    let split = rng.random_bool(0.5);
    let parts = if split && area.w() >= area.h() {
        let m = area.x0 + area.w() * rng.random_range(0.4..0.6);
        vec![Rect { x1: m - 2.0, ..area }, Rect { x0: m + 2.0, ..area }]
    } else if split {
        let m = area.y0 + area.h() * rng.random_range(0.4..0.6);
        vec![Rect { y1: m - 2.0, ..area }, Rect { y0: m + 2.0, ..area }]
    } else {
        vec![area]
    };
    for part in parts {
        if part.w() < 2.0 || part.h() < 2.0 {
            continue;
        }
        // Leave some grass on random sides for trees.
        let b = Rect {
            x0: part.x0 + rng.random_range(0.0..part.w() * 0.2),
            y0: part.y0 + rng.random_range(0.0..part.h() * 0.2),
            x1: part.x1 - rng.random_range(0.0..part.w() * 0.2),
            y1: part.y1 - rng.random_range(0.0..part.h() * 0.2),
        };
        let h = mm(curb + rng.random_range(p.building_min_height_m..=p.building_max_height_m));
        let grey = rng.random_range(90..170);
        let tint = [grey, (grey as i32 - rng.random_range(0..25)) as u8, (grey as i32 - rng.random_range(0..40)) as u8];
        cv.fill(b, Surface::Building, h, Some(tint));
    }
}

/// Start poses on the road at the south-west crossing, heading east, two abreast.
fn start_poses(world: &World, p: &CityParams, x0: f64, y0: f64) -> Vec<Pose2> {
    let limits = UgvLimits::default();
    let mut poses = Vec::with_capacity(p.team_start_poses);
    let mut k = 0usize;
    while poses.len() < p.team_start_poses && k < 4 * p.team_start_poses + 8 {
        let lane = if k.is_multiple_of(2) { -2.5 } else { 2.5 };
        let pose = Pose2::new(x0 + (k / 2) as f64 * p.start_spacing_m, y0 + lane, 0.0);
        if limits.can_stand(world, pose.position()) {
            poses.push(pose);
        }
        k += 1;
    }
    poses
}
