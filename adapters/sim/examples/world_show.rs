//! Generates a city and writes it as a world directory plus a top-down picture (`render.png`)
//! and the depth panorama seen from the first start pose (`panorama.png`, near = bright).
//!
//! `cargo run -p spomp-sim --example world_show -- OUT_DIR [SEED]`

use spomp_core::{DepthPanorama, PanoramaGeometry, SemanticPanorama, UNKNOWN_CLASS};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = args.next().unwrap_or_else(|| "world_out".into());
    let seed: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(1);
    let world = spomp_world::generate_city(&spomp_world::CityParams::default(), seed)?;
    world.save(&out)?;
    spomp_world::render_png(&world).save(std::path::Path::new(&out).join("render.png"))?;
    let g = PanoramaGeometry::default_lidar();
    let renderer = spomp_sim::PanoramaRenderer::new(g, 0.4, 50.0)?;
    let mut depth = DepthPanorama::empty(g);
    let mut sem = SemanticPanorama { geometry: g, class: vec![UNKNOWN_CLASS; g.len()] };
    if let Some(&start) = world.meta.start_poses.first() {
        renderer.render(&world, start, &mut depth, &mut sem);
        let img = image::GrayImage::from_fn(g.cols as u32, g.rows as u32, |x, y| {
            let r = depth.at(y as usize, x as usize);
            image::Luma([if r > 0.0 { (255.0 - r * 5.0).clamp(30.0, 255.0) as u8 } else { 0 }])
        });
        img.save(std::path::Path::new(&out).join("panorama.png"))?;
    }
    println!(
        "{} x {} cells, {} vehicle clusters, {} roadblocks, {} start poses",
        world.spec().width,
        world.spec().height,
        world.meta.vehicle_clusters.len(),
        world.meta.roadblocks.len(),
        world.meta.start_poses.len()
    );
    Ok(())
}
