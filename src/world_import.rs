//! `spomp world import`: a colour-coded semantic raster (an aerial survey's class map) becomes a
//! world folder the simulator loads.
//!
//! - Every raster pixel becomes one cell of `--resolution-m` metres (or `1 / --pixels-per-m`);
//!   row 0 of the image is the northern edge, the map frame's origin is the south-west corner.
//! - Each pixel takes the class whose table colour is nearest (Euclidean RGB distance); colours
//!   farther than `--colour-tolerance` from every class are still snapped to the nearest class,
//!   and their share (and the most common such colours) is reported: anti-aliased edges are
//!   common, a wrong class table shows as a large share.
//! - Elevation comes from the classes: each class's `height_m` in the table, else the world
//!   loader's default height for its name (building 12 m, vehicle 1.5 m, grass_sidewalk 0.15 m, …),
//!   so a sidewalk next to a road is a curb step, as in generated cities.
//! - Curb cuts: a class map shows no ramps or driveways, yet a real site has them wherever
//!   people and vehicles cross a curb. Every curb (a step of at most [`CURB_MAX_M`] between two
//!   passable classes) gets a ramp every `--ramp-spacing-m` metres along it (default
//!   [`DEFAULT_RAMP_SPACING_M`]; at least one on every stretch of curb, 0 for none): the raised
//!   side slopes down to the lower ground over [`RAMP_RUN_M`], as the generated cities' ramps do,
//!   and the class (and the colour the robots see) stays. Between ramps the curb stands.
//! - The colour layer is the class colours (anti-aliasing removed).
//! - Vehicle clusters (scoring ground truth) are what the goal detector finds with its default
//!   settings in the whole map, when the table has a `vehicle` class.
//! - Start poses: cells of the easiest class at least [`START_CLEARANCE_M`] from any cell of
//!   another class, nearest to `--start-near` (default: the south-west corner), at least
//!   [`START_SPACING_M`] apart, facing the world's centre, each one a pose the simulator's UGV can
//!   stand on.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};
use serde_json::json;
use spomp_behaviors::mission::limits::{MAX_SOURCE_BYTES, read_regular, read_text};
use spomp_behaviors::mission::yaml;
use spomp_core::{AerialMap, ClassId, ClassInfo, ClassTable, GridSpec, Point2, Pose2};
use spomp_world::{DerivedElevationParams, UgvLimits, World, WorldMeta};

/// The largest raster file read, bytes.
pub const MAX_RASTER_BYTES: u64 = 64 << 20;

/// The most pixels a raster may have: one cell per pixel, and a world has at most this many.
pub const MAX_RASTER_PIXELS: u64 = 16_000_000;

/// A raster spanning more than this (its longer side) is questioned, metres.
pub const MAX_PLAUSIBLE_SPAN_M: f64 = 5_000.0;

/// A raster spanning less than this (its longer side) is questioned, metres.
pub const MIN_PLAUSIBLE_SPAN_M: f64 = 5.0;

/// A start pose is at least this far from any cell not of its class, metres.
pub const START_CLEARANCE_M: f64 = 2.0;

/// Start poses are at least this far apart, metres.
pub const START_SPACING_M: f64 = 4.0;

/// Default colour tolerance: Euclidean distance in RGB (0–441).
pub const DEFAULT_COLOUR_TOLERANCE: f64 = 30.0;

/// WGS-84 equatorial radius, metres (the equirectangular approximation QGC plans use too).
const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// The class-table formats `--classes` accepts, shown when a table does not parse.
pub const CLASS_TABLE_FORMAT: &str = "\
either spomp's table:
classes:
  - { index: 0, name: road,     rank: 0, color: [128, 64, 128] }
  - { index: 2, name: building, rank: 5, color: [70, 70, 70], height_m: 10 }
  # index: label value 0-254, unique; name: unique; rank: 0 easiest … 5 impassable;
  # color: the class's [R, G, B] in the raster; optional height_m (metres above the road,
  # default by name: building 12, vehicle 1.5, grass_sidewalk 0.15, vegetation 1,
  # tree_trunk 5, light_pole 6, others 0) and ignored (true for classes such as people)
or a list of names with colours (YAML or JSON), as mapping pipelines write it:
- { name: road, color: [128, 64, 128] }
- { name: grass/sidewalk, color: \"#98fb98\" }
  # colour as [R, G, B] or \"#RRGGBB\" (key color, colour or rgb); label value = position in
  # the list unless the entry gives index (or id); rank, height_m and ignored as the spomp
  # table's class of the same name (spellings differ: grass/sidewalk is grass_sidewalk), rank 5
  # (impassable) for names it lacks, unless the entry gives them";

/// Name of the class a transparent pixel (alpha 0) becomes: the raster says nothing there.
pub const NO_DATA_CLASS: &str = "no_data";

/// Height of no-data cells, metres: a wall the simulated UGV cannot climb and its range sensor
/// sees, as a fence at the edge of the surveyed area would be. Their class is impassable (rank
/// 5), so planners never route through them and no robot starts there.
pub const NO_DATA_HEIGHT_M: f32 = 3.0;

/// The highest step between two passable classes that is taken for a curb (and gets curb cuts);
/// higher steps (bushes, parked cars, walls) are not ramped, metres.
pub const CURB_MAX_M: f32 = 0.3;

/// Curb cuts are about this far apart along a curb by default, metres: a campus has a ramp or
/// a driveway at every crossing, path, lot entrance and parking aisle. (On the yard site, 20 m
/// left the gravel yard's curbs, 50 m long, with two or three cuts each, and 3 of 60 clusters
/// unvisited in 900 s.)
pub const DEFAULT_RAMP_SPACING_M: f64 = 10.0;

/// A curb cut slopes from the lower ground up to the curb's height over this run, metres
/// (0.15 m over 1.5 m: a 10 % ramp, within what the simulated UGV climbs).
pub const RAMP_RUN_M: f64 = 1.5;

/// Half the width of a curb cut along the curb at the kerb line, metres (a 6 m wide cut, its
/// sides flared: the cut narrows to about 5 m at the top).
pub const RAMP_HALF_WIDTH_M: f64 = 3.0;

/// A car seen from above is about this wide, metres (and 4.5 m long).
pub const CAR_WIDTH_M: f64 = 2.0;

/// The typical width of the vehicle blobs must lie in this range, metres, or the scale is
/// questioned: a single car is about 2 m wide, a row of cars parked side by side about 5 m.
pub const PLAUSIBLE_VEHICLE_WIDTH_M: (f64, f64) = (1.0, 6.0);

/// The pixel scale of the raster.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Scale {
    /// Metres per pixel.
    MetresPerPixel(f64),
    /// Pixels per metre.
    PixelsPerMetre(f64),
}

impl Scale {
    fn metres_per_pixel(self) -> f64 {
        match self {
            Scale::MetresPerPixel(m) => m,
            Scale::PixelsPerMetre(p) => 1.0 / p,
        }
    }
}

/// Options of `spomp world import`.
#[derive(Clone, Debug)]
pub struct ImportArgs {
    /// The colour-coded class raster (PNG).
    pub raster: PathBuf,
    /// The class table (YAML, [`CLASS_TABLE_FORMAT`]).
    pub classes: PathBuf,
    /// Pixel size.
    pub scale: Scale,
    /// Cell size of the world, metres; `None`: one cell per pixel.
    pub cell_m: Option<f64>,
    /// WGS-84 latitude and longitude of the raster's north-west (top-left) corner, degrees.
    pub gps_reference: Option<(f64, f64)>,
    /// Largest RGB distance counted as a match.
    pub colour_tolerance: f64,
    /// Start poses are placed nearest this map-frame point (default: the south-west corner).
    pub start_near: Option<Point2>,
    /// How many start poses to place.
    pub starts: usize,
    /// The class whose clusters are the world's vehicle clusters.
    pub vehicle_class: String,
    /// Curb cuts are this far apart along each curb, metres (0: none, curbs everywhere).
    pub ramp_spacing_m: f64,
    /// Import even when the resolution looks implausible or most colours match no class.
    pub force: bool,
    /// Output world folder.
    pub out: PathBuf,
    /// Print JSON.
    pub json: bool,
}

/// One row of the import class table: the core class row plus a height.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ImportClass {
    index: ClassId,
    name: String,
    rank: u8,
    color: [u8; 3],
    #[serde(default)]
    ignored: bool,
    #[serde(default)]
    height_m: Option<f32>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ImportTable {
    classes: Vec<ImportClass>,
}

/// An entry of a class list as mapping pipelines write it: a name and a colour, the rest
/// optional (fields other pipelines add, such as a training id, are ignored).
#[derive(Clone, Debug, Deserialize)]
struct ListedClass {
    name: String,
    #[serde(alias = "colour", alias = "rgb")]
    color: ListedColour,
    #[serde(default, alias = "id")]
    index: Option<ClassId>,
    #[serde(default)]
    rank: Option<u8>,
    #[serde(default)]
    height_m: Option<f32>,
    #[serde(default)]
    ignored: Option<bool>,
}

/// A colour as `[R, G, B]` or `"#RRGGBB"`.
#[derive(Clone, Debug, Deserialize)]
#[serde(untagged)]
enum ListedColour {
    Rgb([u8; 3]),
    Hex(String),
}

impl ListedColour {
    fn rgb(&self) -> Result<[u8; 3], String> {
        match self {
            ListedColour::Rgb(c) => Ok(*c),
            ListedColour::Hex(text) => {
                let hex = text.trim().trim_start_matches('#');
                let byte = |k: usize| hex.get(k..k + 2).and_then(|h| u8::from_str_radix(h, 16).ok());
                match (hex.len(), byte(0), byte(2), byte(4)) {
                    (6, Some(r), Some(g), Some(b)) => Ok([r, g, b]),
                    _ => Err(format!("colour `{text}` is neither [R, G, B] nor \"#RRGGBB\"")),
                }
            }
        }
    }
}

/// A class table for import: the classes and each one's height, metres.
#[derive(Clone, Debug)]
pub struct ImportClasses {
    /// The table the world will carry.
    pub table: ClassTable,
    /// Height of each class index, metres.
    pub heights_m: [f32; 256],
    /// What the reader had to assume (ranks of names the built-in table lacks), for the user.
    pub notes: Vec<String>,
}

fn table_error(path: &Path, line: u32, column: u32, message: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{}:{line}:{column}: the class table does not parse: {message}\nexpected format:\n{CLASS_TABLE_FORMAT}",
        path.display()
    )
}

/// Reads an import class table: a regular YAML file of at most the mission language's size
/// limit. Errors name the file, line and column and show the expected format.
pub fn read_classes(path: &Path) -> Result<ImportClasses> {
    let text = read_text(path, MAX_SOURCE_BYTES).map_err(|e| anyhow::anyhow!("class table: {e}"))?;
    parse_classes(path, &text)
}

/// Parses the text of an import class table (`path` names it in errors): spomp's table, or a
/// list of names with colours ([`CLASS_TABLE_FORMAT`]).
pub fn parse_classes(path: &Path, text: &str) -> Result<ImportClasses> {
    let root = yaml::parse(text).map_err(|e| table_error(path, e.loc.line, e.loc.column, &e.message))?;
    if root.as_seq().is_some() {
        return parse_listed(path, &root);
    }
    // A file that is not a class table at all (a password file, a key, an `.env`) is said to be
    // so without quoting any of it.
    if root.get("classes").is_none() {
        let found = match root.as_map() {
            Some(_) => "a mapping without a `classes` key".to_string(),
            None => root.value.kind().to_string(),
        };
        return Err(table_error(
            path,
            root.loc.line,
            root.loc.column,
            &format!(
                "this is not a class table: expected a mapping with a `classes` list or a list of names with \
                 colours, found {found}"
            ),
        ));
    }
    let parsed: ImportTable = root.deserialize().map_err(|e| {
        let field = e.path_string();
        let loc = e.loc.unwrap_or(root.loc);
        let message = if field.is_empty() { e.message.clone() } else { format!("{field}: {}", e.message) };
        table_error(path, loc.line, loc.column, &message)
    })?;
    let defaults = DerivedElevationParams::default();
    let mut heights_m = [0.0f32; 256];
    for (i, c) in parsed.classes.iter().enumerate() {
        let h = c.height_m.unwrap_or_else(|| defaults.height_of(&c.name));
        if !(h.is_finite() && (-100.0..=1000.0).contains(&h)) {
            let loc = class_loc(&root, i);
            return Err(table_error(
                path,
                loc.line,
                loc.column,
                &format!("classes[{i}].height_m must be between -100 and 1000 metres, got {h}"),
            ));
        }
        heights_m[c.index as usize] = h;
    }
    let table = ClassTable {
        classes: parsed
            .classes
            .iter()
            .map(|c| ClassInfo {
                index: c.index,
                name: c.name.clone(),
                rank: c.rank,
                color: c.color,
                ignored: c.ignored,
            })
            .collect(),
    };
    finish_table(path, &root, table, heights_m, Vec::new())
}

/// A list of names with colours: label values by position (or the entry's `index`), ranks,
/// heights and `ignored` from the built-in class of the same name.
fn parse_listed(path: &Path, root: &yaml::Node) -> Result<ImportClasses> {
    let entries = root.as_seq().unwrap_or_default();
    let builtin = ClassTable::default_table();
    let defaults = DerivedElevationParams::default();
    let mut heights_m = [0.0f32; 256];
    let mut classes = Vec::with_capacity(entries.len());
    let mut unranked = Vec::new();
    for (i, node) in entries.iter().enumerate() {
        let fail = |message: String| table_error(path, node.loc.line, node.loc.column, &format!("[{i}]: {message}"));
        if node.as_map().is_none() {
            return Err(fail(format!("expected an entry with a `name` and a `color`, found {}", node.value.kind())));
        }
        let entry: ListedClass = node.deserialize().map_err(|e| {
            let field = e.path_string();
            fail(if field.is_empty() { e.message.clone() } else { format!("{field}: {}", e.message) })
        })?;
        let color = entry.color.rgb().map_err(&fail)?;
        let index = match entry.index {
            Some(k) => k,
            None => ClassId::try_from(i).map_err(|_| fail("more than 255 classes".into()))?,
        };
        let known = builtin.by_name(&entry.name);
        let rank = match (entry.rank, known) {
            (Some(r), _) => r,
            (None, Some(k)) => k.rank,
            (None, None) => {
                unranked.push(entry.name.clone());
                spomp_core::classes::IMPASSABLE_RANK
            }
        };
        let h = entry.height_m.unwrap_or_else(|| defaults.height_of(&entry.name));
        if !(h.is_finite() && (-100.0..=1000.0).contains(&h)) {
            return Err(fail(format!("height_m must be between -100 and 1000 metres, got {h}")));
        }
        heights_m[index as usize] = h;
        let ignored = entry.ignored.unwrap_or(known.is_some_and(|k| k.ignored));
        classes.push(ClassInfo { index, name: entry.name, rank, color, ignored });
    }
    let mut notes = Vec::new();
    if !unranked.is_empty() {
        notes.push(format!(
            "classes {unranked:?} are not among spomp's classes ({}), so they are taken as impassable (rank 5); give \
             an entry `rank: 0…5` to change that",
            builtin.names().join(", ")
        ));
    }
    finish_table(path, root, ClassTable { classes }, heights_m, notes)
}

/// The checks both formats share: duplicates (located at the entry that repeats an earlier
/// one), an empty table, and the core table's rules.
fn finish_table(
    path: &Path,
    root: &yaml::Node,
    table: ClassTable,
    heights_m: [f32; 256],
    notes: Vec<String>,
) -> Result<ImportClasses> {
    let listed = root.as_seq().is_some();
    let entry_loc = |i: usize| {
        if listed { root.as_seq().and_then(|s| s.get(i)).map_or(root.loc, |n| n.loc) } else { class_loc(root, i) }
    };
    let entry_name = |i: usize| if listed { format!("[{i}]") } else { format!("classes[{i}]") };
    // Duplicates located at the entry that repeats an earlier one (the core check below would
    // only name the value).
    for (i, c) in table.classes.iter().enumerate() {
        let earlier = &table.classes[..i];
        let what = if earlier.iter().any(|e| e.index == c.index) {
            Some(format!("{}: index {} is used twice", entry_name(i), c.index))
        } else if earlier.iter().any(|e| e.name == c.name) {
            Some(format!("{}: name `{}` is used twice", entry_name(i), c.name))
        } else if earlier.iter().any(|e| e.color == c.color) {
            Some(format!(
                "{}: colour {:?} is used twice (a pixel could not tell the classes apart)",
                entry_name(i),
                c.color
            ))
        } else if c.name == NO_DATA_CLASS {
            Some(format!(
                "{}: the name `{NO_DATA_CLASS}` is reserved for the raster's transparent pixels",
                entry_name(i)
            ))
        } else {
            None
        };
        if let Some(message) = what {
            let loc = entry_loc(i);
            return Err(table_error(path, loc.line, loc.column, &message));
        }
    }
    if table.classes.is_empty() {
        return Err(table_error(path, root.loc.line, root.loc.column, "the table is empty; list at least one class"));
    }
    // The core parser owns the table's rules (unique indices and names, ranks, reserved index).
    let text = serde_saphyr::to_string(&table).context("serialising the class table")?;
    if let Err(e) = ClassTable::from_yaml(&text) {
        let loc = root.get("classes").map_or(root.loc, |n| n.loc);
        return Err(table_error(path, loc.line, loc.column, &e.to_string()));
    }
    Ok(ImportClasses { table, heights_m, notes })
}

fn class_loc(root: &yaml::Node, i: usize) -> yaml::Loc {
    root.get("classes").and_then(|c| c.as_seq()).and_then(|s| s.get(i)).map_or(root.loc, |n| n.loc)
}

/// Decodes a PNG raster within the limits: a regular file of at most [`MAX_RASTER_BYTES`], at
/// most [`MAX_RASTER_PIXELS`] pixels (checked from the header before decoding). Alpha is kept
/// (opaque when the image has none): transparent pixels are no data.
pub fn read_raster(path: &Path) -> Result<image::RgbaImage> {
    let bytes = read_regular(path, MAX_RASTER_BYTES).map_err(|e| anyhow::anyhow!("raster: {e}"))?;
    let reader = || {
        image::ImageReader::new(std::io::Cursor::new(&bytes[..]))
            .with_guessed_format()
            .with_context(|| format!("reading {}", path.display()))
    };
    let (w, h) = reader()?.into_dimensions().with_context(|| format!("{}: not a readable image", path.display()))?;
    let pixels = u64::from(w) * u64::from(h);
    if pixels == 0 || pixels > MAX_RASTER_PIXELS {
        bail!("{}: the raster is {w} × {h} pixels; between 1 and {MAX_RASTER_PIXELS} are allowed", path.display());
    }
    let mut reader = reader()?;
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(w);
    limits.max_image_height = Some(h);
    limits.max_alloc = Some(pixels * 16 + (64 << 20));
    reader.limits(limits);
    let img = reader.decode().with_context(|| format!("{}: not a readable image", path.display()))?;
    Ok(img.to_rgba8())
}

/// How the raster's colours matched the classes.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ColourMatch {
    /// Pixels whose colour is a class colour.
    pub exact: u64,
    /// Pixels within the tolerance of a class colour.
    pub near: u64,
    /// Pixels farther than the tolerance from every class colour, given the class around them.
    pub snapped: u64,
    /// Transparent pixels (alpha 0): no data.
    pub no_data: u64,
    /// The most common snapped colours: `[r, g, b]`, pixels, the class they went to.
    pub top_snapped: Vec<([u8; 3], u64, String)>,
}

impl ColourMatch {
    /// Share of the opaque pixels snapped, 0–1.
    pub fn snapped_share(&self) -> f64 {
        self.snapped as f64 / (self.exact + self.near + self.snapped).max(1) as f64
    }
}

/// The no-data class a table gains for a raster with transparent pixels: the highest free
/// index below the reserved unknown index, impassable, and a colour no class uses (black when
/// free) so the world's class layer can still be written as colours.
pub fn no_data_class(table: &ClassTable) -> Option<ClassInfo> {
    let index = (0..spomp_core::classes::UNKNOWN_CLASS).rev().find(|&k| table.get(k).is_none())?;
    let used = |c: [u8; 3]| table.classes.iter().any(|k| k.color == c);
    let color = (0u32..1 << 24).map(|v| [(v >> 16) as u8, (v >> 8) as u8, v as u8]).find(|&c| !used(c))?;
    Some(ClassInfo {
        index,
        name: NO_DATA_CLASS.to_string(),
        rank: spomp_core::classes::IMPASSABLE_RANK,
        color,
        ignored: false,
    })
}

/// The class of every pixel (row-major, image rows top-down) and how the colours matched.
///
/// A transparent pixel (alpha 0) is `no_data` (its colour is meaningless and never matched).
/// An opaque colour within `tolerance` of a class colour takes that class (the nearest one). A
/// colour farther from every class (an anti-aliased edge, a text label, a scale bar) takes the
/// class around it: each pass gives every such pixel that touches classified pixels (3 × 3)
/// their most common class, until none is left; so an edge goes to the majority across it and
/// a label to what it was printed on (no data on a transparent margin), never to the class
/// whose colour happens to be nearest white. Only a raster with no matched pixel at all falls
/// back to the nearest colour.
pub fn classify(
    img: &image::RgbaImage,
    table: &ClassTable,
    no_data: Option<ClassId>,
    tolerance: f64,
) -> (Vec<ClassId>, ColourMatch) {
    let colours: Vec<([u8; 3], ClassId)> =
        table.classes.iter().filter(|c| Some(c.index) != no_data).map(|c| (c.color, c.index)).collect();
    let nearest = |rgb: [u8; 3]| -> (ClassId, f64) {
        let d2 = |c: [u8; 3]| (0..3).map(|k| (f64::from(c[k]) - f64::from(rgb[k])).powi(2)).sum::<f64>();
        colours
            .iter()
            .map(|&(c, idx)| (idx, d2(c)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or((0, f64::INFINITY), |(idx, d)| (idx, d.sqrt()))
    };
    let (w, h) = (img.width() as usize, img.height() as usize);
    let mut memo: HashMap<[u8; 3], (ClassId, f64)> = HashMap::new();
    let mut report = ColourMatch::default();
    let mut classes = Vec::with_capacity(w * h);
    let mut matched = Vec::with_capacity(w * h);
    for px in img.pixels() {
        let [r, g, b, alpha] = px.0;
        if alpha == 0
            && let Some(nd) = no_data
        {
            report.no_data += 1;
            classes.push(nd);
            matched.push(true);
            continue;
        }
        let (class, distance) = *memo.entry([r, g, b]).or_insert_with(|| nearest([r, g, b]));
        if distance == 0.0 {
            report.exact += 1;
        } else if distance <= tolerance {
            report.near += 1;
        } else {
            report.snapped += 1;
        }
        classes.push(class);
        matched.push(distance <= tolerance);
    }
    let mut pending: Vec<usize> = (0..w * h).filter(|&i| !matched[i]).collect();
    let mut votes = [0u32; 256];
    // Pixels given a class in one pass vote only in the next, so the result does not depend on
    // the scan order.
    while !pending.is_empty() {
        let mut assigned = Vec::new();
        let mut still = Vec::new();
        for &i in &pending {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            votes.fill(0);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                        let j = ny as usize * w + nx as usize;
                        if matched[j] {
                            votes[classes[j] as usize] += 1;
                        }
                    }
                }
            }
            // The most votes; ties to the lower index.
            match (0..256).max_by_key(|&c| (votes[c], std::cmp::Reverse(c))).filter(|&c| votes[c] > 0) {
                Some(c) => assigned.push((i, c as ClassId)),
                None => still.push(i),
            }
        }
        if assigned.is_empty() {
            break; // nothing matched anywhere: the nearest colours stand
        }
        for (i, c) in assigned {
            classes[i] = c;
            matched[i] = true;
        }
        pending = still;
    }
    let mut snapped_to: HashMap<([u8; 3], ClassId), u64> = HashMap::new();
    for (i, px) in img.pixels().enumerate() {
        let [r, g, b, alpha] = px.0;
        let opaque_or_kept = alpha != 0 || no_data.is_none();
        if opaque_or_kept && memo.get(&[r, g, b]).is_some_and(|&(_, d)| d > tolerance) {
            *snapped_to.entry(([r, g, b], classes[i])).or_insert(0) += 1;
        }
    }
    // Per snapped colour: its pixel count and the class most of them went to.
    let mut per_colour: HashMap<[u8; 3], (u64, ClassId, u64)> = HashMap::new();
    for ((rgb, class), n) in snapped_to {
        let e = per_colour.entry(rgb).or_insert((0, class, 0));
        e.0 += n;
        if n > e.2 || (n == e.2 && class < e.1) {
            (e.1, e.2) = (class, n);
        }
    }
    let mut top: Vec<([u8; 3], u64, ClassId)> = per_colour.into_iter().map(|(rgb, (n, c, _))| (rgb, n, c)).collect();
    top.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    report.top_snapped = top
        .into_iter()
        .take(5)
        .map(|(rgb, n, c)| (rgb, n, table.get(c).map_or("?", |c| c.name.as_str()).to_string()))
        .collect();
    (classes, report)
}

/// Checks a pixel size and the span it gives the raster; an implausible span is an error
/// unless `force`.
pub fn check_scale(scale: Scale, width: u32, height: u32, force: bool) -> Result<f64> {
    let res = scale.metres_per_pixel();
    let (lo, hi) = spomp_world::RESOLUTION_RANGE_M;
    if !(res.is_finite() && (lo..=hi).contains(&res)) {
        bail!("a pixel must be between {lo} and {hi} m; got {res} m per pixel");
    }
    let (w_m, h_m) = (f64::from(width) * res, f64::from(height) * res);
    let span = w_m.max(h_m);
    if !force && !(MIN_PLAUSIBLE_SPAN_M..=MAX_PLAUSIBLE_SPAN_M).contains(&span) {
        bail!(
            "at {res} m per pixel the {width} × {height} raster would span {w_m:.1} m × {h_m:.1} m; a robot mission's \
             aerial map spans between {MIN_PLAUSIBLE_SPAN_M} m and {:.0} km. Check --resolution-m / --pixels-per-m \
             (metres per pixel vs pixels per metre?), or pass --force to import it anyway",
            MAX_PLAUSIBLE_SPAN_M / 1000.0
        );
    }
    Ok(res)
}

/// Distance of every cell to the nearest cell for which `blocked` is true, metres (chamfer
/// distance with 1 and √2 steps: within 8 % of Euclidean, enough to keep starts clear).
fn clearance_m(spec: &GridSpec, blocked: impl Fn(usize) -> bool) -> Vec<f32> {
    let (w, h) = (spec.width as usize, spec.height as usize);
    let res = spec.resolution_m as f32;
    let diag = res * std::f32::consts::SQRT_2;
    let mut d: Vec<f32> = (0..w * h).map(|i| if blocked(i) { 0.0 } else { f32::INFINITY }).collect();
    let relax = |d: &mut Vec<f32>, i: usize, c: i64, r: i64, step: f32| {
        if c >= 0 && r >= 0 && (c as usize) < w && (r as usize) < h {
            let v = d[r as usize * w + c as usize] + step;
            if v < d[i] {
                d[i] = v;
            }
        }
    };
    for r in 0..h as i64 {
        for c in 0..w as i64 {
            let i = r as usize * w + c as usize;
            relax(&mut d, i, c - 1, r, res);
            relax(&mut d, i, c, r - 1, res);
            relax(&mut d, i, c - 1, r - 1, diag);
            relax(&mut d, i, c + 1, r - 1, diag);
        }
    }
    for r in (0..h as i64).rev() {
        for c in (0..w as i64).rev() {
            let i = r as usize * w + c as usize;
            relax(&mut d, i, c + 1, r, res);
            relax(&mut d, i, c, r + 1, res);
            relax(&mut d, i, c + 1, r + 1, diag);
            relax(&mut d, i, c - 1, r + 1, diag);
        }
    }
    d
}

/// Start poses for a team in `world`: see the module documentation. Fewer than `count` when the
/// world has too little clear easy ground.
pub fn start_poses(world: &World, near: Point2, count: usize) -> Vec<Pose2> {
    let spec = *world.spec();
    let classes = world.classes();
    let map = world.map();
    let present: Vec<ClassId> = classes.easiest_first().into_iter().filter(|&c| map.class.contains(&c)).collect();
    let Some(&easiest) = present.first() else { return Vec::new() };
    if classes.rank(easiest) >= spomp_core::classes::IMPASSABLE_RANK {
        return Vec::new();
    }
    let clear = clearance_m(&spec, |i| map.class[i] != easiest);
    let (w_m, h_m) = spec.size_m();
    let inside = |p: Point2| {
        let (dx, dy) = (p.x - spec.origin.x, p.y - spec.origin.y);
        dx.min(w_m - dx).min(dy).min(h_m - dy) >= START_CLEARANCE_M
    };
    let mut candidates: Vec<(f64, usize)> = (0..spec.len())
        // Cell centre to cell centre, less half a cell: the distance to the other class's edge.
        .filter(|&i| {
            f64::from(clear[i]) - spec.resolution_m / 2.0 >= START_CLEARANCE_M
                && inside(spec.center(spec.cell_of_index(i)))
        })
        .map(|i| (spec.center(spec.cell_of_index(i)).distance(near), i))
        .collect();
    candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let centre = Point2::new(spec.origin.x + w_m / 2.0, spec.origin.y + h_m / 2.0);
    let mut out: Vec<Pose2> = Vec::new();
    for (_, i) in candidates {
        if out.len() >= count {
            break;
        }
        let p = spec.center(spec.cell_of_index(i));
        if out.iter().any(|s| s.position().distance(p) < START_SPACING_M) {
            continue;
        }
        let to_centre = centre - p;
        let yaw = if to_centre.norm() > 1e-9 { to_centre.y.atan2(to_centre.x) } else { 0.0 };
        // Round to centimetres and centiradians so the poses read well in a mission file.
        let pose =
            Pose2::new((p.x * 100.0).round() / 100.0, (p.y * 100.0).round() / 100.0, (yaw * 100.0).round() / 100.0);
        if UgvLimits::default().stand_at(world, pose.position()).is_ok() {
            out.push(pose);
        }
    }
    out
}

/// A class grid, row-major, rows top-down (as the image).
struct ClassGrid {
    width: u32,
    height: u32,
    class: Vec<ClassId>,
}

/// The pixel classes on a grid of `cell_m` cells over the same extent: each cell takes the most
/// common class of the pixels whose centres fall in it (ties to the easier rank, then the lower
/// index: a road pixel is not lost to an equal count of building), or of the pixel under its
/// centre when it is smaller than a pixel. Errors when the grid would exceed the world's cells.
fn resample(
    pixels: &[ClassId],
    width: u32,
    height: u32,
    pixel_m: f64,
    cell_m: f64,
    table: &ClassTable,
) -> Result<ClassGrid> {
    if (cell_m - pixel_m).abs() <= 1e-9 * pixel_m {
        return Ok(ClassGrid { width, height, class: pixels.to_vec() });
    }
    let cols = ((f64::from(width) * pixel_m / cell_m).round() as u64).max(1);
    let rows = ((f64::from(height) * pixel_m / cell_m).round() as u64).max(1);
    if cols * rows > spomp_world::MAX_WORLD_CELLS {
        bail!(
            "at --cell-m {cell_m} the world would be {cols} × {rows} cells; at most {} are allowed",
            spomp_world::MAX_WORLD_CELLS
        );
    }
    let (cols, rows) = (cols as u32, rows as u32);
    let rank = table.rank_lut();
    // The pixel span of a cell along one axis: the pixels whose centres lie in the cell, or the
    // pixel under the cell's centre.
    let span = |k: u32, n_px: u32| -> (u32, u32) {
        let (a, b) = (f64::from(k) * cell_m / pixel_m, f64::from(k + 1) * cell_m / pixel_m);
        let first = (a - 0.5).ceil().max(0.0) as u32;
        let last = ((b - 0.5).ceil().max(0.0) as u32).min(n_px);
        if first < last {
            (first, last)
        } else {
            let centre = (((a + b) / 2.0).floor() as u32).min(n_px - 1);
            (centre, centre + 1)
        }
    };
    let mut class = Vec::with_capacity(cols as usize * rows as usize);
    let mut votes = [0u32; 256];
    for r in 0..rows {
        let (y0, y1) = span(r, height);
        for c in 0..cols {
            let (x0, x1) = span(c, width);
            votes.fill(0);
            for y in y0..y1 {
                for x in x0..x1 {
                    votes[pixels[y as usize * width as usize + x as usize] as usize] += 1;
                }
            }
            let best = (0..256usize)
                .filter(|&k| votes[k] > 0)
                .max_by_key(|&k| (votes[k], std::cmp::Reverse(rank[k]), std::cmp::Reverse(k)))
                .unwrap_or(0);
            class.push(best as ClassId);
        }
    }
    Ok(ClassGrid { width: cols, height: rows, class })
}

/// The typical width of the vehicle blobs (8-connected pixels of class `vehicle`) of a pixel
/// class grid, metres: per blob of at least two pixels, the diameter of the widest disc inside
/// it (from the distance of its pixels to the nearest other pixel), and the median over blobs.
/// A car is about [`CAR_WIDTH_M`] wide whatever the cluster it is parked in, so this measures
/// the pixel scale; `None` without vehicle blobs.
pub fn vehicle_width_m(pixels: &[ClassId], width: u32, height: u32, vehicle: ClassId, pixel_m: f64) -> Option<f64> {
    let (w, h) = (width as usize, height as usize);
    let spec = GridSpec::new(Point2::new(0.0, 0.0), pixel_m, width, height);
    let inside = clearance_m(&spec, |i| pixels[i] != vehicle);
    let mut seen = vec![false; w * h];
    let mut widths = Vec::new();
    let mut stack = Vec::new();
    for start in 0..w * h {
        if pixels[start] != vehicle || seen[start] {
            continue;
        }
        seen[start] = true;
        stack.push(start);
        let (mut count, mut deepest) = (0usize, 0.0f32);
        while let Some(i) = stack.pop() {
            count += 1;
            deepest = deepest.max(inside[i]);
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                        let j = ny as usize * w + nx as usize;
                        if pixels[j] == vehicle && !seen[j] {
                            seen[j] = true;
                            stack.push(j);
                        }
                    }
                }
            }
        }
        if count >= 2 {
            // Centre-to-centre distances: a blob n pixels across has its deepest pixel n / 2
            // (n even) or (n + 1) / 2 (n odd) pixels from the outside; half a pixel off either way.
            widths.push((2.0 * f64::from(deepest) - 0.5 * pixel_m).max(pixel_m));
        }
    }
    if widths.is_empty() {
        return None;
    }
    widths.sort_by(f64::total_cmp);
    Some(widths[widths.len() / 2])
}

/// Refuses a pixel scale at which vehicles come out of implausible size, unless `force`; the
/// error names the measured width and the resolution that would make it a car's.
pub fn check_vehicle_width(measured_m: f64, pixel_m: f64, force: bool) -> Result<()> {
    let (lo, hi) = PLAUSIBLE_VEHICLE_WIDTH_M;
    if force || (lo..=hi).contains(&measured_m) {
        return Ok(());
    }
    let likely = pixel_m * CAR_WIDTH_M / measured_m;
    bail!(
        "at {pixel_m} m per pixel the raster's vehicles are {measured_m:.1} m wide (the median over its vehicle \
         blobs); cars are about {CAR_WIDTH_M} m × 4.5 m, so the scale is probably wrong: the likely resolution is \
         about --resolution-m {likely:.3} (--pixels-per-m {:.2}). Check the map's scale, or pass --force to import it \
         as given",
        1.0 / likely
    )
}

/// Vehicle-cluster centres as the goal detector sees them with its defaults in the whole map;
/// none when the table has no class `vehicle_class`.
fn vehicle_clusters(map: &AerialMap, table: &ClassTable, vehicle_class: &str) -> Vec<Point2> {
    let params = spomp_mapping::GoalDetectionParams { class: vehicle_class.to_string(), ..Default::default() };
    if table.by_name(&params.class).is_none() {
        return Vec::new();
    }
    match spomp_mapping::GoalDetector::new(params, table).and_then(|mut d| d.detect(map, &[])) {
        Ok(found) => found.goals.iter().map(|g| g.cluster_centroid).collect(),
        Err(_) => Vec::new(),
    }
}

/// Where a world was imported from: written beside `world.yaml` as `import.yaml`.
#[derive(Clone, Debug, Serialize)]
pub struct ImportRecord {
    /// The raster file.
    pub raster: PathBuf,
    /// The class table file.
    pub classes: PathBuf,
    /// Metres per raster pixel.
    pub pixel_m: f64,
    /// Metres per world cell.
    pub resolution_m: f64,
    /// Size in metres (east–west, north–south).
    pub size_m: [f64; 2],
    /// WGS-84 position of the raster's north-west corner, `[lat, lon]` degrees, as given.
    pub gps_reference_north_west: Option<[f64; 2]>,
    /// WGS-84 position of the map frame's origin (the south-west corner), `[lat, lon]`: the
    /// `gps_origin` of a robot's `ros2:` settings and the planned home of a QGC plan drawn on
    /// this world.
    pub gps_origin: Option<[f64; 2]>,
    /// Colour tolerance used.
    pub colour_tolerance: f64,
    /// How the colours matched.
    pub colours: ColourMatch,
    /// The typical width of the raster's vehicle blobs, metres (see [`vehicle_width_m`]).
    pub vehicle_width_m: Option<f64>,
    /// Spacing of the curb cuts, metres (0: none).
    pub ramp_spacing_m: f64,
    /// Curb cuts made.
    pub curb_cuts: usize,
    /// What the class-table reader assumed.
    pub notes: Vec<String>,
}

/// Imports a raster into a [`World`] (not yet written).
pub fn import_world(a: &ImportArgs) -> Result<(World, ImportRecord)> {
    if !(a.colour_tolerance.is_finite() && a.colour_tolerance >= 0.0) {
        bail!("--colour-tolerance must be a non-negative RGB distance, got {}", a.colour_tolerance);
    }
    let mut classes = read_classes(&a.classes)?;
    let img = read_raster(&a.raster)?;
    let (width, height) = img.dimensions();
    let res = check_scale(a.scale, width, height, a.force)?;
    let no_data = if img.pixels().any(|p| p.0[3] == 0) {
        let class = no_data_class(&classes.table).context("the class table leaves no index or colour for no data")?;
        classes.heights_m[class.index as usize] = NO_DATA_HEIGHT_M;
        let index = class.index;
        classes.table.classes.push(class);
        Some(index)
    } else {
        None
    };
    let (pixel_classes, colours) = classify(&img, &classes.table, no_data, a.colour_tolerance);
    let vehicle_width_m = classes
        .table
        .by_name(&a.vehicle_class)
        .and_then(|v| vehicle_width_m(&pixel_classes, width, height, v.index, res));
    if let Some(measured) = vehicle_width_m {
        check_vehicle_width(measured, res, a.force)?;
    }
    let share = colours.snapped_share();
    if share > 0.2 && !a.force {
        bail!(
            "{:.1} % of the raster's pixels are farther than {} from every class colour (most common: {}); is {} the \
             table this raster was drawn with? Raise --colour-tolerance, fix the table, or pass --force",
            share * 100.0,
            a.colour_tolerance,
            describe_top(&colours),
            a.classes.display()
        );
    }

    if !(a.ramp_spacing_m.is_finite() && a.ramp_spacing_m >= 0.0) {
        bail!("--ramp-spacing-m must be a non-negative distance in metres (0: no curb cuts), got {}", a.ramp_spacing_m);
    }
    let cell_m = a.cell_m.unwrap_or(res);
    let (lo, hi) = spomp_world::RESOLUTION_RANGE_M;
    if !(cell_m.is_finite() && (lo..=hi).contains(&cell_m)) {
        bail!("--cell-m must be between {lo} and {hi} m, got {cell_m}");
    }
    let cells = resample(&pixel_classes, width, height, res, cell_m, &classes.table)?;
    let spec = GridSpec::new(Point2::new(0.0, 0.0), cell_m, cells.width, cells.height);
    let mut map = AerialMap::unknown(spec);
    let mut colour_of = [[0u8; 3]; 256];
    for c in &classes.table.classes {
        colour_of[c.index as usize] = c.color;
    }
    let (w, h) = (cells.width as usize, cells.height as usize);
    for (k, &class) in cells.class.iter().enumerate() {
        let (x, y) = (k % w, k / w);
        let i = (h - 1 - y) * w + x;
        map.class[i] = class;
        map.rgb[i] = colour_of[class as usize];
        map.elevation[i] = classes.heights_m[class as usize];
    }
    map.version = 1;
    let curb_cuts = if a.ramp_spacing_m > 0.0 { cut_curbs(&mut map, &classes.table, a.ramp_spacing_m) } else { 0 };
    let clusters = vehicle_clusters(&map, &classes.table, &a.vehicle_class);
    let mut world =
        World::new(map, classes.table.clone(), WorldMeta { vehicle_clusters: clusters, ..WorldMeta::default() })
            .context("building the world")?;
    let near = a.start_near.unwrap_or(spec.origin);
    world.meta.start_poses = start_poses(&world, near, a.starts);

    let (w_m, h_m) = (f64::from(width) * res, f64::from(height) * res);
    let gps_origin = match a.gps_reference {
        Some((lat, lon)) => {
            if !(lat.is_finite() && lat.abs() <= 85.0 && lon.is_finite() && lon.abs() <= 180.0) {
                bail!("--gps-reference must be LAT,LON in degrees (|LAT| ≤ 85, |LON| ≤ 180), got {lat},{lon}");
            }
            Some([lat - (h_m / EARTH_RADIUS_M).to_degrees(), lon])
        }
        None => None,
    };
    world.meta.gps_origin = gps_origin.map(|[lat, lon]| spomp_core::GeoPoint::new(lat, lon));
    let record = ImportRecord {
        raster: a.raster.clone(),
        classes: a.classes.clone(),
        pixel_m: res,
        resolution_m: cell_m,
        size_m: [w_m, h_m],
        gps_reference_north_west: a.gps_reference.map(|(lat, lon)| [lat, lon]),
        gps_origin,
        colour_tolerance: a.colour_tolerance,
        colours,
        vehicle_width_m,
        ramp_spacing_m: a.ramp_spacing_m,
        curb_cuts,
        notes: classes.notes,
    };
    Ok((world, record))
}

/// Makes curb cuts (see the module notes): picks cut centres on the raised side of every curb,
/// [`RAMP_HALF_WIDTH_M`]-wide patches about `spacing_m` apart (scanning the curb cells in order,
/// a cell becomes a centre when no centre is nearer than the spacing, so every stretch of curb
/// gets one), and lowers the raised cells near each centre to a ramp: a cell `d` metres from
/// the lower ground takes the lower ground's height plus `d / RAMP_RUN_M` of the step. Returns
/// how many cuts were made.
fn cut_curbs(map: &mut AerialMap, table: &ClassTable, spacing_m: f64) -> usize {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let spec = map.spec;
    let (w, h) = (spec.width as usize, spec.height as usize);
    let res = spec.resolution_m;
    let mut passable = [false; 256];
    for c in &table.classes {
        passable[c.index as usize] = c.rank < 5 && !c.ignored;
    }
    let ground = |i: usize| passable[map.class[i] as usize];
    let neighbours = |i: usize| {
        let (x, y) = (i % w, i / w);
        [(x > 0).then(|| i - 1), (x + 1 < w).then(|| i + 1), (y > 0).then(|| i - w), (y + 1 < h).then(|| i + w)]
    };
    // Whether `hi` stands a curb above `lo`.
    let curb = |hi: f32, lo: f32| hi - lo > 1e-3 && hi - lo <= CURB_MAX_M;
    // The lower ground at each curb, and how far (metres) each raised cell near one lies from it,
    // with the height of that lower ground: a Dijkstra over raised cells out to the ramp's reach.
    let reach = RAMP_HALF_WIDTH_M + RAMP_RUN_M;
    let mut dist = vec![f64::INFINITY; w * h];
    let mut low = vec![0.0f32; w * h];
    let mut heap = BinaryHeap::new();
    let mut curb_cells = Vec::new();
    for i in 0..w * h {
        if !ground(i) {
            continue;
        }
        let e = map.elevation[i];
        let lower = neighbours(i).into_iter().flatten().filter(|&j| ground(j) && curb(e, map.elevation[j]));
        if let Some(lo) = lower.map(|j| map.elevation[j]).reduce(f32::min) {
            curb_cells.push(i);
            // The raised cell's centre is half a cell from the kerb line.
            let d = 0.5 * res;
            if d < dist[i] {
                dist[i] = d;
                low[i] = lo;
                heap.push(Reverse((Ordered(d), i)));
            }
        }
    }
    while let Some(Reverse((d, i))) = heap.pop() {
        let d = d.0;
        if d > dist[i] {
            continue;
        }
        let (x, y) = ((i % w) as i64, (i / w) as i64);
        for (dx, dy) in [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)] {
            let (nx, ny) = (x + dx, y + dy);
            if nx < 0 || ny < 0 || nx >= w as i64 || ny >= h as i64 {
                continue;
            }
            let j = ny as usize * w + nx as usize;
            // Spread over raised ground of the same curb (a curb's height above its low side).
            if !ground(j) || !curb(map.elevation[j], low[i]) {
                continue;
            }
            let nd = d + if dx != 0 && dy != 0 { res * std::f64::consts::SQRT_2 } else { res };
            if nd < dist[j] && nd <= reach {
                dist[j] = nd;
                low[j] = low[i];
                heap.push(Reverse((Ordered(nd), j)));
            }
        }
    }
    // Cut centres, about `spacing_m` apart: a coarse bucket grid finds the nearby ones.
    let bucket = spacing_m.max(res);
    let mut buckets: HashMap<(i64, i64), Vec<Point2>> = HashMap::new();
    let mut centres = Vec::new();
    for &i in &curb_cells {
        let p = Point2::new((i % w) as f64 * res, (i / w) as f64 * res);
        let (bx, by) = ((p.x / bucket).floor() as i64, (p.y / bucket).floor() as i64);
        let near = (-1..=1).any(|ox| {
            (-1..=1)
                .any(|oy| buckets.get(&(bx + ox, by + oy)).is_some_and(|v| v.iter().any(|q| q.distance(p) < spacing_m)))
        });
        if !near {
            buckets.entry((bx, by)).or_default().push(p);
            centres.push(i);
        }
    }
    // Each cut: the raised cells within its reach of the centre slope down to the lower ground.
    let r_cells = (reach / res).ceil() as i64;
    let original = map.elevation.clone();
    for &c in &centres {
        let (cx, cy) = ((c % w) as i64, (c / w) as i64);
        for y in (cy - r_cells).max(0)..=(cy + r_cells).min(h as i64 - 1) {
            for x in (cx - r_cells).max(0)..=(cx + r_cells).min(w as i64 - 1) {
                let k = y as usize * w + x as usize;
                let along = res * (((x - cx) * (x - cx) + (y - cy) * (y - cy)) as f64).sqrt();
                if !dist[k].is_finite() || along > reach || dist[k] > RAMP_RUN_M {
                    continue;
                }
                let share = ((dist[k] - 0.5 * res) / RAMP_RUN_M).clamp(0.0, 1.0) as f32;
                let ramp = low[k] + (original[k] - low[k]) * share;
                map.elevation[k] = map.elevation[k].min(ramp);
            }
        }
    }
    centres.len()
}

/// An `f64` ordered for the heap (distances: finite, non-negative).
#[derive(Clone, Copy, PartialEq)]
struct Ordered(f64);

impl Eq for Ordered {}

impl PartialOrd for Ordered {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Ordered {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

fn describe_top(c: &ColourMatch) -> String {
    if c.top_snapped.is_empty() {
        return "none".into();
    }
    c.top_snapped
        .iter()
        .map(|(rgb, n, class)| format!("[{}, {}, {}] × {n} → {class}", rgb[0], rgb[1], rgb[2]))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `spomp world import`.
pub fn import(a: &ImportArgs) -> Result<ExitCode> {
    if a.out.exists() && !a.out.is_dir() {
        bail!("--out {}: exists and is not a folder", a.out.display());
    }
    let (world, record) = import_world(a)?;
    world.save(&a.out).with_context(|| format!("writing the world to {}", a.out.display()))?;
    let record_path = a.out.join("import.yaml");
    let text = serde_saphyr::to_string(&record).context("serialising the import record")?;
    crate::output::write(&record_path, text)?;

    let spec = *world.spec();
    let share = record.colours.snapped_share();
    if a.json {
        let v = json!({
            "dir": a.out,
            "width": spec.width,
            "height": spec.height,
            "resolution_m": spec.resolution_m,
            "pixel_m": record.pixel_m,
            "size_m": record.size_m,
            "colours": {
                "exact": record.colours.exact,
                "near": record.colours.near,
                "snapped": record.colours.snapped,
                "snapped_share": share,
                "top_snapped": record.colours.top_snapped,
                "no_data": record.colours.no_data,
            },
            "vehicle_width_m": record.vehicle_width_m,
            "curb_cuts": record.curb_cuts,
            "notes": record.notes,
            "vehicle_clusters": world.meta.vehicle_clusters,
            "start_poses": world.meta.start_poses,
            "gps_origin": record.gps_origin,
        });
        out!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        out!(
            "wrote {} ({} × {} cells at {} m = {:.1} m × {:.1} m): {} vehicle clusters, {} start poses",
            a.out.display(),
            spec.width,
            spec.height,
            spec.resolution_m,
            record.size_m[0],
            record.size_m[1],
            world.meta.vehicle_clusters.len(),
            world.meta.start_poses.len()
        );
        let total = (record.colours.exact + record.colours.near + record.colours.snapped).max(1) as f64;
        out!(
            "colours: {:.1} % exact, {:.1} % within tolerance {}, {:.1} % matched no class and were snapped{}",
            record.colours.exact as f64 / total * 100.0,
            record.colours.near as f64 / total * 100.0,
            a.colour_tolerance,
            share * 100.0,
            if record.colours.snapped > 0 {
                format!(" (most common: {})", describe_top(&record.colours))
            } else {
                String::new()
            }
        );
        if record.colours.no_data > 0 {
            out!(
                "{:.1} % of the pixels are transparent: class `{NO_DATA_CLASS}` (impassable, a {NO_DATA_HEIGHT_M} m wall \
                 in the simulator)",
                record.colours.no_data as f64 / (total + record.colours.no_data as f64) * 100.0
            );
        }
        if let Some(v) = record.vehicle_width_m {
            out!("vehicles are {v:.1} m wide (median over the vehicle blobs; a car is about {CAR_WIDTH_M} m)");
        }
        if record.ramp_spacing_m > 0.0 {
            out!(
                "{} curb cuts, about {} m apart along the curbs (--ramp-spacing-m)",
                record.curb_cuts,
                record.ramp_spacing_m
            );
        }
        for (i, s) in world.meta.start_poses.iter().enumerate() {
            out!("start pose {i}: {{ x_m: {:.2}, y_m: {:.2}, yaw_deg: {:.0} }}", s.x, s.y, s.yaw.to_degrees());
        }
        if let Some([lat, lon]) = record.gps_origin {
            out!("map origin (south-west corner) at {lat:.7}, {lon:.7} (ros2.gps_origin, QGC planned home)");
        }
    }
    for note in &record.notes {
        errln!("warning: {note}");
    }
    if world.meta.vehicle_clusters.is_empty()
        && let Some(vehicle) = world.classes().by_name(&a.vehicle_class)
        && world.count_class(vehicle.index) > 0
    {
        errln!(
            "warning: the world has {} vehicle cells but the goal detector finds no cluster in them at {} m per cell \
             (it removes specks thinner than about two cells); a finer --cell-m keeps them",
            world.count_class(vehicle.index),
            spec.resolution_m
        );
    }
    if world.meta.start_poses.len() < a.starts {
        errln!(
            "warning: only {} of {} start poses found (clear easy ground at least {START_CLEARANCE_M} m from other \
             classes)",
            world.meta.start_poses.len(),
            a.starts
        );
    }
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table() -> ImportClasses {
        let yaml = "classes:\n  - { index: 0, name: road, rank: 0, color: [128, 64, 128] }\n  - { index: 2, name: building, rank: 5, color: [70, 70, 70], height_m: 10 }\n  - { index: 3, name: grass_sidewalk, rank: 2, color: [152, 251, 152] }\n";
        match parse_classes(Path::new("t.yaml"), yaml) {
            Ok(t) => t,
            Err(e) => panic!("{e:#}"),
        }
    }

    #[test]
    fn heights_come_from_the_table_or_the_class_name() {
        let t = table();
        assert_eq!(t.heights_m[2], 10.0);
        assert_eq!(t.heights_m[3], 0.15, "the loader's curb height for grass_sidewalk");
        assert_eq!(t.heights_m[0], 0.0);
    }

    #[test]
    fn a_bad_table_names_file_line_column_and_shows_the_format() {
        let yaml = "classes:\n  - { index: 0, name: road, rank: 0 }\n";
        let e = format!(
            "{:#}",
            parse_classes(Path::new("tbl.yaml"), yaml).err().map(|e| e.to_string()).unwrap_or_default()
        );
        assert!(e.starts_with("tbl.yaml:2:"), "{e}");
        assert!(e.contains("color") && e.contains("expected format"), "{e}");
        let dup = "classes:\n  - { index: 0, name: a, rank: 0, color: [1, 2, 3] }\n  - { index: 0, name: b, rank: 0, color: [4, 5, 6] }\n";
        let e = parse_classes(Path::new("d.yaml"), dup).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("d.yaml:3:5") && e.contains("classes[1]: index 0 is used twice"), "{e}");
        let garbage = "classes: [1, 2";
        let e = parse_classes(Path::new("g.yaml"), garbage).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.starts_with("g.yaml:") && e.contains("expected format"), "{e}");
    }

    #[test]
    fn colours_snap_to_the_nearest_class_and_far_ones_are_counted() {
        let t = table();
        let mut img = image::RgbaImage::new(4, 1);
        img.put_pixel(0, 0, image::Rgba([128, 64, 128, 255])); // exact road
        img.put_pixel(1, 0, image::Rgba([120, 60, 125, 255])); // anti-aliased road
        img.put_pixel(2, 0, image::Rgba([75, 72, 70, 255])); // near building
        img.put_pixel(3, 0, image::Rgba([255, 255, 0, 255])); // no class: snapped to its neighbours'
        let (classes, m) = classify(&img, &t.table, None, 30.0);
        assert_eq!(classes, [0, 0, 2, 2]);
        assert_eq!((m.exact, m.near, m.snapped), (1, 2, 1));
        assert!((m.snapped_share() - 0.25).abs() < 1e-12);
        assert_eq!(m.top_snapped, vec![([255, 255, 0], 1, "building".to_string())]);
        // A blend of road and grass lies nearer gravel's colour than either; among road and
        // grass pixels it goes to the majority around it, not to gravel.
        let mut table = t.table.clone();
        table.classes.push(ClassInfo {
            index: 6,
            name: "gravel".into(),
            rank: 1,
            color: [190, 153, 153],
            ignored: false,
        });
        let mut edge = image::RgbaImage::from_pixel(3, 3, image::Rgba([152, 251, 152, 255]));
        edge.put_pixel(0, 0, image::Rgba([128, 64, 128, 255]));
        edge.put_pixel(1, 1, image::Rgba([140, 157, 140, 255]));
        let (classes, m) = classify(&edge, &table, None, 30.0);
        assert_eq!(classes[4], 3, "{classes:?}");
        assert_eq!(m.snapped, 1);
        // Alone, a far colour takes the nearest class colour.
        let lone = image::RgbaImage::from_pixel(1, 1, image::Rgba([140, 157, 140, 255]));
        assert_eq!(classify(&lone, &table, None, 30.0).0, [6]);
    }

    /// The authors' class-table format: a list of names with colours, read as it is.
    #[test]
    fn a_list_of_names_with_colours_is_a_class_table() {
        let yaml = "- { name: unknown, color: [0, 0, 0] }\n- { name: road, color: [128, 64, 128] }\n\
                    - { name: grass/sidewalk, colour: \"#98FB98\" }\n- { name: vehicle, rgb: [0, 0, 142], trainId: 7 }\n\
                    - { name: water, color: [60, 110, 220] }\n- { name: pond, color: [60, 110, 221], rank: 4, id: 20 }\n";
        let t = parse_classes(Path::new("l.yaml"), yaml).unwrap_or_else(|e| panic!("{e:#}"));
        let c = |n: &str| t.table.by_name(n).cloned().unwrap_or_else(|| panic!("{n}"));
        assert_eq!((c("road").index, c("road").rank), (1, 0), "position is the label value, rank by name");
        assert_eq!((c("grass/sidewalk").index, c("grass/sidewalk").rank), (2, 2));
        assert_eq!(c("grass/sidewalk").color, [152, 251, 152]);
        assert_eq!(t.heights_m[2], 0.15, "the curb, by the built-in name");
        assert_eq!((c("vehicle").rank, t.heights_m[3]), (3, 1.5));
        assert_eq!((c("water").rank, c("unknown").rank), (5, 5), "names spomp lacks are impassable");
        assert_eq!((c("pond").index, c("pond").rank), (20, 4), "an entry's own index and rank win");
        assert!(t.notes.len() == 1 && t.notes[0].contains("\"water\"") && t.notes[0].contains("rank"), "{:?}", t.notes);
        // The same in JSON.
        let json = r##"[{"name": "road", "color": "#804080"}, {"name": "Building", "color": [70, 70, 70]}]"##;
        let t = parse_classes(Path::new("l.json"), json).unwrap_or_else(|e| panic!("{e:#}"));
        assert_eq!(t.table.by_name("building").map(|c| (c.index, c.rank)), Some((1, 5)));
        // Anything else: located, and both formats shown.
        let err =
            |text: &str| parse_classes(Path::new("x.yaml"), text).err().map(|e| e.to_string()).unwrap_or_default();
        let e = err("- { name: road }\n");
        assert!(e.starts_with("x.yaml:1:3:") && e.contains("[0]") && e.contains("color"), "{e}");
        let e = err("- { name: road, color: \"#12345\" }\n");
        assert!(e.contains("#RRGGBB"), "{e}");
        let e = err("- road\n- grass\n");
        assert!(e.contains("[0]: expected an entry with a `name` and a `color`"), "{e}");
        let e = err("road: [1, 2, 3]\n");
        assert!(e.contains("a list of names with colours") && e.contains("- { name: road"), "{e}");
        let e = err("- { name: a, color: [1, 2, 3] }\n- { name: b, color: [1, 2, 3] }\n");
        assert!(e.contains("x.yaml:2:3") && e.contains("colour [1, 2, 3] is used twice"), "{e}");
        let e = err("- { name: no_data, color: [1, 2, 3] }\n");
        assert!(e.contains("reserved"), "{e}");
    }

    /// Transparent pixels are no data, never matched to a colour; a white label takes the class
    /// it was printed on (or no data on the margin), never the class nearest white.
    #[test]
    fn transparency_is_no_data_and_labels_take_the_class_beneath() {
        let mut t = table();
        // A light vehicle colour nearest white, as some tables have.
        t.table.classes.push(ClassInfo {
            index: 4,
            name: "vehicle".into(),
            rank: 3,
            color: [220, 220, 250],
            ignored: false,
        });
        let nd = no_data_class(&t.table).unwrap_or_else(|| panic!("a free index"));
        assert_eq!((nd.index, nd.rank, nd.color), (254, 5, [0, 0, 0]));
        let mut table = t.table.clone();
        table.classes.push(nd);
        // 12 × 6: road, a transparent west margin (4 columns, black RGB behind alpha 0), and a
        // white 3 × 3 label, half on the margin, half on the road.
        let mut img = image::RgbaImage::from_pixel(12, 6, image::Rgba([128, 64, 128, 255]));
        for y in 0..6 {
            for x in 0..4 {
                img.put_pixel(x, y, image::Rgba([128, 64, 128, 0]));
            }
        }
        for y in 1..4 {
            for x in 3..9 {
                img.put_pixel(x, y, image::Rgba([255, 255, 255, 255]));
            }
        }
        let (classes, m) = classify(&img, &table, Some(254), 30.0);
        assert_eq!(m.no_data, 21, "the margin less the label's pixels on it");
        assert_eq!(m.snapped, 18);
        assert!(!classes.contains(&4), "no label pixel became a vehicle: {classes:?}");
        assert_eq!(classes[0], 254, "a transparent pixel is no data even with a class colour behind it");
        assert_eq!(classes[2 * 12 + 8], 0, "the label on the road is road");
        assert_eq!(classes[2 * 12 + 3], 254, "the label on the margin is no data");
        // Without no data (an opaque raster), alpha is not looked at.
        let (classes, _) = classify(&img, &t.table, None, 30.0);
        assert_eq!(classes[0], 0);
    }

    #[test]
    fn vehicle_blobs_measure_the_scale() {
        // Two cars of 4 × 9 pixels and one 3 × 3 speck on road.
        let (w, h) = (30u32, 14u32);
        let mut px = vec![0 as ClassId; (w * h) as usize];
        let mut paint = |x0: u32, y0: u32, cw: u32, ch: u32| {
            for y in y0..y0 + ch {
                for x in x0..x0 + cw {
                    px[(y * w + x) as usize] = 4;
                }
            }
        };
        paint(2, 2, 4, 9);
        paint(10, 2, 4, 9);
        paint(20, 2, 3, 3);
        let at = |m: f64| vehicle_width_m(&px, w, h, 4, m).unwrap_or(f64::NAN);
        // Four pixels at 0.5 m: 2 m, measured to within a pixel.
        assert!((at(0.5) - 2.0).abs() <= 0.5, "{}", at(0.5));
        assert!(check_vehicle_width(at(0.5), 0.5, false).is_ok());
        // Pixels per metre taken for metres per pixel: 2.5 m pixels, 10 m wide cars.
        let e = check_vehicle_width(at(2.5), 2.5, false).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("m wide") && e.contains("--resolution-m 0.") && e.contains("--force"), "{e}");
        assert!(check_vehicle_width(at(2.5), 2.5, true).is_ok());
        // Too small: 5 cm pixels make 20 cm cars.
        assert!(check_vehicle_width(at(0.05), 0.05, false).is_err());
        assert_eq!(vehicle_width_m(&[0; 4], 2, 2, 4, 0.5), None);
    }

    #[test]
    fn resampling_takes_the_majority_of_the_pixels_of_a_cell() {
        let t = table();
        // 4 × 2 pixels of 0.5 m: road, road, building, grass / road, building, building, grass.
        let px = [0, 0, 2, 3, 0, 2, 2, 3];
        let one = resample(&px, 4, 2, 0.5, 1.0, &t.table).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((one.width, one.height), (2, 1));
        // Left cell: three road, one building; right cell: two building, two grass: a tie that
        // goes to the easier grass.
        assert_eq!(one.class, [0, 3]);
        let fine = resample(&px, 4, 2, 0.5, 0.25, &t.table).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!((fine.width, fine.height), (8, 4));
        assert_eq!(fine.class[..8], [0, 0, 0, 0, 2, 2, 3, 3]);
        assert_eq!(fine.class[24..], [0, 0, 2, 2, 2, 2, 3, 3]);
        let same = resample(&px, 4, 2, 0.5, 0.5, &t.table).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(same.class, px);
        assert!(resample(&px, 4, 2, 0.5, 0.0001, &t.table).is_err(), "too many cells");
    }

    #[test]
    fn implausible_spans_are_questioned_unless_forced() {
        // A 600-pixel campus at 15 m per pixel would be 9 km across.
        let e = check_scale(Scale::MetresPerPixel(15.0), 600, 400, false).err().map(|e| e.to_string());
        assert!(e.as_deref().unwrap_or_default().contains("9000.0 m × 6000.0 m"), "{e:?}");
        assert_eq!(check_scale(Scale::MetresPerPixel(15.0), 600, 400, true).ok(), Some(15.0));
        // Pixels per metre confused with metres per pixel: 2 m across.
        assert!(check_scale(Scale::PixelsPerMetre(200.0), 400, 300, false).is_err());
        assert_eq!(check_scale(Scale::PixelsPerMetre(2.0), 400, 300, false).ok(), Some(0.5));
        assert!(check_scale(Scale::MetresPerPixel(f64::NAN), 4, 4, true).is_err());
    }

    #[test]
    fn start_poses_are_on_clear_road_near_the_anchor_and_apart() {
        let t = table();
        // 60 × 40 m of grass with a 10 m wide road along y in [10, 20).
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 120, 80);
        let mut world = World::flat(spec, t.table.clone(), 3, 0.15).unwrap_or_else(|e| panic!("{e}"));
        for row in 20..40 {
            for col in 0..120 {
                world.set_cell(spomp_core::Cell::new(col, row), 0, [128, 64, 128], 0.0);
            }
        }
        let starts = start_poses(&world, Point2::new(0.0, 0.0), 3);
        assert_eq!(starts.len(), 3);
        for s in &starts {
            assert!(s.y >= 12.0 && s.y <= 18.0, "clear of the curb by 2 m: {s:?}");
            assert!(s.x < 20.0, "near the south-west corner: {s:?}");
        }
        for (i, a) in starts.iter().enumerate() {
            for b in &starts[i + 1..] {
                assert!(a.position().distance(b.position()) >= START_SPACING_M);
            }
        }
        // No road at all: no start pose.
        let grass = World::flat(spec, t.table, 3, 0.15).unwrap_or_else(|e| panic!("{e}"));
        let on_grass = start_poses(&grass, Point2::new(0.0, 0.0), 2);
        assert!(on_grass.iter().all(|s| grass.class_at(s.position()) == Some(3)));
    }

    #[test]
    fn curbs_get_cuts_so_a_lot_behind_a_grass_strip_is_reachable() {
        let t = table();
        // 60 m × 20 m: road for y < 8 m, a 1 m grass strip (a curb on both sides), then a lot
        // (road class) for y ≥ 9 m.
        let spec = GridSpec::new(Point2::new(0.0, 0.0), 0.5, 120, 40);
        let mut map = AerialMap::unknown(spec);
        for i in 0..spec.len() {
            let strip = (16..18).contains(&(i / 120));
            map.class[i] = if strip { 3 } else { 0 };
            map.elevation[i] = t.heights_m[map.class[i] as usize];
        }
        let reach = |map: &AerialMap| {
            let world =
                World::new(map.clone(), t.table.clone(), WorldMeta::default()).unwrap_or_else(|e| panic!("{e}"));
            let cells =
                spomp_world::reachable_cells(&world, &spomp_world::UgvLimits::default(), Point2::new(30.0, 3.0));
            *cells.at(spec.cell_at(Point2::new(30.0, 15.0)).unwrap_or_else(|| panic!("off the map")))
        };
        assert!(!reach(&map), "without cuts the strip is a wall of curbs");
        let cuts = cut_curbs(&mut map, &t.table, 20.0);
        // About one cut per 20 m of each side of the strip, the two sides' cuts overlapping.
        assert!((3..=8).contains(&cuts), "{cuts}");
        assert!(reach(&map), "the cuts lead over the strip");
        // Between the cuts the curb stands; no cell rose.
        let raised = (0..spec.len()).filter(|&i| map.elevation[i] > 0.149).count();
        assert!(raised > 0 && raised < 240, "{raised}");
        assert!(map.elevation.iter().all(|&e| e <= 0.15 + 1e-6));
    }
}
