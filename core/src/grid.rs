//! Regular grids in the map frame (aerial maps, worlds, cost layers).
//!
//! Cell (col, row) covers x ∈ [origin.x + col·res, origin.x + (col+1)·res) and
//! y ∈ [origin.y + row·res, …): row 0 is the southern edge, rows grow north. Storage is row-major.

use serde::{Deserialize, Serialize};

use crate::geometry::Point2;

/// A cell index: column (x) and row (y).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Cell {
    /// Column, along +x.
    pub col: u32,
    /// Row, along +y.
    pub row: u32,
}

impl Cell {
    /// A cell.
    pub const fn new(col: u32, row: u32) -> Self {
        Cell { col, row }
    }
}

/// Placement and size of a grid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridSpec {
    /// Map-frame position of the south-west corner of cell (0, 0).
    pub origin: Point2,
    /// Edge length of a cell, metres.
    pub resolution_m: f64,
    /// Number of columns.
    pub width: u32,
    /// Number of rows.
    pub height: u32,
}

impl GridSpec {
    /// A grid spec.
    pub fn new(origin: Point2, resolution_m: f64, width: u32, height: u32) -> Self {
        GridSpec { origin, resolution_m, width, height }
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether the grid has no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Row-major index of a cell (the caller guarantees it is inside).
    #[inline]
    pub fn index(&self, c: Cell) -> usize {
        c.row as usize * self.width as usize + c.col as usize
    }

    /// The cell at a row-major index.
    #[inline]
    pub fn cell_of_index(&self, i: usize) -> Cell {
        let w = self.width as usize;
        Cell::new((i % w) as u32, (i / w) as u32)
    }

    /// The cell containing a map point, if it is on the grid.
    #[inline]
    pub fn cell_at(&self, p: Point2) -> Option<Cell> {
        let fx = ((p.x - self.origin.x) / self.resolution_m).floor();
        let fy = ((p.y - self.origin.y) / self.resolution_m).floor();
        if fx < 0.0 || fy < 0.0 || fx >= self.width as f64 || fy >= self.height as f64 {
            return None;
        }
        Some(Cell::new(fx as u32, fy as u32))
    }

    /// The map point at the centre of a cell.
    #[inline]
    pub fn center(&self, c: Cell) -> Point2 {
        Point2::new(
            self.origin.x + (c.col as f64 + 0.5) * self.resolution_m,
            self.origin.y + (c.row as f64 + 0.5) * self.resolution_m,
        )
    }

    /// Whether signed cell coordinates are on the grid.
    #[inline]
    pub fn contains(&self, col: i64, row: i64) -> bool {
        col >= 0 && row >= 0 && col < self.width as i64 && row < self.height as i64
    }

    /// Size in metres (width, height).
    pub fn size_m(&self) -> (f64, f64) {
        (self.width as f64 * self.resolution_m, self.height as f64 * self.resolution_m)
    }
}

/// A grid of values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid<T> {
    /// Placement and size.
    pub spec: GridSpec,
    /// Row-major values, `spec.len()` of them.
    pub data: Vec<T>,
}

impl<T: Clone> Grid<T> {
    /// A grid filled with `value`.
    pub fn filled(spec: GridSpec, value: T) -> Self {
        Grid { data: vec![value; spec.len()], spec }
    }
}

impl<T> Grid<T> {
    /// The value of a cell (the caller guarantees it is inside).
    #[inline]
    pub fn at(&self, c: Cell) -> &T {
        &self.data[self.spec.index(c)]
    }

    /// The value of a cell, mutable.
    #[inline]
    pub fn at_mut(&mut self, c: Cell) -> &mut T {
        let i = self.spec.index(c);
        &mut self.data[i]
    }

    /// The value at a map point, if on the grid.
    #[inline]
    pub fn get(&self, p: Point2) -> Option<&T> {
        self.spec.cell_at(p).map(|c| self.at(c))
    }

    /// The value at signed cell coordinates, if on the grid.
    #[inline]
    pub fn get_cell(&self, col: i64, row: i64) -> Option<&T> {
        if self.spec.contains(col, row) {
            Some(&self.data[row as usize * self.spec.width as usize + col as usize])
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cell_round_trip_and_bounds() {
        let spec = GridSpec::new(Point2::new(-10.0, 5.0), 0.5, 40, 20);
        let c = spec.cell_at(Point2::new(-9.76, 5.26)).unwrap();
        assert_eq!(c, Cell::new(0, 0));
        assert_eq!(spec.center(c), Point2::new(-9.75, 5.25));
        assert_eq!(spec.cell_at(Point2::new(9.99, 14.99)), Some(Cell::new(39, 19)));
        assert_eq!(spec.cell_at(Point2::new(10.0, 6.0)), None);
        assert_eq!(spec.cell_at(Point2::new(-10.01, 6.0)), None);
        assert_eq!(spec.cell_of_index(spec.index(Cell::new(7, 3))), Cell::new(7, 3));
    }
}
