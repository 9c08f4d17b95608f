//! Renders N panoramas from a street of the default city (for profiling with `perf stat`).
//!
//! `cargo run --profile profiling -p spomp-sim --example render_loop -- 500`

use spomp_core::{DepthPanorama, PanoramaGeometry, Pose2, SemanticPanorama, UNKNOWN_CLASS};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::args().nth(1).map(|s| s.parse()).transpose()?.unwrap_or(200);
    let world = spomp_world::generate_city(&spomp_world::CityParams::default(), 1)?;
    let g = PanoramaGeometry::default_lidar();
    let renderer = spomp_sim::PanoramaRenderer::new(g, 0.4, 50.0)?;
    let mut depth = DepthPanorama::empty(g);
    let mut sem = SemanticPanorama { geometry: g, class: vec![UNKNOWN_CLASS; g.len()] };
    let mid = Pose2::new(world.spec().size_m().0 / 2.0, 5.0, 0.3);
    let start = std::time::Instant::now();
    let mut checksum = 0.0f64;
    for k in 0..n {
        let pose = Pose2 { x: mid.x + (k % 10) as f64 * 0.1, ..mid };
        renderer.render(&world, pose, &mut depth, &mut sem);
        checksum += depth.range_m[k % depth.range_m.len()] as f64;
    }
    let elapsed = start.elapsed();
    println!("{n} renders, {:.3} ms each (wall), checksum {checksum:.3}", elapsed.as_secs_f64() * 1e3 / n as f64);
    Ok(())
}
