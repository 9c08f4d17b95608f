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
use std::fmt;
use std::path::{Path, PathBuf};

use serde_json::Value;
use spomp_behaviors::mission::limits::{MAX_SOURCE_BYTES, read_text};
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

/// Why a plan file cannot be flown.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PlanError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong, and where in the file.
    pub message: String,
}

impl fmt::Display for PlanError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "QGroundControl plan `{}`: {}", self.path.display(), self.message)
    }
}

impl std::error::Error for PlanError {}

/// Reads and interprets a `.plan` file, placed through `map_origin` when the operating area is
/// georeferenced (else around the plan's home).
pub(crate) fn load_plan(path: &Path, map_origin: Option<GeoPoint>) -> Result<QgcPlan, PlanError> {
    let error = |message: String| PlanError { path: path.to_path_buf(), message };
    // The loader checked the file, but it is read again here when the tree is built: the same
    // rules (a regular file, at most the mission language's size limit) hold at this read too.
    let text = read_text(path, MAX_SOURCE_BYTES).map_err(|e| error(format!("cannot read the file: {e}")))?;
    parse_plan(&text, map_origin).map_err(error)
}

/// The waypoints of a QGroundControl `.plan` file in the map frame, read and placed exactly as
/// `follow_waypoints` reads them over an area whose origin lies at `map_origin` (`None`: the
/// plan's planned home is the origin): for checks made outside the node, such as `spomp
/// validate`'s world stage. The error names the file and the problem.
pub fn plan_waypoints(path: &Path, map_origin: Option<GeoPoint>) -> Result<Vec<Point2>, String> {
    load_plan(path, map_origin).map(|p| p.waypoints.iter().map(|w| w.position).collect()).map_err(|e| e.to_string())
}

/// Interprets the text of a `.plan` file; errors say where in the file the problem is.
pub(crate) fn parse_plan(text: &str, map_origin: Option<GeoPoint>) -> Result<QgcPlan, String> {
    let root: Value = serde_json::from_str(text).map_err(|e| format!("not valid JSON: {e}"))?;
    let Some(obj) = root.as_object() else {
        return Err(format!("expected a JSON object with `fileType: \"Plan\"`, found {}", kind(&root)));
    };
    match obj.get("fileType").and_then(Value::as_str) {
        Some("Plan") => {}
        Some(other) => return Err(format!("`fileType` is `{other}`, expected `Plan`")),
        None => return Err("missing `fileType: \"Plan\"`; is this a QGroundControl plan?".into()),
    }
    let mission = obj.get("mission").ok_or("missing the `mission` section")?;
    let home = mission.get("plannedHomePosition").ok_or("missing `mission.plannedHomePosition`")?;
    let (home_lat, home_lon) = home_of(home)?;
    let origin = match map_origin {
        Some(o) => {
            if !(o.latitude_deg.is_finite() && o.latitude_deg.abs() <= 85.0) {
                return Err(format!(
                    "the map origin's latitude {} is too close to a pole for a flat map",
                    o.latitude_deg
                ));
            }
            Origin { at: o, what: "the map origin" }
        }
        None => Origin { at: GeoPoint::new(home_lat, home_lon), what: "the plan's home" },
    };
    let home = origin.to_local(home_lat, home_lon).map_err(|e| format!("`mission.plannedHomePosition`: {e}"))?;

    let items = mission.get("items").and_then(Value::as_array).ok_or("`mission.items` must be a list of items")?;
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

/// The local tangent plane points are placed on.
struct Origin {
    at: GeoPoint,
    /// What the reference is, for errors.
    what: &'static str,
}

impl Origin {
    /// Latitude/longitude in degrees to metres east/north of the origin.
    fn to_local(&self, lat: f64, lon: f64) -> Result<Point2, String> {
        check_lat_lon(lat, lon)?;
        let p = self.at.local_of(lat, lon);
        if p.norm() > MAX_EXTENT_M {
            return Err(format!(
                "({lat}, {lon}) lies {:.0} km from {}; plans must stay within {:.0} km",
                p.norm() / 1000.0,
                self.what,
                MAX_EXTENT_M / 1000.0
            ));
        }
        Ok(p)
    }
}

fn check_lat_lon(lat: f64, lon: f64) -> Result<(), String> {
    if !(lat.is_finite() && (-90.0..=90.0).contains(&lat)) {
        return Err(format!("latitude {lat} is not within [-90, 90] degrees"));
    }
    if !(lon.is_finite() && (-180.0..=180.0).contains(&lon)) {
        return Err(format!("longitude {lon} is not within [-180, 180] degrees"));
    }
    Ok(())
}

fn home_of(home: &Value) -> Result<(f64, f64), String> {
    let bad = || format!("`mission.plannedHomePosition` must be [latitude, longitude, altitude], found {home}");
    let arr = home.as_array().ok_or_else(bad)?;
    let lat = arr.first().and_then(Value::as_f64).ok_or_else(bad)?;
    let lon = arr.get(1).and_then(Value::as_f64).ok_or_else(bad)?;
    check_lat_lon(lat, lon).map_err(|e| format!("`mission.plannedHomePosition`: {e}"))?;
    if lat.abs() > 85.0 {
        return Err(format!("`mission.plannedHomePosition`: latitude {lat} is too close to a pole for a flat map"));
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
    fn item(&mut self, item: &Value, at: &str, out: &mut Vec<PlanWaypoint>) -> Result<(), String> {
        let ty = item
            .get("type")
            .and_then(Value::as_str)
            .ok_or_else(|| format!("{at}: missing the item `type` (SimpleItem or ComplexItem)"))?;
        match ty {
            "SimpleItem" => {}
            "ComplexItem" => {
                let what = item.get("complexItemType").and_then(Value::as_str).unwrap_or("unknown");
                // Surveys and corridor scans carry the simple items QGroundControl generated
                // for them: the route the vehicle is sent.
                let generated = item.get("TransectStyleComplexItem").and_then(|t| t.get("Items"));
                let Some(inner) = generated else {
                    return Err(format!(
                        "{at}: complex item `{what}` is not supported (surveys and corridor scans are, through the \
                         items QGroundControl generated for them in `TransectStyleComplexItem.Items`); replace it \
                         with waypoints"
                    ));
                };
                let inner = inner
                    .as_array()
                    .ok_or_else(|| format!("{at}.TransectStyleComplexItem.Items must be a list of items"))?;
                if inner.is_empty() {
                    return Err(format!(
                        "{at}: complex item `{what}` has no generated items (`TransectStyleComplexItem.Items` is \
                         empty); open and save the plan in QGroundControl to generate them"
                    ));
                }
                for (k, sub) in inner.iter().enumerate() {
                    self.item(sub, &format!("{at}.TransectStyleComplexItem.Items[{k}]"), out)?;
                    if self.returned {
                        break;
                    }
                }
                return Ok(());
            }
            other => return Err(format!("{at}: unknown item type `{other}` (expected SimpleItem or ComplexItem)")),
        }
        let wp = item_waypoint(item, self.origin, self.home, out.last()).map_err(|e| format!("{at}: {e}"))?;
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
) -> Result<Option<(PlanWaypoint, bool)>, String> {
    let command = item.get("command").and_then(Value::as_u64).ok_or("missing the MAVLink `command` number")?;
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
        let flown: Vec<String> = FLOWN.iter().map(|(c, n)| format!("{c} {n}")).collect();
        return Err(format!(
            "navigation command {command} {name} is not supported (flown: {}, 20 NAV_RETURN_TO_LAUNCH; skipped: 22 \
             NAV_TAKEOFF, 84 NAV_VTOL_TAKEOFF, and non-navigation commands ≥ 100)",
            flown.join(", ")
        ));
    }
    let frame = match item.get("frame") {
        None => 3,
        Some(f) => f.as_u64().ok_or_else(|| format!("`frame` must be a MAVLink frame number, found {f}"))?,
    };
    if !GLOBAL_FRAMES.contains(&frame) {
        return Err(format!(
            "frame {frame} is not a global (latitude/longitude) frame; supported frames: {GLOBAL_FRAMES:?}"
        ));
    }
    let params = item.get("params").and_then(Value::as_array).ok_or("missing the 7 `params` of the command")?;
    if params.len() != 7 {
        return Err(format!("a command has 7 `params`, found {}", params.len()));
    }
    let number = |i: usize, what: &str| {
        params.get(i).and_then(Value::as_f64).ok_or_else(|| format!("params[{i}] ({what}) must be a number"))
    };
    let lat = number(4, "latitude")?;
    let lon = number(5, "longitude")?;
    let altitude_m = match params.get(6).and_then(Value::as_f64) {
        Some(a) if a.is_finite() => a,
        _ => item.get("Altitude").and_then(Value::as_f64).ok_or("params[6] (altitude) must be a number")?,
    };
    Ok(Some((PlanWaypoint { position: origin.to_local(lat, lon)?, altitude_m }, false)))
}

/// Number of sides of the polygon that replaces a circular fence.
const CIRCLE_SIDES: usize = 16;

/// The exclusion zones and the inclusion fences of a `geoFence` section.
fn fences(fence: &Value, origin: &Origin) -> Result<(Polygons, Polygons), String> {
    let (mut zones, mut inside) = (Vec::new(), Vec::new());
    let inclusion = |v: &Value, at: &str| -> Result<bool, String> {
        v.get("inclusion").and_then(Value::as_bool).ok_or_else(|| format!("{at}: missing `inclusion` (true or false)"))
    };
    let latlon = |v: &Value, at: &str| -> Result<Point2, String> {
        let arr =
            v.as_array().filter(|a| a.len() >= 2).ok_or_else(|| format!("{at}: expected [latitude, longitude]"))?;
        let lat = arr.first().and_then(Value::as_f64).ok_or_else(|| format!("{at}: latitude must be a number"))?;
        let lon = arr.get(1).and_then(Value::as_f64).ok_or_else(|| format!("{at}: longitude must be a number"))?;
        origin.to_local(lat, lon).map_err(|e| format!("{at}: {e}"))
    };
    if let Some(polys) = fence.get("polygons") {
        let polys = polys.as_array().ok_or("`geoFence.polygons` must be a list")?;
        for (i, p) in polys.iter().enumerate() {
            let at = format!("geoFence.polygons[{i}]");
            let include = inclusion(p, &at)?;
            let verts = p.get("polygon").and_then(Value::as_array).ok_or_else(|| format!("{at}: missing `polygon`"))?;
            if verts.len() < 3 {
                return Err(format!("{at}: a polygon needs at least 3 vertices, found {}", verts.len()));
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
        let circles = circles.as_array().ok_or("`geoFence.circles` must be a list")?;
        for (i, c) in circles.iter().enumerate() {
            let at = format!("geoFence.circles[{i}]");
            let include = inclusion(c, &at)?;
            let circle = c.get("circle").ok_or_else(|| format!("{at}: missing `circle`"))?;
            let center = latlon(circle.get("center").unwrap_or(&Value::Null), &format!("{at}.circle.center"))?;
            let radius = circle
                .get("radius")
                .and_then(Value::as_f64)
                .filter(|r| r.is_finite() && *r > 0.0)
                .ok_or_else(|| format!("{at}.circle.radius: expected a positive number of metres"))?;
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
        let e = parse_plan(&plan(&wp(16, 39.9527, -75.1651), &missing), None).unwrap_err();
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
        let e = parse_plan(&empty, Some(origin)).unwrap_err();
        assert!(e.contains("mission.items[2]") && e.contains("no generated items"), "{e}");
        // A point far from the map origin is refused, naming the reference.
        let far = parse_plan(&plan(&wp(16, 41.0, -75.1651), "{}"), Some(origin)).unwrap_err();
        assert!(far.contains("km from the map origin"), "{far}");
    }

    #[test]
    fn unsupported_items_are_named() {
        let e = parse_plan(&plan(&wp(21, 39.9527, -75.1651), "{}"), None).unwrap_err();
        assert!(e.contains("mission.items[0]") && e.contains("21 NAV_LAND"), "{e}");
        let survey = r#"{"type": "ComplexItem", "complexItemType": "survey"}"#;
        let e = parse_plan(&plan(survey, "{}"), None).unwrap_err();
        assert!(e.contains("complex item `survey`"), "{e}");
        let far = parse_plan(&plan(&wp(16, 41.0, -75.1651), "{}"), None).unwrap_err();
        assert!(far.contains("km from the plan's home"), "{far}");
    }
}
