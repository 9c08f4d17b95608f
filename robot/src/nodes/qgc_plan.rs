//! QGroundControl `.plan` files: the waypoint list (and exclusion geofences) of the UAV's
//! exploration, in the map frame.
//!
//! Placement: latitude and longitude become metres east (x) and north (y) on the local tangent
//! plane at a reference point, by the equirectangular approximation on the WGS-84 equatorial
//! radius — exact to well under a metre over the few kilometres a mission spans (points farther
//! than [`MAX_EXTENT_M`] from the reference are refused). The reference is where the map
//! frame's origin lies on the Earth when the robot's operating area is georeferenced (a world
//! imported with `--gps-reference`, or the robot's `ros2.gps_origin`): every waypoint and fence
//! is then placed by its own coordinates, wherever the plan's home is. Without a georeference
//! the plan's `mission.plannedHomePosition` is taken as the map origin (0, 0), so a plan drawn
//! around the map's south-west corner flies as drawn. Either way the home itself is used only
//! where the plan says so: a return to launch flies back to it.
//!
//! Mission items:
//! - `SimpleItem` with command 16 (`NAV_WAYPOINT`) or 82 (`NAV_SPLINE_WAYPOINT`, flown as a
//!   straight leg): a waypoint at `params[4]`/`params[5]` (latitude, longitude), altitude
//!   `params[6]`;
//! - loiters 17/18/19/31 (`NAV_LOITER_*`): the UAV flies to the position; the hold itself is not
//!   applied (exploration time is governed by the mission's state machine);
//! - 22/84 (`NAV_TAKEOFF`, `NAV_VTOL_TAKEOFF`): skipped, the UAV takes off where it stands;
//! - 20 (`NAV_RETURN_TO_LAUNCH`): a waypoint at the plan's home, at the previous altitude; the
//!   items after it are not flown (the vehicle would be home);
//! - commands 100 and above (`CONDITION_*`, `DO_*`, camera and gimbal commands) do not move the
//!   vehicle and are skipped;
//! - `ComplexItem` surveys and corridor scans: the simple items QGroundControl generated for
//!   them (`TransectStyleComplexItem.Items`, what it uploads to the vehicle), read as above;
//! - every other navigation command (below 100: land, …) and every other complex item
//!   (structure scans) is refused with an error naming the item: spomp would otherwise fly a
//!   different route than the operator planned.
//!
//! Geofences (as PX4 reads them): exclusion polygons become no-fly zones, exclusion circles the
//! 16-gon that circumscribes them; inclusion polygons become fences the UAV's transfers stay
//! inside, inclusion circles the 16-gon inscribed in them (so inside the polygon is inside the
//! circle). With several inclusion fences the UAV may fly anywhere inside any of them (their
//! union), never inside an exclusion zone. Rally points are ignored.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use serde_json::Value;
use spomp_behaviors::mission::limits::{MAX_SOURCE_BYTES, SourceError, read_text};
use spomp_core::{GeoPoint, Point2};

/// Farthest a waypoint or fence vertex may lie from the placement reference, metres.
pub(crate) const MAX_EXTENT_M: f64 = 50_000.0;

/// Polygons in the map frame (each a list of vertices).
pub(crate) type Polygons = Vec<Vec<Point2>>;

/// A waypoint of a plan, in the map frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct PlanWaypoint {
    /// Position, metres (x east, y north of the map origin).
    pub position: Point2,
    /// Altitude the plan gives for it, metres.
    pub altitude_m: f64,
}

/// The parts of a `.plan` file the UAV flies.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct QgcPlan {
    /// Waypoints in flight order.
    pub waypoints: Vec<PlanWaypoint>,
    /// Exclusion geofences as polygons in the map frame.
    pub no_fly: Polygons,
    /// Inclusion geofences as polygons in the map frame: fly only inside (any of) them.
    pub fly_inside: Polygons,
}

/// Why a plan file cannot be flown: the file and what is wrong in it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("QGroundControl plan `{}`: {problem}", path.display())]
pub struct PlanError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong, and where in the file.
    pub problem: PlanProblem,
}

/// What is wrong in a `.plan` file. Problems inside the file are wrapped in
/// [`PlanProblem::At`] with the JSON path they were found at (`mission.items[3]`).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanProblem {
    /// The file could not be read (missing, not a regular file, too large, not UTF-8).
    #[error("cannot read the file: {0}")]
    Unreadable(#[source] SourceError),
    /// The text is not JSON.
    #[error("not valid JSON: {0}")]
    NotJson(String),
    /// The top level is not a JSON object.
    #[error("expected a JSON object with `fileType: \"Plan\"`, found {0}")]
    NotAnObject(&'static str),
    /// `fileType` names another kind of file.
    #[error("`fileType` is `{0}`, expected `Plan`")]
    WrongFileType(String),
    /// No `fileType` at all.
    #[error("missing `fileType: \"Plan\"`; is this a QGroundControl plan?")]
    NotAPlan,
    /// A required field is absent (its path in the file).
    #[error("missing `{0}`")]
    Missing(&'static str),
    /// No `mission` section.
    #[error("missing the `mission` section")]
    NoMission,
    /// `mission.plannedHomePosition` is not `[latitude, longitude, altitude]` (the value found).
    #[error("`mission.plannedHomePosition` must be [latitude, longitude, altitude], found {0}")]
    BadHome(String),
    /// The georeferenced map origin is too close to a pole for the flat placement.
    #[error("the map origin's latitude {0} is too close to a pole for a flat map")]
    OriginNearPole(f64),
    /// A latitude is too close to a pole for the flat placement.
    #[error("latitude {0} is too close to a pole for a flat map")]
    NearPole(f64),
    /// A field that must be a list is not (its path in the file).
    #[error("`{0}` must be a list")]
    NotAList(&'static str),
    /// `mission.items` is not a list.
    #[error("`mission.items` must be a list of items")]
    ItemsNotAList,
    /// A latitude outside [-90, 90] degrees.
    #[error("latitude {0} is not within [-90, 90] degrees")]
    Latitude(f64),
    /// A longitude outside [-180, 180] degrees.
    #[error("longitude {0} is not within [-180, 180] degrees")]
    Longitude(f64),
    /// A point farther from the placement reference than plans may reach (50 km).
    #[error(
        "({latitude_deg}, {longitude_deg}) lies {:.0} km from {reference}; plans must stay within {:.0} km",
        .distance_m / 1000.0,
        MAX_EXTENT_M / 1000.0
    )]
    TooFar {
        /// The point's latitude, degrees.
        latitude_deg: f64,
        /// The point's longitude, degrees.
        longitude_deg: f64,
        /// Its distance from the reference, metres.
        distance_m: f64,
        /// What the reference is (`the map origin`, `the plan's home`).
        reference: &'static str,
    },
    /// A mission item without `type`.
    #[error("missing the item `type` (SimpleItem or ComplexItem)")]
    NoItemType,
    /// A mission item of a type other than `SimpleItem` / `ComplexItem`.
    #[error("unknown item type `{0}` (expected SimpleItem or ComplexItem)")]
    UnknownItemType(String),
    /// A complex item without the simple items QGroundControl generates for it.
    #[error(
        "complex item `{0}` is not supported (surveys and corridor scans are, through the items QGroundControl \
         generated for them in `TransectStyleComplexItem.Items`); replace it with waypoints"
    )]
    UnsupportedComplexItem(String),
    /// A survey or corridor scan whose generated items are empty.
    #[error(
        "complex item `{0}` has no generated items (`TransectStyleComplexItem.Items` is empty); open and save the \
         plan in QGroundControl to generate them"
    )]
    NoGeneratedItems(String),
    /// `TransectStyleComplexItem.Items` of the item at this path is not a list.
    #[error("{0}.TransectStyleComplexItem.Items must be a list of items")]
    GeneratedItemsNotAList(String),
    /// A simple item without its MAVLink `command`.
    #[error("missing the MAVLink `command` number")]
    NoCommand,
    /// A navigation command spomp does not fly (number and MAVLink name, when known).
    #[error(
        "navigation command {command} {name} is not supported (flown: {}, 20 NAV_RETURN_TO_LAUNCH; skipped: 22 \
             NAV_TAKEOFF, 84 NAV_VTOL_TAKEOFF, and non-navigation commands ≥ 100)",
        flown_list()
    )]
    UnsupportedCommand {
        /// The MAVLink command number.
        command: u64,
        /// Its name, empty when not known.
        name: &'static str,
    },
    /// `frame` is not a number (the value found).
    #[error("`frame` must be a MAVLink frame number, found {0}")]
    FrameNotNumber(String),
    /// A frame other than a global latitude/longitude one.
    #[error("frame {0} is not a global (latitude/longitude) frame; supported frames: {GLOBAL_FRAMES:?}")]
    NotGlobalFrame(u64),
    /// No `params` list.
    #[error("missing the 7 `params` of the command")]
    NoParams,
    /// `params` of another length than 7.
    #[error("a command has 7 `params`, found {0}")]
    ParamCount(usize),
    /// A parameter that must be a number is not.
    #[error("params[{index}] ({what}) must be a number")]
    ParamNotNumber {
        /// Index in `params`.
        index: usize,
        /// What the parameter is.
        what: &'static str,
    },
    /// A geofence without `inclusion`.
    #[error("missing `inclusion` (true or false)")]
    NoInclusion,
    /// A polygon fence without `polygon`.
    #[error("missing `polygon`")]
    NoPolygon,
    /// A polygon of fewer than 3 vertices (the count).
    #[error("a polygon needs at least 3 vertices, found {0}")]
    TooFewVertices(usize),
    /// A fence vertex that is not `[latitude, longitude]`.
    #[error("expected [latitude, longitude]")]
    NotLatLon,
    /// A fence vertex whose latitude is not a number.
    #[error("latitude must be a number")]
    LatitudeNotNumber,
    /// A fence vertex whose longitude is not a number.
    #[error("longitude must be a number")]
    LongitudeNotNumber,
    /// A circle fence without `circle`.
    #[error("missing `circle`")]
    NoCircle,
    /// A circle fence whose radius is not a positive number.
    #[error("expected a positive number of metres")]
    BadRadius,
    /// A problem at a path in the file (`mission.items[2]`, `geoFence.polygons[0]`).
    #[error("{at}: {problem}")]
    At {
        /// Where in the file.
        at: String,
        /// What is wrong there.
        problem: Box<PlanProblem>,
    },
}

impl PlanProblem {
    /// This problem, found at `at` in the file.
    fn at(self, at: impl Into<String>) -> Self {
        PlanProblem::At { at: at.into(), problem: Box::new(self) }
    }
}

/// The flown navigation commands, for [`PlanProblem::UnsupportedCommand`]'s message.
fn flown_list() -> String {
    FLOWN.iter().map(|(c, n)| format!("{c} {n}")).collect::<Vec<_>>().join(", ")
}

/// Reads and interprets a `.plan` file, placed through `map_origin` when the operating area is
/// georeferenced (else around the plan's home).
pub(crate) fn load_plan(path: &Path, map_origin: Option<GeoPoint>) -> Result<QgcPlan, PlanError> {
    let error = |problem: PlanProblem| PlanError { path: path.to_path_buf(), problem };
    // The loader checked the file, but it is read again here when the tree is built: the same
    // rules (a regular file, at most the mission language's size limit) hold at this read too.
    let text = read_text(path, MAX_SOURCE_BYTES).map_err(|e| error(PlanProblem::Unreadable(e)))?;
    parse_plan(&text, map_origin).map_err(error)
}

/// The waypoints of a QGroundControl `.plan` file in the map frame, read and placed exactly as
/// `follow_waypoints` reads them over an area whose origin lies at `map_origin` (`None`: the
/// plan's planned home is the origin): for checks made outside the node, such as `spomp
/// validate`'s world stage. The error names the file and the problem.
pub fn plan_waypoints(path: &Path, map_origin: Option<GeoPoint>) -> Result<Vec<Point2>, PlanError> {
    load_plan(path, map_origin).map(|p| p.waypoints.iter().map(|w| w.position).collect())
}

/// Interprets the text of a `.plan` file; errors say where in the file the problem is.
pub(crate) fn parse_plan(text: &str, map_origin: Option<GeoPoint>) -> Result<QgcPlan, PlanProblem> {
    let root: Value = serde_json::from_str(text).map_err(|e| PlanProblem::NotJson(e.to_string()))?;
    let Some(obj) = root.as_object() else {
        return Err(PlanProblem::NotAnObject(kind(&root)));
    };
    match obj.get("fileType").and_then(Value::as_str) {
        Some("Plan") => {}
        Some(other) => return Err(PlanProblem::WrongFileType(other.to_string())),
        None => return Err(PlanProblem::NotAPlan),
    }
    let mission = obj.get("mission").ok_or(PlanProblem::NoMission)?;
    let home = mission.get("plannedHomePosition").ok_or(PlanProblem::Missing("mission.plannedHomePosition"))?;
    let (home_lat, home_lon) = home_of(home)?;
    let origin = match map_origin {
        Some(o) => {
            if !(o.latitude_deg.is_finite() && o.latitude_deg.abs() <= 85.0) {
                return Err(PlanProblem::OriginNearPole(o.latitude_deg));
            }
            Origin { at: o, what: "the map origin" }
        }
        None => Origin { at: GeoPoint::new(home_lat, home_lon), what: "the plan's home" },
    };
    let home = origin.to_local(home_lat, home_lon).map_err(|e| e.at(HOME_AT))?;

    let items = mission.get("items").and_then(Value::as_array).ok_or(PlanProblem::ItemsNotAList)?;
    let mut plan = QgcPlan::default();
    let mut walk = Walk { origin: &origin, home, returned: false };
    for (i, item) in items.iter().enumerate() {
        walk.item(item, &format!("mission.items[{i}]"), &mut plan.waypoints)?;
        if walk.returned {
            break;
        }
    }
    if let Some(fence) = obj.get("geoFence") {
        (plan.no_fly, plan.fly_inside) = fences(fence, &origin)?;
    }
    Ok(plan)
}

/// How the plan's home is named in errors.
const HOME_AT: &str = "`mission.plannedHomePosition`";

/// The local tangent plane points are placed on.
struct Origin {
    at: GeoPoint,
    /// What the reference is, for errors.
    what: &'static str,
}

impl Origin {
    /// Latitude/longitude in degrees to metres east/north of the origin.
    fn to_local(&self, lat: f64, lon: f64) -> Result<Point2, PlanProblem> {
        check_lat_lon(lat, lon)?;
        let p = self.at.local_of(lat, lon);
        if p.norm() > MAX_EXTENT_M {
            return Err(PlanProblem::TooFar {
                latitude_deg: lat,
                longitude_deg: lon,
                distance_m: p.norm(),
                reference: self.what,
            });
        }
        Ok(p)
    }
}

fn check_lat_lon(lat: f64, lon: f64) -> Result<(), PlanProblem> {
    if !(lat.is_finite() && (-90.0..=90.0).contains(&lat)) {
        return Err(PlanProblem::Latitude(lat));
    }
    if !(lon.is_finite() && (-180.0..=180.0).contains(&lon)) {
        return Err(PlanProblem::Longitude(lon));
    }
    Ok(())
}

fn home_of(home: &Value) -> Result<(f64, f64), PlanProblem> {
    let bad = || PlanProblem::BadHome(home.to_string());
    let arr = home.as_array().ok_or_else(bad)?;
    let lat = arr.first().and_then(Value::as_f64).ok_or_else(bad)?;
    let lon = arr.get(1).and_then(Value::as_f64).ok_or_else(bad)?;
    check_lat_lon(lat, lon).map_err(|e| e.at(HOME_AT))?;
    if lat.abs() > 85.0 {
        return Err(PlanProblem::NearPole(lat).at(HOME_AT));
    }
    Ok((lat, lon))
}

fn kind(v: &Value) -> &'static str {
    spomp_behaviors::blackboard::json_kind(v)
}

/// Navigation commands flown as a waypoint at the item's position.
const FLOWN: &[(u64, &str)] = &[
    (16, "NAV_WAYPOINT"),
    (17, "NAV_LOITER_UNLIM"),
    (18, "NAV_LOITER_TURNS"),
    (19, "NAV_LOITER_TIME"),
    (31, "NAV_LOITER_TO_ALT"),
    (82, "NAV_SPLINE_WAYPOINT"),
];
/// `NAV_RETURN_TO_LAUNCH`: fly back to the plan's home.
const RETURN_TO_LAUNCH: u64 = 20;
/// Navigation commands skipped: the UAV is already airborne where it starts.
const SKIPPED: &[(u64, &str)] = &[(22, "NAV_TAKEOFF"), (84, "NAV_VTOL_TAKEOFF")];
/// Names of refused navigation commands, for the error message.
const REFUSED: &[(u64, &str)] =
    &[(21, "NAV_LAND"), (85, "NAV_VTOL_LAND"), (93, "NAV_DELAY"), (80, "NAV_ROI"), (81, "NAV_PATHPLANNING")];
/// MAVLink frames with global latitude/longitude coordinates.
const GLOBAL_FRAMES: &[u64] = &[0, 3, 5, 6, 10, 11];

/// Reads mission items in order into waypoints.
struct Walk<'a> {
    origin: &'a Origin,
    /// The plan's home in the map frame.
    home: Point2,
    /// A return to launch was read: nothing after it is flown.
    returned: bool,
}

impl Walk<'_> {
    fn item(&mut self, item: &Value, at: &str, out: &mut Vec<PlanWaypoint>) -> Result<(), PlanProblem> {
        let ty = item.get("type").and_then(Value::as_str).ok_or_else(|| PlanProblem::NoItemType.at(at))?;
        match ty {
            "SimpleItem" => {}
            "ComplexItem" => {
                let what = item.get("complexItemType").and_then(Value::as_str).unwrap_or("unknown");
                // Surveys and corridor scans carry the simple items QGroundControl generated
                // for them: the route the vehicle is sent.
                let generated = item.get("TransectStyleComplexItem").and_then(|t| t.get("Items"));
                let Some(inner) = generated else {
                    return Err(PlanProblem::UnsupportedComplexItem(what.to_string()).at(at));
                };
                let inner = inner.as_array().ok_or_else(|| PlanProblem::GeneratedItemsNotAList(at.to_string()))?;
                if inner.is_empty() {
                    return Err(PlanProblem::NoGeneratedItems(what.to_string()).at(at));
                }
                for (k, sub) in inner.iter().enumerate() {
                    self.item(sub, &format!("{at}.TransectStyleComplexItem.Items[{k}]"), out)?;
                    if self.returned {
                        break;
                    }
                }
                return Ok(());
            }
            other => return Err(PlanProblem::UnknownItemType(other.to_string()).at(at)),
        }
        let wp = item_waypoint(item, self.origin, self.home, out.last()).map_err(|e| e.at(at))?;
        if let Some((wp, returns)) = wp {
            out.push(wp);
            self.returned = returns;
        }
        Ok(())
    }
}

/// The waypoint a simple item flies to, and whether it is the return to launch.
fn item_waypoint(
    item: &Value,
    origin: &Origin,
    home: Point2,
    previous: Option<&PlanWaypoint>,
) -> Result<Option<(PlanWaypoint, bool)>, PlanProblem> {
    let command = item.get("command").and_then(Value::as_u64).ok_or(PlanProblem::NoCommand)?;
    if command >= 100 {
        return Ok(None); // CONDITION_*, DO_*, camera: they do not move the vehicle
    }
    if SKIPPED.iter().any(|(c, _)| *c == command) {
        return Ok(None);
    }
    if command == RETURN_TO_LAUNCH {
        let altitude_m = previous.map_or(0.0, |p| p.altitude_m);
        return Ok(Some((PlanWaypoint { position: home, altitude_m }, true)));
    }
    if !FLOWN.iter().any(|(c, _)| *c == command) {
        let name = REFUSED.iter().find(|(c, _)| *c == command).map_or("", |(_, n)| *n);
        return Err(PlanProblem::UnsupportedCommand { command, name });
    }
    let frame = match item.get("frame") {
        None => 3,
        Some(f) => f.as_u64().ok_or_else(|| PlanProblem::FrameNotNumber(f.to_string()))?,
    };
    if !GLOBAL_FRAMES.contains(&frame) {
        return Err(PlanProblem::NotGlobalFrame(frame));
    }
    let params = item.get("params").and_then(Value::as_array).ok_or(PlanProblem::NoParams)?;
    if params.len() != 7 {
        return Err(PlanProblem::ParamCount(params.len()));
    }
    let number = |index: usize, what: &'static str| {
        params.get(index).and_then(Value::as_f64).ok_or(PlanProblem::ParamNotNumber { index, what })
    };
    let lat = number(4, "latitude")?;
    let lon = number(5, "longitude")?;
    let altitude_m = match params.get(6).and_then(Value::as_f64) {
        Some(a) if a.is_finite() => a,
        _ => item
            .get("Altitude")
            .and_then(Value::as_f64)
            .ok_or(PlanProblem::ParamNotNumber { index: 6, what: "altitude" })?,
    };
    Ok(Some((PlanWaypoint { position: origin.to_local(lat, lon)?, altitude_m }, false)))
}

/// Number of sides of the polygon that replaces a circular fence.
const CIRCLE_SIDES: usize = 16;

/// The exclusion zones and the inclusion fences of a `geoFence` section.
fn fences(fence: &Value, origin: &Origin) -> Result<(Polygons, Polygons), PlanProblem> {
    let (mut zones, mut inside) = (Vec::new(), Vec::new());
    let inclusion = |v: &Value, at: &str| -> Result<bool, PlanProblem> {
        v.get("inclusion").and_then(Value::as_bool).ok_or_else(|| PlanProblem::NoInclusion.at(at))
    };
    let latlon = |v: &Value, at: &str| -> Result<Point2, PlanProblem> {
        let arr = v.as_array().filter(|a| a.len() >= 2).ok_or_else(|| PlanProblem::NotLatLon.at(at))?;
        let lat = arr.first().and_then(Value::as_f64).ok_or_else(|| PlanProblem::LatitudeNotNumber.at(at))?;
        let lon = arr.get(1).and_then(Value::as_f64).ok_or_else(|| PlanProblem::LongitudeNotNumber.at(at))?;
        origin.to_local(lat, lon).map_err(|e| e.at(at))
    };
    if let Some(polys) = fence.get("polygons") {
        let polys = polys.as_array().ok_or(PlanProblem::NotAList("geoFence.polygons"))?;
        for (i, p) in polys.iter().enumerate() {
            let at = format!("geoFence.polygons[{i}]");
            let include = inclusion(p, &at)?;
            let verts =
                p.get("polygon").and_then(Value::as_array).ok_or_else(|| PlanProblem::NoPolygon.at(at.as_str()))?;
            if verts.len() < 3 {
                return Err(PlanProblem::TooFewVertices(verts.len()).at(at));
            }
            let pts = verts
                .iter()
                .enumerate()
                .map(|(j, v)| latlon(v, &format!("{at}.polygon[{j}]")))
                .collect::<Result<Vec<_>, _>>()?;
            if include { inside.push(pts) } else { zones.push(pts) }
        }
    }
    if let Some(circles) = fence.get("circles") {
        let circles = circles.as_array().ok_or(PlanProblem::NotAList("geoFence.circles"))?;
        for (i, c) in circles.iter().enumerate() {
            let at = format!("geoFence.circles[{i}]");
            let include = inclusion(c, &at)?;
            let circle = c.get("circle").ok_or_else(|| PlanProblem::NoCircle.at(at.as_str()))?;
            let center = latlon(circle.get("center").unwrap_or(&Value::Null), &format!("{at}.circle.center"))?;
            let radius = circle
                .get("radius")
                .and_then(Value::as_f64)
                .filter(|r| r.is_finite() && *r > 0.0)
                .ok_or_else(|| PlanProblem::BadRadius.at(format!("{at}.circle.radius")))?;
            // Exclusion: the polygon around the circle; inclusion: the polygon inside it. Either
            // way the polygon errs on the safe side.
            let r = if include { radius } else { radius / (PI / CIRCLE_SIDES as f64).cos() };
            let polygon = (0..CIRCLE_SIDES)
                .map(|k| {
                    let a = 2.0 * PI * k as f64 / CIRCLE_SIDES as f64;
                    Point2::new(center.x + r * a.cos(), center.y + r * a.sin())
                })
                .collect();
            if include { inside.push(polygon) } else { zones.push(polygon) }
        }
    }
    Ok((zones, inside))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plan_path_that_is_no_regular_file_is_refused_without_reading_it() {
        // /dev/zero would be read until memory ran out.
        let e = load_plan(Path::new("/dev/zero"), None).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("not a regular file"), "{e}");
        let e = load_plan(Path::new("/no/such/plan.plan"), None).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("cannot read the file"), "{e}");
    }

    fn plan(items: &str, fence: &str) -> String {
        format!(
            r#"{{"fileType": "Plan", "geoFence": {fence}, "mission": {{"items": [{items}],
               "plannedHomePosition": [39.9526, -75.1652, 0]}}}}"#
        )
    }

    fn wp(command: u32, lat: f64, lon: f64) -> String {
        format!(
            r#"{{"type": "SimpleItem", "command": {command}, "frame": 3, "params": [0, 0, 0, null, {lat}, {lon}, 60]}}"#
        )
    }

    #[test]
    fn waypoints_are_metres_on_the_tangent_plane_and_non_navigation_items_are_skipped() {
        let items =
            [wp(22, 0.0, 0.0), wp(16, 39.95273475, -75.16502422), wp(178, 0.0, 0.0), wp(16, 39.95300424, -75.16068838)]
                .join(",");
        let p = parse_plan(&plan(&items, "{}"), None).unwrap();
        assert_eq!(p.waypoints.len(), 2);
        let a = p.waypoints[0].position;
        let b = p.waypoints[1].position;
        assert!((a.x - 15.0).abs() < 0.01 && (a.y - 15.0).abs() < 0.01, "{a:?}");
        assert!((b.x - 385.0).abs() < 0.01 && (b.y - 45.0).abs() < 0.01, "{b:?}");
        assert_eq!(p.waypoints[0].altitude_m, 60.0);
    }

    #[test]
    fn exclusion_fences_become_zones_and_inclusion_fences_become_fences() {
        let fence = r#"{"version": 2, "polygons": [{"inclusion": false, "version": 1,
            "polygon": [[39.9527, -75.1650], [39.9527, -75.1640], [39.9530, -75.1640]]}],
            "circles": [{"inclusion": false, "version": 1, "circle": {"center": [39.9530, -75.1630], "radius": 10}}]}"#;
        let p = parse_plan(&plan(&wp(16, 39.9527, -75.1651), fence), None).unwrap();
        assert_eq!(p.no_fly.len(), 2);
        assert!(p.fly_inside.is_empty());
        assert_eq!(p.no_fly[1].len(), CIRCLE_SIDES);
        // The exclusion polygon circumscribes its circle: its vertices lie beyond the radius.
        let centre = p.no_fly[1].iter().fold(Point2::new(0.0, 0.0), |a, b| a + *b) * (1.0 / CIRCLE_SIDES as f64);
        assert!(p.no_fly[1].iter().all(|v| v.distance(centre) > 10.0));

        let both = fence.replace("\"inclusion\": false", "\"inclusion\": true");
        let p = parse_plan(&plan(&wp(16, 39.9527, -75.1651), &both), None).unwrap();
        assert!(p.no_fly.is_empty());
        assert_eq!(p.fly_inside.len(), 2);
        // The inclusion polygon is inscribed: its vertices lie on the circle.
        let centre = p.fly_inside[1].iter().fold(Point2::new(0.0, 0.0), |a, b| a + *b) * (1.0 / CIRCLE_SIDES as f64);
        assert!(p.fly_inside[1].iter().all(|v| (v.distance(centre) - 10.0).abs() < 1e-6));

        let missing = fence.replacen("\"inclusion\": false, ", "", 1);
        let e = parse_plan(&plan(&wp(16, 39.9527, -75.1651), &missing), None).unwrap_err().to_string();
        assert!(e.contains("geoFence.polygons[0]") && e.contains("missing `inclusion`"), "{e}");
    }

    /// A plan as QGroundControl writes it, its home far from the map origin: placed through the
    /// area's GPS reference, every point lands where its coordinates say; the home is flown to
    /// only by the return to launch.
    #[test]
    fn a_georeferenced_plan_is_placed_by_its_coordinates_not_its_home() {
        let origin = GeoPoint::new(39.95, -75.19);
        let at = |x: f64, y: f64| {
            let lat = 39.95 + (y / spomp_core::geo::EARTH_RADIUS_M).to_degrees();
            let lon = -75.19 + (x / (spomp_core::geo::EARTH_RADIUS_M * 39.95f64.to_radians().cos())).to_degrees();
            (lat, lon)
        };
        let item = |cmd: u32, x: f64, y: f64| {
            let (lat, lon) = at(x, y);
            format!(
                r#"{{"type": "SimpleItem", "command": {cmd}, "frame": 3, "autoContinue": true, "doJumpId": 1,
                "params": [0, 0, 0, null, {lat}, {lon}, 50], "Altitude": 50, "AltitudeMode": 1}}"#
            )
        };
        let camera = r#"{"type": "SimpleItem", "command": 206, "frame": 2, "params": [0, 0, 1, 1, 0, 0, 0]}"#;
        let survey = format!(
            r#"{{"type": "ComplexItem", "complexItemType": "survey", "version": 5, "angle": 0,
               "polygon": [[39.95, -75.19], [39.951, -75.19], [39.951, -75.189]],
               "TransectStyleComplexItem": {{"version": 1, "CameraShots": 4,
                 "Items": [{}, {camera}, {}, {}]}}}}"#,
            item(16, 40.0, 20.0),
            item(16, 40.0, 80.0),
            item(16, 60.0, 80.0)
        );
        let (hlat, hlon) = at(900.0, -700.0);
        let fence = {
            let v = [at(0.0, 0.0), at(10.0, 0.0), at(10.0, 10.0)];
            format!(
                r#"{{"version": 2, "polygons": [{{"inclusion": false, "version": 1, "polygon": [[{}, {}], [{}, {}], [{}, {}]]}}]}}"#,
                v[0].0, v[0].1, v[1].0, v[1].1, v[2].0, v[2].1
            )
        };
        let items =
            [item(22, 0.0, 0.0), item(16, 20.0, 30.0), survey, item(20, 0.0, 0.0), item(16, 5.0, 5.0)].join(",");
        let text = format!(
            r#"{{"fileType": "Plan", "version": 1, "groundStation": "QGroundControl", "geoFence": {fence},
               "rallyPoints": {{"points": [], "version": 2}},
               "mission": {{"version": 2, "firmwareType": 12, "vehicleType": 2, "cruiseSpeed": 15, "hoverSpeed": 5,
                 "plannedHomePosition": [{hlat}, {hlon}, 12], "items": [{items}]}}}}"#
        );
        let p = parse_plan(&text, Some(origin)).unwrap();
        let got: Vec<(f64, f64)> = p.waypoints.iter().map(|w| (w.position.x, w.position.y)).collect();
        let want = [(20.0, 30.0), (40.0, 20.0), (40.0, 80.0), (60.0, 80.0), (900.0, -700.0)];
        assert_eq!(
            got.len(),
            want.len(),
            "takeoff and camera skipped, the survey's items flown, nothing after RTL: {got:?}"
        );
        for (g, w) in got.iter().zip(want) {
            assert!((g.0 - w.0).abs() < 0.01 && (g.1 - w.1).abs() < 0.01, "{got:?}");
        }
        assert_eq!(p.waypoints[4].altitude_m, 50.0, "RTL at the last altitude");
        assert!(p.no_fly[0][1].distance(Point2::new(10.0, 0.0)) < 0.01, "{:?}", p.no_fly);
        // Without a GPS reference the home is the origin: the same waypoint lands 900 m west.
        let p = parse_plan(&text, None).unwrap();
        assert!((p.waypoints[0].position.x - (20.0 - 900.0)).abs() < 0.5, "{:?}", p.waypoints[0]);
        // A survey QGroundControl never generated items for is named.
        let empty = text.replace(
            &format!("[{}, {camera}, {}, {}]", item(16, 40.0, 20.0), item(16, 40.0, 80.0), item(16, 60.0, 80.0)),
            "[]",
        );
        let e = parse_plan(&empty, Some(origin)).unwrap_err().to_string();
        assert!(e.contains("mission.items[2]") && e.contains("no generated items"), "{e}");
        // A point far from the map origin is refused, naming the reference.
        let far = parse_plan(&plan(&wp(16, 41.0, -75.1651), "{}"), Some(origin)).unwrap_err().to_string();
        assert!(far.contains("km from the map origin"), "{far}");
    }

    /// Callers tell problems apart by variant, with the place in the file beside them.
    #[test]
    fn problems_are_typed_and_located() {
        let e = parse_plan(&plan(&wp(21, 39.9527, -75.1651), "{}"), None).unwrap_err();
        let PlanProblem::At { at, problem } = &e else { panic!("{e:?}") };
        assert_eq!(at, "mission.items[0]");
        assert_eq!(**problem, PlanProblem::UnsupportedCommand { command: 21, name: "NAV_LAND" });
        assert_eq!(parse_plan("[]", None).unwrap_err(), PlanProblem::NotAnObject("a list"));
        let e = load_plan(Path::new("/no/such/plan.plan"), None).unwrap_err();
        assert_eq!(e.path, Path::new("/no/such/plan.plan"));
        assert!(matches!(e.problem, PlanProblem::Unreadable(_)), "{e:?}");
    }

    #[test]
    fn unsupported_items_are_named() {
        let e = parse_plan(&plan(&wp(21, 39.9527, -75.1651), "{}"), None).unwrap_err().to_string();
        assert!(e.contains("mission.items[0]") && e.contains("21 NAV_LAND"), "{e}");
        let survey = r#"{"type": "ComplexItem", "complexItemType": "survey"}"#;
        let e = parse_plan(&plan(survey, "{}"), None).unwrap_err().to_string();
        assert!(e.contains("complex item `survey`"), "{e}");
        let far = parse_plan(&plan(&wp(16, 41.0, -75.1651), "{}"), None).unwrap_err().to_string();
        assert!(far.contains("km from the plan's home"), "{far}");
    }
}
