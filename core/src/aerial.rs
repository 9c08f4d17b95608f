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

    /// Visits the cells of a consistent tile that lie on a map of `spec` and are not unknown in
    /// the tile: `(map index, tile index)`, row by row, until `visit` returns false.
    fn for_each_tile_cell(spec: GridSpec, tile: &MapTile, mut visit: impl FnMut(usize, usize) -> bool) {
        for tr in 0..tile.height {
            let row = tile.row0 as u64 + tr as u64;
            if row >= spec.height as u64 {
                break;
            }
            for tc in 0..tile.width {
                let col = tile.col0 as u64 + tc as u64;
                if col >= spec.width as u64 {
                    break;
                }
                let ti = tr as usize * tile.width as usize + tc as usize;
                if tile.class[ti] == UNKNOWN_CLASS {
                    continue;
                }
                if !visit(spec.index(Cell::new(col as u32, row as u32)), ti) {
                    return;
                }
            }
        }
    }

    /// Whether writing the tile's cell `ti` into map cell `mi` would change the map.
    #[inline]
    fn cell_differs(&self, tile: &MapTile, mi: usize, ti: usize) -> bool {
        let elev = tile.elevation[ti];
        let same_elev = self.elevation[mi] == elev || (elev.is_nan() && self.elevation[mi].is_nan());
        self.class[mi] != tile.class[ti] || self.rgb[mi] != tile.rgb[ti] || !same_elev
    }

    /// Whether [`Self::apply_tile`] would change any cell: a map shared with others is only
    /// copied when it would.
    pub fn tile_changes_anything(&self, tile: &MapTile) -> bool {
        if !tile.is_consistent() {
            return false;
        }
        let mut differs = false;
        Self::for_each_tile_cell(self.spec, tile, |mi, ti| {
            differs = self.cell_differs(tile, mi, ti);
            !differs
        });
        differs
    }

    /// Writes a tile into the map, clipped to the map; returns the number of cells changed.
    /// The version increases when anything changed.
    pub fn apply_tile(&mut self, tile: &MapTile) -> usize {
        if !tile.is_consistent() {
            return 0;
        }
        let mut changed = 0;
        Self::for_each_tile_cell(self.spec, tile, |mi, ti| {
            if self.cell_differs(tile, mi, ti) {
                self.class[mi] = tile.class[ti];
                self.rgb[mi] = tile.rgb[ti];
                let elev = tile.elevation[ti];
                if !elev.is_nan() {
                    self.elevation[mi] = elev;
                }
                changed += 1;
            }
            true
        });
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
    fn a_tile_changes_the_map_exactly_when_applying_it_would() {
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 4, 3));
        let tile = MapTile {
            col0: 1,
            row0: 0,
            width: 2,
            height: 2,
            class: vec![3, 3, UNKNOWN_CLASS, 3],
            rgb: vec![[9, 9, 9]; 4],
            elevation: vec![0.2, f32::NAN, 0.2, 0.2],
        };
        assert!(map.tile_changes_anything(&tile));
        assert_eq!(map.apply_tile(&tile), 3);
        assert!(!map.tile_changes_anything(&tile), "the same tile again changes nothing");
        let mut recoloured = tile.clone();
        recoloured.rgb[3] = [1, 1, 1];
        assert!(map.tile_changes_anything(&recoloured));
        let mut only_unknown = tile.clone();
        only_unknown.class = vec![UNKNOWN_CLASS; 4];
        only_unknown.rgb = vec![[0, 0, 0]; 4];
        assert!(!map.tile_changes_anything(&only_unknown), "unknown tile cells are never applied");
    }

    #[test]
    fn inconsistent_tile_is_ignored() {
        let mut map = AerialMap::unknown(GridSpec::new(Point2::new(0.0, 0.0), 0.5, 4, 3));
        let tile = MapTile { col0: 0, row0: 0, width: 2, height: 2, class: vec![0], rgb: vec![], elevation: vec![] };
        assert_eq!(map.apply_tile(&tile), 0);
    }
}
