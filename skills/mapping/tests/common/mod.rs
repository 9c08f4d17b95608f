//! Synthetic aerial maps for tests and benchmarks.
#![allow(dead_code, clippy::unwrap_used)]

use spomp_core::{AerialMap, ClassId, ClassTable, GridSpec, Point2};

pub const ROAD: ClassId = 0;
pub const VEGETATION: ClassId = 1;
pub const BUILDING: ClassId = 2;
pub const GRASS: ClassId = 3;
pub const VEHICLE: ClassId = 4;
pub const GRAVEL: ClassId = 6;

/// A w×h map at 0.5 m, origin (0, 0), all one class, flat.
pub fn flat(w: u32, h: u32, class: ClassId) -> AerialMap {
    let mut m = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, w, h));
    let table = ClassTable::default_table();
    for i in 0..m.class.len() {
        m.class[i] = class;
        m.rgb[i] = table.get(class).map_or([0, 0, 0], |c| c.color);
        m.elevation[i] = 0.0;
    }
    m
}

/// Fills the rectangle [x0, x1) × [y0, y1) (metres) with a class.
pub fn fill(m: &mut AerialMap, x0: f64, y0: f64, x1: f64, y1: f64, class: ClassId) {
    let res = m.spec.resolution_m;
    let (c0, c1) = ((x0 / res).round() as u32, ((x1 / res).round() as u32).min(m.spec.width));
    let (r0, r1) = ((y0 / res).round() as u32, ((y1 / res).round() as u32).min(m.spec.height));
    for r in r0..r1 {
        for c in c0..c1 {
            let i = r as usize * m.spec.width as usize + c as usize;
            m.class[i] = class;
        }
    }
}

/// A 4.5 m × 2 m vehicle with its south-west corner at (x, y).
pub fn vehicle(m: &mut AerialMap, x: f64, y: f64) {
    fill(m, x, y, x + 4.5, y + 2.0, VEHICLE);
}

/// A row of `n` vehicles along x, `gap` metres apart.
pub fn vehicle_row(m: &mut AerialMap, x: f64, y: f64, n: usize, gap: f64) {
    for k in 0..n {
        vehicle(m, x + k as f64 * (4.5 + gap), y);
    }
}

/// A city-like map: grass, a road grid every 60 m (10 m wide) with gravel shoulders, buildings
/// in the blocks, parking lots with vehicle clusters, trees; colours from the class table with
/// per-pixel noise, smooth elevation with building heights. Deterministic.
pub fn city(w: u32, h: u32) -> AerialMap {
    let mut m = flat(w, h, GRASS);
    let (wm, hm) = (w as f64 * 0.5, h as f64 * 0.5);
    let mut x = 0.0;
    while x < wm {
        fill(&mut m, x + 25.0, 0.0, x + 35.0, hm, ROAD);
        fill(&mut m, x + 24.0, 0.0, x + 25.0, hm, GRAVEL);
        x += 60.0;
    }
    let mut y = 0.0;
    while y < hm {
        fill(&mut m, 0.0, y + 25.0, wm, y + 35.0, ROAD);
        y += 60.0;
    }
    let mut bx = 0.0;
    let mut k = 0;
    while bx < wm {
        let mut by = 0.0;
        while by < hm {
            match k % 3 {
                0 => fill(&mut m, bx + 38.0, by + 38.0, bx + 55.0, by + 55.0, BUILDING),
                1 => vehicle_row(&mut m, bx + 37.0, by + 40.0, 3, 2.5),
                _ => fill(&mut m, bx + 40.0, by + 40.0, bx + 50.0, by + 48.0, VEGETATION),
            }
            k += 1;
            by += 60.0;
        }
        bx += 60.0;
    }
    let table = ClassTable::default_table();
    let mut state = 0x2545_f491_4f6c_dd1du64;
    for i in 0..m.class.len() {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let base = table.get(m.class[i]).map_or([0, 0, 0], |c| c.color);
        let noise = (state % 9) as i16 - 4;
        m.rgb[i] = base.map(|v| (v as i16 + noise).clamp(0, 255) as u8);
        let (c, r) = ((i % w as usize) as f32, (i / w as usize) as f32);
        let ground = 0.02 * c + 0.01 * r + (0.05 * c).sin();
        let height = if m.class[i] == BUILDING { 12.0 } else { 0.0 };
        m.elevation[i] = ((ground + height) * 100.0).round() / 100.0;
    }
    m
}
