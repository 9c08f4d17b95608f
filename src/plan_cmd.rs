//! `spomp plan`: builds the global planner's traversability graph on a world's full aerial map
//! and plans on it, one query or many random ones.
//!
//! A path the graph finds is not always one a robot can drive: the graph ranks classes (it
//! may cross vegetation, which is costly, not forbidden), and an edge across a curb it found no
//! ramp around stays straight, for the robot's scans to judge. So every path is also checked
//! against what the simulated UGV can drive on the world's ground truth: the cells it can reach
//! from the start ([`spomp_world::reachable_cells`]: its step and drop limits, slope and disc
//! footprint, down a curb but not up it). The path is drivable when every point of it lies
//! within [`DRIVE_CORRIDOR_M`] of a reachable cell (the local planner swerves that much around a
//! global path, off a curb edge, say), on no impassable class, and the ground along its line
//! rises by no more than a climb step and falls by no more than a drop step from one point to
//! the next (a path straight up a curb). The report gives the
//! share of queries whose path is drivable beside the graph's success rate, and what stopped
//! the others (the class there and why).

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_filled_circle_mut, draw_line_segment_mut};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;
use spomp_core::{GridSpec, Point2};
use spomp_global_planner::{EdgeState, GlobalPath, GlobalPlanner, GlobalPlannerParams};
use spomp_sim::UgvParams;
use spomp_world::{UgvLimits, World, render_png};

use crate::world_cmd::load_world;

/// How far a drivable path may stray from the cells the UGV can reach, metres: about the
/// robot's diameter, what its local planner deviates from a global path.
pub const DRIVE_CORRIDOR_M: f64 = 1.0;

/// Where a path stopped the simulated UGV.
#[derive(Clone, Debug, PartialEq)]
pub struct Blocked {
    /// The first point of the path it cannot get to, map frame.
    pub at: Point2,
    /// Class of the cell there.
    pub class: String,
    /// Why, for people.
    pub why: String,
}

/// Checks `path` against what the UGV with `limits` can drive on the world's ground truth from
/// the path's first point: `None` when it can follow it to the end, else where and why not.
pub fn drive(world: &World, limits: &UgvLimits, path: &[Point2]) -> Option<Blocked> {
    let classes = world.classes();
    let spec = *world.spec();
    let name_at = |p: Point2| {
        world.class_at(p).and_then(|c| classes.get(c)).map_or_else(|| "off the map".to_string(), |c| c.name.clone())
    };
    let first = *path.first()?;
    let reach = spomp_world::reachable_cells(world, limits, first);
    if !reach.data.iter().any(|&r| r) {
        return Some(Blocked { at: first, class: name_at(first), why: "the UGV cannot stand at the start".into() });
    }
    let near = distance_to(&spec, &reach.data);
    let step = spec.resolution_m / 2.0;
    // The ground under the path's line, point after point: a rise the UGV cannot climb stops it
    // whatever ground it could reach around there (the sidewalk beyond a curb is reachable up a
    // ramp elsewhere, so the corridor alone passes a path straight up the curb).
    let mut ground: Option<f32> = world.elevation_at(first);
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        let n = ((a.distance(b) / step).ceil() as usize).max(1);
        for k in 0..=n {
            let p = a + (b - a) * (k as f64 / n as f64);
            let Some(cell) = spec.cell_at(p) else {
                return Some(Blocked { at: p, class: name_at(p), why: "off the map".into() });
            };
            let i = spec.index(cell);
            if classes.rank(world.map().class[i]) >= spomp_core::classes::IMPASSABLE_RANK {
                return Some(Blocked { at: p, class: name_at(p), why: "an impassable class".into() });
            }
            let here = world.elevation_at(p);
            if let (Some(before), Some(now)) = (ground, here) {
                let rise = f64::from(now - before);
                if rise > limits.max_step_m + 1e-4 || -rise > limits.max_drop_m + 1e-4 {
                    let (what, limit) =
                        if rise > 0.0 { ("up", limits.max_step_m) } else { ("down", limits.max_drop_m) };
                    return Some(Blocked {
                        at: p,
                        class: name_at(p),
                        why: format!(
                            "a step of {:.2} m {what} on the path's line, more than the UGV's {limit:.2} m (a curb \
                             the path crosses where it has no ramp)",
                            rise.abs()
                        ),
                    });
                }
            }
            if here.is_some() {
                ground = here;
            }
            if f64::from(near[i]) > DRIVE_CORRIDOR_M {
                return Some(Blocked {
                    at: p,
                    class: name_at(p),
                    why: format!(
                        "no ground the UGV can reach from the start within {DRIVE_CORRIDOR_M} m (a step, curb or \
                         slope it cannot climb, or too narrow for its footprint)"
                    ),
                });
            }
        }
    }
    None
}

/// Distance of every cell to the nearest cell marked in `mask`, metres (chamfer, 1 and √2
/// steps).
fn distance_to(spec: &GridSpec, mask: &[bool]) -> Vec<f32> {
    let (w, h) = (spec.width as usize, spec.height as usize);
    let res = spec.resolution_m as f32;
    let diag = res * std::f32::consts::SQRT_2;
    let mut d: Vec<f32> = mask.iter().map(|&m| if m { 0.0 } else { f32::INFINITY }).collect();
    /// A neighbour already visited in a pass: column and row offsets, step length.
    type Step = (i64, i64, f32);
    let passes: [(bool, [Step; 4]); 2] = [
        (false, [(-1, 0, res), (0, -1, res), (-1, -1, diag), (1, -1, diag)]),
        (true, [(1, 0, res), (0, 1, res), (1, 1, diag), (-1, 1, diag)]),
    ];
    for (backward, steps) in passes {
        for k in 0..w * h {
            let i = if backward { w * h - 1 - k } else { k };
            let (c, r) = ((i % w) as i64, (i / w) as i64);
            for (dc, dr, cost) in steps {
                let (nc, nr) = (c + dc, r + dr);
                if nc >= 0 && nr >= 0 && (nc as usize) < w && (nr as usize) < h {
                    let v = d[nr as usize * w + nc as usize] + cost;
                    if v < d[i] {
                        d[i] = v;
                    }
                }
            }
        }
    }
    d
}

/// What to plan.
pub enum Queries {
    /// One query.
    Single {
        /// Start, map frame.
        from: Point2,
        /// Goal, map frame.
        to: Point2,
    },
    /// Random pairs of cells on the easiest classes.
    RandomPairs {
        /// Number of pairs.
        count: usize,
        /// Seed of the pair draw.
        seed: u64,
        /// Hardest class rank a start or goal cell may have.
        max_rank: u8,
    },
}

/// Options of `spomp plan`.
pub struct PlanArgs {
    /// World folder.
    pub dir: PathBuf,
    /// The queries.
    pub queries: Queries,
    /// Learned cost (`true`) or the class-rank ablation (`false`); `None` keeps the params'.
    pub learning: Option<bool>,
    /// YAML file of `GlobalPlannerParams`.
    pub params: Option<PathBuf>,
    /// Folder for the picture of the graph and path.
    pub out: Option<PathBuf>,
    /// Print JSON.
    pub json: bool,
}

fn load_params(file: Option<&Path>) -> Result<GlobalPlannerParams> {
    let Some(file) = file else { return Ok(GlobalPlannerParams::default()) };
    // A regular file of at most 4 MiB: a FIFO or a device given as --params is refused, not read.
    let text = spomp_behaviors::mission::limits::read_text(file, spomp_behaviors::mission::limits::MAX_SOURCE_BYTES)
        .map_err(|e| anyhow::anyhow!("--params: {e}"))?;
    serde_saphyr::from_str(&text)
        .with_context(|| format!("{}: not a valid global planner parameter file", file.display()))
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// `spomp plan`.
pub fn plan(a: &PlanArgs) -> Result<ExitCode> {
    let mut params = load_params(a.params.as_deref())?;
    if let Some(on) = a.learning {
        params.learning.enabled = on;
    }
    let world = load_world(&a.dir)?;

    let start = Instant::now();
    let mut planner = GlobalPlanner::new(params, world.classes().clone()).context("global planner parameters")?;
    // The robot plans on the world as seen from above (its aerial view, where that differs).
    planner.update_map(world.aerial_map()).context("building the traversability graph")?;
    let build_ms = ms_since(start);
    let stats = planner.graph_stats();

    let (pairs, single) = match a.queries {
        Queries::Single { from, to } => (vec![(from, to)], true),
        Queries::RandomPairs { count, seed, max_rank } => (random_pairs(&world, count, seed, max_rank)?, false),
    };
    let mut query_ms = Vec::with_capacity(pairs.len());
    let mut paths: Vec<GlobalPath> = Vec::new();
    let mut failures = Vec::new();
    let limits = UgvParams::default().limits;
    let mut drivable = 0usize;
    let mut blocked: Vec<(Point2, Point2, Blocked)> = Vec::new();
    for (from, to) in &pairs {
        let t = Instant::now();
        let result = planner.plan(*from, *to);
        query_ms.push(ms_since(t));
        match result {
            Ok(p) => {
                // The robot starts at `from` and must end at `to`, wherever the graph's path
                // begins and ends.
                let mut route = vec![*from];
                route.extend(p.waypoints.iter().copied());
                route.push(*to);
                route.dedup_by(|a, b| a.distance(*b) < 1e-9);
                match drive(&world, &limits, &route) {
                    None => drivable += 1,
                    Some(b) => blocked.push((*from, *to, b)),
                }
                paths.push(p);
            }
            Err(e) => failures.push(format!("({:.1}, {:.1}) → ({:.1}, {:.1}): {e}", from.x, from.y, to.x, to.y)),
        }
    }
    let success_rate = if pairs.is_empty() { 0.0 } else { paths.len() as f64 / pairs.len() as f64 };
    let drivable_rate = if pairs.is_empty() { 0.0 } else { drivable as f64 / pairs.len() as f64 };
    let mut blocked_by: std::collections::BTreeMap<String, usize> = std::collections::BTreeMap::new();
    for (_, _, b) in &blocked {
        *blocked_by.entry(b.class.clone()).or_insert(0) += 1;
    }
    let query_max = query_ms.iter().copied().fold(0.0, f64::max);
    query_ms.sort_by(f64::total_cmp);
    let query_median = query_ms.get(query_ms.len() / 2).copied().unwrap_or(f64::NAN);
    let single_path = if single { paths.first() } else { None };

    if let Some(dir) = &a.out {
        crate::output::create_dir(dir)?;
        let file = dir.join("plan.png");
        crate::output::write_png(&plan_image(&world, &planner, &paths), &file)?;
        if !a.json {
            out!("wrote {}", file.display());
        }
    }

    if a.json {
        let v = json!({
            "nodes": stats.nodes,
            "edges": stats.edges,
            "build_ms": build_ms,
            "query_ms_median": query_median,
            "query_ms_max": query_max,
            "success_rate": success_rate,
            "ugv_drivable_rate": drivable_rate,
            "ugv_blocked_by_class": blocked_by,
            "ugv_blocked": blocked.iter().map(|(f, t, b)| json!({
                "from": [f.x, f.y], "to": [t.x, t.y], "at": [b.at.x, b.at.y], "class": b.class, "why": b.why,
            })).collect::<Vec<_>>(),
            "path_length_m": single_path.map(|p| p.length_m),
            "path_cost": single_path.map(|p| p.cost),
            "path_waypoints": single_path.map(|p| p.waypoints.iter().map(|w| [w.x, w.y]).collect::<Vec<_>>()),
        });
        out!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        out!(
            "{}: graph of {} nodes, {} edges ({} cells covered), built in {build_ms:.1} ms (learning {})",
            a.dir.display(),
            stats.nodes,
            stats.edges,
            stats.covered_cells,
            if planner.params().learning.enabled { "on" } else { "off" }
        );
        if let Some(p) = single_path {
            out!(
                "path: {:.1} m, cost {:.3}, {} waypoints, query {query_median:.3} ms",
                p.length_m,
                p.cost,
                p.waypoints.len()
            );
            match blocked.first() {
                None => out!("the simulated UGV can drive it"),
                Some((_, _, b)) => out!(
                    "the simulated UGV cannot drive it: stopped at ({:.1}, {:.1}) on `{}` ({})",
                    b.at.x,
                    b.at.y,
                    b.class,
                    b.why
                ),
            }
        } else if !single {
            out!(
                "{} random pairs: graph success {:.1} %, drivable by the simulated UGV {:.1} %, query median \
                 {query_median:.3} ms, max {query_max:.3} ms",
                pairs.len(),
                success_rate * 100.0,
                drivable_rate * 100.0
            );
            if !blocked_by.is_empty() {
                let by: Vec<String> = blocked_by.iter().map(|(c, n)| format!("{n} on `{c}`")).collect();
                out!("paths the UGV cannot drive: {} ({})", blocked.len(), by.join(", "));
            }
        }
    }
    for f in &failures {
        errln!("no path: {f}");
    }
    // A single query that finds no path is a failure; random pairs report a rate.
    Ok(if single && single_path.is_none() { ExitCode::from(1) } else { ExitCode::SUCCESS })
}

/// `count` seeded pairs of distinct cell centres whose class rank is at most `max_rank`.
fn random_pairs(world: &World, count: usize, seed: u64, max_rank: u8) -> Result<Vec<(Point2, Point2)>> {
    let ranks = world.classes().rank_lut();
    let ignored: Vec<bool> = (0..=255u8).map(|c| world.classes().is_ignored(c)).collect();
    let spec = *world.spec();
    let cells: Vec<usize> = world
        .map()
        .class
        .iter()
        .enumerate()
        .filter(|(_, c)| ranks[**c as usize] <= max_rank && !ignored[**c as usize] && **c != spomp_core::UNKNOWN_CLASS)
        .map(|(i, _)| i)
        .collect();
    if cells.len() < 2 {
        bail!("{} cells of rank ≤ {max_rank}: too few to draw pairs from", cells.len());
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let centre = |i: usize| spec.center(spec.cell_of_index(i));
    let mut pairs = Vec::with_capacity(count);
    while pairs.len() < count {
        let a = cells[rng.random_range(0..cells.len())];
        let b = cells[rng.random_range(0..cells.len())];
        if a != b {
            pairs.push((centre(a), centre(b)));
        }
    }
    Ok(pairs)
}

/// Image pixel of a map point (north up, one pixel per cell).
fn to_pixel(spec: &GridSpec, p: Point2) -> (f32, f32) {
    let x = (p.x - spec.origin.x) / spec.resolution_m;
    let y = spec.height as f64 - (p.y - spec.origin.y) / spec.resolution_m;
    (x as f32, y as f32)
}

/// The world's render with the graph's edges (white, green trav, red not_trav), its nodes and
/// the paths (magenta, start green dot, goal red dot).
fn plan_image(world: &World, planner: &GlobalPlanner, paths: &[GlobalPath]) -> RgbImage {
    let spec = world.spec();
    let mut img = render_png(world);
    for e in planner.edges() {
        let colour = match e.state {
            EdgeState::Unknown => Rgb([235, 235, 235]),
            EdgeState::Trav => Rgb([60, 200, 80]),
            EdgeState::NotTrav => Rgb([230, 40, 40]),
        };
        let points: Vec<Point2> = std::iter::once(e.from).chain(e.via.iter().copied()).chain([e.to]).collect();
        for w in points.windows(2) {
            draw_line_segment_mut(&mut img, to_pixel(spec, w[0]), to_pixel(spec, w[1]), colour);
        }
    }
    for (_, p, _) in planner.nodes() {
        let (x, y) = to_pixel(spec, p);
        draw_filled_circle_mut(&mut img, (x as i32, y as i32), 1, Rgb([255, 255, 255]));
    }
    for path in paths {
        for w in path.waypoints.windows(2) {
            let (a, b) = (to_pixel(spec, w[0]), to_pixel(spec, w[1]));
            // Three parallel lines for a thicker stroke.
            for d in [-1.0f32, 0.0, 1.0] {
                draw_line_segment_mut(&mut img, (a.0 + d, a.1), (b.0 + d, b.1), Rgb([230, 0, 230]));
                draw_line_segment_mut(&mut img, (a.0, a.1 + d), (b.0, b.1 + d), Rgb([230, 0, 230]));
            }
        }
        if let (Some(s), Some(g)) = (path.waypoints.first(), path.waypoints.last()) {
            let (sx, sy) = to_pixel(spec, *s);
            let (gx, gy) = to_pixel(spec, *g);
            draw_filled_circle_mut(&mut img, (sx as i32, sy as i32), 4, Rgb([0, 200, 0]));
            draw_filled_circle_mut(&mut img, (gx as i32, gy as i32), 4, Rgb([220, 0, 0]));
        }
    }
    img
}
