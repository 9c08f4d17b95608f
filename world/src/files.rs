//! World files: `world.yaml` plus PNG layers, and a top-down picture of a world.
//!
//! PNG row 0 is the northern edge of the world (images are drawn north-up), so pixel (x, y) is
//! cell (x, height − 1 − y).

use std::path::{Path, PathBuf};

use image::{ImageBuffer, Luma, Rgb, RgbImage};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{AerialMap, ClassTable, DepthPanorama, GridSpec, PanoramaGeometry, Point2};

use spomp_behaviors::mission::limits::{
    MAX_SOURCE_BYTES, SourceError, number, read_regular, read_text, resolve_inside,
};
use spomp_behaviors::mission::output;
use spomp_behaviors::mission::yaml::{self, Node};

use crate::error::WorldError;
use crate::world::{World, WorldMeta};

/// Name of the world description inside a world directory.
pub const WORLD_FILE: &str = "world.yaml";

/// Where the class table of a world file comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum ClassTableSource {
    /// A YAML class table file, relative to the world directory.
    Path(String),
    /// The table itself.
    Inline(ClassTable),
}

/// The 16-bit elevation layer: elevation = offset_m + count · scale_m.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ElevationLayer {
    /// 16-bit grayscale PNG, relative to the world directory.
    pub file: String,
    /// Metres per count.
    pub scale_m: f64,
    /// Elevation of count 0, metres.
    #[serde(default)]
    pub offset_m: f64,
}

/// The layer files of a world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LayerFiles {
    /// RGB PNG whose colours are class colours of the table.
    pub class: String,
    /// Optional elevation layer; without it elevations are derived from the classes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elevation: Option<ElevationLayer>,
    /// Optional RGB PNG of the world's appearance; without it the class colours are used.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub color: Option<String>,
    /// Optional: the world as seen from above, where it differs from the ground (what the
    /// UAV's tiles and a prior map show); without it the ground layers are seen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub aerial: Option<AerialLayers>,
}

/// The world as seen from above where it is not what is on the ground: a barrier under tree
/// canopy or a fence too thin for an aerial map, drawn as the road it stands on. The robots'
/// aerial map then misleads there, and only driving tells.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct AerialLayers {
    /// RGB PNG of class colours, the size of the class layer. Where its class differs from the
    /// ground's, the aerial view has that class, its table colour and the height the class
    /// derives to (as for a world without an elevation layer); elsewhere the ground's layers.
    pub class: String,
}

/// The contents of `world.yaml`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WorldFile {
    /// Cell size, metres.
    pub resolution_m: f64,
    /// Map-frame position of the south-west corner of the world.
    #[serde(default)]
    pub origin: Point2,
    /// Width in cells; checked against the layers when given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<u32>,
    /// Height in cells; checked against the layers when given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height: Option<u32>,
    /// The class table; the table shipped with spomp when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub class_table: Option<ClassTableSource>,
    /// Layer files.
    pub layers: LayerFiles,
    /// Ground truth and start poses.
    #[serde(default)]
    pub meta: WorldMeta,
}

/// Heights used to derive an elevation layer from classes when a world has none.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct DerivedElevationParams {
    /// Height of `building` cells, metres.
    pub building_m: f32,
    /// Height of `vehicle` cells, metres.
    pub vehicle_m: f32,
    /// Height of `grass_sidewalk` cells (the curb), metres.
    pub grass_sidewalk_m: f32,
    /// Height of `vegetation` cells (bushes, canopy edge), metres.
    pub vegetation_m: f32,
    /// Height of `tree_trunk` cells, metres.
    pub tree_trunk_m: f32,
    /// Height of `light_pole` cells, metres.
    pub light_pole_m: f32,
}

impl Default for DerivedElevationParams {
    fn default() -> Self {
        DerivedElevationParams {
            building_m: 12.0,
            vehicle_m: 1.5,
            grass_sidewalk_m: 0.15,
            vegetation_m: 1.0,
            tree_trunk_m: 5.0,
            light_pole_m: 6.0,
        }
    }
}

impl DerivedElevationParams {
    /// Height for a class name, however the table spells it (`grass/sidewalk` is
    /// `grass_sidewalk`: [`spomp_core::classes::class_key`]); classes not listed (road, gravel,
    /// …) lie at 0.
    pub fn height_of(&self, class_name: &str) -> f32 {
        match spomp_core::classes::class_key(class_name).as_str() {
            "building" => self.building_m,
            "vehicle" => self.vehicle_m,
            "grass_sidewalk" => self.grass_sidewalk_m,
            "vegetation" => self.vegetation_m,
            "tree_trunk" => self.tree_trunk_m,
            "light_pole" => self.light_pole_m,
            _ => 0.0,
        }
    }
}

/// The most cells a world may have (a 4000 × 4000 grid); each simulated robot keeps maps of the
/// same size.
pub const MAX_WORLD_CELLS: u64 = 16_000_000;

/// Cell sizes a world may have, metres.
pub const RESOLUTION_RANGE_M: (f64, f64) = (0.01, 100.0);

/// The farthest a world's origin or a point of its metadata may lie from the map frame's
/// origin, metres (1000 km).
pub const MAX_COORDINATE_M: f64 = 1e6;

/// A value of `world.yaml` that is out of range: its field path (`origin.x`) and what is wrong.
type FieldError = (String, String);

/// Checks the numbers of a world description before anything is allocated from them: finite,
/// in range, the map-frame points of the metadata inside the coordinate limit.
fn check_description(desc: &WorldFile) -> Result<(), FieldError> {
    let (lo, hi) = RESOLUTION_RANGE_M;
    if !(desc.resolution_m.is_finite() && (lo..=hi).contains(&desc.resolution_m)) {
        return Err((
            "resolution_m".into(),
            format!("resolution_m must be between {lo} and {hi} metres per cell, got {}", number(desc.resolution_m)),
        ));
    }
    let coordinate = |what: String, v: f64| -> Result<(), FieldError> {
        if v.is_finite() && v.abs() <= MAX_COORDINATE_M {
            Ok(())
        } else {
            let message =
                format!("{what} must be a finite coordinate within ±{} m, got {}", number(MAX_COORDINATE_M), number(v));
            Err((what, message))
        }
    };
    coordinate("origin.x".into(), desc.origin.x)?;
    coordinate("origin.y".into(), desc.origin.y)?;
    if let (Some(w), Some(h)) = (desc.width, desc.height) {
        check_cells(w, h, desc.resolution_m).map_err(|m| ("width".to_string(), m))?;
    }
    if let Some(e) = &desc.layers.elevation {
        let scale_ok = e.scale_m.is_finite() && e.scale_m > 0.0 && e.scale_m <= 1.0;
        let offset_ok = e.offset_m.is_finite() && e.offset_m.abs() <= 1e4;
        if !(scale_ok && offset_ok) {
            let field = if scale_ok { "layers.elevation.offset_m" } else { "layers.elevation.scale_m" };
            return Err((
                field.into(),
                format!(
                    "layers.elevation needs 0 < scale_m ≤ 1 metre per count and |offset_m| ≤ 10000 m, got scale_m {} and offset_m {}",
                    number(e.scale_m),
                    number(e.offset_m)
                ),
            ));
        }
    }
    for (i, p) in desc.meta.vehicle_clusters.iter().enumerate() {
        coordinate(format!("meta.vehicle_clusters[{i}].x"), p.x)?;
        coordinate(format!("meta.vehicle_clusters[{i}].y"), p.y)?;
    }
    for (i, p) in desc.meta.roadblocks.iter().enumerate() {
        coordinate(format!("meta.roadblocks[{i}].x"), p.x)?;
        coordinate(format!("meta.roadblocks[{i}].y"), p.y)?;
    }
    for (i, p) in desc.meta.start_poses.iter().enumerate() {
        coordinate(format!("meta.start_poses[{i}].x"), p.x)?;
        coordinate(format!("meta.start_poses[{i}].y"), p.y)?;
        if !p.yaw.is_finite() {
            let field = format!("meta.start_poses[{i}].yaw");
            let message = format!("{field} must be finite, got {}", p.yaw);
            return Err((field, message));
        }
    }
    if let Some(g) = &desc.meta.gps_origin
        && !(g.latitude_deg.is_finite()
            && g.latitude_deg.abs() <= 85.0
            && g.longitude_deg.is_finite()
            && g.longitude_deg.abs() <= 180.0)
    {
        let field = "meta.gps_origin".to_string();
        let message = format!(
            "{field} must be a latitude within ±85° and a longitude within ±180°, got {}, {}",
            number(g.latitude_deg),
            number(g.longitude_deg)
        );
        return Err((field, message));
    }
    Ok(())
}

/// Checks the size of a grid: at most [`MAX_WORLD_CELLS`] cells, and an extent within the
/// coordinate limit.
fn check_cells(width: u32, height: u32, resolution_m: f64) -> Result<(), String> {
    let cells = u64::from(width) * u64::from(height);
    if cells == 0 {
        return Err(format!("the world is {width} × {height} cells; it needs at least one"));
    }
    if cells > MAX_WORLD_CELLS {
        return Err(format!("the world is {width} × {height} = {cells} cells; at most {MAX_WORLD_CELLS} are allowed"));
    }
    let extent = f64::from(width.max(height)) * resolution_m;
    if extent > MAX_COORDINATE_M {
        return Err(format!("the world is {extent} m across; at most {MAX_COORDINATE_M} m are allowed"));
    }
    Ok(())
}

/// The node a field path (`meta.start_poses[2].yaw`) names, or the deepest node on the way
/// there that exists (the mapping a defaulted key is missing from).
fn node_at<'a>(root: &'a Node, field: &str) -> &'a Node {
    let mut node = root;
    for part in field.split('.') {
        let (key, indices) = part.split_once('[').map_or((part, ""), |(k, rest)| (k, rest));
        if !key.is_empty() {
            match node.get(key) {
                Some(n) => node = n,
                None => return node,
            }
        }
        for index in indices.split('[').filter(|s| !s.is_empty()) {
            let item = index.trim_end_matches(']').parse::<usize>().ok().and_then(|i| node.as_seq()?.get(i));
            match item {
                Some(n) => node = n,
                None => return node,
            }
        }
    }
    node
}

/// A located error of `world.yaml`: at the value of `field` (or the nearest node above it).
fn field_error(path: &Path, root: &Node, field: &str, message: String) -> WorldError {
    let loc = node_at(root, field).loc;
    let message = if message.starts_with(field) { message } else { format!("{field}: {message}") };
    WorldError::BadYaml { path: path.to_path_buf(), line: loc.line, column: loc.column, field: field.into(), message }
}

/// Parses `world.yaml` into a description; every error carries its line, column and field.
fn parse_description(path: &Path, text: &str) -> Result<(Node, WorldFile), WorldError> {
    let root = yaml::parse(text).map_err(|e| WorldError::BadYaml {
        path: path.to_path_buf(),
        line: e.loc.line,
        column: e.loc.column,
        field: String::new(),
        message: e.message,
    })?;
    let desc: WorldFile = root.deserialize().map_err(|e| {
        let field = e.path_string();
        let loc = e.loc.unwrap_or_else(|| node_at(&root, &field).loc);
        let message = if field.is_empty() { e.message } else { format!("{field}: {}", e.message) };
        WorldError::BadYaml { path: path.to_path_buf(), line: loc.line, column: loc.column, field, message }
    })?;
    check_description(&desc).map_err(|(field, message)| field_error(path, &root, &field, message))?;
    Ok((root, desc))
}

fn source_err(path: &Path) -> impl FnOnce(SourceError) -> WorldError + '_ {
    move |e| match e {
        SourceError::Io { message, kind, .. } => {
            WorldError::Io { path: path.to_path_buf(), source: std::io::Error::new(kind, message) }
        }
        other => {
            let (line, column) = other.position().unwrap_or((0, 0));
            WorldError::BadYaml {
                path: path.to_path_buf(),
                line,
                column,
                field: String::new(),
                message: other.to_string(),
            }
        }
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> WorldError + '_ {
    move |source| WorldError::Io { path: path.to_path_buf(), source }
}

fn image_err(path: &Path) -> impl FnOnce(image::ImageError) -> WorldError + '_ {
    move |e| match e {
        image::ImageError::IoError(source) => WorldError::Io { path: path.to_path_buf(), source },
        other => WorldError::BadImage { path: path.to_path_buf(), message: other.to_string() },
    }
}

/// Re-checks a table written inline in `world.yaml` through the core parser (which owns the
/// rules); its errors point at the `class_table` key.
fn checked_table(table: ClassTable, path: &Path, root: &Node) -> Result<ClassTable, WorldError> {
    let text = serde_saphyr::to_string(&table)
        .map_err(|e| field_error(path, root, "class_table", format!("class_table: {e}")))?;
    ClassTable::from_yaml(&text).map_err(|e| field_error(path, root, "class_table", format!("class_table: {e}")))
}

fn open_layer(dir: &Path, file: &str, layer: &'static str) -> Result<(PathBuf, image::DynamicImage), WorldError> {
    let path = resolve_inside(&[dir.to_path_buf()], dir, file).map_err(source_err(&dir.join(WORLD_FILE)))?;
    if !path.is_file() {
        return Err(WorldError::MissingLayer { layer, path });
    }
    // A regular file within the size limit (no FIFO, no device, no multi-gigabyte file), then
    // decoded from memory with the image library's default allocation limits.
    let bytes = read_regular(&path, MAX_LAYER_PNG_BYTES).map_err(source_err(&path))?;
    let img = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|source| WorldError::Io { path: path.clone(), source })?
        .decode()
        .map_err(image_err(&path))?;
    Ok((path, img))
}

/// The largest world layer PNG read, bytes (a 10 000 × 10 000 colour layer compresses far below).
pub const MAX_LAYER_PNG_BYTES: u64 = 256 << 20;

fn check_size(layer: &'static str, path: &Path, spec: &GridSpec, w: u32, h: u32) -> Result<(), WorldError> {
    if w != spec.width || h != spec.height {
        return Err(WorldError::WrongSize {
            layer,
            path: path.to_path_buf(),
            width: spec.width,
            height: spec.height,
            got_width: w,
            got_height: h,
        });
    }
    Ok(())
}

/// The aerial view of a world whose `layers.aerial` names a class raster: the ground's layers
/// (`ground`), with the aerial class, its table colour and its derived height wherever the
/// aerial class differs from the ground's.
fn aerial_view(
    dir: &Path,
    layers: &AerialLayers,
    ground: &AerialMap,
    classes: &ClassTable,
    color_lut: &[([u8; 3], u8)],
    heights: &DerivedElevationParams,
) -> Result<AerialMap, WorldError> {
    let (path, img) = open_layer(dir, &layers.class, "aerial.class")?;
    let img = img.to_rgb8();
    let spec = ground.spec;
    check_size("aerial.class", &path, &spec, img.width(), img.height())?;
    let (w, h) = (spec.width as usize, spec.height as usize);
    let mut height_of = [0.0f32; 256];
    for c in &classes.classes {
        height_of[c.index as usize] = heights.height_of(&c.name);
    }
    let mut aerial = ground.clone();
    for (x, y, px) in img.enumerate_pixels() {
        let rgb = px.0;
        let Ok(k) = color_lut.binary_search_by(|(c, _)| c.cmp(&rgb)) else {
            return Err(WorldError::UnknownColor { path, x, y, color: rgb });
        };
        let class = color_lut[k].1;
        let i = (h - 1 - y as usize) * w + x as usize;
        if class != ground.class[i] {
            aerial.class[i] = class;
            aerial.rgb[i] = rgb;
            aerial.elevation[i] = height_of[class as usize];
        }
    }
    Ok(aerial)
}

impl World {
    /// Loads a world directory (`world.yaml` and its layers); elevations absent from the files
    /// are derived from the classes with the default heights.
    pub fn load(dir: impl AsRef<Path>) -> Result<World, WorldError> {
        World::load_with(dir, &DerivedElevationParams::default())
    }

    /// Loads a world directory, deriving missing elevations with `heights`.
    pub fn load_with(dir: impl AsRef<Path>, heights: &DerivedElevationParams) -> Result<World, WorldError> {
        let dir = dir.as_ref();
        let yaml_path = dir.join(WORLD_FILE);
        let text = read_text(&yaml_path, MAX_SOURCE_BYTES).map_err(source_err(&yaml_path))?;
        let (root, desc) = parse_description(&yaml_path, &text)?;
        let classes = match &desc.class_table {
            None => ClassTable::default_table(),
            Some(ClassTableSource::Inline(t)) => checked_table(t.clone(), &yaml_path, &root)?,
            Some(ClassTableSource::Path(p)) => {
                let path = resolve_inside(&[dir.to_path_buf()], dir, p).map_err(source_err(&yaml_path))?;
                let text = read_text(&path, MAX_SOURCE_BYTES).map_err(source_err(&path))?;
                ClassTable::from_yaml(&text)?
            }
        };

        let (class_path, class_img) = open_layer(dir, &desc.layers.class, "class")?;
        let (width, height) = (desc.width.unwrap_or(class_img.width()), desc.height.unwrap_or(class_img.height()));
        check_cells(width, height, desc.resolution_m).map_err(|message| {
            // The size comes from `width`/`height` when given, else from the class layer.
            let field = match (desc.width, desc.height) {
                (Some(_), _) => "width",
                (None, Some(_)) => "height",
                (None, None) => "layers.class",
            };
            field_error(&yaml_path, &root, field, message)
        })?;
        let class_img = class_img.to_rgb8();
        let spec = GridSpec::new(desc.origin, desc.resolution_m, width, height);
        check_size("class", &class_path, &spec, class_img.width(), class_img.height())?;
        let (w, h) = (spec.width as usize, spec.height as usize);
        let mut map = AerialMap::unknown(spec);
        let mut color_lut: Vec<([u8; 3], u8)> = classes.classes.iter().map(|c| (c.color, c.index)).collect();
        color_lut.sort_unstable();
        for (x, y, px) in class_img.enumerate_pixels() {
            let rgb = px.0;
            let Ok(k) = color_lut.binary_search_by(|(c, _)| c.cmp(&rgb)) else {
                return Err(WorldError::UnknownColor { path: class_path, x, y, color: rgb });
            };
            let i = (h - 1 - y as usize) * w + x as usize;
            map.class[i] = color_lut[k].1;
            map.rgb[i] = rgb;
        }

        match &desc.layers.elevation {
            Some(layer) => {
                let (path, img) = open_layer(dir, &layer.file, "elevation")?;
                let image::DynamicImage::ImageLuma16(img) = img else {
                    return Err(WorldError::BadImage {
                        path,
                        message: format!("elevation must be a 16-bit grayscale PNG, found {:?}", img.color()),
                    });
                };
                check_size("elevation", &path, &spec, img.width(), img.height())?;
                for (x, y, px) in img.enumerate_pixels() {
                    let i = (h - 1 - y as usize) * w + x as usize;
                    map.elevation[i] = (layer.offset_m + px.0[0] as f64 * layer.scale_m) as f32;
                }
            }
            None => {
                let mut lut = [0.0f32; 256];
                for c in &classes.classes {
                    lut[c.index as usize] = heights.height_of(&c.name);
                }
                for (e, &c) in map.elevation.iter_mut().zip(&map.class) {
                    *e = lut[c as usize];
                }
            }
        }

        if let Some(file) = &desc.layers.color {
            let (path, img) = open_layer(dir, file, "color")?;
            let img = img.to_rgb8();
            check_size("color", &path, &spec, img.width(), img.height())?;
            for (x, y, px) in img.enumerate_pixels() {
                map.rgb[(h - 1 - y as usize) * w + x as usize] = px.0;
            }
        }
        map.version = 1;
        let aerial = match &desc.layers.aerial {
            Some(layers) => Some(aerial_view(dir, layers, &map, &classes, &color_lut, heights)?),
            None => None,
        };
        let mut world = World::new(map, classes, desc.meta)?;
        if let Some(aerial) = aerial {
            world.set_aerial_view(aerial)?;
        }
        Ok(world)
    }

    /// Writes the world into `dir` (created if needed): `world.yaml` with the class table
    /// inline, `class.png`, a 16-bit `elevation.png` (1 mm per count when the relief fits),
    /// `color.png` and, for a world with an aerial view of its own, its classes as
    /// `aerial-class.png` (loaded back, the view's colours and heights are derived from them).
    pub fn save(&self, dir: impl AsRef<Path>) -> Result<(), WorldError> {
        let dir = dir.as_ref();
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let spec = *self.spec();
        let (w, h) = (spec.width, spec.height);
        let lo = self.map().elevation.iter().copied().fold(f32::INFINITY, f32::min);
        let offset_m = (lo as f64).floor();
        let relief = self.max_elevation_m() as f64 - offset_m;
        // Millimetres when the relief fits in 16 bits, else the smallest whole-millimetre step that fits.
        let scale_m = ((relief / u16::MAX as f64) * 1000.0).ceil().max(1.0) / 1000.0;

        let mut class_img = RgbImage::new(w, h);
        let mut color_img = RgbImage::new(w, h);
        let mut elev_img: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::new(w, h);
        let mut class_colors = [[0u8; 3]; 256];
        for c in &self.classes().classes {
            class_colors[c.index as usize] = c.color;
        }
        for (i, ((&class, &rgb), &e)) in
            self.map().class.iter().zip(&self.map().rgb).zip(&self.map().elevation).enumerate()
        {
            let cell = spec.cell_of_index(i);
            let (x, y) = (cell.col, h - 1 - cell.row);
            class_img.put_pixel(x, y, Rgb(class_colors[class as usize]));
            color_img.put_pixel(x, y, Rgb(rgb));
            let count = ((e as f64 - offset_m) / scale_m).round().clamp(0.0, u16::MAX as f64) as u16;
            elev_img.put_pixel(x, y, Luma([count]));
        }
        // Encoded in memory, then written without following a link planted in the folder.
        let save_png = |name: &str, result: Result<(), image::ImageError>, bytes: Vec<u8>| {
            let path = dir.join(name);
            result.map_err(image_err(&path))?;
            output::write_file(&path, &bytes).map_err(io_err(&path))
        };
        let mut bytes = Vec::new();
        let encoded = class_img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png);
        save_png("class.png", encoded, bytes)?;
        let mut bytes = Vec::new();
        let encoded = color_img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png);
        save_png("color.png", encoded, bytes)?;
        let mut bytes = Vec::new();
        let encoded = elev_img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png);
        save_png("elevation.png", encoded, bytes)?;
        let aerial = if self.has_aerial_view() {
            let mut aerial_img = RgbImage::new(w, h);
            for (i, &class) in self.aerial_map().class.iter().enumerate() {
                let cell = spec.cell_of_index(i);
                aerial_img.put_pixel(cell.col, h - 1 - cell.row, Rgb(class_colors[class as usize]));
            }
            let mut bytes = Vec::new();
            let encoded = aerial_img.write_to(&mut std::io::Cursor::new(&mut bytes), image::ImageFormat::Png);
            save_png("aerial-class.png", encoded, bytes)?;
            Some(AerialLayers { class: "aerial-class.png".into() })
        } else {
            None
        };

        let desc = WorldFile {
            resolution_m: spec.resolution_m,
            origin: spec.origin,
            width: Some(w),
            height: Some(h),
            class_table: Some(ClassTableSource::Inline(self.classes().clone())),
            layers: LayerFiles {
                class: "class.png".into(),
                elevation: Some(ElevationLayer { file: "elevation.png".into(), scale_m, offset_m }),
                color: Some("color.png".into()),
                aerial,
            },
            meta: self.meta.clone(),
        };
        let yaml_path = dir.join(WORLD_FILE);
        let text = serde_saphyr::to_string(&desc).map_err(|e| WorldError::BadYaml {
            path: yaml_path.clone(),
            line: 0,
            column: 0,
            field: String::new(),
            message: e.to_string(),
        })?;
        output::write_file(&yaml_path, text.as_bytes()).map_err(io_err(&yaml_path))
    }
}

/// The largest depth-panorama PNG [`read_depth_png`] reads, bytes.
pub const MAX_DEPTH_PNG_BYTES: u64 = 64 << 20;

/// Reads a depth panorama saved as a 16-bit grayscale PNG of range counts (`spomp terrain`'s
/// input, `--save-panos` output): a regular file of at most [`MAX_DEPTH_PNG_BYTES`], decoded by
/// [`decode_depth_png`].
pub fn read_depth_png(path: &Path, range_scale_m: f64, v_fov_rad: f64) -> Result<DepthPanorama, WorldError> {
    let bytes = read_regular(path, MAX_DEPTH_PNG_BYTES).map_err(source_err(path))?;
    decode_depth_png(&bytes, range_scale_m, v_fov_rad).map_err(|e| match e {
        WorldError::BadImage { message, .. } => WorldError::BadImage { path: path.to_path_buf(), message },
        other => other,
    })
}

/// Decodes the bytes of a 16-bit grayscale PNG of range counts into a depth panorama of
/// `range_scale_m` metres per count and a vertical field of view of `v_fov_rad`. Errors (as
/// [`WorldError::BadImage`] with an empty path) when the bytes are no image, not 16-bit grayscale,
/// or larger than the decoder's memory limit.
pub fn decode_depth_png(bytes: &[u8], range_scale_m: f64, v_fov_rad: f64) -> Result<DepthPanorama, WorldError> {
    let bad = |message: String| WorldError::BadImage { path: PathBuf::new(), message };
    let reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    let img = reader.decode().map_err(|e| bad(format!("not a readable PNG image: {e}")))?;
    let image::DynamicImage::ImageLuma16(gray) = img else {
        return Err(bad(format!("expected a 16-bit grayscale PNG of range counts, found {:?}", img.color())));
    };
    let geometry = PanoramaGeometry { rows: gray.height() as usize, cols: gray.width() as usize, v_fov_rad };
    DepthPanorama::from_counts(geometry, gray.as_raw(), range_scale_m)
        .ok_or_else(|| bad("the pixel count does not match the image size".into()))
}

/// A top-down picture of a world, north up: the colour layer shaded by the relief (light from
/// the north-west, so curbs and buildings stand out), vehicle-cluster centres marked with blue
/// squares, roadblocks with red crosses and start poses with white dots.
pub fn render_png(world: &World) -> RgbImage {
    let spec = *world.spec();
    let (w, h) = (spec.width, spec.height);
    let res = spec.resolution_m as f32;
    let mut img = RgbImage::new(w, h);
    for row in 0..h as i64 {
        for col in 0..w as i64 {
            let e = |c: i64, r: i64| world.elevation_cell(c, r).unwrap_or(0.0);
            let here = e(col, row);
            // Slope towards the light (north-west), clamped: positive faces the light.
            let facing = ((e(col + 1, row - 1) - e(col - 1, row + 1)) / (2.0 * res)).clamp(-2.0, 2.0);
            let shade = (1.0 - 0.25 * facing).clamp(0.5, 1.4);
            let i = row as usize * w as usize + col as usize;
            let rgb = world.map().rgb[i];
            let lift = (here.max(0.0) * 2.0).min(40.0);
            let px = rgb.map(|v| ((v as f32 + lift) * shade).clamp(0.0, 255.0) as u8);
            img.put_pixel(col as u32, (h as i64 - 1 - row) as u32, Rgb(px));
        }
    }
    let mut mark = |p: Point2, color: [u8; 3], offsets: &[(i64, i64)]| {
        let Some(cell) = spec.cell_at(p) else { return };
        for &(dx, dy) in offsets {
            let (x, y) = (cell.col as i64 + dx, h as i64 - 1 - cell.row as i64 - dy);
            if x >= 0 && y >= 0 && x < w as i64 && y < h as i64 {
                img.put_pixel(x as u32, y as u32, Rgb(color));
            }
        }
    };
    let half = (7.5 / spec.resolution_m).round() as i64;
    let square: Vec<(i64, i64)> = (-half..=half).flat_map(|k| [(k, -half), (k, half), (-half, k), (half, k)]).collect();
    let cross: Vec<(i64, i64)> = (-4..=4).flat_map(|k| [(k, k), (k, -k)]).collect();
    let dot: Vec<(i64, i64)> = (-1..=1).flat_map(|a| (-1..=1).map(move |b| (a, b))).collect();
    for &p in &world.meta.vehicle_clusters {
        mark(p, [0, 90, 255], &square);
    }
    for &p in &world.meta.roadblocks {
        mark(p, [255, 0, 0], &cross);
    }
    for s in &world.meta.start_poses {
        mark(s.position(), [255, 255, 255], &dot);
    }
    img
}
