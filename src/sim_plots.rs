//! PNG plots of a simulated run: the map with trajectories and goals, and goal-visit times.

use std::path::Path;

use anyhow::Result;
use image::{Rgb, RgbImage};
use imageproc::drawing::{draw_filled_circle_mut, draw_hollow_circle_mut, draw_line_segment_mut};
use plotters::prelude::*;
use spomp_core::{Point2, RobotKind};
use spomp_sim::run::{RunResult, RunSummary};

/// Colours of the robots' tracks, in team order.
const TRACK_COLOURS: [[u8; 3]; 6] =
    [[230, 25, 75], [60, 180, 75], [0, 130, 200], [245, 130, 48], [145, 30, 180], [70, 240, 240]];

/// The world (shaded colour layer) with each robot's track, the goals (filled: visited; ring:
/// not visited) and the ground-truth vehicle clusters (small crosses).
pub fn map_plot(result: &RunResult, path: &Path) -> Result<()> {
    let world = &result.world;
    let spec = *world.spec();
    let mut img = spomp_world::render_png(world);
    // Dim the background so the overlays read well.
    for p in img.pixels_mut() {
        p.0 = p.0.map(|v| (v as f32 * 0.6) as u8);
    }
    let h = spec.height as f32;
    let to_px = |p: Point2| -> (f32, f32) {
        (
            ((p.x - spec.origin.x) / spec.resolution_m) as f32,
            h - 1.0 - ((p.y - spec.origin.y) / spec.resolution_m) as f32,
        )
    };
    for (k, (_, kind, track)) in result.trajectories.iter().enumerate() {
        let c = TRACK_COLOURS[k % TRACK_COLOURS.len()];
        let colour = if *kind == RobotKind::Uav { Rgb([255, 255, 255]) } else { Rgb(c) };
        for w in track.windows(2) {
            draw_line_segment_mut(&mut img, to_px(w[0]), to_px(w[1]), colour);
        }
    }
    let radius = (2.0 / spec.resolution_m).round() as i32;
    for g in &result.summary.goals {
        let (x, y) = to_px(Point2::new(g.position[0], g.position[1]));
        let (x, y) = (x as i32, y as i32);
        if g.visited_s.is_some() {
            draw_filled_circle_mut(&mut img, (x, y), radius, Rgb([40, 255, 40]));
        } else {
            draw_hollow_circle_mut(&mut img, (x, y), radius, Rgb([255, 40, 40]));
        }
    }
    for c in &world.meta.vehicle_clusters {
        let (x, y) = to_px(*c);
        draw_line_segment_mut(&mut img, (x - 3.0, y - 3.0), (x + 3.0, y + 3.0), Rgb([255, 255, 0]));
        draw_line_segment_mut(&mut img, (x - 3.0, y + 3.0), (x + 3.0, y - 3.0), Rgb([255, 255, 0]));
    }
    save(&img, path)
}

fn save(img: &RgbImage, path: &Path) -> Result<()> {
    crate::output::write_png(img, path)
}

/// The font plots are labelled with (DejaVu Sans Mono, shipped in `assets/fonts` with its
/// licence): a fresh machine may have no system fonts at all.
static PLOT_FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSansMono.ttf");

/// Registers the bundled font as plotters' "sans-serif" (once).
pub fn ensure_font() -> Result<()> {
    static REGISTERED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok =
        *REGISTERED.get_or_init(|| plotters::style::register_font("sans-serif", FontStyle::Normal, PLOT_FONT).is_ok());
    if ok { Ok(()) } else { anyhow::bail!("the bundled plot font could not be loaded") }
}

/// Goals visited over time (a step curve), with the mission's time limit as the x range.
pub fn goal_times_plot(summary: &RunSummary, path: &Path) -> Result<()> {
    ensure_font()?;
    let mut times: Vec<f64> = summary.goals.iter().filter_map(|g| g.visited_s).collect();
    times.sort_by(f64::total_cmp);
    let total = summary.goals.len().max(1) as f64;
    let x_max = summary.end_s.max(1.0);
    crate::output::plot_png(path, (800, 400), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .margin(15)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..x_max, 0.0..total)?;
        chart.configure_mesh().x_desc("time (s)").y_desc("goals visited").draw()?;
        let mut points = vec![(0.0, 0.0)];
        for (k, t) in times.iter().enumerate() {
            points.push((*t, k as f64));
            points.push((*t, (k + 1) as f64));
        }
        points.push((x_max, times.len() as f64));
        chart.draw_series(LineSeries::new(points, BLUE.stroke_width(2)))?;
        chart
            .draw_series(times.iter().enumerate().map(|(k, t)| Circle::new((*t, (k + 1) as f64), 3, BLUE.filled())))?;
        Ok(())
    })
}

/// Each UGV's localization error over time (one line per UGV, in team colours), with the
/// acceptance bars of the cross-view localizer as horizontal lines at 2 m (median) and 5 m
/// (max). The y range covers the largest error (at least 6 m).
pub fn localization_error_plot(result: &RunResult, path: &Path) -> Result<()> {
    ensure_font()?;
    let series = &result.localization_errors;
    let x_max = result.summary.end_s.max(1.0);
    let worst =
        series.iter().flat_map(|(_, s)| s.iter().map(|&(_, e)| e)).filter(|e| e.is_finite()).fold(0.0, f64::max);
    let y_max = (worst * 1.05).max(6.0);
    crate::output::plot_png(path, (800, 400), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .margin(15)
            .x_label_area_size(35)
            .y_label_area_size(45)
            .build_cartesian_2d(0.0..x_max, 0.0..y_max)?;
        chart.configure_mesh().x_desc("time (s)").y_desc("position error (m)").draw()?;
        for (bar, label, colour) in [(2.0, "2 m (median bar)", RGBColor(230, 140, 0)), (5.0, "5 m (max bar)", RED)] {
            let style = colour.stroke_width(2);
            chart
                .draw_series(DashedLineSeries::new([(0.0, bar), (x_max, bar)], 8, 5, style))?
                .label(label)
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], style));
        }
        for (k, (id, points)) in series.iter().enumerate() {
            let [r, g, b] = TRACK_COLOURS[k % TRACK_COLOURS.len()];
            let colour = RGBColor(r, g, b);
            let points = points.iter().copied().filter(|(t, e)| t.is_finite() && e.is_finite());
            chart
                .draw_series(LineSeries::new(points, colour.stroke_width(2)))?
                .label(id.to_string())
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 15, y)], colour.stroke_width(2)));
        }
        chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
        Ok(())
    })
}
