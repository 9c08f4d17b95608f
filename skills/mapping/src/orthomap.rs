//! The growing, versioned orthomap and the PNG compression of its layers for transmission.
//!
//! Each layer of a map region becomes one PNG (paper §Aerial Mapper: about 10× smaller):
//! - class: 8-bit grey, the class index (255 = unknown);
//! - colour: 8-bit RGB;
//! - elevation: the f32 bit patterns as a 16-bit grey image of twice the height, the high halves
//!   in the top half and the low halves below, so the round trip is exact (NaN included) while
//!   the smooth high halves still compress well.
//!
//! The PNGs travel in a [`CompressedMap`] (region placement, map version, the three PNGs),
//! serialised with postcard into one blob for `spomp-teamstate`.

use std::io::Cursor;
use std::sync::Arc;

use image::codecs::png::{CompressionType, FilterType, PngDecoder, PngEncoder};
use image::{ExtendedColorType, ImageDecoder, ImageEncoder};
use serde::{Deserialize, Serialize};
use spomp_core::{AerialMap, GridSpec, MapTile};

use crate::error::MappingError;
use crate::params::{CompressionParams, PngLevel};

/// Largest region a blob may declare, cells (16 384 × 16 384 at 0.5 m is 8 km square): bounds
/// the memory a hostile blob can make the decoder allocate.
pub const MAX_REGION_CELLS: u64 = 1 << 28;

/// A map region with its layers PNG-compressed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompressedMap {
    /// The whole map's grid (the region is placed in it).
    pub spec: GridSpec,
    /// Map version the region was taken from.
    pub version: u64,
    /// First column of the region.
    pub col0: u32,
    /// First row of the region.
    pub row0: u32,
    /// Region width, cells.
    pub width: u32,
    /// Region height, cells.
    pub height: u32,
    /// Class layer PNG.
    pub class_png: Vec<u8>,
    /// Colour layer PNG.
    pub rgb_png: Vec<u8>,
    /// Elevation layer PNG (f32 bits split into two 16-bit planes).
    pub elevation_png: Vec<u8>,
}

impl CompressedMap {
    /// Encoded size of the three PNGs, bytes.
    pub fn png_bytes(&self) -> usize {
        self.class_png.len() + self.rgb_png.len() + self.elevation_png.len()
    }

    /// Uncompressed size of the region's layers (1 + 3 + 4 bytes per cell), bytes.
    pub fn raw_bytes(&self) -> usize {
        self.width as usize * self.height as usize * 8
    }

    /// One blob for transmission (e.g. `TeamState::add_map_version`).
    pub fn to_bytes(&self) -> Vec<u8> {
        postcard::to_stdvec(self).unwrap_or_default()
    }

    /// Parses a blob made by [`CompressedMap::to_bytes`]. The PNGs are checked only when
    /// decoded.
    pub fn from_bytes(bytes: &[u8]) -> Result<CompressedMap, MappingError> {
        let (map, rest) =
            postcard::take_from_bytes::<CompressedMap>(bytes).map_err(|e| MappingError::CorruptBlob(e.to_string()))?;
        if !rest.is_empty() {
            return Err(MappingError::CorruptBlob(format!("{} trailing bytes", rest.len())));
        }
        Ok(map)
    }
}

fn compression(level: PngLevel) -> CompressionType {
    match level {
        PngLevel::Fast => CompressionType::Fast,
        PngLevel::Default => CompressionType::Default,
        PngLevel::Best => CompressionType::Best,
    }
}

fn png(data: &[u8], w: u32, h: u32, color: ExtendedColorType, level: PngLevel) -> Result<Vec<u8>, MappingError> {
    let mut out = Vec::new();
    PngEncoder::new_with_quality(&mut out, compression(level), FilterType::Adaptive)
        .write_image(data, w, h, color)
        .map_err(|e| MappingError::Encode(e.to_string()))?;
    Ok(out)
}

/// Decodes a PNG that must have the given size and colour type; returns native-endian bytes.
fn unpng(bytes: &[u8], w: u32, h: u32, color: image::ColorType, what: &str) -> Result<Vec<u8>, MappingError> {
    let corrupt = |e: String| MappingError::CorruptBlob(format!("{what} layer: {e}"));
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    limits.max_alloc = Some((w as u64 * h as u64 * 8).max(1 << 16) * 2);
    let decoder = PngDecoder::with_limits(Cursor::new(bytes), limits).map_err(|e| corrupt(e.to_string()))?;
    if decoder.dimensions() != (w, h) || decoder.color_type() != color {
        return Err(corrupt(format!(
            "expected {w}×{h} {color:?}, found {:?} {:?}",
            decoder.dimensions(),
            decoder.color_type()
        )));
    }
    let mut buf = vec![0u8; decoder.total_bytes() as usize];
    decoder.read_image(&mut buf).map_err(|e| corrupt(e.to_string()))?;
    Ok(buf)
}

fn check_map(map: &AerialMap) -> Result<(), MappingError> {
    let n = map.spec.len();
    if map.class.len() != n || map.rgb.len() != n || map.elevation.len() != n {
        return Err(MappingError::InconsistentMap(format!(
            "layers have {}, {}, {} cells for a {}×{} grid",
            map.class.len(),
            map.rgb.len(),
            map.elevation.len(),
            map.spec.width,
            map.spec.height
        )));
    }
    Ok(())
}

/// Compresses the whole map.
pub fn encode_layers(map: &AerialMap, params: &CompressionParams) -> Result<CompressedMap, MappingError> {
    encode_region(map, 0, 0, map.spec.width, map.spec.height, params)
}

/// Compresses a rectangular region of the map (e.g. the part that changed).
pub fn encode_region(
    map: &AerialMap,
    col0: u32,
    row0: u32,
    width: u32,
    height: u32,
    params: &CompressionParams,
) -> Result<CompressedMap, MappingError> {
    check_map(map)?;
    let fits = |start: u32, len: u32, size: u32| start.checked_add(len).is_some_and(|end| end <= size);
    if width == 0 || height == 0 || !fits(col0, width, map.spec.width) || !fits(row0, height, map.spec.height) {
        return Err(MappingError::InconsistentMap(format!(
            "region {width}×{height} at ({col0}, {row0}) is empty or outside the {}×{} map",
            map.spec.width, map.spec.height
        )));
    }
    let (w, h) = (width as usize, height as usize);
    let mut class = Vec::with_capacity(w * h);
    let mut rgb = Vec::with_capacity(w * h * 3);
    let mut hi = Vec::with_capacity(w * h * 2);
    let mut lo = Vec::with_capacity(w * h * 2);
    for r in 0..h {
        let start = (row0 as usize + r) * map.spec.width as usize + col0 as usize;
        let range = start..start + w;
        class.extend_from_slice(&map.class[range.clone()]);
        for px in &map.rgb[range.clone()] {
            rgb.extend_from_slice(px);
        }
        for e in &map.elevation[range] {
            let bits = e.to_bits();
            hi.extend_from_slice(&((bits >> 16) as u16).to_ne_bytes());
            lo.extend_from_slice(&(bits as u16).to_ne_bytes());
        }
    }
    hi.extend_from_slice(&lo);
    let level = params.level;
    Ok(CompressedMap {
        spec: map.spec,
        version: map.version,
        col0,
        row0,
        width,
        height,
        class_png: png(&class, width, height, ExtendedColorType::L8, level)?,
        rgb_png: png(&rgb, width, height, ExtendedColorType::Rgb8, level)?,
        elevation_png: png(&hi, width, height * 2, ExtendedColorType::L16, level)?,
    })
}

/// Decompresses a region into a tile (apply it with [`Orthomap::apply_tile`] or
/// `AerialMap::apply_tile`). Corrupt or inconsistent blobs are errors.
pub fn decode_region(blob: &CompressedMap) -> Result<MapTile, MappingError> {
    let (w, h) = (blob.width, blob.height);
    let fits = |start: u32, len: u32, size: u32| start.checked_add(len).is_some_and(|end| end <= size);
    if w == 0 || h == 0 || !fits(blob.col0, w, blob.spec.width) || !fits(blob.row0, h, blob.spec.height) {
        return Err(MappingError::CorruptBlob("region is empty or outside its map".into()));
    }
    if w as u64 * h as u64 > MAX_REGION_CELLS {
        return Err(MappingError::CorruptBlob(format!("region of {w}×{h} cells is too large")));
    }
    let h2 = h.checked_mul(2).ok_or_else(|| MappingError::CorruptBlob("region too tall".into()))?;
    let class = unpng(&blob.class_png, w, h, image::ColorType::L8, "class")?;
    let rgb_bytes = unpng(&blob.rgb_png, w, h, image::ColorType::Rgb8, "colour")?;
    let elev_bytes = unpng(&blob.elevation_png, w, h2, image::ColorType::L16, "elevation")?;
    let n = w as usize * h as usize;
    let rgb = rgb_bytes.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let (hi, lo) = elev_bytes.split_at(n * 2);
    let elevation = hi
        .chunks_exact(2)
        .zip(lo.chunks_exact(2))
        .map(|(a, b)| {
            let hi = u16::from_ne_bytes([a[0], a[1]]) as u32;
            let lo = u16::from_ne_bytes([b[0], b[1]]) as u32;
            f32::from_bits(hi << 16 | lo)
        })
        .collect();
    Ok(MapTile { col0: blob.col0, row0: blob.row0, width: w, height: h, class, rgb, elevation })
}

/// Decompresses a blob into a full map of its grid (cells outside the region unknown), with the
/// blob's version.
pub fn decode_map(blob: &CompressedMap) -> Result<AerialMap, MappingError> {
    let tile = decode_region(blob)?;
    let mut map = AerialMap::unknown(blob.spec);
    write_tile_exact(&mut map, &tile);
    map.version = blob.version;
    Ok(map)
}

/// Copies every cell of a tile (unknown cells and NaN elevations included) into the map.
fn write_tile_exact(map: &mut AerialMap, tile: &MapTile) {
    let mw = map.spec.width as usize;
    for r in 0..tile.height as usize {
        let src = r * tile.width as usize;
        let dst = (tile.row0 as usize + r) * mw + tile.col0 as usize;
        let n = tile.width as usize;
        map.class[dst..dst + n].copy_from_slice(&tile.class[src..src + n]);
        map.rgb[dst..dst + n].copy_from_slice(&tile.rgb[src..src + n]);
        map.elevation[dst..dst + n].copy_from_slice(&tile.elevation[src..src + n]);
    }
}

/// The UAV's orthomap: an [`AerialMap`] that grows by tiles and keeps a version, plus the
/// bounding box of what changed since the last transmission.
#[derive(Clone, Debug)]
pub struct Orthomap {
    /// Shared with snapshots taken for work off the tick thread; written copy-on-write.
    map: Arc<AerialMap>,
    /// Changed cells since `take_dirty_region`: (col_min, row_min, col_max, row_max).
    dirty: Option<(u32, u32, u32, u32)>,
}

impl Orthomap {
    /// An all-unknown map over `spec`.
    pub fn new(spec: GridSpec) -> Self {
        Orthomap { map: Arc::new(AerialMap::unknown(spec)), dirty: None }
    }

    /// Wraps an existing map (e.g. one received from a peer).
    pub fn from_map(map: AerialMap) -> Result<Self, MappingError> {
        Self::from_shared(Arc::new(map))
    }

    /// Wraps a map others hold too (a team's prior map): no copy is made until this map
    /// changes, so robots that start with the same map hold it once.
    pub fn from_shared(map: Arc<AerialMap>) -> Result<Self, MappingError> {
        check_map(&map)?;
        Ok(Orthomap { map, dirty: None })
    }

    /// The map.
    pub fn map(&self) -> &AerialMap {
        &self.map
    }

    /// The map as it is now, shared: a snapshot for work on another thread costs no copy, and
    /// the next change to this map copies it instead.
    pub fn shared(&self) -> Arc<AerialMap> {
        Arc::clone(&self.map)
    }

    /// The map version (grows with every change).
    pub fn version(&self) -> u64 {
        self.map.version
    }

    /// Writes a tile (clipped to the map; unknown cells are not applied); returns the number of
    /// cells changed. Inconsistent tiles are errors.
    pub fn apply_tile(&mut self, tile: &MapTile) -> Result<usize, MappingError> {
        if !tile.is_consistent() {
            return Err(MappingError::InconsistentMap("tile layers do not match its size".into()));
        }
        // A tile that changes nothing (a camera passing over a prior map) must not copy a map
        // shared with others.
        if !self.map.tile_changes_anything(tile) {
            return Ok(0);
        }
        let changed = Arc::make_mut(&mut self.map).apply_tile(tile);
        if changed > 0 && tile.col0 < self.map.spec.width && tile.row0 < self.map.spec.height {
            let c1 = (tile.col0 as u64 + tile.width as u64).min(self.map.spec.width as u64) as u32 - 1;
            let r1 = (tile.row0 as u64 + tile.height as u64).min(self.map.spec.height as u64) as u32 - 1;
            self.dirty = Some(match self.dirty {
                None => (tile.col0, tile.row0, c1, r1),
                Some((a, b, c, d)) => (a.min(tile.col0), b.min(tile.row0), c.max(c1), d.max(r1)),
            });
        }
        Ok(changed)
    }

    /// Decompresses a received blob and merges it; returns the number of cells changed.
    pub fn apply_compressed(&mut self, blob: &CompressedMap) -> Result<usize, MappingError> {
        if blob.spec != self.map.spec {
            return Err(MappingError::CorruptBlob("blob is for a different map grid".into()));
        }
        let tile = decode_region(blob)?;
        self.apply_tile(&tile)
    }

    /// Compresses the whole map.
    pub fn encode(&self, params: &CompressionParams) -> Result<CompressedMap, MappingError> {
        encode_layers(&self.map, params)
    }

    /// Compresses the region changed since the last call (None if nothing changed) and clears
    /// it.
    pub fn encode_changes(&mut self, params: &CompressionParams) -> Result<Option<CompressedMap>, MappingError> {
        let Some((c0, r0, c1, r1)) = self.dirty else {
            return Ok(None);
        };
        let blob = encode_region(&self.map, c0, r0, c1 - c0 + 1, r1 - r0 + 1, params)?;
        self.dirty = None;
        Ok(Some(blob))
    }
}
