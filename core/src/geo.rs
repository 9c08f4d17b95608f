//! Where a map frame lies on the Earth.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use crate::Point2;

/// Radius of the WGS-84 ellipsoid at the equator, metres: the sphere the equirectangular
/// approximation below uses (good to well under a metre over the few kilometres of a mission).
pub const EARTH_RADIUS_M: f64 = 6_378_137.0;

/// A WGS-84 latitude and longitude, degrees: the position of a map frame's origin (0, 0) when
/// the map is georeferenced.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GeoPoint {
    /// Latitude, degrees north.
    pub latitude_deg: f64,
    /// Longitude, degrees east.
    pub longitude_deg: f64,
}

impl GeoPoint {
    /// A point from latitude and longitude, degrees.
    pub fn new(latitude_deg: f64, longitude_deg: f64) -> Self {
        GeoPoint { latitude_deg, longitude_deg }
    }

    /// Metres east (x) and north (y) of `self` of the point at `lat_deg`, `lon_deg`, on the
    /// tangent plane at `self` (equirectangular; longitudes wrap across ±180°).
    pub fn local_of(&self, lat_deg: f64, lon_deg: f64) -> Point2 {
        let dlon = (lon_deg - self.longitude_deg + 540.0).rem_euclid(360.0) - 180.0;
        Point2::new(
            EARTH_RADIUS_M * dlon.to_radians() * self.latitude_deg.to_radians().cos(),
            EARTH_RADIUS_M * (lat_deg - self.latitude_deg).to_radians(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_degree_of_latitude_is_about_111_km_and_longitude_shrinks_with_latitude() {
        let o = GeoPoint::new(60.0, 10.0);
        let north = o.local_of(61.0, 10.0);
        assert!((north.y - 111_319.5).abs() < 1.0 && north.x.abs() < 1e-6, "{north:?}");
        let east = o.local_of(60.0, 11.0);
        assert!((east.x - 55_659.7).abs() < 1.0, "{east:?}");
        let across = GeoPoint::new(0.0, 179.9).local_of(0.0, -179.9);
        assert!((across.x - 22_263.9).abs() < 1.0, "{across:?}");
    }
}
