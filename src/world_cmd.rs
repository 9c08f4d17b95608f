//! `spomp world generate | show | pano`: procedural cities, world folders and rendered panoramas.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use image::{ImageBuffer, Luma};
use serde_json::json;
use spomp_core::{DepthPanorama, Pose2, SemanticPanorama};
use spomp_sim::{PanoramaRenderer, SensorParams};
use spomp_world::{CityParams, World, generate_city, render_png};

/// Options of `spomp world generate`.
pub struct GenerateArgs {
    /// City seed.
    pub seed: u64,
    /// World extent (east–west, north–south), metres; `None` keeps the default.
    pub size_m: Option<(f64, f64)>,
    /// Vehicle clusters; `None` keeps the default.
    pub clusters: Option<usize>,
    /// Roadblocks; `None` keeps the default.
    pub roadblocks: Option<usize>,
    /// Output world folder.
    pub out: PathBuf,
    /// Print JSON.
    pub json: bool,
}

/// `spomp world generate`.
pub fn generate(a: &GenerateArgs) -> Result<ExitCode> {
    let mut params = CityParams::default();
    if let Some((w, h)) = a.size_m {
        params.width_m = w;
        params.height_m = h;
    }
    if let Some(k) = a.clusters {
        params.vehicle_clusters = k;
    }
    if let Some(r) = a.roadblocks {
        params.roadblocks = r;
    }
    let world = generate_city(&params, a.seed).context("generating the city")?;
    world.save(&a.out).with_context(|| format!("writing the world to {}", a.out.display()))?;
    let spec = world.spec();
    if a.json {
        let out = json!({
            "dir": a.out,
            "seed": a.seed,
            "width": spec.width,
            "height": spec.height,
            "resolution_m": spec.resolution_m,
            "vehicle_clusters": world.meta.vehicle_clusters,
            "roadblocks": world.meta.roadblocks,
            "start_poses": world.meta.start_poses,
        });
        out!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        let (w, h) = spec.size_m();
        out!(
            "wrote {} ({} × {} cells, {w} m × {h} m, seed {}): {} vehicle clusters, {} roadblocks, {} start poses",
            a.out.display(),
            spec.width,
            spec.height,
            a.seed,
            world.meta.vehicle_clusters.len(),
            world.meta.roadblocks.len(),
            world.meta.start_poses.len()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Loads a world folder, with the folder named in the error.
pub fn load_world(dir: &Path) -> Result<World> {
    if !dir.is_dir() {
        bail!("{}: not a world folder (no such directory)", dir.display());
    }
    World::load(dir).with_context(|| format!("loading the world in {}", dir.display()))
}

/// `spomp world show`.
pub fn show(dir: &Path, out: Option<&Path>, json: bool) -> Result<ExitCode> {
    let world = load_world(dir)?;
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| dir.join("render.png"));
    crate::output::write_png(&render_png(&world), &out)?;

    let spec = world.spec();
    let mut counts = [0usize; 256];
    for &c in &world.map().class {
        counts[c as usize] += 1;
    }
    let classes: Vec<_> = world
        .classes()
        .classes
        .iter()
        .filter(|c| counts[c.index as usize] > 0)
        .map(|c| {
            let cells = counts[c.index as usize];
            json!({ "name": c.name, "rank": c.rank, "cells": cells,
                    "fraction": cells as f64 / spec.len().max(1) as f64 })
        })
        .collect();
    let (w_m, h_m) = spec.size_m();
    if json {
        let v = json!({
            "dir": dir,
            "width": spec.width,
            "height": spec.height,
            "resolution_m": spec.resolution_m,
            "size_m": [w_m, h_m],
            "origin": spec.origin,
            "max_elevation_m": world.max_elevation_m(),
            "classes": classes,
            "vehicle_clusters": world.meta.vehicle_clusters,
            "roadblocks": world.meta.roadblocks,
            "start_poses": world.meta.start_poses,
            "render": out,
        });
        out!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(ExitCode::SUCCESS);
    }
    out!(
        "{}: {} × {} cells at {} m = {w_m} m × {h_m} m, origin ({}, {}), highest point {:.1} m",
        dir.display(),
        spec.width,
        spec.height,
        spec.resolution_m,
        spec.origin.x,
        spec.origin.y,
        world.max_elevation_m()
    );
    out!("classes present:");
    for c in &classes {
        out!(
            "  {:<16} rank {}  {:>9} cells  {:5.1} %",
            c["name"].as_str().unwrap_or("?"),
            c["rank"],
            c["cells"],
            c["fraction"].as_f64().unwrap_or(0.0) * 100.0
        );
    }
    out!("vehicle clusters: {}", world.meta.vehicle_clusters.len());
    for p in &world.meta.vehicle_clusters {
        out!("  ({:.1}, {:.1})", p.x, p.y);
    }
    out!("roadblocks: {}, start poses: {}", world.meta.roadblocks.len(), world.meta.start_poses.len());
    out!("wrote {}", out.display());
    Ok(ExitCode::SUCCESS)
}

/// Options of `spomp world pano`.
pub struct PanoArgs {
    /// World folder.
    pub dir: PathBuf,
    /// Sensor pose in the map frame.
    pub at: Pose2,
    /// Sensor model (size, field of view, height, range).
    pub sensor: SensorParams,
    /// Metres per count of the 16-bit PNG.
    pub range_scale_m: f64,
    /// Output PNG.
    pub out: PathBuf,
    /// Print JSON.
    pub json: bool,
}

/// `spomp world pano`: renders a depth panorama and stores it as a 16-bit PNG of range counts.
pub fn pano(a: &PanoArgs) -> Result<ExitCode> {
    if !(a.range_scale_m.is_finite() && a.range_scale_m > 0.0) {
        bail!("--range-scale must be a positive number of metres per count, got {}", a.range_scale_m);
    }
    let world = load_world(&a.dir)?;
    if world.class_at(a.at.position()).is_none() {
        let (w, h) = world.spec().size_m();
        bail!("--at ({}, {}) is off the map ({w} m × {h} m from its origin)", a.at.x, a.at.y);
    }
    let renderer = PanoramaRenderer::from_params(&a.sensor).context("sensor parameters")?;
    let g = renderer.geometry();
    let mut depth = DepthPanorama::empty(g);
    let mut semantic = SemanticPanorama { geometry: g, class: vec![0; g.len()] };
    renderer.render(&world, a.at, &mut depth, &mut semantic);
    save_depth_png(&depth, a.range_scale_m, &a.out)?;
    let returns = depth.range_m.iter().filter(|r| **r > 0.0).count();
    if a.json {
        let v = json!({
            "out": a.out, "rows": g.rows, "cols": g.cols, "v_fov_deg": a.sensor.v_fov_deg,
            "range_scale_m": a.range_scale_m, "pose": a.at, "returns": returns,
        });
        out!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        out!(
            "wrote {} ({} × {}, {}° vertical FOV, {} m per count, {returns} of {} pixels with a return)",
            a.out.display(),
            g.rows,
            g.cols,
            a.sensor.v_fov_deg,
            a.range_scale_m,
            g.len()
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// Stores a depth panorama as a 16-bit PNG of range counts (`range_scale_m` metres per count,
/// 0 = no return), the format `spomp terrain` reads.
pub fn save_depth_png(depth: &DepthPanorama, range_scale_m: f64, path: &Path) -> Result<()> {
    let g = depth.geometry;
    let counts = depth.to_counts(range_scale_m);
    let img: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_raw(g.cols as u32, g.rows as u32, counts)
        .context("panorama buffer does not match its geometry")?;
    crate::output::write_png(&img, path)
}
