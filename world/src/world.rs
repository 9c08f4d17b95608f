//! The simulated world: a 2.5D grid (class, elevation, colour) plus the class table and the
//! ground truth a generator knows about it.

use std::sync::Arc;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use spomp_core::{AerialMap, Cell, ClassId, ClassTable, GeoPoint, GridSpec, Point2, Pose2};

use crate::error::WorldError;

/// What the world's author knows that the robots must find out: scoring ground truth and where
/// a team may start.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct WorldMeta {
    /// Centre of every vehicle cluster (ground truth for scoring goal detection), map frame.
    pub vehicle_clusters: Vec<Point2>,
    /// Centre of every roadblock (physically high, labelled road).
    pub roadblocks: Vec<Point2>,
    /// Free start poses for a team, in order of use.
    pub start_poses: Vec<Pose2>,
    /// Where the map frame's origin (0, 0) lies on the Earth, for a georeferenced world
    /// (`spomp world import --gps-reference`): QGroundControl plans flown in it are placed by
    /// their coordinates through it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gps_origin: Option<GeoPoint>,
}

/// The simulated world.
///
/// The layers live in an [`AerialMap`] whose every cell is known: the ground truth bodies and
/// sensors meet. The UAV reveals tiles of the world as seen from above, which are these layers
/// unless the world has an aerial view of its own ([`World::set_aerial_view`]: a barrier under
/// canopy, a fence too thin for an aerial map). Elevations are finite (metres above the
/// world's datum).
#[derive(Clone, Debug, PartialEq)]
pub struct World {
    /// Class, colour and elevation layers (private: the highest elevation is cached).
    map: Arc<AerialMap>,
    /// The world seen from above where it differs from the ground: what a prior map holds and
    /// the UAV's tiles show. `None`: the ground layers themselves. Shared: robots that start
    /// with the whole map (`sim.prior_map`) hold these very layers until they change their copy.
    aerial: Option<Arc<AerialMap>>,
    /// The class table the class layer refers to.
    classes: ClassTable,
    /// Ground truth and start poses.
    pub meta: WorldMeta,
    /// Upper bound of the elevations, metres (kept for the renderer's early exit).
    max_elevation_m: f32,
}

impl World {
    /// A world from its layers. Checks that the layers fit the grid, the resolution is positive,
    /// every class is in the table and every elevation is finite.
    pub fn new(map: AerialMap, classes: ClassTable, meta: WorldMeta) -> Result<Self, WorldError> {
        let n = map.spec.len();
        if !(map.spec.resolution_m.is_finite() && map.spec.resolution_m > 0.0) {
            return Err(WorldError::invalid("world", "resolution must be positive"));
        }
        if map.spec.is_empty() {
            return Err(WorldError::invalid("world", "the grid has no cells"));
        }
        if map.class.len() != n || map.rgb.len() != n || map.elevation.len() != n {
            return Err(WorldError::invalid("world", "layer lengths differ from the grid size"));
        }
        let mut known = [false; 256];
        for c in &classes.classes {
            known[c.index as usize] = true;
        }
        if let Some(i) = map.class.iter().position(|&c| !known[c as usize]) {
            let cell = map.spec.cell_of_index(i);
            return Err(WorldError::invalid(
                "world",
                format!("cell ({}, {}) has class {} which is not in the table", cell.col, cell.row, map.class[i]),
            ));
        }
        if let Some(i) = map.elevation.iter().position(|e| !e.is_finite()) {
            let cell = map.spec.cell_of_index(i);
            return Err(WorldError::invalid(
                "world",
                format!("cell ({}, {}) has a non-finite elevation", cell.col, cell.row),
            ));
        }
        let max_elevation_m = map.elevation.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        Ok(World { map: Arc::new(map), aerial: None, classes, meta, max_elevation_m })
    }

    /// A world of one class at one elevation (tests, toy scenes).
    pub fn flat(spec: GridSpec, classes: ClassTable, class: ClassId, elevation_m: f32) -> Result<Self, WorldError> {
        let color = classes.get(class).map_or([0, 0, 0], |c| c.color);
        let map = AerialMap {
            class: vec![class; spec.len()],
            rgb: vec![color; spec.len()],
            elevation: vec![elevation_m; spec.len()],
            version: 1,
            spec,
        };
        World::new(map, classes, WorldMeta::default())
    }

    /// The class, colour and elevation layers: the ground truth.
    #[inline]
    pub fn map(&self) -> &AerialMap {
        &self.map
    }

    /// The world as seen from above: what the UAV's tiles and a prior map show. The ground
    /// layers unless the world has an aerial view of its own.
    #[inline]
    pub fn aerial_map(&self) -> &AerialMap {
        self.aerial.as_deref().unwrap_or(&self.map)
    }

    /// Whether the world has an aerial view that differs from its ground layers.
    pub fn has_aerial_view(&self) -> bool {
        self.aerial.is_some()
    }

    /// The world as seen from above, shared (a prior map for the robots costs no copy).
    pub fn shared_map(&self) -> Arc<AerialMap> {
        Arc::clone(self.aerial.as_ref().unwrap_or(&self.map))
    }

    /// Gives the world an aerial view of its own: what is seen from above where it differs
    /// from the ground (a barrier under canopy, a fence too thin for an aerial map), so that
    /// the robots' aerial map misleads where the world's does. An error, and no change, unless
    /// `aerial` has the world's grid, every class in the table and finite elevations.
    pub fn set_aerial_view(&mut self, aerial: AerialMap) -> Result<(), WorldError> {
        if aerial.spec != self.map.spec {
            return Err(WorldError::invalid("aerial view", "its grid differs from the world's"));
        }
        // The same checks as the ground layers'.
        let checked = World::new(aerial, self.classes.clone(), WorldMeta::default())?;
        let aerial = checked.map;
        self.aerial = (*aerial != *self.map).then_some(aerial);
        Ok(())
    }

    /// The class table of the class layer.
    #[inline]
    pub fn classes(&self) -> &ClassTable {
        &self.classes
    }

    /// Placement and size of the grid.
    #[inline]
    pub fn spec(&self) -> &GridSpec {
        &self.map.spec
    }

    /// Highest elevation, metres (an upper bound once cells were lowered with `set_cell`).
    #[inline]
    pub fn max_elevation_m(&self) -> f32 {
        self.max_elevation_m
    }

    /// Elevation of the cell containing `p`, if on the grid.
    #[inline]
    pub fn elevation_at(&self, p: Point2) -> Option<f32> {
        self.map.spec.cell_at(p).map(|c| self.map.elevation[self.map.spec.index(c)])
    }

    /// Class of the cell containing `p`, if on the grid.
    #[inline]
    pub fn class_at(&self, p: Point2) -> Option<ClassId> {
        self.map.spec.cell_at(p).map(|c| self.map.class[self.map.spec.index(c)])
    }

    /// Elevation at signed cell coordinates, if on the grid.
    #[inline]
    pub fn elevation_cell(&self, col: i64, row: i64) -> Option<f32> {
        if self.map.spec.contains(col, row) {
            Some(self.map.elevation[row as usize * self.map.spec.width as usize + col as usize])
        } else {
            None
        }
    }

    /// Sets a cell's ground layers (generators and tests); ignores cells off the grid, classes
    /// not in the table and non-finite elevations. An aerial view of the world's own, if it has
    /// one, stays as it is.
    pub fn set_cell(&mut self, cell: Cell, class: ClassId, rgb: [u8; 3], elevation_m: f32) {
        let inside = cell.col < self.map.spec.width && cell.row < self.map.spec.height;
        if inside && elevation_m.is_finite() && self.classes.get(class).is_some() {
            let map = Arc::make_mut(&mut self.map);
            let i = map.spec.index(cell);
            map.class[i] = class;
            map.rgb[i] = rgb;
            map.elevation[i] = elevation_m;
            self.max_elevation_m = self.max_elevation_m.max(elevation_m);
        }
    }

    /// An all-unknown aerial map over the same grid: what a team starts with.
    pub fn unknown_map(&self) -> AerialMap {
        AerialMap::unknown(self.map.spec)
    }

    /// The number of cells of a class.
    pub fn count_class(&self, class: ClassId) -> usize {
        self.map.class.iter().filter(|&&c| c == class).count()
    }
}
