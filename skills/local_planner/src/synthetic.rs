//! A small ray caster that renders depth panoramas of simple scenes, following the core panorama
//! convention exactly (row 0 at +v_fov/2, column 0 along +x, azimuth decreasing with the
//! column). Used by the tests and benchmarks; also handy for tools.
//!
//! Coordinates are in the sensor frame: x forward, y left, z up, the sensor at the origin, so
//! flat ground lies at z = −sensor height.

use spomp_core::{DepthPanorama, PanoramaGeometry};

/// One solid or surface of a scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Primitive {
    /// The horizontal plane z = `z_m` (seen from above only).
    Ground {
        /// Height of the plane, metres (negative: below the sensor).
        z_m: f64,
    },
    /// A ramp rising from the line x = `start_x_m` (where its height is `z_m`) with slope
    /// `grade` (rise over run) for all x ≥ `start_x_m`, any y.
    Ramp {
        /// Where the ramp starts, metres along x.
        start_x_m: f64,
        /// Height at the start line, metres.
        z_m: f64,
        /// Rise over run.
        grade: f64,
    },
    /// An axis-aligned box: walls, curbs (a long low box), cars.
    Box {
        /// Lower corner (x, y, z), metres.
        min: [f64; 3],
        /// Upper corner (x, y, z), metres.
        max: [f64; 3],
    },
}

impl Primitive {
    /// Distance along the unit ray `dir` from the origin to the first hit, if any.
    pub fn intersect(&self, dir: [f64; 3]) -> Option<f64> {
        match *self {
            Primitive::Ground { z_m } => (dir[2] < 0.0 && z_m < 0.0).then(|| z_m / dir[2]).filter(|t| t.is_finite()),
            Primitive::Ramp { start_x_m, z_m, grade } => {
                // z = z0 + g (x − x0) with x = t dx, z = t dz.
                let den = dir[2] - grade * dir[0];
                if den == 0.0 {
                    return None;
                }
                let t = (z_m - grade * start_x_m) / den;
                (t > 0.0 && t * dir[0] >= start_x_m).then_some(t)
            }
            Primitive::Box { min, max } => {
                let (mut near, mut far) = (0.0f64, f64::INFINITY);
                for k in 0..3 {
                    if dir[k] == 0.0 {
                        if 0.0 < min[k] || 0.0 > max[k] {
                            return None;
                        }
                        continue;
                    }
                    let (a, b) = (min[k] / dir[k], max[k] / dir[k]);
                    near = near.max(a.min(b));
                    far = far.min(a.max(b));
                }
                (near <= far && near > 0.0).then_some(near)
            }
        }
    }
}

fn span(a: f64, b: f64) -> (f64, f64) {
    (a.min(b), a.max(b))
}

/// A scene to render.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// The primitives; a ray returns its nearest hit.
    pub primitives: Vec<Primitive>,
    /// Hits beyond this range give no return, metres.
    pub max_range_m: f64,
}

impl Scene {
    /// Flat ground `sensor_height_m` below the sensor, nothing else.
    pub fn flat(sensor_height_m: f64) -> Self {
        Scene { primitives: vec![Primitive::Ground { z_m: -sensor_height_m }], max_range_m: 100.0 }
    }

    /// Adds a primitive.
    pub fn with(mut self, primitive: Primitive) -> Self {
        self.primitives.push(primitive);
        self
    }

    /// A street seen from its centre line: ground, raised sidewalks with curbs on both sides,
    /// building fronts, a few parked cars and boxes, a light pole. Used by the benchmarks.
    pub fn street(sensor_height_m: f64) -> Self {
        let ground = -sensor_height_m;
        let curb = ground + 0.15;
        let mut s = Scene::flat(sensor_height_m);
        for side in [-1.0f64, 1.0] {
            let (lo, hi) = span(side * 4.0, side * 7.0);
            s = s.with(Primitive::Box { min: [-60.0, lo, ground - 1.0], max: [60.0, hi, curb] });
            let (lo, hi) = span(side * 7.0, side * 12.0);
            s = s.with(Primitive::Box { min: [-60.0, lo, ground], max: [60.0, hi, ground + 9.0] });
        }
        for (x, y) in [(6.0, 2.8), (-5.0, -2.9), (14.0, -2.8)] {
            s = s.with(Primitive::Box { min: [x - 2.2, y - 0.9, ground], max: [x + 2.2, y + 0.9, ground + 1.5] });
        }
        s.with(Primitive::Box { min: [3.0, -0.8, ground], max: [3.6, -0.2, ground + 0.6] })
            .with(Primitive::Box { min: [-2.5, 4.5, ground], max: [-2.3, 4.7, ground + 5.0] })
    }

    /// Range of the nearest hit along azimuth `azimuth` and elevation `elevation`, 0 if none.
    pub fn cast(&self, azimuth: f64, elevation: f64) -> f64 {
        let (se, ce) = elevation.sin_cos();
        let (sa, ca) = azimuth.sin_cos();
        let dir = [ce * ca, ce * sa, se];
        let nearest = self.primitives.iter().filter_map(|p| p.intersect(dir)).fold(f64::INFINITY, f64::min);
        if nearest <= self.max_range_m { nearest } else { 0.0 }
    }

    /// Renders a depth panorama of the scene.
    pub fn render(&self, geometry: PanoramaGeometry) -> DepthPanorama {
        let mut pano = DepthPanorama::empty(geometry);
        for row in 0..geometry.rows {
            let elevation = geometry.elevation_of_row(row);
            for col in 0..geometry.cols {
                pano.range_m[row * geometry.cols + col] = self.cast(geometry.azimuth_of_col(col), elevation) as f32;
            }
        }
        pano
    }
}

/// Adds zero-mean noise of standard deviation about `sigma_m` (sum of uniforms) to every return
/// and drops a fraction `dropout` of the returns, deterministically for `rng`.
pub fn add_noise(pano: &mut DepthPanorama, sigma_m: f64, dropout: f64, rng: &mut impl rand::Rng) {
    // The sum of three U(−1, 1) has variance 1: scale by sigma.
    for r in pano.range_m.iter_mut().filter(|r| **r > 0.0) {
        if rng.random::<f64>() < dropout {
            *r = 0.0;
            continue;
        }
        let n: f64 = (0..3).map(|_| rng.random::<f64>() * 2.0 - 1.0).sum();
        *r = (*r as f64 + sigma_m * n).max(0.0) as f32;
    }
}
