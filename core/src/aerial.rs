//! The aerial orthomap as plain data: class, colour and elevation layers over one grid.
//!
//! The map covers the mission's operating area from the start; cells the UAV has not seen yet
//! hold [`UNKNOWN_CLASS`] and a NaN elevation. It grows by [`MapTile`]s.

use serde::{Deserialize, Serialize};

use crate::classes::{ClassId, UNKNOWN_CLASS};
use crate::grid::{Cell, GridSpec};

/// A rectangular patch of the orthomap, as the UAV's camera reveals it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapTile {
    /// Column of the tile's first cell in the map grid.
    pub col0: u32,
    /// Row of the tile's first cell in the map grid.
    pub row0: u32,
    /// Tile width, cells.
    pub width: u32,
    /// Tile height, cells.
    pub height: u32,
    /// Row-major class labels; [`UNKNOWN_CLASS`] cells are not applied.
    pub class: Vec<ClassId>,
    /// Row-major colours.
    pub rgb: Vec<[u8; 3]>,
    /// Row-major elevations, metres (NaN = unknown, not applied).
    pub elevation: Vec<f32>,
}

impl MapTile {
    /// Whether the layers have the declared size.
    pub fn is_consistent(&self) -> bool {
        let n = self.width as usize * self.height as usize;
        self.class.len() == n && self.rgb.len() == n && self.elevation.len() == n
    }
}

/// The orthomap.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AerialMap {
    /// Placement and size (0.5 m cells by default).
    pub spec: GridSpec,
    /// Class label per cell.
    pub class: Vec<ClassId>,
    /// Colour per cell.
    pub rgb: Vec<[u8; 3]>,
    /// Elevation per cell, metres; NaN where unknown.
    pub elevation: Vec<f32>,
    /// Increases every time a tile changes the map.
    pub version: u64,
}

impl AerialMap {
    /// An all-unknown map.
    pub fn unknown(spec: GridSpec) -> Self {
        AerialMap {
            class: vec![UNKNOWN_CLASS; spec.len()],
            rgb: vec![[0, 0, 0]; spec.len()],
            elevation: vec![f32::NAN; spec.len()],
            version: 0,
            spec,
        }
    }

    /// Class of a cell.
    #[inline]
    pub fn class_at(&self, c: Cell) -> ClassId {
        self.class[self.spec.index(c)]
    }

    /// Whether a cell has been mapped.
    #[inline]
    pub fn is_known(&self, c: Cell) -> bool {
        self.class_at(c) != UNKNOWN_CLASS
    }

    /// Number of mapped cells.
    pub fn known_cells(&self) -> usize {
        self.class.iter().filter(|&&c| c != UNKNOWN_CLASS).count()
    }

    /// Writes a tile into the map, clipped to the map; returns the number of cells changed.
    /// The version increases when anything changed.
    pub fn apply_tile(&mut self, tile: &MapTile) -> usize {
        if !tile.is_consistent() {
            return 0;
        }
        let mut changed = 0;
        for tr in 0..tile.height {
            let row = tile.row0 as u64 + tr as u64;
            if row >= self.spec.height as u64 {
                break;
            }
            for tc in 0..tile.width {
                let col = tile.col0 as u64 + tc as u64;
                if col >= self.spec.width as u64 {
                    break;
                }
                let ti = tr as usize * tile.width as usize + tc as usize;
                let class = tile.class[ti];
                if class == UNKNOWN_CLASS {
                    continue;
                }
                let mi = self.spec.index(Cell::new(col as u32, row as u32));
                let elev = tile.elevation[ti];
                let same_elev = self.elevation[mi] == elev || (elev.is_nan() && self.elevation[mi].is_nan());
                if self.class[mi] != class || self.rgb[mi] != tile.rgb[ti] || !same_elev {
                    self.class[mi] = class;
                    self.rgb[mi] = tile.rgb[ti];
                    if !elev.is_nan() {
                        self.elevation[mi] = elev;
                    }
                    changed += 1;
                }
            }
        }
        if changed > 0 {
            self.version += 1;
        }
        changed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Point2;

    #[test]
    fn tiles_grow_the_map_and_bump_the_version() {
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 4, 3));
        let tile = MapTile {
            col0: 2,
            row0: 1,
            width: 3,
            height: 1,
            class: vec![0, UNKNOWN_CLASS, 4],
            rgb: vec![[1, 2, 3]; 3],
            elevation: vec![0.5; 3],
        };
        assert_eq!(map.apply_tile(&tile), 1, "one cell inside, one unknown, one clipped");
        assert_eq!(map.version, 1);
        assert_eq!(map.class_at(Cell::new(2, 1)), 0);
        assert_eq!(map.apply_tile(&tile), 0);
        assert_eq!(map.version, 1, "re-applying the same tile changes nothing");
        assert_eq!(map.known_cells(), 1);
    }

    #[test]
    fn inconsistent_tile_is_ignored() {
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 4, 3));
        let tile = MapTile { col0: 0, row0: 0, width: 2, height: 2, class: vec![0], rgb: vec![], elevation: vec![] };
        assert_eq!(map.apply_tile(&tile), 0);
    }
}
