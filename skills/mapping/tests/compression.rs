//! PNG compression of map layers: exact round trips, corrupt blobs rejected.
#![allow(clippy::unwrap_used)]

mod common;

use common::*;
use proptest::prelude::*;
use spomp_core::{AerialMap, MapTile, UNKNOWN_CLASS};
use spomp_mapping::{
    CompressedMap, CompressionParams, Orthomap, decode_map, decode_region, encode_layers, encode_region,
};

fn same(a: &AerialMap, b: &AerialMap) -> bool {
    a.spec == b.spec
        && a.class == b.class
        && a.rgb == b.rgb
        && a.version == b.version
        && a.elevation.iter().zip(&b.elevation).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn round_trip_is_lossless_including_unknown_and_nan() {
    let mut m = city(160, 120);
    fill(&mut m, 0.0, 0.0, 20.0, 10.0, UNKNOWN_CLASS);
    for e in m.elevation.iter_mut().step_by(7) {
        *e = f32::NAN;
    }
    m.elevation[3] = -1234.567;
    m.version = 42;
    let blob = encode_layers(&m, &CompressionParams::default()).unwrap();
    let bytes = blob.to_bytes();
    let back = decode_map(&CompressedMap::from_bytes(&bytes).unwrap()).unwrap();
    assert!(same(&m, &back));
}

#[test]
fn a_city_map_compresses_several_fold() {
    let m = city(400, 300);
    let blob = encode_layers(&m, &CompressionParams::default()).unwrap();
    let ratio = blob.raw_bytes() as f64 / blob.to_bytes().len() as f64;
    assert!(ratio > 4.0, "ratio {ratio:.1}");
}

#[test]
fn regions_round_trip_into_another_orthomap() {
    let m = city(120, 100);
    let mut src = Orthomap::from_map(m.clone()).unwrap();
    let mut dst = Orthomap::new(m.spec);
    let blob = encode_region(src.map(), 10, 20, 50, 30, &CompressionParams::default()).unwrap();
    let changed = dst.apply_compressed(&blob).unwrap();
    assert_eq!(changed, 50 * 30);
    assert_eq!(dst.version(), 1);
    for r in 0..100u32 {
        for c in 0..120u32 {
            let cell = spomp_core::Cell::new(c, r);
            let inside = (10..60).contains(&c) && (20..50).contains(&r);
            assert_eq!(dst.map().is_known(cell), inside);
            if inside {
                assert_eq!(dst.map().class_at(cell), m.class_at(cell));
            }
        }
    }
    assert!(encode_region(src.map(), 100, 0, 30, 10, &CompressionParams::default()).is_err());
    // Incremental transmission: only the changed box is encoded.
    assert!(src.encode_changes(&CompressionParams::default()).unwrap().is_none());
    let tile = MapTile {
        col0: 5,
        row0: 6,
        width: 2,
        height: 3,
        class: vec![ROAD; 6],
        rgb: vec![[1, 2, 3]; 6],
        elevation: vec![9.0; 6],
    };
    assert_eq!(src.apply_tile(&tile).unwrap(), 6);
    let delta = src.encode_changes(&CompressionParams::default()).unwrap().unwrap();
    assert_eq!((delta.col0, delta.row0, delta.width, delta.height), (5, 6, 2, 3));
    let t = decode_region(&delta).unwrap();
    assert_eq!(t, tile);
}

#[test]
fn a_shared_map_is_copied_only_when_a_tile_changes_it() {
    let shared = std::sync::Arc::new(city(60, 40));
    let mut a = Orthomap::from_shared(shared.clone()).unwrap();
    let b = Orthomap::from_shared(shared.clone()).unwrap();
    // The camera passing over what the map already holds.
    let spec = shared.spec;
    let cells: Vec<usize> = (0..10).map(|c| spec.index(spomp_core::Cell::new(c, 3))).collect();
    let same_tile = MapTile {
        col0: 0,
        row0: 3,
        width: 10,
        height: 1,
        class: cells.iter().map(|&i| shared.class[i]).collect(),
        rgb: cells.iter().map(|&i| shared.rgb[i]).collect(),
        elevation: cells.iter().map(|&i| shared.elevation[i]).collect(),
    };
    assert_eq!(a.apply_tile(&same_tile).unwrap(), 0);
    assert!(std::sync::Arc::ptr_eq(&a.shared(), &shared), "an unchanged map stays shared");
    let mut new_tile = same_tile.clone();
    new_tile.class[4] = if new_tile.class[4] == ROAD { GRASS } else { ROAD };
    assert_eq!(a.apply_tile(&new_tile).unwrap(), 1);
    assert!(!std::sync::Arc::ptr_eq(&a.shared(), &shared), "a change copies the map");
    assert!(std::sync::Arc::ptr_eq(&b.shared(), &shared), "the other holder keeps the original");
    assert_eq!(b.version(), shared.version);
    assert_eq!(a.version(), shared.version + 1);
}

#[test]
fn corrupt_blobs_are_rejected() {
    let m = city(60, 40);
    let blob = encode_layers(&m, &CompressionParams::default()).unwrap();
    let mut bad = blob.clone();
    bad.class_png.truncate(bad.class_png.len() / 2);
    assert!(decode_region(&bad).is_err());
    let mut bad = blob.clone();
    let n = bad.rgb_png.len();
    bad.rgb_png[n / 2] ^= 0xff; // CRC and zlib checks catch this
    assert!(decode_region(&bad).is_err());
    let mut bad = blob.clone();
    bad.width += 1; // header disagrees with the PNGs
    assert!(decode_region(&bad).is_err());
    let mut bad = blob.clone();
    bad.elevation_png = blob.class_png.clone(); // wrong colour type and size
    assert!(decode_region(&bad).is_err());
    let mut bad = blob.clone();
    bad.col0 = u32::MAX;
    assert!(decode_region(&bad).is_err());
    let mut bad = blob.clone();
    bad.spec.width = 1 << 20;
    bad.spec.height = 1 << 20;
    bad.width = 1 << 20;
    bad.height = 1 << 20;
    assert!(decode_region(&bad).is_err(), "hostile sizes are refused before decoding");
    let bytes = blob.to_bytes();
    assert!(CompressedMap::from_bytes(&bytes[..bytes.len() - 3]).is_err());
    assert!(CompressedMap::from_bytes(&[]).is_err());
    let mut other = Orthomap::new(spomp_core::GridSpec::new(spomp_core::Point2::new(1.0, 0.0), 0.5, 60, 40));
    assert!(other.apply_compressed(&blob).is_err(), "different grid");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn garbage_blobs_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300), flip in any::<(usize, u8)>()) {
        if let Ok(blob) = CompressedMap::from_bytes(&bytes) {
            let _ = decode_region(&blob);
        }
        let blob = encode_layers(&flat(8, 6, ROAD), &CompressionParams::default()).unwrap();
        let mut raw = blob.to_bytes();
        let n = raw.len();
        raw[flip.0 % n] ^= flip.1 | 1;
        if let Ok(b) = CompressedMap::from_bytes(&raw) {
            let _ = decode_map(&b);
        }
    }

    #[test]
    fn random_maps_round_trip(w in 1u32..24, h in 1u32..24, seed in any::<u64>()) {
        let mut m = flat(w, h, ROAD);
        let mut s = seed | 1;
        for i in 0..m.class.len() {
            s ^= s << 13; s ^= s >> 7; s ^= s << 17;
            m.class[i] = (s % 10) as u8;
            m.rgb[i] = [(s >> 8) as u8, (s >> 16) as u8, (s >> 24) as u8];
            m.elevation[i] = f32::from_bits((s >> 32) as u32);
        }
        let back = decode_map(&encode_layers(&m, &CompressionParams::default()).unwrap()).unwrap();
        prop_assert!(same(&m, &back));
    }
}
