//! The semantic class table: data, not code (docs/design.md §5).
//!
//! Class rasters, semantic panoramas and aerial maps store a [`ClassId`] per cell or pixel; the
//! table gives each index a name, a traversability rank (0 easiest … 5 impassable), a colour for
//! PNG rasters and whether downstream processing ignores it.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A class index as stored in rasters and panoramas.
pub type ClassId = u8;

/// The label of a cell or pixel whose class is not known (not yet mapped, no return).
pub const UNKNOWN_CLASS: ClassId = 255;

/// The highest traversability rank: impassable.
pub const IMPASSABLE_RANK: u8 = 5;

/// One row of the class table.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClassInfo {
    /// Label value in rasters.
    pub index: ClassId,
    /// Name used in missions (`vehicle`, `road`, …).
    pub name: String,
    /// Traversability rank, 0 = easiest … 5 = impassable.
    pub rank: u8,
    /// Colour of the class in class-raster PNGs.
    pub color: [u8; 3],
    /// Dropped by downstream processing (people).
    #[serde(default)]
    pub ignored: bool,
}

/// Why a class table was rejected.
#[derive(Debug, thiserror::Error)]
pub enum ClassTableError {
    /// The YAML did not parse into a table.
    #[error("class table does not parse: {0}")]
    Parse(String),
    /// The table breaks a rule.
    #[error("class table is invalid: {0}")]
    Invalid(String),
}

/// The form of a class name that spellings of one name share: lower case, every run of
/// characters other than letters and digits one `_`, none at either end (`Grass/Sidewalk ` →
/// `grass_sidewalk`).
pub fn class_key(name: &str) -> String {
    let mut key = String::with_capacity(name.len());
    for c in name.chars() {
        if c.is_alphanumeric() {
            key.extend(c.to_lowercase());
        } else if !key.is_empty() && !key.ends_with('_') {
            key.push('_');
        }
    }
    while key.ends_with('_') {
        key.pop();
    }
    key
}

/// The class table.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClassTable {
    /// The classes, any order; indices unique.
    pub classes: Vec<ClassInfo>,
}

/// The table shipped with spomp (the paper's classes).
pub const DEFAULT_CLASS_TABLE_YAML: &str = include_str!("../data/classes.yaml");

impl ClassTable {
    /// Parses and checks a table from YAML text.
    pub fn from_yaml(text: &str) -> Result<Self, ClassTableError> {
        let table: ClassTable = serde_saphyr::from_str(text).map_err(|e| ClassTableError::Parse(e.to_string()))?;
        table.check()?;
        Ok(table)
    }

    /// The table shipped with spomp.
    pub fn default_table() -> Self {
        // The embedded table is part of the build and covered by a test; failing here is a
        // packaging bug, not bad input.
        Self::from_yaml(DEFAULT_CLASS_TABLE_YAML).expect("embedded class table is valid")
    }

    fn check(&self) -> Result<(), ClassTableError> {
        let mut seen_index = [false; 256];
        for c in &self.classes {
            if c.index == UNKNOWN_CLASS {
                return Err(ClassTableError::Invalid(format!(
                    "class `{}` uses index {UNKNOWN_CLASS}, which is reserved for unknown",
                    c.name
                )));
            }
            if c.rank > IMPASSABLE_RANK {
                return Err(ClassTableError::Invalid(format!(
                    "class `{}` has rank {}, expected 0..={IMPASSABLE_RANK}",
                    c.name, c.rank
                )));
            }
            if std::mem::replace(&mut seen_index[c.index as usize], true) {
                return Err(ClassTableError::Invalid(format!("index {} is used twice", c.index)));
            }
            if self.classes.iter().filter(|o| o.name == c.name).count() > 1 {
                return Err(ClassTableError::Invalid(format!("name `{}` is used twice", c.name)));
            }
        }
        Ok(())
    }

    /// The class with this index.
    pub fn get(&self, index: ClassId) -> Option<&ClassInfo> {
        self.classes.iter().find(|c| c.index == index)
    }

    /// The class with this name: the exact name, else the one class whose name has the same
    /// [`class_key`] (so `grass/sidewalk`, `Grass Sidewalk` and `grass_sidewalk` are one name,
    /// as mapping pipelines spell classes differently). Two classes with the same key and
    /// neither exact: none, the name is ambiguous.
    pub fn by_name(&self, name: &str) -> Option<&ClassInfo> {
        if let Some(exact) = self.classes.iter().find(|c| c.name == name) {
            return Some(exact);
        }
        let key = class_key(name);
        let mut same = self.classes.iter().filter(|c| class_key(&c.name) == key);
        match (same.next(), same.next()) {
            (Some(only), None) if !key.is_empty() => Some(only),
            _ => None,
        }
    }

    /// The class whose raster colour is `rgb`.
    pub fn by_color(&self, rgb: [u8; 3]) -> Option<&ClassInfo> {
        self.classes.iter().find(|c| c.color == rgb)
    }

    /// Rank of a class; unknown and missing classes count as impassable.
    pub fn rank(&self, index: ClassId) -> u8 {
        self.get(index).map_or(IMPASSABLE_RANK, |c| c.rank)
    }

    /// A 256-entry rank lookup (unknown = impassable), for per-pixel loops.
    pub fn rank_lut(&self) -> [u8; 256] {
        let mut lut = [IMPASSABLE_RANK; 256];
        for c in &self.classes {
            lut[c.index as usize] = c.rank;
        }
        lut
    }

    /// Whether downstream processing should drop this class.
    pub fn is_ignored(&self, index: ClassId) -> bool {
        self.get(index).is_some_and(|c| c.ignored)
    }

    /// Class indices sorted from easiest to hardest rank (ties by index), ignored classes left out.
    pub fn easiest_first(&self) -> Vec<ClassId> {
        let mut v: Vec<&ClassInfo> = self.classes.iter().filter(|c| !c.ignored).collect();
        v.sort_by_key(|c| (c.rank, c.index));
        v.into_iter().map(|c| c.index).collect()
    }

    /// All class names, for error messages.
    pub fn names(&self) -> Vec<&str> {
        self.classes.iter().map(|c| c.name.as_str()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_table_matches_design() {
        let t = ClassTable::default_table();
        assert_eq!(t.classes.len(), 9);
        assert_eq!(t.by_name("vehicle").map(|c| (c.index, c.rank)), Some((4, 3)));
        assert_eq!(t.rank(2), 5);
        assert_eq!(t.rank(UNKNOWN_CLASS), 5);
        assert!(t.is_ignored(5));
        assert_eq!(t.easiest_first()[..3], [0, 6, 3]);
    }

    #[test]
    fn names_are_found_however_a_mapping_pipeline_spells_them() {
        let t = ClassTable::from_yaml(
            "classes:\n  - {index: 0, name: grass/sidewalk, rank: 2, color: [0,0,0]}\n  \
             - {index: 1, name: Tree Trunk, rank: 5, color: [1,1,1]}\n  - {index: 2, name: road, rank: 0, color: [2,2,2]}\n",
        )
        .unwrap();
        assert_eq!(t.by_name("grass_sidewalk").map(|c| c.index), Some(0));
        assert_eq!(t.by_name("Grass Sidewalk").map(|c| c.index), Some(0));
        assert_eq!(t.by_name("tree_trunk").map(|c| c.index), Some(1));
        assert_eq!(t.by_name("road").map(|c| c.index), Some(2));
        assert_eq!(t.by_name("sidewalk"), None);
        assert_eq!(t.by_name("//"), None);
        assert_eq!(class_key(" Grass/ Sidewalk- "), "grass_sidewalk");
    }

    #[test]
    fn an_ambiguous_spelling_finds_no_class_but_an_exact_name_does() {
        let t = ClassTable::from_yaml(
            "classes:\n  - {index: 0, name: Road, rank: 0, color: [0,0,0]}\n  - {index: 1, name: road!, rank: 1, color: [1,1,1]}\n",
        )
        .unwrap();
        assert_eq!(t.by_name("road"), None);
        assert_eq!(t.by_name("road!").map(|c| c.index), Some(1));
    }

    #[test]
    fn duplicate_index_is_rejected() {
        let yaml = "classes:\n  - {index: 0, name: a, rank: 0, color: [0,0,0]}\n  - {index: 0, name: b, rank: 1, color: [1,1,1]}\n";
        let err = ClassTable::from_yaml(yaml).unwrap_err().to_string();
        assert!(err.contains("index 0 is used twice"), "{err}");
    }

    #[test]
    fn bad_rank_and_reserved_index_are_rejected() {
        let rank = "classes:\n  - {index: 0, name: a, rank: 9, color: [0,0,0]}\n";
        assert!(ClassTable::from_yaml(rank).unwrap_err().to_string().contains("rank 9"));
        let reserved = "classes:\n  - {index: 255, name: a, rank: 0, color: [0,0,0]}\n";
        assert!(ClassTable::from_yaml(reserved).unwrap_err().to_string().contains("reserved"));
    }

    #[test]
    fn garbage_is_a_parse_error_not_a_panic() {
        assert!(matches!(ClassTable::from_yaml("classes: [1, 2"), Err(ClassTableError::Parse(_))));
        assert!(matches!(ClassTable::from_yaml("\u{0}\u{1}"), Err(ClassTableError::Parse(_))));
    }
}
