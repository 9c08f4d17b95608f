//! Goal detection on an 800×600 map and layer compression (encode/decode).
#![allow(clippy::unwrap_used)]

#[path = "../tests/common/mod.rs"]
mod common;

use criterion::{Criterion, criterion_group, criterion_main};
use spomp_core::ClassTable;
use spomp_mapping::{CompressionParams, GoalDetectionParams, GoalDetector, PngLevel, decode_region, encode_layers};

fn bench(c: &mut Criterion) {
    let map = common::city(800, 600);
    let mut detector = GoalDetector::new(GoalDetectionParams::default(), &ClassTable::default_table()).unwrap();
    let found = detector.detect(&map, &[]).unwrap();
    eprintln!("800×600 city map: {} goals, {} too small", found.goals.len(), found.too_small);
    c.bench_function("detect goals 800x600", |b| b.iter(|| detector.detect(&map, &[]).unwrap()));

    // Cost of the image stages on the same map, to see where detection time goes.
    {
        use image::{GrayImage, Luma};
        use imageproc::distance_transform::{Norm, euclidean_squared_distance_transform};
        use imageproc::morphology::dilate;
        use imageproc::region_labelling::{Connectivity, connected_components};
        let mask =
            GrayImage::from_fn(800, 600, |x, y| Luma([if map.class[(y * 800 + x) as usize] == 4 { 255 } else { 0 }]));
        c.bench_function("stage: dilate L2 r=15", |b| b.iter(|| dilate(&mask, Norm::L2, 15)));
        c.bench_function("stage: euclidean EDT (imageproc)", |b| {
            b.iter(|| euclidean_squared_distance_transform(&mask))
        });
        // The transform detection uses: same values, reused buffers.
        let mut edt = spomp_raster::SquaredEdt::default();
        c.bench_function("stage: euclidean EDT (spomp-raster)", |b| b.iter(|| edt.of_mask(mask.as_raw(), 800, 600)));
        c.bench_function("stage: connected components", |b| {
            b.iter(|| connected_components(&mask, Connectivity::Eight, Luma([0u8])))
        });
    }

    for level in [PngLevel::Fast, PngLevel::Default, PngLevel::Best] {
        let params = CompressionParams { level };
        let blob = encode_layers(&map, &params).unwrap();
        let bytes = blob.to_bytes().len();
        eprintln!(
            "{level:?}: raw {} B -> {} B (class {} B, rgb {} B, elevation {} B): ratio {:.1}",
            blob.raw_bytes(),
            bytes,
            blob.class_png.len(),
            blob.rgb_png.len(),
            blob.elevation_png.len(),
            blob.raw_bytes() as f64 / bytes as f64
        );
        c.bench_function(&format!("encode 800x600 {level:?}"), |b| b.iter(|| encode_layers(&map, &params).unwrap()));
        c.bench_function(&format!("decode 800x600 {level:?}"), |b| b.iter(|| decode_region(&blob).unwrap()));
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
