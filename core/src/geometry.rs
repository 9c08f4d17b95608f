//! Planar geometry in the map frame: x east, y north, yaw counter-clockwise from +x, metres and
//! radians.

use std::f64::consts::PI;
use std::ops::{Add, Mul, Sub};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Wraps an angle to (−π, π].
pub fn normalize_angle(a: f64) -> f64 {
    let mut r = (a + PI).rem_euclid(2.0 * PI) - PI;
    if r <= -PI {
        r += 2.0 * PI;
    }
    r
}

/// A point (or vector) in the plane, metres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Point2 {
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
}

impl Point2 {
    /// A point.
    pub const fn new(x: f64, y: f64) -> Self {
        Point2 { x, y }
    }

    /// Euclidean norm.
    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }

    /// Distance to `other`.
    pub fn distance(self, other: Point2) -> f64 {
        (self - other).norm()
    }

    /// Dot product.
    pub fn dot(self, other: Point2) -> f64 {
        self.x * other.x + self.y * other.y
    }

    /// The z component of the 3D cross product.
    pub fn cross(self, other: Point2) -> f64 {
        self.x * other.y - self.y * other.x
    }

    /// Angle of the vector from +x, radians.
    pub fn angle(self) -> f64 {
        self.y.atan2(self.x)
    }
}

impl Add for Point2 {
    type Output = Point2;
    fn add(self, o: Point2) -> Point2 {
        Point2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for Point2 {
    type Output = Point2;
    fn sub(self, o: Point2) -> Point2 {
        Point2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for Point2 {
    type Output = Point2;
    fn mul(self, s: f64) -> Point2 {
        Point2::new(self.x * s, self.y * s)
    }
}

/// A planar pose: position and heading.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Pose2 {
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
    /// Heading, radians counter-clockwise from +x.
    #[serde(default)]
    pub yaw: f64,
}

impl Pose2 {
    /// A pose.
    pub const fn new(x: f64, y: f64, yaw: f64) -> Self {
        Pose2 { x, y, yaw }
    }

    /// The position.
    pub fn position(self) -> Point2 {
        Point2::new(self.x, self.y)
    }

    /// `self ⊕ other`: `other` expressed in this pose's frame, taken to the parent frame.
    pub fn compose(self, other: Pose2) -> Pose2 {
        let p = self.transform_point(other.position());
        Pose2::new(p.x, p.y, normalize_angle(self.yaw + other.yaw))
    }

    /// The inverse transform.
    pub fn inverse(self) -> Pose2 {
        let (s, c) = self.yaw.sin_cos();
        Pose2::new(-c * self.x - s * self.y, s * self.x - c * self.y, normalize_angle(-self.yaw))
    }

    /// The pose of `other` relative to `self` (`self⁻¹ ⊕ other`).
    pub fn between(self, other: Pose2) -> Pose2 {
        self.inverse().compose(other)
    }

    /// A point in this pose's frame, taken to the parent frame.
    pub fn transform_point(self, p: Point2) -> Point2 {
        let (s, c) = self.yaw.sin_cos();
        Point2::new(self.x + c * p.x - s * p.y, self.y + s * p.x + c * p.y)
    }

    /// A point in the parent frame, taken into this pose's frame.
    pub fn inverse_transform_point(self, p: Point2) -> Point2 {
        let (s, c) = self.yaw.sin_cos();
        let d = p - self.position();
        Point2::new(c * d.x + s * d.y, -s * d.x + c * d.y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn close(a: Pose2, b: Pose2) -> bool {
        (a.x - b.x).abs() < 1e-9 && (a.y - b.y).abs() < 1e-9 && normalize_angle(a.yaw - b.yaw).abs() < 1e-9
    }

    #[test]
    fn normalize_wraps_into_half_open_interval() {
        assert!((normalize_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((normalize_angle(-PI) - PI).abs() < 1e-12);
        assert!((normalize_angle(0.5) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn transform_point_rotates_then_translates() {
        let p = Pose2::new(1.0, 2.0, PI / 2.0).transform_point(Point2::new(1.0, 0.0));
        assert!((p.x - 1.0).abs() < 1e-12 && (p.y - 3.0).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn compose_with_inverse_is_identity(x in -1e3..1e3f64, y in -1e3..1e3f64, yaw in -7.0..7.0f64) {
            let p = Pose2::new(x, y, yaw);
            prop_assert!(close(p.compose(p.inverse()), Pose2::default()));
            prop_assert!(close(p.between(p), Pose2::default()));
        }

        #[test]
        fn point_round_trip(x in -1e3..1e3f64, y in -1e3..1e3f64, yaw in -7.0..7.0f64, px in -50.0..50.0f64, py in -50.0..50.0f64) {
            let pose = Pose2::new(x, y, yaw);
            let q = pose.inverse_transform_point(pose.transform_point(Point2::new(px, py)));
            prop_assert!((q.x - px).abs() < 1e-9 && (q.y - py).abs() < 1e-9);
        }
    }
}
