//! `spomp terrain`: runs the local planner's terrain analysis on a depth-panorama PNG, times the
//! fused analysis the robot runs (the total) and, for a breakdown, each stage of the staged run,
//! and writes the stage images.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use image::{DynamicImage, GrayImage, ImageBuffer, Luma, Rgb, RgbImage};
use serde_json::json;
use spomp_core::DepthPanorama;
use spomp_local_planner::{TerrainAnalyzer, TerrainOutput, TerrainParams, TerrainStage};

/// Options of `spomp terrain`.
pub struct TerrainArgs {
    /// Depth panorama: 16-bit grayscale PNG of range counts.
    pub pano: PathBuf,
    /// Metres per count.
    pub range_scale_m: f64,
    /// Vertical field of view of the panorama, degrees.
    pub v_fov_deg: f64,
    /// YAML file of `TerrainParams`.
    pub params: Option<PathBuf>,
    /// Start from the paper's simulation values instead of the defaults.
    pub simulation: bool,
    /// Timed runs (after one untimed warm-up run); timings are medians over them.
    pub repeat: usize,
    /// Folder for the stage images.
    pub out: Option<PathBuf>,
    /// Print JSON.
    pub json: bool,
}

/// Reads a 16-bit grayscale PNG of range counts into a depth panorama (the simulator's reader,
/// which the `terrain_input` fuzz target exercises).
pub fn read_depth_png(path: &Path, range_scale_m: f64, v_fov_rad: f64) -> Result<DepthPanorama> {
    Ok(spomp_world::read_depth_png(path, range_scale_m, v_fov_rad)?)
}

fn load_params(a: &TerrainArgs) -> Result<TerrainParams> {
    let Some(file) = &a.params else {
        return Ok(if a.simulation { TerrainParams::simulation() } else { TerrainParams::default() });
    };
    // A regular file of at most 4 MiB: a FIFO or a device given as --params is refused, not read.
    let text = spomp_behaviors::mission::limits::read_text(file, spomp_behaviors::mission::limits::MAX_SOURCE_BYTES)
        .map_err(|e| anyhow::anyhow!("--params: {e}"))?;
    let params: TerrainParams = serde_saphyr::from_str(&text)
        .with_context(|| format!("{}: not a valid terrain parameter file", file.display()))?;
    params.validate().with_context(|| format!("{}: bad terrain parameters", file.display()))?;
    Ok(params)
}

fn median(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    values.sort_by(f64::total_cmp);
    let n = values.len();
    if n % 2 == 1 { values[n / 2] } else { 0.5 * (values[n / 2 - 1] + values[n / 2]) }
}

/// `spomp terrain`.
pub fn terrain(a: &TerrainArgs) -> Result<ExitCode> {
    if !(a.range_scale_m.is_finite() && a.range_scale_m > 0.0) {
        bail!("--range-scale must be a positive number of metres per count, got {}", a.range_scale_m);
    }
    if !(a.v_fov_deg.is_finite() && a.v_fov_deg > 0.0 && a.v_fov_deg <= 180.0) {
        bail!("--v-fov-deg must be in (0, 180], got {}", a.v_fov_deg);
    }
    if a.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let params = load_params(a)?;
    let depth = read_depth_png(&a.pano, a.range_scale_m, a.v_fov_deg.to_radians())?;
    let g = depth.geometry;
    let mut analyzer = TerrainAnalyzer::new(g, params)
        .with_context(|| format!("{}: cannot analyse a {} × {} panorama", a.pano.display(), g.rows, g.cols))?;

    // One untimed run first: the analyzer's output buffers are touched for the first time there
    // (page faults), which the robot pays once, not per panorama.
    analyzer.analyze(&depth)?;
    // The wall time of every run (the skill takes no clock; the CLI times it): the fused analysis
    // (`analyze`, stages 1–6 as the robot runs them), back to back as the benchmark runs it, and
    // then, for the breakdown, the staged run (`analyze_observed`), stage by stage. (Alternating
    // the two measured the fused analysis 13–20 % slower than the benchmark on the same panorama,
    // back to back within 4 %.)
    let mut fused_ms = Vec::with_capacity(a.repeat);
    for _ in 0..a.repeat {
        let start = Instant::now();
        analyzer.analyze(&depth)?;
        fused_ms.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let mut stage_ms = vec![Vec::with_capacity(a.repeat); TerrainStage::ALL.len()];
    let mut staged_ms = Vec::with_capacity(a.repeat);
    for _ in 0..a.repeat {
        let start = Instant::now();
        let mut last = start;
        let mut stage_index = 0;
        analyzer.analyze_observed(&depth, |_stage| {
            let now = Instant::now();
            if let Some(times) = stage_ms.get_mut(stage_index) {
                times.push((now - last).as_secs_f64() * 1e3);
            }
            stage_index += 1;
            last = now;
        })?;
        staged_ms.push(start.elapsed().as_secs_f64() * 1e3);
    }
    let medians: Vec<(TerrainStage, f64)> =
        TerrainStage::ALL.iter().zip(stage_ms.iter_mut()).map(|(s, t)| (*s, median(t))).collect();
    let staged_median = median(&mut staged_ms);
    let fused_min = fused_ms.iter().copied().fold(f64::INFINITY, f64::min);
    let fused_median = median(&mut fused_ms);

    let out = analyzer.output();
    let traversable_pixels = out.traversable().iter().filter(|t| **t).count();
    if let Some(dir) = &a.out {
        write_stage_images(dir, out, a.range_scale_m, analyzer.params())?;
    }

    if a.json {
        let timings: serde_json::Map<String, serde_json::Value> =
            medians.iter().map(|(s, ms)| (s.name().to_string(), json!(ms))).collect();
        let reach: Vec<_> = out
            .reach_range_m()
            .iter()
            .zip(out.reach_obstacle())
            .map(|(r, o)| json!({ "range_m": r, "obstacle": o }))
            .collect();
        let v = json!({
            "rows": g.rows,
            "cols": g.cols,
            "total_ms": fused_median,
            "total_min_ms": fused_min,
            "staged_total_ms": staged_median,
            "timings_ms": timings,
            "reachability": reach,
            "traversable_pixels": traversable_pixels,
        });
        out!("{}", serde_json::to_string(&v)?);
        return Ok(ExitCode::SUCCESS);
    }

    out!("{}: {} × {} panorama, {}° vertical FOV", a.pano.display(), g.rows, g.cols, a.v_fov_deg);
    out!(
        "{:<20} {fused_median:>9.3} ms median, {fused_min:.3} ms min of {} runs (the robot's analysis: stages 1–6 fused row by row)",
        "total (fused)",
        a.repeat
    );
    out!("the stages run one after the other, for a breakdown (medians):");
    for (s, ms) in &medians {
        out!("{:<20} {ms:>9.3} ms", s.name());
    }
    out!("{:<20} {staged_median:>9.3} ms", "staged total");
    let reach = out.reach_range_m();
    let obstacle_cols = out.reach_obstacle().iter().filter(|o| **o).count();
    let finite: Vec<f32> = reach.iter().copied().filter(|r| r.is_finite()).collect();
    let (lo, hi) = finite.iter().fold((f32::INFINITY, 0.0f32), |(lo, hi), r| (lo.min(*r), hi.max(*r)));
    out!("reachability: {obstacle_cols} of {} columns end at an obstacle, range {lo:.2}–{hi:.2} m", reach.len());
    out!(
        "traversable pixels: {traversable_pixels} of {} ({:.1} %)",
        g.len(),
        100.0 * traversable_pixels as f64 / g.len().max(1) as f64
    );
    if let Some(dir) = &a.out {
        out!(
            "wrote {}/{{filled_depth,gradient,obstacles,distance,traversable,reachability,stages}}.png",
            dir.display()
        );
    }
    Ok(ExitCode::SUCCESS)
}

fn unit_to_u8(v: f32) -> u8 {
    if v.is_finite() { (v.clamp(0.0, 1.0) * 255.0).round() as u8 } else { 0 }
}

fn save_gray(dir: &Path, name: &str, cols: usize, rows: usize, pixels: Vec<u8>) -> Result<()> {
    let path = dir.join(name);
    let img = GrayImage::from_raw(cols as u32, rows as u32, pixels).context("stage buffer size")?;
    crate::output::write_png(&img, &path)
}

fn save_rgb(path: &Path, img: &RgbImage) -> Result<()> {
    crate::output::write_png(img, path)
}

/// Writes one image per stage: `filled_depth.png` (16-bit counts, same scale as the input),
/// `gradient.png` (|∇| / 2∇_thresh), `obstacles.png` (red obstacle, black no return),
/// `distance.png` (D / D_max), `traversable.png` and `reachability.png` (top-down S(φ)).
fn write_stage_images(dir: &Path, out: &TerrainOutput, range_scale_m: f64, params: &TerrainParams) -> Result<()> {
    crate::output::create_dir(dir)?;
    let g = out.geometry();
    let (rows, cols) = (g.rows, g.cols);

    let filled = DepthPanorama { geometry: g, range_m: out.ranges_m().to_vec() };
    let path = dir.join("filled_depth.png");
    let img: ImageBuffer<Luma<u16>, Vec<u16>> =
        ImageBuffer::from_raw(cols as u32, rows as u32, filled.to_counts(range_scale_m))
            .context("stage buffer size")?;
    crate::output::write_png(&img, &path)?;

    let grad_full_scale = (2.0 * params.slope_threshold) as f32;
    save_gray(
        dir,
        "gradient.png",
        cols,
        rows,
        out.gradient().iter().map(|v| unit_to_u8(v / grad_full_scale)).collect(),
    )?;

    let d_max = params.max_obstacle_distance_m as f32;
    save_gray(dir, "distance.png", cols, rows, out.distance_m().iter().map(|d| unit_to_u8(d / d_max)).collect())?;

    let ranges = out.ranges_m();
    let has_return = |i: usize| ranges.get(i).is_some_and(|r| r.is_finite() && *r > 0.0);
    let mut obstacles = RgbImage::new(cols as u32, rows as u32);
    let mut traversable = RgbImage::new(cols as u32, rows as u32);
    for (i, (o, t)) in out.obstacle().iter().zip(out.traversable()).enumerate() {
        let (x, y) = ((i % cols) as u32, (i / cols) as u32);
        let ret = has_return(i);
        obstacles.put_pixel(
            x,
            y,
            if *o {
                Rgb([220, 40, 40])
            } else if ret {
                Rgb([90, 90, 90])
            } else {
                Rgb([0, 0, 0])
            },
        );
        let colour = if *t {
            Rgb([60, 180, 75])
        } else if *o {
            Rgb([220, 40, 40])
        } else if ret {
            Rgb([230, 160, 40])
        } else {
            Rgb([0, 0, 0])
        };
        traversable.put_pixel(x, y, colour);
    }
    save_rgb(&dir.join("obstacles.png"), &obstacles)?;
    save_rgb(&dir.join("traversable.png"), &traversable)?;
    let reachability = reachability_image(out);
    save_rgb(&dir.join("reachability.png"), &reachability)?;

    let gray_rgb = |values: Vec<u8>| -> Result<RgbImage> {
        let gray = GrayImage::from_raw(cols as u32, rows as u32, values).context("stage buffer size")?;
        Ok(DynamicImage::ImageLuma8(gray).to_rgb8())
    };
    // Near returns bright, far ones dark, none black: legible at a glance, unlike raw counts.
    const DEPTH_FULL_SCALE_M: f32 = 30.0;
    let depth = gray_rgb(
        ranges
            .iter()
            .map(|&r| {
                let nearness = (1.0 - r / DEPTH_FULL_SCALE_M).clamp(0.0, 1.0);
                if r.is_finite() && r > 0.0 { 40 + (nearness * 215.0).round() as u8 } else { 0 }
            })
            .collect(),
    )?;
    let gradient = gray_rgb(out.gradient().iter().map(|v| unit_to_u8(v / grad_full_scale)).collect())?;
    let distance = gray_rgb(out.distance_m().iter().map(|d| unit_to_u8(d / d_max)).collect())?;
    let panels = [
        (format!("1 filled depth (bright = near, {DEPTH_FULL_SCALE_M:.0} m and beyond dark)"), &depth),
        (format!("3 gradient |∇| (white = {grad_full_scale:.2}, twice the slope threshold)"), &gradient),
        ("4 obstacles (red), returns (grey), no return (black)".to_string(), &obstacles),
        (format!("5 distance to obstacle D (white = D_max {d_max:.1} m)"), &distance),
        (
            format!("5 traversable: D ≥ {:.2} m (green), near obstacles (orange), obstacles (red)", params.inflation_m),
            &traversable,
        ),
    ];
    write_stage_sheet(&dir.join("stages.png"), &panels, &reachability)
}

/// One picture of the stages for documentation: the panorama-shaped stages stacked on the left,
/// each under its caption, the top-down reachability polygon on the right.
fn write_stage_sheet(path: &Path, panels: &[(String, &RgbImage)], reachability: &RgbImage) -> Result<()> {
    use plotters::prelude::*;
    const CAPTION_PX: u32 = 26;
    const GAP_PX: u32 = 16;
    let panel_w = panels.iter().map(|(_, img)| img.width()).max().unwrap_or(0);
    let left_h: u32 = panels.iter().map(|(_, img)| CAPTION_PX + img.height()).sum();
    let width = panel_w + GAP_PX + reachability.width();
    let height = left_h.max(CAPTION_PX + reachability.height());
    let mut sheet = RgbImage::from_pixel(width, height, Rgb([40, 40, 40]));
    let mut captions = Vec::new();
    let mut y = 0;
    for (caption, img) in panels {
        captions.push((caption.clone(), 0, y));
        image::imageops::replace(&mut sheet, *img, 0, i64::from(y + CAPTION_PX));
        y += CAPTION_PX + img.height();
    }
    let right_x = panel_w + GAP_PX;
    captions.push(("6 reachability S(φ), top-down, +x right (red: obstacle)".to_string(), right_x, 0));
    image::imageops::replace(&mut sheet, reachability, i64::from(right_x), i64::from(CAPTION_PX));

    crate::sim_plots::ensure_font()?;
    let (w, h) = sheet.dimensions();
    {
        let root = BitMapBackend::with_buffer(&mut sheet, (w, h)).into_drawing_area();
        let style = ("sans-serif", 16).into_font().color(&RGBColor(235, 235, 235));
        for (caption, x, y) in &captions {
            root.draw_text(caption, &style, (*x as i32 + 6, *y as i32 + 5))
                .map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))?;
        }
        root.present().map_err(|e| anyhow::anyhow!("drawing {}: {e}", path.display()))?;
    }
    save_rgb(path, &sheet)
}

/// Top-down picture of the reachability polygon, robot at the centre, +x to the right, +y up:
/// green inside S(φ), the boundary red where a column ends at an obstacle, yellow where it
/// ends in the unknown.
fn reachability_image(out: &TerrainOutput) -> RgbImage {
    const SIZE: u32 = 601;
    let g = out.geometry();
    let reach = out.reach_range_m();
    let farthest = reach.iter().copied().filter(|r| r.is_finite()).fold(1.0f32, f32::max) as f64;
    let m_per_px = 2.2 * farthest / SIZE as f64;
    let centre = (SIZE / 2) as f64;
    let mut img = RgbImage::from_pixel(SIZE, SIZE, Rgb([25, 25, 25]));
    if g.cols == 0 || reach.len() != g.cols {
        return img;
    }
    for (px, py, pixel) in img.enumerate_pixels_mut() {
        let x = (px as f64 - centre) * m_per_px;
        let y = (centre - py as f64) * m_per_px;
        let col = g.col_of_azimuth(y.atan2(x));
        if reach.get(col).is_some_and(|r| x.hypot(y) <= *r as f64) {
            *pixel = Rgb([60, 140, 70]);
        }
    }
    for (col, (r, obstacle)) in reach.iter().zip(out.reach_obstacle()).enumerate() {
        if !r.is_finite() {
            continue;
        }
        let az = g.azimuth_of_col(col);
        let px = centre + *r as f64 * az.cos() / m_per_px;
        let py = centre - *r as f64 * az.sin() / m_per_px;
        if px >= 0.0 && py >= 0.0 && px < SIZE as f64 && py < SIZE as f64 {
            let colour = if *obstacle { Rgb([230, 40, 40]) } else { Rgb([240, 220, 60]) };
            imageproc::drawing::draw_filled_circle_mut(&mut img, (px as i32, py as i32), 1, colour);
        }
    }
    imageproc::drawing::draw_filled_circle_mut(&mut img, (centre as i32, centre as i32), 3, Rgb([80, 140, 255]));
    img
}

#[cfg(test)]
mod tests {
    use super::median;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut []).is_nan());
    }
}
